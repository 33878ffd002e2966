"""Airborne flight plans: overlapping strips add up on flat ground, every return keeps its line,
the DALES-like preset, sensor files, and the single-line scanner unchanged to the bit."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.load import normalize_mesh
from zbuf_occlude.sensors import AirborneScanner, airborne_preset, scan_airborne
from zbuf_occlude.sensors.patterns.airborne import AIRBORNE_IDEAL_BEAM, MAX_FLIGHT_LINES, FlightLine
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.crops import lidar_object_samples, object_crop
from zbuf_occlude.sensors.placement import CropDistributions, draw_placement
from zbuf_occlude.sensors.kinds import sensor_from_name
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject

#: The riegl-q1560 beam before the presets carried their data sheets' footprints and echoes: one return per
#: pulse (the centre ray's first hit), 2 cm range noise; what the byte-for-byte checks below were made with.
Q1560_SINGLE_RETURN = Beam("riegl-q1560", wavelength_nm=1064.0, range_noise_m=0.02)

#: Binomial tolerance of the dropout, in standard deviations (a false failure about once in 10^6 examples).
DROPOUT_SIGMAS = 5.0


def _plane(half: float = 3000.0) -> trimesh.Trimesh:
    v = [[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]]
    return trimesh.Trimesh(vertices=v, faces=[[0, 1, 2], [0, 2, 3]], process=False)


def _in_patch(points, heading_deg: float, center, half_along: float, half_across: float) -> int:
    """Returns inside a rectangle aligned with the first heading's lines (world x–y)."""
    frame = FlightLine(0, heading_deg, 0.0)
    local = frame.to_line(points[:, :2].astype(np.float64)) - frame.to_line(np.asarray(center, dtype=np.float64))
    return int(np.sum((np.abs(local[:, 0]) <= half_along) & (np.abs(local[:, 1]) <= half_across)))


@pytest.mark.slow
@settings(max_examples=25, deadline=None)
@given(
    altitude_m=st.floats(100.0, 400.0),
    swath_deg=st.floats(20.0, 60.0),
    side_overlap=st.floats(0.0, 0.75),
    speed_mps=st.floats(20.0, 70.0),
    line_rate_hz=st.floats(20.0, 120.0),
    pattern=st.sampled_from(["linear", "oscillating"]),
    dropout=st.sampled_from([0.0, 0.2]),
    headings=st.sampled_from([(0.0,), (35.0,), (0.0, 90.0), (-20.0, 70.0)]),
    extra_lines=st.integers(0, 1),
    start=st.floats(-0.5, 0.5),
    seed=st.integers(0, 2**31),
)
def test_overlapping_strips_add_up_to_prr_over_speed_times_spacing(altitude_m, swath_deg, side_overlap, speed_mps, line_rate_hz,
                                                                    pattern, dropout, headings, extra_lines, start, seed) -> None:  # fmt: skip
    """Where the block is unbounded, an across-track band one line spacing wide receives every
    pulse column of one line exactly once, so its count is (1 − dropout) · PRR · length / v per
    heading: the density PRR / (v · s).  Lattice tolerance: each column of each line puts
    length / Δx pulses in the band ± 1 (linear) or ± 2 (oscillating: two interleaved rows), and
    one column per band edge more or less (float32 points); plus a binomial tolerance of the dropout."""
    s_probe = AirborneScanner("probe", swath_deg, 1000.0 * line_rate_hz, line_rate_hz, altitude_m, speed_mps)
    spacing = s_probe.swath_width_m * (1.0 - side_overlap)
    dx = speed_mps / line_rate_hz  # along-track distance between a column's pulses
    crossing = len(headings) == 2
    along = spacing if crossing else 60.0 * dx  # a square patch when lines cross: one spacing both ways
    # pulses per line: about 150k rays cast per example whatever the geometry
    reach = math.hypot(along, spacing) / 2.0 + 1.0
    m = int(np.clip(150_000.0 * speed_mps * spacing / (line_rate_hz * (2 * reach) ** 2 * len(headings)), 8, 5000))
    n_lines = math.ceil(s_probe.swath_width_m / spacing) + 2 + extra_lines  # the patch lies where the block is unbounded
    scanner = AirborneScanner("plan", swath_deg, m * line_rate_hz, line_rate_hz, altitude_m, speed_mps, pattern=pattern,
                              beam=AIRBORNE_IDEAL_BEAM.with_(dropout=dropout), n_lines=n_lines, side_overlap=side_overlap,
                              headings_deg=headings)  # fmt: skip
    assert scanner.flight_line_spacing_m == pytest.approx(spacing)
    center = FlightLine(0, headings[0], 0.0).axes()[1] * start * spacing  # anywhere within a spacing of the centre
    s = scan_airborne(_plane(), scanner, center, reach, seed=seed)
    got = _in_patch(s.points, headings[0], center, along / 2.0, spacing / 2.0)
    rows = along / dx
    ideal = len(headings) * m * rows  # = survey_density_m2 · area
    assert ideal == pytest.approx(scanner.survey_density_m2 * along * spacing, rel=1e-9)
    lattice = len(headings) * (m * (1 if pattern == "linear" else 2) + 2 * (rows + 2))
    binomial = DROPOUT_SIGMAS * math.sqrt(ideal * dropout * (1.0 - dropout)) + 1.0
    assert abs(got - (1.0 - dropout) * ideal) <= lattice + binomial, (got, (1.0 - dropout) * ideal, lattice, binomial)
    assert set(np.unique(s.meta["line_id"])) <= set(range(n_lines * len(headings)))


