"""Point-set files as inputs of ``generate`` and ``farm``: discovery, names, classes, splits, frame.

Each cloud of a point-set file is one object of the plan (:mod:`zbuf_occlude.mesh.inputs.point_sets`).
The files are built here from points sampled on the shipped meshes; nothing is rendered.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import trimesh

import zbuf_occlude as zo
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.farm.journal import plan_doc
from zbuf_occlude.farm.config import FarmParams
from zbuf_occlude.mesh.inputs.discovery import walk_mesh_files
from zbuf_occlude.mesh.inputs.kinds import INPUT_KINDS, MESH, POINT_SET, kind_of
from zbuf_occlude.mesh.inputs.plan import FarmObject, scan_inputs, scan_objects
from zbuf_occlude.mesh.inputs.point_sets import POINT_SET_LAYOUT, load_cloud, point_set_clouds, pointnet_split

REPO_ROOT = Path(__file__).resolve().parents[2]
CHAIR = REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"
SOFA = REPO_ROOT / "data" / "samples" / "sofa" / "test" / "sofa_0681.off"


def _points(mesh_path: Path, n: int = 500, seed: int = 0) -> np.ndarray:
    return zo.sample_surface(zo.load_mesh(mesh_path), n, seed=seed)[0]


def _h5(path: Path, clouds: list[np.ndarray], labels: list[int] | None = None, normals: list[np.ndarray] | None = None) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as f:
        f["data"] = np.stack(clouds).astype(np.float32)
        if labels is not None:
            f["label"] = np.asarray(labels, dtype=np.uint8)[:, None]
        if normals is not None:
            f["normal"] = np.stack(normals).astype(np.float32)
    return path


def _npy(path: Path, points: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, points)
    return path


@pytest.fixture
def pointnet(tmp_path: Path) -> Path:
    """A PointNet-layout folder: two files of clouds, their labels, class names and split lists."""
    root = tmp_path / "modelnet40_ply_hdf5_2048"
    chair, sofa = _points(CHAIR, 256), _points(SOFA, 256)
    _h5(root / "ply_data_train0.h5", [chair, sofa, chair], [0, 1, 0])
    _h5(root / "ply_data_test0.h5", [sofa], [1])
    (root / "shape_names.txt").write_text("chair\nsofa\n")
    (root / "train_files.txt").write_text("data/modelnet40_ply_hdf5_2048/ply_data_train0.h5\n")
    (root / "test_files.txt").write_text("data/modelnet40_ply_hdf5_2048/ply_data_test0.h5\n")
    return root


def test_each_cloud_of_a_pointnet_file_is_an_object_named_classed_and_split_by_the_files(pointnet: Path) -> None:
    scan = scan_objects(pointnet, kinds=INPUT_KINDS)
    got = [(o.name, o.class_name, o.split, o.label, o.cloud) for o in scan.objects]
    assert got == [
        ("ply_data_test0_0000", "sofa", "test", 1, 0),
        ("ply_data_train0_0000", "chair", "train", 0, 0),
        ("ply_data_train0_0001", "sofa", "train", 1, 1),
        ("ply_data_train0_0002", "chair", "train", 0, 2),
    ]
    assert scan.layout == POINT_SET_LAYOUT and not scan.skipped
    assert all(Path(o.source).name.startswith("ply_data_") for o in scan.objects)


def test_without_point_sets_the_same_folder_holds_nothing(pointnet: Path) -> None:
    # the flag is off for every caller but generate and farm: a mesh scan is what it was
    with pytest.raises(InvalidInputError, match="no mesh files"):
        scan_objects(pointnet)
    files, _ = walk_mesh_files(pointnet)
    assert files == []


def test_labels_without_class_names_keep_their_numbers(tmp_path: Path) -> None:
    _h5(tmp_path / "in" / "clouds.h5", [_points(CHAIR, 64)] * 3, [2, 0, 10])
    objects = scan_inputs([tmp_path / "in"], kinds=INPUT_KINDS).objects
    assert [(o.class_name, o.label) for o in objects] == [("2", 1), ("0", 0), ("10", 2)]  # natural order: 0, 2, 10


def test_a_label_beyond_the_class_list_skips_the_file_with_its_reason(tmp_path: Path) -> None:
    root = tmp_path / "in"
    _h5(root / "bad.h5", [_points(CHAIR, 64)] * 2, [0, 5])
    _h5(root / "good.h5", [_points(CHAIR, 64)], [0])
    (root / "shape_names.txt").write_text("chair\nsofa\n")
    scan = scan_objects(root, kinds=INPUT_KINDS)
    assert [o.name for o in scan.objects] == ["good_0000"]
    assert len(scan.skipped) == 1 and scan.skipped[0].path.endswith("bad.h5")
    assert "label 5 has no line" in scan.skipped[0].reason and "\n" not in scan.skipped[0].reason


def test_files_without_labels_take_the_class_of_their_folder_beside_meshes(tmp_path: Path) -> None:
    root = tmp_path / "in"
    (root / "chair").mkdir(parents=True)
    (root / "chair" / "chair_0001.off").write_bytes(CHAIR.read_bytes())
    _npy(root / "chair" / "cloud_a.npy", _points(CHAIR))
    (root / "sofa").mkdir()
    trimesh.PointCloud(_points(SOFA)).export(root / "sofa" / "cloud_b.ply")
    _npy(root / "sofa" / "test" / "cloud_c.npy", _points(SOFA))
    scan = scan_objects(root, kinds=INPUT_KINDS)
    got = {o.name: (o.class_name, o.split, o.cloud) for o in scan.objects}
    assert got == {
        "chair/chair_0001": ("chair", "train", None),  # the mesh: no cloud
        "chair/cloud_a": ("chair", "train", 0),
        "sofa/cloud_b": ("sofa", "train", 0),  # a .ply without faces is a point set
        "sofa/test/cloud_c": ("sofa", "test", 0),
    }
    assert scan.layout == "class-folders"


def test_a_ply_with_faces_stays_a_mesh_and_mesh_plans_are_unchanged(tmp_path: Path, sample_meshes_dir: Path) -> None:
    root = tmp_path / "in"
    for cls in ("chair", "sofa"):
        (root / cls).mkdir(parents=True)
        trimesh.load(CHAIR if cls == "chair" else SOFA).export(root / cls / f"{cls}_0001.ply")
    with_points, without = scan_objects(root, kinds=INPUT_KINDS), scan_objects(root)
    assert with_points == without and not any(o.kind is POINT_SET for o in with_points.objects)
    shipped = scan_inputs([sample_meshes_dir], kinds=INPUT_KINDS)
    assert shipped == scan_inputs([sample_meshes_dir])
    # the plan of meshes names no cloud: plan.json is what it was before point sets
    plan = plan_doc(shipped.objects, FarmParams(), "samples")
    assert all("cloud" not in o for o in plan["objects"])


def test_a_point_set_file_given_by_name_is_planned_and_a_non_pointnet_h5_is_refused(tmp_path: Path) -> None:
    cloud = _npy(tmp_path / "bunny.npy", _points(CHAIR))
    objects = scan_inputs([cloud], kinds=INPUT_KINDS).objects
    assert [(o.name, o.class_name, o.cloud) for o in objects] == [("bunny", tmp_path.name, 0)]
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["points"] = np.zeros((5, 3))
    with pytest.raises(InvalidInputError, match=r"other\.h5 is not a point-set file.*'data'"):
        scan_inputs([other], kinds=INPUT_KINDS)
    # in a folder, an HDF5 file of another layout is passed over as notes are
    assert scan_objects(tmp_path, kinds=INPUT_KINDS).skipped == []


def test_farm_refuses_a_point_set_file_for_a_folder(tmp_path: Path) -> None:
    cloud = _npy(tmp_path / "x.npy", _points(CHAIR))
    with pytest.raises(InvalidInputError, match=r"x\.npy is a point-set file; farm takes a folder"):
        scan_objects(cloud, kinds=INPUT_KINDS)


def test_a_list_file_names_point_set_files_too(tmp_path: Path) -> None:
    _npy(tmp_path / "a.npy", _points(CHAIR))
    _h5(tmp_path / "b.h5", [_points(SOFA, 64)] * 2)
    (tmp_path / "list.txt").write_text("a.npy chair\nb.h5 sofa test\n")
    objects = scan_objects(tmp_path / "list.txt", kinds=INPUT_KINDS).objects
    assert [(o.name, o.class_name, o.split, o.cloud) for o in objects] == [
        ("a", "chair", "train", 0), ("b_0000", "sofa", "test", 0), ("b_0001", "sofa", "test", 1),
    ]  # fmt: skip


def test_pointnet_split_reads_the_lists_beside_the_file(pointnet: Path) -> None:
    assert pointnet_split(pointnet / "ply_data_test0.h5") == "test"
    assert pointnet_split(pointnet / "ply_data_train0.h5") == "train"
    (pointnet / "test_files.txt").write_text("ply_data_train0.h5\nply_data_test0.h5\n")  # in both: none
    assert pointnet_split(pointnet / "ply_data_train0.h5") is None


def test_point_set_clouds_reads_no_points(pointnet: Path) -> None:
    entries = point_set_clouds(pointnet / "ply_data_train0.h5")
    assert [(e.cloud, e.suffix, e.class_name) for e in entries] == [(0, "_0000", "chair"), (1, "_0001", "sofa"), (2, "_0002", "chair")]


def test_load_cloud_normalises_as_a_mesh_and_turns_points_and_normals_up(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    points = rng.uniform(-3.0, 5.0, (200, 3)) * [1.0, 2.0, 0.5]
    normals = rng.normal(size=(200, 3))
    path = _h5(tmp_path / "c.h5", [points, points], normals=[normals, normals])
    stored = points.astype(np.float32).astype(np.float64)
    cloud = load_cloud(path, 1, up="+z")  # as stored
    lo, hi = stored.min(axis=0), stored.max(axis=0)
    np.testing.assert_array_equal(cloud.points, (stored - (lo + hi) / 2) * (1.0 / (hi - lo).max()))
    assert (cloud.up, cloud.up_source) == ("+z", "explicit")
    turned = load_cloud(path, 1)  # PointNet's layout is +y up: (x, y, z) -> (x, -z, y)
    assert np.allclose(turned.points[:, 2] * (hi - lo).max(), stored[:, 1] - (lo[1] + hi[1]) / 2)
    unit = normals.astype(np.float32).astype(np.float64)
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    assert np.allclose(turned.normals, unit[:, [0, 2, 1]] * [1, -1, 1])
    assert (turned.up, turned.up_source) == ("+y", "PointNet HDF5 layout (+y)")
    npy = load_cloud(_npy(tmp_path / "c.npy", points), 0)  # a .npy declares no frame: as stored
    assert (npy.up, npy.up_source) == ("+z", "as stored (+z)")


@pytest.mark.parametrize("points", [np.ones((10, 3)), np.zeros((1, 3))], ids=["coincident", "one point"])
def test_a_cloud_without_extent_is_refused_in_one_line(tmp_path: Path, points: np.ndarray) -> None:
    path = _npy(tmp_path / "flat.npy", points)
    with pytest.raises(InvalidInputError, match=r"flat\.npy.*all coincide") as err:
        load_cloud(path, 0)
    assert "\n" not in str(err.value)


def test_farm_object_of_a_mesh_has_no_cloud() -> None:
    mesh = FarmObject(0, "a", "a.off", "c", "train", 0)
    assert mesh.cloud is None and mesh.kind is MESH
    assert FarmObject(0, "a_0001", "a.h5", "c", "train", 0, 1).kind is POINT_SET


def test_the_kinds_asked_for_decide_what_discovery_finds(tmp_path: Path) -> None:
    """Each kind answers for its own files: a .ply without faces is a point set where point sets
    are asked for and a mesh where they are not; point sets alone leave every mesh out."""
    root = tmp_path / "in"
    (root / "chair").mkdir(parents=True)
    shutil.copy(CHAIR, root / "chair" / "a.off")
    _npy(root / "chair" / "b.npy", _points(CHAIR, 64))
    trimesh.PointCloud(_points(CHAIR, 64)).export(root / "chair" / "c.ply")
    trimesh.load(SOFA).export(root / "chair" / "d.ply")
    names = {kinds: [f.name for f in walk_mesh_files(root, kinds=kinds)[0]] for kinds in ((MESH,), (POINT_SET,), INPUT_KINDS)}
    assert names == {
        (MESH,): ["a.off", "c.ply", "d.ply"],
        (POINT_SET,): ["b.npy", "c.ply"],
        INPUT_KINDS: ["a.off", "b.npy", "c.ply", "d.ply"],
    }
    assert [kind_of(root / "chair" / n, INPUT_KINDS) for n in ("a.off", "b.npy", "c.ply", "d.ply")] == [MESH, POINT_SET, POINT_SET, MESH]
    assert kind_of(root / "chair" / "c.ply") is MESH and kind_of(root / "chair" / "b.npy") is None
    clouds = scan_objects(root, class_from=1, kinds=(POINT_SET,)).objects
    assert [(o.name, o.kind) for o in clouds] == [("chair/b", POINT_SET), ("chair/c", POINT_SET)]
    meshes_only = tmp_path / "meshes"
    meshes_only.mkdir()
    shutil.copy(CHAIR, meshes_only / "a.off")
    with pytest.raises(InvalidInputError, match=r"no point-set files \(\.h5, \.hdf5, \.npy, \.ply\) under"):
        scan_inputs([meshes_only], kinds=(POINT_SET,))
