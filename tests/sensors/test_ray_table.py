"""A ray table as a sensor (:class:`~zbuf_occlude.sensors.patterns.ray_table.RayTable`): a given table is reproduced
exactly (each point along its row's direction, at its row's time, with its row as pulse id), it scans as the
LiDAR whose rays it lists, its columns are checked, and hostile files are one line naming the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

import zbuf_occlude.sensors.patterns.ray_table as ray_table_module
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.ray_tables import ray_table_bytes
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.kinds import SENSOR_KINDS, with_beam
from zbuf_occlude.sensors.patterns.spinning import Lidar, beam_directions, lidar_preset
from zbuf_occlude.sensors.patterns.ray_table import ROSETTE_FOV_DEG, RayTable, load_ray_table, rosette_table
from zbuf_occlude.sensors.scan import scan

RADIUS_M = 10.0


@pytest.fixture(scope="module")
def sphere() -> trimesh.Trimesh:
    """A closed sphere of radius 10 m about the sensor: every ray hits it."""
    return trimesh.creation.icosphere(subdivisions=3, radius=RADIUS_M)


def _random_table(n: int, seed: int = 0, *, max_elevation: float = 80.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    time_s = np.cumsum(rng.exponential(1e-5, n)) + 1.6e9  # GPS-like seconds: float64 digits matter
    time_s[5:8] = time_s[5]  # equal times are allowed (several beams at once)
    return time_s, rng.uniform(-360.0, 360.0, n), rng.uniform(-max_elevation, max_elevation, n)


def _angles(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth and elevation, degrees, of directions ``d (N, 3)``: the inverse of ``beam_directions``."""
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    return np.degrees(np.arctan2(d[:, 1], d[:, 0])), np.degrees(np.arcsin(np.clip(d[:, 2], -1.0, 1.0)))


def _azimuth_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs((a - b + 180.0) % 360.0 - 180.0)


def test_rays_follow_the_lidar_convention_to_1e_9_degrees() -> None:
    time_s, az, el = _random_table(2000, max_elevation=89.0)
    table = RayTable("t", time_s, az, el)
    d, row, azimuth = table.rays()
    assert np.array_equal(row, np.arange(2000)) and np.array_equal(azimuth, az)
    assert np.array_equal(d, beam_directions(el, az))  # the LiDAR's own function, not a copy
    got_az, got_el = _angles(d)
    assert _azimuth_gap(got_az, az).max() < 1e-9 and np.abs(got_el - el).max() < 1e-9
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=0, atol=1e-15)


def test_a_scan_reproduces_the_table_exactly(sphere) -> None:
    """Every row one point: along the row's direction, at the row's time bit for bit, pulse id the row."""
    time_s, az, el = _random_table(3000)
    table = RayTable("t", time_s, az, el)  # the ideal beam: no noise
    s = scan(sphere, table, np.eye(4), frame="sensor")
    assert np.array_equal(np.sort(s.pulse_id), np.arange(3000))  # every row once
    row = s.pulse_id
    assert s.gps_time.dtype == np.float64 and s.gps_time.tobytes() == time_s[row].tobytes()
    assert np.array_equal(s.scan_angle_deg, el[row].astype(np.float32))
    assert s.ring is None and s.pixel is None and np.all(s.return_number == 1) and np.all(s.number_of_returns == 1)
    # the points are float32 (Scan.points): their directions hold the table's to float32's precision
    got_az, got_el = _angles(s.points.astype(np.float64))
    assert _azimuth_gap(got_az, az[row]).max() < 2e-5 and np.abs(got_el - el[row]).max() < 2e-5
    assert np.all((s.range_m > 0.99 * RADIUS_M) & (s.range_m <= RADIUS_M))  # the icosphere's facets lie within 1 % inside it


def test_a_table_in_world_frame_turns_with_the_pose(sphere) -> None:
    time_s, az, el = _random_table(500)
    table = RayTable("t", time_s, az, el)
    c, s_ = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    pose = np.array([[c, -s_, 0, 0.5], [s_, c, 0, -0.25], [0, 0, 1, 0.1], [0, 0, 0, 1.0]])
    s = scan(sphere, table, pose, frame="world")
    direction = (s.points.astype(np.float64) - pose[:3, 3]) @ pose[:3, :3]  # back to the sensor frame
    got_az, got_el = _angles(direction)
    assert _azimuth_gap(got_az, az[s.pulse_id]).max() < 1e-4 and np.abs(got_el - el[s.pulse_id]).max() < 1e-4


