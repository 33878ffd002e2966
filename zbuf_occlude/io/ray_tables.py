"""Ray tables from anyone: a ``(time, azimuth, elevation)`` row per pulse, as CSV or ``.npy``.

A non-repetitive scanner (Livox's rosette, DJI L2) or a hybrid solid-state unit is described by
the directions it fires in, in order, with each pulse's time.  Two file formats:

* **CSV**: a header line ``time_s,azimuth_deg,elevation_deg`` (those three names, in that order;
  spaces around them allowed), then one row per pulse of three numbers separated by commas.
  Blank lines are skipped (but count towards the cap on rows, except those at the end); nothing
  else (comments, quotes, other columns) is accepted.  The file is opened by
  :func:`~zbuf_occlude.io.regular_files.open_regular_file` (a regular file, at most
  :data:`CSV_BYTES_PER_ROW` bytes per row allowed) and read :data:`CSV_BLOCK_BYTES` at a time,
  each line at most :data:`~zbuf_occlude.io.caps.MAX_RAY_TABLE_LINE_BYTES` long and UTF-8, each block's rows parsed by numpy:
  a file of one endless line, or of more rows than the cap, is refused after a block, never held
  whole;
* **NumPy** ``.npy``: one ``(N, 3)`` floating-point array, columns in that order, read by
  :func:`~zbuf_occlude.io.arrays.load_npy` (its header's declared size checked against the row
  cap before the body is allocated, nothing unpickled).

Only the format is checked here (the columns, numbers, the number of rows); what the numbers
mean (finite, time non-decreasing, elevations within ±90°) is checked by the sensor that takes
them, :class:`~zbuf_occlude.sensors.patterns.ray_table.RayTable`.  Every error is one line naming the
file (and, in a CSV, the line).
"""

from __future__ import annotations

import io
import re
import warnings
from os import PathLike
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.geometry.arguments import described
from zbuf_occlude.io.arrays import load_npy
from zbuf_occlude.io.caps import MAX_RAY_TABLE_LINE_BYTES
from zbuf_occlude.io.encodings import npy_bytes
from zbuf_occlude.io.regular_files import open_regular_file

__all__ = [
    "CSV_BLOCK_BYTES", "CSV_BYTES_PER_ROW", "RAY_TABLE_COLUMNS", "RAY_TABLE_SUFFIXES", "ray_table_bytes",
    "read_ray_table",
]  # fmt: skip

#: The columns of a ray table, in file order: seconds, degrees, degrees.
RAY_TABLE_COLUMNS = ("time_s", "azimuth_deg", "elevation_deg")
#: The file suffixes read (lower case).
RAY_TABLE_SUFFIXES = (".csv", ".npy")
#: Bytes a CSV row may take on average, for the file's size cap: three float64 written to round
#: trip (``%.17g``: at most 24 characters each) and their separators take at most 76.
CSV_BYTES_PER_ROW = 96
#: Room for the header line and blank lines on top of the rows' bytes.
_CSV_SLACK_BYTES = 4096
#: Bytes of a CSV read and parsed at a time: about 25,000 rows, so that what is held beside the
#: rows read so far is a few MiB whatever the file holds.
CSV_BLOCK_BYTES = 1 << 20
#: Lines numpy skips: empty ones (a lone carriage return is the end of a CRLF line).
_BLANK_LINES = ("", "\r")
#: The column in numpy's reason ("could not convert string '...' to float64 at row R, column C"): the
#: only part of it shown, the quoted text being the file's.
_NUMPY_COLUMN = re.compile(r"at row \d+, column (\d+)")


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
    ArgumentTypeError
        ``path`` or ``within`` is not a path, or ``max_rows`` not a whole number >= 1.
    InvalidInputError
        One line naming the file: another suffix; missing, not a regular file (a FIFO), larger
        than the cap; a CSV line longer than :data:`~zbuf_occlude.io.caps.MAX_RAY_TABLE_LINE_BYTES` or not UTF-8, a header
        other than ``time_s,azimuth_deg,elevation_deg``, a row that is not three numbers (each
        naming its line), no rows, more than ``max_rows``; a ``.npy`` that is not an ``(N, 3)``
        floating-point array, or declares more bytes than ``max_rows`` rows of float64.
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    if not isinstance(path, (str, PathLike)):
        raise ArgumentTypeError(f"path must be a ray table's path (str or os.PathLike), got {described(path)}")
    if within is not None and not isinstance(within, (str, PathLike)):
        raise ArgumentTypeError(f"within must be a folder's path (str or os.PathLike) or None, got {described(within)}")
    if isinstance(max_rows, bool) or not isinstance(max_rows, (int, np.integer)) or max_rows < 1:
        raise ArgumentTypeError(f"max_rows must be a whole number >= 1, got {described(max_rows)}")
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
    """The ``(N, 3)`` rows of a CSV ray table, its header checked first, read a block of lines at a time."""
    fh, _ = open_regular_file(path, max_bytes=max_rows * CSV_BYTES_PER_ROW + _CSV_SLACK_BYTES, error=InvalidInputError, within=within)
    parts: list[NDArray[np.float64]] = []
    with fh:
        first_line, header = 1, None
        for lines in _csv_blocks(fh, path):
            if header is None:
                header, lines = lines[0], lines[1:]
                _check_header(path, header)
                first_line = 2
            parts.extend(_csv_rows(path, lines, first_line, max_rows))
            first_line += len(lines)
        if header is None:
            _check_header(path, "")
    rows = sum(len(part) for part in parts)
    return np.concatenate(parts) if rows else np.zeros((0, 3))


