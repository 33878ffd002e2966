"""One way to read, one way to write: only ``zbuf_occlude.io`` opens, loads, saves or makes a path.

A reader outside ``io/`` (a plain ``h5py.File``, ``np.load``, ``open``, ``read_text`` on a lock, a
list followed through a link) skips the checks the layer holds: regular files only, inside the
folder they were named from, sizes capped before a byte is read, HDF5 without links or external
storage.  A writer outside it (``open(..., "w")``, ``np.save``, ``savefig``, ``mkdir``) skips the
lock, the ledger and the atomic rename.  The walker finds both; :data:`ALLOWED` is the short list
of the calls that stay outside, each with its reason.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import zbuf_occlude

PACKAGE = Path(zbuf_occlude.__file__).parent
#: Module functions that read or write a path (``module.name``).
_MODULE_CALLS = {
    "h5py": {"File"},
    "np": {"load", "save", "savez", "savez_compressed", "savetxt", "loadtxt", "genfromtxt", "fromfile"},
    "numpy": {"load", "save", "savez", "savez_compressed", "savetxt", "loadtxt", "genfromtxt", "fromfile"},
    "json": {"load", "dump"},
    "pickle": {"load", "loads", "dump", "dumps"},
    "torch": {"load", "save"},
    "os": {"open", "fdopen", "mkdir", "makedirs"},
    "io": {"open"},
    "trimesh": {"load", "load_mesh"},
    "laspy": {"read", "open"},
    "shutil": {"copy", "copy2", "copyfile", "copytree"},
}
#: Methods that read or write the path they are called on, whatever the object (``Path``).
_METHODS = {"read_text", "read_bytes", "mkdir", "savefig", "open", "tofile"}
#: Methods that write a path when given one positional argument (``Path.write_text(text)``; the
#: owned folder's ``folder.write_text(rel, text)`` takes two and is the layer itself).
_ONE_ARG_WRITES = {"write_text", "write_bytes"}

#: The calls that stay outside ``io/``: ``"module.py: call" -> why``.  Short on purpose.
ALLOWED = {
    "resources.py: .read_text()": "reads the kernel's /proc and /sys/fs/cgroup memory files, never a user's",
    "render/shaders/__init__.py: .read_text()": "reads the package's own GLSL files, shipped beside it",
    "visibility/warmup.py: .read_text()": "reads an installed module's source (numba's), not a user's file",
    "cli/main.py: open()": "opens os.devnull as stderr when the real one is closed (no file of a user's)",
    "cli/main.py: os.open()": "points a closed stdout or stderr descriptor at os.devnull (no file of a user's)",
}


def io_calls(source: str) -> list[tuple[int, str]]:
    """``(line, text)`` of each call in ``source`` that opens, loads, saves or makes a path."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        if isinstance(func, ast.Name) and func.id == "open":
            found.append((node.lineno, "open()"))
        elif isinstance(func, ast.Attribute):
            attr, owner = func.attr, func.value
            if isinstance(owner, ast.Name) and owner.id in _MODULE_CALLS:
                if attr in _MODULE_CALLS[owner.id]:
                    found.append((node.lineno, f"{owner.id}.{attr}()"))
                continue
            if attr in _METHODS:
                found.append((node.lineno, f".{attr}()"))
            elif attr in _ONE_ARG_WRITES and len(node.args) == 1:
                found.append((node.lineno, f".{attr}()"))
    return found


def test_only_io_reads_or_writes():
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.startswith("io/"):
            continue
        for line, text in io_calls(path.read_text(encoding="utf-8")):
            if f"{rel}: {text}" not in ALLOWED:
                offenders.append(f"{rel}:{line}: {text}")
    assert not offenders, "read and write through zbuf_occlude.io:\n" + "\n".join(offenders)


def test_every_allowed_call_is_still_there():
    """An allow-list entry whose call is gone is removed, so the list stays short and true."""
    present = set()
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        present.update(f"{rel}: {text}" for _, text in io_calls(path.read_text(encoding="utf-8")))
    assert set(ALLOWED) <= present, sorted(set(ALLOWED) - present)


@pytest.mark.parametrize(
    "code",
    [
        "h5py.File(p, 'r')", "h5py.File(p, 'w')", "np.load(p)", "np.save(p, a)", "np.savez(fh, **a)", "open(p)",
        "open(p, 'w')", "json.load(fh)", "pickle.loads(b)", "torch.load(p, weights_only=True)", "path.read_text()", "path.read_bytes()",
        "Path(p).read_text(encoding='utf-8')", "fig.savefig(p)", "folder.mkdir(parents=True)", "os.makedirs(p)",
        "path.write_text('x')", "tmp.write_bytes(b)", "path.open('rb')", "trimesh.load(p)", "laspy.read(p)",
        "os.open(p, os.O_RDONLY)",
    ],
)  # fmt: skip
def test_the_walker_finds_every_way_to_read_or_write(code):
    assert io_calls(code)


def unsafe_torch_loads(tree: ast.AST) -> list[int]:
    """Lines of ``torch.load`` calls in a parsed ``tree`` without ``weights_only=True`` (an unpickler that runs code)."""
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "load":
            owner = node.func.value
            if isinstance(owner, ast.Name) and owner.id == "torch":
                safe = any(k.arg == "weights_only" and isinstance(k.value, ast.Constant) and k.value.value is True for k in node.keywords)
                if not safe:
                    lines.append(node.lineno)
    return lines


def test_every_torch_load_of_the_package_is_weights_only():
    """io/ included: a checkpoint is unpickled by PyTorch's weights-only unpickler, never one that runs code."""
    offenders = [
        f"{path.relative_to(PACKAGE).as_posix()}:{line}"
        for path in sorted(PACKAGE.rglob("*.py"))
        for line in unsafe_torch_loads(ast.parse(path.read_text(encoding="utf-8")))
    ]
    assert not offenders, "torch.load(..., weights_only=True) only:\n" + "\n".join(offenders)


def _load_call(**keywords: object) -> ast.Module:
    """A module of one call of ``torch``'s ``load`` on a name, with ``keywords`` (constants), built as a syntax tree: no source
    text of a load is written here, nothing is run."""
    call = ast.Call(func=ast.Attribute(value=ast.Name(id="torch", ctx=ast.Load()), attr="load", ctx=ast.Load()),
                    args=[ast.Name(id="path", ctx=ast.Load())],
                    keywords=[ast.keyword(arg=k, value=ast.Constant(v)) for k, v in keywords.items()])  # fmt: skip
    return ast.fix_missing_locations(ast.Module(body=[ast.Expr(call)], type_ignores=[]))


@pytest.mark.parametrize("keywords", [{}, {"weights_only": False}, {"map_location": "cpu"}])
def test_the_torch_walker_finds_unsafe_loads(keywords):
    """A load without weights_only=True is found."""
    assert unsafe_torch_loads(_load_call(**keywords))


def test_the_torch_walker_passes_the_safe_load():
    assert not unsafe_torch_loads(_load_call(map_location="cpu", weights_only=True))


@pytest.mark.parametrize(
    "code", ["json.loads(text)", "json.dumps(x)", "folder.write_text('a.txt', text)", "np.asarray(x)", "text.splitlines()"]
)
def test_the_walker_lets_other_calls_be(code):
    assert not io_calls(code)
