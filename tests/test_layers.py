"""The package's import rule: each package imports only packages below it, never sideways or up.

The layers, lowest first (one per package or base module, so no two packages can lean on each
other unseen): _version → errors → defaults → resources → geometry → io → mesh → render →
visibility → pipeline → dataset → real_scans → sensors → farm → protocols → exporters → learn → experiments →
cli → __main__ → the package's ``__init__``.  Deferred imports inside functions count too.  Also
here: no import cycle between modules, argparse and ``cli`` only in ``cli``, moderngl only in
``render``, and the architecture page names every package.
"""

from __future__ import annotations

import ast
import re
from collections import defaultdict
from pathlib import Path

import pytest

import zbuf_occlude

PACKAGE = Path(zbuf_occlude.__file__).parent
ROOT = "zbuf_occlude"
ARCHITECTURE = PACKAGE.parent / "docs" / "development" / "architecture.md"

#: Layer of each top-level module or subpackage of zbuf_occlude (a subpackage's modules share its
#: layer; a module may import modules of its own package).  A new package gets its own number.
LAYERS: dict[str, int] = {
    "_version": 0, "_llvm": 0, "errors": 1, "defaults": 2, "resources": 3,
    "geometry": 5,      # pure numpy: cameras, sampling, seeds and draws
    "io": 6,            # atomic writes, cloud formats, safe paths
    "mesh": 7,          # files -> normalised trimesh, discovery, layouts
    "render": 8,        # everything OpenGL
    "visibility": 9,    # HSR methods behind visible_mask
    "pipeline": 10,     # occlude(): one object, many poses
    "dataset": 11,      # the on-disk data set
    "real_scans": 12,
    "sensors": 13,
    "farm": 14,
    "protocols": 15,
    "exporters": 16,       # data sets in the layouts other code reads
    "learn": 17,
    "experiments": 18,
    "cli": 19,
    "__main__": 20,
    "__init__": 21,     # the public API
}  # fmt: skip

