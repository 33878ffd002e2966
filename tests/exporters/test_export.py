"""``export``: each target read back as its family's own code reads it (file names, keys, dtypes,
shapes, list lines resolved from the client's root), the same points as the source, labels that
agree with the class names, shuffled files whose batches mix classes."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import SAMPLE_MESHES

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.errors import InvalidInputError, UnsafePathError
from zbuf_occlude.exporters import export
from zbuf_occlude.exporters.label_sets import MODELNET10_CLASSES
from zbuf_occlude.protocols.modelnet40c import MODELNET40_CLASSES


def y_up(points: np.ndarray) -> np.ndarray:
    """Our +z-up points in the +y-up frame of PointNet's files: ``(x, y, z) → (x, z, −y)``."""
    return np.stack([points[..., 0], points[..., 2], -points[..., 1]], axis=-1)


#: Six train meshes of five classes and three test meshes: enough rows for several files of 64.
MESHES = ("bathtub/train/bathtub_0001.off", "bed/train/bed_0001.off", "chair/train/chair_0001.off",
          "monitor/train/monitor_0001.off", "stool/train/stool_0002.off", "desk/test/desk_0201.off",
          "sofa/test/sofa_0681.off", "table/test/table_0393.off")  # fmt: skip
FARM = ["--views", "grid25", "--dense-points", "1024", "--samples-per-view", "2", "--points", "32", "--resolution", "64", "--no-progress"]


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    """The same meshes as a farm's dense and compact data sets and as generate's h5, npz and ply."""
    root = tmp_path_factory.mktemp("sources")
    for rel in MESHES:
        (root / "meshes" / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(SAMPLE_MESHES / rel, root / "meshes" / rel)
    made = {}
    for kind, argv in {
        "dense": ["farm", "--storage", "dense"], "compact": ["farm", "--storage", "compact"],
        "h5": ["generate", "--format", "h5"], "npz": ["generate", "--format", "npz"], "ply": ["generate", "--format", "ply"],
    }.items():  # fmt: skip
        assert cli_main([argv[0], str(root / "meshes"), "--out", str(root / kind), *argv[1:], *FARM]) == 0
        made[kind] = root / kind
    return made


def _pointnet_read(client: Path, list_file: str) -> tuple[np.ndarray, np.ndarray]:
    """PointNet's provider.getDataFiles + loadDataFile, run from the client repository's root."""
    here = os.getcwd()
    os.chdir(client)
    try:
        files = [line.rstrip() for line in open(list_file)]
        data, label = zip(*((h5py.File(f, "r")["data"][:], h5py.File(f, "r")["label"][:]) for f in files))
    finally:
        os.chdir(here)
    return np.concatenate(data), np.concatenate(label)


@pytest.mark.parametrize("kind", ["dense", "compact", "h5", "npz", "ply"])
def test_pointnet_h5_reads_back_the_source_as_pointnet_reads_it(sources, tmp_path, kind):
    client = tmp_path / "pointnet"
    out = client / "data" / "modelnet40_ply_hdf5_2048"
    export(sources[kind], "pointnet-h5", out, seed=3)
    names = (out / "shape_names.txt").read_text().splitlines()
    for split in ("train", "test"):
        source = OccludedDataset(sources[kind], split=split)
        data, label = _pointnet_read(client, f"data/modelnet40_ply_hdf5_2048/{split}_files.txt")
        assert data.dtype == np.float32 and data.shape == (len(source), source.n_points, 3)
        assert label.dtype == np.uint8 and label.shape == (len(source), 1)
        ids = [i for f in sorted(out.glob(f"ply_data_{split}_*_id2file.json")) for i in json.loads(f.read_text())]
        by_id = {}
        for i in range(len(source)):
            meta = source.metadata(i)
            by_id[f"{meta['name']}/v{meta['pose_index']:03d}_s{meta['sample_index']:02d}"] = i
        assert len(ids) == len(source) and set(ids) == set(by_id)
        for row, sample_id in enumerate(ids):
            points, lab, meta = source[by_id[sample_id]]
            np.testing.assert_array_equal(data[row], y_up(points))  # in PointNet's frame, each value as it was
            assert names[int(label[row, 0])] == meta["class_name"]


def test_files_hold_at_most_rows_per_file_and_batches_mix_classes(sources, tmp_path, monkeypatch):
    import zbuf_occlude.exporters.pointnet_h5 as writer

    out = tmp_path / "modelnet40_ply_hdf5_2048"
    monkeypatch.setattr(writer, "ROWS_PER_FILE", 64)  # small files, as 2048 are to a large set
    monkeypatch.setattr(writer, "MAX_OPEN_FILES", 2)  # and in passes, as a set of more files than that is
    export(sources["compact"], "pointnet-h5", out)
    files = sorted(out.glob("ply_data_train*.h5"), key=lambda p: int(p.stem.removeprefix("ply_data_train")))
    sizes = [h5py.File(f, "r")["label"].shape[0] for f in files]
    assert len(files) > 2 and all(s == 64 for s in sizes[:-1]) and 0 < sizes[-1] <= 64
    for f in files:  # PointNet shuffles within a file: a file of one class gives batches of one class
        label = h5py.File(f, "r")["label"][:, 0]
        for start in range(0, len(label) - 31, 32):
            assert len(set(label[start : start + 32])) > 1


def test_the_shuffle_follows_the_seed(sources, tmp_path):
    rows = {}
    for seed in (0, 0, 1):
        out = tmp_path / f"s{seed}_{len(rows)}"
        export(sources["dense"], "pointnet-h5", out, seed=seed)
        rows[len(rows)] = h5py.File(out / "ply_data_train0.h5", "r")["label"][:, 0]
    assert np.array_equal(rows[0], rows[1]) and not np.array_equal(rows[0], rows[2])


def test_a_label_set_gives_a_pretrained_networks_ids(sources, tmp_path):
    export(sources["dense"], "pointnet-h5", tmp_path / "mn40", label_set_name="modelnet40")
    assert (tmp_path / "mn40" / "shape_names.txt").read_text().splitlines() == list(MODELNET40_CLASSES)
    ds = OccludedDataset(sources["dense"], split="test")
    with h5py.File(tmp_path / "mn40" / "ply_data_test0.h5", "r") as f:
        got = sorted(set(f["label"][:, 0].tolist()))
    assert got == sorted(MODELNET40_CLASSES.index(c) for c in {ds.metadata(i)["class_name"] for i in range(len(ds))})


def test_a_class_the_label_set_lacks_is_refused_by_name(sources, tmp_path, capsys):
    with pytest.raises(InvalidInputError, match="'stool'"):
        export(sources["dense"], "pointnet-h5", tmp_path / "x", label_set_name="modelnet10")
    assert "stool" not in MODELNET10_CLASSES
    assert (
        cli_main(["export", str(sources["dense"]), "--to", "pointnet-h5", "--out", str(tmp_path / "y"), "--label-set", "modelnet10"]) == 2
    )
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "'stool'" in err and "Traceback" not in err
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def test_the_list_prefix_names_the_client_path(sources, tmp_path):
    export(sources["dense"], "pointnet-h5", tmp_path / "out", list_prefix="data/mine/")
    assert (tmp_path / "out" / "train_files.txt").read_text().splitlines()[0] == "data/mine/ply_data_train0.h5"


def _pointnet2_pytorch_read(root: Path, split: str, num_category: int = 40):
    """Pointnet_Pointnet2_pytorch's ModelNetDataLoader (use_normals=True), by hand."""
    cat = [line.rstrip() for line in open(root / f"modelnet{num_category}_shape_names.txt")]
    classes = dict(zip(cat, range(len(cat))))
    ids = [line.rstrip() for line in open(root / f"modelnet{num_category}_{split}.txt")]
    for shape_id in ids:
        shape_name = "_".join(shape_id.split("_")[0:-1])
        points = np.loadtxt(root / shape_name / (shape_id + ".txt"), delimiter=",").astype(np.float32)
        yield points, classes[shape_name]


@pytest.mark.parametrize("label_set,num_category", [("own", 40), ("modelnet40", 40)])
def test_modelnet_txt_reads_back_as_pointnet2_pytorch_reads_it(sources, tmp_path, label_set, num_category):
    out = tmp_path / "modelnet40_normal_resampled"
    export(sources["h5"], "modelnet-txt", out, label_set_name=label_set)
    for split in ("train", "test"):
        source = OccludedDataset(sources["h5"], split=split)
        cat = (out / "modelnet40_shape_names.txt").read_text().splitlines()
        read = list(_pointnet2_pytorch_read(out, split, num_category))
        assert len(read) == len(source)
        for i, (points, label) in enumerate(read):  # in the source's order
            expected, _, meta = source[i]
            assert points.shape == (source.n_points, 6)
            np.testing.assert_allclose(points[:, :3], y_up(expected), atol=5e-7)
            np.testing.assert_allclose(np.linalg.norm(points[:, 3:], axis=1), 1.0, atol=1e-5)
            assert cat[label] == meta["class_name"]


def test_modelnet10_names_its_files_as_that_loader_opens_them(tmp_path):
    from conftest import tiny_dataset

    ds = tiny_dataset(tmp_path / "ds")
    export(ds, "modelnet-txt", tmp_path / "out", label_set_name="modelnet10")
    assert (tmp_path / "out" / "modelnet10_shape_names.txt").read_text().splitlines() == list(MODELNET10_CLASSES)
    assert [label for _, label in _pointnet2_pytorch_read(tmp_path / "out", "train", 10)] == [MODELNET10_CLASSES.index("chair")] * 2


def test_an_export_replaces_only_its_own_files(sources, tmp_path):
    out = tmp_path / "out"
    export(sources["dense"], "pointnet-h5", out)
    export(sources["dense"], "pointnet-h5", out)  # a rerun replaces its own files
    (out / "ply_data_train0.h5").write_bytes(b"changed")
    with pytest.raises(UnsafePathError, match="ply_data_train0.h5"):
        export(sources["dense"], "pointnet-h5", out)
    assert (out / "ply_data_train0.h5").read_bytes() == b"changed"
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "shape_names.txt").write_text("my classes\n")
    with pytest.raises(UnsafePathError, match="shape_names.txt"):
        export(sources["dense"], "pointnet-h5", mine)
    assert (mine / "shape_names.txt").read_text() == "my classes\n"


def test_an_export_inside_its_source_is_refused(sources, tmp_path):
    with pytest.raises(InvalidInputError, match="inside the data set"):
        export(sources["dense"], "pointnet-h5", sources["dense"] / "export")


def test_a_modelnet40c_folder_is_named_as_a_protocol_folder(tmp_path):
    """Its runs are recorded per corruption and severity (protocol_<run>.json), and it is still told apart from a data set."""
    from zbuf_occlude.protocols import ProtocolOptions, get_protocol, run_protocol

    (tmp_path / "meshes" / "chair" / "train").mkdir(parents=True)
    shutil.copy(SAMPLE_MESHES / "chair/train/chair_0001.off", tmp_path / "meshes" / "chair" / "train" / "chair_0001.off")
    run_protocol(
        get_protocol("modelnet40-c-occlusion"), [tmp_path / "meshes"], tmp_path / "mn40c", ProtocolOptions(severity=1), progress=False
    )
    with pytest.raises(InvalidInputError, match=r"`generate --protocol` folder \(--protocol modelnet40-c-occlusion\)"):
        export(tmp_path / "mn40c", "pointnet-h5", tmp_path / "out")
    assert not (tmp_path / "out").exists()
