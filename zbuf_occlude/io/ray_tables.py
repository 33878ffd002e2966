"""Ray tables from anyone: a ``(time, azimuth, elevation)`` row per pulse, as CSV or ``.npy``.

A non-repetitive scanner (Livox's rosette, DJI L2) or a hybrid solid-state unit is described by
the directions it fires in, in order, with each pulse's time.  Two file formats:

* **CSV**: a header line ``time_s,azimuth_deg,elevation_deg`` (those three names, in that order;
  spaces around them allowed), then one row per pulse of three numbers separated by commas.
  Blank lines are skipped (but count towards the cap on rows, except those at the end); nothing
  else (comments, quotes, other columns) is accepted.  The file is read by
  :func:`~zbuf_occlude.io.regular_files.read_text_file`'s rules (a regular file, at most
  :data:`CSV_BYTES_PER_ROW` bytes per row allowed, UTF-8);
* **NumPy** ``.npy``: one ``(N, 3)`` floating-point array, columns in that order, read by
  :func:`~zbuf_occlude.io.arrays.load_npy` (its header's declared size checked against the row
  cap before the body is allocated, nothing unpickled).

Only the format is checked here (the columns, numbers, the number of rows); what the numbers
mean (finite, time non-decreasing, elevations within ±90°) is checked by the sensor that takes
them, :class:`~zbuf_occlude.sensors.ray_table.RayTable`.  Every error is one line naming the
file.
"""

from __future__ import annotations

import io
import warnings
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.arrays import load_npy
from zbuf_occlude.io.encodings import npy_bytes
from zbuf_occlude.io.regular_files import read_text_file

__all__ = ["CSV_BYTES_PER_ROW", "RAY_TABLE_COLUMNS", "RAY_TABLE_SUFFIXES", "ray_table_bytes", "read_ray_table"]

#: The columns of a ray table, in file order: seconds, degrees, degrees.
RAY_TABLE_COLUMNS = ("time_s", "azimuth_deg", "elevation_deg")
#: The file suffixes read (lower case).
RAY_TABLE_SUFFIXES = (".csv", ".npy")
#: Bytes a CSV row may take on average, for the file's size cap: three float64 written to round
#: trip (``%.17g``: at most 24 characters each) and their separators take at most 76.
CSV_BYTES_PER_ROW = 96
#: Room for the header line and blank lines on top of the rows' bytes.
_CSV_SLACK_BYTES = 4096


