"""Load GLSL sources from ``shaders/`` by name.

The sources live in the top-level ``shaders/`` folder of a checkout; a wheel ships them as
``zbuf_occlude/shaders`` (pyproject's force-include).  Both places are searched, the
installed one first.  A line ``//#include NAME`` is replaced by that file's text.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path

from zbuf_occlude.errors import BackendUnavailable

__all__ = ["shader_dirs", "load_shader"]

_INCLUDE = re.compile(r"^//#include\s+(\S+)\s*$", re.MULTILINE)


def shader_dirs() -> list[Path]:
    """Folders searched for shaders: the installed package's, then the checkout's."""
    package = Path(__file__).resolve().parents[1]
    return [d for d in (package / "shaders", package.parent / "shaders") if d.is_dir()]


@functools.lru_cache(maxsize=None)
def load_shader(name: str, defines: tuple[tuple[str, int | float], ...] = ()) -> str:
    """The GLSL source of ``shaders/NAME`` with its ``//#include`` lines expanded and
    ``#define KEY VALUE`` lines for ``defines`` inserted after ``#version``.

    Raises
    ------
    BackendUnavailable
        The file is in none of :func:`shader_dirs` (a broken install).
    """
    for folder in shader_dirs():
        path = folder / name
        if path.is_file():
            text = _INCLUDE.sub(lambda m: load_shader(m.group(1)), path.read_text(encoding="utf-8"))
            if defines:
                version, _, body = text.partition("\n")
                text = "\n".join([version, *(f"#define {k} {v}" for k, v in defines), body])
            return text
    raise BackendUnavailable(f"shader {name!r} not found in {[str(d) for d in shader_dirs()] or 'any folder'}; reinstall zbuf-occlude")
