"""``export`` writes each target in the frame its networks train in (+y up), held against the
loaders' own augmentation: PointNet's ``provider.rotate_point_cloud`` turns a cloud about y
("along up direction"), so in an export the object's base must stay on the plane y = min under
that turn.  ``up`` chooses another frame; ``up="+z"`` gives the data set's own values."""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest
from conftest import SAMPLE_MESHES, tiny_dataset
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.exporters import export
from zbuf_occlude.exporters.base import UP_AXES, turn_up
from zbuf_occlude.io.owned import LEDGER_FILE

#: The base of an object: points this close to its lowest height (object units, of a unit-sphere object).
BASE_TOLERANCE = 1e-6


def rotate_point_cloud(batch: np.ndarray, angle: float) -> np.ndarray:
    """charlesq34/pointnet ``provider.rotate_point_cloud``, one angle for the batch: "Rotate the point
    cloud along up direction", ``np.dot(shape_pc, rotation_matrix)`` with the matrix below."""
    c, s = np.cos(angle), np.sin(angle)
    rotation_matrix = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.stack([np.dot(pc.reshape((-1, 3)), rotation_matrix) for pc in batch])


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return tiny_dataset(tmp_path_factory.mktemp("frame") / "ds")


def _h5_rows(out, split="train"):
    """The rows of an export's split with their source sample (through ``id2file.json``)."""
    with h5py.File(out / f"ply_data_{split}0.h5", "r") as f:
        data = f["data"][:]
    return data, json.loads((out / f"ply_data_{split}_0_id2file.json").read_text())


def _source_points(dataset, split="train"):
    source = OccludedDataset(dataset, split=split)
    by_id = {}
    for i in range(len(source)):
        meta = source.metadata(i)
        by_id[f"{meta['name']}/v{meta['pose_index']:03d}_s{meta['sample_index']:02d}"] = source[i][0]
    return by_id


def _base_stays_on_the_ground(cloud: np.ndarray, base: np.ndarray) -> bool:
    """Whether the points ``base`` (the object's lowest) lie on the plane y = min of ``cloud``."""
    return bool(np.all(cloud[base, 1] <= cloud[:, 1].min() + BASE_TOLERANCE))


def test_pointnet_h5_is_y_up_and_the_loaders_rotation_keeps_its_ground_plane(dataset, tmp_path):
    out = tmp_path / "modelnet40_ply_hdf5_2048"
    result = export(dataset, "pointnet-h5", out, progress=False)
    assert result.up == "+y"
    data, ids = _h5_rows(out)
    source = _source_points(dataset)
    for angle in np.linspace(0.1, 2 * np.pi, 7):
        turned = rotate_point_cloud(data, angle)
        for row, sample_id in enumerate(ids):
            points = source[sample_id]
            base = points[:, 2] <= points[:, 2].min() + BASE_TOLERANCE  # the object's base: lowest in our +z-up frame
            assert _base_stays_on_the_ground(data[row], base) and _base_stays_on_the_ground(turned[row], base)
            np.testing.assert_array_equal(turned[row][:, 1], data[row][:, 1])  # heights kept: a turn about the up axis


def test_the_data_sets_own_frame_fails_the_loaders_rotation(dataset, tmp_path):
    """What ``up="+z"`` (the frame every export had) gives: the loader turns the object about a horizontal axis."""
    out = tmp_path / "zup"
    export(dataset, "pointnet-h5", out, up="+z", progress=False)
    data, ids = _h5_rows(out)
    source = _source_points(dataset)
    np.testing.assert_array_equal(data, np.stack([source[i] for i in ids]))  # the data set's values, as they are
    turned = rotate_point_cloud(data, np.pi / 2)
    kept = [_base_stays_on_the_ground(turned[row], source[i][:, 2] <= source[i][:, 2].min() + BASE_TOLERANCE) for row, i in enumerate(ids)]
    assert not all(kept)


@pytest.mark.parametrize("up", UP_AXES)
def test_each_up_axis_reads_back_through_the_readers_up_rotation(dataset, tmp_path, up):
    """A reader given ``up`` (``load_mesh(up=...)``, a point set's ``--up``) turns the export back to the source, value for value."""
    from zbuf_occlude.mesh.scene import up_rotation

    out = tmp_path / "out"
    result = export(dataset, "pointnet-h5", out, up=up, progress=False)
    assert result.up == up and json.loads((out / "export.json").read_text())["up"] == up
    with h5py.File(out / "ply_data_train0.h5", "r") as f:
        assert f.attrs["up"] == up  # what the point-set readers take as the file's frame
    data, ids = _h5_rows(out)
    source = _source_points(dataset)
    rotation = up_rotation(up)[:3, :3]
    for row, sample_id in enumerate(ids):
        np.testing.assert_array_equal((data[row].astype(np.float64) @ rotation.T).astype(np.float32), source[sample_id])


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(UP_AXES), st.sampled_from(UP_AXES), st.integers(0, 2**32 - 1))
def test_turn_up_is_a_proper_rotation_that_turns_back_exactly(a, b, seed):
    points = np.random.default_rng(seed).normal(size=(5, 3)).astype(np.float32)
    there = turn_up(points, a, b)
    assert there.dtype == np.float32 and turn_up(there, b, a).tobytes() == points.tobytes()
    rotation = turn_up(np.eye(3), a, b)  # rows: where x, y and z go
    assert np.isclose(np.linalg.det(rotation), 1.0) and np.allclose(rotation @ rotation.T, np.eye(3))
    up_there = turn_up(turn_up(np.array([[0.0, 0.0, 1.0]]), "+z", a), a, b)  # a's up, turned to b's frame
    sign = -1.0 if b[0] == "-" else 1.0
    assert np.array_equal(up_there[0], sign * np.eye(3)["xyz".index(b[1])])


