"""``verify`` on what ``generate`` writes by default: PointNet's joined files carry SHA-256 too."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from zbuf_occlude.cli.main import main
from zbuf_occlude.dataset.verify import verify_dataset

REPO_ROOT = Path(__file__).resolve().parents[2]
CHAIR = REPO_ROOT / "data" / "samples" / "chair"


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("gen") / "o"
    assert main(["generate", str(CHAIR), "--views", "0:0,30:90", "--dense-points", "3000", "--points", "256",
                 "--samples-per-view", "2", "--out", str(out)]) == 0  # fmt: skip
    return out


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


def test_verify_accepts_what_generate_writes_by_default(generated, capsys):
    assert (generated / "occluded_train.h5").is_file()
    card = json.loads((generated / "dataset_card.json").read_text())
    assert {e["path"] for e in card["joined_files"]} >= {"occluded_train.h5", "train_files.txt"}
    assert main(["verify", str(generated)]) == 0
    assert capsys.readouterr().out.startswith("OK ")


def test_a_zeroed_sample_in_pointnets_file_is_caught(generated, tmp_path):
    ds = _copy(generated, tmp_path / "ds")
    with h5py.File(ds / "occluded_train.h5", "r+") as f:
        data = f["data"]
        assert np.abs(data[0]).sum() > 0
        data[0] = np.zeros_like(data[0])
    report = verify_dataset(ds)
    assert not report.ok
    assert any("occluded_train.h5 differs from its SHA-256 in the card" in p for p in report.problems), report.problems


def test_a_list_file_pointing_elsewhere_is_caught(generated, tmp_path):
    ds = _copy(generated, tmp_path / "ds")
    (ds / "train_files.txt").write_text("shards/train_000000.h5\n")
    problems = verify_dataset(ds).problems
    assert any("train_files.txt differs from its SHA-256" in p for p in problems), problems
    assert any("does not list the same files as the card's joined files" in p for p in problems), problems


def test_a_missing_joined_file_is_caught(generated, tmp_path):
    ds = _copy(generated, tmp_path / "ds")
    (ds / "occluded_train.h5").unlink()
    assert any("joined file occluded_train.h5 is missing" in p for p in verify_dataset(ds).problems)


def test_a_joined_file_named_outside_the_folder_is_refused(generated, tmp_path):
    ds = _copy(generated, tmp_path / "ds")
    card = json.loads((ds / "dataset_card.json").read_text())
    card["joined_files"][0]["path"] = "../outside.h5"
    (ds / "dataset_card.json").write_text(json.dumps(card))
    problems = verify_dataset(ds).problems
    assert any("joined_files" in p and "outside.h5" in p for p in problems), problems