#: Known exceptions, each with its reason; the list may only shrink.
ALLOWED: dict[tuple[str, str], str] = {}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _top(module: str) -> str:
    """``zbuf_occlude.visibility.oracle`` → ``visibility``; the package itself → ``__init__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def imported_modules(module: str, source: str, is_package: bool = False) -> list[tuple[int, str]]:
    """``(line, absolute module)`` of every zbuf_occlude import in ``source``, at any depth."""
    base = module.split(".") if is_package else module.split(".")[:-1]
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == ROOT]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parent = base[: len(base) - node.level + 1]
                target = ".".join(parent + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != ROOT:
                continue
            if target == ROOT:  # `from zbuf_occlude import io` names a module; `... import __version__` the package
                found += [(node.lineno, f"{ROOT}.{a.name}" if a.name in LAYERS else ROOT) for a in node.names]
            else:
                found.append((node.lineno, target))
    return found


def violations(sources: dict[str, tuple[str, bool]]) -> list[str]:
    """Upward imports among ``{module: (source, is_package)}``."""
    out = []
    for module, (source, is_package) in sorted(sources.items()):
        here = _top(module)
        for line, target in imported_modules(module, source, is_package):
            there = _top(target)
            if here == there or (here, there) in ALLOWED:
                continue
            if LAYERS.get(there, -1) > LAYERS.get(here, 99):
                out.append(f"{module}:{line} imports {target} (layer {LAYERS[there]} above {LAYERS[here]})")
    return out


def _package_sources() -> dict[str, tuple[str, bool]]:
    return {_module_name(p): (p.read_text(encoding="utf-8"), p.name == "__init__.py") for p in sorted(PACKAGE.rglob("*.py"))}


def test_every_module_has_a_layer() -> None:
    missing = sorted({_top(m) for m in _package_sources()} - set(LAYERS))
    assert not missing, f"give these modules a layer in LAYERS: {missing}"


def test_no_upward_import() -> None:
    bad = violations(_package_sources())
    assert not bad, "\n".join(bad)


def test_allowed_exceptions_still_exist() -> None:
    """An exception that no longer happens must leave ALLOWED, so it cannot come back silently."""
    sources = _package_sources()
    for here, there in ALLOWED:
        imports = [_top(t) for m, (src, pkg) in sources.items() if _top(m) == here for _, t in imported_modules(m, src, pkg)]
        assert there in imports, f"{here} no longer imports {there}: remove it from ALLOWED"


@pytest.mark.parametrize(
    ("module", "source", "is_package", "expected"),
    [
        ("zbuf_occlude.render", "def f():\n    from ..visibility.zbuffer import renderer_for\n", True, 1),
        ("zbuf_occlude.render.moderngl_backend", "from zbuf_occlude.visibility import registry\n", False, 1),
        ("zbuf_occlude.farm.worker", "def v():\n    from .. import __version__\n", False, 1),
        ("zbuf_occlude.geometry.sampling", "import zbuf_occlude.mesh.load\n", False, 1),
        ("zbuf_occlude.sensors.scan", "from zbuf_occlude.real_scans import RealScan\n", False, 0),
        ("zbuf_occlude.real_scans.files", "from zbuf_occlude.sensors import scan\n", False, 1),  # sideways: a lower layer
        ("zbuf_occlude.visibility.zbuffer", "from ..render.renderer_cache import renderer_for\n", False, 0),
        ("zbuf_occlude.farm.run", "from .. import io\nfrom .worker import x\n", False, 0),
    ],
)
def test_the_check_sees_upward_imports(module: str, source: str, is_package: bool, expected: int) -> None:
    assert len(violations({module: (source, is_package)})) == expected


def _module_graph() -> dict[str, set[str]]:
    """Module → zbuf_occlude modules it imports (a package import counts as its ``__init__``)."""
    sources = _package_sources()
    graph: dict[str, set[str]] = defaultdict(set)
    for module, (source, is_package) in sources.items():
        for _, target in imported_modules(module, source, is_package):
            while target not in sources and "." in target:  # `from pkg.mod import name` where name is no module
                target = target.rpartition(".")[0]
            if target != module:
                graph[module].add(target)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_cycle() -> None:
    # a package's __init__ imports its own modules, which may import names from it: not a cycle of the code
    graph = {m: {t for t in ts if not (m.startswith(t + ".") and _module_name_is_package(t))} for m, ts in _module_graph().items()}
    assert not _cycles(graph), _cycles(graph)


def _module_name_is_package(module: str) -> bool:
    return (PACKAGE.parent / module.replace(".", "/") / "__init__.py").is_file()


def test_the_cycle_check_sees_a_cycle() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def _imports_of(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.add(node.module)
    return names


@pytest.mark.parametrize(
    ("library", "home"),
    [("argparse", "cli"), ("zbuf_occlude.cli", "cli"), ("moderngl", "render"), ("glcontext", "render")],
)
def test_only_its_package_imports(library: str, home: str) -> None:
    outside = [
        str(p.relative_to(PACKAGE.parent))
        for p in sorted(PACKAGE.rglob("*.py"))
        if p.relative_to(PACKAGE).parts[0] not in (home, "__main__.py")  # python -m zbuf_occlude runs the CLI
        and any(n == library or n.startswith(library + ".") for n in _imports_of(p))
    ]
    assert not outside, f"only zbuf_occlude/{home}/ may import {library}: {outside}"


def test_architecture_page_names_every_package() -> None:
    text = ARCHITECTURE.read_text(encoding="utf-8")
    packages = sorted(p.parent.name for p in PACKAGE.glob("*/__init__.py"))
    missing = [p for p in packages if not re.search(rf"\b{p}/", text)]
    assert not missing, f"docs/development/architecture.md does not describe: {missing}"


def test_tests_mirror_the_package() -> None:
    """A test folder is named after the package it tests (tests/visibility/test_oracle.py for visibility/oracle.py)."""
    tests = Path(__file__).resolve().parent
    folders = [p.relative_to(tests) for p in tests.rglob("*") if p.is_dir() and any(p.glob("test_*.py"))]
    stray = [str(f) for f in folders if not (PACKAGE / f / "__init__.py").is_file()]
    assert not stray, f"test folders that name no package of zbuf_occlude: {stray}"
