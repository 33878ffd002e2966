"""``generate`` and ``farm`` on point-set files: the same data sets as from meshes, seen from the points.

The inputs are made here from points sampled on the shipped meshes: a ``.npy`` cloud, a ``.ply``
point cloud and a PointNet-layout HDF5 file of three clouds with ``shape_names.txt``.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import trimesh

import zbuf_occlude as zo
from zbuf_occlude.cli.main import main
from zbuf_occlude.dataset.layout import CARD_FILE, CARD_SHA256_FILE
from zbuf_occlude.dataset.schema import card_sha256_line
from zbuf_occlude.io.atomic import file_sha256

REPO_ROOT = Path(__file__).resolve().parents[2]
SAMPLES = REPO_ROOT / "data" / "samples"
CHAIR, SOFA, STOOL = (SAMPLES / rel for rel in ("chair/train/chair_0001.off", "sofa/test/sofa_0681.off", "stool/train/stool_0002.off"))
ARGS = ["--views", "0:0,30:45,-30:200", "--points", "128", "--samples-per-view", "2"]  # --resolution: meshes only
#: z-up -> y-up, as PointNet's HDF5 files store ModelNet (read back +y up by default): exact in float32.
Z_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

pytestmark = pytest.mark.slow


def _sampled(mesh: Path, n: int, seed: int = 0) -> np.ndarray:
    return zo.sample_surface(zo.load_mesh(mesh), n, seed=seed)[0]


def make_point_sets(root: Path) -> dict[str, np.ndarray]:
    """The input folder; returns the stored points of each object, by its name in the plan."""
    stored = {}
    (root / "chair").mkdir(parents=True)
    (root / "sofa").mkdir()
    stored["chair/scan_a"] = _sampled(CHAIR, 1500)
    np.save(root / "chair" / "scan_a.npy", stored["chair/scan_a"])
    ply = _sampled(SOFA, 1500, seed=1)
    trimesh.PointCloud(ply).export(root / "sofa" / "scan_b.ply")  # binary PLY: float32 coordinates
    stored["sofa/scan_b"] = ply.astype(np.float32).astype(np.float64)
    clouds = np.stack([_sampled(m, 1024, seed=2) for m in (CHAIR, SOFA, STOOL)]).astype(np.float32)
    pointnet = root / "pointnet"
    pointnet.mkdir()
    with h5py.File(pointnet / "ply_data_train0.h5", "w") as f:
        f["data"] = (clouds @ Z_TO_Y_UP.T.astype(np.float32)).astype(np.float32)  # +y up, as PointNet's files
        f["label"] = np.array([[0], [1], [2]], dtype=np.uint8)
    (pointnet / "shape_names.txt").write_text("chair\nsofa\nstool\n")
    for row in range(3):
        stored[f"pointnet/ply_data_train0_{row:04d}"] = clouds[row].astype(np.float64)
    return stored


def normalised(points: np.ndarray) -> np.ndarray:
    """The points as a mesh's vertices are normalised: bounding-box centre at 0, largest side 1."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    return (points - (lo + hi) / 2.0) * (1.0 / float((hi - lo).max()))


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> tuple[Path, dict[str, np.ndarray], Path]:
    """The inputs and one ``generate`` data set of them (HDF5)."""
    tmp = tmp_path_factory.mktemp("point_sets")
    stored = make_point_sets(tmp / "in")
    out = tmp / "generated"
    assert main(["generate", str(tmp / "in"), "--out", str(out), *ARGS, "--no-progress"]) == 0
    return tmp / "in", stored, out


def _card(out: Path) -> dict:
    return json.loads((out / CARD_FILE).read_text(encoding="utf-8"))


def _samples_by_name(out: Path) -> dict[tuple[str, int, int], np.ndarray]:
    ds = zo.OccludedDataset(out)
    return {(m["name"], m["pose_index"], m["sample_index"]): p for p, _, m in (ds[i] for i in range(len(ds)))}


def test_generate_writes_a_data_set_verify_accepts_whose_card_says_points(made, capsys) -> None:
    _, stored, out = made
    assert main(["verify", str(out)]) == 0
    assert capsys.readouterr().out.startswith(f"OK {out}: 5 objects")
    card = _card(out)
    assert card["visibility_from"] == "points" and card["shape_names"] == ["chair", "sofa", "stool"]
    assert card["point_sets"]["n_objects"] == 5 and card["point_sets"]["visibility"] == "point-splat"
    assert card["point_sets"]["n_with_normals"] == 0 and card["point_sets"]["face_index"] == -1
    assert card["renderers"] == [] and card["layout"] == "class-folders, point-set labels"
    records = [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]
    assert {r["name"]: (r["class_name"], r["cloud"], r["n_dense"]) for r in records} == {
        "chair/scan_a": ("chair", 0, 1500), "sofa/scan_b": ("sofa", 0, 1500),
        "pointnet/ply_data_train0_0000": ("chair", 0, 1024), "pointnet/ply_data_train0_0001": ("sofa", 1, 1024),
        "pointnet/ply_data_train0_0002": ("stool", 2, 1024),
    }  # fmt: skip
    assert all(r["visibility"] == "point-splat" and r["visibility_from"] == "points" and r["normals"] is False for r in records)
    assert all(sum(r["n_topped_up"]) == 0 and "n_faces" not in r for r in records)
    assert set(stored) == {r["name"] for r in records}


def test_every_sample_is_a_subset_of_its_input_points(made) -> None:
    _, stored, out = made
    samples = _samples_by_name(out)
    assert len(samples) == 5 * 3 * 2
    for (name, _, _), points in samples.items():
        rows = {tuple(p) for p in normalised(stored[name]).astype(np.float32)}
        assert all(tuple(p) in rows for p in points), name
        visible = len({tuple(p) for p in points})
        assert 1 < visible <= len(points)
    with h5py.File(out / "occluded_train.h5", "r") as f:
        assert (f["face_index"][()] == -1).all()  # a point set has no faces


