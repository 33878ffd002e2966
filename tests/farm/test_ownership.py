"""Nothing lost: a run replaces or deletes only what an earlier run of ours in ``--out`` wrote.

Each test builds the folder a user may really have (a PointNet download, their own ``records/``,
meshes inside ``--out``), runs the command (``--overwrite`` or not) and checks that every file
that was not ours is still there, byte for byte (zbuf_occlude.farm.ownership).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from conftest import SAMPLE_MESHES

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.dataset.layout import CARD_FILE, PLAN_FILE

CHAIR = SAMPLE_MESHES / "chair/train/chair_0001.off"
#: One pose, few points: each run takes a second or two on llvmpipe.
SMALL = ["--views", "0:0", "--dense-points", "500", "--samples-per-view", "1", "--points", "64", "--resolution", "64"]


def _snapshot(root: Path) -> dict[str, bytes]:
    """Every regular file under ``root`` and its bytes."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _meshes(root: Path) -> Path:
    (root / "chair" / "train").mkdir(parents=True)
    shutil.copy(CHAIR, root / "chair" / "train" / "chair_0001.off")
    return root


def _farm(src: Path, out: Path, *extra: str) -> int:
    return cli_main(["farm", str(src), "--out", str(out), *SMALL, *extra])


def _generate(src: Path, out: Path, *extra: str) -> int:
    return cli_main(["generate", str(src), "--out", str(out), *SMALL, *extra])


def _pointnet_download(out: Path) -> None:
    out.mkdir(parents=True)
    (out / "shape_names.txt").write_text("airplane\nbathtub\n")
    (out / "train_files.txt").write_text("data/modelnet40_ply_hdf5_2048/ply_data_train0.h5\n")


def _users_own_journal_names(out: Path) -> None:
    for folder in ("records", "tasks", "shards"):
        (out / folder).mkdir(parents=True)
        (out / folder / "notes.txt").write_text(f"my own {folder}\n")
    (out / "test_files.txt").write_text("mine.h5\n")
    (out / "manifest.jsonl").write_text('{"mine": true}\n')


@pytest.mark.parametrize("make", [_pointnet_download, _users_own_journal_names], ids=["pointnet-download", "own-records"])
@pytest.mark.parametrize("command", [_farm, _generate], ids=["farm", "generate"])
@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]], ids=["resume", "overwrite"])
def test_a_folder_with_no_run_of_ours_is_refused_and_left_as_it_was(tmp_path, capsys, make, command, overwrite):
    src, out = _meshes(tmp_path / "meshes"), tmp_path / "out"
    make(out)
    before = _snapshot(out)
    assert command(src, out, *overwrite) == 2
    err = capsys.readouterr().err
    assert "not written by zbuf_occlude" in err and str(out) in err and err.count("\n") == 1
    assert _snapshot(out) == before
    assert not (out / PLAN_FILE).exists()


@pytest.mark.slow
def test_empty_folders_of_our_names_are_no_reason_to_refuse(tmp_path):
    src, out = _meshes(tmp_path / "meshes"), tmp_path / "out"
    for name in ("shards", "records", "tasks"):
        (out / name).mkdir(parents=True)
    (out / "README.txt").write_text("a file of another name stays\n")
    assert _farm(src, out) == 0
    assert (out / CARD_FILE).is_file() and (out / "README.txt").read_text() == "a file of another name stays\n"


def test_a_plan_that_is_not_ours_is_refused_even_with_overwrite(tmp_path, capsys):
    src, out = _meshes(tmp_path / "meshes"), tmp_path / "out"
    out.mkdir()
    (out / PLAN_FILE).write_text('{"travel": "plan"}\n')
    (out / "shards").mkdir()
    (out / "shards" / "photo.jpg").write_bytes(b"\xff\xd8")
    before = _snapshot(out)
    assert _farm(src, out, "--overwrite") == 2
    assert f"{out / PLAN_FILE} was not written by zbuf_occlude" in capsys.readouterr().err
    assert _snapshot(out) == before


@pytest.mark.parametrize("command", [_farm, _generate], ids=["farm", "generate"])
@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]], ids=["resume", "overwrite"])
@pytest.mark.parametrize("inside", ["records", "shards/meshes", "."], ids=["records", "nested", "out-itself"])
def test_an_input_inside_out_is_refused_before_anything_is_touched(tmp_path, capsys, command, overwrite, inside):
    out = tmp_path / "out"
    src = _meshes(out / inside) if inside != "." else _meshes(out)
    before = _snapshot(out)
    assert command(src, out, *overwrite) == 2
    err = capsys.readouterr().err
    assert "lies inside --out" in err or "lies inside the input folder" in err
    assert _snapshot(out) == before