def read_ray_table(
    path: str | PathLike[str], *, max_rows: int, within: str | PathLike[str] | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The three columns of a ray table file (module docstring), as they are in the file.

    Parameters
    ----------
    path : str or PathLike
        A ``.csv`` or ``.npy`` file (by its suffix, any case).
    max_rows : int
        The most rows accepted (a sensor's cap on its rays), checked before the rows are parsed
        (CSV: the file's size and its line count; ``.npy``: the size its header declares).
    within : str or PathLike, optional
        The folder ``path`` was named from: it must stay inside it, links resolved.

    Returns
    -------
    time_s, azimuth_deg, elevation_deg : (N,) float64
        Seconds, degrees, degrees, row order kept; 1 ≤ N ≤ ``max_rows``.  Values are not
        checked beyond being numbers (NaN stays NaN).

    Raises
    ------
    InvalidInputError
        One line naming the file: another suffix; missing, not a regular file (a FIFO), larger
        than the cap or not UTF-8; a CSV header other than ``time_s,azimuth_deg,elevation_deg``,
        a row that is not three numbers (its line named), no rows, more than ``max_rows``;
        a ``.npy`` that is not an ``(N, 3)`` floating-point array, or declares more bytes than
        ``max_rows`` rows of float64.
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        table = _read_csv(path, max_rows, within)
    elif suffix == ".npy":
        table = _read_npy(path, max_rows, within)
    else:
        raise InvalidInputError(f"{path}: a ray table must be a .csv or a .npy file, got {path.suffix or 'no suffix'!r}")
    if len(table) == 0:
        raise InvalidInputError(f"{path}: the ray table has no rows (one row per pulse: {','.join(RAY_TABLE_COLUMNS)})")
    if len(table) > max_rows:
        raise InvalidInputError(f"{path}: {len(table):,} rows, more than the {max_rows:,} rays a sensor may cast")
    return table[:, 0].copy(), table[:, 1].copy(), table[:, 2].copy()


def _read_csv(path: Path, max_rows: int, within) -> NDArray[np.float64]:
    """The ``(N, 3)`` rows of a CSV ray table, its header checked first."""
    text = read_text_file(path, max_bytes=max_rows * CSV_BYTES_PER_ROW + _CSV_SLACK_BYTES, error=InvalidInputError, within=within)
    first, _, body = text.partition("\n")
    header = tuple(name.strip() for name in first.strip().split(","))
    if header != RAY_TABLE_COLUMNS:
        shown = first.strip()[:80]
        raise InvalidInputError(f"{path}: a ray table's first line must be the header {','.join(RAY_TABLE_COLUMNS)}, got {shown!r}")
    if body.rstrip().count("\n") >= max_rows:  # lines counted before parsing, blank ones among them (not those at the end)
        raise InvalidInputError(f"{path}: more than {max_rows:,} lines after the header, the most rays a sensor may cast")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": an empty table is refused below
            rows = np.loadtxt(io.StringIO(body), delimiter=",", dtype=np.float64, comments=None, ndmin=2, encoding=None)
    except ValueError as exc:  # numpy names the row (0-based after the header) and the column
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0].split(";")[0].rstrip(".")
        raise InvalidInputError(
            f"{path}: not a ray table of three numbers per row ({reason}; rows count from 0 after the header)"
        ) from None
    if rows.size == 0:
        return np.zeros((0, 3))
    if rows.shape[1] != len(RAY_TABLE_COLUMNS):
        raise InvalidInputError(
            f"{path}: each row must hold {len(RAY_TABLE_COLUMNS)} numbers ({','.join(RAY_TABLE_COLUMNS)}), got {rows.shape[1]}"
        )
    return rows


def _read_npy(path: Path, max_rows: int, within) -> NDArray[np.float64]:
    """The ``(N, 3)`` rows of a ``.npy`` ray table: any floating dtype, as float64."""
    array = load_npy(path, max_bytes=max_rows * len(RAY_TABLE_COLUMNS) * 8, error=InvalidInputError, within=within)
    if array.dtype.kind != "f" or array.ndim != 2 or array.shape[1] != len(RAY_TABLE_COLUMNS):
        raise InvalidInputError(
            f"{path}: a ray table .npy must be an (N, 3) floating-point array ({', '.join(RAY_TABLE_COLUMNS)}), "
            f"got shape {array.shape} dtype {array.dtype}"
        )
    return array.astype(np.float64)


def ray_table_bytes(time_s: ArrayLike, azimuth_deg: ArrayLike, elevation_deg: ArrayLike, *, suffix: str = ".csv") -> bytes:
    """A ray table as the bytes of a file :func:`read_ray_table` reads back exactly.

    Parameters
    ----------
    time_s, azimuth_deg, elevation_deg : (N,) float
        Seconds, degrees, degrees.
    suffix : {".csv", ".npy"}
        CSV: the header line, then each value written to 17 significant digits (``%.17g``,
        which reads back to the same float64); ``.npy``: one ``(N, 3)`` float64 array.

    Returns
    -------
    bytes
        Write them with :func:`~zbuf_occlude.io.atomic.write_bytes`.

    Raises
    ------
    InvalidInputError
        Columns of different lengths or not 1-D, or another suffix.
    """
    columns = [np.asarray(c, dtype=np.float64) for c in (time_s, azimuth_deg, elevation_deg)]
    if any(c.ndim != 1 or len(c) != len(columns[0]) for c in columns):
        raise InvalidInputError(f"a ray table's columns must be 1-D and of one length, got shapes {[c.shape for c in columns]}")
    table = np.column_stack(columns) if len(columns[0]) else np.zeros((0, 3))
    suffix = suffix.lower()
    if suffix == ".npy":
        return npy_bytes(table)
    if suffix != ".csv":
        raise InvalidInputError(f"a ray table is written as .csv or .npy, got {suffix!r}")
    buffer = io.StringIO()
    np.savetxt(buffer, table, fmt="%.17g", delimiter=",", header=",".join(RAY_TABLE_COLUMNS), comments="")
    return buffer.getvalue().encode("utf-8")