def _lidar_rows(lidar: Lidar, pulse_id: np.ndarray) -> np.ndarray:
    """The row of :meth:`RayTable.from_lidar`'s table of each LiDAR pulse id (``ring · n_azimuths + firing``)."""
    ring, firing = np.divmod(pulse_id, lidar.n_azimuths)
    return firing * lidar.n_beams + ring


@pytest.mark.parametrize(
    "changes",
    [
        {},
        {"footprint_rays": 7, "divergence_deg": 3.0, "max_returns": 3, "range_resolution_m": 0.5},
    ],
    ids=["one-return", "footprint-and-returns"],
)
def test_the_table_of_a_lidar_scans_as_the_lidar(changes: dict) -> None:
    """Same points, ranges, faces, times, scan angles and returns, pulse by pulse (noise off: the draws follow pulse order)."""
    lidar = with_beam(lidar_preset("vlp16", firing_rate_hz=3600.0), range_noise_m=0.0, **changes)
    table = RayTable.from_lidar(lidar)
    assert len(table) == lidar.n_beams * lidar.n_azimuths and np.all(np.diff(table.time_s) >= 0)
    # a wall 8 m ahead with a pole before it: edges in every footprint near the pole
    wall = trimesh.creation.box((0.2, 12.0, 6.0), trimesh.transformations.translation_matrix((8.0, 0.0, 0.0)))
    pole = trimesh.creation.cylinder(radius=0.05, height=6.0, transform=trimesh.transformations.translation_matrix((5.0, 0.3, 0.0)))
    scene = trimesh.util.concatenate([wall, pole])
    a, b = scan(scene, lidar, np.eye(4), seed=3), scan(scene, table, np.eye(4), seed=3)
    assert len(a) == len(b) > 100
    if changes:
        assert a.number_of_returns.max() >= 2  # the footprint straddles the pole
    row = _lidar_rows(lidar, a.pulse_id)
    order = np.lexsort((a.return_number, row))
    assert np.array_equal(row[order], b.pulse_id)
    for name in ("points", "range_m", "face_index", "normal", "incidence_deg", "gps_time", "scan_angle_deg", "return_number",
                 "number_of_returns", "intensity"):  # fmt: skip
        assert np.array_equal(getattr(a, name)[order], getattr(b, name)), name


@pytest.mark.parametrize(
    "changes", [{"footprint_rays": 7, "divergence_deg": 3.0}, {"footprint_rays": 7, "divergence_deg": 3.0, "echo_separation_m": 0.5}]
)
def test_a_table_fires_a_footprint_with_one_return_per_pulse_as_the_lidar_does(changes: dict) -> None:
    """A table accepts any beam (the one pipeline fires it): a footprint's strongest echo, mixed pixels merged within
    echo_separation_m, pulse by pulse the LiDAR's (:meth:`RayTable.from_lidar` keeps the LiDAR's beam as it is)."""
    lidar = with_beam(lidar_preset("vlp16", firing_rate_hz=3600.0), range_noise_m=0.0, **changes)
    table = RayTable.from_lidar(lidar)
    assert table.beam == lidar.beam
    wall = trimesh.creation.box((0.2, 12.0, 6.0), trimesh.transformations.translation_matrix((8.0, 0.0, 0.0)))
    pole = trimesh.creation.cylinder(radius=0.05, height=6.0, transform=trimesh.transformations.translation_matrix((5.0, 0.3, 0.0)))
    scene = trimesh.util.concatenate([wall, pole])
    a, b = scan(scene, lidar, np.eye(4), seed=3), scan(scene, table, np.eye(4), seed=3)
    one_ray = scan(scene, with_beam(lidar, footprint_rays=1, echo_separation_m=0.0), np.eye(4), seed=3)
    assert len(a) == len(b) > 100 and np.all(b.number_of_returns == 1)
    assert not np.array_equal(a.range_m, one_ray.range_m)  # the footprint was fired, not the centre ray alone
    row = _lidar_rows(lidar, a.pulse_id)
    order = np.argsort(row)
    assert np.array_equal(row[order], b.pulse_id)
    for name in ("points", "range_m", "face_index", "intensity", "gps_time"):
        assert np.array_equal(getattr(a, name)[order], getattr(b, name)), name


