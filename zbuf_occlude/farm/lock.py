"""One writer per data set: the lock a farm run, a ``--shard`` task or a merge holds on ``--out``.

The lock is :func:`zbuf_occlude.io.locks.acquire_lock`'s :class:`filelock.SoftFileLock`, a file created with ``O_CREAT | O_EXCL`` that holds
the owner's pid, host name and process start token.  Unlike ``flock``/``fcntl`` locks it works
on the network file systems clusters share (NFS, Lustre, GPFS), where advisory locks may be
missing or local to one node.  filelock removes a lock whose owner is a dead process on the
same host (a run killed with SIGKILL); a lock of another host is never broken automatically
(its owner may be alive there): the error names the host, pid and start time, and says which
file to delete once that process is known to be gone.

Scopes (:func:`farm_lock`):

* a whole run (``--shard 0/1``), ``farm-merge`` and ``generate`` hold the data-set lock
  ``DATASET/.zbuf_occlude.lock`` and refuse while any task lock is held;
* a ``--shard I/N`` task holds only ``DATASET/tasks/lock-I-of-N.lock``, so the tasks of one
  SLURM array run at once, and refuses while the data-set lock is held.

Each side takes its own lock first and then looks at the other's, so of two runs that start
at the same instant at least one sees the other.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

from zbuf_occlude.dataset.layout import LOCK_FILE, TASK_DIR, task_lock_name
from zbuf_occlude.errors import DatasetBusy
from zbuf_occlude.io.locks import acquire_lock

__all__ = ["DatasetBusy", "farm_lock", "task_lock_path"]


def task_lock_path(out: Path, shard: tuple[int, int]) -> Path:
    """The lock of ``--shard I/N`` task ``shard`` in data set ``out``."""
    return out / task_lock_name(*shard)


def _refuse_if_held(path: Path, what: str) -> None:
    # taking and dropping the lock at once also breaks it if its owner died
    if path.exists():
        acquire_lock(path, what).release()


@contextlib.contextmanager
def farm_lock(out: str | os.PathLike, shard: tuple[int, int] = (0, 1)) -> Iterator[Path]:
    """Hold the lock of data set ``out`` (or of one ``--shard I/N`` task) for the ``with`` block.

    Parameters
    ----------
    out : str or PathLike
        The data set folder (must exist).
    shard : (I, N)
        ``(0, 1)``: the whole data set (a run, a merge); else the lock of task ``I`` of ``N``.

    Yields
    ------
    path : Path
        The lock file held.

    Raises
    ------
    DatasetBusy
        A live process holds this lock, the data-set lock (for a task) or a task lock (for
        the whole data set); the message names its pid, host and start time.
    OutputError
        The lock file cannot be created.
    """
    out = Path(out)
    dataset_path = out / LOCK_FILE
    whole = shard[1] == 1
    if whole:
        lock = acquire_lock(dataset_path, f"the data set {out}")
    else:
        lock = acquire_lock(task_lock_path(out, shard), f"task {shard[0]}/{shard[1]} of {out}")
    try:
        if whole:
            for task in sorted((out / TASK_DIR).glob("lock-*.lock")):
                _refuse_if_held(task, f"the data set {out} (task {task.stem[5:].replace('-of-', '/')})")
        else:
            _refuse_if_held(dataset_path, f"the data set {out}")
        yield Path(lock.lock_file)
    finally:
        lock.release()
