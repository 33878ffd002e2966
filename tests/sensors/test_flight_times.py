"""A flight plan's lines are flown one after another, and the scan writes the trajectory that flew them."""

from __future__ import annotations

import math

import laspy
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.cli.main import main
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors import airborne_preset
from zbuf_occlude.sensors.patterns.flight_times import TURN_S, flown_poses, line_length_m
from zbuf_occlude.sensors.platform import Trajectory, load_trajectory
from zbuf_occlude.sensors.scan_data import GPS_START_S

BLOCK = airborne_preset("dales-q1560")


def _pulses(scanner, center=(3.0, -2.0), half=6.0, seed=0):
    return scanner.pulses(center, half, np.random.default_rng(seed))


def test_a_blocks_lines_are_flown_one_after_another() -> None:
    p = _pulses(BLOCK)
    line = p.per_pulse_meta["line_id"]
    length = line_length_m((3.0, -2.0), 6.0)
    assert p.meta["line_length_m"] == length and np.all(p.time_s >= 0.0)
    flown = length / BLOCK.speed_mps
    ids = np.unique(line)
    assert len(ids) >= 5  # the strips that cover the square (about 6 of the 9 lines, 216 m apart, 1,441 m wide)
    for a, b in zip(ids[:-1], ids[1:]):
        ta, tb = p.time_s[line == a], p.time_s[line == b]
        assert ta.max() < tb.min()  # strictly ordered
        assert tb.min() - ta.min() >= flown  # at least the line's length over the speed apart
        assert tb.min() - ta.max() >= TURN_S  # the turn between them
    starts = np.asarray(p.meta["line_start_s"])
    assert np.allclose(np.diff(starts), flown + TURN_S, rtol=1e-12)


