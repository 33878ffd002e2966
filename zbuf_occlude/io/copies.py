"""A file copied from a folder we read into one we write: the source by the reading layer's rules, the target atomically.

``farm-merge`` copies the shards of task folders into ``--out``.  A task folder may be shared or
crafted: its shard may be a FIFO (a plain copy would block), or a link to any file on the machine
(whose bytes would land in the merged data set).  :func:`copy_regular_file` opens the source as
:func:`~zbuf_occlude.io.regular_files.open_regular_file` does (a regular file, inside the folder
it was named from once links are resolved) and writes the copy through
:func:`~zbuf_occlude.io.atomic.atomic_path`, so a reader never sees half a file.
"""

from __future__ import annotations

import shutil
from os import PathLike
from pathlib import Path

from zbuf_occlude.errors import InvalidInputError, ZbufOccludeError
from zbuf_occlude.io.atomic import atomic_path
from zbuf_occlude.io.regular_files import open_regular_file

__all__ = ["copy_regular_file"]

#: Bytes copied at a time: memory stays bounded whatever the file's size.
_COPY_CHUNK_BYTES = 1 << 20


def copy_regular_file(
    source: str | PathLike[str],
    target: str | PathLike[str],
    *,
    within: str | PathLike[str],
    error: type[ZbufOccludeError] = InvalidInputError,
) -> Path:
    """Copy the bytes of ``source``, a regular file inside ``within``, to ``target`` (atomically).

    Parameters
    ----------
    source : str or PathLike
        The file to copy, named from the folder ``within``.
    target : str or PathLike
        Where the copy goes (its folder is made; an existing file is replaced whole).
    within : str or PathLike
        The folder ``source`` was named from: it must stay inside it, links resolved.
    error : type
        The exception raised for a source that cannot be read.

    Returns
    -------
    Path
        ``target``.

    Raises
    ------
    ``error``
        Naming ``source``: missing, unreadable, or not a regular file (a FIFO, a folder).
    UnsafePathError
        ``source`` leads outside ``within``.
    OutputError
        ``target`` cannot be written (:func:`~zbuf_occlude.io.atomic.atomic_path`).
    """
    fh, _ = open_regular_file(source, error=error, within=within)
    with fh, atomic_path(target) as tmp, open(tmp, "wb") as out:
        shutil.copyfileobj(fh, out, _COPY_CHUNK_BYTES)
    return Path(target)
