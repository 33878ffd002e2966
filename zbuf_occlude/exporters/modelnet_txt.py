"""``export --to modelnet-txt``: the ``modelnet40_normal_resampled`` layout of Pointnet_Pointnet2_pytorch.

What yanx27/Pointnet_Pointnet2_pytorch's ``ModelNetDataLoader`` reads:

* ``<class>/<class>_<NNNN>.txt``: one sample a file, ``x,y,z,nx,ny,nz`` per line (``%.6f``), +y up
  as ModelNet's own files (``up`` turns them otherwise), numbered per class from 1 across the
  splits; the normals are estimated from the sample's points and face its sensor
  (:func:`estimate_normals`: :func:`~zbuf_occlude.geometry.normals.estimate_normals`' method on
  numba kernels), as a real scan's are;
* ``modelnet40_shape_names.txt`` (``modelnet10_...`` for ``label_set_name="modelnet10"``, which that
  loader opens when ``num_category`` is 10): the label set's classes, one per label;
* ``modelnet40_<split>.txt``: the ids of a split, one a line; the loader takes an id's class from
  the id (all but its last ``_`` part) and its label from the class list;
* ``modelnet40_<split>_id2file.json``: each id's mesh and view (``<name>/vPPP_sSS``), as
  ``pointnet-h5``'s ``id2file.json`` (the loader does not open it).

Samples are read one object at a time (memory for one object's samples); a few threads make the
next samples' files while one is written (:data:`MAX_THREADS`), each line without a Python loop (:func:`~zbuf_occlude.exporters.text_table.fixed_point_table_bytes`, the bytes
of ``np.savetxt``), the files recorded and synced 64 at a time
(:meth:`~zbuf_occlude.io.owned.OwnedFolder.write_many`).  Each line holds xyz and normals only: a ``farm --sensor`` data set's per-point
return fields are left out (the loader reads six columns).
"""

from __future__ import annotations

import json
import os
from collections import deque
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from zbuf_occlude.exporters.base import ExportOptions, Target, Written, turn_up
from zbuf_occlude.exporters.source import Splits, open_dataset, sample_file
from zbuf_occlude.geometry import normals
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS
from zbuf_occlude.io.owned import BatchWriter, OwnedFolder
from zbuf_occlude.io.progress import progress
from zbuf_occlude.resources import check_memory
from zbuf_occlude.sensors.patterns.spinning import beam_directions

__all__ = ["FILE_NAMES", "TARGET", "estimate_normals", "write_modelnet_txt"]

#: Bytes per point of one sample while it is written: six float64 columns, their int64 digits, and
#: their text (16 bytes a value while it is cut, 11 characters once written for coordinates in [-1, 1]).
BYTES_PER_POINT = 6 * 8 * 3 + 6 * 16 * 2
#: Threads that make the samples' text while the files are written (the normals' numpy and scipy
#: work and the writes' waits on the disk both run outside the GIL); at most the CPUs there are.
MAX_THREADS = 4
#: Samples made ahead per thread: the memory of (this + 1) samples' text, whatever the data set's size.
LOOKAHEAD_PER_THREAD = 2
#: The names this target writes (regular expressions, for the owned folder).
FILE_NAMES = (r"[^/]+/[^/]+_\d{4,}\.txt", r"modelnet(10|40)_(shape_names|[a-z]+)\.txt", r"modelnet(10|40)_[a-z]+_id2file\.json")