def test_farm_with_two_workers_writes_the_same_samples_in_compact_storage(made, tmp_path) -> None:
    root, _, generated = made
    out = tmp_path / "farmed"
    assert main(["farm", str(root), "--out", str(out), *ARGS, "--workers", "2", "--storage", "compact", "--no-progress"]) == 0
    assert main(["verify", str(out)]) == 0
    assert _card(out)["visibility_from"] == "points"
    farmed, made_by_generate = _samples_by_name(out), _samples_by_name(generated)
    assert farmed.keys() == made_by_generate.keys()
    assert all(np.array_equal(farmed[k], made_by_generate[k]) for k in farmed)


def test_a_rerun_resumes_every_object(made, capsys) -> None:
    root, _, out = made
    shards = {p: p.read_bytes() for p in sorted((out / "shards").iterdir())}
    capsys.readouterr()
    assert main(["generate", str(root), "--out", str(out), *ARGS, "--no-progress"]) == 0
    assert "(5 clouds from an earlier run)" in capsys.readouterr().out
    assert {p: p.read_bytes() for p in sorted((out / "shards").iterdir())} == shards


def test_meshes_and_point_sets_mix_and_the_card_says_so(tmp_path) -> None:
    root = tmp_path / "in"
    (root / "chair").mkdir(parents=True)
    shutil.copy(CHAIR, root / "chair" / "chair_0001.off")
    (root / "sofa").mkdir()
    np.save(root / "sofa" / "scan.npy", _sampled(SOFA, 1000))
    out = tmp_path / "out"
    assert main(["generate", str(root), "--out", str(out), *ARGS, "--dense-points", "3000", "--resolution", "128", "--format", "npz"]) == 0
    assert main(["verify", str(out)]) == 0
    card = _card(out)
    assert card["visibility_from"] == "points and meshes" and card["point_sets"]["n_objects"] == 1
    records = {r["name"]: r for r in map(json.loads, (out / "manifest.jsonl").read_text().splitlines())}
    assert "visibility" not in records["chair/chair_0001"] and "cloud" not in records["chair/chair_0001"]
    assert records["chair/chair_0001"]["n_dense"] == 3000 and records["sofa/scan"]["n_dense"] == 1000
    assert card["renderers"]  # the mesh was rendered
    assert all(np.load(f)["face_index"].min() == -1 for f in (out / "sofa" / "scan").glob("*.npz"))


def test_the_files_normals_are_used_and_counted(tmp_path) -> None:
    mesh = zo.load_mesh(STOOL)
    points, face_index = zo.sample_surface(mesh, 800, seed=0)
    root = tmp_path / "in"
    root.mkdir()
    with h5py.File(root / "with_normals.h5", "w") as f:
        f["data"] = points[None].astype(np.float32)
        f["normal"] = mesh.face_normals[face_index][None].astype(np.float32)
    out = tmp_path / "out"
    assert main(["generate", str(root), "--out", str(out), *ARGS]) == 0
    card = _card(out)
    assert card["point_sets"]["n_with_normals"] == 1
    (record,) = map(json.loads, (out / "manifest.jsonl").read_text().splitlines())
    assert record["normals"] is True and record["class_name"] == "with_normals"  # no labels: as a mesh, the flat layout


@pytest.mark.parametrize("method", ["embree-fast", "oracle", "zbuffer"])
@pytest.mark.parametrize("command", ["generate", "farm"])
def test_a_method_that_needs_a_mesh_is_refused_naming_it(made, tmp_path, capsys, command, method) -> None:
    root, _, _ = made
    out = tmp_path / "out"
    assert main([command, str(root), "--out", str(out), *ARGS, "--method", method, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error: ") and "\n" not in err
    assert f"--method {method}" in err and "point-set" in err and "point-splat" in err
    assert not out.exists()


def test_farm_sensor_is_refused_with_point_sets(made, tmp_path, capsys) -> None:
    root, _, _ = made
    out = tmp_path / "out"
    assert main(["farm", str(root), "--out", str(out), "--sensor", "hdl32e", "--points", "64", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--sensor hdl32e scans meshes" in err and "\n" not in err


def test_point_splat_named_explicitly_is_taken(made, tmp_path) -> None:
    root, _, generated = made
    out = tmp_path / "out"
    assert main(["generate", str(root), "--out", str(out), *ARGS, "--method", "point-splat"]) == 0
    # the same visibility as the default's: the samples are those of the default run
    a, b = _samples_by_name(out), _samples_by_name(generated)
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


def test_verify_refuses_a_card_that_hides_its_point_sets(made, tmp_path, capsys) -> None:
    _, _, generated = made
    out = tmp_path / "copy"
    shutil.copytree(generated, out)
    card = _card(out)
    card["point_sets"]["n_objects"] = 4
    (out / CARD_FILE).write_text(json.dumps(card))
    (out / CARD_SHA256_FILE).write_text(card_sha256_line(file_sha256(out / CARD_FILE)))
    assert main(["verify", str(out)]) == 1
    assert (
        "5 objects are clouds of point-set files (field 'cloud'), the card's field 'point_sets' says another number"
        in capsys.readouterr().err
    )
    del card["visibility_from"]  # the card must say both or neither
    (out / CARD_FILE).write_text(json.dumps(card))
    (out / CARD_SHA256_FILE).write_text(card_sha256_line(file_sha256(out / CARD_FILE)))
    assert main(["verify", str(out)]) == 1
    assert "'visibility_from' and 'point_sets' go together" in capsys.readouterr().err
