"""Process lifecycle of a farm run: SIGTERM as an interrupt, workers that die with their parent.

A farm parent killed with SIGKILL cannot tell its workers anything, and one stopped with
SIGTERM used to die without stopping them: the workers (~250 MB each) went on rendering and
writing records for minutes.  Here

* every pool worker asks the kernel to kill it when its parent dies
  (``prctl(PR_SET_PDEATHSIG, SIGKILL)`` on Linux, through :mod:`ctypes`) and, on every
  system, runs a watchdog thread that exits the process once its parent id changes (the
  orphan was adopted by init or a subreaper);
* the parent turns SIGTERM into :class:`Terminated`, a :class:`KeyboardInterrupt`, so a
  batch scheduler's stop is handled like Ctrl-C: the pool's workers are stopped, the
  manifest of what finished is written, the lock is released, and the same command
  resumes.  The CLI exits 130 after SIGINT and 143 (128 + 15) after SIGTERM.

A worker killed mid-write leaves only a temporary file named by its pid, which the next run
removes (:func:`~zbuf_occlude.farm.journal.remove_stale_temps`); the parent records its
object as failed (:mod:`zbuf_occlude.farm.pool`) and the next run does it again.  The
parent only waits while its workers render, so a signal reaches it at once even when a
worker is inside a long native call (Embree, the GL driver), which in-process it would not.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import logging
import os
import signal
import sys
import threading
from collections.abc import Iterator

__all__ = ["Terminated", "sigterm_as_interrupt", "die_with_parent", "PARENT_POLL_S"]

log = logging.getLogger(__name__)

#: Seconds between the watchdog's looks at the parent id (a worker outlives its parent by at most this).
PARENT_POLL_S = 0.5
#: ``PR_SET_PDEATHSIG`` of ``<linux/prctl.h>``.
_PR_SET_PDEATHSIG = 1


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived: stop like Ctrl-C (exit status 128 + ``signum``)."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__(f"terminated by signal {signum}")
        self.signum = int(signum)


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` in the main thread.

    Does nothing outside the main thread (Python delivers signals to it only) or when a
    handler other than the default one is already installed (an embedding program's).
    """
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        yield
        return

    def handler(signum, frame):
        raise Terminated(signum)

    signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _set_pdeathsig(sig: int) -> bool:
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent_pid: int) -> None:
    stop = threading.Event()
    while not stop.wait(PARENT_POLL_S):
        if os.getppid() != parent_pid:
            os._exit(1)  # no cleanup: the next run removes our temporary files


def die_with_parent(parent_pid: int) -> None:
    """Pool-worker initializer: end this process soon after ``parent_pid`` is gone.

    Parameters
    ----------
    parent_pid : int
        The farm parent's pid (``os.getpid()`` there, passed as ``initargs``).
    """
    _set_pdeathsig(signal.SIGKILL)
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)
    threading.Thread(target=_watch, args=(parent_pid,), name="zbuf-parent-watchdog", daemon=True).start()
