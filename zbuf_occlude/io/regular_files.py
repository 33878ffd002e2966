"""Files whose names come from a user or from another file: regular files only, sizes checked first.

A user names a cloud or a scan, a mesh names its buffers and textures, a folder of scans names
its files.  Every such file is opened here, so that one set of rules holds:

* only a **regular file** is read.  A FIFO, a socket or a device would block the reader
  forever (a FIFO) or read without end (``/dev/zero``).  The file is opened with
  ``O_NONBLOCK`` (opening a FIFO for reading then returns at once instead of waiting for a
  writer), and its type is checked on the open file (``fstat``), so a name swapped between a
  check and the open cannot slip through;
* its **size is checked before it is read**, against the cap the caller names for what it reads
  (every cap is in :mod:`zbuf_occlude.io.caps`: :data:`~zbuf_occlude.io.caps.MAX_LIST_BYTES` for
  text lists, :data:`~zbuf_occlude.io.caps.MAX_METADATA_BYTES` for JSON metadata, ...); the error
  names the file, its size and the cap;
* when the caller names the folder the file was found in (``within=``), the file must still
  lie **inside that folder once links are resolved**: a list, a shard or a ``shape_names.txt``
  that is a symlink to a file elsewhere is refused
  (:class:`~zbuf_occlude.errors.UnsafePathError`, naming both).

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

from zbuf_occlude.errors import InvalidInputError, UnsafePathError, ZbufOccludeError

__all__ = [
    "check_within", "file_digest", "open_regular_file", "read_at_most", "read_regular_file", "read_text_file", "regular_file_size",
]  # fmt: skip

#: Bytes read at a time when a file is hashed (bounded memory, whatever the file's size).
_HASH_CHUNK_BYTES = 1 << 20
#: Bytes read at a time from a file that grew after it was opened (its new size is unknown).
_GROWTH_CHUNK_BYTES = 1 << 20


def _nonblocking(name: str, flags: int) -> int:
    # O_NONBLOCK: opening a FIFO for reading returns at once instead of waiting for a writer.
    return os.open(name, flags | getattr(os, "O_NONBLOCK", 0))


def check_within(path: str | PathLike[str], within: str | PathLike[str]) -> Path:
    """``path``, after checking that it lies inside the folder ``within`` once links are resolved.

    Parameters
    ----------
    path : str or PathLike
        A file found in (or named from) ``within``.
    within : str or PathLike
        The folder the file was named from (a data set, a point set's folder, a source).

    Returns
    -------
    Path
        ``path`` resolved (every link followed): open this one, not ``path``.

    Raises
    ------
    UnsafePathError
        ``path``, or a folder on the way to it, is a link that leads outside ``within``, or it
        cannot be resolved (a link loop); the message names both.
    """
    try:
        real, root = Path(path).resolve(), Path(within).resolve()
    except (OSError, RuntimeError) as exc:  # a link loop (RuntimeError before Python 3.13)
        raise UnsafePathError(f"{path}: cannot be resolved inside {within} ({exc})") from None
    if real != root and root not in real.parents:
        raise UnsafePathError(f"{path} leads outside {within} (to {real}, through a link); refused")
    return real


def open_regular_file(
    path: str | PathLike[str],
    *,
    max_bytes: int | None = None,
    error: type[ZbufOccludeError] = InvalidInputError,
    within: str | PathLike[str] | None = None,
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
    within : str or PathLike, optional
        The folder ``path`` was named from: it must stay inside it, links resolved
        (:func:`check_within`).

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
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    path = Path(path)
    target = path if within is None else check_within(path, within)
    try:
        fh = open(target, "rb", opener=_nonblocking)  # noqa: SIM115 - closed by the callers
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
    path: str | PathLike[str],
    *,
    max_bytes: int,
    error: type[ZbufOccludeError] = InvalidInputError,
    within: str | PathLike[str] | None = None,
) -> bytes:
    """The bytes of ``path``, when it is a regular file of at most ``max_bytes`` bytes.

    Parameters
    ----------
    path : str or PathLike
    max_bytes : int
        The cap, checked against the file's size before anything is read: the one of
        :mod:`zbuf_occlude.io.caps` named for the file read (no default).
    error : type
        The exception raised (:class:`~zbuf_occlude.errors.MeshLoadError` for meshes,
        :class:`~zbuf_occlude.errors.InvalidInputError` or a subclass for scans and clouds).

    within : str or PathLike, optional
        The folder ``path`` was named from (:func:`check_within`).

    Returns
    -------
    bytes
        The whole file.

    Raises
    ------
    ``error``
        Naming the file: missing, unreadable, not a regular file (a FIFO would block), or
        larger than ``max_bytes`` (both numbers given).
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    fh, size = open_regular_file(path, max_bytes=max_bytes, error=error, within=within)
    with fh:
        data = read_at_most(fh, size, max_bytes)
    if len(data) > max_bytes:
        raise error(f"{path}: more than the {max_bytes:,} bytes a file read here may have")
    return data


def read_at_most(fh: BinaryIO, size: int, max_bytes: int) -> bytes:
    """The rest of the open file ``fh``, reserving memory for what it holds, never for the cap.

    ``fh.read(n)`` allocates ``n`` bytes before it reads one, so reading "up to the cap" reserves
    the cap (gigabytes for a 6-byte file), which fails under an address-space limit (``ulimit -v``,
    a batch scheduler's memory limit).  This reads ``size + 1`` bytes (the size ``fstat`` gave
    when the file was opened), then, only if the file grew since, the rest in chunks of
    :data:`_GROWTH_CHUNK_BYTES`, stopping once more than ``max_bytes`` were read.

    Parameters
    ----------
    fh : binary file
        Open, positioned where reading starts.
    size : int
        The bytes it held when opened (``os.fstat``), at most ``max_bytes``.
    max_bytes : int
        The cap.

    Returns
    -------
    bytes
        At most ``max_bytes + 1`` bytes: more than ``max_bytes`` means the file grew past the cap
        (the caller refuses it).
    """
    parts = [fh.read(min(size, max_bytes) + 1)]
    read = len(parts[0])
    if read > size:  # it grew after fstat: go on in bounded chunks, never past the cap
        while read <= max_bytes and (chunk := fh.read(min(_GROWTH_CHUNK_BYTES, max_bytes + 1 - read))):
            parts.append(chunk)
            read += len(chunk)
    return parts[0] if len(parts) == 1 else b"".join(parts)


def read_text_file(
    path: str | PathLike[str],
    *,
    max_bytes: int,
    error: type[ZbufOccludeError] = InvalidInputError,
    within: str | PathLike[str] | None = None,
    errors: str = "strict",
) -> str:
    """The UTF-8 text of ``path`` (a list, a lock, a table), read by :func:`read_regular_file`'s rules.

    Parameters
    ----------
    path : str or PathLike
    max_bytes : int
        The cap (:data:`~zbuf_occlude.io.caps.MAX_LIST_BYTES` for a list), checked before anything is read.
    error : type
        The exception raised, as for :func:`read_regular_file`.
    within : str or PathLike, optional
        The folder ``path`` was named from (:func:`check_within`).
    errors : str
        How undecodable bytes are handled (``"strict"``: refused, naming the file;
        ``"replace"``: U+FFFD, for text only shown to a person, such as a lock's holder).

    Returns
    -------
    str
        The whole file, decoded.

    Raises
    ------
    ``error``
        As :func:`read_regular_file`, or the bytes are not UTF-8 (with ``errors="strict"``).
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    data = read_regular_file(path, max_bytes=max_bytes, error=error, within=within)
    try:
        return data.decode("utf-8", errors)
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text (byte {exc.start}); refused") from None


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
