"""Realism statistics (issue 12): ring spacing, count-vs-range exponent, readers, report."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
import trimesh

import zbuf_occlude.sensors as S
from zbuf_occlude.sensors.beam.fields import Beam
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
    assert "median outline share (points ending a run of their ring)" in met  # sensor-frame scans: the outline and ranges
    header = (tmp_path / "rep" / "realism_classes.csv").read_text().splitlines()[0].split(",")
    assert {"outline_share", "count_exponent", "n_points_by_range_5-10_m", "crops_by_range_20-25_m"} <= set(header)
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
    # the plan elongation: a 4 x 1 m footprint spreads four times as far along as across; a round one as far
    assert shape_stats(box)["plan_elongation"] == pytest.approx(4.0, rel=0.1)
    assert shape_stats(_shaft(rng))["plan_elongation"] < 1.4
    line = np.column_stack([np.linspace(0, 3, 20), np.zeros(20), np.linspace(0, 1, 20)])
    assert math.isnan(shape_stats(line)["plan_elongation"])  # a line has no breadth


@settings(max_examples=25, deadline=None)
@given(
    angle=st.floats(0.0, 2 * np.pi),
    scale=st.floats(0.01, 100.0),
    shift=st.tuples(*[st.floats(-1e3, 1e3)] * 3),
    seed=st.integers(0, 2**32 - 1),
)
def test_plan_elongation_is_of_the_footprint_s_proportions_alone(angle: float, scale: float, shift: tuple, seed: int) -> None:
    """Turning a crop about z, scaling it or moving it leaves its plan elongation as it was (a heading-free statistic)."""
    from zbuf_occlude.experiments.realism import shape_stats

    crop = np.random.default_rng(seed).uniform([-2.0, -0.5, 0.0], [2.0, 0.5, 1.5], (100, 3))
    c, s_ = np.cos(angle), np.sin(angle)
    moved = scale * crop @ np.array([[c, s_, 0], [-s_, c, 0], [0, 0, 1]]) + shift
    assert shape_stats(moved)["plan_elongation"] == pytest.approx(shape_stats(crop)["plan_elongation"], rel=1e-6)


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
    assert not any(key.startswith(("n_points_by_range", "outline")) for key in classes[0])  # aerial crops: no sensor, no range
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


# -- outline share: the points that end a run of their ring's scan line ----------------------------
def _ring(elevation_deg: float, azimuths_deg, range_m=10.0) -> np.ndarray:
    """Points of one ring at ``elevation_deg``, at ``azimuths_deg`` (degrees) and ``range_m`` (metres, one or one per point)."""
    e, a = np.radians(elevation_deg), np.radians(np.asarray(azimuths_deg, dtype=np.float64))
    r = np.broadcast_to(np.asarray(range_m, dtype=np.float64), a.shape)
    return np.column_stack([r * np.cos(e) * np.cos(a), r * np.cos(e) * np.sin(a), r * np.full_like(a, np.sin(e))])


def _known_runs() -> tuple[np.ndarray, np.ndarray]:
    """Two rings, 0.2° azimuth steps: the lower one in runs of 5, 1 and 3 points 1° apart, the upper one
    run of 4; and which points end a run (7 of 13)."""
    low = np.concatenate([np.arange(5) * 0.2, [1.8], 2.8 + np.arange(3) * 0.2])
    points = np.vstack([_ring(-5.0, low), _ring(-3.67, 0.1 + np.arange(4) * 0.2)])
    ends = np.zeros(13, dtype=bool)
    ends[[0, 4, 5, 6, 8, 9, 12]] = True
    return points, ends


def test_outline_of_rings_with_known_runs() -> None:
    from zbuf_occlude.experiments.realism import outline_mask, outline_share, ring_labels

    points, ends = _known_runs()
    assert ring_labels(points).tolist() == [0] * 9 + [1] * 4
    shuffle = np.random.default_rng(0).permutation(len(points))  # the input's order does not matter
    assert np.array_equal(outline_mask(points[shuffle]), ends[shuffle])
    assert outline_share(points) == pytest.approx(7 / 13)
    # a given step of 1°: the 1° gaps are the scan line going on, one run per ring
    assert np.flatnonzero(outline_mask(points, azimuth_step_deg=1.0)).tolist() == [0, 8, 9, 12]
    # a tighter factor splits at every gap wider than 1.2 steps: nothing here (the gaps are 1 or 5 steps)
    assert np.array_equal(outline_mask(points, gap_factor=1.2), ends)
    # a factor of 6 steps: one run per ring
    assert outline_mask(points, gap_factor=6.0).sum() == 4


def test_scan_line_runs_of_rings_with_known_runs() -> None:
    from zbuf_occlude.experiments.realism import scan_line_runs

    points, _ = _known_runs()
    shuffle = np.random.default_rng(1).permutation(len(points))
    ring, length = scan_line_runs(points[shuffle])
    assert ring.tolist() == [0, 0, 0, 1] and length.tolist() == [5, 1, 3, 4]
    assert [v.tolist() for v in scan_line_runs(points, azimuth_step_deg=1.0)] == [[0, 1], [9, 4]]
    assert [v.tolist() for v in scan_line_runs(np.zeros((0, 3)))] == [[], []]


def test_outline_runs_across_the_back_of_the_sensor_and_returns_of_one_pulse() -> None:
    from zbuf_occlude.experiments.realism import outline_mask, outline_share

    points, ends = _known_runs()
    turn = np.radians(179.0)  # the runs now cross azimuth ±180°
    c, s = np.cos(turn), np.sin(turn)
    behind = points @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    assert np.array_equal(outline_mask(behind), ends)
    # every pulse with two returns (the same direction, 10 and 11 m): one run, whose first and last points end it
    azimuths = np.repeat(np.arange(20) * 0.2, 2)
    two = _ring(-5.0, azimuths, np.tile([10.0, 11.0], 20))
    assert outline_mask(two).sum() == 2 and outline_share(two) == pytest.approx(2 / 40)
    assert outline_share(_ring(-5.0, [0.0])) == 1.0 and math.isnan(outline_share(np.zeros((0, 3))))


@pytest.mark.parametrize(
    ("points", "options", "match"),
    [
        (np.ones((4, 2)), {}, "shape"),
        (np.array([[1.0, 0.0, np.nan]]), {}, "finite"),
        (np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]), {}, "origin"),
        (np.ones((2, 3)), {"gap_factor": 0.0}, "gap_factor"),
        (np.ones((2, 3)), {"azimuth_step_deg": -0.2}, "azimuth_step_deg"),
        (np.ones((2, 3)), {"azimuth_step_deg": math.inf}, "azimuth_step_deg"),
    ],
)
def test_outline_refuses_bad_points_and_options(points, options, match) -> None:
    from zbuf_occlude.experiments.realism import outline_mask

    with pytest.raises(InvalidInputError, match=match):
        outline_mask(points, **options)


def test_a_cloud_with_a_point_at_the_sensor_is_refused_naming_its_file() -> None:
    from zbuf_occlude.experiments.realism import ObjectCloud, class_summary

    cloud = ObjectCloud(np.array([[5.0, 0.0, -1.0], [0.0, 0.0, 0.0], [5.0, 0.1, -1.0]]), "car", "Car/car7.csv")
    for stats in (lambda: cloud_stats(cloud), lambda: class_summary([cloud], by_range=True)):
        with pytest.raises(InvalidInputError, match=r"Car/car7\.csv: points: .*origin"):
            stats()


@given(st.integers(2, 300), st.floats(0.05, 1.0), st.floats(-30.0, 10.0), st.floats(2.0, 60.0), st.floats(-180.0, 180.0), st.data())
@settings(max_examples=80, deadline=None)
def test_one_run_of_m_points_has_outline_share_two_over_m(m, step, elevation, range_m, start, data) -> None:
    """Gaps from one to 1.4 steps never split a run (the median gap is at least one step, the split at 1.5 of it), on an
    object seen from outside: a run under 180° of azimuth (a ring of nearly a full turn is cut ±180° from its centroid's
    azimuth, which uneven gaps move into it)."""
    from zbuf_occlude.experiments.realism import outline_mask, outline_share

    assume(1.4 * step * (m - 1) < 180.0)
    gaps = np.asarray(data.draw(st.lists(st.floats(1.0, 1.4), min_size=m - 1, max_size=m - 1))) * step
    points = _ring(elevation, start + np.concatenate([[0.0], np.cumsum(gaps)]), range_m)
    assert outline_share(points) == 2 / m and outline_mask(points).sum() == 2


@given(st.lists(st.tuples(st.integers(0, 5), st.floats(-20.0, 20.0), st.floats(3.0, 40.0)), min_size=1, max_size=120))
@settings(max_examples=80, deadline=None)
def test_outline_share_lies_in_0_1_and_each_ring_has_an_outline(rows) -> None:
    from zbuf_occlude.experiments.realism import outline_mask, outline_share, ring_labels, scan_line_runs

    ring, azimuth, range_m = (np.array(v, dtype=np.float64) for v in zip(*rows))
    points = np.vstack([_ring(-10.0 + 1.33 * k, [a], r) for k, a, r in zip(ring, azimuth, range_m)])
    share, mask, labels = outline_share(points), outline_mask(points), ring_labels(points)
    assert 0.0 < share <= 1.0
    run_ring, length = scan_line_runs(points)  # every point in one run; two outline points a run, one for a run of one
    assert length.sum() == len(points) and (length >= 1).all() and mask.sum() == np.minimum(length, 2).sum()
    assert np.array_equal(np.unique(run_ring), np.unique(labels))
    assert len(np.unique(labels)) == len(np.unique(ring))  # the rings are 1.33° apart, well over the gap
    assert all(mask[labels == r].sum() >= min(2, (labels == r).sum()) for r in np.unique(labels))


def test_scanned_box_outline_is_two_points_per_ring_and_rings_are_the_scanners() -> None:
    """An HDL-32E scan of a car-sized box: each ring crosses it in one run, so 2 outline points a ring
    (more than one point in each), with one return per pulse or with the 7-ray footprint's two;
    the rings from elevations are the scanner's own."""
    from zbuf_occlude.experiments.realism import outline_mask, ring_labels
    from zbuf_occlude.sensors.request import kept_returns

    scene = S.ScanScene().add({"box_m": [4.5, 1.8, 1.5]}, position_m=(8.0, 0.0))
    for sensor in (S.Lidar.preset("hdl32e"), kept_returns(S.Lidar.preset("hdl32e"), 2)):
        crop = S.scan(scene, sensor, seed=0).crop(1)
        p = crop.points.astype(np.float64)
        labels = ring_labels(p)
        assert np.array_equal(labels, np.unique(crop.ring, return_inverse=True)[1])  # the scanner's rings, lowest first
        assert len(np.unique(labels)) >= 5 and outline_mask(p).sum() == 2 * len(np.unique(labels))


