"""The GLSL sources of the renderer and the visibility passes, loaded by name.

The files sit beside this module and ship in the wheel as package data (as pyrender's
``pyrender/shaders``); they are read through :mod:`importlib.resources`, so an installed copy
reads its own files, never a checkout's.  A line ``//#include NAME`` is replaced by that file's
text; every shader gets the constants of :mod:`zbuf_occlude.render.bindings` (binding points,
work-group size) as ``#define`` lines after its ``#version`` line.
"""

from __future__ import annotations

import functools
import importlib.resources
import re
from typing import TYPE_CHECKING

from zbuf_occlude.errors import BackendUnavailable
from zbuf_occlude.render.bindings import SHADER_DEFINES

if TYPE_CHECKING:
    from importlib.resources.abc import Traversable

__all__ = ["load_shader", "shader_dir"]

_INCLUDE = re.compile(r"^//#include\s+(\S+)\s*$", re.MULTILINE)


def shader_dir() -> Traversable:
    """The folder of the GLSL files: this package's own (a checkout's or an install's)."""
    return importlib.resources.files(__name__)


@functools.cache
def _expanded(name: str) -> str:
    """``NAME``'s text with its ``//#include`` lines replaced by the included files' text."""
    path = shader_dir().joinpath(name)
    if not path.is_file():
        raise BackendUnavailable(f"shader {name!r} not found in {shader_dir()}; reinstall zbuf-occlude")
    return _INCLUDE.sub(lambda m: _expanded(m.group(1)), path.read_text(encoding="utf-8"))


@functools.cache
def load_shader(name: str, defines: tuple[tuple[str, int | float], ...] = ()) -> str:
    """The GLSL source of ``shaders/NAME``, ready to compile.

    Its ``//#include`` lines are expanded, and after its ``#version`` line come ``#define KEY
    VALUE`` lines: first :data:`~zbuf_occlude.render.bindings.SHADER_DEFINES`, then ``defines``
    (the shader's own compile-time switches, e.g. ``(("NEIGHBORHOOD", 1),)``).

    Raises
    ------
    BackendUnavailable
        The file is not in :func:`shader_dir` (a broken install).
    ValueError
        The file does not start with a ``#version`` line, or ``defines`` repeats a name of
        :mod:`~zbuf_occlude.render.bindings`.
    """
    version, _, body = _expanded(name).partition("\n")
    if not version.startswith("#version"):
        raise ValueError(f"shader {name!r} must start with a #version line, not {version!r}")
    clash = {key for key, _ in defines} & {key for key, _ in SHADER_DEFINES}
    if clash:
        raise ValueError(f"defines {sorted(clash)} of shader {name!r} are zbuf_occlude.render.bindings names")
    lines = (f"#define {key} {value}" for key, value in (*SHADER_DEFINES, *defines))
    return "\n".join([version, *lines, body])
