"""Realism statistics (issue 12): ring spacing, count-vs-range exponent, readers, report."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

import zbuf_occlude.sensors as S
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.realism import (
    cloud_stats,
    compare_sets,
    fit_count_exponent,
    read_object_clouds,
    realism_report,
    ring_spacings_deg,
)  # fmt: skip

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
    lidar = S.Lidar("fine", tuple(np.arange(-12.0, 12.01, 0.1)), rotation_hz=10.0, firing_rate_hz=36_000.0, range_noise_m=0.0)
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
    assert main(["scan", "cylinder", "--extents", "0.3,0.3,6", "--distance", "4:12", "--azimuth", "0:360", "--samples", "4", "--crop", "--out", str(out)]) == 0
    assert main(["scan", "box", "--extents", "4.5,1.8,1.5", "--distance", "8", "--out", str(tmp_path / "full"), "--format", "both", "--frame", "world"]) == 0
    full = S.read_scan_npz(next((tmp_path / "full").glob("*.npz")))
    assert set(np.unique(full.object_id)) == {0, 1} and np.allclose(full.sensor_position, [0, 0, 1.8])
    box = full.crop(1).points
    assert abs(box[:, 2].max() - 1.5) < 0.1 and box[:, 2].min() > -0.05  # stands on the ground, 1.5 m tall
    rows = realism_report(out, out, tmp_path / "rep", figure=False)
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
        (folder / f"car{k}.csv").write_text("origin_x,origin_y,origin_z,relative_x,relative_y,relative_z,object,complexity\n" + "\n".join(rows) + "\n")
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
    assert main(["scan", "box", "--extents", "4.5,1.8,1.5", "--distance", "8", "--crop", "--ground-margin", "0.5", "--out", str(crops)]) == 0
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
    scan = S.scan(S.ScanScene(objects=boxes), S.Lidar.preset("vlp16", range_noise_m=0.0), [0.0, 0.0, 1.0])
    scan.to_npz(tmp_path / "two.npz")
    assert set(np.unique(scan.object_id)) == {0, 1, 2}
    for flag in (False, True):  # not a crop: each object alone, never the ground
        clouds = read_object_clouds(tmp_path, ground_in_crops=flag)
        assert sorted(len(c.points_m) for c in clouds) == sorted(int(np.sum(scan.object_id == i)) for i in (1, 2))
