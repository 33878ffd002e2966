"""Caps on file reads: defined once, in zbuf_occlude/io/caps.py, and each one used."""

from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

import pytest

import zbuf_occlude
from zbuf_occlude.io import caps
from zbuf_occlude.io.regular_files import read_regular_file, read_text_file

PACKAGE = Path(zbuf_occlude.__file__).parent
CAPS_MODULE = Path("io/caps.py")
#: A cap's name: what it caps, then BYTES (a private ``_..._MAX_BYTES`` too).
CAP_NAME = re.compile(r"^_?[A-Z0-9_]*MAX_[A-Z0-9_]*BYTES$")
#: Caps on the sizes a mesh *declares* (its counts, a glTF accessor's byte length), not on what a read
#: holds: they stay beside the readers that check them.
DECLARED_SIZE_CAPS = {Path("mesh/limits.py"), Path("mesh/formats/gltf.py")}


def _module_assignments(tree: ast.Module) -> list[str]:
    names = []
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) else []
        names += [t.id for t in targets if isinstance(t, ast.Name)]
    return names


def _sources() -> dict[Path, ast.Module]:
    return {path.relative_to(PACKAGE): ast.parse(path.read_text(encoding="utf-8")) for path in sorted(PACKAGE.rglob("*.py"))}


def test_caps_are_defined_only_in_io_caps() -> None:
    stray = [
        f"{rel}: {name}"
        for rel, tree in _sources().items()
        if rel != CAPS_MODULE and rel not in DECLARED_SIZE_CAPS
        for name in _module_assignments(tree)
        if CAP_NAME.match(name)
    ]
    assert not stray, f"caps on a file read belong in zbuf_occlude/io/caps.py: {stray}"


def test_every_cap_is_used_outside_io_caps() -> None:
    used = {
        node.id if isinstance(node, ast.Name) else node.attr
        for rel, tree in _sources().items()
        if rel != CAPS_MODULE
        for node in ast.walk(tree)
        if isinstance(node, ast.Name | ast.Attribute)
    }
    assert set(caps.__all__) == set(_module_assignments(_sources()[CAPS_MODULE])) - {"__all__"}  # every cap there is public
    unused = sorted(set(caps.__all__) - used)
    assert not unused, f"caps no module uses: {unused}"


@pytest.mark.parametrize("reader", [read_regular_file, read_text_file])
def test_a_read_names_its_cap_at_the_call(reader: object) -> None:
    # a default cap is a cap not named for what it caps: every caller passes one from io.caps
    assert inspect.signature(reader).parameters["max_bytes"].default is inspect.Parameter.empty


def test_caps_module_imports_nothing_above_defaults() -> None:
    tree = ast.parse((PACKAGE / CAPS_MODULE).read_text(encoding="utf-8"))
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)} | {
        alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names
    }
    assert {name for name in imported if name and name.startswith("zbuf_occlude")} <= {"zbuf_occlude.defaults"}
