"""The lock a writer holds on a folder: one writer at a time, a dead writer's lock taken over.

The lock is a :class:`filelock.SoftFileLock`, a file created with ``O_CREAT | O_EXCL`` that holds
the owner's pid and host name.  Unlike ``flock``/``fcntl`` locks it works on the network file
systems clusters share (NFS, Lustre, GPFS).  A lock whose owner is known to be gone (a dead
process of this host, or a file that names no process at all: garbage, or empty because its
writer was killed before it wrote) is removed before the first try, whatever the load; a lock of
another host is never broken (its owner may be alive there): the error names the host and pid
and says which file to delete once that process is known to be gone.
"""

from __future__ import annotations

import logging
import os
import socket
from pathlib import Path

from zbuf_occlude.errors import DatasetBusy, OutputError

__all__ = ["LOCK_FILE", "ACQUIRE_TIMEOUT_S", "acquire_lock"]

log = logging.getLogger(__name__)

#: The lock file of an owned folder (a farm's ``--shard`` tasks add their own under ``tasks/``).
LOCK_FILE = ".zbuf_occlude.lock"
#: Seconds an acquire keeps trying: long enough for filelock to break a dead owner's lock
#: (checked on each try) or for a concurrent peek to end, short enough to refuse at once.
ACQUIRE_TIMEOUT_S = 2.0
POLL_INTERVAL_S = 0.05


def _lock_holder(path: Path) -> str:
    """``pid P on host H since T`` of the process holding lock file ``path`` (what it says)."""
    from datetime import datetime, timezone

    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
        since = datetime.fromtimestamp(path.stat().st_mtime, timezone.utc).isoformat(timespec="seconds")
    except OSError:
        return "a process that has just released it"
    pid = lines[0] if lines and lines[0].isdigit() else "?"
    host = lines[1] if len(lines) > 1 else "?"
    return f"pid {pid} on host {host} since {since}"


def _break_dead_lock(path: Path) -> None:
    """Remove a lock file whose owner is known to be gone: a dead process of this host, or a
    file that names no process at all (garbage, empty: a writer killed before it wrote its pid).

    filelock breaks a dead owner's lock only when it can parse the file, and checks it only
    while it polls; under load a damaged lock file was refused where a quiet machine took it
    over.  This decides it once, before the first try.
    """
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return
    pid = int(lines[0]) if lines and lines[0].strip().isdigit() else None
    host = lines[1].strip() if len(lines) > 1 else None
    if pid is not None and host not in (None, socket.gethostname()):
        return  # another host's: its owner may be alive there
    if pid is not None:
        try:
            os.kill(pid, 0)
            return  # alive (or someone else's live process)
        except ProcessLookupError:
            pass
        except PermissionError:
            return
    log.info("removing the lock %s of a process that is gone", path)
    path.unlink(missing_ok=True)


def acquire_lock(path: str | os.PathLike, what: str, *, timeout: float = ACQUIRE_TIMEOUT_S):
    """Take the lock file ``path``; return the held :class:`filelock.SoftFileLock` (``release()`` it).

    Raises
    ------
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
        _break_dead_lock(path)
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
