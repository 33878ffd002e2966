"""The airborne fit (sensors/fit/airborne.py): known scanners recovered from their own simulated aerial crops."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.patterns.airborne import AIRBORNE_IDEAL_BEAM, AirborneScanner
from zbuf_occlude.sensors.scan import scan_airborne
from zbuf_occlude.sensors.fit.airborne import _face_density, crop_faces, fit_airborne
from zbuf_occlude.sensors.kinds import kind_of, sensor_from_name


def _scanner(name: str, density_m2: float, altitude_m: float, swath_deg: float, noise_m: float, dropout: float = 0.0) -> AirborneScanner:
    """A single-line scanner of the given flat-ground density, its lines as far apart as its pulses (a square pattern)."""
    speed = 60.0
    width = 2.0 * altitude_m * math.tan(math.radians(swath_deg / 2.0))
    prr = density_m2 * speed * width
    line_rate = math.sqrt(prr * speed / (altitude_m * math.radians(swath_deg)))
    return AirborneScanner(name, swath_deg=swath_deg, pulse_rate_hz=prr, line_rate_hz=line_rate, altitude_m=altitude_m,
                           speed_mps=speed, beam=AIRBORNE_IDEAL_BEAM.with_(range_noise_m=noise_m, dropout=dropout))  # fmt: skip


def _box_crops(scanner: AirborneScanner, n: int, seed: int) -> tuple[list[np.ndarray], list[float], list[float]]:
    """Car-sized boxes at random yaw, spread over the swath: the crops, the true density at each and its scan angle."""
    rng = np.random.default_rng(seed)
    half_width = scanner.altitude_m * math.tan(math.radians(scanner.swath_deg / 2.0))
    crops, density, angle = [], [], []
    for i in range(n):
        ext = rng.uniform([3.5, 1.6, 1.3], [5.0, 2.2, 2.5])
        box = trimesh.creation.box(extents=ext)
        y = float(rng.uniform(-0.95, 0.95)) * half_width
        box.apply_transform(trimesh.transformations.rotation_matrix(math.radians(rng.uniform(0.0, 180.0)), [0, 0, 1]))
        box.apply_translation([0.0, y, ext[2] / 2.0])
        scan = scan_airborne(box, scanner, center_xy=(0.0, y), half_size_m=4.0, seed=seed * 1000 + i)
        crops.append(np.asarray(scan.points, dtype=np.float64))
        density.append(scanner.density_at_m2(y) * (1.0 - scanner.beam.dropout))
        angle.append(math.degrees(math.atan2(abs(y), scanner.altitude_m)))
    return crops, density, angle


SCANNERS = {
    "35 points/m², 500 m, 60°": _scanner("a", 35.0, 500.0, 60.0, 0.03),
    "16 points/m², 700 m, 50°, dropout 0.2": _scanner("b", 20.0, 700.0, 50.0, 0.05, dropout=0.2),
}


#: Where aerial crops lie in a user's files: projected coordinates (UTM-like eastings and northings, metres).
_UTM_OFFSET = np.array([480_000.0, 5_400_000.0, 120.0])


@pytest.fixture(scope="module", params=sorted(SCANNERS))
def simulated(request):
    scanner = SCANNERS[request.param]
    crops, density, angle = _box_crops(scanner, 16, seed=3)
    return scanner, crops, density, angle, fit_airborne(crops, scanner, bootstrap=40)


def test_the_fit_recovers_density_noise_and_scan_angle_range(simulated) -> None:
    scanner, _, density, angle, fit = simulated
    e = fit.estimates
    assert e["density_m2"].value == pytest.approx(np.mean(density), rel=0.10)
    assert e["range_noise_m"].value == pytest.approx(scanner.beam.range_noise_m, rel=0.20)
    assert abs(e["max_scan_angle_deg"].value - scanner.swath_deg / 2.0) <= 5.0  # the crops spread over the swath
    assert e["two_sided_fraction"].value == 0.0
    for key in ("density_m2", "range_noise_m", "max_scan_angle_deg"):
        assert 0.0 < e[key].std < 0.5 * abs(e[key].value), key  # the bootstrap says something, not nothing
        assert e[key].set_in_sensor


def test_each_crop_gets_its_own_scan_angle(simulated) -> None:
    _, crops, _, angle, _ = simulated
    measured = np.array([crop_faces(c).incidence_deg for c in crops])
    told = np.isfinite(measured)
    assert told.sum() >= len(crops) // 2  # near nadir a box shows too little wall to tell
    assert np.median(np.abs(measured[told] - np.array(angle)[told])) <= 3.0


def test_crops_in_projected_coordinates_fit_as_at_the_origin(simulated) -> None:
    # aerial crops come in eastings and northings of 10^5 to 10^7 m: the same crops there give the same fit
    scanner, crops, _, _, fit = simulated
    far = fit_airborne([np.asarray(c, dtype=np.float64) + _UTM_OFFSET for c in crops], scanner, bootstrap=40)
    for key in ("density_m2", "max_scan_angle_deg", "range_noise_m"):
        assert far.estimates[key].value == pytest.approx(fit.estimates[key].value, rel=1e-3), key


def test_the_fitted_sensor_file_loads_and_scans_at_the_measured_density(simulated, tmp_path) -> None:
    scanner, _, density, _, fit = simulated
    path = tmp_path / "fitted.json"
    path.write_text(json.dumps(fit.to_json()))
    loaded = sensor_from_name(path)
    assert loaded == fit.sensor and loaded.name == f"{scanner.name}-fitted"
    assert loaded.altitude_m == scanner.altitude_m and loaded.speed_mps == scanner.speed_mps  # what crops cannot tell
    again, density_again, _ = _box_crops(loaded, 10, seed=11)
    refit = fit_airborne(again, loaded, bootstrap=10)
    assert refit.estimates["density_m2"].value == pytest.approx(np.mean(density), rel=0.12)


def _top_scan_angles(folder) -> np.ndarray:
    """Per scan file, the median incidence on the object's horizontal top: the scan angle at the object, degrees."""
    from zbuf_occlude.sensors.scan_data import read_scan_npz

    angles = []
    for f in sorted(folder.glob("*.npz")):
        s = read_scan_npz(f)
        top = np.abs(s.normal[:, 2]) > 0.99
        angles.append(float(np.median(s.incidence_deg[top])))
    return np.array(angles)


