"""Point-set inputs as a hostile shared folder makes them: lists beside the files that link out or
block, declared sizes, and clouds that float64 cannot normalise (mesh/point_inputs.py).

Each case is refused in one line naming the file or the value; what the lists outside the folder
say never reaches a plan, an output or a class list.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np
import pytest

from zbuf_occlude import resources
from zbuf_occlude.cli.main import main
from zbuf_occlude.errors import DatasetFormatError, InsufficientMemoryError, InvalidInputError, UnsafePathError
from zbuf_occlude.mesh.inputs.kinds import INPUT_KINDS
from zbuf_occlude.mesh.inputs.plan import scan_inputs
from zbuf_occlude.mesh.inputs.point_sets import MIN_KEPT_DISTINCT, cloud_frame, load_cloud, point_set_clouds, pointnet_split

TINY = ["--views", "0:0", "--points", "64", "--samples-per-view", "1", "--no-progress"]  # --resolution: meshes only
CLOUD = np.random.default_rng(0).normal(size=(300, 3))
#: What a file outside the point set's folder says: it must never become a class name.
SECRET = "SECRET_FROM_OUTSIDE"


def _pointnet(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    with h5py.File(folder / "ply_data_train0.h5", "w") as f:
        f["data"] = np.stack([CLOUD, CLOUD * [1.0, 2.0, 0.5]]).astype(np.float32)
        f["label"] = np.array([[0], [1]], np.uint8)
    return folder / "ply_data_train0.h5"


def _outside(tmp_path: Path) -> Path:
    path = tmp_path / "elsewhere" / "names.txt"
    path.parent.mkdir()
    path.write_text(f"{SECRET}_A\n{SECRET}_B\nply_data_train0.h5\n")
    return path


def _one_line(exc: pytest.ExceptionInfo, *words: str) -> None:
    message = str(exc.value)
    assert "\n" not in message and all(w in message for w in words), message


# -- the lists beside a point set ---------------------------------------------------------------------
@pytest.mark.parametrize("listing", ["shape_names.txt", "modelnet40_shape_names.txt", "train_files.txt", "test_files.txt"])
def test_a_list_that_links_out_of_the_folder_is_refused_naming_it(tmp_path, listing) -> None:
    h5 = _pointnet(tmp_path / "set")
    os.symlink(_outside(tmp_path), tmp_path / "set" / listing)
    read = point_set_clouds if "shape" in listing else pointnet_split
    with pytest.raises(UnsafePathError, match="leads outside") as exc:
        read(h5)
    _one_line(exc, listing)
    assert SECRET not in str(exc.value)
    # discovery, as generate, the farm and on-the-fly data sets run it: the file is skipped naming
    # why (a class list), or the scan refused (a split list: every file of the folder is in question)
    with pytest.raises(InvalidInputError, match=f"{listing} leads outside") as exc:
        scan_inputs([tmp_path / "set"], kinds=INPUT_KINDS)
    assert SECRET not in str(exc.value)


def test_a_list_that_links_inside_the_folder_is_read(tmp_path) -> None:
    h5 = _pointnet(tmp_path / "set")
    (tmp_path / "set" / "names.txt").write_text("chair\nsofa\n")
    os.symlink("names.txt", tmp_path / "set" / "shape_names.txt")
    (tmp_path / "set" / "lists").mkdir()
    (tmp_path / "set" / "lists" / "test.txt").write_text("data/x/ply_data_train0.h5\n")
    os.symlink(Path("lists") / "test.txt", tmp_path / "set" / "test_files.txt")
    assert [c.class_name for c in point_set_clouds(h5)] == ["chair", "sofa"]
    assert pointnet_split(h5) == "test"


@pytest.mark.parametrize("listing", ["shape_names.txt", "test_files.txt"])
@pytest.mark.parametrize("kind", ["fifo", "dangling link", "folder"])
def test_a_list_that_is_no_regular_file_is_refused_unopened(tmp_path, listing, kind) -> None:
    h5 = _pointnet(tmp_path / "set")
    where = tmp_path / "set" / listing
    {"fifo": os.mkfifo, "dangling link": lambda p: os.symlink("missing.txt", p), "folder": os.mkdir}[kind](where)
    read = point_set_clouds if "shape" in listing else pointnet_split
    with pytest.raises(InvalidInputError) as exc:  # a FIFO would block the reader: refused at once
        read(h5)
    _one_line(exc, str(where))


def test_a_list_larger_than_the_cap_is_refused_before_it_is_read(tmp_path, monkeypatch) -> None:
    from zbuf_occlude.mesh.inputs import point_sets

    h5 = _pointnet(tmp_path / "set")
    (tmp_path / "set" / "train_files.txt").write_text("ply_data_train0.h5\n" * 10)
    assert pointnet_split(h5) == "train"
    monkeypatch.setattr(point_sets, "MAX_LIST_BYTES", 100)
    with pytest.raises(InvalidInputError, match="190 bytes, more than the 100") as exc:
        pointnet_split(h5)
    _one_line(exc, "train_files.txt")


def test_generate_from_a_point_set_whose_class_list_links_out_exits_1_in_one_line(tmp_path, capsys) -> None:
    root = tmp_path / "in"
    _pointnet(root / "pointnet")
    os.symlink(_outside(tmp_path), root / "pointnet" / "shape_names.txt")
    (root / "good" / "cloud").mkdir(parents=True)
    np.save(root / "good" / "cloud" / "a.npy", CLOUD)  # the run goes on with it
    out = tmp_path / "out"
    assert main(["generate", str(root), "--out", str(out), *TINY]) == 1
    err = capsys.readouterr().err
    said = [line for line in err.splitlines() if "shape_names.txt" in line]
    assert len(said) == 1 and said[0].startswith("SKIPPED") and "leads outside" in said[0], err
    assert "Traceback" not in err and SECRET not in err
    for path in out.rglob("*"):  # not one output holds the outside file's lines
        assert not path.is_file() or SECRET.encode() not in path.read_bytes(), path
    card = json.loads((out / "dataset_card.json").read_text())
    assert card["n_objects_ok"] == 1 and len(card["skipped_inputs"]) == 1


def test_generate_from_a_point_set_whose_split_list_links_out_is_a_one_line_error(tmp_path, capsys) -> None:
    _pointnet(tmp_path / "in")
    (tmp_path / "in" / "shape_names.txt").write_text("chair\nsofa\n")
    os.symlink(_outside(tmp_path), tmp_path / "in" / "test_files.txt")
    out = tmp_path / "out"
    assert main(["generate", str(tmp_path / "in"), "--out", str(out), *TINY]) != 0
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err and "test_files.txt leads outside" in err, err
    assert not (out / "dataset_card.json").exists()


# -- declared sizes ---------------------------------------------------------------------------------
def test_a_file_that_declares_rows_it_does_not_store_is_refused_before_planning(tmp_path) -> None:
    path = tmp_path / "empty.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("data", shape=(100_000, 2048, 3), dtype=np.float32)
        f["label"] = np.zeros((100_000, 1), np.int64)
    with pytest.raises(DatasetFormatError, match=r"declares shape \(100000, 2048, 3\)") as exc:
        point_set_clouds(path)
    _one_line(exc, str(path))
    with pytest.raises(InvalidInputError, match=r"empty\.h5: .*declares shape"):  # nothing else to plan
        scan_inputs([tmp_path], kinds=INPUT_KINDS)


def test_planning_more_clouds_than_memory_holds_is_refused_naming_them(tmp_path, monkeypatch) -> None:
    path = tmp_path / "many.h5"
    with h5py.File(path, "w") as f:  # 2,000 clouds of one point: their labels fit the budget, their plan does not
        f["data"] = np.random.default_rng(1).random((2_000, 1, 3)).astype(np.float32)
        f["label"] = np.zeros((2_000, 1), np.uint8)
    monkeypatch.setattr(resources, "available_memory", lambda: (200_000, "test budget"))
    monkeypatch.setattr(resources, "MIN_CHECKED_BYTES", 0)  # a small file, a smaller budget
    with pytest.raises(InsufficientMemoryError, match="planning the 2,000 clouds") as exc:
        point_set_clouds(path)
    _one_line(exc, "many.h5")


# -- clouds float64 cannot normalise -------------------------------------------------------------------
@pytest.mark.parametrize(
    ("points", "said"),
    [
        (np.array([[-1.5e308, 0.0, 0.0], [1.5e308, 1.0, 1.0], [0.0, 0.5, 0.5]]), "extent overflows float64"),
        (np.vstack([CLOUD, [[1e200, 0.0, 0.0]]]), "its 301 distinct points become 2"),
        (np.vstack([CLOUD, [[1e200, 1e200, 1e200]], [[-1e200, 0.0, 0.0]]]), "distinct points become"),
        (np.array([[0.0, 0.0, 0.0], [1e-320, 0.0, 0.0]]), "too small to scale to 1"),
        (np.ones((10, 3)), "all coincide"),
    ],
    ids=["overflowing extent", "one outlier", "two outliers", "subnormal extent", "coincident"],
)
def test_a_cloud_that_cannot_be_normalised_is_refused_in_one_line(tmp_path, points, said) -> None:
    with pytest.raises(InvalidInputError, match=said) as exc:
        cloud_frame(points, None, "+z", what="the cloud 'x'")
    _one_line(exc, "the cloud 'x'")
    np.save(tmp_path / "c.npy", points)  # as generate, the farm and on-the-fly data sets read it
    with pytest.raises(InvalidInputError, match=said) as exc:
        load_cloud(tmp_path / "c.npy", 0)
    _one_line(exc, "c.npy")


def test_clouds_float64_can_normalise_are_normalised() -> None:
    # a far-off cloud whose centre overflows a sum: centred without it
    far = np.array([[1.5e308, 0.0, 0.0], [1.7e308, 1e307, 0.0], [1.6e308, 0.0, 2e307]])
    points, _ = cloud_frame(far, None, "+z", what="far")
    assert np.isfinite(points).all() and np.isclose(np.ptp(points, axis=0).max(), 1.0)
    assert len(np.unique(points, axis=0)) == 3
    # near-duplicates (within float32's resolution) merge when written: rounding, not a collapse
    near = np.vstack([CLOUD, CLOUD[:100] + 1e-12])
    points, _ = cloud_frame(near, None, "+z", what="near")
    assert len(np.unique(points.astype(np.float32), axis=0)) == len(CLOUD) >= MIN_KEPT_DISTINCT * len(near)
    # an outlier far but not past float64's resolution of the rest is geometry: kept
    points, _ = cloud_frame(np.vstack([CLOUD, [[1e6, 0.0, 0.0]]]), None, "+z", what="outlier")
    assert len(np.unique(points, axis=0)) == len(CLOUD) + 1
    # repeated points (a padded sample) are not a collapse: only distinct points count
    padded = np.vstack([CLOUD[:20]] * 50)
    points, _ = cloud_frame(padded, None, "+z", what="padded")
    assert len(np.unique(points, axis=0)) == 20
