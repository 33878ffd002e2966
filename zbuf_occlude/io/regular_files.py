"""Files whose names come from a user or from another file: regular files only, sizes checked first.

A user names a cloud or a scan, a mesh names its buffers and textures, a folder of scans names
its files.  Every such file is opened here, so that one set of rules holds:

* only a **regular file** is read.  A FIFO, a socket or a device would block the reader
  forever (a FIFO) or read without end (``/dev/zero``).  The file is opened with
  ``O_NONBLOCK`` (opening a FIFO for reading then returns at once instead of waiting for a
  writer), and its type is checked on the open file (``fstat``), so a name swapped between a
  check and the open cannot slip through;
* its **size is checked before it is read**, against a cap the caller gives (the error names
  the file, its size and the cap).

Each function takes the ``error`` class it raises, so that a mesh reader raises
:class:`~zbuf_occlude.errors.MeshLoadError` and a scan or cloud reader
:class:`~zbuf_occlude.errors.InvalidInputError` (or a subclass); every message names the file
in one line.
"""

from __future__ import annotations

import hashlib
import os
import stat
from os import PathLike
from pathlib import Path
from typing import BinaryIO

from zbuf_occlude.errors import InvalidInputError, ZbufOccludeError

__all__ = ["MAX_NAMED_FILE_BYTES", "file_digest", "open_regular_file", "read_regular_file", "regular_file_size"]

#: Largest file :func:`read_regular_file` reads unless given another cap: 2 GiB, the most a
#: mesh may name (a glTF buffer, an OBJ material, a texture).  glTF buffers are addressed with
#: 32-bit byte lengths and a GLB is at most 4 GiB by its uint32 length field; a buffer larger
#: than this is not an object's mesh.
MAX_NAMED_FILE_BYTES = 2 << 30
#: Bytes read at a time when a file is hashed (bounded memory, whatever the file's size).
_HASH_CHUNK_BYTES = 1 << 20


def _nonblocking(name: str, flags: int) -> int:
    # O_NONBLOCK: opening a FIFO for reading returns at once instead of waiting for a writer.
    return os.open(name, flags | getattr(os, "O_NONBLOCK", 0))


def open_regular_file(
    path: str | PathLike[str], *, max_bytes: int | None = None, error: type[ZbufOccludeError] = InvalidInputError
) -> tuple[BinaryIO, int]:
    """``path`` opened for reading in binary, when it is a regular file (of at most ``max_bytes``).

    The one opener of this module's rules (module docstring): opened without blocking, its type
    checked on the open file, its size checked before a byte is read.

    Parameters
    ----------
    path : str or PathLike
    max_bytes : int, optional
        The cap on the file's size (default: none).
    error : type
        The exception raised (:class:`~zbuf_occlude.errors.MeshLoadError` for meshes,
        :class:`~zbuf_occlude.errors.InvalidInputError` or a subclass for scans and clouds).

    Returns
    -------
    file : binary file
        Open: the caller closes it (``with file:``).
    size : int
        The file's size in bytes when it was opened.

    Raises
    ------
    ``error``
        Naming the file: missing, unreadable, a FIFO, socket, device or folder, or larger than
        ``max_bytes`` (both numbers given).
    """
    path = Path(path)
    try:
        fh = open(path, "rb", opener=_nonblocking)  # noqa: SIM115 - closed by the callers
    except OSError as exc:
        raise error(f"{path}: cannot read file ({exc.strerror or exc})") from None
    info = os.fstat(fh.fileno())
    if not stat.S_ISREG(info.st_mode):
        fh.close()
        kind = "a FIFO" if stat.S_ISFIFO(info.st_mode) else "a folder" if stat.S_ISDIR(info.st_mode) else "not a regular file"
        raise error(f"{path}: is {kind}; only regular files are read")
    if max_bytes is not None and info.st_size > max_bytes:
        fh.close()
        raise error(f"{path}: {info.st_size:,} bytes, more than the {max_bytes:,} a file read here may have")
    return fh, int(info.st_size)


def regular_file_size(path: str | PathLike[str], *, error: type[ZbufOccludeError] = InvalidInputError) -> int:
    """Bytes of ``path``, checking that it is a regular file (without reading it).

    Parameters
    ----------
    path : str or PathLike
    error : type
        The exception raised (:class:`~zbuf_occlude.errors.MeshLoadError` for meshes,
        :class:`~zbuf_occlude.errors.InvalidInputError` or a subclass for scans and clouds).

    Returns
    -------
    int
        The file's size in bytes.

    Raises
    ------
    ``error``
        Naming the file: missing, unreadable, or a FIFO, socket, device or folder.
    """
    fh, size = open_regular_file(path, error=error)
    fh.close()
    return size


def read_regular_file(
    path: str | PathLike[str], *, max_bytes: int = MAX_NAMED_FILE_BYTES, error: type[ZbufOccludeError] = InvalidInputError
) -> bytes:
    """The bytes of ``path``, when it is a regular file of at most ``max_bytes`` bytes.

    Parameters
    ----------
    path : str or PathLike
    max_bytes : int
        The cap, checked against the file's size before anything is read.
    error : type
        The exception raised (:class:`~zbuf_occlude.errors.MeshLoadError` for meshes,
        :class:`~zbuf_occlude.errors.InvalidInputError` or a subclass for scans and clouds).

    Returns
    -------
    bytes
        The whole file.

    Raises
    ------
    ``error``
        Naming the file: missing, unreadable, not a regular file (a FIFO would block), or
        larger than ``max_bytes`` (both numbers given).
    """
    fh, _ = open_regular_file(path, max_bytes=max_bytes, error=error)
    with fh:
        data = fh.read(max_bytes + 1)  # the file may grow after fstat: never read past the cap
    if len(data) > max_bytes:
        raise error(f"{path}: more than the {max_bytes:,} bytes a file read here may have")
    return data


def file_digest(path: str | PathLike[str], *, max_bytes: int, error: type[ZbufOccludeError] = InvalidInputError) -> str:
    """MD5 hex digest of a regular file of at most ``max_bytes``, read in 1 MiB chunks (never whole).

    Parameters
    ----------
    path : str or PathLike
    max_bytes : int
        The cap, checked against the file's size before the first byte is hashed.
    error : type
        The exception raised, as for :func:`read_regular_file`.

    Returns
    -------
    str
        32 lowercase hex digits.

    Raises
    ------
    ``error``
        As :func:`read_regular_file`.
    """
    fh, _ = open_regular_file(path, max_bytes=max_bytes, error=error)
    with fh:
        digest = hashlib.md5(usedforsecurity=False)
        while chunk := fh.read(_HASH_CHUNK_BYTES):
            digest.update(chunk)
    return digest.hexdigest()
