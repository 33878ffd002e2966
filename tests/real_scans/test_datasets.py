"""Real-scan readers (SUO binary/CSV, LiDARNet v2), normalisation, and the car TP/FP/F1 protocol."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.errors import InvalidInputError, ZbufOccludeError
from zbuf_occlude.real_scans.datasets import (
    SUO_DTYPE,
    car_scores,
    car_scores_from_labels,
    load_real_scans,
    read_lidarnet_csv,
    read_suo_bin,
    read_suo_csv,
    read_suo_object,
    write_suo_bin,
    write_suo_csv,
)
from zbuf_occlude.real_scans.records import normalize_points

LIDARNET = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "lidarnet_v2_partial"


def _records(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rec = np.zeros(n, dtype=SUO_DTYPE)
    rec["t"] = rng.integers(0, 2**40, n)
    rec["intensity"] = rng.integers(0, 256, n)
    rec["id"] = rng.integers(0, 32, n)
    for k in ("x", "y", "z", "azimuth", "range"):
        rec[k] = rng.normal(scale=5.0, size=n).astype(np.float32)
    rec["pid"] = rng.integers(0, 10**6, n)
    return rec


def test_suo_record_is_34_bytes_packed():
    # 4wd.0.2299.bin is 66,470 bytes = 1955 records of 34 bytes (SUO's numpy snippet, no alignment)
    assert SUO_DTYPE.itemsize == 34
    assert 66_470 % SUO_DTYPE.itemsize == 0


def test_suo_bin_and_csv_round_trip(tmp_path):
    rec = _records(57)
    write_suo_bin(tmp_path / "car.1.2.bin", rec)
    write_suo_csv(tmp_path / "car.1.2.csv", rec)
    assert (tmp_path / "car.1.2.bin").stat().st_size == 57 * 34
    back_bin = read_suo_bin(tmp_path / "car.1.2.bin")
    back_csv = read_suo_csv(tmp_path / "car.1.2.csv")
    assert back_bin.tobytes() == rec.tobytes()
    assert back_csv.tobytes() == rec.tobytes()  # 9 significant digits are exact for float32
    scan = read_suo_object(tmp_path / "car.1.2.bin")
    assert scan.label == "car" and scan.dataset == "suo"
    xyz = np.stack([rec["x"], rec["y"], rec["z"]], 1).astype(np.float64)
    np.testing.assert_allclose(scan.extent_m, xyz.max(0) - xyz.min(0), rtol=1e-6)


def test_suo_bin_rejects_lfs_pointer(tmp_path):
    p = tmp_path / "4wd.0.2299.bin"
    p.write_text("version https://git-lfs.github.com/spec/v1\noid sha256:abc\nsize 66470\n")
    with pytest.raises(InvalidInputError, match="multiple of the 34-byte"):
        read_suo_bin(p)


def test_suo_csv_bad_line_names_file_and_line(tmp_path):
    p = tmp_path / "van.0.1.csv"
    p.write_text("1,2,3,0.1,0.2,0.3,0.4,0.5,6\n1,2,3\n")
    with pytest.raises(InvalidInputError, match=r"van\.0\.1\.csv:2"):
        read_suo_csv(p)


def test_normalize_points_centre_and_extent():
    rng = np.random.default_rng(1)
    p = rng.uniform([-3, 10, 5], [7, 12, 6], size=(500, 3))
    q = normalize_points(p)
    lo, hi = q.min(0), q.max(0)
    np.testing.assert_allclose((lo + hi) / 2, 0, atol=1e-6)
    assert math.isclose(float((hi - lo).max()), 1.0, rel_tol=1e-6)
    # shape is preserved up to scale: ratios of extents
    np.testing.assert_allclose((hi - lo) / (hi - lo).max(), (p.max(0) - p.min(0)) / (p.max(0) - p.min(0)).max(), rtol=1e-5)
    for bad in (np.zeros((0, 3)), np.zeros((4, 2)), np.ones((5, 3)), np.array([[np.nan, 0, 0], [1, 1, 1]])):
        with pytest.raises(InvalidInputError):
            normalize_points(bad)


def _write_lidarnet(path: Path, pts: np.ndarray, label: str) -> None:
    lines = ["origin_x,origin_y,origin_z,relative_x,relative_y,relative_z,object,complexity"]
    c = (pts.min(0) + pts.max(0)) / 2
    for p, r in zip(pts, pts - c):
        lines.append(",".join(f"{v:.6f}" for v in (*p, *r)) + f",{label},1")
    path.write_text("\n".join(lines) + "\n")


def test_lidarnet_y_up_becomes_z_up_and_duplicates_drop(tmp_path):
    # a "pedestrian": 1.8 m tall along y (y up), 5 units per metre
    rng = np.random.default_rng(2)
    pts = rng.uniform([0, 0, 0], [0.5 * 5, 1.8 * 5, 0.3 * 5], size=(300, 3)) + [40, -2, 3]
    (tmp_path / "Ped").mkdir()
    _write_lidarnet(tmp_path / "Ped" / "p1.csv", pts, "pedestrian")
    (tmp_path / "Ped" / "p2.csv").write_bytes((tmp_path / "Ped" / "p1.csv").read_bytes())  # duplicate
    _write_lidarnet(tmp_path / "Ped" / "p3.csv", pts[:100], "pedestrian")
    (tmp_path / "MANIFEST.csv").write_text("relpath\n")
    scan = read_lidarnet_csv(tmp_path / "Ped" / "p1.csv")
    assert scan.label == "pedestrian"
    np.testing.assert_allclose(scan.extent_m[2], 1.8, rtol=0.02)  # height is z, in metres
    assert scan.extent_m[2] > scan.extent_m[0] and scan.extent_m[2] > scan.extent_m[1]
    assert math.isclose(float(np.ptp(scan.points[:, 2])), 1.0, rel_tol=1e-6)
    scans = load_real_scans(tmp_path)
    assert [Path(s.source).name for s in scans] == ["p1.csv", "p3.csv"]
    assert len(load_real_scans(tmp_path, dedupe=False)) == 3


def test_lidarnet_axes_are_a_proper_rotation(tmp_path):
    # (x, y, z) with y up → (x, −z, y): z up, handedness kept (a mirror would flip a chiral shape)
    pts = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 0.0, 15.0]])
    _write_lidarnet(tmp_path / "a.csv", pts, "car")
    scan = read_lidarnet_csv(tmp_path / "a.csv")
    expected = normalize_points(np.stack([pts[:, 0], -pts[:, 2], pts[:, 1]], axis=1))
    np.testing.assert_allclose(scan.points, expected, atol=1e-6)
    np.testing.assert_allclose(scan.extent_m, [1.0, 3.0, 2.0], rtol=1e-6)  # 5 units per metre


def test_lidarnet_bad_header(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("a,b,c\n1,2,3\n")
    with pytest.raises(InvalidInputError, match="not a LiDARNet CSV"):
        read_lidarnet_csv(p)


def test_load_real_scans_missing_path(tmp_path):
    with pytest.raises(ZbufOccludeError, match="does not exist"):
        load_real_scans(tmp_path / "nope")


if LIDARNET.is_dir():  # extra coverage next to ../shared; a fresh clone has nothing to skip

    @pytest.mark.slow
    def test_real_lidarnet_tree():
        scans = load_real_scans(LIDARNET)
        labels = {s.label for s in scans}
        assert labels == {"bush", "car", "pedestrian", "pole"}
        assert len(scans) == 724 - 37  # SOURCE.md: 37 byte-identical duplicates
        ped = np.median([s.extent_m[2] for s in scans if s.label == "pedestrian"])
        assert 1.3 < ped < 2.0  # metres, z up


def test_car_scores_hand_made_confusion():
    # real classes (rows) × model classes (columns: car, chair, table)
    true_names = ["4wd", "car", "pedestrian", "van"]
    pred_names = ["car", "chair", "table"]
    cm = np.array([
        [6, 3, 1],   # 4wd: 10 scans, 6 predicted car
        [18, 2, 0],  # car: 20 scans, 18 predicted car
        [2, 5, 3],   # pedestrian predicted car twice → FP = 2
        [0, 4, 1],   # van: never car
    ])  # fmt: skip
    out = car_scores(cm, true_names, pred_names)
    rows = {r["class"]: r for r in out["per_class"]}
    assert set(rows) == {"4wd", "car", "van"} and out["fp"] == 2 and out["n_scans"] == 45
    r = rows["4wd"]
    assert (r["tp"], r["fn"], r["fp"]) == (6, 4, 2)
    assert math.isclose(r["accuracy"], 0.6) and math.isclose(r["precision"], 6 / 8)
    assert math.isclose(r["f1"], 2 * 6 / (2 * 6 + 2 + 4))
    assert math.isclose(rows["car"]["f1"], 36 / 40)
    assert rows["van"]["f1"] == 0.0
    assert math.isclose(out["mean_f1"], (12 / 18 + 36 / 40 + 0.0) / 3)
    with pytest.raises(InvalidInputError):
        car_scores(cm[:, :2], true_names, pred_names)
    with pytest.raises(InvalidInputError, match="no model class"):
        car_scores(cm, true_names, pred_names, predicted_car="truck")


def test_car_scores_from_labels_with_label_map():
    true = ["Car", "Car", "Car", "pole", "pole"]
    pred = ["car", "car", "chair", "car", "lamp"]
    out = car_scores_from_labels(true, pred, model_classes=["car", "chair", "lamp"], label_map={"Car": "car"})
    (row,) = out["per_class"]
    assert (row["class"], row["tp"], row["fn"], row["fp"]) == ("car", 2, 1, 1)
    assert out["confusion"].sum() == 5
    with pytest.raises(InvalidInputError, match="not model classes"):
        car_scores_from_labels(["car"], ["boat"], model_classes=["car"])
