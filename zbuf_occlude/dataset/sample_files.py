"""Read the points of ``generate``'s one-file-per-sample outputs (``--format npz`` and ``ply``).

:class:`~zbuf_occlude.dataset.reader.OccludedDataset` serves such a folder like a farm data set:
the manifest lists each object's sample files (``shards``, pose-major, then sample index,
with their SHA-256), and this module reads one file's points.  The files are opened as data
only: ``.npz`` with ``allow_pickle=False``, ``.ply`` by trimesh's parser.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.dataset.layout import SAMPLE_FILE_FORMATS
from zbuf_occlude.errors import DatasetFormatError, InvalidInputError
from zbuf_occlude.io.arrays import npz_member_header

__all__ = ["read_sample_points"]


def _npz_points(path: Path, n_points: int) -> NDArray:
    with np.load(path, allow_pickle=False) as z:
        if "points" not in z.files:
            raise KeyError(f"no array 'points' (it holds {sorted(z.files)[:5]})")
        # the shape and dtype the member declares, before it is inflated: a small member may inflate to GBs
        shape, dtype = npz_member_header(z.zip, "points")
        if shape != (n_points, 3) or dtype.kind != "f":
            raise ValueError(f"'points' is declared {shape} {dtype}, not ({n_points}, 3) floats")
        return z["points"]


def _ply_points(path: Path) -> NDArray:
    import trimesh

    cloud = trimesh.load(path, file_type="ply", process=False)
    if not isinstance(cloud, trimesh.PointCloud):
        raise ValueError(f"a {type(cloud).__name__}, not a point cloud")
    return cloud.vertices  # float64 of the file's float32: casting back is exact


def read_sample_points(path: str | os.PathLike, fmt: str, n_points: int) -> NDArray[np.float32]:
    """The points of one sample file that ``generate --format npz|ply`` wrote.

    Parameters
    ----------
    path : str or PathLike
        A ``.npz`` (:func:`zbuf_occlude.io.clouds.write_npz`) or ``.ply`` (:func:`zbuf_occlude.io.clouds.write_ply`) file.
    fmt : {"npz", "ply"}
    n_points : int
        Points the data set's card says every sample holds.

    Returns
    -------
    points : (n_points, 3) float32
        Object frame, normalised mesh units, as written.

    Raises
    ------
    InvalidInputError
        Unknown format.
    DatasetFormatError
        The file cannot be read, has no ``points``, or does not hold ``(n_points, 3)``
        floats (checked in an ``.npz`` member's header, before it is inflated); the
        message names the file.
    """
    if fmt not in SAMPLE_FILE_FORMATS:
        raise InvalidInputError(f"{path}: unknown sample file format {fmt!r}; expected one of {SAMPLE_FILE_FORMATS}")
    path = Path(path)
    try:
        points = _npz_points(path, int(n_points)) if fmt == "npz" else _ply_points(path)
    except (OSError, ValueError, KeyError, IndexError, TypeError, EOFError, zipfile.BadZipFile) as exc:
        raise DatasetFormatError(f"cannot read the sample file {path}: {exc}; rerun the generate command to redo it") from None
    points = np.asarray(points)
    if points.shape != (int(n_points), 3) or not np.issubdtype(points.dtype, np.floating):
        raise DatasetFormatError(
            f"the sample file {path} holds points of shape {points.shape} ({points.dtype}), not ({int(n_points)}, 3) floats"
        )
    return points.astype(np.float32, copy=False)
