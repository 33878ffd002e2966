"""The lock a writer holds on a folder: one writer at a time, a dead writer's lock taken over.

The lock is a :class:`filelock.SoftFileLock`, a file created with ``O_CREAT | O_EXCL`` that holds
the owner's pid and host name.  Unlike ``flock``/``fcntl`` locks it works on the network file
systems clusters share (NFS, Lustre, GPFS).  filelock breaks the lock of a dead process of this
host and, after watching it unchanged for 2 s, a malformed one; an acquire keeps trying long
enough for that whatever the load (:data:`ACQUIRE_TIMEOUT_S`).  An empty or unreadable lock file
older than :data:`ABANDONED_MARKER_AGE_S` (a writer killed before it wrote its pid) is removed
first.  A lock file that is a link, a FIFO, a folder or larger than a lock (:data:`~zbuf_occlude.io.caps.MAX_LOCK_BYTES`) is
refused, never read nor broken.  A lock of another host is never broken (its owner may be alive there): the error names
the host and pid and says which file to delete once that process is known to be gone.
"""

from __future__ import annotations

import logging
import os
import stat
from pathlib import Path

from zbuf_occlude.errors import DatasetBusy, OutputError, UnsafePathError, ZbufOccludeError
from zbuf_occlude.io.caps import MAX_LOCK_BYTES
from zbuf_occlude.io.regular_files import read_text_file

__all__ = ["LOCK_FILE", "ACQUIRE_TIMEOUT_S", "acquire_lock"]

log = logging.getLogger(__name__)

#: The lock file of an owned folder (a farm's ``--shard`` tasks add their own under ``tasks/``).
LOCK_FILE = ".zbuf_occlude.lock"
#: Seconds an acquire keeps trying: longer than filelock watches a malformed lock before it
#: breaks it (2 s), with room for a loaded machine's sparse polls (at 2 s the two ran out together,
#: and a garbage lock was refused under load where a quiet machine took it over); long enough for
#: a dead owner's lock to be broken or a concurrent peek to end; short enough to refuse soon.
ACQUIRE_TIMEOUT_S = 5.0
#: Seconds after which a lock file that names no process is abandoned (:func:`_break_abandoned_marker`).
ABANDONED_MARKER_AGE_S = 30.0
POLL_INTERVAL_S = 0.05


def _lock_holder(path: Path) -> str:
    """``pid P on host H since T`` of the process holding lock file ``path`` (what it says)."""
    from datetime import datetime, timezone

    try:
        lines = read_text_file(path, max_bytes=MAX_LOCK_BYTES, errors="replace").splitlines()
        since = datetime.fromtimestamp(path.stat().st_mtime, timezone.utc).isoformat(timespec="seconds")
    except (OSError, ZbufOccludeError):
        return "a process that has just released it"
    pid = lines[0] if lines and lines[0].isdigit() else "?"
    host = lines[1] if len(lines) > 1 else "?"
    return f"pid {pid} on host {host} since {since}"


def _break_abandoned_marker(path: Path) -> None:
    """Remove a lock file that names no process and has not changed for :data:`ABANDONED_MARKER_AGE_S`.

    filelock breaks a dead owner's lock itself (it reads the pid and host, and swaps the marker
    out only if it is still the one it read), and a malformed one once it has watched it unchanged
    for 2 s.  An *empty* marker it takes for a holder's and never breaks: a writer killed between
    creating the file and writing its pid leaves one for good.  A live writer fills its marker
    within microseconds of creating it, so an empty or unreadable marker that old is abandoned.
    The marker is removed only if it is still that file (same inode and modification time).
    """
    import time

    try:
        before = path.lstat()
        lines = read_text_file(path, max_bytes=MAX_LOCK_BYTES, errors="replace").splitlines()
    except (OSError, ZbufOccludeError):  # gone, or not a lock of ours (too large): filelock judges it
        return
    if lines and lines[0].strip().isdigit() or time.time() - before.st_mtime < ABANDONED_MARKER_AGE_S:
        return  # a holder's pid (filelock's to judge), or a marker a writer may still be filling
    try:
        now = path.lstat()
        if (now.st_ino, now.st_mtime_ns) == (before.st_ino, before.st_mtime_ns):
            log.info("removing the abandoned lock %s (no process named in it for %.0f s)", path, time.time() - now.st_mtime)
            path.unlink()
    except OSError:
        return


def _check_lock_kind(path: Path) -> None:
    """Refuse a lock file that is a link, a FIFO, a device or a folder, or larger than any lock of
    ours: reading a FIFO would block every command on the folder, a link would make the lock
    another file, and a large file at the lock's name is someone's data, which filelock would
    break (delete) as a malformed lock after watching it for 2 s."""
    try:
        info = path.lstat()
    except OSError:
        return  # released meanwhile
    mode = info.st_mode
    if not stat.S_ISREG(mode):
        kind = (
            "a link"
            if stat.S_ISLNK(mode)
            else "a FIFO"
            if stat.S_ISFIFO(mode)
            else "a folder"
            if stat.S_ISDIR(mode)
            else "not a regular file"
        )
        raise UnsafePathError(f"the lock file {path} is {kind}, not a lock of ours; move it away and run again")
    if info.st_size > MAX_LOCK_BYTES:
        raise UnsafePathError(
            f"the lock file {path} holds {info.st_size:,} bytes, more than the {MAX_LOCK_BYTES} of a lock of ours (a pid "
            "and a host name); it is not one: move it away and run again"
        )


def acquire_lock(path: str | os.PathLike, what: str, *, timeout: float = ACQUIRE_TIMEOUT_S):
    """Take the lock file ``path``; return the held :class:`filelock.SoftFileLock` (``release()`` it).

    Raises
    ------
    UnsafePathError
        The lock file is a link, a FIFO, a device or a folder (never opened, so never blocks), or
        larger than a lock of ours (never read, nor deleted).
    DatasetBusy
        A live process holds it (named: pid and host), or one of another host that cannot be
        checked from here; the message says which file to delete once it is known to be gone.
    OutputError
        The lock file cannot be created.
    """
    from filelock import SoftFileLock, Timeout

    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create {path.parent}: {exc.strerror or exc}; choose a writable --out") from None
    if os.path.lexists(path):
        _check_lock_kind(path)
        _break_abandoned_marker(path)
    lock = SoftFileLock(str(path), timeout=timeout, poll_interval=POLL_INTERVAL_S, is_singleton=False, thread_local=False)
    try:
        lock.acquire()
    except Timeout:
        raise DatasetBusy(
            f"{what} is being written by {_lock_holder(path)} (lock file {path}); wait for it to finish, "
            f"or, if that process is gone (another host cannot be checked from here), delete {path} and run again"
        ) from None
    except OSError as exc:
        raise OutputError(f"cannot create the lock file {path}: {exc.strerror or exc}; choose a writable --out") from None
    return lock
