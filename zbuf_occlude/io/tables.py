"""CSV tables read back (an experiment's ``results.csv``, a cached curve): one reader.

The file is read by :func:`~zbuf_occlude.io.regular_files.read_text_file`'s rules (a regular
file, inside the folder it was named from when the caller knows it, at most
:data:`~zbuf_occlude.io.caps.MAX_TABLE_BYTES`, UTF-8) and parsed in memory by :class:`csv.DictReader`; a file that is
not a CSV table is one line naming it.
"""

from __future__ import annotations

import csv
import io
import os

from zbuf_occlude.errors import InvalidInputError, ZbufOccludeError
from zbuf_occlude.io.caps import MAX_TABLE_BYTES
from zbuf_occlude.io.regular_files import read_text_file

__all__ = ["read_csv_rows"]


def read_csv_rows(
    path: str | os.PathLike,
    *,
    within: str | os.PathLike | None = None,
    max_bytes: int = MAX_TABLE_BYTES,
    error: type[ZbufOccludeError] = InvalidInputError,
) -> list[dict[str, str]]:
    """The rows of a CSV file with a header line, as :class:`csv.DictReader` gives them.

    Parameters
    ----------
    path : str or PathLike
    within : str or PathLike, optional
        The folder ``path`` was named from (a run's output folder): it must stay inside it,
        links resolved.
    max_bytes : int
        The cap on the file's size (:data:`~zbuf_occlude.io.caps.MAX_TABLE_BYTES`), checked before a byte is read.
    error : type
        The exception raised for a file that cannot be read or parsed.

    Returns
    -------
    list of dict
        One per line after the header, ``column -> text`` (a short line's missing columns are
        ``None``, as :class:`csv.DictReader` gives them).

    Raises
    ------
    ``error``
        The file is missing, not a regular file (a FIFO), larger than ``max_bytes``, not
        UTF-8, or not CSV (a field longer than :func:`csv.field_size_limit`); the message
        names it.
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    text = read_text_file(path, max_bytes=max_bytes, error=error, within=within)
    try:
        return list(csv.DictReader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise error(f"{path}: not a CSV table ({exc})") from None
