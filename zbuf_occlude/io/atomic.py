"""Atomic writes: a reader or a resumed run never sees a partial file.

Data go to a temporary file in the target folder, are flushed and fsynced, then renamed over
the target (``os.replace``).  A failed write (unwritable folder, disk full) raises
:class:`~zbuf_occlude.errors.OutputError` and leaves no temporary file behind; a temporary
file's name says which process on which host owns it, so a resumed run removes only orphans.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import hashlib
import os
import re
import socket
import stat
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from zbuf_occlude.errors import OutputError

__all__ = [
    "atomic_path",
    "new_temp",
    "raise_output_error",
    "atomic_h5",
    "temp_h5",
    "positional_writer",
    "TempOwner",
    "temp_owner",
    "temp_is_orphan",
    "file_sha256",
    "size_mismatch",
    "write_text",
    "write_bytes",
    "write_csv",
]


@functools.lru_cache(maxsize=1)
def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def raise_output_error(path: Path, exc: OSError) -> None:
    """Raise the :class:`~zbuf_occlude.errors.OutputError` that names ``path`` and what to do about ``exc``."""
    if exc.errno == errno.ENOSPC:
        raise OutputError(f"disk full while writing {path}; free space and run again (finished files are kept)") from exc
    if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        raise OutputError(f"cannot write {path}: permission denied; choose a writable --out folder") from exc
    raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc


@functools.lru_cache(maxsize=1)
def _host_tag() -> str:
    # 8 hex digits of the host name: temp names stay short and free of the dots host names hold
    return hashlib.blake2b(socket.gethostname().encode("utf-8", "surrogateescape"), digest_size=4).hexdigest()


#: ``.<target>.<pid>-<host tag>-<random>.tmp``: the temporary files of :func:`atomic_path`.
_TEMP_RE = re.compile(r"^\.(?P<target>.+)\.(?P<pid>\d+)-(?P<host>[0-9a-f]{8})-[^.]*\.tmp$")


#: Temporary files of older versions, ``.<target>.<random>.tmp`` (no owner recorded).
_LEGACY_TEMP_RE = re.compile(r"^\.(?P<target>.+)\.[^.]+\.tmp$")


@dataclass(frozen=True)
class TempOwner:
    """Who wrote a temporary file of :func:`atomic_path` (parsed from its name).

    Attributes
    ----------
    target : str
        Name of the file it was going to become.
    pid : int or None
        Process id of the writer (``None``: a temp of an older version, owner unknown).
    host_tag : str or None
        Hash of the writer's host name (``None`` as above).
    """

    target: str
    pid: int | None
    host_tag: str | None


def temp_owner(name: str) -> TempOwner | None:
    """Parse a temporary file name of :func:`atomic_path`; ``None`` if it is not one."""
    m = _TEMP_RE.match(name)
    if m:
        return TempOwner(m["target"], int(m["pid"]), m["host"])
    m = _LEGACY_TEMP_RE.match(name)
    return TempOwner(m["target"], None, None) if m else None


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def temp_is_orphan(owner: TempOwner) -> bool:
    """True if the process that wrote a temporary file is gone.

    Only a process on this host can be checked; a temp of another host is never an
    orphan here (its writer may be alive on a shared file system).  Temps of older
    versions record no owner and count as orphans: call this only while holding the
    data set's lock.
    """
    if owner.pid is None:
        return True
    return owner.host_tag == _host_tag() and not _pid_alive(owner.pid)


def size_mismatch(files: Sequence[Path], recorded_bytes: int | None) -> str | None:
    """Why ``files`` cannot be the ones a record describes, told from their sizes alone (no byte is
    read); ``None`` when they may be.

    The one check made before any recorded file is hashed: a file swapped for a large or sparse one
    (a 1 TB hole reads as zeros) is refused at once instead of being read in full.

    Parameters
    ----------
    files : sequence of Path
        The files of one record (an object's shard or sample files).
    recorded_bytes : int, optional
        Their total size as recorded; ``None`` (records of older versions): only that each is a
        regular file.
    """
    for file in files:
        if not file.is_file():
            return f"{file} is missing or not a regular file"
    if recorded_bytes is None:
        return None
    total = sum(file.stat().st_size for file in files)
    if total != recorded_bytes:
        named = ", ".join(map(str, files[:3])) + (" ..." if len(files) > 3 else "")
        verb = "holds" if len(files) == 1 else "hold"
        return f"{named} {verb} {total:,} bytes where the record says {recorded_bytes:,}"
    return None


def file_sha256(path: str | os.PathLike, *, chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of a regular file's bytes, read in ``chunk_bytes`` pieces (never whole).

    A piece is no larger than the file (its ``fstat`` size, plus one byte to see the end):
    ``read(n)`` allocates ``n`` bytes first, which for a card or a record of a few hundred bytes
    would be a thousand times what it holds.

    Raises
    ------
    OSError
        The file cannot be opened, or it is not a regular file: a FIFO is opened without
        blocking and refused (``EINVAL``), never waited on; a device is never read without end.
    """
    h = hashlib.sha256()
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as fh:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise OSError(errno.EINVAL, f"{path} is not a regular file (a FIFO, device or folder); not read")
        piece = max(1, min(chunk_bytes, info.st_size + 1))
        while block := fh.read(piece):
            h.update(block)
    return h.hexdigest()


def new_temp(path: str | os.PathLike) -> Path:
    """Create an empty temporary beside ``path`` (its folder made if missing), named
    ``.<name>.<pid>-<host tag>-<random>.tmp`` so that it records its writer (:func:`temp_owner`,
    :func:`temp_is_orphan`), with the mode a plain ``open()`` gives (0666 less the umask;
    ``mkstemp`` makes 0600).

    Raises
    ------
    OutputError
        The folder cannot be created or written, or the disk is full.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}-{_host_tag()}-", suffix=".tmp", dir=path.parent)
        os.close(fd)
        os.chmod(tmp, 0o666 & ~_umask())
    except OSError as exc:
        raise_output_error(path, exc)
    return Path(tmp)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, before_replace: Callable[[Path], None] | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success fsync and rename it to ``path``.

    ``before_replace(tmp)``, when given, runs once the temporary is complete and before it takes
    its name (the owned-folder layer records the file there: :mod:`zbuf_occlude.io.owned`).

    The temporary name, ``.<name>.<pid>-<host tag>-<random>.tmp``, is unique per process and
    records its writer (:func:`temp_owner`), so a cleanup removes only the temps of dead
    processes (:func:`temp_is_orphan`).

    Raises
    ------
    OutputError
        The folder cannot be created or written, or the disk is full.
    """
    path = Path(path)
    tmp_path = new_temp(path)
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as fh:
            os.fsync(fh.fileno())
        if before_replace is not None:
            before_replace(tmp_path)
        os.replace(tmp_path, path)
    except OSError as exc:
        tmp_path.unlink(missing_ok=True)
        raise_output_error(path, exc)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def atomic_h5(path: str | os.PathLike) -> Iterator[Any]:
    """An ``h5py.File`` open for writing at a temporary beside ``path`` (:func:`atomic_path`,
    :func:`temp_h5`)."""
    with atomic_path(path) as tmp, temp_h5(tmp) as f:
        yield f


@contextlib.contextmanager
def temp_h5(tmp: str | os.PathLike) -> Iterator[Any]:
    """An ``h5py.File`` open for writing at ``tmp``, the temporary of an atomic write that is under
    way (:func:`atomic_path`, :meth:`~zbuf_occlude.io.owned.OwnedFolder.write`), which renames it.

    HDF5 reports a full disk in its message, not always in ``errno``: such an error is
    re-raised as ``ENOSPC`` so that :func:`atomic_path` turns it into the disk-full
    :class:`OutputError`, as for every other writer.
    """
    import h5py

    try:
        with h5py.File(tmp, "w") as f:
            yield f
    except OSError as exc:
        if exc.errno is None and "No space left" in str(exc):
            raise OSError(errno.ENOSPC, str(exc)) from exc
        raise


@contextlib.contextmanager
def positional_writer(tmp: str | os.PathLike) -> Iterator[Callable[[int, bytes], None]]:
    """Yield ``write(offset, data)``, which writes ``data`` at byte ``offset`` of ``tmp`` (``os.pwrite``),
    for a temporary of an atomic write that is under way and already holds its layout (a contiguous
    HDF5 dataset made by :func:`temp_h5`, whose rows are then written in any order).

    ``tmp`` is opened without following a link and must be a regular file; an ``OSError`` (a full
    disk) reaches :func:`atomic_path`, which raises :class:`OutputError`.
    """
    fd = os.open(tmp, os.O_WRONLY | getattr(os, "O_NOFOLLOW", 0))
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, f"{tmp} is not a regular file")

        def write(offset: int, data: bytes) -> None:
            view = memoryview(data)
            while view:  # a regular file takes all of it at once, but pwrite may write fewer bytes
                done = os.pwrite(fd, view, offset)
                if done <= 0:
                    raise OSError(errno.ENOSPC, f"no byte written to {tmp}")
                view, offset = view[done:], offset + done

        yield write
    finally:
        os.close(fd)


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (:func:`atomic_path`)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`atomic_path`)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def write_csv(path: str | os.PathLike, rows: Sequence[dict], fieldnames: Sequence[str] | None = None, *, atomic: bool = True) -> Path:
    """Write dict rows as CSV atomically; columns ``fieldnames`` (default: the first row's keys),
    keys outside them are left out.  ``atomic=False``: straight to ``path``, a temporary of the caller's."""
    import csv

    path = Path(path)
    fields = list(fieldnames) if fieldnames is not None else list(rows[0]) if rows else []
    with atomic_path(path) if atomic else contextlib.nullcontext(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    return path
