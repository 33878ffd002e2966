"""Every error raised on purpose belongs to the ZbufOccludeError family."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
import trimesh

import zbuf_occlude as zo
from zbuf_occlude import errors

PACKAGE = Path(zo.__file__).parent
#: Modules whose raises are checked here (the visibility methods and the comparison).
CHECKED = [PACKAGE / "visibility", PACKAGE / "experiments" / "compare"]
BUILTIN_ERRORS = {"ValueError", "RuntimeError", "TypeError", "KeyError", "Exception", "AssertionError", "OSError"}


def test_every_error_type_is_in_the_family() -> None:
    assert all(folder.is_dir() for folder in CHECKED), CHECKED
    for name in errors.__all__:
        family = Warning if name.endswith("Warning") else errors.ZbufOccludeError  # warnings are not errors
        assert issubclass(getattr(errors, name), family), name
        assert getattr(zo, name, getattr(errors, name)) is getattr(errors, name)


def _builtin_raises(tree: ast.AST) -> list[int]:
    return [
        node.lineno
        for node in ast.walk(tree)
        if isinstance(node, ast.Raise)
        and isinstance(node.exc, ast.Call)
        and isinstance(node.exc.func, ast.Name)
        and node.exc.func.id in BUILTIN_ERRORS
    ]


def test_no_builtin_exception_is_raised_by_the_methods() -> None:
    offenders = [
        f"{path.relative_to(PACKAGE)}:{line}"
        for root in CHECKED
        for path in sorted(root.rglob("*.py"))
        for line in _builtin_raises(ast.parse(path.read_text(encoding="utf-8")))
    ]
    assert not offenders, offenders
    assert _builtin_raises(ast.parse("raise ValueError('x')")) == [1]


def test_bad_resolve_is_an_invalid_input_even_without_uncertain_points() -> None:
    mesh = trimesh.creation.box()
    points, face_index = trimesh.sample.sample_surface(mesh, 50, seed=0)
    camera = zo.camera_on_sphere(20.0, 30.0, 4.0, resolution=64)
    with pytest.raises(errors.InvalidInputError, match="resolve must be"):
        zo.visible_mask(mesh, points, camera, "zbuffer", face_index=face_index, resolve="bogus")
    assert issubclass(errors.InvalidInputError, ValueError)  # callers catching ValueError still do


def test_every_exception_type_is_defined_in_errors_and_exported() -> None:
    """One home for exceptions: a class deriving from an error anywhere else is a second door."""
    elsewhere = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "errors.py" and path.parent == PACKAGE:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):  # private: caught where raised
                bases = {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases}
                if any(b == "Exception" or b.endswith("Error") for b in bases):
                    elsewhere.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {node.name}")
    assert not elsewhere, elsewhere
    for name in errors.__all__:
        assert getattr(zo, name) is getattr(errors, name), name