def test_modelnet_txt_is_y_up_normals_turned_with_points_and_each_file_maps_to_its_sample(dataset, tmp_path):
    y, z = tmp_path / "y", tmp_path / "z"
    result = export(dataset, "modelnet-txt", y, progress=False)
    export(dataset, "modelnet-txt", z, up="+z", progress=False)
    source = {**_source_points(dataset, "train"), **_source_points(dataset, "test")}
    ids = {}
    for split in ("train", "test"):
        ids.update(json.loads((y / f"modelnet40_{split}_id2file.json").read_text()))
        assert list(json.loads((y / f"modelnet40_{split}_id2file.json").read_text())) == (y / f"modelnet40_{split}.txt").read_text().split()
    assert len(ids) == len(source) and set(ids.values()) == set(source)
    for sample_id, sample in ids.items():
        cls = sample_id.rsplit("_", 1)[0]
        in_y = np.loadtxt(y / cls / f"{sample_id}.txt", delimiter=",")
        in_z = np.loadtxt(z / cls / f"{sample_id}.txt", delimiter=",")
        np.testing.assert_allclose(in_z[:, :3], source[sample], atol=5e-7)  # this file is this sample
        for part in (slice(0, 3), slice(3, 6)):  # points and normals, each (x, y, z) -> (x, z, -y)
            np.testing.assert_array_equal(
                in_y[:, part], np.stack([in_z[:, part][:, 0], in_z[:, part][:, 2], -in_z[:, part][:, 1]], 1) + 0.0
            )
    record = json.loads((y / "export.json").read_text())
    assert record["up"] == "+y" and "+y up" in record["frame"] and record["data_files"] == result.data_files == len(ids) + 2
    ledger = [json.loads(line)["path"] for line in (y / LEDGER_FILE).read_text().splitlines()]
    assert len(set(ledger)) == result.data_files + len(result.files)


def test_pcn_stays_in_pcns_frame_and_up_turns_it(tmp_path):
    from pypcd4 import PointCloud

    from zbuf_occlude.protocols import get_protocol, run_protocol

    (tmp_path / "meshes" / "chair" / "train").mkdir(parents=True)
    shutil.copy(SAMPLE_MESHES / "chair/train/chair_0001.off", tmp_path / "meshes" / "chair" / "train" / "chair_0001.off")
    run_protocol(get_protocol("pcn"), [tmp_path / "meshes"], tmp_path / "run", progress=False)
    assert export(tmp_path / "run", "pcn", tmp_path / "y", progress=False).up == "+y"
    export(tmp_path / "run", "pcn", tmp_path / "z", up="+z", progress=False)
    rel = "train/complete/03001627/chair_0001.pcd"
    in_y, in_z = (PointCloud.from_path(tmp_path / d / rel).numpy() for d in ("y", "z"))
    np.testing.assert_array_equal(in_z, np.stack([in_y[:, 0], -in_y[:, 2], in_y[:, 1]], 1) + 0.0)
    assert in_y[:, 1].max() - in_y[:, 1].min() > in_y[:, 2].max() - in_y[:, 2].min()  # a chair is taller than deep


def test_the_cli_says_the_frame_and_takes_up(dataset, tmp_path, capsys):
    assert cli_main(["export", str(dataset), "--to", "pointnet-h5", "--out", str(tmp_path / "a"), "--no-progress"]) == 0
    said = capsys.readouterr()
    assert "frame: +y up, as PointNet's modelnet40_ply_hdf5_2048" in said.out and "data files" in said.out and not said.err
    assert cli_main(["export", str(dataset), "--to", "pointnet-h5", "--out", str(tmp_path / "b"), "--up", "+z"]) == 0
    said = capsys.readouterr()
    assert "frame: +z up (asked for; pointnet-h5's networks train +y up" in said.out and "export pointnet-h5" in said.err
    with pytest.raises(SystemExit):
        cli_main(["export", str(dataset), "--to", "pointnet-h5", "--out", str(tmp_path / "c"), "--up", "y"])
    assert "--up" in capsys.readouterr().err and not (tmp_path / "c").exists()
    with pytest.raises(InvalidInputError, match=r"up='y': give one of \+x"):
        export(dataset, "pointnet-h5", tmp_path / "d", up="y")


def test_a_failure_while_a_sample_is_made_ahead_is_raised_not_lost(dataset, tmp_path, monkeypatch):
    import zbuf_occlude.exporters.modelnet_txt as writer

    calls = []

    def failing(points, eye):
        calls.append(1)
        if len(calls) == 2:
            raise MemoryError("the second sample's normals")
        return np.tile(np.float32([0, 0, 1]), (len(points), 1))

    monkeypatch.setattr(writer, "estimate_normals", failing)
    with pytest.raises(MemoryError, match="second sample"):
        export(dataset, "modelnet-txt", tmp_path / "out", progress=False)
    assert not (tmp_path / "out" / "modelnet40_train.txt").exists()
