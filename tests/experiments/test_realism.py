"""Realism statistics (issue 12): ring spacing, count-vs-range exponent, readers, report."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

import zbuf_occlude.sensors as S
from zbuf_occlude.sensors.beam import Beam
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.realism import (
    cloud_stats,
    compare_sets,
    fit_count_exponent,
    read_object_clouds,
    realism_report,
    ring_spacings_deg,
)

LIDARNET = Path(__file__).resolve().parents[3] / "shared" / "data" / "lidarnet_v2_partial"


def test_ring_spacing_of_synthetic_rings():
    elev = np.radians(np.array([-10.0, -8.67, -7.33, -6.0, -3.33]))  # one ring missing
    az = np.radians(np.linspace(-5, 5, 40))
    e, a = np.meshgrid(elev, az)
    # symmetric elevation spread, wider on higher rings: the ring's centre is its median
    e = e + np.radians(np.linspace(-1.0, 1.0, len(az)))[:, None] * 0.05 * np.arange(1, 6)
    p = 8.0 * np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1).reshape(-1, 3)
    s = ring_spacings_deg(p)
    assert np.allclose(s, [1.33, 1.34, 1.33, 2.67], atol=0.01)
    assert np.median(s) == pytest.approx(1.335, abs=0.01)


@pytest.mark.parametrize("b", [-2.0, -1.0])
def test_fit_recovers_exponent(b):
    r = np.geomspace(3, 30, 50)
    noise = np.random.default_rng(0).normal(0, 0.05, len(r))
    got, se, a = fit_count_exponent(r, 5000 * r**b * np.exp(noise))
    assert abs(got - b) < 3 * se + 1e-9 and se < 0.05 and abs(a - math.log(5000)) < 0.2


@pytest.mark.slow
def test_wall_scans_fall_as_inverse_square(tmp_path):
    """A fixed extended object inside the FOV: count ∝ r^-2 (both angles shrink as 1/r); a fine
    custom beam table (0.1°) keeps ring discretisation out of the law."""
    lidar = S.Lidar(
        "fine",
        tuple(np.arange(-12.0, 12.01, 0.1)),
        rotation_hz=10.0,
        firing_rate_hz=36_000.0,
        beam=Beam(min_range_m=1.0, max_range_m=100.0),
    )
    for d in (6.0, 9.0, 13.0, 19.0):
        v = np.array([[d, -1.5, -1.0], [d, 1.5, -1.0], [d, 1.5, 1.0], [d, -1.5, 1.0]])  # centred near elevation 0
        S.scan(trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False), lidar, np.zeros(3)).to_npz(tmp_path / f"w{d:.0f}.npz")
    clouds = read_object_clouds(tmp_path)
    stats = [cloud_stats(c, ring_gap_deg=0.04) for c in clouds]
    b, se, _ = fit_count_exponent([s["range_m"] for s in stats], [s["n_points"] for s in stats])
    assert abs(b + 2.0) < 0.05
    assert all(abs(np.median(s["ring_spacings_deg"]) - 0.1) < 0.01 for s in stats)
    rows, g, r = compare_sets(clouds, clouds, ring_gap_deg=0.04)
    assert g["count_ratio_at_matched_range"] == pytest.approx(1.0, rel=0.1)
    assert {row["metric"]: row["met"] for row in rows}["median ring spacing, deg"] is True


def test_report_files_and_cli(tmp_path):
    from zbuf_occlude.cli.main import main

    out = tmp_path / "gen"
    assert (
        main(
            [
                "scan",
                "cylinder",
                "--extents",
                "0.3,0.3,6",
                "--distance",
                "4:12",
                "--azimuth",
                "0:360",
                "--samples",
                "4",
                "--crop",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "scan",
                "box",
                "--extents",
                "4.5,1.8,1.5",
                "--distance",
                "8",
                "--out",
                str(tmp_path / "full"),
                "--format",
                "both",
                "--frame",
                "world",
            ]
        )
        == 0
    )
    full = S.read_scan_npz(next((tmp_path / "full").glob("*.npz")))
    assert set(np.unique(full.object_id)) == {0, 1} and np.allclose(full.sensor_position, [0, 0, 1.8])
    box = full.crop(1).points
    assert abs(box[:, 2].max() - 1.5) < 0.1 and box[:, 2].min() > -0.05  # stands on the ground, 1.5 m tall
    rows, _ = realism_report(out, out, tmp_path / "rep", figure=False)
    assert (tmp_path / "rep" / "realism.md").read_text().count("|") > 20 and (tmp_path / "rep" / "realism.csv").exists()
    met = {row["metric"].split(",")[0]: row["met"] for row in rows}
    assert met["median ring spacing"] is True and met["count-vs-range exponent b (count ∝ r^b)"] is True
    with pytest.raises(InvalidInputError):
        read_object_clouds(tmp_path / "nothing")
    assert main(["scan", "box", "--distance", "5:2", "--out", str(tmp_path / "x")]) == 2


def _synthetic_lidarnet(folder: Path) -> Path:
    """An HDL-32E scan of a car-sized box written as LiDARNet v2 CSVs (y up, 5 units per metre)."""
    folder.mkdir(parents=True, exist_ok=True)
    for k, d in enumerate((6.0, 9.0)):
        scene = S.ScanScene().add({"box_m": [4.5, 1.8, 1.5]}, position_m=(d, 0.0))
        p = S.scan(scene, S.Lidar.preset("hdl32e"), seed=k).crop(1).points.astype(np.float64)
        origin = np.column_stack([p[:, 0], p[:, 2], -p[:, 1]]) * 5.0
        rel = origin - (origin.min(0) + origin.max(0)) / 2
        rows = [",".join([*(f"{v:.6g}" for v in (*o, *r)), "car", "1"]) for o, r in zip(origin, rel)]
        (folder / f"car{k}.csv").write_text(
            "origin_x,origin_y,origin_z,relative_x,relative_y,relative_z,object,complexity\n" + "\n".join(rows) + "\n"
        )
    return folder


@pytest.mark.parametrize("cls", ["synthetic", *(c for c in ("Car", "Trunk") if (LIDARNET / c).is_dir())])
def test_lidarnet_rings_are_the_hdl32e_table(cls, tmp_path):
    """LiDARNet CSVs are read in the sensor frame (z up, metres) and their rings are the HDL-32E
    table's; ``synthetic`` (always run) checks the reader on a simulated scan written in that
    format, the real classes (with ../shared) check the data."""
    folder = _synthetic_lidarnet(tmp_path / "Car") if cls == "synthetic" else LIDARNET / cls
    clouds = read_object_clouds(folder)
    spacing = np.concatenate([ring_spacings_deg(c.points_m) for c in clouds])
    table = np.diff(S.Lidar.preset("hdl32e").elevations_deg)
    assert abs(np.median(spacing) - np.median(table)) < 0.01
    if cls == "synthetic":
        assert len(clouds) == 2
        for c, d in zip(sorted(clouds, key=lambda c: c.source), (6.0, 9.0)):
            assert abs(np.percentile(c.points_m[:, 0], 1) - (d - 2.25)) < 0.05  # the box's near face, metres
            assert abs(np.percentile(c.points_m[:, 2], 99) - (1.5 - 1.8)) < 0.05  # its top, below the sensor


def test_ground_in_crops_counts_a_crops_ground_returns_and_nothing_else(tmp_path):
    from zbuf_occlude.cli.main import main

    crops, full = tmp_path / "crops", tmp_path / "full"
    assert (
        main(["scan", "box", "--extents", "4.5,1.8,1.5", "--distance", "8", "--crop", "--ground-margin", "0.5", "--out", str(crops)]) == 0
    )
    assert main(["scan", "box", "--extents", "4.5,1.8,1.5", "--distance", "8", "--out", str(full)]) == 0
    scan = S.read_scan_npz(next(crops.glob("*.npz")))
    n_object, n_ground = int(np.sum(scan.object_id == 1)), int(np.sum(scan.object_id == 0))
    assert n_object > 0 and n_ground > 0
    (alone,) = read_object_clouds(crops)
    (with_ground,) = read_object_clouds(crops, ground_in_crops=True)
    assert len(alone.points_m) == n_object and len(with_ground.points_m) == n_object + n_ground
    # without the option the ground never counts, in a crop or in a full scan of the sector
    (full_cloud,) = read_object_clouds(full)
    assert len(full_cloud.points_m) == int(np.sum(S.read_scan_npz(next(full.glob("*.npz"))).object_id == 1))


def test_ground_in_crops_leaves_a_scan_of_several_objects_as_it_is(tmp_path):
    boxes = [S.SceneObject(trimesh.creation.box(extents=(1.0, 1.0, 1.0)), position_m=(6.0, y)) for y in (-2.0, 2.0)]
    scan = S.scan(S.ScanScene(objects=boxes), with_beam(S.Lidar.preset("vlp16"), range_noise_m=0.0), [0.0, 0.0, 1.0])
    scan.to_npz(tmp_path / "two.npz")
    assert set(np.unique(scan.object_id)) == {0, 1, 2}
    for flag in (False, True):  # not a crop: each object alone, never the ground
        clouds = read_object_clouds(tmp_path, ground_in_crops=flag)
        assert sorted(len(c.points_m) for c in clouds) == sorted(int(np.sum(scan.object_id == i)) for i in (1, 2))


# -- per class: points per crop, height / width, vertical distribution (aerial crops) --------------------
def _shaft(rng, n: int = 60) -> np.ndarray:
    """A pole as a tall shaft: points all the way up a 0.3 m wide, 8 m tall cylinder."""
    a, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(0.0, 8.0, n)
    return np.column_stack([0.15 * np.cos(a), 0.15 * np.sin(a), z])


def _squat_top(rng, n: int = 60) -> np.ndarray:
    """A pole as aerial crops show it: a 1.2 m wide lamp head 0.6 m tall, three points on the shaft below."""
    r, a = 0.6 * np.sqrt(rng.uniform(0, 1, n - 3)), rng.uniform(0, 2 * np.pi, n - 3)
    head = np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(7.4, 8.0, n - 3)])
    return np.vstack([head, [[0.1, 0.0, 2.0], [0.1, 0.0, 4.0], [0.1, 0.0, 6.0]]])


def test_shape_stats_of_a_shaft_and_a_squat_top() -> None:
    from zbuf_occlude.experiments.realism import HEIGHT_BINS, shape_stats

    rng = np.random.default_rng(0)
    shaft, top = shape_stats(_shaft(rng)), shape_stats(_squat_top(rng))
    assert shaft["height_to_width"] > 20 and 0.35 < shaft["median_normalised_height"] < 0.65
    assert top["height_to_width"] < 8.0 / 1.0 and top["median_normalised_height"] > 0.9
    assert top["height_shares"][-1] > 0.9 and top["height_shares"].sum() == pytest.approx(1.0)
    assert len(shaft["height_shares"]) == HEIGHT_BINS and shaft["height_shares"].max() < 0.3
    # the width is along the footprint's principal axis: a turned box measures the same
    box = rng.uniform([-2.0, -0.5, 0.0], [2.0, 0.5, 1.5], (400, 3))
    c, s_ = np.cos(0.7), np.sin(0.7)
    turned = box @ np.array([[c, s_, 0], [-s_, c, 0], [0, 0, 1]])
    assert shape_stats(turned)["width_m"] == pytest.approx(shape_stats(box)["width_m"], rel=1e-9)
    assert shape_stats(box)["width_m"] == pytest.approx(4.0, abs=0.1)


def test_compare_classes_reveals_tall_shafts_against_squat_tops() -> None:
    from zbuf_occlude.experiments.realism import ObjectCloud, class_table, compare_classes

    rng = np.random.default_rng(1)
    generated = [ObjectCloud(_shaft(rng), "pole", f"g{i}") for i in range(6)]
    real = [ObjectCloud(_squat_top(rng) + [480_000.0, 5_400_000.0, 95.0], "pole", f"r{i}") for i in range(6)]  # projected coordinates
    rows, table = compare_classes(generated, real)
    met = {row["metric"].split(" (")[0]: row["met"] for row in rows}
    assert met["pole: median height / width"] is False and met["pole: median height above the crop's bottom, share of its height"] is False
    assert met["pole: share of points in another tenth of the height"] is False
    assert met["pole: median points per crop"] is True  # as many points: only the shape differs
    assert table["pole"]["generated"]["height_to_width"] > 3 * table["pole"]["real"]["height_to_width"]
    assert "| pole | generated | 6 |" in class_table(table) and "| pole | real | 6 |" in class_table(table)
    # the same clouds against themselves meet every target; without a shared class every cloud is pooled as "all"
    same_rows, _ = compare_classes(real, real)
    assert all(row["met"] is True for row in same_rows)
    pooled_rows, pooled = compare_classes([ObjectCloud(c.points_m, "object1", c.source) for c in generated], real)
    assert list(pooled) == ["all"] and pooled_rows[0]["metric"].startswith("all: ")


@pytest.mark.slow
def test_realism_command_compares_airborne_crops_per_class(tmp_path, capsys) -> None:
    """Simulated airborne crops of poles (tall shafts) and cars against 'real' class folders of .xyz crops:
    squat lamp heads for the poles, other simulated cars for the cars. The table flags the poles, not the cars."""
    import csv

    from zbuf_occlude.cli.main import main

    gen, real = tmp_path / "gen", tmp_path / "real"
    common = ["--sensor", "dales-q1560", "--crop", "--samples", "4"]
    assert main(["scan", "cylinder", "--extents", "0.3,=,8", *common, "--out", str(gen / "pole")]) == 0
    assert main(["scan", "box", "--extents", "4.5,1.8,1.5", "--yaw", "0:360", *common, "--out", str(gen / "car")]) == 0
    assert main(["scan", "box", "--extents", "4.5,1.8,1.5", "--yaw", "0:360", *common, "--seed", "9", "--out", str(tmp_path / "cars")]) == 0
    rng = np.random.default_rng(2)
    (real / "pole").mkdir(parents=True)
    (real / "car").mkdir()
    for i in range(4):
        np.savetxt(real / "pole" / f"{i}.xyz", _squat_top(rng) + [480_000.0, 5_400_000.0, 95.0], fmt="%.3f")
    for i, f in enumerate(sorted((tmp_path / "cars").glob("*.npz"))):
        np.savetxt(real / "car" / f"{i}.xyz", S.read_scan_npz(f).points.astype(np.float64) + [480_000.0, 5_400_000.0, 95.0], fmt="%.3f")
    capsys.readouterr()
    assert main(["realism", str(gen), str(real), "--airborne", "--out", str(tmp_path / "rep")]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("reading ") and "| pole | generated | 4 |" in printed and "ring spacing" not in printed
    with open(tmp_path / "rep" / "realism.csv", newline="", encoding="utf-8") as fh:
        met = {row["metric"].split(" (")[0]: row["met"] for row in csv.DictReader(fh)}
    assert met["pole: median height / width"] == "False" and met["car: median height / width"] == "True"
    assert met["pole: median height above the crop's bottom, share of its height"] == "False"
    assert met["car: median height above the crop's bottom, share of its height"] == "True"
    with open(tmp_path / "rep" / "realism_classes.csv", newline="", encoding="utf-8") as fh:
        classes = list(csv.DictReader(fh))
    assert {(r["class"], r["set"]) for r in classes} == {(k, s) for k in ("car", "pole") for s in ("generated", "real")}
    assert all(sum(float(r[f"share_{b / 10:g}_{(b + 1) / 10:g}"]) for b in range(10)) == pytest.approx(1.0) for r in classes)
    assert (tmp_path / "rep" / "realism.png").stat().st_size > 0


@pytest.mark.parametrize("name", ["scan.npz", "scan.csv"])
def test_a_scan_file_linking_out_of_the_folder_is_refused_before_it_is_read(tmp_path, name) -> None:
    """A shared folder's ``car/scan.npz`` that links to a private file elsewhere is not a scan:
    refused naming the link and the folder, and the file's bytes appear in no message."""
    from zbuf_occlude.errors import UnsafePathError

    secret = tmp_path / "outside" / "credentials"
    secret.parent.mkdir()
    secret.write_text("aws_secret_access_key = SECRET-MARKER\n")
    root = tmp_path / "scans"
    (root / "car").mkdir(parents=True)
    (root / "car" / name).symlink_to(secret)
    with pytest.raises(UnsafePathError) as info:
        read_object_clouds(root)
    text = str(info.value)
    assert str(root) in text and name in text and "SECRET-MARKER" not in text and "\n" not in text
