"""The mesh the speed benchmarks time: ModelNet10 ``sofa_0001`` (27,288 faces) from
``../shared/data/modelnet_subset`` when present, else the first shipped sofa."""

from __future__ import annotations

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_MESH = REPO_ROOT.parent / "shared" / "data" / "modelnet_subset" / "ModelNet10" / "sofa" / "train" / "sofa_0001.off"
SHIPPED_MESH = REPO_ROOT / "data" / "samples" / "sofa"


def default_mesh() -> Path:
    """The shared subset's ``sofa_0001.off``, else the first shipped sofa."""
    return SHARED_MESH if SHARED_MESH.is_file() else sorted(SHIPPED_MESH.rglob("*.off"))[0]
