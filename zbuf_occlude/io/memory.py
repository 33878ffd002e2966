"""Memory checked before the work, wherever the size of a user's input sets an allocation.

A file, a record or an argument declares a size (a cloud's points, a shard's rows, a ledger's
lines); what it makes us allocate is known before the first byte is allocated.  Checking it then
turns what would be a ``MemoryError`` halfway through (or the OOM killer) into one line that names
the input and the memory it would need.  :func:`check_memory` is the check every reader of a
user's input calls; it compares with :func:`zbuf_occlude.resources.available_memory`: the least of
``MemAvailable`` (``/proc/meminfo``), the room under a cgroup memory limit, and the address space
left under ``RLIMIT_AS`` (``ulimit -v``, a batch scheduler's limit) less what is mapped now
(``VmSize``).  Sizes below :data:`~zbuf_occlude.resources.MIN_CHECKED_BYTES` are not checked
(reading ``/proc`` costs more than they risk); where the memory available is unknown, nothing is
refused.
"""

from __future__ import annotations

from zbuf_occlude.resources import check_memory as _check_estimate

__all__ = ["check_memory"]

#: What to do, when the caller says nothing more precise.
DEFAULT_HINT = "use a smaller input, or run where more memory is available"


def check_memory(need_bytes: int, what: str, *, hint: str | None = None) -> None:
    """Refuse, before allocating, work on ``what`` that needs more memory than is available.

    Parameters
    ----------
    need_bytes : int
        Bytes the work would allocate at its peak (an estimate from the sizes the input declares).
    what : str
        The input that sets the size, for the message: the file or the argument and its value
        (``"the cloud chair.ply (9,900,000 points)"``).
    hint : str, optional
        What to do (default :data:`DEFAULT_HINT`).

    Raises
    ------
    InsufficientMemoryError
        ``need_bytes`` is more than the memory available; one line naming ``what``, the memory it
        needs and the memory available (and where that figure comes from).
    """
    _check_estimate(int(need_bytes), option=what, hint=hint or DEFAULT_HINT)
