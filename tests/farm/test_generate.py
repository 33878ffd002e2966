"""``zbuf-occlude generate`` on the farm's engine (issue 9): names, parameters, up-front checks, h5.

Small shipped meshes (``data/samples``), two poses, 64-point samples.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from zbuf_occlude.cli.main import main
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.errors import DatasetFormatError, InvalidInputError, ShardChecksumError
from zbuf_occlude.farm import FarmParams, run_farm
from zbuf_occlude.farm.config import RunOptions
from zbuf_occlude.io.clouds import read_h5, read_npz

REPO_ROOT = Path(__file__).resolve().parents[2]
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
@pytest.mark.slow
@pytest.mark.parametrize(
    "change, option",
    [(["--points", "32"], "--points"), (["--views", "0:0"], "--views"), (["--dense-points", "1000"], "--dense-points"),
     (["--samples-per-view", "1"], "--samples-per-view"), (["--seed", "3"], "--seed")],
)  # fmt: skip
def test_a_rerun_with_other_options_is_refused_unless_overwrite(tree, tmp_path, capsys, change, option):
    out = tmp_path / "out"
    change = [*change, "--format", "npz"]
    assert main(["generate", str(tree), "--out", str(out), *ARGS, "--format", "npz"]) == 0
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


@pytest.mark.slow
def test_generate_resumes_what_is_missing_and_records_its_files(tree, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["generate", str(tree), "--out", str(out), *ARGS, "--format", "npz"]) == 0
    victim = sorted(out.rglob("*.npz"))[3]
    victim.unlink()
    assert main(["generate", str(tree), "--out", str(out), *ARGS, "--format", "npz"]) == 0
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


@pytest.mark.slow
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
def test_validate_dense_points_0_is_a_usage_error(tree, capsys):
    assert main(["validate", str(tree), "--views", "0:0", "--dense-points", "0"]) == 2
    assert "--dense-points" in _error(capsys)


@pytest.mark.parametrize("damaged", ["dataset_card.json", "manifest.jsonl"])
def test_a_damaged_card_or_manifest_names_the_file(tree, tmp_path, damaged):
    out = tmp_path / "ds"
    run_farm(tree, out, params=FarmParams(views="0:0", samples_per_view=1, n_points=32, dense_points=500, resolution=64), options=RunOptions(progress=False))  # fmt: skip
    path = out / damaged
    path.write_text(path.read_text()[:-25])  # cut short
    with pytest.raises(InvalidInputError, match=damaged.replace(".", r"\.")):
        OccludedDataset(out)


# -- one pipeline: generate --format h5 is the farm's engine ------------------------------------------
@pytest.mark.slow
def test_generate_h5_equals_the_farm_split_by_split(tree, tmp_path):
    out = tmp_path / "gen"
    assert main(["generate", str(tree), "--out", str(out), "--format", "h5", *ARGS]) == 0
    assert not (out / ".parts").exists() and not (out / "occluded.h5").exists()
    farm = tmp_path / "farm"
    params = FarmParams(views="0:0,30:45", samples_per_view=2, n_points=64, dense_points=2000, resolution=128)
    run_farm(tree, farm, params=params, options=RunOptions(progress=False))
    for split in ("train", "test"):
        merged = read_h5(out / f"occluded_{split}.h5")
        assert merged["data"].shape == (4, 64, 3) and list(merged["shape_names"]) == ["sofa", "stool"]
        assert set(merged["source"]) == {p.relative_to(tree).as_posix() for p in sorted(tree.glob(f"*/{split}/*.off"))}
        farm_data, farm_labels = OccludedDataset(farm, split=split).to_arrays()
        # same objects, keys and order: the same samples, bit for bit
        assert np.array_equal(merged["data"], farm_data) and np.array_equal(merged["label"], farm_labels)
        gen_data, _ = OccludedDataset(out, split=split).to_arrays()  # the parts are a data set the reader takes
        assert np.array_equal(gen_data, farm_data)
        with h5py.File(out / f"occluded_{split}.h5") as f:
            assert f["face_index"].shape == (4, 64)


# -- the default output is what the reader reads, in every format ---------------------------------------
@pytest.mark.slow
def test_the_default_generate_output_opens_with_the_reader(tree, tmp_path):
    out = tmp_path / "gen"
    assert main(["generate", str(tree), "--out", str(out), *ARGS]) == 0  # no --format
    ds = OccludedDataset(out)
    assert ds.storage == "h5" and len(ds) == 8 and ds.shape_names == ["sofa", "stool"]
    points, label, meta = ds[0]
    assert points.shape == (64, 3) and points.dtype == np.float32 and ds.shape_names[label] == meta["class_name"]


@pytest.mark.slow
def test_npz_and_ply_folders_read_as_the_h5_one(tree, tmp_path):
    """The reader serves generate's npz and ply folders, the same samples as h5 for one set of options."""
    got = {}
    for fmt in ("h5", "npz", "ply"):
        out = tmp_path / fmt
        assert main(["generate", str(tree), "--out", str(out), "--format", fmt, *ARGS]) == 0
        ds = OccludedDataset(out)
        assert ds.storage == fmt and len(ds) == 8
        got[fmt] = (*ds.to_arrays(), [ds[i] for i in range(len(ds))], OccludedDataset(out, split="test").to_arrays()[0])
    h5_data, h5_labels, h5_items, h5_test = got["h5"]
    for fmt in ("npz", "ply"):
        data, labels, items, test = got[fmt]
        assert np.array_equal(data, h5_data) and np.array_equal(labels, h5_labels) and np.array_equal(test, h5_test)
        for (p, lab, meta), (hp, hlab, hmeta) in zip(items, h5_items):
            assert np.array_equal(p, hp) and lab == hlab and meta == hmeta
    # each npz file holds the points the reader serves for its row
    ds = OccludedDataset(tmp_path / "npz")
    rec = json.loads((tmp_path / "npz" / "manifest.jsonl").read_text().splitlines()[0])
    assert np.array_equal(read_npz(tmp_path / "npz" / rec["shards"][1]).points, ds[1][0])


