"""The install hint of an optional extra: the one way messages say it, naming commands that work.

No package index serves zbuf-occlude, so ``pip install 'zbuf-occlude[EXTRA]'`` fails, and
``pip install '.[EXTRA]'`` works only in a checkout; every message builds its hint with
:func:`zbuf_occlude._version.install_hint` (the extra's own packages, by name), and every extra it
names is one of ``pyproject.toml``.  (tests/test_wheel.py checks that the wheel it names is the
one ``pip wheel`` builds.)
"""

from __future__ import annotations

import ast
import re
import shlex
import subprocess
import sys
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


def _pyproject_extra(extra: str) -> list[str]:
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"][extra]


def _spec(requirement: str) -> tuple[str, set[str]]:
    """``("pycollada", {"<1", ">=0.8"})``: a requirement's name and version clauses, in any order."""
    head = requirement.split(";")[0].strip()
    name = re.split(r"[<>=!~ ]", head, maxsplit=1)[0]
    return name.lower(), {c.strip() for c in head[len(name) :].split(",") if c.strip()}


@pytest.mark.parametrize("extra", ["collada", "learn", "pyg", "plot", "yaml"])
def test_the_hint_installs_the_extras_own_packages_by_name(extra: str) -> None:
    """No path, no '.': the command works from any directory, with the version ranges of pyproject's extra."""
    hint = install_hint(extra)
    assert hint.startswith("pip install '") and hint.endswith(f" (the {extra} extra)") and "'.[" not in hint and "dist/" not in hint, hint
    named = sorted(_spec(r) for r in re.findall(r"'([^']+)'", hint))
    assert named == sorted(_spec(r) for r in _pyproject_extra(extra))


def test_the_collada_hint_works_from_another_directory(tmp_path: Path) -> None:
    """The hint's command, run by pip (offline, --dry-run) outside the checkout: satisfied by what is installed."""
    pytest.importorskip("collada", reason="pycollada is the collada extra's")
    args = shlex.split(install_hint("collada").split(" (the ")[0])
    run = subprocess.run([sys.executable, "-m", *args, "--dry-run", "--no-index", "--no-deps", "-q"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    assert run.returncode == 0, run.stderr


def test_a_hint_without_the_packages_metadata_names_a_checkout_and_this_versions_wheel(monkeypatch: pytest.MonkeyPatch) -> None:
    from importlib import metadata

    def missing(name):
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(metadata, "requires", missing)
    assert install_hint("learn") == (
        "pip install '.[learn]' from a checkout, or pip install 'dist/zbuf_occlude-"
        f"{__version__}-py3-none-any.whl[learn]' from a built wheel"
    )
    assert WHEEL_NAME in install_hint("pyg") and WHEEL_NAME in install_hint("no-such-extra")


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
