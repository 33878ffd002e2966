"""Read the points of ``generate``'s one-file-per-sample outputs (``--format npz`` and ``ply``).

:class:`~zbuf_occlude.dataset.reader.OccludedDataset` serves such a folder like a farm data set:
the manifest lists each object's sample files (``shards``, pose-major, then sample index,
with their SHA-256), and this module reads one file's points.  The files are opened as data
only, through the reading layer: a regular file of at most :func:`sample_file_max_bytes`, inside
the data set's folder once links are resolved; ``.npz`` with ``allow_pickle=False``
(:func:`~zbuf_occlude.io.arrays.load_npz`), ``.ply`` by trimesh's parser from memory
(:func:`~zbuf_occlude.io.ply.parse_ply_vertices`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.dataset.layout import SAMPLE_FILE_FORMATS
from zbuf_occlude.errors import DatasetFormatError, InvalidInputError
from zbuf_occlude.io.arrays import load_npz
from zbuf_occlude.io.ply import parse_ply_vertices
from zbuf_occlude.io.regular_files import read_regular_file

__all__ = ["read_sample_points", "sample_file_max_bytes"]

#: Bytes one point of a sample file may take: x, y, z and a face index, 8 bytes each at most
#: (:func:`zbuf_occlude.io.clouds.write_npz` writes 20, :func:`~zbuf_occlude.io.clouds.write_ply` 16).
SAMPLE_BYTES_PER_POINT = 32
#: Bytes a sample file may hold beside its points: the pose, the counts, the class name and the
#: mesh's path (a few kB as ``.npz`` strings of 4 bytes a character, less in a PLY header).
SAMPLE_METADATA_BYTES = 1 << 20


def sample_file_max_bytes(n_points: int) -> int:
    """The most bytes a sample file of ``n_points`` points may hold (or inflate to, for ``.npz``)."""
    return int(n_points) * SAMPLE_BYTES_PER_POINT + SAMPLE_METADATA_BYTES


def _npz_points(path: Path, n_points: int, within: Path | None) -> NDArray:
    def check(declared: dict[str, tuple[tuple[int, ...], np.dtype]]) -> None:
        # the shape and dtype the member declares, before it is inflated
        if "points" not in declared:
            raise DatasetFormatError(f"{path}: no array 'points'")
        shape, dtype = declared["points"]
        if shape != (n_points, 3) or dtype.kind != "f":
            raise DatasetFormatError(f"{path}: 'points' is declared {shape} {dtype}, not ({n_points}, 3) floats")

    max_bytes = sample_file_max_bytes(n_points)
    return load_npz(path, max_bytes=max_bytes, error=DatasetFormatError, within=within, keys=("points",), check=check)["points"]


def _ply_points(path: Path, n_points: int, within: Path | None) -> NDArray:
    raw = read_regular_file(path, max_bytes=sample_file_max_bytes(n_points), error=DatasetFormatError, within=within)
    return parse_ply_vertices(raw, path, error=DatasetFormatError, points_only=True)  # float64 of the file's float32: exact


def read_sample_points(path: str | os.PathLike, fmt: str, n_points: int, *, within: str | os.PathLike | None = None) -> NDArray[np.float32]:
    """The points of one sample file that ``generate --format npz|ply`` wrote.

    Parameters
    ----------
    path : str or PathLike
        A ``.npz`` (:func:`zbuf_occlude.io.clouds.write_npz`) or ``.ply`` (:func:`zbuf_occlude.io.clouds.write_ply`) file.
    fmt : {"npz", "ply"}
    n_points : int
        Points the data set's card says every sample holds.
    within : str or PathLike, optional
        The data set's folder: the file must stay inside it, links resolved.

    Returns
    -------
    points : (n_points, 3) float32
        Object frame, normalised mesh units, as written.

    Raises
    ------
    InvalidInputError
        Unknown format.
    DatasetFormatError
        The file is missing, not a regular file (a FIFO), larger than
        :func:`sample_file_max_bytes` (for ``.npz``: its members inflate past it, read from
        the zip directory before a byte is inflated), cannot be read, has no ``points``, or does
        not hold ``(n_points, 3)`` floats; the message names the file.
    UnsafePathError
        ``within`` is given and the file leads outside it.
    """
    if fmt not in SAMPLE_FILE_FORMATS:
        raise InvalidInputError(f"{path}: unknown sample file format {fmt!r}; expected one of {SAMPLE_FILE_FORMATS}")
    path = Path(path)
    try:
        points = (_npz_points if fmt == "npz" else _ply_points)(path, int(n_points), None if within is None else Path(within))
    except DatasetFormatError as exc:
        raise DatasetFormatError(f"{exc}; rerun the generate command to redo it") from None
    points = np.asarray(points)
    if points.shape != (int(n_points), 3) or not np.issubdtype(points.dtype, np.floating):
        raise DatasetFormatError(
            f"the sample file {path} holds points of shape {points.shape} ({points.dtype}), not ({int(n_points)}, 3) floats"
        )
    return points.astype(np.float32, copy=False)
