"""The line a first run prints before numba compiles the visibility kernels (a minute or more, once).

numba compiles a kernel the first time a process calls it and keeps the machine code in its on-disk
cache (:mod:`zbuf_occlude.visibility.warmup`, which ``scripts/install.sh`` runs).  After a plain
``pip install`` nothing has compiled them, and the first command that computes visibility is silent
while it does.  :func:`say_if_cold` says so on stderr, from the command line only: the library
stays silent, as libraries do.
"""

from __future__ import annotations

import os
import sys

__all__ = ["VISIBILITY_COMMANDS", "FIRST_RUN_LINE", "interactive", "kernels_cold", "say_if_cold"]

#: The commands that compute visibility on the CPU, and so call the numba kernels.
VISIBILITY_COMMANDS = frozenset({"generate", "validate", "compare", "elevation-profile", "farm", "experiment"})
#: What a first run says on stderr, once, before its work.
FIRST_RUN_LINE = (
    "zbuf-occlude: first run here: numba compiles the visibility kernels (a minute or two, once; later runs "
    "load them from numba's cache; python -m zbuf_occlude.visibility.warmup compiles them ahead)"
)


def kernels_cold() -> bool:
    """True when numba's cache holds no compiled code of the default method's kernels
    (:func:`zbuf_occlude.visibility.warmup.default_method_kernels`), where numba looks for it
    (``$NUMBA_CACHE_DIR``, ``__pycache__`` beside the modules, or the user's cache folder): no
    command has computed visibility with this cache yet, and the next one compiles them for a
    minute or two.  False when one of them is there (a command ran, or the warm-up: which of them
    a view compiles depends on its mesh and pose, and what a later view adds takes seconds), or
    when numba's cache cannot be asked (the line is a courtesy, never an error).

    Kernels compiled only inside others (``inline="always"``) are not asked for: they have no
    entry of their own in the cache.
    """
    try:
        from zbuf_occlude.visibility.warmup import default_method_kernels

        paths = [kernel._cache._cache_file._index_path for kernel in default_method_kernels().values()
                 if kernel._cache is not None and hasattr(kernel._cache, "_cache_file")]  # fmt: skip
    except Exception:  # numba's cache layout is its own: a change there costs the line, not the run
        return False
    return bool(paths) and not any(os.path.isfile(p) for p in paths)


def interactive() -> bool:
    """Whether stderr is a terminal: a person waits on it.  A script, a pipe or a log reads the
    command's own lines only (an error stays one line)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced or closed
        return False


def say_if_cold(command: str) -> bool:
    """Print :data:`FIRST_RUN_LINE` on stderr, when it is a terminal (:func:`interactive`), before a
    command of :data:`VISIBILITY_COMMANDS` whose kernels are not compiled yet
    (:func:`kernels_cold`); True when it printed."""
    if command not in VISIBILITY_COMMANDS or not interactive() or not kernels_cold():
        return False
    print(FIRST_RUN_LINE, file=sys.stderr, flush=True)
    return True
