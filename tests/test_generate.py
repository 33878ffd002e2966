"""``zbuf-occlude generate`` on the farm's engine (issue 9): names, parameters, up-front checks, h5.

Small shipped meshes (``data/samples``), two poses, 64-point samples.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from zbuf_occlude.cli import main
from zbuf_occlude.dataset import OccludedDataset
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.farm import FarmParams, run_farm
from zbuf_occlude.io import read_h5, read_npz

REPO_ROOT = Path(__file__).resolve().parents[1]
ARGS = ["--views", "0:0,30:45", "--points", "64", "--samples-per-view", "2", "--dense-points", "2000", "--resolution", "128"]


@pytest.fixture
def tree(tmp_path, sample_meshes_dir) -> Path:
    root = tmp_path / "in"
    for rel in ("sofa/test/sofa_0681.off", "stool/train/stool_0002.off"):
        dst = root / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(sample_meshes_dir / rel, dst)
    return root


def _error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error:") and "\n" not in err and "Traceback" not in err
    return err


# -- defect 2: two meshes with one stem ---------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["npz", "h5"])
def test_two_files_with_one_name_are_refused_before_any_work(tree, tmp_path, capsys, fmt):
    chair = tree / "chair" / "train"
    chair.mkdir(parents=True)
    shutil.copy(tree / "stool/train/stool_0002.off", chair / "chair_0001.off")
    # the same mesh as OBJ: one name, chair/train/chair_0001, for two files
    import trimesh

    trimesh.load(chair / "chair_0001.off").export(chair / "chair_0001.obj")
    out = tmp_path / "out"
    assert main(["generate", str(tree), "--out", str(out), "--format", fmt, *ARGS]) == 2
    err = _error(capsys)
    assert "chair_0001.off" in err and "chair_0001.obj" in err and "unique" in err
    assert not list(out.rglob("*.npz")) and not list(out.rglob("*.h5"))


# -- defect 3: other parameters into the same --out -------------------------------------------------
@pytest.mark.parametrize(
    "change, option",
    [(["--points", "32"], "--points"), (["--views", "0:0"], "--views"), (["--dense-points", "1000"], "--dense-points"),
     (["--samples-per-view", "1"], "--samples-per-view"), (["--seed", "3"], "--seed")],
)  # fmt: skip
def test_a_rerun_with_other_options_is_refused_unless_overwrite(tree, tmp_path, capsys, change, option):
    out = tmp_path / "out"
    assert main(["generate", str(tree), "--out", str(out), *ARGS]) == 0
    first = sorted(out.rglob("*.npz"))
    assert len(first) == 2 * 2 * 2
    capsys.readouterr()
    assert main(["generate", str(tree), "--out", str(out), *ARGS, *change]) == 2
    err = _error(capsys)
    assert option in err and "--overwrite" in err and "n_points" not in err
    assert sorted(out.rglob("*.npz")) == first  # nothing touched

    assert main(["generate", str(tree), "--out", str(out), *ARGS, *change, "--overwrite"]) == 0
    args = dict(zip(ARGS[::2], ARGS[1::2])) | dict(zip(change[::2], change[1::2]))
    n_views = len(args["--views"].split(","))
    files = sorted(out.rglob("*.npz"))
    assert len(files) == 2 * n_views * int(args["--samples-per-view"])  # no file of the first run is left
    assert {read_npz(f).points.shape[0] for f in files} == {int(args["--points"])}


def test_generate_resumes_what_is_missing_and_records_its_files(tree, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["generate", str(tree), "--out", str(out), *ARGS]) == 0
    victim = sorted(out.rglob("*.npz"))[3]
    victim.unlink()
    assert main(["generate", str(tree), "--out", str(out), *ARGS]) == 0
    assert victim.exists()
    assert "2 meshes done, 0 failed" in capsys.readouterr().out
    records = [json.loads(p.read_text()) for p in sorted((out / "records").glob("*.json"))]
    assert sum(len(r["shards"]) for r in records) == 8 and all(len(r["sha256"]) == len(r["shards"]) for r in records)


# -- defect 11 and the farm's up-front checks -------------------------------------------------------
@pytest.mark.parametrize(
    "bad, option",
    [(["--resolution", "0"], "--resolution"), (["--resolution", "100000"], "--resolution"), (["--points", "0"], "--points"),
     (["--method", "bogus"], "bogus"), (["--seed", "-1"], "--seed"), (["--radius", "0.1"], "--radius"),
     (["--samples-per-view", "0"], "--samples-per-view"), (["--dense-points", "0"], "--dense-points")],
)  # fmt: skip
def test_generate_usage_errors_exit_2_before_any_mesh(tree, tmp_path, capsys, no_mesh_loaded, bad, option):
    assert main(["generate", str(tree), "--out", str(tmp_path / "out"), *ARGS, *bad]) == 2
    err = _error(capsys)
    assert option in err
    for internal in ("n_points", "samples_per_view", "image size must be positive", "dense_points"):
        assert internal not in err


def test_an_unwritable_out_is_a_usage_error_before_any_mesh(tree, tmp_path, capsys, no_mesh_loaded):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    assert main(["generate", str(tree), "--out", str(blocker / "out"), *ARGS]) == 2
    assert "--out" in _error(capsys)


@pytest.mark.parametrize("command", ["generate", "farm"])
def test_a_bogus_gl_backend_is_named_and_exits_2(tree, tmp_path, command):
    extra = ["--no-progress"] if command == "farm" else []
    proc = subprocess.run(
        [sys.executable, "-m", "zbuf_occlude", command, str(tree), "--out", str(tmp_path / "o"), *ARGS, *extra],
        env={**os.environ, "PYTHONPATH": str(REPO_ROOT), "ZBUF_OCCLUDE_GL": "bogus"},
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert "ZBUF_OCCLUDE_GL" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "o" / "records").exists()


@pytest.mark.parametrize(
    "bad, option",
    [(["--seed", "-1"], "--seed"), (["--resolution", "100000"], "--resolution"), (["--radius", "0.1"], "--radius")],
)
def test_the_farm_refuses_bad_options_up_front(tree, tmp_path, capsys, no_mesh_loaded, bad, option):
    assert main(["farm", str(tree), "--out", str(tmp_path / "o"), *ARGS, "--no-progress", *bad]) == 2
    assert option in _error(capsys)
    assert not (tmp_path / "o" / "records").exists()


# -- defect 13 -------------------------------------------------------------------------------------
def test_validate_points_0_is_a_usage_error(tree, capsys):
    assert main(["validate", str(tree), "--views", "0:0", "--points", "0"]) == 2
    assert "--points" in _error(capsys)


@pytest.mark.parametrize("damaged", ["dataset_card.json", "manifest.jsonl"])
def test_a_damaged_card_or_manifest_names_the_file(tree, tmp_path, damaged):
    out = tmp_path / "ds"
    run_farm(tree, out, params=FarmParams(views="0:0", samples_per_view=1, n_points=32, dense_points=500, resolution=64),
             progress=False)  # fmt: skip
    path = out / damaged
    path.write_text(path.read_text()[:-25])  # cut short
    with pytest.raises(InvalidInputError, match=damaged.replace(".", r"\.")):
        OccludedDataset(out)


# -- one pipeline: generate --format h5 is the farm's engine ------------------------------------------
def test_generate_h5_equals_the_farm_and_keeps_no_hidden_copy(tree, tmp_path):
    out = tmp_path / "gen"
    assert main(["generate", str(tree), "--out", str(out), "--format", "h5", *ARGS]) == 0
    assert not (out / ".parts").exists()
    merged = read_h5(out / "occluded.h5")
    assert merged["data"].shape == (8, 64, 3) and list(merged["shape_names"]) == ["sofa", "stool"]
    assert set(merged["source"]) == {str(p) for p in sorted(tree.rglob("*.off"))}

    farm = tmp_path / "farm"
    params = FarmParams(views="0:0,30:45", samples_per_view=2, n_points=64, dense_points=2000, resolution=128)
    run_farm(tree, farm, params=params, progress=False)
    farm_data, farm_labels = OccludedDataset(farm).to_arrays()
    # same objects, keys and order: the same samples, bit for bit
    assert np.array_equal(merged["data"], farm_data) and np.array_equal(merged["label"], farm_labels)
    gen_data, _ = OccludedDataset(out).to_arrays()  # the parts are a data set the reader takes
    assert np.array_equal(gen_data, farm_data)
    with h5py.File(out / "occluded.h5") as f:
        assert f["face_index"].shape == (8, 64)


def test_the_reader_refuses_a_folder_of_npz_files(tree, tmp_path):
    out = tmp_path / "gen"
    assert main(["generate", str(tree), "--out", str(out), *ARGS]) == 0
    with pytest.raises(InvalidInputError, match="one file per sample"):
        OccludedDataset(out)