def test_the_trajectory_flies_through_every_pulse_origin() -> None:
    for scanner in (BLOCK, airborne_preset("riegl-q1560"), BLOCK.with_(headings_deg=(0.0, 90.0), n_lines=2)):
        p = _pulses(scanner)
        rotation, position = Trajectory(*p.meta["flight"]).poses_at(p.time_s)
        assert np.max(np.abs(position - p.origins)) < 1e-6  # metres, at 1,300 m
        line = p.per_pulse_meta["line_id"]
        heading = np.radians(np.asarray(scanner.headings_deg)[line // scanner.n_lines])
        assert np.allclose(rotation[:, :2, 0], np.column_stack([np.cos(heading), np.sin(heading)]), atol=1e-9)  # x along track


def test_opposite_headings_are_joined_by_a_half_way_pose() -> None:
    lines = BLOCK.with_(headings_deg=(0.0, 180.0), n_lines=1).flight_lines(0.0)
    t = Trajectory(*flown_poses(lines, 50.0, 1000.0, 50.0, 60.0))  # a half turn between the lines: the Trajectory would refuse it
    mid = np.flatnonzero((t.time_s > 1.0) & (t.time_s < 61.0))
    assert len(mid) == 1 and math.isclose(t.time_s[mid[0]], 31.0)


@settings(max_examples=30, deadline=None)
@given(st.floats(0.1, 600.0), st.floats(-50.0, 50.0), st.floats(-50.0, 50.0), st.floats(1.0, 40.0))
def test_line_times_follow_the_plan_for_any_turn_and_square(turn_s: float, cx: float, cy: float, half: float) -> None:
    scanner = BLOCK.with_(turn_s=turn_s, n_lines=3)
    p = _pulses(scanner, (cx, cy), half)
    if len(p.time_s) == 0:
        return
    length = line_length_m((cx, cy), half)
    line = p.per_pulse_meta["line_id"]
    start = line * (length / scanner.speed_mps + turn_s)
    assert np.all(p.time_s >= start - 1e-9) and np.all(p.time_s <= start + length / scanner.speed_mps + 1e-9)


@pytest.mark.parametrize("turn", [0.0, -1.0, math.nan, "2", 1e9])
def test_a_bad_turn_time_is_refused_naming_it(turn) -> None:
    with pytest.raises(InvalidInputError, match="turn_s"):
        BLOCK.with_(turn_s=turn)


def test_the_scan_command_writes_the_trajectory_read_back_as_flown(tmp_path, capsys) -> None:
    chair = "data/samples/chair/train/chair_0001.off"
    out = tmp_path / "air"
    assert main(["scan", chair, "--sensor", "dales-q1560", "--size", "3", "--format", "las", "--no-progress", "--out", str(out)]) == 0
    (las_path,) = out.glob("*.las")
    (csv_path,) = out.glob("*_trajectory.csv")
    assert "wrote 2 files" in capsys.readouterr().out
    las, trajectory = laspy.read(las_path), load_trajectory(csv_path)
    t = np.asarray(las.gps_time)
    assert t.min() >= GPS_START_S and trajectory.start_s == GPS_START_S
    # every return lies below the aircraft's position at its pulse's time, along its beam: within the swath, at altitude
    _, position = trajectory.poses_at(t)
    assert np.all(position[:, 2] == BLOCK.altitude_m)
    xy = np.column_stack([np.asarray(las.x), np.asarray(las.y)])
    across = np.abs(xy[:, 1] - position[:, 1])
    assert np.all(np.abs(xy[:, 0] - position[:, 0]) < 0.5) and np.all(across <= BLOCK.swath_width_m / 2.0)


def test_the_origin_option_puts_the_points_where_the_crs_says(tmp_path, capsys) -> None:
    """A scene made about its origin, written with ``--crs EPSG:2154 --origin E,N,H``: laspy reads the points at their world
    positions plus the origin, in Lambert-93 (their geographic position inside France), and the trajectory beside them too."""
    pytest.importorskip("pyproj")
    from pyproj import Transformer

    chair, origin = "data/samples/chair/train/chair_0001.off", (652_000.0, 6_862_000.0, 35.0)  # Paris in Lambert-93
    common = ["scan", chair, "--sensor", "riegl-q1560", "--size", "3", "--format", "las", "--no-progress", "--seed", "1"]
    assert main([*common, "--out", str(tmp_path / "local")]) == 0
    assert main([*common, "--crs", "EPSG:2154", "--origin", ",".join(map(str, origin)), "--out", str(tmp_path / "placed")]) == 0
    (local,), (placed,) = (sorted((tmp_path / d).glob("*.las")) for d in ("local", "placed"))
    a, b = laspy.read(local), laspy.read(placed)
    xyz = lambda las: np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])  # noqa: E731
    assert np.allclose(xyz(b), xyz(a) + origin, atol=1.5e-3)  # 1 mm steps in each file
    assert b.header.parse_crs().to_epsg() == 2154
    lon, lat = Transformer.from_crs(2154, 4326, always_xy=True).transform(float(np.mean(b.x)), float(np.mean(b.y)))
    assert 2.2 < lon < 2.5 and 48.7 < lat < 49.0  # Paris, not the Atlantic
    # the trajectory in the same coordinates (read as a table: load_trajectory reads a scene's frame, within ±16.8 km)
    ta, tb = (np.loadtxt(next((tmp_path / d).glob("*_trajectory.csv")), delimiter=",", skiprows=1) for d in ("local", "placed"))
    assert np.allclose(tb[:, 1:4], ta[:, 1:4] + origin, atol=1e-6) and np.array_equal(tb[:, [0, 4, 5, 6]], ta[:, [0, 4, 5, 6]])


def test_an_origin_needs_the_world_frame_and_good_numbers(tmp_path, capsys) -> None:
    common = ["scan", "box", "--format", "las", "--no-progress", "--out", str(tmp_path / "o")]
    assert main([*common, "--sensor", "hdl32e", "--origin", "1,2"]) == 2
    assert "--origin places the world frame's origin: it needs --frame world" in capsys.readouterr().err
    for bad, says in (("1,2,3,4", "2 or 3"), ("nan,1", "finite"), ("1e9,0", "finite number in"), ("abc", "E,N or E,N,H")):
        assert main([*common, "--sensor", "riegl-q1560", "--origin", bad]) == 2
        assert says in capsys.readouterr().err
    assert main(["scan", "box", "--sensor", "riegl-q1560", "--no-progress", "--origin", "1,2", "--out", str(tmp_path / "n")]) == 2
    assert "--origin fills LAS/LAZ files" in capsys.readouterr().err


def test_a_block_reaching_beyond_a_trajectorys_bound_scans_without_one() -> None:
    """200 lines a swath apart reach ±143 km: the scan runs as before, with no trajectory to write."""
    import zbuf_occlude as zo
    from zbuf_occlude.sensors import scan_airborne

    wide = BLOCK.with_(n_lines=200, side_overlap=0.0)
    scene = zo.ScanScene(ground_half_extent_m=20.0).add({"box_m": [2.0, 2.0, 2.0]}, position_m=(0.0, 0.0))
    s = scan_airborne(scene, wide, (0.0, 0.0), 5.0, seed=0, lateral_shift_m=0.0)
    assert len(s) > 0 and "trajectory" not in s.meta and "flight" not in s.meta
