"""One table of storage kinds: only ``zbuf_occlude/dataset/storage.py`` decides by a kind's name.

Every other module asks the kind (:func:`~zbuf_occlude.dataset.storage.storage_kind`) what it needs,
its estimates, its files, its checks, so that a new kind is one class and one entry of
:data:`~zbuf_occlude.dataset.storage.STORAGE_KINDS`, and nothing outside the table guesses for it."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import zbuf_occlude
from zbuf_occlude.dataset.storage import STORAGE_KINDS

PACKAGE = Path(zbuf_occlude.__file__).parent
#: The table: the only module that may switch on a kind's name.
TABLE = "dataset/storage.py"
#: Every kind's name and the storage its card says.
KIND_NAMES = {k.name for k in STORAGE_KINDS.values()} | {k.storage for k in STORAGE_KINDS.values()}
#: Lists of kind names in :mod:`zbuf_occlude.dataset.layout` (what the CLI offers).
NAME_LISTS = {"STORAGE_MODES", "GENERATE_STORAGES", "SAMPLE_FILE_FORMATS"}
#: Known exceptions ``(module, code)``, each with its reason; the list may only shrink.
ALLOWED: dict[tuple[str, str], str] = {
    ("farm/config.py", 'self.storage != "dense"'): "the option rule of --sensor, whose message names the storage it takes",
}


def _is_storage(node: ast.AST) -> bool:
    """``storage``, ``params.storage``, ``card.storage``, ...: a value that names a storage kind."""
    return (isinstance(node, ast.Name) and node.id == "storage") or (isinstance(node, ast.Attribute) and node.attr == "storage")


def _names_kinds(node: ast.AST) -> bool:
    """A kind's name, a literal collection holding one, or one of layout's lists of them."""
    if isinstance(node, ast.Constant):
        return node.value in KIND_NAMES
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return any(_names_kinds(e) for e in node.elts)
    if isinstance(node, ast.Starred):
        return _names_kinds(node.value)
    return (isinstance(node, ast.Name) and node.id in NAME_LISTS) or (isinstance(node, ast.Attribute) and node.attr in NAME_LISTS)


def storage_switches(source: str) -> list[tuple[int, str]]:
    """``(line, code)`` of each place in ``source`` that decides by a storage kind's name: a comparison
    of a storage with a kind's name, a lookup keyed by a storage, a ``match`` on one, a kind taken
    from :data:`STORAGE_KINDS` by its name."""
    found = []
    for node in ast.walk(ast.parse(source)):
        hit = False
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            hit = any(map(_is_storage, operands)) and any(map(_names_kinds, operands))
        elif isinstance(node, ast.Subscript):
            by_name = isinstance(node.value, ast.Name) and node.value.id == "STORAGE_KINDS" and isinstance(node.slice, ast.Constant)
            hit = _is_storage(node.slice) or by_name
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get":
            hit = bool(node.args) and _is_storage(node.args[0])
        elif isinstance(node, ast.Match):
            hit = _is_storage(node.subject)
        if hit:
            found.append((node.lineno, ast.get_source_segment(source, node) or ""))
    return found


def _package_switches() -> list[tuple[str, int, str]]:
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel != TABLE:
            found += [(rel, line, code) for line, code in storage_switches(path.read_text(encoding="utf-8"))]
    return found


def test_no_module_outside_the_table_switches_on_a_storage_kind():
    offenders = [f"{rel}:{line}: {code}" for rel, line, code in _package_switches() if (rel, code) not in ALLOWED]
    assert not offenders, "ask the storage kind (dataset/storage.py) instead:\n" + "\n".join(offenders)


def test_allowed_exceptions_still_exist():
    found = {(rel, code) for rel, _, code in _package_switches()}
    assert not set(ALLOWED) - found, f"these no longer happen: remove them from ALLOWED: {sorted(set(ALLOWED) - found)}"


@pytest.mark.parametrize(
    "code",
    [
        'if params.storage == "compact": pass', 'names += x if storage in ("npz", "ply") else y',
        "ok = params.storage not in GENERATE_STORAGES", "ok = self.storage in (*STORAGE_MODES, *layout.GENERATE_STORAGES)",
        'held = {"dense": 1, "h5": 2}.get(params.storage, 3)', "held = PER_KIND[card.storage]",
        'kind = STORAGE_KINDS["dense"]', 'match card.storage:\n    case "h5":\n        pass',
        'f = objects if params.storage == "h5" else []', '"ply" != storage',
    ],
)  # fmt: skip
def test_the_walker_finds_every_switch(code):
    assert storage_switches(code)


@pytest.mark.parametrize(
    "code",
    [
        "kind = storage_kind(params.storage, sensor=True)", 'points = read(path, fmt) if fmt == "npz" else 0',
        'storage = rec.get("storage")', "f = open_shard(path, storage=card.storage)", "ok = self.storage in storages()",
        'fmt = ("npz", "ply") if args.format == "both" else (args.format,)', "kind = STORAGE_KINDS.get(name)",
    ],
)  # fmt: skip
def test_the_walker_lets_other_uses_be(code):
    assert not storage_switches(code)
