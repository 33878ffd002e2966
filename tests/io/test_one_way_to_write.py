"""One way to delete or rename: only the owned-folder layer (zbuf_occlude.io.owned, its delete
rules in zbuf_occlude.io.deletes), its atomic
write (zbuf_occlude.io.atomic) and its lock (zbuf_occlude.io.locks, which removes a dead writer's
lock) unlink, remove, rename or replace a path.  Any other module must
call the layer, whose checks (lock, layout, names, recorded size and SHA-256) a direct call would skip."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import zbuf_occlude

PACKAGE = Path(zbuf_occlude.__file__).parent
#: The layer: the only modules that may delete or rename.
LAYER = {"io/owned.py", "io/deletes.py", "io/atomic.py", "io/locks.py"}
#: Module functions that delete or rename a path.
_MODULE_CALLS = {
    "os": {"remove", "unlink", "rmdir", "removedirs", "rename", "renames", "replace"},
    "shutil": {"rmtree", "move"},
}
#: Methods of pathlib.Path that delete or rename (``replace`` and ``rename`` take one argument, the
#: target; ``str.replace`` takes two, ``dataclasses.replace`` is a module function, handled above).
_PATH_METHODS = {"unlink", "rmdir"}
_PATH_RENAMES = {"rename", "replace"}


def deleting_calls(source: str) -> list[tuple[int, str]]:
    """``(line, text)`` of each call in ``source`` that deletes or renames a path."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call) or not isinstance(node.func, ast.Attribute):
            continue
        attr, owner = node.func.attr, node.func.value
        if isinstance(owner, ast.Name) and owner.id in _MODULE_CALLS:
            if attr in _MODULE_CALLS[owner.id]:
                found.append((node.lineno, f"{owner.id}.{attr}"))
            continue
        if isinstance(owner, ast.Name) and owner.id in ("dataclasses", "str"):
            continue
        if attr in _PATH_METHODS:
            found.append((node.lineno, f".{attr}()"))
        elif attr in _PATH_RENAMES and len(node.args) == 1 and not node.keywords and not isinstance(owner, ast.Constant):
            found.append((node.lineno, f".{attr}(target)"))
    return found


def test_only_the_layer_deletes_or_renames():
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel in LAYER:
            continue
        offenders += [f"{rel}:{line}: {text}" for line, text in deleting_calls(path.read_text(encoding="utf-8"))]
    assert not offenders, "delete and rename through zbuf_occlude.io.owned:\n" + "\n".join(offenders)


@pytest.mark.parametrize(
    "code",
    [
        "os.remove(p)", "os.unlink(p)", "os.rename(a, b)", "os.replace(a, b)", "shutil.rmtree(d)", "shutil.move(a, b)",
        "path.unlink()", "(out / 'x').unlink(missing_ok=True)", "folder.rmdir()", "tmp.replace(target)", "tmp.rename(target)",
    ],
)  # fmt: skip
def test_the_walker_finds_every_way_to_delete(code):
    assert deleting_calls(code)


@pytest.mark.parametrize(
    "code", ["text.replace('a', 'b')", "dataclasses.replace(obj, x=1)", "sig.replace(parameters=[])", "items.remove(x)", "'a'.replace(b)"]
)
def test_the_walker_lets_other_replaces_be(code):
    assert not deleting_calls(code)


def test_an_owned_folder_removes_only_its_own_dead_writers_temporaries(tmp_path):
    """A user's folder may hold other programs' ``.x.tmp`` files: only a dead writer's temporary
    of a name the run writes goes."""
    import subprocess
    import sys

    from zbuf_occlude.io.atomic import _host_tag
    from zbuf_occlude.io.owned import OwnedFolder

    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    dead = f"{child.pid}-{_host_tag()}-abc"
    ours, other, legacy = f".a.csv.{dead}.tmp", f".notes.md.{dead}.tmp", ".editor.swap.tmp"
    for name in (ours, other, legacy):
        (tmp_path / name).write_text("x")
    with OwnedFolder(tmp_path, names=[r"a\.csv"]):
        pass
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")) == sorted([other, legacy])
