"""Shared fixtures: where the test meshes live.

* Real ModelNet meshes (research-only, not shipped): ``../shared/data/modelnet_subset``
  next to the repository root.  See its SOURCE.md for what the files exercise.
* The repository's own sample meshes, shipped with the project: ``data/samples/``.

Tests that need either are skipped, with the reason, when the folder is absent.
A test that takes an argument named ``modelnet_off_file`` runs once per real mesh.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from zbuf_occlude.mesh import SUPPORTED_EXTENSIONS

REPO_ROOT = Path(__file__).resolve().parents[1]
#: Real ModelNet meshes, next to (not inside) the repository.
MODELNET_SUBSET = REPO_ROOT.parent / "shared" / "data" / "modelnet_subset"
#: Sample meshes shipped in the repository.
SAMPLE_MESHES = REPO_ROOT / "data" / "samples"


def _modelnet_off_files() -> list[Path]:
    return sorted(MODELNET_SUBSET.rglob("*.off")) if MODELNET_SUBSET.is_dir() else []


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    # Parametrise at collection time so that each real mesh is its own test case.
    if "modelnet_off_file" in metafunc.fixturenames:
        files = _modelnet_off_files()
        params = [pytest.param(p, id=p.relative_to(MODELNET_SUBSET).as_posix()) for p in files] or [
            pytest.param(None, marks=pytest.mark.skip(reason=f"no .off files under {MODELNET_SUBSET}"))
        ]
        metafunc.parametrize("modelnet_off_file", params)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path to the real ModelNet subset; skips the test when it is absent."""
    if not MODELNET_SUBSET.is_dir():
        pytest.skip(f"real ModelNet meshes not found at {MODELNET_SUBSET}")
    return MODELNET_SUBSET


@pytest.fixture(scope="session")
def modelnet_off_files(shared_data: Path) -> list[Path]:
    """All ``.off`` files of the real ModelNet subset, sorted."""
    files = _modelnet_off_files()
    if not files:
        pytest.skip(f"no .off files under {shared_data}")
    return files


@pytest.fixture(scope="session")
def sample_meshes_dir() -> Path:
    """The repository's shipped sample meshes (``data/samples/``); skips when absent."""
    if not SAMPLE_MESHES.is_dir():
        pytest.skip(f"no sample meshes shipped yet at {SAMPLE_MESHES}")
    return SAMPLE_MESHES


@pytest.fixture(scope="session")
def sample_mesh_files(sample_meshes_dir: Path) -> list[Path]:
    """Every mesh file in ``data/samples/`` that load_mesh can read, sorted."""
    files = sorted(p for p in sample_meshes_dir.rglob("*") if p.suffix.lower() in SUPPORTED_EXTENSIONS)
    if not files:
        pytest.skip(f"no mesh files in {sample_meshes_dir}")
    return files
