"""No module imports from a layer above its own (deferred imports inside functions included).

The layers, lowest first: the base (errors, defaults, ...) → mesh → sampling → cameras →
render → visibility → occlude → io → farm/compare → cli → the package's ``__init__``.
Modules of one layer may import each other.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import zbuf_occlude

PACKAGE = Path(zbuf_occlude.__file__).parent
ROOT = "zbuf_occlude"

#: Layer of each top-level module or subpackage of zbuf_occlude (a subpackage's modules
#: share its layer).  A new module gets a line here, in the layer of what it does.
LAYERS: dict[str, int] = {
    # base: no zbuf_occlude imports but each other's
    "errors": 0, "defaults": 0, "_version": 0, "safe_paths": 0, "mesh_cache": 0, "metrics": 0, "resources": 0,
    "mesh_formats": 1, "discovery": 1, "mesh_layouts": 1, "mesh": 1, "mesh_scene": 1, "object_sizes": 1,
    "sampling": 2,
    "cameras": 3,
    "render": 4,
    "visibility": 5,
    "occlude": 6,
    # writers and readers, and the on-disk layout they share
    "io": 7, "dataset": 7, "layout": 7, "real_scans": 7, "schema": 7, "verify": 7, "sample_files": 7, "scan_files": 7,
    # engines on top of one object's pipeline
    "farm": 8, "compare": 8, "elevation_profile": 8, "sensors": 8, "protocols": 8,
    "learn": 9,
    "cli": 9, "__main__": 9,
    "__init__": 10,  # the public API re-exports everything
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
            if target == ROOT:  # `from .. import io` names modules; `from .. import __version__` the package
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
    return {
        _module_name(p): (p.read_text(encoding="utf-8"), p.name == "__init__.py") for p in sorted(PACKAGE.rglob("*.py"))
    }


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
        imports = [
            _top(t) for m, (src, pkg) in sources.items() if _top(m) == here for _, t in imported_modules(m, src, pkg)
        ]
        assert there in imports, f"{here} no longer imports {there}: remove it from ALLOWED"


@pytest.mark.parametrize(
    ("module", "source", "is_package", "expected"),
    [
        ("zbuf_occlude.render", "def f():\n    from ..visibility.zbuffer import renderer_for\n", True, 1),
        ("zbuf_occlude.render.moderngl_backend", "from ..visibility import registry\n", False, 1),
        ("zbuf_occlude.farm.worker", "def v():\n    from .. import __version__\n", False, 1),
        ("zbuf_occlude.mesh", "import zbuf_occlude.sampling\n", False, 1),
        ("zbuf_occlude.visibility.zbuffer", "from ..render.renderer_cache import renderer_for\n", False, 0),
        ("zbuf_occlude.farm.run", "from .. import io\nfrom .worker import x\n", False, 0),
    ],
)
def test_the_check_sees_upward_imports(module: str, source: str, is_package: bool, expected: int) -> None:
    assert len(violations({module: (source, is_package)})) == expected