@pytest.mark.slow
def test_scanning_with_the_fitted_sensor_file_reproduces_the_fitted_scan_angles(tmp_path) -> None:
    """The fitted scanner chooses the flight plan: scan puts each object in one strip, anywhere across it, so
    the scan angles at the objects span what the crops showed (0° to max_scan_angle_deg, tan θ uniform)."""
    from zbuf_occlude.cli.main import main

    scanner = SCANNERS["35 points/m², 500 m, 60°"]
    crops, _, _ = _box_crops(scanner, 16, seed=3)
    fit = fit_airborne(crops, scanner.with_(name="base"), bootstrap=10)
    assert (fit.sensor.n_lines, fit.sensor.side_overlap) == (3, 0.0) and "strips abut" in fit.markdown()
    path = tmp_path / "fitted.json"
    path.write_text(json.dumps(fit.to_json()))
    argv = ["scan", "box", "--extents", "4.5,1.8,1.5", "--yaw", "0:360", "--sensor", str(path), "--crop", "--samples", "40"]
    assert main([*argv, "--out", str(tmp_path / "scans")]) == 0
    angles = _top_scan_angles(tmp_path / "scans")
    fitted_max = fit.estimates["max_scan_angle_deg"].value
    assert np.min(angles) <= 5.0 and abs(np.max(angles) - fitted_max) <= 5.0
    # tan θ uniform on [0, tan(fitted_max)]: its median at half the largest tangent
    assert abs(np.median(angles) - math.degrees(math.atan(math.tan(math.radians(fitted_max)) / 2.0))) <= 5.0
    # the scanner of the crops themselves (one line over the plan centre) sees every object at the nadir
    path.write_text(json.dumps({**fit.to_json(), "n_lines": 1}))
    assert main([*argv, "--out", str(tmp_path / "one_line")]) == 0
    assert np.max(_top_scan_angles(tmp_path / "one_line")) < 2.0