@pytest.mark.parametrize("command", [_farm, _generate], ids=["farm", "generate"])
def test_a_list_file_naming_meshes_inside_out_is_refused(tmp_path, capsys, command):
    out = tmp_path / "out"
    mesh = _meshes(out / "records") / "chair" / "train" / "chair_0001.off"
    listing = tmp_path / "list.txt"
    listing.write_text(f"{mesh} chair train\n")
    before = _snapshot(out)
    status = command(listing, out, "--overwrite") if command is _farm else command(mesh, out, "--overwrite")
    assert status == 2
    assert "lies inside --out" in capsys.readouterr().err
    assert _snapshot(out) == before


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["h5", "npz"])
def test_overwrite_deletes_only_what_the_earlier_run_recorded(tmp_path, fmt):
    src, out = _meshes(tmp_path / "meshes"), tmp_path / "out"
    assert _generate(src, out, "--format", fmt) == 0
    ours = _snapshot(out)
    record = json.loads((out / "records" / "000000.json").read_text())
    assert record["shards"] and all(rel in ours for rel in record["shards"])
    # the user's own files, beside and among ours
    mine = {"notes.txt": b"top\n", "shards/mine.h5": b"not a shard\n", "records/mine.json": b"{}\n"}
    if fmt == "npz":
        mine[str(Path(record["shards"][0]).parent / "mine.txt")] = b"beside the samples\n"
    for rel, data in mine.items():
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_bytes(data)
    assert _generate(src, out, "--format", fmt, "--seed", "5", "--overwrite") == 0
    after = _snapshot(out)
    assert all(after.get(rel) == data for rel, data in mine.items())
    for rel in record["shards"]:  # the earlier run's samples were replaced by the new run's
        assert rel not in after or after[rel] != ours[rel]


@pytest.mark.slow
def test_overwrite_of_a_sharded_task_keeps_the_other_tasks_objects(tmp_path):
    src, out = tmp_path / "meshes", tmp_path / "out"
    for rel in ["chair/train/chair_0001.off", "sofa/test/sofa_0681.off"]:
        (src / Path(rel).parent).mkdir(parents=True, exist_ok=True)
        shutil.copy(SAMPLE_MESHES / rel, src / rel)
    assert _farm(src, out, "--shard", "0/2") == 0 and _farm(src, out, "--shard", "1/2") == 0
    records = sorted(p.name for p in (out / "records").iterdir())
    other = {rel: data for rel, data in _snapshot(out).items() if rel.startswith("records/000001") or "_000001" in rel}
    assert _farm(src, out, "--shard", "0/2", "--overwrite") == 0
    after = _snapshot(out)
    assert other and all(after[rel] == data for rel, data in other.items())
    assert sorted(p.name for p in (out / "records").iterdir()) == records


def _task_folders(tmp_path: Path) -> tuple[Path, Path, Path]:
    src = tmp_path / "meshes"
    for rel in ["chair/train/chair_0001.off", "sofa/test/sofa_0681.off"]:
        (src / Path(rel).parent).mkdir(parents=True, exist_ok=True)
        shutil.copy(SAMPLE_MESHES / rel, src / rel)
    a, b = tmp_path / "task0", tmp_path / "task1"
    assert _farm(src, a, "--shard", "0/2") == 0 and _farm(src, b, "--shard", "1/2") == 0
    return src, a, b


@pytest.mark.slow
def test_merge_into_a_folder_with_foreign_files_is_refused(tmp_path, capsys):
    _, a, b = _task_folders(tmp_path)
    out = tmp_path / "merged"
    _pointnet_download(out)
    before = _snapshot(out)
    assert cli_main(["farm-merge", str(a), str(b), "--out", str(out)]) == 2
    assert "not written by zbuf_occlude" in capsys.readouterr().err
    assert _snapshot(out) == before


@pytest.mark.slow
@pytest.mark.parametrize("damage", ["deep", "missing"])
def test_a_merge_that_cannot_finish_writes_nothing(tmp_path, capsys, damage):
    _, a, b = _task_folders(tmp_path)
    capsys.readouterr()  # the task runs' own output (their progress lines)
    record = b / "records" / "000001.json"
    if damage == "deep":
        record.write_text("[" * 100_000 + "]" * 100_000)
    else:
        record.unlink()
    out = tmp_path / "merged"
    assert cli_main(["farm-merge", str(a), str(b), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "1 of 2 objects have no result yet" in err and err.count("\n") == 1
    assert not out.exists() or _snapshot(out) == {}


def test_protocol_overwrite_leaves_shards_it_did_not_write(tmp_path, capsys):
    src, out = _meshes(tmp_path / "meshes"), tmp_path / "out"
    (out / "shards").mkdir(parents=True)
    (out / "shards" / "my_results.h5").write_bytes(b"precious\n")
    args = ["generate", str(src), "--out", str(out), "--protocol", "modelnet40-c-occlusion", "--severity", "1", "--overwrite"]
    assert cli_main(args) == 2
    assert "not written by zbuf_occlude" in capsys.readouterr().err
    assert (out / "shards" / "my_results.h5").read_bytes() == b"precious\n"