def _csv_blocks(fh: BinaryIO, path: Path):
    """The file's lines, a list per :data:`CSV_BLOCK_BYTES` read (a CRLF line keeps its ``\\r``), each line checked for
    its length (:data:`~zbuf_occlude.io.caps.MAX_RAY_TABLE_LINE_BYTES`, before more is read) and for UTF-8."""
    pending, line = b"", 1
    while True:
        block = fh.read(CSV_BLOCK_BYTES)
        data = pending + block
        cut = data.rfind(b"\n") + 1  # the whole lines; after them, the start of the next (or the last, unended)
        ends = np.flatnonzero(np.frombuffer(data[:cut], np.uint8) == ord("\n"))
        long = np.flatnonzero(np.diff(ends, prepend=-1) > MAX_RAY_TABLE_LINE_BYTES)
        if len(long) or len(data) - cut > MAX_RAY_TABLE_LINE_BYTES:
            at = line + (int(long[0]) if len(long) else len(ends))
            raise InvalidInputError(f"{path}: line {at:,} is longer than {MAX_RAY_TABLE_LINE_BYTES:,} bytes; a ray table's rows are "
                                    f"three numbers ({','.join(RAY_TABLE_COLUMNS)})")  # fmt: skip
        whole, pending = (data[:cut], data[cut:]) if block else (data, b"")
        if whole:
            try:
                text = whole.decode("utf-8")
            except UnicodeDecodeError as exc:
                at = line + whole.count(b"\n", 0, exc.start)
                raise InvalidInputError(f"{path}: line {at:,} is not UTF-8 text; refused") from None
            lines = text.split("\n")
            if text.endswith("\n"):
                lines.pop()  # the empty piece after the last line end
            line += len(lines)
            yield lines
        if not block:
            return


def _check_header(path: Path, first: str) -> None:
    """Refuse a first line other than the three column names (spaces around them allowed), without quoting it."""
    header = tuple(name.strip() for name in first.strip().split(","))
    if header != RAY_TABLE_COLUMNS:
        found = "the file is empty" if not first.strip() else f"line 1 holds {len(header)} other fields"
        if len(header) == len(RAY_TABLE_COLUMNS) and set(header) == set(RAY_TABLE_COLUMNS):
            found = "line 1 names them in another order"
        raise InvalidInputError(f"{path}: a ray table's first line must be the header {','.join(RAY_TABLE_COLUMNS)}; {found}")


def _csv_rows(path: Path, lines: list[str], first_line: int, max_rows: int) -> list[NDArray[np.float64]]:
    """The rows of ``lines`` (the first is line ``first_line`` of the file) as an ``(n, 3)`` array, or none if all are blank."""
    last = len(lines) - 1
    while last >= 0 and lines[last] in _BLANK_LINES:
        last -= 1
    if last < 0:
        return []
    if first_line + last - 1 > max_rows:  # lines after the header, blank ones among them (not those at the end)
        raise InvalidInputError(f"{path}: more than {max_rows:,} lines after the header, the most rays a sensor may cast")
    rows = _parsed(lines[: last + 1])
    if isinstance(rows, np.ndarray) and rows.shape[1] == len(RAY_TABLE_COLUMNS):
        return [rows]
    # the first line that breaks the block: the longest prefix that parses is found by halving
    good, bad = 0, last + 1
    while bad - good > 1:
        middle = (good + bad) // 2
        parsed = _parsed(lines[:middle])
        good, bad = (middle, bad) if isinstance(parsed, np.ndarray) and parsed.shape[1] in (0, len(RAY_TABLE_COLUMNS)) else (good, middle)
    at, alone = first_line + good, _parsed([lines[good]])
    if isinstance(alone, np.ndarray) and alone.shape[1] != len(RAY_TABLE_COLUMNS):
        raise InvalidInputError(f"{path}: line {at:,} holds {alone.shape[1]} numbers; each row must hold "
                                f"{len(RAY_TABLE_COLUMNS)} ({','.join(RAY_TABLE_COLUMNS)})")  # fmt: skip
    detail = f" ({alone})" if isinstance(alone, str) and alone else ""  # the column numpy names, if it does
    raise InvalidInputError(f"{path}: line {at:,} is not a row of three numbers separated by commas{detail}")


def _parsed(lines: list[str]) -> NDArray[np.float64] | str:
    """``lines`` parsed by numpy as rows of comma-separated numbers (``(n, k)``, ``(0, 0)`` if all are blank), or where
    numpy refused them: ``"column C is not a number"``, or ``""`` (numpy's own words quote the file, so they are not kept)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": all blank
            rows = np.loadtxt(lines, delimiter=",", dtype=np.float64, comments=None, ndmin=2, encoding=None)
    except ValueError as exc:
        column = _NUMPY_COLUMN.search(str(exc))
        return f"column {column.group(1)} is not a number" if column else ""
    return rows if rows.size else np.zeros((0, 0))


def _read_npy(path: Path, max_rows: int, within) -> NDArray[np.float64]:
    """The ``(N, 3)`` rows of a ``.npy`` ray table: any floating dtype, as float64."""
    array = load_npy(path, max_bytes=max_rows * len(RAY_TABLE_COLUMNS) * 8, error=InvalidInputError, within=within)
    if array.dtype.kind != "f" or array.ndim != 2 or array.shape[1] != len(RAY_TABLE_COLUMNS):
        raise InvalidInputError(
            f"{path}: a ray table .npy must be an (N, 3) floating-point array ({', '.join(RAY_TABLE_COLUMNS)}), "
            f"got shape {array.shape} dtype {array.dtype.name}"  # the name: a structured dtype's str() holds its fields' names
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