def test_the_density_law_catches_a_missing_strip() -> None:
    """The law's tolerance is tight enough to see one strip fewer (k − 1 of k strips on a point)."""
    q = AirborneScanner("plan", 40.0, 200 * 60.0, 60.0, 200.0, 40.0, n_lines=6, side_overlap=0.6)
    s = scan_airborne(_plane(), q, (0.0, 0.0), 40.0, seed=1)
    dx = q.speed_mps / q.line_rate_hz
    got = _in_patch(s.points, 0.0, (0.0, 0.0), 30 * dx, q.flight_line_spacing_m / 2)
    ideal = q.survey_density_m2 * 60 * dx * q.flight_line_spacing_m
    k = q.swath_width_m / q.flight_line_spacing_m  # 2.5 strips on a point
    assert abs(got - ideal) <= q.pulses_per_line + 2 * 62
    assert abs(got - ideal * (k - 1) / k) > q.pulses_per_line + 2 * 62


def test_survey_density_at_a_point_sums_the_strips_that_cover_it() -> None:
    q = airborne_preset("dales-q1560")
    y = np.linspace(-q.flight_line_spacing_m / 2, q.flight_line_spacing_m / 2, 4001)
    rho = q.survey_density_at_m2(np.column_stack([np.zeros_like(y), y]))
    # one period of the unbounded block: its mean is PRR / (v · s)
    assert rho.mean() == pytest.approx(q.survey_density_m2, rel=1e-3)
    assert rho.min() > 6 * q.density_at_m2(q.swath_width_m / 2) and rho.max() < 7 * q.density_at_m2(0.0)
    # a single line: the strip's own law, and nothing beyond the swath
    single = airborne_preset("riegl-q1560")
    assert single.survey_density_at_m2((5.0, 250.0)) == pytest.approx(single.density_at_m2(250.0))
    assert single.survey_density_at_m2((5.0, single.swath_width_m / 2 + 1.0)) == 0.0
    assert single.survey_density_m2 == single.density_m2
    assert single.with_(headings_deg=(0.0, 90.0)).survey_density_at_m2((300.0, 250.0)) == pytest.approx(
        single.density_at_m2(250.0) + single.density_at_m2(300.0)
    )


def test_flight_lines_geometry() -> None:
    q = AirborneScanner("plan", 40.0, 1e5, 50.0, 500.0, 60.0, n_lines=4, side_overlap=0.3, headings_deg=(10.0, 100.0))
    lines = q.flight_lines([5.0, -2.0])
    assert [ln.line_id for ln in lines] == list(range(8))
    s = q.swath_width_m * 0.7
    np.testing.assert_allclose([ln.offset_m for ln in lines[:4]], np.array([-1.5, -0.5, 0.5, 1.5]) * s + 5.0)
    np.testing.assert_allclose([ln.offset_m for ln in lines[4:]], np.array([-1.5, -0.5, 0.5, 1.5]) * s - 2.0)
    assert {ln.heading_deg for ln in lines[4:]} == {100.0}
    along, across = lines[0].axes()
    np.testing.assert_allclose(along, [math.cos(math.radians(10)), math.sin(math.radians(10))])
    np.testing.assert_allclose(lines[0].to_line(lines[0].offset_m * across + 7.0 * along), [7.0, 0.0], atol=1e-9)


