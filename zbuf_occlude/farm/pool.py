"""The farm's local worker processes: objects run in processes that can be stopped, and that may die.

A native call (Embree, the GL driver, numba) does not return to the interpreter until it is
done, so a SIGTERM sent to a process inside one is handled only afterwards, minutes later
for a slow mesh.  The farm therefore renders in worker processes and the parent only waits:
its wait is interrupted by a signal at once (:func:`~.lifecycle.sigterm_as_interrupt`), and
it stops the workers with SIGTERM (their default action: exit now, wherever they are), then
SIGKILL for one that is still there after :data:`STOP_GRACE_S`.

:class:`concurrent.futures.ProcessPoolExecutor` breaks as a whole when one worker dies
(``BrokenProcessPool`` for every pending object, without saying which object the dead one
held).  Here each worker has its own pipe and the parent knows which object it holds, so a
worker killed by the out-of-memory killer or a signal costs only that object: it is recorded
as failed (the cause in its record), a fresh worker takes the next object, the others finish,
and the run ends with status 1; a rerun redoes the failed object.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import signal
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any

from zbuf_occlude.farm.config import FarmParams
from zbuf_occlude.farm.lifecycle import die_with_parent
from zbuf_occlude.farm.worker import base_record, process_object, write_record
from zbuf_occlude.mesh.inputs.plan import FarmObject
from zbuf_occlude.resources import address_space_limit

__all__ = ["run_in_workers", "STOP_GRACE_S", "worker_death_error"]

log = logging.getLogger(__name__)

#: Seconds a stopped worker gets to exit on SIGTERM before it is sent SIGKILL.
STOP_GRACE_S = 2.0


def _serve(conn: Connection, parent_pid: int, params: FarmParams, out: str, root: str | None) -> None:
    """A worker's loop: receive an object, send back its record (or the fatal error it raised)."""
    die_with_parent(parent_pid)
    # Ctrl-C reaches the whole process group: the parent decides and stops us (SIGTERM).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        try:
            obj = conn.recv()
        except EOFError:  # the parent closed the pipe
            return
        if obj is None:
            return
        try:
            reply: tuple[str, Any] = ("record", process_object(obj, params, out, root))
        except BaseException as exc:  # fatal for the run (OutputError, BackendUnavailable): the parent raises it
            reply = ("error", exc)
        try:
            conn.send(reply)
        except Exception:  # an exception that cannot be pickled: its text still tells why
            conn.send(("error", RuntimeError(f"{type(reply[1]).__name__}: {reply[1]}")))


def worker_death_error(exitcode: int | None) -> str:
    """The record's ``error`` for an object whose worker process died: names the signal, and the
    address-space limit the worker ran under, if any (:func:`_address_space_hint`)."""
    if exitcode is not None and exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        hint = " (the out-of-memory killer sends SIGKILL)" if -exitcode == signal.SIGKILL else ""
        return f"WorkerDied: the worker process was killed by {name}{hint}{_address_space_hint()}"
    return f"WorkerDied: the worker process exited with status {exitcode} without a result{_address_space_hint()}"


def _address_space_hint() -> str:
    """What to try when the workers run under an address-space limit (``ulimit -v``, ``prlimit --as``; they
    inherit ours), else nothing.

    Under such a limit a thread that cannot get its stack or its malloc arena does not raise
    ``MemoryError``: Mesa's llvmpipe crashes (SIGSEGV), glibc aborts ("cannot allocate memory for
    thread-local data", SIGABRT or status 127).  llvmpipe starts two threads per core for each
    GL context and numba one per core, each reserving some 72 MiB of address space (an 8 MiB
    stack and a 64 MiB arena), so on a many-core machine threads alone can fill the limit.
    """
    limit = address_space_limit()
    if limit is None:
        return ""
    return (
        f"; it ran under an address-space limit of {limit / 2**30:.1f} GiB (ulimit -v), which the renderer's and numba's "
        "threads, some per core, count against: raise the limit, or set LP_NUM_THREADS and NUMBA_NUM_THREADS lower"
    )


@dataclass
class _Worker:
    process: multiprocessing.process.BaseProcess
    conn: Connection
    obj: FarmObject | None = None


