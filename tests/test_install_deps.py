"""A plain install (``pip install .``: the core dependencies, no extra) reads what the docs say it reads.

Each check runs in a child process whose imports are limited to the standard library,
zbuf_occlude and the distributions that ``pyproject.toml``'s core dependencies install (with
their own requirements): every other module raises ``ModuleNotFoundError`` as it would in a
clean virtual environment, even where this test environment has it (Pillow comes with the
``test`` extra's matplotlib).
"""

from __future__ import annotations

import importlib.metadata
import json
import re
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

#: Each test starts Python and imports the package in a child: seconds each.
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]

#: The child: refuses every top-level module outside ``argv[1]`` (a JSON list of names),
#: the standard library and zbuf_occlude, then loads the meshes ``argv[2:]`` and prints their
#: face counts, or ``MeshLoadError: MESSAGE`` at the first that fails and exits 1.
CHILD = r"""
import importlib.abc, json, sys
allowed = set(json.loads(sys.argv[1])) | {"zbuf_occlude"}
class OnlyThese(importlib.abc.MetaPathFinder):
    # in front of the usual finders: a module they would find outside the list is not found
    # (an import fails, importlib.util.find_spec answers None), as in a clean environment
    def __init__(self, finders):
        self.finders = finders
    def find_spec(self, name, path=None, target=None):
        top = name.partition(".")[0]
        if top not in allowed and top not in sys.stdlib_module_names and top not in sys.builtin_module_names:
            return None
        for finder in self.finders:
            spec = finder.find_spec(name, path, target) if hasattr(finder, "find_spec") else None
            if spec is not None:
                return spec
        return None
sys.meta_path[:] = [OnlyThese(list(sys.meta_path))]
import zbuf_occlude as zo
from zbuf_occlude.errors import MeshLoadError
try:
    print(" ".join(str(len(zo.load_mesh(path).faces)) for path in sys.argv[2:]))
except MeshLoadError as exc:
    print(f"MeshLoadError: {exc}")
    sys.exit(1)
"""


def _name(requirement: str) -> str:
    return re.split(r"[\s\[<>=!~;(]", requirement.strip(), maxsplit=1)[0]


def _normal(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def core_distributions() -> set[str]:
    """Normalised names of the distributions ``pip install .`` brings: the core dependencies
    of pyproject.toml and, recursively, their requirements without extras (markers evaluated here)."""
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    requirements = pytest.importorskip("packaging.requirements")
    todo = list(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"])
    found: set[str] = set()
    while todo:
        req = requirements.Requirement(todo.pop())
        name = _normal(req.name)
        if name in found or (req.marker is not None and not req.marker.evaluate({"extra": ""})):
            continue
        try:
            todo += importlib.metadata.requires(req.name) or []
        except importlib.metadata.PackageNotFoundError:  # not for this platform or Python: nothing to import
            continue
        found.add(name)
    return found


def core_modules() -> list[str]:
    """Top-level modules of the core distributions (:func:`core_distributions`)."""
    core = core_distributions()
    return sorted(m for m, dists in importlib.metadata.packages_distributions().items() if any(_normal(d) in core for d in dists))


def _png_1x1() -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", 1, 1, 8, 2, 0, 0, 0)  # 1×1, 8 bits, RGB
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\x00\xc8\x64\x32")) + chunk(b"IEND", b"")


#: OBJ files with texture coordinates that name a material: its texture in the ``.mtl`` (read
#: with Pillow), or a material the folder lacks (as Gazebo's exports, whose ``.mtl`` is not
#: shipped: trimesh then makes a default texture, with Pillow too).
OBJ_MATERIALS = {
    "textured": ("tetra.mtl", "paint"),
    "material_not_there": ("gone.mtl", "paint"),
}


def obj_with_material(folder: Path, case: str) -> Path:
    """A tetrahedron in OBJ with texture coordinates and a material (:data:`OBJ_MATERIALS`)."""
    mtl, material = OBJ_MATERIALS[case]
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "paint.png").write_bytes(_png_1x1())
    (folder / "tetra.mtl").write_text("newmtl paint\nKd 0.8 0.4 0.2\nmap_Kd paint.png\n")
    (folder / "tetra.obj").write_text(
        f"mtllib {mtl}\n"
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
        "vt 0 0\nvt 1 0\nvt 0 1\n"
        f"usemtl {material}\n"
        "f 1/1 3/3 2/2\nf 1/1 2/2 4/3\nf 1/1 4/3 3/2\nf 2/1 3/2 4/3\n"
    )
    return folder / "tetra.obj"


def _load_with_only(modules: list[str], *meshes: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", CHILD, json.dumps(modules), *map(str, meshes)], capture_output=True,
                          text=True, timeout=300, cwd=ROOT)  # fmt: skip


@pytest.mark.parametrize("case", sorted(OBJ_MATERIALS))
def test_the_core_dependencies_read_an_obj_that_names_a_material(tmp_path, case):
    r = _load_with_only(core_modules(), obj_with_material(tmp_path / "obj", case))
    assert r.returncode == 0 and r.stdout.strip() == "4", r.stdout + r.stderr[-3000:]


def test_the_core_dependencies_read_every_shipped_mesh(sample_mesh_files):
    r = _load_with_only(core_modules(), *sample_mesh_files)
    assert r.returncode == 0 and len(r.stdout.split()) == len(sample_mesh_files), r.stdout + r.stderr[-3000:]


def test_a_missing_module_is_named_with_its_package_not_blamed_on_the_file(tmp_path):
    modules = [m for m in core_modules() if m != "PIL"]
    r = _load_with_only(modules, obj_with_material(tmp_path / "obj", "material_not_there"))
    assert r.returncode == 1, r.stdout + r.stderr[-3000:]
    message = r.stdout.strip()
    assert "needs the Python module 'PIL', which is not installed" in message and "pip install pillow" in message
    assert "tetra.obj" in message and "cannot parse" not in message