def test_range_bin_medians_of_known_counts() -> None:
    from zbuf_occlude.experiments.realism import range_bin_medians

    ranges = [4.9, 5.0, 7.0, 9.99, 10.0, 12.0, 24.9, 25.0, 25.1]
    counts = [1000, 300, 200, 100, 90, 70, 20, 10, 5]
    medians, clouds = range_bin_medians(ranges, counts)
    assert clouds.tolist() == [3, 2, 0, 2]  # 4.9 and 25.1 m in no bin; 25 m in the last, closed
    assert medians[:2].tolist() == [200.0, 80.0] and math.isnan(medians[2]) and medians[3] == 15.0


def test_class_summary_by_range_gives_the_count_exponent_and_the_table_shows_it() -> None:
    from zbuf_occlude.experiments.realism import ObjectCloud, class_summary, class_table, compare_classes

    clouds = []
    for d in (6.0, 8.0, 11.0, 14.0, 18.0, 23.0):  # a wall of points whose count falls as d^-2, one run per ring
        n_rings, per_ring = 8, int(round(20 * (12.0 / d) ** 2 / 8 * 8))
        pts = np.vstack([_ring(-8.0 + 1.33 * k, np.arange(per_ring) * 0.2, d) for k in range(n_rings)])
        clouds.append(ObjectCloud(pts, "wall", f"w{d:g}"))
    summary = class_summary(clouds, by_range=True)
    counts = [len(c.points_m) for c in clouds]
    assert summary["count_exponent"] == pytest.approx(-2.0, abs=0.05)
    assert summary["crops_by_range"].tolist() == [2, 2, 1, 1]
    assert summary["n_points_by_range"][0] == np.median(counts[:2]) and summary["n_points_by_range"][3] == counts[5]
    per_ring = [len(c.points_m) / 8 for c in clouds]
    assert summary["outline_share"] == pytest.approx(np.median([2 / n for n in per_ring]))
    assert "n_points_by_range" not in class_summary(clouds)  # not asked: no range (an airborne crop's sensor is unknown)
    _, table = compare_classes(clouds, clouds, by_range=True)
    text = class_table(table)
    assert "median points at 5-10 m (crops)" in text and "| wall | real | 6 |" in text
    assert f"| {np.median(counts[:2]):.3f} (2) |" in text and "count exponent" in text
    _, plain = compare_classes(clouds, clouds)
    assert "count exponent" not in class_table(plain)


