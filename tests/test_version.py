"""The install hint of an optional extra: the one way messages say it, naming commands that work.

No package index serves zbuf-occlude, so ``pip install 'zbuf-occlude[EXTRA]'`` fails; every
message builds its hint with :func:`zbuf_occlude._version.install_hint`, and every extra it
names is one of ``pyproject.toml``.  (tests/test_wheel.py checks that the wheel it names is the
one ``pip wheel`` builds.)
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import zbuf_occlude
from zbuf_occlude._version import WHEEL_NAME, __version__, install_hint
from zbuf_occlude.mesh.formats import FORMATS
from zbuf_occlude.visibility.registry import available_methods, method_info

PACKAGE = Path(zbuf_occlude.__file__).parent
ROOT = PACKAGE.parent


def _extras() -> set[str]:
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    return set(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"])


def _sources() -> list[tuple[Path, ast.AST]]:
    return [(path, ast.parse(path.read_text(encoding="utf-8"))) for path in sorted(PACKAGE.rglob("*.py"))]


def test_the_hint_names_a_checkout_and_this_versions_wheel() -> None:
    assert install_hint("learn") == (
        "pip install '.[learn]' from a checkout, or pip install 'dist/zbuf_occlude-"
        f"{__version__}-py3-none-any.whl[learn]' from a built wheel"
    )
    assert WHEEL_NAME in install_hint("pyg")


def test_no_message_tells_users_to_install_from_an_index() -> None:
    """A string in the package that says ``pip install 'zbuf-occlude[...]'`` (or without quotes)
    sends users to an index that does not serve it; _version's docstring says why it fails."""
    offenders = [
        f"{path.relative_to(ROOT)}:{node.lineno}"
        for path, tree in _sources()
        if path.name != "_version.py"
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and isinstance(node.value, str)
        and ("install 'zbuf-occlude[" in node.value or "install zbuf-occlude[" in node.value)
    ]  # fmt: skip
    assert not offenders, offenders


def test_every_extra_a_message_names_is_in_pyproject() -> None:
    named = {
        node.args[0].value
        for _, tree in _sources()
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "install_hint"
        and node.args and isinstance(node.args[0], ast.Constant)
    }  # fmt: skip
    named |= {method_info(name).extra for name in available_methods()} - {None}
    named |= {fmt.needs[1] for fmt in FORMATS.values() if fmt.needs is not None}
    assert {"learn", "pyg", "collada", "dask", "plot"} <= named  # the calls were found
    assert named <= _extras(), sorted(named - _extras())
