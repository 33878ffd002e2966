"""The airborne scanner's several returns per pulse: the spinning LiDAR's echo model on each
pulse's footprint (one implementation), the return fields of an airborne scan, and scans with
the model off bit-identical to those taken before it existed.

Analytic scene: flat ground at z = 0 and a thin horizontal plate at ``PLATE_Z`` whose edge runs
along track at ``y = EDGE_Y``, so the footprints of the pulses aimed near the edge fall half on
the plate and half on the ground: two returns, at about ``(h − PLATE_Z) / cos θ`` and ``h / cos θ``.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors import AirborneScanner, airborne_preset, scan_airborne
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.scene.objects import BuiltScene, SceneObject

ALTITUDE_M = 100.0
PLATE_Z = 10.0
EDGE_Y = 2.0


def _plate_over_ground(edge_y: float = EDGE_Y) -> trimesh.Trimesh:
    v = [[-500.0, -500.0, 0.0], [500.0, -500.0, 0.0], [500.0, 500.0, 0.0], [-500.0, 500.0, 0.0]]
    ground = trimesh.Trimesh(vertices=v, faces=[[0, 1, 2], [0, 2, 3]], process=False)
    plate = trimesh.creation.box(extents=(200.0, 100.0, 0.05))
    plate.apply_translation((0.0, edge_y + 50.0, PLATE_Z))
    return trimesh.util.concatenate([ground, plate])


#: The riegl-q1560 beam before the presets carried their data sheets' footprints and echoes: one return per pulse
#: (the centre ray's first hit), 2 cm range noise; what the scans of before returns were taken with.
Q1560_SINGLE_RETURN = Beam("riegl-q1560", wavelength_nm=1064.0, range_noise_m=0.02)


def _scanner(**beam_changes) -> AirborneScanner:
    """A slow, low scanner with a 2° beam (a 3.5 m footprint at 100 m) and no range noise."""
    beam = {"wavelength_nm": 1064.0, "divergence_deg": 2.0, "footprint_rays": 19, "max_returns": 3, "range_resolution_m": 0.5}
    return AirborneScanner("test-als", 20.0, 2000.0, 20.0, ALTITUDE_M, 10.0, beam=Beam(**{**beam, **beam_changes}))


def test_a_plate_half_covering_the_footprint_gives_two_returns_at_its_range_and_the_grounds() -> None:
    s = scan_airborne(_plate_over_ground(), _scanner(), (0.0, EDGE_Y), 8.0, seed=1, phase_s=0.0)
    two = s.number_of_returns == 2
    assert two.sum() >= 10, np.bincount(s.number_of_returns)
    cos = np.cos(np.radians(s.scan_angle_deg[two].astype(np.float64)))
    first, last = two & (s.return_number == 1), two & (s.return_number == 2)
    np.testing.assert_allclose(s.range_m[first], (ALTITUDE_M - PLATE_Z) / cos[s.return_number[two] == 1], atol=0.2)
    np.testing.assert_allclose(s.range_m[last], ALTITUDE_M / cos[s.return_number[two] == 2], atol=0.2)
    np.testing.assert_allclose(s.points[first, 2], PLATE_Z, atol=0.2)
    np.testing.assert_allclose(s.points[last, 2], 0.0, atol=0.2)
    # the two returns of a pulse are aimed near the edge; a pulse whose whole footprint is on the plate or the ground has one
    footprint_radius = ALTITUDE_M * np.tan(np.radians(1.0)) / np.cos(np.radians(10.0)) ** 2
    assert np.all(np.abs(s.points[two, 1] - EDGE_Y) <= footprint_radius + 0.5)
    far = np.abs(s.points[:, 1] - EDGE_Y) > footprint_radius * 1.3 + 0.5
    assert far.any() and np.all(s.number_of_returns[far] == 1)
    # per pulse: one firing time and scan angle, the plate's echo stronger than nothing, returns share the pulse id
    for pid in np.unique(s.pulse_id[two])[:20]:
        mine = s.pulse_id == pid
        assert len(set(s.gps_time[mine])) == 1 and len(set(s.scan_angle_deg[mine])) == 1
    assert np.all(s.intensity > 0)


def test_scan_angle_is_signed_as_asprs_defines_it_and_time_runs_along_the_line() -> None:
    """LAS 1.4: counter-clockwise seen from behind the aircraft is positive: the right (−y) side of a line flown along +x."""
    s = scan_airborne(_plate_over_ground(edge_y=200.0), _scanner(), (0.0, 0.0), 15.0, seed=0, phase_s=0.0)
    right = s.points[:, 1] < -1.0
    assert np.all(s.scan_angle_deg[right] > 0) and np.all(s.scan_angle_deg[s.points[:, 1] > 1.0] < 0)
    np.testing.assert_allclose(s.scan_angle_deg, -s.meta["scan_angle_deg"], rtol=1e-6)
    # the aircraft at x = speed · t fired each pulse from straight above its point's x (nadir-looking across track)
    # the line is flown from -L/2 at time 0 (its start on the plan's clock), at 10 m/s
    np.testing.assert_allclose(s.points[:, 0], 10.0 * s.gps_time - s.meta["line_length_m"] / 2.0, atol=1e-3)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    k=st.sampled_from([3, 7, 19, 37]),
    divergence=st.floats(0.5, 4.0),
    resolution=st.floats(0.2, 5.0),
    max_returns=st.integers(2, 5),
    edge=st.floats(-4.0, 4.0),
    dropout=st.sampled_from([0.0, 0.3]),
    seed=st.integers(0, 2**16),
)
def test_return_numbers_run_1_to_n_and_n_is_the_same_across_a_pulse(k, divergence, resolution, max_returns, edge, dropout, seed) -> None:
    scanner = _scanner(footprint_rays=k, divergence_deg=divergence, range_resolution_m=resolution, max_returns=max_returns,
                       dropout=dropout, range_noise_m=0.05)  # fmt: skip
    s = scan_airborne(_plate_over_ground(edge), scanner, (0.0, edge), 5.0, seed=seed)
    assert len(s) > 0
    order = np.lexsort((s.return_number, s.pulse_id))
    pid, rn, nr = s.pulse_id[order], s.return_number[order], s.number_of_returns[order]
    starts = np.flatnonzero(np.r_[True, pid[1:] != pid[:-1]])
    counts = np.diff(np.r_[starts, len(pid)])
    assert np.all(nr == np.repeat(counts, counts)), "number_of_returns differs within a pulse or from its count"
    assert np.all(rn == np.arange(len(pid)) - np.repeat(starts, counts) + 1), "return numbers do not run 1..n"
    assert np.all((nr >= 1) & (nr <= max_returns))
    for field in ("return_number", "number_of_returns", "intensity", "pulse_id", "gps_time", "scan_angle_deg"):
        assert len(getattr(s, field)) == len(s)


def _digest(a: np.ndarray, shape: bool = True) -> str:
    tail = str(a.dtype) + (str(a.shape) if shape else "")
    return hashlib.sha256(np.ascontiguousarray(a).tobytes() + tail.encode()).hexdigest()[:16]


def _box_scene() -> trimesh.Trimesh:
    v = [[-3000.0, -3000.0, 0.0], [3000.0, -3000.0, 0.0], [3000.0, 3000.0, 0.0], [-3000.0, 3000.0, 0.0]]
    plane = trimesh.Trimesh(vertices=v, faces=[[0, 1, 2], [0, 2, 3]], process=False)
    box = trimesh.creation.box(extents=(4.0, 2.0, 3.0))
    box.apply_translation((1.0, 2.0, 1.5))
    return trimesh.util.concatenate([plane, box])


# sha256 (first 16 hex digits of array bytes + dtype + shape; meta: + dtype) of airborne scans taken before the
# return fields existed: the model off (max_returns 1, the default) must give them bit for bit
_BEFORE = {
    "one_line": {"points": "659ec611a4b98b9f", "range_m": "cd003b91844e0168", "face_index": "538d2e8e4ea73cf2",
                 "object_id": "9b5c78da02badd07", "normal": "ab6147bb52493cd9", "incidence_deg": "662984f0dbba9a1e",
                 "meta.scan_angle_deg": "2e5337ef640a6e31", "meta.line_id": "a4503d163281ba4b"},
    "cross_hatched": {"points": "0e9dff597545f21a", "range_m": "fa7d62a7520737c9", "face_index": "590857c4d5721f7e",
                      "object_id": "7f74617417d92283", "normal": "255154a100ec6b20", "incidence_deg": "6ada571cf70fe657",
                      "meta.scan_angle_deg": "bc9410a4603d7af6", "meta.line_id": "0fcb56616189bca0"},
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(_BEFORE))
def test_one_return_per_pulse_is_bit_identical_to_the_scans_before_returns(name: str) -> None:
    if name == "one_line":
        scanner = AirborneScanner("test", swath_deg=40.0, pulse_rate_hz=100_000.0, line_rate_hz=50.0, altitude_m=500.0, speed_mps=60.0,
                                  beam=Beam(wavelength_nm=1064.0, dropout=0.2, range_noise_m=0.05))  # fmt: skip
        s = scan_airborne(_box_scene(), scanner, (0.0, 0.0), 20.0, seed=7)
    else:
        scanner = airborne_preset("dales-q1560", headings_deg=(0.0, 90.0), n_lines=3, beam=Q1560_SINGLE_RETURN)
        s = scan_airborne(_box_scene(), scanner, (3.0, -2.0), 6.0, seed=11, phase_s=0.001)
    got = {
        key: _digest(np.asarray(s.meta[key[5:]]), shape=False) if key.startswith("meta.") else _digest(getattr(s, key))
        for key in _BEFORE[name]
    }
    assert got == _BEFORE[name]
    assert np.all(s.return_number == 1) and np.all(s.number_of_returns == 1) and np.all(s.intensity == 1.0)
    assert len(np.unique(s.pulse_id)) == len(s)


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"footprint_rays": 7}, r"footprint_rays above 1 needs divergence_deg > 0"),
        ({"footprint_rays": 1025, "divergence_deg": 1.0}, r"footprint_rays"),
        ({"max_returns": 3}, r"max_returns 3 needs range_resolution_m > 0"),
        ({"max_returns": 16, "range_resolution_m": 0.5}, r"max_returns"),
        ({"range_resolution_m": 0.5}, r"range_resolution_m 0.5 separates several returns per pulse: it needs max_returns above 1"),
        ({"max_returns": 2, "range_resolution_m": float("nan")}, r"range_resolution_m"),
        ({"profile": "cone"}, r"profile"),
        ({"max_returns": True, "range_resolution_m": 0.5}, r"max_returns"),
        ({"return_mode": "dual"}, r"return_mode dual records 2 returns per pulse; max_returns \d+ contradicts it"),
    ],
)
def test_bad_return_fields_are_refused_naming_the_field(changes: dict, message: str) -> None:
    """The beam's rules, named by the scanner and its beam."""
    single = airborne_preset("riegl-q1560", beam=Q1560_SINGLE_RETURN)
    with pytest.raises(InvalidInputError, match=r"^airborne scanner: beam: " + message):
        with_beam(single, **changes)


