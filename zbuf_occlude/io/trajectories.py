"""Reading and writing a trajectory file: a CSV of timed poses, its header one of its layouts', parsed into a table of numbers.

:func:`zbuf_occlude.sensors.platform.load_trajectory` checks the values and makes the poses.
"""

from __future__ import annotations

from os import PathLike

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.caps import MAX_TRAJECTORY_BYTES, MAX_TRAJECTORY_LINE_BYTES, MAX_TRAJECTORY_POSES
from zbuf_occlude.io.regular_files import read_text_file

__all__ = ["read_trajectory_table", "trajectory_csv_bytes"]


def read_trajectory_table(path: str | PathLike[str], headers: tuple[tuple[str, ...], ...], *, within: str | PathLike[str] | None = None
                          ) -> tuple[tuple[str, ...], NDArray[np.float64], NDArray[np.int64]]:  # fmt: skip
    """A trajectory CSV's header, rows and line numbers, read whole and parsed (its values are checked by the caller).

    Parameters
    ----------
    path : str or PathLike
    headers : tuple of tuple of str
        The headers a trajectory may have (its layouts' columns).
    within : str or PathLike, optional
        The folder ``path`` was named from: it must stay inside it, links resolved.

    Returns
    -------
    columns : tuple of str
        The file's header, one of ``headers``.
    table : (N, K) float64
        The rows, K the header's columns.
    line_of : (N,) int64
        Each row's line number in the file (blank lines skipped).

    Raises
    ------
    InvalidInputError
        One line naming the file (and the line), never quoting it: what
        :func:`~zbuf_occlude.io.regular_files.read_text_file` refuses (missing, not a regular file,
        over :data:`~zbuf_occlude.io.caps.MAX_TRAJECTORY_BYTES`, not UTF-8); an empty file; more lines
        than :data:`~zbuf_occlude.io.caps.MAX_TRAJECTORY_POSES` (before one is parsed); a line over
        :data:`~zbuf_occlude.io.caps.MAX_TRAJECTORY_LINE_BYTES`; another header; no rows; a row that is
        not the header's width in numbers.
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    text = read_text_file(path, max_bytes=MAX_TRAJECTORY_BYTES, error=InvalidInputError, within=within)
    layouts = " or ".join(",".join(header) for header in headers)
    body = text.removeprefix("\ufeff").rstrip()  # a byte-order mark, as spreadsheets write
    if not body:
        raise InvalidInputError(f"{path}: the file is empty; a trajectory's first line is the header {layouts}")
    if body.count("\n") > MAX_TRAJECTORY_POSES:  # counted before the text is split: a file of short lines stays one string
        raise InvalidInputError(f"{path}: more than {MAX_TRAJECTORY_POSES:,} lines after the header, the most poses a trajectory holds")
    lines = body.split("\n")
    # a character takes at least a byte: a line of more characters than the cap is longer in bytes too
    long = next((i for i, line in enumerate(lines) if len(line) + 1 > MAX_TRAJECTORY_LINE_BYTES), None)
    if long is not None:
        raise InvalidInputError(f"{path}: line {long + 1:,} is longer than {MAX_TRAJECTORY_LINE_BYTES:,} bytes; a row is a few numbers")
    columns = tuple(field.strip() for field in lines[0].split(","))
    if columns not in headers:
        raise InvalidInputError(f"{path}: line 1 must be the header {layouts}; it holds {len(columns)} other fields")
    rows = [(number, line.strip()) for number, line in enumerate(lines[1:], start=2) if line.strip()]
    if not rows:
        raise InvalidInputError(f"{path}: no rows after the header (one row per pose: {','.join(columns)})")
    line_of, data = np.array([number for number, _ in rows], dtype=np.int64), [line for _, line in rows]
    try:
        table = np.loadtxt(data, delimiter=",", dtype=np.float64, comments=None, ndmin=2)
    except ValueError:  # numpy's words quote the line: the line is found again, by Python's float, and only its number shown
        table = np.array([_row(path, line, number, len(columns)) for number, line in zip(line_of, data, strict=True)])
    if table.shape != (len(data), len(columns)):  # every row of one other width
        raise InvalidInputError(f"{path}: line {line_of[0]:,} holds {table.shape[1]} numbers; each row holds {len(columns)}")
    return columns, table, line_of


def _row(path: str | PathLike[str], line: str, number: int, width: int) -> list[float]:
    """The ``width`` numbers of ``line`` (line ``number`` of the file), separated by commas, or InvalidInputError naming the line."""
    try:
        row = [float(field) for field in line.split(",")]
    except ValueError:
        row = []
    if len(row) == width:
        return row
    raise InvalidInputError(f"{path}: line {number:,} is not a row of {width} numbers separated by commas")


def trajectory_csv_bytes(columns: tuple[str, ...], table: NDArray[np.float64]) -> bytes:
    """The bytes of a trajectory CSV that :func:`read_trajectory_table` reads back to the same numbers: the header
    ``columns``, then one line per row of ``table (N, K) float64``, each number as Python's shortest repr of it
    (a float64 round-trips exactly).

    Raises
    ------
    InvalidInputError
        ``table`` not (N, K) with K the header's width and 1 ≤ N ≤ :data:`~zbuf_occlude.io.caps.MAX_TRAJECTORY_POSES`,
        or not finite.
    """
    a = np.asarray(table, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != len(columns) or not 1 <= len(a) <= MAX_TRAJECTORY_POSES or not np.all(np.isfinite(a)):
        raise InvalidInputError(
            f"a trajectory table must be 1 to {MAX_TRAJECTORY_POSES:,} finite rows of {len(columns)} numbers, got shape {a.shape}"
        )
    lines = [",".join(columns), *(",".join(repr(float(v)) for v in row) for row in a)]
    return ("\n".join(lines) + "\n").encode("utf-8")
