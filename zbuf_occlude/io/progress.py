"""Progress of the long commands on stderr: a tqdm bar on a terminal, one line at a time in a log.

Every command that runs longer than a few seconds (``generate``, ``farm``, ``farm-merge``, the
experiments, ``compare``, ``elevation-profile``, the protocols, ``scan``, ``verify``) reports
through :func:`progress`:

- stderr is a terminal, a pseudo-terminal included (``script``, ``ssh``, tmux, an editor's
  terminal): a tqdm bar, redrawn in place, as wide as the terminal; where the terminal does not
  say its size (a pseudo-terminal that nobody sized says 0 × 0, from which tqdm draws nothing)
  ``$COLUMNS`` × ``$LINES``, else :data:`FALLBACK_COLUMNS` × :data:`FALLBACK_LINES`;
- stderr is a file or a pipe: :class:`LineProgress`, a tqdm whose every update is one
  newline-terminated line (``generate: 12/40 obj, 3.10 obj/s, ETA 00:09, 00:04 elapsed``), at
  most one every :data:`PROGRESS_INTERVAL_S` seconds (all bars together), and one more when a
  bar that stays (``leave=True``) closes; never a carriage return;
- ``enabled=False`` (the commands' ``--no-progress``): nothing.

Either way the rate, and the ETA that follows from it, count from the moment the first item of
the run was done (:class:`RateAfterFirst`): the first item carries the start-up (a worker
process starting, numba loading or compiling its kernels, an Embree scene built), so a rate
that counted it would promise minutes for a job of seconds.  Until a second item is done the
rate and the ETA are unknown and not shown; the elapsed time counts from the start.

The interval can be set with the environment variable :data:`PROGRESS_INTERVAL_ENV` (seconds,
≥ 0; 0 writes a line on every update).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from typing import Any

from tqdm.std import tqdm

from zbuf_occlude.errors import InvalidInputError

__all__ = [
    "progress", "LineProgress", "RateAfterFirst", "progress_interval_s", "PROGRESS_INTERVAL_S", "PROGRESS_INTERVAL_ENV",
    "FALLBACK_COLUMNS", "FALLBACK_LINES",
]  # fmt: skip

#: Seconds between two progress lines in a log: often enough to see a run move, rare enough that a
#: day-long farm writes a few thousand lines.
PROGRESS_INTERVAL_S = 10.0
#: Environment variable that overrides :data:`PROGRESS_INTERVAL_S` (seconds).
PROGRESS_INTERVAL_ENV = "ZBUF_OCCLUDE_PROGRESS_INTERVAL_S"
#: Width of the bar, in characters, on a terminal that does not say its own (0 columns) and
#: without ``$COLUMNS``: the width terminals open with.
FALLBACK_COLUMNS = 80
#: Height, in lines, of such a terminal without ``$LINES`` (tqdm draws no bar below the last line).
FALLBACK_LINES = 24


def progress_interval_s() -> float:
    """Seconds between two progress lines: :data:`PROGRESS_INTERVAL_ENV` if set, else :data:`PROGRESS_INTERVAL_S`.

    Raises
    ------
    InvalidInputError
        The variable is not a number ≥ 0.
    """
    text = os.environ.get(PROGRESS_INTERVAL_ENV, "").strip()
    if not text:
        return PROGRESS_INTERVAL_S
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value >= 0 or value == float("inf"):
        raise InvalidInputError(f"{PROGRESS_INTERVAL_ENV}={text!r}: give the seconds between two progress lines, a number >= 0")
    return value


def _stderr_is_terminal() -> bool:
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError):  # no stderr (pythonw), or a closed one
        return False


def _stderr_size() -> tuple[int, int]:
    """The terminal on stderr's ``(columns, lines)``; 0 for what it does not say (an unsized pseudo-terminal)."""
    try:
        size = os.get_terminal_size(sys.stderr.fileno())
    except (AttributeError, ValueError, OSError):  # no file descriptor (a replaced stderr), or not a terminal
        return 0, 0
    return max(size.columns, 0), max(size.lines, 0)


def _from_environ(name: str, fallback: int) -> int:
    try:
        value = int(os.environ.get(name, ""))
    except ValueError:
        return fallback
    return value if value > 0 else fallback


def _bar_shape() -> dict[str, Any]:
    """tqdm's size options for a bar on the terminal on stderr: follow its size where it says it,
    else ``$COLUMNS`` and ``$LINES``, or :data:`FALLBACK_COLUMNS` and :data:`FALLBACK_LINES`.
    A pseudo-terminal nobody sized says 0 × 0, from which tqdm would draw a bar of no characters
    on no line (nothing at all)."""
    columns, lines = _stderr_size()
    if columns and lines:
        return {"dynamic_ncols": True}
    return {"ncols": columns or _from_environ("COLUMNS", FALLBACK_COLUMNS), "nrows": lines or _from_environ("LINES", FALLBACK_LINES)}