def test_crops_lit_from_both_sides_keep_the_base_flight_plan() -> None:
    # inside a DALES-like block (strips overlapping by 85 %) every crop is lit from both sides: the plan cannot be told
    base = _scanner("block", 20.0, 300.0, 60.0, 0.02).with_(n_lines=5, side_overlap=0.85)
    crops = []
    for i in range(6):
        box = trimesh.creation.box(extents=[4.5, 2.0, 1.6])
        box.apply_transform(trimesh.transformations.rotation_matrix(math.radians(90.0 * i), [0, 0, 1]))  # walls facing the lines
        box.apply_translation([0.0, 0.0, 0.8])
        crops.append(np.asarray(scan_airborne(box, base, half_size_m=4.0, seed=i).points, dtype=np.float64))  # the lines shifted at random
    fit = fit_airborne(crops, base, bootstrap=5)
    assert fit.estimates["two_sided_fraction"].value > 0.5
    assert (fit.sensor.n_lines, fit.sensor.side_overlap) == (5, 0.85) and "lit from both sides" in fit.markdown()


def test_the_density_follows_the_scanner_not_the_base() -> None:
    # crops of a scanner with twice the pulse rate are measured at twice the density, whatever base is given
    scanner = SCANNERS["35 points/m², 500 m, 60°"]
    crops, density, _ = _box_crops(scanner.with_(pulse_rate_hz=2.0 * scanner.pulse_rate_hz), 6, seed=5)
    fit = fit_airborne(crops, scanner, bootstrap=5)
    assert fit.estimates["density_m2"].value == pytest.approx(np.mean(density), rel=0.10)
    assert fit.sensor.survey_density_m2 == pytest.approx(fit.estimates["density_m2"].value, rel=1e-9)


def test_crops_lit_from_both_sides_give_no_single_angle() -> None:
    # two lines 300 m either side of a box: both long walls hold points
    scanner = _scanner("two", 20.0, 500.0, 70.0, 0.02).with_(n_lines=2, side_overlap=0.1)
    box = trimesh.creation.box(extents=[4.5, 2.0, 2.0])
    box.apply_translation([0.0, 0.0, 1.0])
    scan = scan_airborne(box, scanner, center_xy=(0.0, 0.0), half_size_m=4.0, seed=1, lateral_shift_m=0.0)
    faces = crop_faces(np.asarray(scan.points, dtype=np.float64))
    assert faces.two_sided and math.isnan(faces.incidence_deg)
    assert len(faces.wall_normals) == 2 and faces.wall_normals[0] @ faces.wall_normals[1] < -0.9


@settings(max_examples=25, deadline=None)
@given(
    spacing=st.floats(0.1, 1.0),
    angle=st.floats(0.0, 90.0),
    offset=st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)),
    jitter=st.floats(0.0, 0.2),
)
def test_face_density_of_a_rotated_lattice_is_one_over_its_cell(spacing, angle, offset, jitter) -> None:
    """Law: a lattice of cell ``s²`` (any rotation, offset, small jitter, an L-shaped outline) has density ``1/s²``."""
    g = np.stack(np.meshgrid(np.arange(30), np.arange(30), indexing="ij"), axis=-1).reshape(-1, 2).astype(np.float64)
    g = g[~((g[:, 0] > 15) & (g[:, 1] > 15))]  # an L, not a convex face
    rng = np.random.default_rng(0)
    g = (g + np.asarray(offset) + jitter * rng.uniform(-0.5, 0.5, g.shape)) * spacing
    c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    uv = g @ np.array([[c, s], [-s, c]])
    assert _face_density(uv) == pytest.approx(1.0 / spacing**2, rel=0.03)


def test_face_density_of_random_points() -> None:
    rng = np.random.default_rng(4)
    uv = rng.uniform(0.0, 10.0, (4000, 2))  # 40 points per unit area
    assert _face_density(uv) == pytest.approx(40.0, rel=0.05)


