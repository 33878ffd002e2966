"""``export --to pointnet-h5``: the ``modelnet40_ply_hdf5_2048`` layout of PointNet (Qi et al. 2017).

What charlesq34/pointnet's ``provider.py`` and ``train.py`` read, and after them PointNet++ (TF),
DGCNN (``glob(ply_data_%s*.h5)``), PCT, PointMLP and CurveNet:

* ``ply_data_<split><k>.h5``: ``data (m, P, 3) float32`` (+y up, as ModelNet40's own files:
  ``provider.rotate_point_cloud`` turns them about y, "along up direction"; the root's attribute
  ``up`` says the axis, which the loaders do not read and the point-set readers do) and ``label (m, 1) uint8`` (``uint16``
  above 256 classes), at most :data:`ROWS_PER_FILE` rows a file.  The rows of every class are
  shuffled across the files with ``seed``: PointNet shuffles only inside a file, so files of one
  class would give batches of one class;
* ``ply_data_<split>_<k>_id2file.json``: each row's mesh and view (``<name>/vPPP_sSS``);
* ``shape_names.txt``: the label set's class names, one per label;
* ``<split>_files.txt``: one line per file, ``<list prefix>/ply_data_<split><k>.h5``, relative to
  the client repository's root as PointNet's are (default prefix ``data/<folder's name>``).

The set is streamed: each object's samples are read once, in the source's order, and each row is
written straight to the place the shuffle gave it, so memory holds one object's samples, not the set's.
The files hold xyz only (a ``farm --sensor`` data set's per-point return fields are left out: PointNet's
``data`` is ``(m, P, 3)``) and no modification times: the same data set gives the same bytes.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from zbuf_occlude.defaults import DEFAULT_SEED
from zbuf_occlude.exporters.base import ExportOptions, Target, Written, turn_up
from zbuf_occlude.exporters.source import Splits, open_dataset, sample_file
from zbuf_occlude.io.atomic import positional_writer, temp_h5
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.io.progress import progress
from zbuf_occlude.resources import check_memory

__all__ = ["FILE_NAMES", "ROWS_PER_FILE", "TARGET", "write_pointnet_h5"]

#: Rows per file, as ``modelnet40_ply_hdf5_2048``'s (its last file of a split holds the rest).
ROWS_PER_FILE = 2048
#: Files open at once while rows are scattered; a larger split is written in passes over the source.
MAX_OPEN_FILES = 256
#: Bytes per sample of a split's bookkeeping: its place in the shuffle, its position, its label (int64 each).
BYTES_PER_SAMPLE = 3 * 8
#: The names this target writes (regular expressions, for the owned folder).
FILE_NAMES = (r"ply_data_[a-z]+\d+\.h5", r"ply_data_[a-z]+_\d+_id2file\.json", r"shape_names\.txt", r"[a-z]+_files\.txt")


def _create_file(path: Path, rows: int, n_points: int, label: np.ndarray, up: str) -> int:
    """Make ``path`` a PointNet file: ``label`` written, ``data (rows, n_points, 3) float32`` allocated
    contiguous and not filled, the root's attribute ``up`` set to the export's up axis (which the
    point-set readers take); return the byte offset of ``data``'s first row.

    The rows are then written straight to that offset, in any order
    (:func:`~zbuf_occlude.io.atomic.positional_writer`): a contiguous, uncompressed HDF5 dataset is
    a C-order array at one place in the file (h5py's ``DatasetID.get_offset``), and a row written
    there costs what a plain write costs, where h5py's writes of scattered rows cost 5-30 times more.
    """
    import h5py

    with temp_h5(path) as f:
        dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
        dcpl.set_layout(h5py.h5d.CONTIGUOUS)
        dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)  # the space exists (and has its offset) now
        dcpl.set_fill_time(h5py.h5d.FILL_TIME_NEVER)  # every row is written below
        dcpl.set_obj_track_times(False)  # no modification times: the same data set, the same bytes
        space = h5py.h5s.create_simple((rows, n_points, 3))
        data = h5py.h5d.create(f.id, b"data", h5py.h5t.IEEE_F32LE, space, dcpl=dcpl)
        offset = data.get_offset()
        f.create_dataset("label", data=label, track_times=False)
        f.attrs["up"] = up
    if offset is None:  # an empty dataset has no storage
        return 0
    return int(offset)


def _label_dtype(n_classes: int) -> np.dtype:
    return np.dtype(np.uint8 if n_classes <= 256 else np.uint16)


def write_pointnet_h5(
    folder: OwnedFolder,
    splits: Mapping[str, object],
    labels: Mapping[str, int],
    names: Sequence[str],
    *,
    seed: int,
    list_prefix: str,
    rows_per_file: int | None = None,
    up: str = "+y",
    show_progress: bool = False,
) -> list[Path]:
    """Write each split of ``splits`` (:class:`~zbuf_occlude.dataset.reader.OccludedDataset` per split) in PointNet's layout.

    Parameters
    ----------
    folder : OwnedFolder
        The export's folder, held.
    splits : mapping of str to OccludedDataset
        The source's samples of each split (an empty one gets an empty file list).
    labels : mapping of str to int
        The label of each class name (:meth:`~zbuf_occlude.exporters.label_sets.LabelSet.labels`).
    names : sequence of str
        The label set's class names (``shape_names.txt``).
    seed : int
        Seed of the shuffle (:func:`numpy.random.default_rng`; split ``k``-th gets ``(seed, k)``).
    list_prefix : str
        What each line of ``<split>_files.txt`` starts with.
    rows_per_file : int, optional
        Rows per file (default :data:`ROWS_PER_FILE`).
    up : str
        The export's up axis (:data:`~zbuf_occlude.exporters.base.UP_AXES`); the source is +z up.
    show_progress : bool
        A progress bar of the samples written, on stderr.

    Returns
    -------
    list of Path
        The class list and the file lists (the data files are in the folder's ledger).

    Raises
    ------
    InsufficientMemoryError
        A split's bookkeeping (:data:`BYTES_PER_SAMPLE` per sample) would not fit in memory.
    OutputError, UnsafePathError
        As :meth:`~zbuf_occlude.io.owned.OwnedFolder.write`.
    """
    rows_per_file = ROWS_PER_FILE if rows_per_file is None else int(rows_per_file)
    largest = max((len(ds) for ds in splits.values()), default=0)  # one split at a time, before any file is written
    check_memory(largest * BYTES_PER_SAMPLE, option=f"the shuffle of a split of {largest:,} samples", hint="free memory")
    written = [folder.write_text("shape_names.txt", "".join(f"{n}\n" for n in names))]
    dtype = _label_dtype(len(names))
    reads = sum(len(ds) * _passes(len(ds), rows_per_file) for ds in splits.values())  # a split is read once per pass
    with progress(total=reads, desc="export pointnet-h5", unit="sample", enabled=show_progress) as bar:
        for k, (split, ds) in enumerate(sorted(splits.items())):
            written.append(_write_split(folder, split, k, ds, labels, dtype, seed=seed, list_prefix=list_prefix,
                                        rows_per_file=rows_per_file, up=up, bar=bar))  # fmt: skip
    return written


def _passes(n: int, rows_per_file: int) -> int:
    """How many times a split of ``n`` samples is read: once per :data:`MAX_OPEN_FILES` files."""
    n_files = -(-n // rows_per_file)
    return -(-n_files // MAX_OPEN_FILES)


def _write_split(
    folder: OwnedFolder, split: str, k: int, ds: object, labels: Mapping[str, int], dtype: np.dtype, *,
    seed: int, list_prefix: str, rows_per_file: int, up: str, bar: object,
) -> Path:  # fmt: skip
    """Write one split's files and id maps (:func:`write_pointnet_h5`); return its file list."""
    n = len(ds)
    n_files = -(-n // rows_per_file)
    order = np.random.default_rng([seed, k]).permutation(n)  # row order[j] of the output is sample j's...
    position = np.empty(n, dtype=np.int64)
    position[order] = np.arange(n)  # ... sample i goes to output row position[i]
    label_of = np.array([labels[c] for c in ds.shape_names], dtype=np.int64) if n else np.zeros(0, np.int64)
    all_labels = label_of[ds.labels] if n else np.zeros(0, np.int64)
    files = [f"ply_data_{split}{f}.h5" for f in range(n_files)]
    for first in range(0, n_files, MAX_OPEN_FILES):
        group = range(first, min(first + MAX_OPEN_FILES, n_files))
        with contextlib.ExitStack() as stack:
            writers, offsets = {}, {}
            for f in group:
                tmp = stack.enter_context(folder.write(files[f]))
                rows = min(rows_per_file, n - f * rows_per_file)
                mine = order[f * rows_per_file : f * rows_per_file + rows]
                offsets[f] = _create_file(tmp, rows, ds.n_points, all_labels[mine].astype(dtype)[:, None], up)
                writers[f] = stack.enter_context(positional_writer(tmp))
            row_bytes = ds.n_points * 3 * 4
            for start, block in ds.iter_arrays():
                where = position[start : start + len(block)]
                rows_le = np.ascontiguousarray(turn_up(block, "+z", up), dtype="<f4")
                for j, pos in enumerate(where):  # each row to its place: HDF5's contiguous layout is a plain array
                    f, row = divmod(int(pos), rows_per_file)
                    if f in writers:
                        writers[f](offsets[f] + row * row_bytes, rows_le[j].tobytes())
                bar.update(len(block))
    for f in range(n_files):
        mine = order[f * rows_per_file : (f + 1) * rows_per_file]
        ids = [sample_file(ds.metadata(int(i))) for i in mine]
        folder.write_text(f"ply_data_{split}_{f}_id2file.json", json.dumps(ids) + "\n")
    return folder.write_text(f"{split}_files.txt", "".join(f"{list_prefix}/{name}\n" for name in files))


def _write(folder: OwnedFolder, src: Splits, options: ExportOptions) -> Written:
    seed = DEFAULT_SEED if options.seed is None else options.seed
    prefix = str(options.list_prefix).rstrip("/")  # export() gives it (by default data/<out's name>), checked
    files = write_pointnet_h5(folder, src.splits, src.labels, src.names, seed=seed, list_prefix=prefix, up=options.up,
                              show_progress=options.progress)  # fmt: skip
    return Written(files, src.samples)


#: ``to="pointnet-h5"``.
TARGET = Target(
    "pointnet-h5", "PointNet's modelnet40_ply_hdf5_2048 (PointNet, PointNet++ TF, DGCNN, PCT, PointMLP, CurveNet)",
    FILE_NAMES, open_dataset, _write, up="+y", frame="as PointNet's modelnet40_ply_hdf5_2048 (its augmentation turns about y)",
    options=("seed", "list_prefix"),
)  # fmt: skip