def test_several_returns_per_pulse_carry_their_pulse_time(sphere) -> None:
    time_s, az, el = _random_table(400)
    table = RayTable("t", time_s, az, el, beam=Beam(divergence_deg=2.0, footprint_rays=7, max_returns=3, range_resolution_m=0.5))
    box = trimesh.creation.box((0.5, 0.5, 20.0), trimesh.transformations.translation_matrix((4.0, 0.0, 0.0)))
    s = scan(trimesh.util.concatenate([sphere, box]), table, np.eye(4))
    assert s.gps_time.tobytes() == time_s[s.pulse_id].tobytes()
    assert np.array_equal(s.scan_angle_deg, el[s.pulse_id].astype(np.float32))
    for p in np.unique(s.pulse_id):
        mine = s.pulse_id == p
        n = s.number_of_returns[mine]
        assert np.all(n == n[0]) and sorted(s.return_number[mine]) == list(range(1, n[0] + 1))


def test_a_sector_keeps_the_rows_in_it_with_their_row_ids(sphere) -> None:
    time_s, az, el = _random_table(1000)
    table = RayTable("t", time_s, az, el)
    s = scan(sphere, table, np.eye(4), azimuth_range_deg=(-30.0, 30.0))
    inside = np.flatnonzero(np.mod(az + 30.0, 360.0) <= 60.0)
    assert np.array_equal(np.sort(s.pulse_id), inside)
    assert s.gps_time.tobytes() == time_s[s.pulse_id].tobytes()


def test_range_limits_noise_and_dropout_apply_as_to_a_lidar(sphere) -> None:
    time_s, az, el = _random_table(2000)
    assert len(scan(sphere, RayTable("t", time_s, az, el), np.eye(4))) == 2000
    assert len(scan(sphere, RayTable("t", time_s, az, el, beam=Beam(max_range_m=9.0)), np.eye(4))) == 0
    assert len(scan(sphere, RayTable("t", time_s, az, el, beam=Beam(min_range_m=10.5)), np.eye(4))) == 0
    lossy = scan(sphere, RayTable("t", time_s, az, el, beam=Beam(dropout=0.5)), np.eye(4), seed=1)
    assert 800 < len(lossy) < 1200
    noisy = scan(sphere, RayTable("t", time_s, az, el, beam=Beam(range_noise_m=0.1)), np.eye(4), seed=1)
    assert 0.05 < np.std(noisy.range_m - RADIUS_M) < 0.15
    again = scan(sphere, RayTable("t", time_s, az, el, beam=Beam(range_noise_m=0.1)), np.eye(4), seed=1)
    assert noisy.points.tobytes() == again.points.tobytes()


def test_the_columns_are_read_only_copies() -> None:
    time_s, az, el = _random_table(10)
    table = RayTable("t", time_s, az, el)
    time_s[0] = -1.0
    assert table.time_s[0] != -1.0
    with pytest.raises(ValueError):
        table.azimuth_deg[0] = 0.0


@pytest.mark.parametrize(
    "columns, match",
    [
        (([0.0, np.nan], [0.0, 1.0], [0.0, 1.0]), r"ray table: time_s\[1\] must be a finite number, got NaN"),
        (([0.0, 1.0], [0.0, np.inf], [0.0, 1.0]), r"azimuth_deg\[1\] must be a finite number, got an infinite number"),
        (([0.0, 1.0, 0.5], [0.0] * 3, [0.0] * 3), r"time_s must not decrease: time_s\[2\] is below time_s\[1\]"),
        (([0.0, 1.0], [0.0, 1.0], [0.0, 90.5]), r"elevation_deg\[1\] must be in \[-90, 90\], got a number outside that range"),
        (([0.0, 1.0], [0.0, 1.0], [0.0]), r"must have one length, got \[2, 2, 1\]"),
        (([], [], []), r"time_s must be a list of 1 to 4,194,304 numbers"),
        (([True, False], [0.0, 1.0], [0.0, 1.0]), r"time_s must be a 1-D array of real numbers, got shape \(2,\) dtype bool"),
        ((["0", "1"], [0.0, 1.0], [0.0, 1.0]), r"time_s must be a 1-D array of real numbers"),
        ((np.zeros((2, 3)), [0.0, 1.0], [0.0, 1.0]), r"time_s must be a 1-D array of real numbers, got shape \(2, 3\)"),
        ((0.0, [0.0], [0.0]), r"time_s must be a list of 1 to"),
    ],
)
def test_bad_columns_are_refused_naming_the_field(columns, match: str) -> None:
    with pytest.raises(InvalidInputError, match=match):
        RayTable("t", *columns)