@pytest.mark.parametrize(
    ("crops", "message"),
    [
        ([np.zeros((50, 3)), np.full((50, 3), np.nan)], r"crop 1: expected finite \(N, 3\) points"),
        ([np.zeros((50, 2))], r"crop 0: expected finite \(N, 3\) points"),
        ([np.random.default_rng(0).normal(size=(100, 3))], r"at least 2 crops"),
    ],
)
def test_bad_crops_are_refused_naming_them(crops, message) -> None:
    with pytest.raises(InvalidInputError, match=message):
        fit_airborne(crops, SCANNERS["35 points/m², 500 m, 60°"], bootstrap=2)


def test_crops_without_a_top_are_refused_with_a_reason() -> None:
    # vertical poles seen from the side (what a ground scan of poles gives): no horizontal face anywhere
    rng = np.random.default_rng(2)
    poles = []
    for _ in range(3):
        z = rng.uniform(0.0, 5.0, 300)
        a = rng.uniform(-0.5, 0.5, 300)
        poles.append(np.column_stack([0.15 * np.cos(a), 0.15 * np.sin(a), z]))
    with pytest.raises(InvalidInputError, match="no crop has a horizontal top"):
        fit_airborne(poles, SCANNERS["35 points/m², 500 m, 60°"], bootstrap=2)


# -- the spinning fit refuses what no spinning sensor could have scanned ------------------------------
def _aerial_crops_beside_an_origin(offset) -> list[np.ndarray]:
    crops, _, _ = _box_crops(SCANNERS["35 points/m², 500 m, 60°"], 6, seed=3)
    return [c - np.r_[c[:, :2].mean(axis=0), 0.0] + np.asarray(offset, dtype=np.float64) for c in crops]


@pytest.mark.parametrize("offset", [(8.0, 0.0, -2.0), (5.0, 5.0, -30.0)])
def test_the_spinning_fit_refuses_aerial_crops_naming_why(offset) -> None:
    from zbuf_occlude.sensors.fit import fit_lidar
    from zbuf_occlude.sensors.patterns.spinning import lidar_preset

    with pytest.raises(InvalidInputError, match="no sensor origin consistent with hdl32e's rings") as info:
        fit_lidar(_aerial_crops_beside_an_origin(offset), lidar_preset("hdl32e"))
    assert "fit_airborne" in str(info.value) and "\n" not in str(info.value)


def test_the_spinning_fit_refuses_crops_beyond_its_range() -> None:
    from zbuf_occlude.sensors.fit import fit_lidar
    from zbuf_occlude.sensors.patterns.spinning import lidar_preset

    with pytest.raises(InvalidInputError, match=r"beyond hdl32e's \d+ m range"):
        fit_lidar(_aerial_crops_beside_an_origin((400.0, 300.0, 0.0)), lidar_preset("hdl32e"))


def test_the_spinning_fit_still_takes_spinning_scans() -> None:
    # the rings' check passes what a spinning sensor makes, far objects and a mount tilt included
    from zbuf_occlude.sensors.fit import fit_lidar
    from zbuf_occlude.sensors.patterns.spinning import lidar_preset
    from zbuf_occlude.sensors.scan import scan

    sensor = lidar_preset("hdl32e")
    tilt = trimesh.transformations.rotation_matrix(np.radians(0.6), (0, 1, 0))
    clouds = []
    for i, (distance, yaw) in enumerate([(6.0, 0.0), (9.0, 20.0), (14.0, -15.0), (30.0, 5.0)]):
        box = trimesh.creation.box(extents=(4.0, 1.8, 1.5))
        box.apply_transform(trimesh.transformations.rotation_matrix(np.radians(yaw), (0, 0, 1)))
        box.apply_translation((distance, 0.0, 0.75 - 1.8))
        s = scan(box, sensor, tilt, seed=i, azimuth_range_deg=(-40.0, 40.0))
        clouds.append(np.asarray(s.points, dtype=np.float64) @ tilt[:3, :3])  # in the tilted sensor's frame
    assert fit_lidar(clouds, sensor, bootstrap=5).n_scans == 4


