"""``export --to pcn``: the export read back as PoinTr's ``PCNDataset`` reads it (``PCN.json``, the
file list of ``_get_file_list``, one ``.pcd`` per view and per complete cloud), each file parsed
both by pypcd4 and by hand from its header and binary body, the same float32 points as the shard,
ShapeNet's synset ids; and the refusals, each one line."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import SAMPLE_MESHES

from zbuf_occlude.cli.export import TARGET_NAMES
from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.exporters import TARGETS, export
from zbuf_occlude.protocols import ProtocolOptions, get_protocol, read_arrays_h5, run_protocol
from zbuf_occlude.protocols.pcn import COMPLETE_POINTS, N_VIEWS

#: A ShapeNet class (train) and one that ShapeNet lacks (test).
MESHES = ("chair/train/chair_0001.off", "desk/test/desk_0201.off")
#: PoinTr's cfgs/dataset_configs/PCN.yaml, relative to its data/PCN folder.
PARTIAL_POINTS_PATH = "%s/partial/%s/%s/%02d.pcd"
COMPLETE_POINTS_PATH = "%s/complete/%s/%s.pcd"
N_POINTS = 16384


def _generate(root: Path, meshes: dict[str, str]) -> Path:
    """``generate --protocol pcn`` of shipped meshes, ``{path in the mesh folder: shipped mesh}``."""
    for rel, shipped in meshes.items():
        (root / "meshes" / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(SAMPLE_MESHES / shipped, root / "meshes" / rel)
    run = run_protocol(get_protocol("pcn"), [root / "meshes"], root / "pcn", ProtocolOptions(seed=5), progress=False)
    assert run.done == len(meshes) and not run.failures
    return root / "pcn"


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return _generate(tmp_path_factory.mktemp("pcn"), {rel: rel for rel in MESHES})


def _shards(source: Path) -> dict[str, dict]:
    """Each shard's arrays by its object's file name (the model id)."""
    return {Path(a["attrs"]["name"]).name: a for a in map(read_arrays_h5, sorted((source / "shards").glob("pcn_*.h5")))}


def _read_pcd_by_hand(path: Path) -> np.ndarray:
    """A binary PCD of float32 x y z, from its header and body with numpy alone (PCL's PCD v0.7)."""
    raw = path.read_bytes()
    header, at = {}, 0
    while True:
        end = raw.index(b"\n", at)
        key, _, value = raw[at:end].decode("ascii").partition(" ")
        at = end + 1
        if not key.startswith("#"):
            header[key] = value.split()
        if key == "DATA":
            break
    assert header["FIELDS"] == ["x", "y", "z"] and header["SIZE"] == ["4"] * 3 and header["TYPE"] == ["F"] * 3
    assert header["COUNT"] == ["1"] * 3 and header["DATA"] == ["binary"] and header["HEIGHT"] == ["1"]
    n = int(header["POINTS"][0])
    assert int(header["WIDTH"][0]) == n and len(raw) - at == n * 12
    return np.frombuffer(raw[at:], dtype="<f4").reshape(n, 3)


def _read_pcd(path: Path) -> np.ndarray:
    """The file by pypcd4 and by hand, which must agree."""
    from pypcd4 import PointCloud

    ours = _read_pcd_by_hand(path)
    theirs = PointCloud.from_path(path).numpy()
    np.testing.assert_array_equal(theirs, ours)
    return ours


def _pointr_file_list(root: Path, subset: str) -> list[dict]:
    """PoinTr's PCN._get_file_list, by hand: ``n_renderings = 8 if subset == 'train' else 1``."""
    n_renderings = 8 if subset == "train" else 1
    file_list = []
    for dc in json.loads((root / "PCN.json").read_text()):
        for s in dc[subset]:
            file_list.append({
                "taxonomy_id": dc["taxonomy_id"], "model_id": s,
                "partial_path": [root / (PARTIAL_POINTS_PATH % (subset, dc["taxonomy_id"], s, i)) for i in range(n_renderings)],
                "gt_path": root / (COMPLETE_POINTS_PATH % (subset, dc["taxonomy_id"], s)),
            })  # fmt: skip
    return file_list


def test_pointr_reads_the_export_as_its_pcn_dataset_does(source, tmp_path):
    out = tmp_path / "PCN"
    result = export(source, "pcn", out)
    assert result.samples == {"train": 1, "test": 1} and result.unit == "model" and result.files == [out / "PCN.json", out / "export.json"]
    categories = json.loads((out / "PCN.json").read_text())
    assert categories == [
        {"taxonomy_id": "03001627", "taxonomy_name": "chair", "train": ["chair_0001"], "val": [], "test": []},
        {"taxonomy_id": "desk", "taxonomy_name": "desk", "train": [], "val": [], "test": ["desk_0201"]},
    ]
    shards = _shards(source)
    for subset, expected in (("train", ["chair_0001"]), ("val", []), ("test", ["desk_0201"])):
        file_list = _pointr_file_list(out, subset)
        assert [s["model_id"] for s in file_list] == expected
        for sample in file_list:
            arrays = shards[sample["model_id"]]
            offsets = arrays["partial_offsets"]
            for i, path in enumerate(sample["partial_path"]):
                partial = _read_pcd(path)
                assert partial.dtype == np.float32 and partial.shape[1] == 3
                np.testing.assert_array_equal(partial, arrays["partial"][offsets[i] : offsets[i + 1]])
            gt = _read_pcd(sample["gt_path"])
            assert gt.shape == (N_POINTS, 3) == (COMPLETE_POINTS, 3)  # PCNDataset asserts N_POINTS
            np.testing.assert_array_equal(gt, arrays["complete"])
            # every view the shard holds is written, also for test (PoinTr reads 00 there)
            views = sorted(p.name for p in sample["partial_path"][0].parent.iterdir())
            assert views == [f"{i:02d}.pcd" for i in range(N_VIEWS)] == [f"{i:02d}.pcd" for i in range(len(offsets) - 1)]


def test_open3d_reads_the_pcd_files_as_pointr_does(source, tmp_path):
    open3d = pytest.importorskip("open3d")
    export(source, "pcn", tmp_path / "PCN")
    path = tmp_path / "PCN" / (COMPLETE_POINTS_PATH % ("train", "03001627", "chair_0001"))
    points = np.array(open3d.io.read_point_cloud(str(path)).points)  # PoinTr's IO._read_pcd
    np.testing.assert_array_equal(points.astype(np.float32), _shards(source)["chair_0001"]["complete"])


def test_a_val_object_goes_to_val_and_shapenet55_keeps_synset_ids_only(source, tmp_path):
    moved = tmp_path / "src"
    shutil.copytree(source, moved)
    with h5py.File(next(moved.glob("shards/pcn_*.h5")), "r+") as f:  # the chair, made a val object
        assert f.attrs["name"] == "chair/train/chair_0001"
        f.attrs["split"] = "val"
    result = export(moved, "pcn", tmp_path / "out")
    assert result.samples == {"val": 1, "test": 1}
    chair = json.loads((tmp_path / "out" / "PCN.json").read_text())[0]
    assert (chair["train"], chair["val"], chair["test"]) == ([], ["chair_0001"], [])
    assert len(_pointr_file_list(tmp_path / "out", "val")[0]["partial_path"]) == 1
    with pytest.raises(InvalidInputError, match="'desk'"):
        export(source, "pcn", tmp_path / "strict", label_set_name="shapenet55")
    assert not (tmp_path / "strict").exists()


def test_two_objects_of_one_model_id_are_refused_and_nothing_is_written(tmp_path):
    rel = "chair/train/chair_0001.off"
    source = _generate(tmp_path, {rel: rel, "chair/test/chair_0001.off": rel})  # one file name in train and test
    with pytest.raises(InvalidInputError, match="'chair/test/chair_0001' and 'chair/train/chair_0001'.*'chair_0001'"):
        export(source, "pcn", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_rerun_replaces_its_own_files_and_removes_models_no_longer_there(source, tmp_path):
    out = tmp_path / "out"
    export(source, "pcn", out)
    chair_only = tmp_path / "chair"
    shutil.copytree(source, chair_only)
    record = json.loads((chair_only / "protocol.json").read_text())
    record["objects"] = record["objects"][:1]
    (chair_only / "protocol.json").write_text(json.dumps(record))
    (chair_only / "shards" / "pcn_000001.h5").unlink()
    export(chair_only, "pcn", out)
    assert [c["taxonomy_id"] for c in json.loads((out / "PCN.json").read_text())] == ["03001627"]
    assert not (out / "test").exists()
    assert len(list((out / "train").rglob("*.pcd"))) == N_VIEWS + 1


def _refused(argv: list[str], capsys) -> str:
    assert cli_main(["export", *argv]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_refusals_are_one_line_and_make_no_folder(source, tmp_path, capsys):
    from conftest import tiny_dataset

    dataset = tiny_dataset(tmp_path / "ds")
    other = tmp_path / "depth_run"
    other.mkdir()
    (other / "protocol.json").write_text(json.dumps({"protocol": "depth", "objects": []}))
    empty = tmp_path / "empty"
    empty.mkdir()
    out = str(tmp_path / "out")
    cases = [
        ([str(dataset), "--to", "pcn"], "holds no complete clouds.*generate MESHES --protocol pcn"),
        ([str(source), "--to", "pointnet-h5"], "`generate --protocol` folder.*--to pcn"),
        ([str(source), "--to", "modelnet-txt"], "`generate --protocol` folder.*--to pcn"),
        ([str(other), "--to", "pcn"], re.escape(str(other / "protocol.json")) + r" is a `generate --protocol depth` run.*--protocol pcn"),
        ([str(empty), "--to", "pcn"], "holds no protocol.json: --to pcn reads a `generate --protocol pcn` folder"),
        ([str(source), "--to", "pcn", "--seed", "1"], "--seed 1 applies to --to pointnet-h5, not to --to pcn; leave it out"),
        ([str(source), "--to", "pcn", "--list-prefix", "data/PCN"], "--list-prefix data/PCN applies to --to pointnet-h5, not to --to pcn"),
        (
            [str(source), "--to", "pcn", "--label-set", "modelnet40"],
            "--to pcn takes --label-set own or --label-set shapenet55, not --label-set modelnet40",
        ),
        ([str(dataset), "--to", "modelnet-txt", "--seed", "1"], "--seed 1 applies to --to pointnet-h5, not to --to modelnet-txt"),
    ]
    for argv, message in cases:
        assert re.search(message, _refused([*argv, "--out", out], capsys)), argv
        assert not Path(out).exists()


def test_the_cli_names_every_target():
    assert TARGET_NAMES == tuple(TARGETS)


def test_a_foreign_pcn_json_is_refused_before_any_file_is_written(tmp_path):
    """A clone of PoinTr ships data/PCN/PCN.json: exporting into it is refused, and nothing is written there."""
    from zbuf_occlude.errors import UnsafePathError
    from zbuf_occlude.exporters import export
    from zbuf_occlude.protocols import get_protocol, run_protocol

    (tmp_path / "meshes" / "chair" / "train").mkdir(parents=True)
    shutil.copy(SAMPLE_MESHES / "chair/train/chair_0001.off", tmp_path / "meshes" / "chair" / "train" / "chair_0001.off")
    run_protocol(get_protocol("pcn"), [tmp_path / "meshes"], tmp_path / "run", progress=False)
    out = tmp_path / "PCN"
    out.mkdir()
    (out / "PCN.json").write_text("[]\n")
    with pytest.raises(UnsafePathError, match="PCN.json"):
        export(tmp_path / "run", "pcn", out)
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["PCN.json"]
    assert not any(out.rglob("*.pcd"))
