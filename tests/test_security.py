"""Hostile data sets, checkpoints, task folders and mesh names: each case is a crafted file.

Nothing in a data set or a checkpoint is trusted: unpickling never runs code, no path the
metadata names is read, written or deleted outside its folder, tampering cannot be hidden
by removing the checksums, and ``zbuf-occlude verify`` names every problem.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO_ROOT, SAMPLE_MESHES, tiny_dataset

from zbuf_occlude import OccludedDataset
from zbuf_occlude.cli.main import main
from zbuf_occlude.errors import InvalidInputError, ZbufOccludeError
from zbuf_occlude.farm.config import RunOptions

CHAIR = SAMPLE_MESHES / "chair/train/chair_0001.off"


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory) -> Path:
    return tiny_dataset(tmp_path_factory.mktemp("ds") / "ds")


@pytest.fixture
def ds(dataset_dir: Path, tmp_path: Path) -> Path:
    """A fresh copy of the tiny data set, to damage."""
    return Path(shutil.copytree(dataset_dir, tmp_path / "copy", symlinks=True))


def _manifest(ds: Path) -> list[dict]:
    return [json.loads(line) for line in (ds / "manifest.jsonl").read_text().splitlines()]


def _write_manifest(ds: Path, records: list[dict]) -> None:
    (ds / "manifest.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))


# -- checkpoints never run code ------------------------------------------------------------------
class _Marker:
    """Unpickling it creates a file: the proof that a checkpoint ran code."""

    def __init__(self, path: Path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    torch = pytest.importorskip("torch", reason="checkpoints need PyTorch: pip install -e '.[learn]'")
    import numpy as np

    from zbuf_occlude.learn.data import CloudSet
    from zbuf_occlude.learn.training import TrainConfig, train

    rng = np.random.default_rng(0)
    pts = rng.normal(size=(8, 32, 3)).astype(np.float32)
    data = CloudSet(pts, np.array([0, 1] * 4, dtype=np.int64), np.zeros(8), np.arange(8))
    cfg = TrainConfig(model="pointnet", epochs=1, batch_size=4, width=0.125, patience=0, threads=1)
    folder = tmp_path_factory.mktemp("ckpt")
    train(data, 2, cfg, checkpoint_dir=folder, progress=False)
    return torch, data, cfg, folder


def _train_again(trained, folder: Path):
    from zbuf_occlude.learn.training import TrainConfig, train

    _, data, cfg, _ = trained
    return train(data, 2, TrainConfig(**{**cfg.to_dict(), "epochs": 2}), checkpoint_dir=folder, progress=False)


@pytest.mark.parametrize("which", ["last.pt", "best.pt"])
def test_a_checkpoint_whose_unpickling_runs_code_is_refused_and_runs_nothing(trained, tmp_path: Path, which: str) -> None:
    from zbuf_occlude.learn.training import load_model

    torch, _, _, folder = trained
    marker = tmp_path / "ran.txt"
    state = torch.load(folder / which, weights_only=True)
    state["history" if which == "last.pt" else "config"] = _Marker(marker)
    crafted = tmp_path / "ckpt"
    crafted.mkdir()
    torch.save(state, crafted / which)
    with pytest.raises(Exception) as exc:
        if which == "last.pt":
            _train_again(trained, crafted)  # resumes from last.pt
        else:
            load_model(crafted / which)
    assert not marker.exists(), "loading the checkpoint ran code"
    assert isinstance(exc.value, ZbufOccludeError) and re.search(rf"{crafted / which}.*refused", str(exc.value))


def _truncated(data: bytes) -> bytes:
    return data[: len(data) // 2]


@pytest.mark.parametrize(
    "damage",
    [_truncated, lambda d: b"", lambda d: b"not a checkpoint\n", lambda d: d[:100] + b"\0" * 64 + d[164:]],
    ids=["truncated", "empty", "text", "zeroed"],
)
@pytest.mark.parametrize("which", ["last.pt", "best.pt"])
def test_a_damaged_checkpoint_is_an_error_naming_the_file(trained, tmp_path: Path, damage, which: str) -> None:
    from zbuf_occlude.learn.training import load_model

    _, _, _, folder = trained
    crafted = tmp_path / "ckpt"
    crafted.mkdir()
    (crafted / which).write_bytes(damage((folder / which).read_bytes()))
    with pytest.raises(ZbufOccludeError, match=str(crafted / which)):
        if which == "last.pt":
            _train_again(trained, crafted)
        else:
            load_model(crafted / which)


def test_a_checkpoint_without_its_fields_names_the_file_and_the_field(trained, tmp_path: Path) -> None:
    from zbuf_occlude.learn.training import load_model

    torch = trained[0]
    torch.save({"model": {}}, tmp_path / "best.pt")
    with pytest.raises(ZbufOccludeError, match=r"best\.pt.*config"):
        load_model(tmp_path / "best.pt")
    torch.save(torch.zeros(3), tmp_path / "tensor.pt")
    with pytest.raises(ZbufOccludeError, match="tensor.pt"):
        load_model(tmp_path / "tensor.pt")


def test_a_good_checkpoint_still_loads_and_resumes(trained) -> None:
    from zbuf_occlude.learn.training import load_model

    _, _, _, folder = trained
    model, cfg = load_model(folder / "best.pt")
    assert cfg["model"] == "pointnet" and not model.training
    copy = folder.parent / "resume"
    shutil.copytree(folder, copy)
    assert len(_train_again(trained, copy).history) == 2


# -- the reader never follows a path out of the data set -----------------------------------------
@pytest.mark.parametrize("how", ["absolute", "dotdot", "symlink"])
def test_a_manifest_path_out_of_the_folder_is_refused_not_read(ds: Path, tmp_path: Path, how: str) -> None:
    # The outside file is a good shard with the checksum the manifest records: a reader that
    # followed the path would read it without complaint.
    outside = tmp_path / "outside"
    outside.mkdir()
    records = _manifest(ds)
    rel = records[0]["shards"][0]
    shutil.copy(ds / rel, outside / "x.h5")
    if how == "absolute":
        path = str(outside / "x.h5")
    elif how == "dotdot":
        path = "../outside/x.h5"
    else:
        (ds / "elsewhere").symlink_to(outside, target_is_directory=True)
        path = "elsewhere/x.h5"
    (ds / rel).unlink()
    records[0]["shards"] = [path]
    _write_manifest(ds, records)
    with pytest.raises(ZbufOccludeError, match=r"manifest\.jsonl:1 field 'shards': the path (is an absolute|leaves|leads outside)") as info:
        ds_read = OccludedDataset(ds)
        ds_read.to_arrays()
    assert path not in str(info.value)  # a value of the manifest: named by its field, never quoted


# -- farm-merge and generate --overwrite stay inside --out ---------------------------------------
def test_farm_merge_does_not_write_through_a_symlink_out_of_out(dataset_dir: Path, tmp_path: Path) -> None:
    from zbuf_occlude.farm import merge_farm

    victim = tmp_path / "victim"
    victim.mkdir()
    # task folder 2 holds results, with a record whose shard sits under link/; folder 1 (the
    # default --out of the merge) holds the plan and a symlink "link" to the victim folder
    task2 = Path(shutil.copytree(dataset_dir, tmp_path / "task2"))
    rec_file = task2 / "records" / "000000.json"
    rec = json.loads(rec_file.read_text())
    (task2 / "link").mkdir()
    shutil.move(task2 / rec["shards"][0], task2 / "link" / "x.h5")
    rec["shards"] = ["link/x.h5"]
    rec_file.write_text(json.dumps(rec))
    task1 = tmp_path / "task1"
    task1.mkdir()
    shutil.copy(task2 / "plan.json", task1 / "plan.json")
    (task1 / "link").symlink_to(victim, target_is_directory=True)
    with pytest.raises(ZbufOccludeError, match=r"link/x\.h5.*leads outside"):
        merge_farm([task1, task2], progress=False)
    assert list(victim.iterdir()) == []


def test_farm_merge_does_not_copy_a_record_path_with_dotdot_out_of_out(dataset_dir: Path, tmp_path: Path) -> None:
    from zbuf_occlude.farm import merge_farm

    task = Path(shutil.copytree(dataset_dir, tmp_path / "a" / "task"))
    rec_file = task / "records" / "000000.json"
    rec = json.loads(rec_file.read_text())
    (tmp_path / "a" / "evil").mkdir()
    shutil.move(task / rec["shards"][0], tmp_path / "a" / "evil" / "x.h5")
    rec["shards"] = ["../evil/x.h5"]
    rec_file.write_text(json.dumps(rec))
    out = tmp_path / "b" / "out"
    with pytest.raises(ZbufOccludeError, match=r"\.\./evil/x\.h5"):
        merge_farm([task], out, progress=False)
    assert not (tmp_path / "b" / "evil").exists()


def test_farm_merge_does_not_write_a_file_list_named_by_a_crafted_plan_out_of_out(dataset_dir: Path, tmp_path: Path) -> None:
    from zbuf_occlude.farm import merge_farm

    task = Path(shutil.copytree(dataset_dir, tmp_path / "a" / "task"))
    plan = json.loads((task / "plan.json").read_text())
    plan["objects"][0]["split"] = "../../evil"  # the file list would be task/../../evil_files.txt
    (task / "plan.json").write_text(json.dumps(plan))
    out = tmp_path / "a" / "out"
    with pytest.raises(ZbufOccludeError, match=r"evil_files\.txt.*leaves"):
        merge_farm([task], out, progress=False)
    assert not (tmp_path / "evil_files.txt").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a"]


def test_farm_merge_of_a_damaged_plan_names_it(dataset_dir: Path, tmp_path: Path) -> None:
    from zbuf_occlude.farm import merge_farm

    task = Path(shutil.copytree(dataset_dir, tmp_path / "task"))
    plan = json.loads((task / "plan.json").read_text())
    del plan["objects"][0]["label"]
    (task / "plan.json").write_text(json.dumps(plan))
    with pytest.raises(ZbufOccludeError, match=r"plan\.json.*'objects\.0\.label'"):
        merge_farm([task], tmp_path / "out", progress=False)


def test_farm_merge_removes_the_temporaries_of_dead_writers(dataset_dir: Path, tmp_path: Path) -> None:
    from zbuf_occlude.farm import merge_farm

    out = Path(shutil.copytree(dataset_dir, tmp_path / "out"))
    # a writer killed mid-write (os._exit inside atomic_path) leaves its temporary behind
    code = (
        "import os\nfrom zbuf_occlude.io.clouds import atomic_path\n"
        "with atomic_path('shards/train_000000.h5') as tmp:\n    tmp.write_bytes(b'partial')\n    os._exit(9)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    assert subprocess.run([sys.executable, "-c", code], cwd=out, env=env).returncode == 9
    temps = list((out / "shards").glob(".*.tmp"))
    assert len(temps) == 1
    merge_farm([out], progress=False)
    assert list((out / "shards").glob(".*.tmp")) == []


def _generate(out: Path, *paths: Path, overwrite: bool = False, fmt: str = "h5") -> int:
    argv = ["generate", *map(str, paths), "--out", str(out), "--views", "0:0", "--points", "32", "--dense-points", "512",
            "--resolution", "64", "--samples-per-view", "1", "--format", fmt]  # fmt: skip
    return main([*argv, "--overwrite"] if overwrite else argv)


@pytest.mark.slow
def test_generate_overwrite_does_not_delete_a_file_a_record_names_outside_out(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert _generate(out, CHAIR) == 0
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    rec_file = out / "records" / "000000.json"
    rec = json.loads(rec_file.read_text())
    rec["shards"].append(str(victim))
    rec_file.write_text(json.dumps(rec))
    status = _generate(out, CHAIR, overwrite=True)
    assert victim.exists() and victim.read_text() == "keep me"
    assert status == 2


@pytest.mark.slow
@pytest.mark.parametrize("given", ["file", "folder"])
def test_a_mesh_named_dot_dot_does_not_write_beside_out(tmp_path: Path, capsys, given: str) -> None:
    meshes = tmp_path / "chair"  # a class folder: a folder named "meshes" is refused as a class
    meshes.mkdir()
    shutil.copy(CHAIR, meshes / "...off")  # stem ".."
    shutil.copy(CHAIR, meshes / "chair_0001.off")
    out = tmp_path / "work" / "out"
    out.parent.mkdir()
    paths = [meshes / "...off", meshes / "chair_0001.off"] if given == "file" else [meshes]
    status = _generate(out, *paths, fmt="npz")  # npz: each mesh's name becomes a folder under --out
    assert sorted(p.name for p in out.parent.iterdir()) == ["out"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["chair", "work"]
    assert status == 1  # the other mesh is done
    assert "cannot name a file inside the output folder" in capsys.readouterr().err
    assert any(out.glob("chair_0001/*.npz"))


# -- symlinked subfolders of --out: nothing outside is written or deleted --------------------------
FARM_OPTIONS = ["--views", "0:0", "--points", "32", "--dense-points", "512", "--resolution", "64",
                "--samples-per-view", "1", "--no-progress"]  # fmt: skip


def _two_meshes(tmp_path: Path) -> Path:
    tree = tmp_path / "meshes"
    for rel in ("chair/train/chair_0001.off", "desk/test/desk_0201.off"):
        (tree / rel).parent.mkdir(parents=True, exist_ok=True)
        (tree / rel).symlink_to(SAMPLE_MESHES / rel)
    return tree


def _victim(tmp_path: Path, out: Path) -> dict[Path, bytes]:
    """OUT/shards and OUT/records as symlinks to folders elsewhere, holding files the farm would write."""
    files = {}
    for sub, names in (("shards", ["train_000000.h5", "test_000001.h5"]), ("records", ["000000.json", "000001.json"])):
        victim = tmp_path / "victim" / sub
        victim.mkdir(parents=True, exist_ok=True)
        for name in names:
            (victim / name).write_bytes(b"keep me " + name.encode())
            files[victim / name] = (victim / name).read_bytes()
        if (out / sub).exists():
            shutil.rmtree(out / sub)
        (out / sub).symlink_to(victim, target_is_directory=True)
    return files


def _untouched(files: dict[Path, bytes]) -> bool:
    folders = {p.parent for p in files}
    return all(p.is_file() and p.read_bytes() == b for p, b in files.items()) and sum(len(list(f.iterdir())) for f in folders) == len(files)


@pytest.mark.slow
@pytest.mark.parametrize("run", ["farm", "generate --overwrite", "farm --shard 0/2 --overwrite"])
def test_a_symlinked_subfolder_of_out_is_refused_and_nothing_outside_changes(tmp_path: Path, capsys, run: str) -> None:
    tree, out = _two_meshes(tmp_path), tmp_path / "out"
    if run == "farm":
        out.mkdir()
        argv = ["farm", str(tree), "--out", str(out), *FARM_OPTIONS]
    elif run == "generate --overwrite":
        assert _generate(out, CHAIR) == 0
        argv = ["generate", str(CHAIR), "--out", str(out), "--overwrite", *FARM_OPTIONS[:-1], "--format", "h5"]
    else:
        assert main(["farm", str(tree), "--out", str(out), "--shard", "0/2", *FARM_OPTIONS]) == 0
        argv = ["farm", str(tree), "--out", str(out), "--shard", "0/2", "--overwrite", *FARM_OPTIONS]
    files = _victim(tmp_path, out)
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert re.search(r"'(shards|records)' leads outside .*out", err), err
    assert _untouched(files)


def test_farm_merge_refuses_a_symlinked_subfolder_of_out(dataset_dir: Path, tmp_path: Path) -> None:
    from zbuf_occlude.errors import UnsafePathError
    from zbuf_occlude.farm import merge_farm

    out = Path(shutil.copytree(dataset_dir, tmp_path / "out"))
    files = _victim(tmp_path, out)
    with pytest.raises(UnsafePathError, match=r"'(shards|records)' leads outside"):
        merge_farm([out], progress=False)
    assert _untouched(files)


# -- tamper detection cannot be switched off -----------------------------------------------------
def test_a_manifest_without_checksums_is_read_only_with_verify_false(ds: Path) -> None:
    records = _manifest(ds)
    for rec in records:
        rec.pop("sha256")
    _write_manifest(ds, records)
    shard = ds / records[0]["shards"][0]
    data = bytearray(shard.read_bytes())
    data[-200:] = bytes(200)  # a changed shard nobody could notice now
    shard.write_bytes(bytes(data))
    with pytest.raises(InvalidInputError, match=r"manifest\.jsonl:1.*'sha256'.*verify=False"):
        OccludedDataset(ds)
    assert len(OccludedDataset(ds, verify=False)) == 4  # the user's explicit choice
    assert json.loads((ds / "dataset_card.json").read_text())["checksums"] == "sha256"


def test_a_changed_shard_is_still_caught_with_its_checksum(ds: Path) -> None:
    shard = ds / _manifest(ds)[0]["shards"][0]
    data = bytearray(shard.read_bytes())
    data[-200:] = bytes(200)
    shard.write_bytes(bytes(data))
    with pytest.raises(ZbufOccludeError, match="was changed after"):
        OccludedDataset(ds).to_arrays()


# -- class names with control characters ---------------------------------------------------------
@pytest.mark.parametrize("cls", ["a\x85b", "c\nd", "e\u2028f"])
def test_a_class_name_with_a_control_character_is_refused_before_any_work(tmp_path: Path, cls: str, monkeypatch) -> None:
    import zbuf_occlude.mesh.load as mesh
    from zbuf_occlude.farm import FarmParams, run_farm

    (tmp_path / "meshes" / cls).mkdir(parents=True)
    shutil.copy(CHAIR, tmp_path / "meshes" / cls / "x_0001.off")
    shutil.copytree(SAMPLE_MESHES / "chair", tmp_path / "meshes" / "chair")
    monkeypatch.setattr(mesh, "load_mesh", lambda *a: pytest.fail("a mesh was loaded"))  # the worker imports it when it runs
    with pytest.raises(InvalidInputError, match=re.escape(f"class name {cls!r} holds the control character")):
        run_farm(
            tmp_path / "meshes", tmp_path / "out", params=FarmParams(views="0:0", dense_points=256), options=RunOptions(progress=False)
        )


def test_shape_names_with_a_control_character_are_refused_by_the_reader(ds: Path) -> None:
    # "a\x85b" reads as two lines to str.splitlines: the labels after it would shift by one
    names = (ds / "shape_names.txt").read_text().split("\n")
    names[0] = "cha\x85ir"
    (ds / "shape_names.txt").write_text("\n".join(names))
    card = json.loads((ds / "dataset_card.json").read_text())
    card["shape_names"][0] = "cha\x85ir"
    (ds / "dataset_card.json").write_text(json.dumps(card))
    (ds / "dataset_card.json.sha256").unlink()  # a crafted data set: its author leaves out (or redoes) the checksum
    with pytest.raises(ZbufOccludeError, match=r"shape_names\.txt:1.*U\+0085"):
        OccludedDataset(ds)


# -- zbuf-occlude verify ---------------------------------------------------------------------------
def test_verify_a_clean_data_set_exits_0_with_one_line(dataset_dir: Path, capsys) -> None:
    assert main(["verify", str(dataset_dir)]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert out == [f"OK {dataset_dir}: 2 objects, 2 files (SHA-256 checked), 4 samples"]


def test_verify_names_every_problem_and_exits_1(ds: Path, tmp_path: Path, capsys) -> None:
    records = _manifest(ds)
    shard0, shard1 = (ds / r["shards"][0] for r in records)
    shard0.write_bytes(shard0.read_bytes()[:-8] + bytes(8))  # changed bytes
    records[1]["shards"] = ["../" + ds.name + "/" + records[1]["shards"][0]]  # a path through ..
    records.append({"status": "ok", "name": "x"})  # a record without its fields
    _write_manifest(ds, records)
    (ds / "train_files.txt").write_text("/etc/passwd\n")
    assert main(["verify", str(ds)]) == 1
    err = capsys.readouterr().err
    assert "differs from its SHA-256" in err and str(shard0.name) in err
    assert "manifest.jsonl:2 field 'shards'" in err and "'..'" in err
    assert "manifest.jsonl:3 is not a valid manifest record" in err and "'split'" in err
    assert "train_files.txt:1" in err and "absolute" in err
    assert shard1.is_file()


def test_verify_reports_missing_checksums(ds: Path, capsys) -> None:
    records = _manifest(ds)
    records[0].pop("sha256")
    _write_manifest(ds, records)
    assert main(["verify", str(ds)]) == 1
    assert "no SHA-256 (field 'sha256') although the card" in capsys.readouterr().err


def test_verify_usage_errors_exit_2(tmp_path: Path, capsys) -> None:
    assert main(["verify", str(tmp_path / "missing")]) == 2
    err = capsys.readouterr().err
    assert "no such folder" in err and str(tmp_path / "missing") in err
    with pytest.raises(SystemExit) as exc:
        main(["verify"])
    assert exc.value.code == 2


def test_verify_a_folder_that_is_not_a_data_set_exits_1(tmp_path: Path, capsys) -> None:
    assert main(["verify", str(tmp_path)]) == 1
    assert "no dataset_card.json" in capsys.readouterr().err


def test_paths_inside_the_folder_pass_and_others_do_not(tmp_path: Path) -> None:
    from zbuf_occlude.io.safe_paths import check_relative_name, path_inside

    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "in").symlink_to(tmp_path / "d", target_is_directory=True)  # a symlink that stays inside
    assert path_inside(tmp_path / "d", "in/x.h5", what="t") == tmp_path / "d" / "in" / "x.h5"
    for bad in ["/etc/passwd", "../x", "a/../../x", "", 3, None]:
        with pytest.raises(ZbufOccludeError):
            path_inside(tmp_path / "d", bad, what="t")
    assert check_relative_name("chair/train/chair_0001", what="t") == "chair/train/chair_0001"
    for bad in ["..", ".", "/x", "a//b", "a/./b", "c\nd"]:
        with pytest.raises(ZbufOccludeError):
            check_relative_name(bad, what="t")
