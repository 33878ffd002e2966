"""Shared fixtures: where the test meshes live.

* The repository's own sample meshes, shipped with the project: ``data/samples/`` (8 real
  ModelNet meshes, byte-identical copies of files of the subset below; ``MANIFEST.csv``
  maps each to its path there).  A fresh clone runs every test on these and on procedural
  meshes built in the tests.
* The larger real ModelNet subset (research-only, not shipped): ``../shared/data/modelnet_subset``
  next to the repository root.  When present it is extra coverage: the sweeps run over
  its 27 meshes instead of the 8 shipped ones.  Nothing skips when it is absent.

A test that takes an argument named ``modelnet_off_file`` runs once per real mesh (the
subset's when present, else the shipped ones).
"""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from zbuf_occlude.farm.config import RunOptions
from zbuf_occlude.mesh.formats import SUPPORTED_EXTENSIONS

REPO_ROOT = Path(__file__).resolve().parents[1]
#: Real ModelNet meshes, next to (not inside) the repository.
MODELNET_SUBSET = REPO_ROOT.parent / "shared" / "data" / "modelnet_subset"
#: Sample meshes shipped in the repository.
SAMPLE_MESHES = REPO_ROOT / "data" / "samples"


def _sample_files() -> list[Path]:
    if not SAMPLE_MESHES.is_dir():
        return []
    return sorted(p for p in SAMPLE_MESHES.rglob("*") if p.suffix.lower() in SUPPORTED_EXTENSIONS)