def write_modelnet_txt(
    folder: OwnedFolder,
    splits: Mapping[str, object],
    labels: Mapping[str, int],
    names: Sequence[str],
    *,
    prefix: str,
    up: str = "+y",
    show_progress: bool = False,
) -> list[Path]:
    """Write every sample of ``splits`` as one text file (module docstring).

    Parameters
    ----------
    folder : OwnedFolder
        The export's folder, held.
    splits : mapping of str to OccludedDataset
        The source's samples of each split (+z up).
    labels : mapping of str to int
        The label of each class name.
    names : sequence of str
        The label set's class names: the folders, the ids' class part and the class list.
    prefix : str
        ``modelnet40`` or ``modelnet10``: the class list's and id lists' names.
    up : str
        The export's up axis (:data:`~zbuf_occlude.exporters.base.UP_AXES`); points and normals turn together.
    show_progress : bool
        A progress bar of the samples written, on stderr.

    Returns
    -------
    list of Path
        The class list and id lists (the sample files and id maps are many; they are in the folder's ledger).

    Raises
    ------
    InsufficientMemoryError
        The samples made ahead (:data:`LOOKAHEAD_PER_THREAD` per thread, :data:`BYTES_PER_POINT` per
        point) would not fit in memory.
    OutputError, UnsafePathError
        As :meth:`~zbuf_occlude.io.owned.OwnedFolder.write`.
    """
    n_points = max((ds.n_points for ds in splits.values()), default=0)  # before any file is written
    threads = min(MAX_THREADS, os.cpu_count() or 1)
    in_flight = LOOKAHEAD_PER_THREAD * threads
    check_memory(
        (in_flight + 1) * n_points * BYTES_PER_POINT, option=f"{in_flight + 1} samples' text ({n_points:,} points each)", hint="free memory"
    )
    written = [folder.write_text(f"{prefix}_shape_names.txt", "".join(f"{n}\n" for n in names))]
    counter: dict[str, int] = {}
    total = sum(len(ds) for ds in splits.values())
    with progress(total=total, desc="export modelnet-txt", unit="sample", enabled=show_progress) as bar, \
            ThreadPoolExecutor(max_workers=threads, thread_name_prefix="modelnet-txt") as pool, \
            folder.write_many() as batch:  # fmt: skip
        for split, ds in sorted(splits.items()):
            ids = {}
            radius = float(ds.card.get("params", {}).get("radius") or DEFAULT_RADIUS)
            pending: deque = deque()  # (file, text to come), in the source's order: written in that order
            for start, block in ds.iter_arrays():
                for j, points in enumerate(block):
                    meta = ds.metadata(start + j)
                    cls = names[labels[meta["class_name"]]]
                    counter[cls] = counter.get(cls, 0) + 1
                    sample_id = f"{cls}_{counter[cls]:04d}"
                    eye = beam_directions(meta["elevation_deg"], meta["azimuth_deg"]) * float(meta.get("radius", radius))
                    pending.append((f"{cls}/{sample_id}.txt", pool.submit(_sample_text, points, eye, up)))
                    ids[sample_id] = sample_file(meta)
                    while len(pending) > in_flight:
                        _write_next(batch, pending, bar)
            while pending:
                _write_next(batch, pending, bar)
            batch.flush()  # the split's files are named before its lists name them
            folder.write_text(f"{prefix}_{split}_id2file.json", json.dumps(ids, indent=0) + "\n")
            written.append(folder.write_text(f"{prefix}_{split}.txt", "".join(f"{i}\n" for i in ids)))
    return written


def _sample_text(points: np.ndarray, eye: np.ndarray, up: str) -> bytes:
    """One sample's file: its points and their normals (estimated +z up, facing ``eye``), turned to ``up``, as text."""
    # numba: imported by this target alone
    from zbuf_occlude.exporters.text_table import fixed_point_table_bytes

    table = turn_up(np.hstack([points, estimate_normals(points, eye)]).reshape(-1, 2, 3), "+z", up)
    return fixed_point_table_bytes(table.reshape(-1, 6))


def estimate_normals(points: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """Unit normals ``(n, 3) float32`` of one sample's ``points (n, 3)``, each facing ``eye (3,)``: the
    method of :func:`~zbuf_occlude.geometry.normals.estimate_normals` (the plane of each point's
    :data:`~zbuf_occlude.geometry.normals.NORMAL_NEIGHBOURS` nearest points, flipped toward the
    sensor) on the numba kernels of point-only visibility: the k-d tree's neighbours from a grid
    (:func:`~zbuf_occlude.visibility.point_neighbours.nearest_neighbours`) and a closed-form 3 x 3
    plane fit (:func:`~zbuf_occlude.visibility.point_preparation.plane_fits`) for LAPACK's.

    The two agree to float rounding (tests/exporters/test_modelnet_txt_normals.py): a value's
    ``%.6f`` text may differ in its last digit, a component that is zero but for rounding may print
    as ``-0.000000`` for ``0.000000``, and a point whose plane passes through ``eye`` (neither side
    faces it) may face the other way.
    """
    # numba's kernels, imported by this target alone
    from zbuf_occlude.visibility.point_neighbours import nearest_neighbours
    from zbuf_occlude.visibility.point_preparation import plane_fits

    p = np.asarray(points, dtype=np.float64)
    n = len(p)
    k = min(normals.NORMAL_NEIGHBOURS, n)
    if k < 3:
        return normals.estimate_normals(p, eye)
    _, index = nearest_neighbours(p, k, workers=1)
    fits, variation = np.empty((1, n, 3)), np.empty((1, n))
    plane_fits(p, index, np.array([k], dtype=np.int64), 0, n, fits, variation)
    normal = fits[0]
    normal[np.einsum("ni,ni->n", normal, np.asarray(eye, dtype=np.float64) - p) < 0] *= -1.0
    return normal.astype(np.float32)


def _write_next(batch: BatchWriter, pending: deque, bar: object) -> None:
    """Write the first of ``pending`` once its text is made (its error, if any, raised here)."""
    rel, text = pending.popleft()
    batch.write_bytes(rel, text.result())
    bar.update(1)


def _write(folder: OwnedFolder, src: Splits, options: ExportOptions) -> Written:
    prefix = "modelnet10" if src.set_name == "modelnet10" else "modelnet40"
    files = write_modelnet_txt(folder, src.splits, src.labels, src.names, prefix=prefix, up=options.up, show_progress=options.progress)
    return Written(files, src.samples)


#: ``to="modelnet-txt"``.
TARGET = Target(
    "modelnet-txt", "Pointnet_Pointnet2_pytorch's modelnet40_normal_resampled", FILE_NAMES, open_dataset, _write,
    up="+y", frame="as ModelNet's modelnet40_normal_resampled (PointNet-family augmentation turns about y)",
)  # fmt: skip
