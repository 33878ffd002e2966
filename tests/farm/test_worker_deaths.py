"""farm.pool.worker_death_error: what a failed object's record says when its worker process died."""

from __future__ import annotations

import resource
import signal

import pytest
from memory_limit import run_python_limited

from zbuf_occlude.farm.pool import worker_death_error

_UNLIMITED = resource.getrlimit(resource.RLIMIT_AS)[0] == resource.RLIM_INFINITY


@pytest.mark.skipif(not _UNLIMITED, reason="this test process runs under an address-space limit")
def test_a_death_names_the_signal_or_the_status_and_nothing_more_without_a_limit() -> None:
    assert worker_death_error(-signal.SIGSEGV) == "WorkerDied: the worker process was killed by SIGSEGV"
    assert (
        worker_death_error(-signal.SIGKILL)
        == "WorkerDied: the worker process was killed by SIGKILL (the out-of-memory killer sends SIGKILL)"
    )
    assert worker_death_error(127) == "WorkerDied: the worker process exited with status 127 without a result"


@pytest.mark.slow
def test_under_an_address_space_limit_a_death_names_the_limit_and_the_thread_counts_to_lower() -> None:
    # llvmpipe's threads that cannot get their stacks crash the worker (SIGSEGV), glibc aborts (status 127): no MemoryError says why
    done = run_python_limited(
        "import signal\nfrom zbuf_occlude.farm.pool import worker_death_error\n"
        "print(worker_death_error(-signal.SIGSEGV))\nprint(worker_death_error(127))"
    )
    assert done.returncode == 0, done.stderr[-2000:]
    limit_gib = f"{done.limit_bytes / 2**30:.1f} GiB"
    for line, start in zip(
        done.stdout.splitlines(), ("killed by SIGSEGV; it ran", "exited with status 127 without a result; it ran"), strict=True
    ):
        assert start in line and f"under an address-space limit of {limit_gib} (ulimit -v)" in line, line
        assert line.endswith("raise the limit, or set LP_NUM_THREADS and NUMBA_NUM_THREADS lower"), line