def _shipped_by_subset_path() -> dict[str, Path]:
    """``{path in the subset: shipped copy}`` from ``data/samples/MANIFEST.csv``."""
    manifest = SAMPLE_MESHES / "MANIFEST.csv"
    if not manifest.is_file():
        return {}
    out = {}
    with open(manifest, newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            rel = Path(row["relpath"])
            shipped = SAMPLE_MESHES / row["class"] / row["split"] / rel.name
            if shipped.is_file():
                out[rel.as_posix()] = shipped
    return out


def shared_available() -> bool:
    """Whether the larger real subset ``../shared/data/modelnet_subset`` is present."""
    return MODELNET_SUBSET.is_dir() and any(MODELNET_SUBSET.rglob("*.off"))


def real_mesh_files() -> list[Path]:
    """The real meshes the sweeps run over: the subset's ``.off`` files, else the shipped ones."""
    if shared_available():
        return sorted(MODELNET_SUBSET.rglob("*.off"))
    return _sample_files()


def real_mesh(relpath: str, substitute: str | None = None) -> Path:
    """A real mesh by its path in the subset, wherever it is.

    The subset's file when present; else its shipped copy (same bytes); else the shipped
    copy of ``substitute`` (a subset path of a shipped mesh with the property the test
    needs).  Never skips: a missing file is a broken checkout.
    """
    if (MODELNET_SUBSET / relpath).is_file():
        return MODELNET_SUBSET / relpath
    shipped = _shipped_by_subset_path()
    for rel in (relpath, substitute):
        if rel is not None and rel in shipped:
            return shipped[rel]
    raise FileNotFoundError(f"{relpath} is neither in {MODELNET_SUBSET} nor shipped in {SAMPLE_MESHES} (substitute {substitute})")


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    # Parametrise at collection time so that each real mesh is its own test case.
    if "modelnet_off_file" in metafunc.fixturenames:
        root = MODELNET_SUBSET if shared_available() else SAMPLE_MESHES
        tag = "shared" if shared_available() else "samples"
        params = [pytest.param(p, id=f"{tag}/{p.relative_to(root).as_posix()}") for p in real_mesh_files()]
        metafunc.parametrize("modelnet_off_file", params)


@pytest.fixture(scope="session")
def modelnet_off_files() -> list[Path]:
    """All real meshes (the subset's ``.off`` files if present, else the shipped ones), sorted."""
    return real_mesh_files()


@pytest.fixture(scope="session")
def sample_meshes_dir() -> Path:
    """The repository's shipped sample meshes (``data/samples/``)."""
    assert SAMPLE_MESHES.is_dir(), f"the shipped sample meshes are missing: {SAMPLE_MESHES}"
    return SAMPLE_MESHES


@pytest.fixture(scope="session")
def sample_mesh_files(sample_meshes_dir: Path) -> list[Path]:
    """Every mesh file in ``data/samples/`` that load_mesh can read, sorted."""
    files = _sample_files()
    assert files, f"no mesh files in {sample_meshes_dir}"
    return files


@pytest.fixture
def no_mesh_loaded(monkeypatch):
    """Fails the test if any mesh is loaded (by a farm worker or by ``validate``): the checks must come first."""
    import zbuf_occlude.mesh.load as mesh

    def refuse(*args, **kwargs):
        raise AssertionError("a mesh was loaded before the options were checked")

    # the farm's worker and validate import load_mesh from its module when they run
    monkeypatch.setattr(mesh, "load_mesh", refuse)


def tiny_dataset(out: Path, storage: str = "dense") -> Path:
    """A finished farm data set of two shipped meshes (a chair, train; a desk, test), two poses,
    one 64-point sample per pose: made in about a second, for tests that damage or craft one."""
    from zbuf_occlude.farm import FarmParams, run_farm

    tree = out.parent / f"{out.name}_meshes"
    for rel in ("chair/train/chair_0001.off", "desk/test/desk_0201.off"):
        (tree / rel).parent.mkdir(parents=True, exist_ok=True)
        (tree / rel).symlink_to(SAMPLE_MESHES / rel)
    params = FarmParams(views="0:0,30:90", samples_per_view=1, n_points=64, dense_points=1024, resolution=64, storage=storage)
    run_farm(tree, out, params=params, options=RunOptions(progress=False))
    return out


def aerial_slab_crops(root: Path, offset=(0.0, 0.0, 0.0)) -> Path:
    """Four aerial crops (``dales-q1560``) of a flat car-sized slab under the plan centre, one class
    ``car``, written as ``root/car/NNN.xyz`` (shifted by ``offset``, metres): a top and no wall, so
    no crop tells a scan angle.  Returns ``root``."""
    import numpy as np
    import trimesh

    from zbuf_occlude.sensors.scan import scan_airborne
    from zbuf_occlude.sensors.kinds import sensor_from_name

    base = sensor_from_name("dales-q1560")
    (root / "car").mkdir(parents=True)
    for i in range(4):
        slab = trimesh.creation.box(extents=[4.5, 2.0, 0.3])
        slab.apply_translation([0.0, 0.0, 0.15])
        points = np.asarray(scan_airborne(slab, base, half_size_m=4.0, seed=i, lateral_shift_m=0.0).points, dtype=np.float64)
        np.savetxt(root / "car" / f"{i:03d}.xyz", points + np.asarray(offset), fmt="%.3f")
    return root


def shingles_mesh(cards: int = 60, step: float = 0.01, gap: float = 0.01):
    """A deck of ``cards`` unit squares facing ±x, each ``gap`` behind the one before and shifted
    ``step`` along y, normalised: from ``el=0, az=0`` (the camera on +x) every card but the first
    shows only a strip, so the faces a pose sees are mostly hidden.  The visible surface is then
    too small a part of them for the bounded top-up (``geometry.samples.top_up``): the
    degenerate case whose samples stay padded."""
    import numpy as np
    import trimesh

    from zbuf_occlude.mesh.load import normalize_mesh

    vertices, faces = [], []
    for j in range(cards):
        x, y0, base = -j * gap, j * step, len(vertices)
        vertices += [[x, y0, 0.0], [x, y0 + 1.0, 0.0], [x, y0 + 1.0, 1.0], [x, y0, 1.0]]
        faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return normalize_mesh(trimesh.Trimesh(np.array(vertices), np.array(faces), process=False))


@pytest.fixture(scope="session")
def shingles_tree(tmp_path_factory) -> Path:
    """A ModelNet-style tree holding one :func:`shingles_mesh`, ``shingles/train/shingles_0001.off``."""
    root = tmp_path_factory.mktemp("shingles")
    path = root / "shingles" / "train" / "shingles_0001.off"
    path.parent.mkdir(parents=True)
    shingles_mesh().export(path)
    return root


#: Memory a child loading a hostile mesh may map: enough for Python, numpy and trimesh, far below any bomb.
_CHILD_MEMORY_BYTES = 3 << 30
#: A guard, not a measurement: the refusals take well under a second.
_CHILD_SECONDS = 60


def load_in_child(path: Path) -> str:
    """Run load_mesh(path) in a child under a memory limit (RLIMIT_AS) and a wall-clock guard; return
    what it printed (the error, or the bounds), so that a load that would exhaust the machine fails the
    test (MemoryError, killed, or minutes of work) instead of taking the machine down."""
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent(
        f"""
        import resource, sys
        resource.setrlimit(resource.RLIMIT_AS, ({_CHILD_MEMORY_BYTES}, {_CHILD_MEMORY_BYTES}))
        from zbuf_occlude.errors import MeshLoadError
        from zbuf_occlude.mesh.load import load_mesh
        try:
            mesh = load_mesh(sys.argv[1], normalize=False, up="+z")
        except MeshLoadError as exc:
            print("MeshLoadError:", exc)
        else:
            print("loaded", len(mesh.faces), mesh.bounds.tolist())
        """
    )
    try:
        done = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=_CHILD_SECONDS, check=False)
    except subprocess.TimeoutExpired:
        pytest.fail(f"load_mesh({path.name}) ran past {_CHILD_SECONDS} s")
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout
