"""A data set names its meshes relative to the folder it was given (the input root), never by
their absolute paths: the same meshes in two places give the same bytes.

Shipped meshes (``data/samples``) copied into two folders, one pose, 32-point samples.
"""

from __future__ import annotations

import json
import shlex
import shutil
import sys
from pathlib import Path

import h5py
import pytest

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.dataset.layout import CARD_FILE, MANIFEST_FILE, PLAN_FILE
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.farm.journal import input_root, portable_command
from zbuf_occlude.mesh.inputs.plan import FarmObject
from zbuf_occlude.mesh.load import load_mesh

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
MESHES = ("chair/train/chair_0001.off", "sofa/test/sofa_0681.off")
ARGS = ["--views", "0:0", "--samples-per-view", "1", "--points", "32", "--dense-points", "500", "--resolution", "64"]
#: What differs between two builds of one data set: when and by which process (measured: nothing else does).
VOLATILE = {"created", "started", "finished_at", "time_s", "pid", "peak_rss_mb"}


def _copy_meshes(folder: Path) -> Path:
    for rel in MESHES:
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(SAMPLES / rel, folder / rel)
    return folder


def _without_volatile(value):
    if isinstance(value, dict):
        return {k: _without_volatile(v) for k, v in value.items() if k not in VOLATILE}
    return [_without_volatile(v) for v in value] if isinstance(value, list) else value


def _contents(out: Path) -> dict[str, object]:
    """Every file of ``out``: JSON without its volatile fields, other files as bytes (the card's
    SHA-256 file left out: it hashes the card's time of creation)."""
    files = {}
    for path in sorted(p for p in out.rglob("*") if p.is_file() and not p.name.endswith(".sha256")):
        rel = path.relative_to(out).as_posix()
        if path.suffix == ".json":
            files[rel] = _without_volatile(json.loads(path.read_text()))
        elif path.suffix == ".jsonl":
            files[rel] = [_without_volatile(json.loads(line)) for line in path.read_text().splitlines()]
        else:
            files[rel] = path.read_bytes()
    return files


def _no_path_of(folder: Path, out: Path) -> None:
    for path in out.rglob("*"):
        if path.is_file():
            assert str(folder).encode() not in path.read_bytes(), path
            if path.suffix in (".json", ".jsonl"):  # nor the machine's name
                assert b'"host"' not in path.read_bytes(), path


def _cli(monkeypatch, args: list[str]) -> int:
    """``zbuf-occlude ARGS`` as typed in a shell: the card records ``sys.argv``, with the absolute
    paths given here and the program's own (a virtual environment's)."""
    monkeypatch.setattr(sys, "argv", [str(Path(sys.prefix) / "bin" / "zbuf-occlude"), *args])
    return cli_main(args)


@pytest.mark.slow
def test_a_farm_of_the_same_meshes_in_two_places_is_the_same_bytes(tmp_path, monkeypatch):
    outs = []
    for place in ("a", "b/deeper"):
        meshes = _copy_meshes(tmp_path / place / "meshes")
        assert _cli(monkeypatch, ["farm", str(meshes), "--out", str(tmp_path / place / "out"), *ARGS, "--no-progress"]) == 0
        outs.append(tmp_path / place / "out")
        _no_path_of(tmp_path / place, outs[-1])
    assert _contents(outs[0]) == _contents(outs[1])
    card, plan = (json.loads((outs[0] / name).read_text()) for name in (CARD_FILE, PLAN_FILE))
    assert card["source"] == plan["source"] == "meshes"  # the root's name, once
    assert card["commands"] == [f"zbuf-occlude farm meshes --out out {' '.join(ARGS)} --no-progress"]
    assert sorted(o["source"] for o in plan["objects"]) == sorted(MESHES)
    ds = OccludedDataset(outs[1])
    for i in range(len(ds)):  # the input root joined with a sample's source is its mesh
        meta = ds.metadata(i)
        assert meta["source"] in MESHES and load_mesh(tmp_path / "b/deeper/meshes" / meta["source"]).faces.size
    assert cli_main(["verify", str(outs[1])]) == 0


@pytest.mark.slow
def test_generate_of_mesh_files_in_two_places_is_the_same_bytes(tmp_path, monkeypatch):
    # several files given: the root is the deepest folder holding them; h5 rows carry each sample's source
    outs = []
    for place in ("a", "b/deeper"):
        meshes = _copy_meshes(tmp_path / place / "meshes")
        args = ["generate", *(str(meshes / rel) for rel in MESHES), "--out", str(tmp_path / place / "out"), *ARGS]
        assert _cli(monkeypatch, args) == 0
        outs.append(tmp_path / place / "out")
        _no_path_of(tmp_path / place, outs[-1])
    assert _contents(outs[0]) == _contents(outs[1])
    with h5py.File(outs[0] / "occluded_train.h5", "r") as f:
        assert set(f["source"].asstr()[()]) == {"chair/train/chair_0001.off"}
    card = json.loads((outs[0] / CARD_FILE).read_text())
    assert card["source"] == "meshes"
    assert card["commands"] == [f"zbuf-occlude generate {' '.join(f'meshes/{rel}' for rel in MESHES)} --out out {' '.join(ARGS)}"]