@pytest.mark.parametrize(
    "fields, match",
    [
        ({"min_range_m": 5.0, "max_range_m": 5.0}, r"min_range_m must be below max_range_m"),
        ({"range_noise_m": -1.0}, r"range_noise_m must be a finite number in \[0, 1000000\], got a number outside that range"),
        ({"dropout": 1.0}, r"dropout must be a finite number in \[0, 1\)"),
        ({"footprint_rays": 7}, r"footprint_rays above 1 needs divergence_deg > 0"),
        ({"echo_separation_m": 0.5}, r"echo_separation_m 0.5 needs footprint_rays above 1"),
        ({"max_returns": 3}, r"max_returns 3 needs range_resolution_m > 0"),
        ({"range_resolution_m": 0.5}, r"range_resolution_m 0.5 separates several returns per pulse: it needs max_returns above 1"),
        ({"max_returns": 16}, r"max_returns must be an integer from 1 to 15"),
        ({"profile": "flat"}, r"profile must be one of"),
        ({"max_range_m": True}, r"max_range_m must be a finite number"),
    ],
)
def test_bad_model_fields_are_refused_as_the_lidar_refuses_them(fields: dict, match: str) -> None:
    """A table's pulse and receiver fields are its Beam's, checked by the Beam as every scanner's are."""
    with pytest.raises(InvalidInputError, match="^beam: " + match):
        RayTable("t", [0.0], [0.0], [0.0], beam=Beam(**fields))


@pytest.mark.parametrize("beam", [None, {"range_noise_m": 0.1}, "ideal", 0.02])
def test_a_beam_that_is_not_a_beam_is_refused(beam) -> None:
    with pytest.raises(InvalidInputError, match=r"^ray table: beam must be a Beam"):
        RayTable("t", [0.0], [0.0], [0.0], beam=beam)


def test_more_rows_than_a_sensor_may_cast_are_refused(monkeypatch) -> None:
    monkeypatch.setattr(ray_table_module, "MAX_SENSOR_RAYS", 4)
    with pytest.raises(InvalidInputError, match="time_s must be a list of 1 to 4 numbers"):
        RayTable("t", np.zeros(5), np.zeros(5), np.zeros(5))
    with pytest.raises(InvalidInputError, match="n_pulses must be an integer from 1 to 4"):
        rosette_table(5, duration_s=1.0)


def test_a_name_that_cannot_name_files_is_refused() -> None:
    with pytest.raises(InvalidInputError, match="ray table name must be"):
        RayTable("a/b", [0.0], [0.0], [0.0])


@pytest.mark.parametrize("suffix", [".csv", ".npy"])
def test_load_ray_table_reads_a_file_exactly(tmp_path: Path, suffix: str) -> None:
    time_s, az, el = _random_table(50)
    path = tmp_path / f"avia{suffix}"
    path.write_bytes(ray_table_bytes(time_s, az, el, suffix=suffix))
    table = load_ray_table(path, beam=Beam(max_returns=2, range_resolution_m=0.5))
    assert table.name == "avia" and table.beam.max_returns == 2
    for got, want in ((table.time_s, time_s), (table.azimuth_deg, az), (table.elevation_deg, el)):
        assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("suffix", [".csv", ".npy"])
@pytest.mark.parametrize(
    "row, match",
    [
        ((np.nan, 0.0, 0.0), r"time_s\[1\] must be a finite number, got NaN"),
        ((1.0, np.inf, 0.0), r"azimuth_deg\[1\] must be a finite number, got an infinite number"),
        ((-1.0, 0.0, 0.0), r"time_s must not decrease: time_s\[1\] is below time_s\[0\]"),
        ((1.0, 0.0, -91.0), r"elevation_deg\[1\] must be in \[-90, 90\], got a number outside that range"),
    ],
)
def test_a_hostile_table_file_is_one_line_naming_it(tmp_path: Path, suffix: str, row, match: str) -> None:
    table = np.array([(0.0, 0.0, 0.0), row])
    path = tmp_path / f"bad{suffix}"
    path.write_bytes(ray_table_bytes(*table.T, suffix=suffix))
    with pytest.raises(InvalidInputError, match=match) as info:
        load_ray_table(path)
    assert str(info.value).startswith(f"{path}: ray table: ") and "\n" not in str(info.value)


