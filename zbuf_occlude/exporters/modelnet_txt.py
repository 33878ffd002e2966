"""``export --to modelnet-txt``: the ``modelnet40_normal_resampled`` layout of Pointnet_Pointnet2_pytorch.

What yanx27/Pointnet_Pointnet2_pytorch's ``ModelNetDataLoader`` reads:

* ``<class>/<class>_<NNNN>.txt``: one sample a file, ``x,y,z,nx,ny,nz`` per line (``%.6f``),
  numbered per class from 1 across the splits; the normals are estimated from the sample's points
  and face its sensor (:func:`~zbuf_occlude.geometry.normals.estimate_normals`), as a real scan's are;
* ``modelnet40_shape_names.txt`` (``modelnet10_...`` for ``--label-set modelnet10``, which that loader
  opens when ``num_category`` is 10): the label set's classes, one per label;
* ``modelnet40_<split>.txt``: the ids of a split, one a line; the loader takes an id's class from
  the id (all but its last ``_`` part) and its label from the class list.

Samples are read one object at a time (memory for one object's samples).  Each line holds xyz and
normals only: a ``farm --sensor`` data set's per-point return fields are left out (the loader reads
six columns).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS
from zbuf_occlude.geometry.normals import estimate_normals
from zbuf_occlude.io.encodings import text_table_bytes
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.resources import check_memory
from zbuf_occlude.sensors.lidar import beam_directions

__all__ = ["FILE_NAMES", "write_modelnet_txt"]

#: Bytes per point of one sample while it is written: six float64 columns, and their text
#: (``-0.123456,`` : at most 11 characters a value for coordinates in [-1, 1] and unit normals, some more for others).
BYTES_PER_POINT = 6 * 8 + 6 * 16
#: The names this target writes (regular expressions, for the owned folder).
FILE_NAMES = (r"[^/]+/[^/]+_\d{4,}\.txt", r"modelnet(10|40)_(shape_names|[a-z]+)\.txt")


def write_modelnet_txt(
    folder: OwnedFolder, splits: Mapping[str, object], labels: Mapping[str, int], names: Sequence[str], *, prefix: str
) -> list[Path]:
    """Write every sample of ``splits`` as one text file (module docstring).

    Parameters
    ----------
    folder : OwnedFolder
        The export's folder, held.
    splits : mapping of str to OccludedDataset
        The source's samples of each split.
    labels : mapping of str to int
        The label of each class name.
    names : sequence of str
        The label set's class names: the folders, the ids' class part and the class list.
    prefix : str
        ``modelnet40`` or ``modelnet10``: the class list's and id lists' names.

    Returns
    -------
    list of Path
        The class list and id lists (the sample files are many; they are in the folder's ledger).

    Raises
    ------
    InsufficientMemoryError
        One sample's text (:data:`BYTES_PER_POINT` per point) would not fit in memory.
    OutputError, UnsafePathError
        As :meth:`~zbuf_occlude.io.owned.OwnedFolder.write`.
    """
    n_points = max((ds.n_points for ds in splits.values()), default=0)  # before any file is written
    check_memory(n_points * BYTES_PER_POINT, option=f"one sample's text ({n_points:,} points)", hint="free memory")
    written = [folder.write_text(f"{prefix}_shape_names.txt", "".join(f"{n}\n" for n in names))]
    counter: dict[str, int] = {}
    for split, ds in sorted(splits.items()):
        ids = []
        radius = float(ds.card.get("params", {}).get("radius") or DEFAULT_RADIUS)
        for start, block in ds.iter_arrays():
            for j, points in enumerate(block):
                meta = ds.metadata(start + j)
                cls = names[labels[meta["class_name"]]]
                counter[cls] = counter.get(cls, 0) + 1
                sample_id = f"{cls}_{counter[cls]:04d}"
                eye = beam_directions(meta["elevation_deg"], meta["azimuth_deg"]) * float(meta.get("radius", radius))
                table = text_table_bytes(np.hstack([points, estimate_normals(points, eye)]), fmt="%.6f", delimiter=",")
                folder.write_bytes(f"{cls}/{sample_id}.txt", table)
                ids.append(sample_id)
        written.append(folder.write_text(f"{prefix}_{split}.txt", "".join(f"{i}\n" for i in ids)))
    return written