def _start(ctx, params: FarmParams, out: Path, root: Path | None) -> _Worker:
    mine, theirs = ctx.Pipe()
    args = (theirs, os.getpid(), params, str(out), None if root is None else str(root))
    proc = ctx.Process(target=_serve, args=args, name="zbuf-farm-worker")
    proc.start()
    theirs.close()
    return _Worker(proc, mine)


def _stop(workers: Sequence[_Worker]) -> None:
    for w in workers:
        with contextlib.suppress(Exception):
            w.process.terminate()
    for w in workers:
        w.process.join(STOP_GRACE_S)
        if w.process.is_alive():
            with contextlib.suppress(Exception):
                w.process.kill()
            w.process.join()
        w.conn.close()


def _died(w: _Worker, params: FarmParams, out: Path) -> dict[str, Any]:
    """The failed record of the object a dead worker held (written here: the worker cannot)."""
    w.process.join()
    record = base_record(w.obj, params)
    record.update(status="failed", error=worker_death_error(w.process.exitcode), pid=w.process.pid)
    log.info("object %s (%s) failed: %s", w.obj.index, w.obj.source, record["error"])  # the summary names it
    return write_record(out, w.obj, record)


def run_in_workers(
    todo: Sequence[FarmObject], params: FarmParams, out: Path, workers: int, root: Path | None = None
) -> Iterator[dict[str, Any]]:
    """Yield the record of each object of ``todo``, rendered by ``workers`` worker processes.

    Workers are ``spawn``ed (a forked child would inherit the parent's GL state; each makes
    its own context) and die with the parent (:func:`~.lifecycle.die_with_parent`).  A
    worker that dies (signal, out-of-memory kill, ``os._exit``) fails only the object it
    held (:func:`worker_death_error`); it is replaced by a fresh one.

    Parameters
    ----------
    todo : sequence of FarmObject
    params : FarmParams
    out : Path
        The data set folder (absolute: the workers' working folder is ours, but be explicit).
    workers : int
        Worker processes (at most ``len(todo)`` are started).
    root : Path, optional
        The input root the objects' sources are relative to (:func:`~.worker.process_object`).

    Raises
    ------
    OutputError, BackendUnavailable
        A worker's fatal error (:func:`~.worker.process_object`), raised here.
    KeyboardInterrupt
        (and :class:`~.lifecycle.Terminated`) while waiting: every worker is stopped at once
        (SIGTERM, then SIGKILL after :data:`STOP_GRACE_S`), whatever it is doing; their
        temporary files are removed by the next run and their objects redone.
    """
    ctx = multiprocessing.get_context("spawn")
    queue = list(reversed(todo))
    pool: list[_Worker] = []
    try:
        while queue or any(w.obj is not None for w in pool):
            for w in [w for w in pool if w.obj is None and not w.process.is_alive()]:  # died between objects
                w.conn.close()
                pool.remove(w)
            while queue and len(pool) < workers:
                pool.append(_start(ctx, params, out, root))
            for w in pool:
                if w.obj is None and queue:
                    w.obj = queue.pop()
                    with contextlib.suppress(OSError):  # a worker that just died: its sentinel tells below
                        w.conn.send(w.obj)
            busy = [w for w in pool if w.obj is not None]
            ready = set(wait([w.conn for w in busy] + [w.process.sentinel for w in busy]))
            for w in busy:
                if w.conn in ready or w.process.sentinel in ready:
                    reply = None
                    with contextlib.suppress(EOFError, OSError):
                        if w.conn.poll():  # a worker may send its result and then die: the result counts
                            reply = w.conn.recv()
                    if reply is None:
                        if w.process.is_alive() and w.process.sentinel not in ready:
                            continue
                        record = _died(w, params, out)
                        w.conn.close()
                        pool.remove(w)
                        yield record
                        continue
                    w.obj = None
                    kind, value = reply
                    if kind == "error":
                        raise value
                    yield value
    except BaseException:
        # interrupted (Ctrl-C, SIGTERM), a fatal error, or the consumer stopped: stop the
        # workers now instead of letting them finish their objects
        _stop(pool)
        pool = []
        raise
    finally:
        for w in pool:  # a normal end: every worker is idle and exits on None
            with contextlib.suppress(Exception):
                w.conn.send(None)
        for w in pool:
            w.process.join(STOP_GRACE_S)
        _stop(pool)