@pytest.mark.slow
def test_a_list_files_meshes_are_named_as_the_list_names_them(tmp_path):
    meshes = _copy_meshes(tmp_path / "data" / "meshes")
    lists = tmp_path / "data" / "lists"
    lists.mkdir()
    (lists / "all.txt").write_text("".join(f"../meshes/{rel} {rel.split('/')[0]} {rel.split('/')[1]}\n" for rel in MESHES))
    out = tmp_path / "out"
    assert cli_main(["farm", str(lists / "all.txt"), "--out", str(out), *ARGS, "--no-progress"]) == 0
    _no_path_of(tmp_path, out)
    records = [json.loads(line) for line in (out / MANIFEST_FILE).read_text().splitlines()]
    # the list's folder holds the list, not the meshes: the root is the folder holding both
    assert sorted(r["source"] for r in records) == sorted(f"meshes/{rel}" for rel in MESHES)
    assert json.loads((out / CARD_FILE).read_text())["source"] == "data"
    assert all(r["status"] == "ok" for r in records) and meshes.is_dir()


@pytest.mark.slow
def test_skipped_inputs_are_named_relative_to_the_root_also_after_a_merge(tmp_path, monkeypatch):
    import os

    meshes = _copy_meshes(tmp_path / "meshes")
    shutil.copy(SAMPLES / MESHES[0], os.fsdecode(bytes(meshes / "chair" / "train") + b"/caf\xe9.off"))  # not UTF-8
    whole, tasks = tmp_path / "whole", tmp_path / "tasks"
    assert _cli(monkeypatch, ["farm", str(meshes), "--out", str(whole), *ARGS, "--no-progress"]) == 1
    for task in ("0/2", "1/2"):
        assert _cli(monkeypatch, ["farm", str(meshes), "--out", str(tasks), "--shard", task, *ARGS, "--no-progress"]) == 1
    assert _cli(monkeypatch, ["farm-merge", str(tasks), "--no-progress"]) == 1  # the merged data set misses that input too
    for out in (whole, tasks):
        card = json.loads((out / CARD_FILE).read_text())
        assert [s["path"] for s in card["skipped_inputs"]] == ["chair/train/caf\\xe9.off"], out
        assert card["commands"][0].startswith("zbuf-occlude farm meshes --out "), card["commands"]
        _no_path_of(tmp_path, out)


def test_a_recorded_command_names_paths_by_the_data_set_the_input_root_or_the_file_name(tmp_path, monkeypatch):
    root, out, sensor = tmp_path / "in" / "meshes", tmp_path / "runs" / "set", tmp_path / "elsewhere" / "lidar.json"
    for folder in (root / "chair", out / "shards", sensor.parent):
        folder.mkdir(parents=True)
    sensor.write_text("{}")
    monkeypatch.chdir(tmp_path / "in")
    argv = [
        "/home/someone/.venv/bin/zbuf-occlude", "farm", str(root), "meshes/chair", "--out", str(out),
        f"--list={out / 'shards'}", "--sensor", str(sensor), "--views", "0:0,30:90", "--seed=7", "chair", "",
    ]  # fmt: skip
    assert portable_command(argv, out=out, root=root) == (
        "zbuf-occlude farm meshes meshes/chair --out set --list=set/shards --sensor lidar.json --views 0:0,30:90 "
        "--seed=7 chair ''"  # a relative word naming nothing here is kept as typed
    )
    # a merge has no input root: the folders it reads are named by their own names
    assert portable_command(["zbuf-occlude", "farm-merge", str(root), "--out", str(out)], out=out) == (
        "zbuf-occlude farm-merge meshes --out set"
    )
    assert portable_command(["zbuf-occlude", "farm", "/"], out=out) == "zbuf-occlude farm /"
    # a command given as text (RunOptions.command) is split as a shell would; one it cannot split, at white space
    assert portable_command(f"my-script --out '{out}' --note 'a b'", out=out) == "my-script --out set --note 'a b'"
    assert portable_command(f"my-script {out} 'unclosed", out=out) == shlex.join(["my-script", "set", "'unclosed"])


def _obj(source: str) -> FarmObject:
    return FarmObject(0, "x", source, "c", "train", 0)


def test_the_input_root_is_the_folder_given_or_the_deepest_folder_holding_every_input(tmp_path):
    (tmp_path / "in" / "chair" / "train").mkdir(parents=True)
    deep = str(tmp_path / "in" / "chair" / "train" / "chair_0001.off")
    # a folder given alone is the root, however deep its meshes lie
    assert input_root([tmp_path / "in"], [_obj(deep)]) == tmp_path / "in"
    # mesh files: the folder holding them all
    other = str(tmp_path / "in" / "sofa" / "sofa_0001.off")
    assert input_root([deep, other], [_obj(deep), _obj(other)]) == tmp_path / "in"
    assert input_root([deep], [_obj(deep)]) == tmp_path / "in" / "chair" / "train"
    # a list file beside its meshes, or in a folder next to them
    assert input_root([tmp_path / "in" / "list.txt"], [_obj(deep)]) == tmp_path / "in"
    assert input_root([tmp_path / "lists" / "list.txt"], [_obj(deep)]) == tmp_path
    # a ready plan without its inputs: the folder holding its meshes
    assert input_root([], [_obj(deep), _obj(other)]) == tmp_path / "in"


def test_a_failed_meshs_record_names_it_relative_to_the_root(tmp_path):
    from zbuf_occlude.farm import FarmParams
    from zbuf_occlude.farm.worker import process_object

    (tmp_path / "in" / "bad").mkdir(parents=True)
    (tmp_path / "in" / "bad" / "broken.off").write_text("OFF\ngarbage here\n")
    obj = FarmObject(0, "bad/broken", "bad/broken.off", "bad", "train", 0)
    rec = process_object(obj, FarmParams(views="0:0", samples_per_view=1, n_points=8, dense_points=100), tmp_path / "out", tmp_path / "in")
    assert rec["status"] == "failed" and rec["source"] == "bad/broken.off"
    assert "bad/broken.off" in rec["error"] and str(tmp_path) not in rec["error"]
