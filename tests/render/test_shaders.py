"""The GLSL loader (zbuf_occlude.render.shaders) and the names it shares with the Python side
(zbuf_occlude.render.bindings): no binding point or work-group size is written as a number."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import zbuf_occlude
from zbuf_occlude.errors import BackendUnavailable
from zbuf_occlude.render import bindings
from zbuf_occlude.render.shaders import load_shader, shader_dir

PACKAGE = Path(zbuf_occlude.__file__).parent
SHADERS = PACKAGE / "render" / "shaders"
#: The files compiled on their own (the .glsl files are only included).
PROGRAMS = sorted(p.name for p in SHADERS.iterdir() if p.suffix in {".comp", ".vert", ".frag"})
NAMES = {name for name, _ in bindings.SHADER_DEFINES}
_BINDING = re.compile(r"\bbinding\s*=\s*(\w+)")
_BUFFER = re.compile(r"layout\(std430,\s*binding\s*=\s*(\w+)\)\s*(?:readonly\s+|writeonly\s+)?buffer\s+(\w+)")


def _glsl_files() -> list[Path]:
    return sorted(p for p in SHADERS.iterdir() if p.suffix in {".glsl", ".comp", ".vert", ".frag"})


def test_the_shaders_are_read_from_the_package_itself():
    assert Path(str(shader_dir())) == SHADERS
    assert PROGRAMS and {"exact_bin.comp", "exact_points.comp", "mesh.frag", "visibility_candidates.comp"} <= set(PROGRAMS)


@pytest.mark.parametrize("path", _glsl_files(), ids=lambda p: p.name)
def test_glsl_names_every_binding_and_the_work_group_size(path):
    text = path.read_text(encoding="utf-8")
    for value in _BINDING.findall(text):
        assert value in NAMES, f"{path.name}: binding = {value}: use a zbuf_occlude.render.bindings name"
    for value in re.findall(r"local_size_x\s*=\s*(\w+)", text):
        assert value == "GROUP_SIZE", f"{path.name}: local_size_x = {value}"


@pytest.mark.parametrize("name", PROGRAMS)
def test_no_two_buffers_of_one_program_share_a_binding_point(name):
    source = load_shader(name)
    buffers = _BUFFER.findall(source)
    points = [getattr(bindings, point) for point, _ in buffers]
    assert len(set(points)) == len(points), buffers


def test_every_binding_name_is_used_by_some_shader():
    used = {value for path in _glsl_files() for value in _BINDING.findall(path.read_text(encoding="utf-8"))}
    assert NAMES - used == {"GROUP_SIZE"}, NAMES - used - {"GROUP_SIZE"}


def test_the_python_side_binds_by_name_only():
    """Every ``bind_to_storage_buffer(...)`` and texture ``use(location=...)`` in the package
    passes a ``bindings.NAME``, never a number or a variable."""
    calls = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                args = []
                if node.func.attr == "bind_to_storage_buffer":
                    args = node.args[:1] + [k.value for k in node.keywords if k.arg == "binding"]
                elif node.func.attr == "use":
                    args = [k.value for k in node.keywords if k.arg == "location"]
                for arg in args:
                    calls.append((path.name, node.lineno, ast.unparse(arg)))
    assert len(calls) > 20, calls  # the scan sees the renderer's, the exact passes' and the probe's calls
    bare = [c for c in calls if not re.fullmatch(r"bindings\.[A-Z0-9_]+", c[2]) or c[2].split(".")[1] not in NAMES]
    assert not bare, bare


def test_the_defines_follow_the_version_line():
    source = load_shader("visibility_candidates.comp", (("NEIGHBORHOOD", 2),))
    lines = source.splitlines()
    assert lines[0] == "#version 430"
    defines = lines[1 : 1 + len(bindings.SHADER_DEFINES) + 1]
    assert defines == [f"#define {k} {v}" for k, v in bindings.SHADER_DEFINES] + ["#define NEIGHBORHOOD 2"]
    assert not re.search(r"^//#include", source, re.MULTILINE) and "bool segment_hits_face" in source  # common.glsl expanded


def test_a_define_may_not_shadow_a_binding_name():
    with pytest.raises(ValueError, match="EXACT_BITS"):
        load_shader("exact_points.comp", (("EXACT_BITS", 5),))


def test_a_missing_shader_is_a_broken_install():
    with pytest.raises(BackendUnavailable, match="no_such.comp.*reinstall"):
        load_shader("no_such.comp")


def test_an_included_file_cannot_be_compiled_on_its_own():
    with pytest.raises(ValueError, match="#version"):
        load_shader("common.glsl")