def _standing_figure(leg_m: float, shoulder_m: float, range_m: float = 8.0) -> np.ndarray:
    """A figure 1.6 m tall, 8 m in front of the sensor (+x), as 16 rows of points across the line of sight (y):
    the lower half ``leg_m`` wide, the upper half ``shoulder_m``, 1 cm apart."""
    rows = []
    for z in np.linspace(-1.8, -0.2, 16):
        w = leg_m if z < -1.0 else shoulder_m
        y = np.arange(-0.5 * w, 0.5 * w + 1e-9, 0.01)
        rows.append(np.column_stack([np.full_like(y, range_m), y, np.full_like(y, z)]))
    return np.vstack(rows)


def test_class_summary_by_range_gives_the_median_width_per_eighth_of_the_height() -> None:
    """Legs half as wide as the shoulders show as eighths half as wide as the top ones; the class's profile is the
    median over its crops of each crop's, and the Markdown table and the CSV rows carry it."""
    from zbuf_occlude.experiments.realism import ObjectCloud, _class_rows, class_summary, class_table, compare_classes
    from zbuf_occlude.sensors.fit import width_profile

    clouds = [ObjectCloud(_standing_figure(leg, 0.5), "pedestrian", f"p{k}") for k, leg in enumerate((0.2, 0.25, 0.3))]
    profile = class_summary(clouds, by_range=True)["width_profile"]
    assert profile.shape == (8,)
    assert profile[:4] / profile[4:] == pytest.approx(np.full(4, 0.5), abs=0.03)  # the median crop's legs: 0.25 of 0.5
    assert profile == pytest.approx(np.median([width_profile(c.points_m) for c in clouds], axis=0))
    assert "width_profile" not in class_summary(clouds)  # no sensor frame, no line of sight
    _, table = compare_classes(clouds, clouds, by_range=True)
    assert "median width per eighth of the height" in class_table(table)
    assert " ".join(f"{v:.2f}" for v in profile) in class_table(table)
    row = _class_rows(table)[0]
    assert [row[f"relative_width_{b / 8:g}_{(b + 1) / 8:g}"] for b in range(8)] == pytest.approx(profile.tolist())
    assert "width_profile" not in row


def test_break_depths_are_the_range_steps_across_the_breaks_of_known_runs() -> None:
    from zbuf_occlude.experiments.realism_stats import break_depths_m

    points, _ = _known_runs()  # the lower ring breaks twice (runs of 5, 1 and 3), the upper one never
    assert break_depths_m(points) == pytest.approx([0.0, 0.0], abs=1e-12)  # every point 10 m away
    # the lower ring's run of one point 0.4 m farther, its last run 1.5 m nearer: breaks 0.4 and 1.9 m deep
    ranges = np.concatenate([np.full(5, 10.0), [10.4], np.full(3, 8.5)])
    low = np.concatenate([np.arange(5) * 0.2, [1.8], 2.8 + np.arange(3) * 0.2])
    stepped = np.vstack([_ring(-5.0, low, ranges), points[9:]])
    shuffle = np.random.default_rng(2).permutation(len(stepped))  # the input's order does not matter
    assert break_depths_m(stepped[shuffle]) == pytest.approx([0.4, 1.9])
    assert break_depths_m(stepped, azimuth_step_deg=1.0).size == 0  # 1° gaps are the line going on
    assert break_depths_m(np.zeros((0, 3))).size == 0