@pytest.mark.slow
def test_a_changed_sample_file_is_named_by_the_reader(tree, tmp_path):
    out = tmp_path / "npz"
    assert main(["generate", str(tree), "--out", str(out), "--format", "npz", *ARGS]) == 0
    victim = sorted(out.rglob("*.npz"))[0]
    data = victim.read_bytes()
    victim.write_bytes(data[:-1] + bytes([data[-1] ^ 1]))  # the same size: only its SHA-256 tells
    ds = OccludedDataset(out)
    with pytest.raises(ShardChecksumError, match=re.escape(victim.name)):
        ds.to_arrays()
    victim.write_bytes(b"not a zip file")  # another size: refused when the data set is opened, unread
    with pytest.raises(DatasetFormatError, match=re.escape(victim.name) + ".*bytes where the record says"):
        OccludedDataset(out)


# -- generate --format h5 keeps the splits apart ---------------------------------------------------------
@pytest.mark.slow
def test_h5_writes_one_file_per_split_with_a_split_column(tree, tmp_path, sample_meshes_dir):
    for rel in ("desk/test/desk_0201.off", "chair/train/chair_0001.off"):  # two objects per split
        (tree / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(sample_meshes_dir / rel, tree / rel)
    out = tmp_path / "gen"
    assert main(["generate", str(tree), "--out", str(out), *ARGS]) == 0
    sources = {}
    for split in ("train", "test"):
        assert (out / f"{split}_files.txt").read_text().splitlines() == [f"occluded_{split}.h5"]
        d = read_h5(out / f"occluded_{split}.h5")
        assert len(d["data"]) == 2 * 2 * 2 and set(d["split"]) == {split}
        # every row's split is its mesh's folder
        assert all(Path(src).parent.name == split for src in d["source"])
        sources[split] = set(d["source"])
    assert sources["train"].isdisjoint(sources["test"]) and len(sources["train"] | sources["test"]) == 4
    # the per-object parts carry the column too
    for part in (out / "shards").glob("*.h5"):
        assert set(read_h5(part)["split"]) == {part.name.split("_")[0]}


@pytest.mark.slow
def test_overwrite_leaves_no_stale_split_file(tree, tmp_path):
    out = tmp_path / "gen"
    assert main(["generate", str(tree), "--out", str(out), *ARGS]) == 0
    assert sorted(p.name for p in out.glob("occluded_*.h5")) == ["occluded_test.h5", "occluded_train.h5"]
    (tree / "sofa").rename(tmp_path / "sofa")  # the only test mesh goes: no test split any more
    assert main(["generate", str(tree), "--out", str(out), *ARGS, "--overwrite"]) == 0
    assert [p.name for p in out.glob("occluded_*.h5")] == ["occluded_train.h5"]
    assert main(["generate", str(tree), "--out", str(out), *ARGS, "--format", "npz", "--overwrite"]) == 0
    assert not list(out.glob("occluded_*.h5")) and len(OccludedDataset(out)) == 4


# -- padding is said, counted and recorded ----------------------------------------------------------------
def _padded_args(points: int, dense_points: int = 4000) -> list[str]:
    return ["--views", "0:0,0:180,30:45", "--points", str(points), "--samples-per-view", "2", "--dense-points",
            str(dense_points), "--resolution", "128"]  # fmt: skip


@pytest.mark.slow
def test_padding_is_warned_once_and_recorded_in_the_card(tree, shingles_tree, tmp_path, caplog):
    # 4000 dense points show 840-1800 per pose: the real meshes' short poses are topped up to 1024
    # distinct points; the shingles (a tiny visible surface) stay padded, and those samples alone
    # are counted
    from zbuf_occlude.farm import GENERATE_DEFAULTS, generate

    shutil.copytree(shingles_tree / "shingles", tree / "shingles")
    out = tmp_path / "gen"
    with caplog.at_level("WARNING"):
        assert main(["generate", str(tree), "--out", str(out), *_padded_args(1024)]) == 0
    ds = OccludedDataset(out)
    meta = [ds.metadata(i) for i in range(len(ds))]
    expected = sum(m["n_visible"] < 1024 for m in meta)
    assert expected == sum(m["padded"] for m in meta) > 0 and all(m["name"].startswith("shingles") for m in meta if m["padded"])
    short = [m for m in meta if m["n_visible"] - m["n_topped_up"] < 1024]  # poses that saw too few dense points
    assert all(m["n_topped_up"] > 0 for m in short) and any(not m["padded"] for m in short)
    card = json.loads((out / "dataset_card.json").read_text())
    assert card["n_padded_samples"] == expected
    warnings = [r.getMessage() for r in caplog.records if "repeated points" in r.getMessage()]
    assert len(warnings) == 1 and f"{expected} of {len(ds)} samples" in warnings[0] and "--points 1024" in warnings[0]
    # the padded samples hold repeats, the others none
    for i in range(len(ds)):
        points, _, m = ds[i]
        assert (len(np.unique(points, axis=0)) == m["n_visible"]) if m["padded"] else len(np.unique(points, axis=0)) == 1024
    # the Python API's result says it too
    params = dataclasses.replace(GENERATE_DEFAULTS, views="0:0,0:180,30:45", n_points=1024, dense_points=4000, resolution=128,
                                 samples_per_view=2)  # fmt: skip
    summary, _ = generate([tree], tmp_path / "api", params=params, progress=False)
    assert summary.padded == expected and "padded" in summary.format()


@pytest.mark.slow
def test_no_padding_no_warning(tree, tmp_path, caplog):
    out = tmp_path / "gen"
    with caplog.at_level("WARNING"):
        assert main(["generate", str(tree), "--out", str(out), *_padded_args(20, 500)]) == 0
    assert json.loads((out / "dataset_card.json").read_text())["n_padded_samples"] == 0
    assert not [r for r in caplog.records if "repeated points" in r.getMessage()]


# -- PointNet's own loop -----------------------------------------------------------------------------------
@pytest.mark.slow
def test_pointnet_style_loop_over_the_file_lists(tree, tmp_path, monkeypatch):
    """PointNet (provider.loadDataFile + train.py) reads data and label from each file in its list; ours are
    relative to the data set (joined with its folder, from any working folder), one file per split so that
    PointNet's in-file shuffle mixes objects; label (B,) is what PointNet's np.squeeze of (B, 1) gives."""
    out = tmp_path / "gen"
    assert main(["generate", str(tree), "--out", str(out), *ARGS]) == 0
    monkeypatch.chdir(tmp_path)  # not the data set folder
    shape_names = (out / "shape_names.txt").read_text().splitlines()
    for split in ("train", "test"):
        files = [os.path.join(out, line.rstrip()) for line in open(out / f"{split}_files.txt")]
        assert len(files) == 1
        with h5py.File(files[0], "r") as f:
            data, label = f["data"][:], f["label"][:]
        assert data.shape == (4, 64, 3) and data.dtype == np.float32
        assert label.shape == (4,) and np.array_equal(np.squeeze(label), label)
        expected = {"train": "stool", "test": "sofa"}[split]
        assert {shape_names[i] for i in label} == {expected}


@pytest.mark.parametrize("command", ["generate", "farm"])
def test_an_out_inside_the_input_folder_is_refused_before_any_work(tmp_path, capsys, command):
    import shutil

    from zbuf_occlude.cli.main import main

    tree = tmp_path / "meshes"
    shutil.copytree(Path(__file__).resolve().parents[2] / "data" / "samples" / "chair", tree / "chair")
    out = tree / "out"
    assert main([command, str(tree), "--out", str(out), "--views", "0:0", "--format" if command == "generate" else "--storage",
                 "ply" if command == "generate" else "dense"]) == 2  # fmt: skip
    assert "lies inside the input folder" in capsys.readouterr().err and not out.exists()


@pytest.mark.slow
def test_generates_progress_bar_is_called_generate(tree, tmp_path, monkeypatch):
    from zbuf_occlude.io import progress

    names = []
    real = progress.progress

    def recording(*args, **kwargs):
        names.append(kwargs.get("desc"))
        return real(*args, **{**kwargs, "enabled": False})

    monkeypatch.setattr(progress, "progress", recording)
    assert main(["generate", str(tree), "--out", str(tmp_path / "out"), *ARGS]) == 0
    assert names == ["generate"]