def test_every_return_lies_in_the_strip_of_its_line_and_lines_have_their_own_phase() -> None:
    q = AirborneScanner("plan", 50.0, 300 * 80.0, 80.0, 300.0, 50.0, n_lines=5, side_overlap=0.5, headings_deg=(0.0, 60.0))
    s = scan_airborne(_plane(), q, (20.0, -30.0), 60.0, seed=4)
    ids = s.meta["line_id"]
    assert ids.dtype == np.int32 and len(ids) == len(s) == len(s.meta["scan_angle_deg"])
    assert len(set(ids.tolist())) >= 6  # most lines of both blocks see the square
    lines = q.flight_lines(s.meta["lateral_shift_m"])
    for line in lines:
        mine = ids == line.line_id
        if not mine.any():
            continue
        y = line.to_line(s.points[mine, :2].astype(np.float64))[:, 1]
        # across-track position = h tan(scan angle) on flat ground, inside the swath
        np.testing.assert_allclose(y, q.altitude_m * np.tan(np.radians(s.meta["scan_angle_deg"][mine])), atol=1e-3)
        assert np.abs(y).max() <= q.swath_width_m / 2 + 1e-3
    assert len(set(s.meta["line_phase_s"])) == 10 and all(0 <= p < 1 / q.line_rate_hz for p in s.meta["line_phase_s"])
    assert all(abs(v) <= q.flight_line_spacing_m / 2 for v in s.meta["lateral_shift_m"])
    again = scan_airborne(_plane(), q, (20.0, -30.0), 60.0, seed=4)
    assert again.points.tobytes() == s.points.tobytes() and np.array_equal(again.meta["line_id"], ids)


def test_each_line_lays_down_its_own_pattern_at_its_own_phase() -> None:
    """The returns of line j are exactly the flat-ground footprints of the single-line pattern
    (:meth:`AirborneScanner.ground_rays`) flown along that line at that line's phase."""
    q = AirborneScanner("plan", 50.0, 200 * 80.0, 80.0, 300.0, 50.0, n_lines=3, side_overlap=0.6, headings_deg=(0.0, 30.0))
    center, half = np.array([10.0, -5.0]), 25.0
    s = scan_airborne(_plane(half=30.0), q, center, half, seed=2)  # the square reaches past the plane: some pulses miss
    assert s.meta["n_rays"] > len(s)
    for line in q.flight_lines(s.meta["lateral_shift_m"]):
        o, d, _ = q.ground_rays(line.to_line(center), half, s.meta["line_phase_s"][line.line_id])
        foot = o[:, :2] + d[:, :2] * (q.altitude_m / -d[:, 2:3])  # line frame, on z = 0
        along, across = line.axes()
        world = line.offset_m * across + foot[:, :1] * along + foot[:, 1:2] * across
        world = world[np.all(np.abs(world) <= 30.0, axis=1)]
        got = s.points[s.meta["line_id"] == line.line_id, :2].astype(np.float64)
        assert len(got) == len(world) > 0
        np.testing.assert_allclose(np.sort(got, axis=0), np.sort(world, axis=0), atol=2e-3)


def test_a_plan_of_one_line_is_the_plain_scanner() -> None:
    q = airborne_preset("riegl-q1560", altitude_m=300.0)
    scene = ScanScene(objects=[SceneObject(trimesh.creation.box(extents=(1, 1, 1)), "box", (0.0, 20.0), 10.0, 4.5)])
    a = scan_airborne(scene, q, (0.0, 20.0), 6.0, seed=9)
    b = scan_airborne(scene, q.with_(side_overlap=0.6), (0.0, 20.0), 6.0, seed=9)  # the overlap needs a second line
    assert a.points.tobytes() == b.points.tobytes() and not a.meta["line_id"].any()


#: sha256 of riegl-q1560 scans and crops made before flight plans existed (script in the test body).
SINGLE_LINE_HASH = "3c4756f5b3ce5c1143d803a8ce7a90289c6d48c0faf9a4fea1f0a1765e023122"


def test_the_single_line_preset_gives_the_bytes_it_gave_before_flight_plans() -> None:
    h = hashlib.sha256()
    q = airborne_preset("riegl-q1560", beam=Q1560_SINGLE_RETURN)
    for pattern in ("linear", "oscillating"):
        s = q.with_(pattern=pattern, altitude_m=400.0, beam=q.beam.with_(dropout=0.1))
        scene = ScanScene(
            objects=[SceneObject(trimesh.creation.box(extents=(1, 1, 1)), "box", (3.0, 40.0), 30.0, 4.5)], ground_half_extent_m=60.0
        )
        out = scan_airborne(scene, s, (3.0, 40.0), 8.0, seed=11)
        for a in (out.points, out.range_m, out.face_index, out.object_id, out.normal, out.incidence_deg, out.meta["scan_angle_deg"]):
            h.update(np.ascontiguousarray(a).tobytes())
        h.update(repr(out.meta["phase_s"]).encode())
    clouds = lidar_object_samples(normalize_mesh(trimesh.creation.cylinder(radius=0.05, height=1.0)), q.with_(altitude_m=300.0), name="pole",
                                  n_samples=3, n_points=64, distributions=CropDistributions(size_m=6.0, distance_m=(1.0, 30.0)), seed=5)  # fmt: skip
    for c in clouds:
        h.update(c.points.tobytes())
        h.update(c.face_index.tobytes())
        h.update(repr((c.n_visible, c.elevation_deg, c.azimuth_deg, c.radius)).encode())
    assert h.hexdigest() == SINGLE_LINE_HASH


