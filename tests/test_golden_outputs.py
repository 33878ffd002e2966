"""Outputs no refactor may change, hashed: a generated data set read back, and the masks of the
exact methods and the paper's on every shipped mesh (``scripts/golden_hashes.py`` says what and
how; the hashes were taken before the package was restructured)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("golden_hashes", ROOT / "scripts" / "golden_hashes.py")
golden = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(golden)

EXPECTED = json.loads((ROOT / "tests" / "data" / "golden_hashes.json").read_text())


@pytest.mark.slow
def test_the_masks_of_every_shipped_mesh_are_unchanged():
    got = golden.mask_hashes()
    assert sorted(got) == sorted(EXPECTED["masks"])
    changed = sorted(k for k in got if got[k] != EXPECTED["masks"][k])
    assert not changed, f"masks changed: {changed}"


@pytest.mark.slow
def test_the_generated_data_set_is_unchanged():
    assert golden.dataset_hash() == EXPECTED["dataset"]