def test_from_lidar_keeps_every_beam_and_its_range_dependent_dropout() -> None:
    """A range-dependent dropout is the beam's: the table loses the same far returns as the LiDAR, on average."""
    lidar = with_beam(lidar_preset("vlp16", firing_rate_hz=3600.0), range_noise_m=0.0, dropout_range_per_m=0.02)
    table = RayTable.from_lidar(lidar)
    assert table.beam == lidar.beam
    wall = trimesh.creation.box((0.2, 40.0, 8.0), trimesh.transformations.translation_matrix((20.0, 0.0, 0.0)))
    full = scan(wall, with_beam(lidar, dropout_range_per_m=0.0), np.eye(4), seed=1)
    kept = [len(scan(wall, sensor, np.eye(4), seed=1)) / len(full) for sensor in (lidar, table)]
    expected = 1.0 - np.clip(0.02 * full.range_m.astype(np.float64), 0.0, 0.95).mean()
    assert abs(kept[0] - expected) < 0.05 and abs(kept[1] - expected) < 0.05


def test_the_rosette_stays_in_its_field_of_view_and_does_not_repeat() -> None:
    table = rosette_table(20_000, duration_s=0.2)
    assert len(table) == 20_000 and table.time_s[0] == 0.0 and np.allclose(np.diff(table.time_s), 1e-5)
    d = table.rays()[0]
    off_axis = np.degrees(np.arccos(np.clip(d[:, 0], -1.0, 1.0)))
    assert off_axis.max() <= ROSETTE_FOV_DEG / 2 + 1e-9
    assert off_axis.min() < 0.5 and off_axis.max() > ROSETTE_FOV_DEG / 2 - 0.5  # petals reach the centre and the edge
    # non-repetitive: the second 0.1 s fires along other directions than the first
    first, second = d[:10_000], d[10_000:]
    assert np.abs(first - second).max() > 0.1
    # the petals cover the field: most of a 2° grid over the disc is within 1° of a pulse after 0.2 s
    g = np.radians(np.arange(-18.0, 18.1, 2.0))
    gu, gv = np.meshgrid(g, g)
    inside = np.hypot(gu, gv) < np.radians(17.0)
    cells = np.stack([np.cos(np.hypot(gu, gv)), np.sin(gu), np.sin(gv)], -1)[inside]
    cells /= np.linalg.norm(cells, axis=1, keepdims=True)
    nearest = np.degrees(np.arccos(np.clip((cells @ d.T).max(axis=1), -1.0, 1.0)))
    assert np.mean(nearest < 1.0) > 0.8


def test_rosette_arguments_are_checked() -> None:
    with pytest.raises(InvalidInputError, match="duration_s must be a finite number > 0"):
        rosette_table(10, duration_s=0.0)
    with pytest.raises(InvalidInputError, match=r"fov_deg must be a finite number in \(0, 180\)"):
        rosette_table(10, duration_s=1.0, fov_deg=180.0)
    with pytest.raises(InvalidInputError, match="prism_hz must be a list of 2 numbers"):
        rosette_table(10, duration_s=1.0, prism_hz=(1.0,))


def test_a_scan_of_a_non_sensor_names_the_kinds(sphere) -> None:
    with pytest.raises(InvalidInputError, match="sensor must be a Lidar, AirborneScanner, RayTable, DepthCamera; got object") as info:
        scan(sphere, object(), np.eye(4))
    assert all(kind.cls.__name__ in str(info.value) for kind in SENSOR_KINDS)


def test_radiometric_detection_applies_to_a_table(sphere) -> None:
    """With ``reflectivity``, a return is kept when ρ cos θ / R² clears the table's threshold, as for a LiDAR."""
    time_s, az, el = _random_table(500)
    seen = RayTable("t", time_s, az, el, beam=Beam(detection_threshold=0.5 / 20.0**2))
    unseen = RayTable("t", time_s, az, el, beam=Beam(detection_threshold=0.5 / 5.0**2, range_noise_m=0.02))
    assert len(scan(sphere, seen, np.eye(4), reflectivity=0.5)) == 500
    assert len(scan(sphere, unseen, np.eye(4), reflectivity=0.5)) == 0  # 0.5 / 100 < 0.5 / 25
    s = scan(sphere, seen, np.eye(4), reflectivity=0.5)
    np.testing.assert_allclose(s.intensity, 0.5 * np.cos(np.radians(s.incidence_deg)) / s.range_m.astype(np.float64) ** 2, rtol=1e-3)
