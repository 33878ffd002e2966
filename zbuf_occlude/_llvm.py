"""Mesa's LLVM and another copy of LLVM in one process, without a crash in any order.

The mechanism.  Mesa's EGL (and OSMesa, and pyrender's EGL platform, and any moderngl context a
program makes itself) loads the llvmpipe driver with ``RTLD_GLOBAL``, which puts the ``libLLVM``
it links into the process's global symbol scope.  Triton's ``libtriton.so`` -- PyPI's default
PyTorch brings Triton, and ``torch.compile`` and ``torch.use_deterministic_algorithms`` import
it, with the CUDA build and the CPU build alike -- carries its own LLVM and exports its
symbols.  The dynamic linker resolves a library's symbols in the global scope first, so a
``libtriton.so`` loaded after Mesa's LLVM has its own LLVM calls bound to Mesa's LLVM of another
version, and its static constructors die with SIGSEGV (``LD_DEBUG=bindings`` shows
``libtriton.so`` bound to ``libLLVM-15.so.1``).

The fix, at that root: ``libtriton.so`` is loaded with ``RTLD_DEEPBIND``, which makes it look
up symbols in itself and its own dependencies before the global scope, so it binds to its own
LLVM whether Mesa's is already loaded or not.  :func:`install` (run by ``import zbuf_occlude``)
puts a finder on ``sys.meta_path`` that does this load just before Python first imports
``triton`` -- and does nothing else: no library is loaded at import, so ``import zbuf_occlude``
stays cheap, and a program that never imports Triton never pays for it (about 60 ms and 100 MB
of relocated pages).  Python's own import of the extension then finds the library loaded.

What stays out of reach: a program that makes a Mesa context *and* imports Triton, both before
it imports zbuf_occlude, crashes before any of our code runs; import zbuf_occlude (or Triton)
before making an OpenGL context of your own.
"""

from __future__ import annotations

import ctypes
import importlib.abc
import importlib.machinery
import logging
import os
import sys
import threading
from pathlib import Path

__all__ = ["LLVM_BUNDLES", "install", "load_bundle"]

log = logging.getLogger(__name__)

#: Python packages whose native library carries its own LLVM with exported symbols, and that
#: library's path inside the package: loaded with ``RTLD_DEEPBIND`` before the package's import.
LLVM_BUNDLES: dict[str, tuple[str, ...]] = {"triton": ("_C", "libtriton.so")}

#: ``dlopen`` flags of a bundle: resolved now, kept out of the global scope, bound to itself first.
_FLAGS = os.RTLD_NOW | os.RTLD_LOCAL | getattr(os, "RTLD_DEEPBIND", 0)

_loaded: set[str] = set()
_lock = threading.Lock()


def load_bundle(package: str) -> bool:
    """Load ``package``'s LLVM-carrying library (:data:`LLVM_BUNDLES`) with ``RTLD_DEEPBIND``,
    without importing the package; once per process.

    Returns
    -------
    bool
        True when the library is loaded now or was loaded earlier by this function; False when
        the package or its library is not installed, or the library cannot be loaded (a broken
        install of that package is its own problem: its import then fails in its own words).
    """
    with _lock:
        if package in _loaded:
            return True
        try:
            # the path finder alone: finds without importing, and without asking sys.meta_path (this module's finder)
            spec = importlib.machinery.PathFinder.find_spec(package)
        except (ImportError, ValueError):
            return False
        if spec is None or not spec.submodule_search_locations:
            return False
        library = Path(next(iter(spec.submodule_search_locations)), *LLVM_BUNDLES[package])
        if not library.is_file():
            return False
        try:
            ctypes.CDLL(str(library), mode=_FLAGS)
        except OSError as exc:
            log.debug("could not load %s: %s", library, exc)
            return False
        _loaded.add(package)
        return True


class _BundleFinder(importlib.abc.MetaPathFinder):
    """Loads a bundle's library (:func:`load_bundle`) when its package is first imported, then
    lets the normal finders import it (``find_spec`` always returns None)."""

    def find_spec(self, fullname, path=None, target=None):  # noqa: ARG002 (the finder protocol)
        if fullname in LLVM_BUNDLES and fullname not in _loaded:
            load_bundle(fullname)
        return None


_FINDER = _BundleFinder()


def install() -> None:
    """Put the finder first on ``sys.meta_path`` (once); a bundle already imported is left as it is."""
    if all(name in sys.modules for name in LLVM_BUNDLES):
        return
    if not any(isinstance(f, _BundleFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _FINDER)