def test_a_footprint_with_one_return_per_pulse_records_its_strongest_echo() -> None:
    """A footprint with one return per pulse is accepted (it was refused before every scanner fired a Beam): each pulse
    records the echo of most energy, so near the plate's edge, where the nearer plate takes a share of the sub-rays worth
    more than the ground's, a pulse whose centre ray falls on the ground returns from the plate."""
    mesh = _plate_over_ground()  # the ground's 2 faces, then the plate's 12: two objects (a footprint's echoes add up per object)
    scene = BuiltScene(mesh, np.repeat(np.array([1, 2], np.int32), [2, 12]), np.r_[np.arange(2), np.arange(12)],
                       [SceneObject(mesh), SceneObject(mesh)], [np.eye(4)] * 3, [None, mesh, mesh])  # fmt: skip
    foot = scan_airborne(scene, _scanner(max_returns=1, range_resolution_m=0.0), (0.0, EDGE_Y), 8.0, seed=1, phase_s=0.0)
    centre = scan_airborne(scene, _scanner(max_returns=1, range_resolution_m=0.0, footprint_rays=1, divergence_deg=0.0),
                           (0.0, EDGE_Y), 8.0, seed=1, phase_s=0.0)  # fmt: skip
    assert len(foot) == len(centre) > 0 and np.all(foot.number_of_returns == 1) and np.all(foot.return_number == 1)
    assert len(np.unique(foot.pulse_id)) == len(foot)
    assert set(np.unique(foot.object_id)) == {1, 2}
    on_plate = foot.object_id == 2
    # the echo's range (the energy-weighted mean of its object's sub-rays), not a mix of both objects, along the centre ray
    np.testing.assert_allclose(foot.points[on_plate, 2], PLATE_Z, atol=0.3)
    np.testing.assert_allclose(foot.points[~on_plate, 2], 0.0, atol=0.3)
    centre_on_plate = centre.object_id == 2
    assert on_plate.sum() > centre_on_plate.sum()
    # the points stay on each pulse's centre direction: the plate's returns reach past the edge, onto the ground's side
    assert foot.points[on_plate, 1].min() < centre.points[centre_on_plate, 1].min()


def test_a_sensor_file_round_trips_the_return_fields(tmp_path) -> None:
    import json

    from zbuf_occlude.sensors.kinds import sensor_from_name, sensor_to_json

    scanner = _scanner(profile="gaussian")
    path = tmp_path / "als.json"
    path.write_text(json.dumps(sensor_to_json(scanner)))
    assert sensor_from_name(path) == scanner