def test_dales_preset_density_and_a_pole_seen_from_several_lines() -> None:
    q = sensor_from_name("dales-q1560")
    assert q is airborne_preset("dales-q1560") or q == airborne_preset("dales-q1560")
    assert 45.0 <= q.survey_density_m2 <= 55.0  # DALES: ~50 points/m²
    assert q.swath_width_m / q.flight_line_spacing_m >= 4.0  # every point in at least four strips
    pole = normalize_mesh(trimesh.creation.cylinder(radius=0.15, height=6.0))
    placement = draw_placement(CropDistributions(size_m=6.0), np.random.default_rng(0))
    one = object_crop(pole, airborne_preset("riegl-q1560"), placement, seed=3)
    many = object_crop(pole, q, placement, seed=3)
    # the presets resolve several echoes per pulse (a pulse grazing the pole records the ground behind it too):
    # count the pulses that met the pole
    assert len(np.unique(one.scan.pulse_id)) <= 3  # one pass leaves a thin pole a couple of pulses
    assert len(np.unique(many.scan.pulse_id)) >= 15
    assert len(many.scan.meta["line_id"]) == len(many.scan) and len(np.unique(many.scan.meta["line_id"])) >= 4
    assert len(many.scan.meta["scan_angle_deg"]) == len(many.scan)
    assert len(many.full.meta["line_id"]) == len(many.full) > len(many.scan)


def test_sensor_files_with_a_flight_plan(tmp_path: Path) -> None:
    spec = tmp_path / "survey.json"
    spec.write_text(json.dumps({"kind": "airborne", "name": "survey", "swath_deg": 40, "pulse_rate_hz": 1e5, "line_rate_hz": 50,
                                "altitude_m": 800, "speed_mps": 60, "n_lines": 5, "side_overlap": 0.5, "headings_deg": [0, 90]}))  # fmt: skip
    q = sensor_from_name(str(spec))
    assert isinstance(q, AirborneScanner) and q.n_lines == 5 and q.headings_deg == (0.0, 90.0)
    assert q.survey_density_m2 == pytest.approx(2 * 1e5 / (60 * q.swath_width_m * 0.5))
    based = tmp_path / "based.json"
    based.write_text(json.dumps({"kind": "airborne", "preset": "riegl-q1560", "name": "mine", "n_lines": 3, "side_overlap": 0.3}))
    q = sensor_from_name(str(based))
    assert (q.name, q.altitude_m, q.n_lines, q.side_overlap) == ("mine", 1300.0, 3, 0.3)
    for bad in ({"n_lines": 0}, {"n_lines": 2.5}, {"n_lines": True}, {"side_overlap": 1.0}, {"side_overlap": -0.1},
                {"headings_deg": []}, {"headings_deg": [0, None]}, {"n_lines": MAX_FLIGHT_LINES + 1}, {"preset": "nope"},
                {"n_line": 3}):  # fmt: skip
        bad_file = tmp_path / "bad.json"
        bad_file.write_text(json.dumps({"kind": "airborne", "preset": "riegl-q1560", **bad}))
        with pytest.raises(InvalidInputError, match="bad.json"):
            sensor_from_name(str(bad_file))


def test_bad_flight_plans() -> None:
    for bad in ({"n_lines": 0}, {"n_lines": -3}, {"n_lines": float("nan")}, {"side_overlap": float("inf")},
                {"side_overlap": 1.0}, {"headings_deg": ()}, {"headings_deg": (0.0, float("nan"))},
                {"n_lines": 200, "headings_deg": (0.0, 90.0)}):  # fmt: skip
        with pytest.raises(InvalidInputError):
            airborne_preset("riegl-q1560", **bad)
    assert airborne_preset("riegl-q1560", headings_deg=45).headings_deg == (45.0,)
    with pytest.raises(InvalidInputError, match="lateral_shift_m"):
        airborne_preset("dales-q1560").flight_lines(float("nan"))