class RateAfterFirst(tqdm):
    """A tqdm whose rate (and so its ETA) leaves out the time to the first item of the run.

    The rate is the items done after the first one over the time since the first one was
    counted (the mean, no smoothing); 0, which tqdm shows as ``?``, until then.  Items counted
    by iterating the bar are seen when the bar is next drawn (tqdm calls no :meth:`update` for
    them), so the time from the first item to that drawing is left out too.
    """

    #: ``(time, n)`` when the first item of this run was counted; None before.
    _first: tuple[float, float] | None = None

    def update(self, n: float | None = 1) -> bool | None:
        if self._first is None and n and not self.disable:
            self._first = (self._time(), self.n + n)
        return super().update(n)

    def reset(self, total: float | None = None) -> None:
        self._first = None
        super().reset(total)

    def rate_after_first(self) -> float:
        """Items per second since the first item of this run was counted; 0 while unknown."""
        if self._first is None:
            if getattr(self, "n", 0) > getattr(self, "initial", 0):  # counted by iteration: first seen now
                self._first = (self._time(), self.n)
            return 0.0
        t_first, n_first = self._first
        dt = self._time() - t_first
        return (self.n - n_first) / dt if self.n > n_first and dt > 0 else 0.0

    @property
    def format_dict(self) -> dict[str, Any]:
        return {**super().format_dict, "rate": self.rate_after_first()}


class LineProgress(RateAfterFirst):
    """A tqdm that writes newline-terminated lines to its ``file`` instead of redrawing a bar.

    A line at most every ``mininterval`` seconds, counted across every :class:`LineProgress`
    (so that nested or successive bars, such as one per training epoch, do not multiply the
    lines), none when it opens, and a last one when it closes if it was made with ``leave=True``
    and its last line does not already say so.
    Its rate is :class:`RateAfterFirst`'s, counting only what was done in this run
    (``initial`` excluded), and the ETA follows from it.
    """

    #: ``time.time()`` of the last line any LineProgress wrote.
    _last_line_t = 0.0

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._opening = True  # tqdm's __init__ displays the bar once: not here
        self._stays = kwargs.get("leave", True)
        self._shown_n: float | None = None  # n at this bar's last line
        kwargs.update(miniters=1, smoothing=0, leave=False, dynamic_ncols=False)
        super().__init__(*args, **kwargs)
        self._opening = False
        if not self.disable:
            if not LineProgress._last_line_t:  # the first bar of the process: its first line comes after an interval
                LineProgress._last_line_t = self.start_t
            # the interval runs from the last line of any bar (never from a time to come: a clock set back)
            self.last_print_t = min(LineProgress._last_line_t, self.start_t)

    def display(self, msg: str | None = None, pos: int | None = None) -> bool:
        if self._opening or msg == "":  # tqdm opening or clearing a bar: nothing to show or clear in a log
            return False
        self.fp.write((self.line() if msg is None else msg) + "\n")
        self.fp.flush()
        self._shown_n = self.n
        LineProgress._last_line_t = self._time()
        return True

    def line(self) -> str:
        """The progress as one line: ``desc: done/total unit, rate unit/s (or s/unit), ETA [h:]mm:ss, elapsed, postfix``
        (no rate and no ETA before a second item is done)."""
        d = self.format_dict
        n, total, unit, elapsed, rate = d["n"], d["total"], d["unit"], d["elapsed"], d["rate"]
        parts = [f"{n}/{total} {unit}" if total else f"{n} {unit}"]
        if rate > 0:
            # as tqdm's bar: seconds per item when slower than one a second
            parts.append(f"{self.format_sizeof(rate)} {unit}/s" if rate >= 1 else f"{self.format_sizeof(1 / rate)} s/{unit}")
            if total and n < total:
                parts.append(f"ETA {self.format_interval((total - n) / rate)}")
        parts.append(f"{self.format_interval(elapsed)} elapsed")
        if d["postfix"]:
            parts.append(d["postfix"])
        return f"{d['prefix']}: " + ", ".join(parts) if d["prefix"] else ", ".join(parts)

    def close(self) -> None:
        if not self.disable and self._stays and self._shown_n != self.n and getattr(self, "sp", None) is not None:
            with self._lock:
                self.display()
        super().close()


def progress(
    iterable: Iterable | None = None,
    *,
    total: int | None = None,
    desc: str,
    unit: str = "it",
    enabled: bool = True,
    leave: bool = True,
    initial: int = 0,
    interval_s: float | None = None,
) -> tqdm:
    """A progress bar on stderr that suits where stderr goes (module docstring).

    Parameters
    ----------
    iterable : iterable, optional
        Wrapped as by tqdm: iterating the bar iterates it and counts each item.
    total : int, optional
        Items expected (default: ``len(iterable)`` where it has one).
    desc : str
        Name at the start of the bar or line, such as the command's name.
    unit : str
        What one item is (``"obj"``, ``"batch"``).
    enabled : bool
        False (``--no-progress``): a tqdm that shows nothing; so is the bar where there is no
        stderr (``sys.stderr`` is None).
    leave : bool
        Whether the bar stays when it closes; in a log, whether it writes a last line.
    initial : int
        Items done before this run (a resumed farm); not counted in the rate.
    interval_s : float, optional
        Seconds between two lines in a log (default: :func:`progress_interval_s`).

    Returns
    -------
    tqdm
        Use it as any tqdm (``update``, ``set_postfix``, ``close``, a ``with`` block).

    Raises
    ------
    InvalidInputError
        :data:`PROGRESS_INTERVAL_ENV` is set to something other than seconds ≥ 0.
    """
    common = dict(total=total, desc=desc, unit=unit, leave=leave, initial=initial, file=sys.stderr)
    if not enabled or sys.stderr is None:  # no stderr (closed, pythonw): nowhere to show it
        return tqdm(iterable, disable=True, **common)
    if _stderr_is_terminal():
        return RateAfterFirst(iterable, **_bar_shape(), **common)  # the bar, redrawn in place
    return LineProgress(iterable, mininterval=progress_interval_s() if interval_s is None else interval_s, **common)