@pytest.mark.parametrize("name", ["hdl32e", "dales-q1560", "riegl-q1560", "kinect-v1"])
def test_sensor_to_json_is_what_sensor_from_name_reads_back(name, tmp_path) -> None:
    from zbuf_occlude.sensors.kinds import sensor_to_json

    sensor = sensor_from_name(name)
    path = tmp_path / "s.json"
    path.write_text(json.dumps(sensor_to_json(sensor)))
    assert sensor_from_name(path) == sensor
    with pytest.raises(InvalidInputError, match="a sensor must be a Lidar, .*; got str"):
        sensor_to_json("hdl32e")


# -- zbuf-occlude fit-sensor on aerial crops ------------------------------------------------------------


def _crop_folder(root, crops) -> None:
    """The crops as a user has them: a class folder of ``.xyz`` files in projected coordinates."""
    (root / "car").mkdir(parents=True)
    for i, c in enumerate(crops):
        np.savetxt(root / "car" / f"{i:03d}.xyz", np.asarray(c, dtype=np.float64) + _UTM_OFFSET, fmt="%.3f")


def test_fit_sensor_command_fits_an_airborne_scanner_to_aerial_crops(tmp_path, capsys) -> None:
    """An airborne preset chooses the airborne fit: crops in, a sensor JSON that scan and sensor_from_name take out."""
    from zbuf_occlude.cli.main import main
    from zbuf_occlude.sensors.scan_data import read_scan_npz

    scanner = SCANNERS["35 points/m², 500 m, 60°"]
    crops, density, _ = _box_crops(scanner, 16, seed=3)
    _crop_folder(tmp_path / "crops", crops)
    out = tmp_path / "fitted.json"
    assert main(["fit-sensor", str(tmp_path / "crops"), "--sensor", "riegl-q1560", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    first, second = printed.splitlines()[:2]  # what it reads and what it fits, before any number
    assert first.startswith("reading the real scans under") and second.startswith(
        "read 16 scans of 1 class (car: 16); fitting an airborne scanner"
    )
    assert "| density_m2 | " in printed and " ± " in printed and "The fitted scanner riegl-q1560-fitted" in printed
    fitted = sensor_from_name(out)  # the loader of scan, farm --sensor and experiment sim2real --sensor
    assert kind_of(fitted).name == "airborne" and fitted.name == "riegl-q1560-fitted"
    assert fitted.survey_density_m2 == pytest.approx(np.mean(density), rel=0.10)
    assert abs(fitted.swath_deg - scanner.swath_deg) <= 10.0
    spec = json.loads(out.read_text())
    assert spec["kind"] == "airborne" and spec["fit"]["n_crops"] == 16 and spec["fit"]["estimates"]["density_m2"]["std"] > 0
    # the preset's beam (its data sheet's footprint, returns, intensity scale) with only the range noise fitted
    assert fitted.beam == sensor_from_name("riegl-q1560").beam.with_(range_noise_m=spec["fit"]["estimates"]["range_noise_m"]["value"])
    assert "| density_m2 | " in out.with_suffix(".md").read_text()
    # the file scans
    assert main(["scan", "box", "--sensor", str(out), "--crop", "--size", "4.5", "--out", str(tmp_path / "scans")]) == 0
    (npz,) = (tmp_path / "scans").glob("*.npz")
    assert len(read_scan_npz(npz).points) > 100


def test_fit_sensor_command_refuses_a_spinning_fit_of_aerial_crops_in_one_line(tmp_path, capsys) -> None:
    from zbuf_occlude.cli.main import main

    crops, _, _ = _box_crops(SCANNERS["35 points/m², 500 m, 60°"], 6, seed=3)
    _crop_folder(tmp_path / "crops", crops)
    out = tmp_path / "fitted.json"
    assert main(["fit-sensor", str(tmp_path / "crops"), "--sensor", "hdl32e", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out.startswith("reading the real scans under")  # said before the work, not silent
    (line,) = captured.err.strip().splitlines()
    assert "not scans in a spinning sensor's frame" in line and "fit-sensor --sensor dales-q1560" in line
    assert "Traceback" not in captured.err and not out.exists()
