"""Several returns per pulse in a spinning LiDAR's scan: the multi-return model of ``Lidar``
(``max_returns`` above 1) and the return fields every LiDAR scan carries.

Analytic scene: two parallel plates facing the sensor at ranges R and R + g, the near one
covering one side of the footprint; one pulse along +x, so each sub-ray's hit, range and energy
are known in closed form (:func:`~zbuf_occlude.sensors.beam.footprint.subray_directions`).
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude.sensors as S
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.beam.footprint import footprint_offsets, subray_directions
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.scan_data import GPS_START_S
from zbuf_occlude.sensors.scene.objects import BuiltScene, SceneObject

R = 10.0  # near plate, metres
DIVERGENCE = 2.0  # degrees: a 0.35 m footprint at 10 m


def _plate(x: float, y_max: float) -> trimesh.Trimesh:
    """The rectangle x = ``x``, -5 <= y <= ``y_max``, |z| <= 5 (two triangles, normal along x)."""
    v = np.array(
        [[x, -5.0, -5.0], [x, y_max, -5.0], [x, y_max, 5.0], [x, -5.0, 5.0]],
        dtype=np.float64,
    )
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


def _plates(gap_m: float) -> BuiltScene:
    """Object 1: the near plate at x = R over y < -1 mm; object 2: the far plate at x = R + gap, everywhere."""
    near, far = _plate(R, -1e-3), _plate(R + gap_m, 5.0)
    return BuiltScene(trimesh.util.concatenate([near, far]), np.array([1, 1, 2, 2], np.int32), np.array([0, 1, 0, 1]),
                      [SceneObject(near), SceneObject(far)], [np.eye(4)] * 3, [None, near, far])  # fmt: skip


def _lidar(**beam_changes) -> S.Lidar:
    beam = {
        "min_range_m": 0.1,
        "max_range_m": 1000.0,
        "divergence_deg": DIVERGENCE,
        "footprint_rays": 7,
        "max_returns": 3,
        "range_resolution_m": 0.5,
    }
    return S.Lidar("plates", (0.0,), rotation_hz=10.0, firing_rate_hz=3600.0, beam=Beam(**(beam | beam_changes)))


def _one_pulse(built: BuiltScene, lidar: S.Lidar, **kw) -> S.Scan:
    return S.scan(built, lidar, np.zeros(3), azimuth_range_deg=(-0.5, 0.5), **kw)  # the firing at azimuth 0 only


def _subray_hits(gap_m: float, k: int = 7):
    """Per sub-ray of the pulse along +x: on the near plate?, range, energy (ρ = 1, top hat)."""
    d = subray_directions([[1.0, 0.0, 0.0]], footprint_offsets(k, DIVERGENCE)[0])[0]
    near = d[:, 1] / d[:, 0] * R < -1e-3
    r = np.where(near, R, R + gap_m) / d[:, 0]  # along the sub-ray to the plane x = const
    energy = d[:, 0] / k / r**2  # cos θ = d_x
    return near, r, energy


def test_two_plates_further_apart_than_the_resolution_give_two_returns():
    near, r, e = _subray_hits(1.0)
    assert 0 < near.sum() < 7  # the near plate covers part of the footprint (3 of 7 sub-rays)
    s = _one_pulse(_plates(1.0), _lidar())
    assert len(s) == 2
    np.testing.assert_array_equal(s.return_number, [1, 2])
    np.testing.assert_array_equal(s.number_of_returns, [2, 2])
    np.testing.assert_array_equal(s.object_id, [1, 2])
    # each return: the energy-weighted range of its plate's sub-rays, their summed energy
    want_r = [
        np.average(r[near], weights=e[near]),
        np.average(r[~near], weights=e[~near]),
    ]
    np.testing.assert_allclose(s.range_m, want_r, rtol=1e-6)
    assert abs(s.range_m[0] - R) < 2e-3 and abs(s.range_m[1] - (R + 1.0)) < 2e-3
    np.testing.assert_allclose(s.intensity, [e[near].sum(), e[~near].sum()], rtol=1e-6)
    # both on the pulse's centre direction, one pulse: one id, one time, the beam's elevation
    np.testing.assert_allclose(s.points[:, 1:], 0.0, atol=1e-6)
    assert s.pulse_id[0] == s.pulse_id[1] and s.gps_time[0] == s.gps_time[1] and np.all(s.scan_angle_deg == 0.0)


def test_a_gap_below_the_resolution_gives_one_return_at_the_energy_weighted_range():
    near, r, e = _subray_hits(0.3)
    s = _one_pulse(_plates(0.3), _lidar())
    assert len(s) == 1 and s.return_number[0] == 1 and s.number_of_returns[0] == 1
    assert R < s.range_m[0] < R + 0.3
    np.testing.assert_allclose(s.range_m, [np.average(r, weights=e)], rtol=1e-6)
    np.testing.assert_allclose(s.intensity, [e.sum()], rtol=1e-6)
    assert s.object_id[0] == (1 if e[near].sum() > e[~near].sum() else 2)


def test_max_returns_keeps_the_first_and_the_threshold_drops_weak_echoes():
    # a third plate between: near (y < 0) at R, middle (y >= 0, z > 0) at R + 1, far at R + 2
    near, far = _plate(R, -1e-3), _plate(R + 2.0, 5.0)
    middle = _plate(R + 1.0, 5.0)
    middle.vertices[:, 2] = np.clip(middle.vertices[:, 2], 1e-3, None)
    three = BuiltScene(trimesh.util.concatenate([near, middle, far]), np.array([1, 1, 2, 2, 3, 3], np.int32),
                       np.array([0, 1, 0, 1, 0, 1]), [SceneObject(near), SceneObject(middle), SceneObject(far)],
                       [np.eye(4)] * 4, [None, near, middle, far])  # fmt: skip
    all_three = _one_pulse(three, _lidar(footprint_rays=19))
    assert all_three.object_id.tolist() == [
        1,
        2,
        3,
    ] and all_three.number_of_returns.tolist() == [3, 3, 3]
    first_two = _one_pulse(three, _lidar(footprint_rays=19, max_returns=2))
    assert first_two.object_id.tolist() == [
        1,
        2,
    ] and first_two.return_number.tolist() == [1, 2]
    assert first_two.number_of_returns.tolist() == [2, 2]
    # a threshold between the two plates' echo energies (ρ = 1): the weaker is not detected
    near, _, e = _subray_hits(1.0)
    weak, strong = sorted([e[near].sum(), e[~near].sum()])
    tau = np.sqrt(weak * strong)
    lidar = _lidar(detection_threshold=float(tau))
    s = _one_pulse(_plates(1.0), lidar, reflectivity=1.0)
    assert len(s) == 1 and s.number_of_returns[0] == 1 and s.intensity[0] == pytest.approx(strong, rel=1e-6)


@settings(max_examples=12, deadline=None)
@given(
    k=st.sampled_from([1, 4, 7, 19]),
    max_returns=st.integers(1, 5),
    resolution=st.sampled_from([0.05, 0.3, 1.0]),
    dropout=st.sampled_from([0.0, 0.3]),
    noise=st.sampled_from([0.0, 0.05]),
    seed=st.integers(0, 3),
)
def test_returns_are_numbered_one_to_n_within_each_pulse(k, max_returns, resolution, dropout, noise, seed):
    scene = (S.ScanScene().add({"box_m": [2.0, 2.0, 2.0]}, position_m=(8.0, 0.0))
             .add_occluder({"cylinder": {"radius_m": 0.1, "height_m": 3.0}}, position_m=(4.0, 0.3)))  # fmt: skip
    lidar = with_beam(S.Lidar.preset("vlp16"), footprint_rays=k, divergence_deg=1.5, max_returns=max_returns,
                      range_resolution_m=resolution if max_returns > 1 else 0.0, dropout=dropout, range_noise_m=noise)  # fmt: skip
    s = S.scan(scene, lidar, seed=seed, azimuth_range_deg=(-8.0, 8.0))
    assert len(s) > 0
    _, start, count = np.unique(s.pulse_id, return_index=True, return_counts=True)
    assert np.all(np.diff(s.pulse_id) >= 0)  # a pulse's returns are consecutive
    for first, n in zip(start, count):
        rows = slice(first, first + n)
        np.testing.assert_array_equal(s.return_number[rows], np.arange(1, n + 1))
        assert np.all(s.number_of_returns[rows] == n) and n <= max_returns
        assert np.all(s.gps_time[rows] == s.gps_time[first]) and np.all(s.ring[rows] == s.ring[first])
    assert s.return_number.dtype == np.uint8 and s.number_of_returns.dtype == np.uint8
    assert s.intensity.dtype == np.float32 and s.pulse_id.dtype == np.int64 and s.gps_time.dtype == np.float64


# sha256 (first 16 hex digits) of scans taken before the return fields existed: the model off
# (max_returns 1) must give them bit for bit
_BEFORE = {
    (1, None, ()): {"points": "f392217e7c28044a", "range_m": "8639086d7b3bf26c", "object_id": "16512c470e64da27",
                    "face_index": "91d0dc683dcc1841", "normal": "882eddba8123abab", "ring": "497b8a8cade01fec"},
    (7, 0.5, ("dropout", "power_noise")): {"points": "44a7b410b0a0da0c", "range_m": "9be73bfa20fc6bfc",
                                           "object_id": "568e34a6bfc8dae8", "face_index": "4bf3b89b7435d838",
                                           "normal": "8fe94491f8afc140", "ring": "85f334eded4cba0c"},
}  # fmt: skip


@pytest.mark.parametrize("key", sorted(_BEFORE, key=str))
def test_one_return_per_pulse_is_bit_identical_to_the_scans_before_returns(key):
    k, rho, extra = key
    changes = {"dropout": 0.1, "power_noise": 0.3} if extra else {}
    # τ = 0.8 / 20² (0.8 at 20 m, the old detection_range_m 20)
    lidar = with_beam(S.Lidar.preset("vlp16"), footprint_rays=k, divergence_deg=0.5, detection_threshold=0.8 / 20.0**2, **changes)
    scene = S.ScanScene().add({"box_m": [2.0, 2.0, 2.0]}, position_m=(6.0, 1.0))
    s = S.scan(scene, lidar, seed=3, reflectivity=rho, azimuth_range_deg=(-60, 60))
    got = {name: hashlib.sha256(np.ascontiguousarray(getattr(s, name)).tobytes()).hexdigest()[:16] for name in _BEFORE[key]}
    assert got == _BEFORE[key]
    assert np.all(s.return_number == 1) and np.all(s.number_of_returns == 1)
    if rho is None:
        # the preset's beam has an intensity scale: the intensity is the received energy |cos θ| / R² with ρ = 1
        # (before beams carried one it was 1.0), and no threshold applies without reflectivities
        cos = np.cos(np.radians(s.incidence_deg.astype(np.float64)))
        np.testing.assert_allclose(
            s.intensity, cos / s.range_m.astype(np.float64) ** 2, rtol=0.07
        )  # R measured with 3 cm noise, 5 m and more
        assert s.intensity.min() < lidar.beam.detection_threshold
        plain = S.scan(scene, with_beam(lidar, intensity_scale=None), seed=3, reflectivity=rho, azimuth_range_deg=(-60, 60))
        assert plain.points.tobytes() == s.points.tobytes() and np.all(plain.intensity == 1.0)
    else:  # the received power the detection test compares with the threshold
        assert np.all(s.intensity >= np.float32(lidar.beam.detection_threshold))


def test_return_fields_survive_npz_and_old_files_read_with_defaults(tmp_path):
    scene = S.ScanScene().add({"box_m": [2.0, 2.0, 2.0]}, position_m=(6.0, 0.0))
    lidar = with_beam(S.Lidar.preset("vlp16"), footprint_rays=7, divergence_deg=1.0, max_returns=3, range_resolution_m=0.3)
    s = S.scan(scene, lidar, seed=0, azimuth_range_deg=(-30, 30))
    keys = list(s.arrays())
    assert keys[: keys.index("sensor") + 1] == ["points", "ring", "range_m", "face_index", "object_id", "normal",
                                                "incidence_deg", "sensor_position", "sensor_to_world", "frame", "sensor"]  # fmt: skip
    # then the return fields, and (known here) the beam's intensity scale, the objects' class names and the largest count
    # and what the device writes of the intensity: a Velodyne's calibrated reflectivity
    assert keys[keys.index("sensor") + 1 :] == [*S.Scan._RETURNS, "intensity_scale", "object_classes", "max_intensity", "intensity_unit"]
    assert s.max_intensity == lidar.beam.max_intensity == 255
    s.to_npz(tmp_path / "s.npz")
    r = S.read_scan_npz(tmp_path / "s.npz")
    for name in S.Scan._PER_POINT:
        got, want = getattr(r, name), getattr(s, name)
        assert (got is None and want is None) or (np.array_equal(got, want) and got.dtype == want.dtype), name
    crop = s.select(s.return_number == 1)
    assert np.all(crop.return_number == 1) and len(crop.pulse_id) == len(crop)
    # a file written before the return fields: one return per pulse, no radiometry
    old = {k: v for k, v in s.arrays().items() if k not in S.Scan._RETURNS}
    np.savez(tmp_path / "old.npz", **old)
    r = S.read_scan_npz(tmp_path / "old.npz")
    assert np.all(r.return_number == 1) and np.all(r.number_of_returns == 1) and np.all(r.intensity == 1.0)
    assert r.pulse_id is None and r.gps_time is None and r.scan_angle_deg is None


def test_gps_time_and_pulse_id_follow_the_firing():
    lidar = with_beam(S.Lidar.preset("vlp16"), range_noise_m=0.0)
    scene = S.ScanScene().add({"box_m": [2.0, 8.0, 3.0]}, position_m=(6.0, 0.0))
    s = S.scan(scene, lidar, seed=0, azimuth_range_deg=(-20, 20))
    az = np.mod(
        np.degrees(np.arctan2(s.points[:, 1], s.points[:, 0])) - lidar.azimuth_offset_deg,
        360.0,
    )
    index = np.rint(az / (360.0 / lidar.n_azimuths)).astype(np.int64) % lidar.n_azimuths
    np.testing.assert_array_equal(s.pulse_id, s.ring * lidar.n_azimuths + index)
    # the beams of one firing cycle fire one after another, beam b at b / n_beams of the cycle
    cycle_s = 1.0 / (lidar.n_azimuths * lidar.rotation_hz)
    np.testing.assert_allclose(s.gps_time, (index + s.ring / lidar.n_beams) * cycle_s, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(s.scan_angle_deg, np.asarray(lidar.elevations_deg, np.float32)[s.ring])
    assert len(np.unique(s.pulse_id)) == len(s)
    # every pulse its own time, so a LAS reader that groups returns by time tells them apart
    assert len(np.unique(s.gps_time)) == len(s)


@pytest.mark.parametrize(
    "changes, words",
    [({"max_returns": 16, "range_resolution_m": 0.5}, "max_returns"), ({"max_returns": 0}, "max_returns"),
     ({"max_returns": 2}, "max_returns 2 needs range_resolution_m > 0"),
     ({"range_resolution_m": 0.5}, "range_resolution_m.*max_returns"),
     ({"range_resolution_m": -1.0}, "range_resolution_m"), ({"footprint_rays": 1025, "divergence_deg": 1.0}, "footprint_rays"),
     ({"footprint_rays": 19}, "footprint_rays above 1 needs divergence_deg"), ({"profile": "flat"}, "profile"),
     ({"max_returns": 2, "range_resolution_m": 0.5, "footprint_rays": 7, "divergence_deg": 1.0, "echo_separation_m": 0.7},
      "echo_separation_m.*range_resolution_m"),
     ({"return_mode": "strongest", "max_returns": 2, "range_resolution_m": 0.5}, "return_mode strongest records 1 return per pulse; max_returns 2 contradicts it"),
     ({"return_mode": "first"}, "return_mode")],
)  # fmt: skip
def test_return_model_fields_are_checked_by_name(changes, words):
    """The return model's rules are the beam's, named by the LiDAR and its beam wherever the beam is changed."""
    with pytest.raises(InvalidInputError, match="^beam: .*" + words):
        S.Lidar("x", (0.0,), beam=Beam(**changes))
    with pytest.raises(InvalidInputError, match="^spinning LiDAR: beam: .*" + words):
        with_beam(S.Lidar("x", (0.0,)), **changes)


def test_any_footprint_size_and_a_gaussian_profile_scan():
    lidar = _lidar(
        footprint_rays=37,
        profile="gaussian",
        max_returns=1,
        range_resolution_m=0.0,
    )
    one = _one_pulse(_plates(1.0), lidar)
    assert len(one) == 1 and one.number_of_returns[0] == 1
    d = lidar.beam.footprint_directions([[1.0, 0.0, 0.0]])
    assert d.shape == (1, 37, 3) and np.allclose(np.linalg.norm(d, axis=2), 1.0)
    w = lidar.beam.footprint_weights()
    assert w[0] > w[-1] and w.sum() == pytest.approx(1.0)
    two = _one_pulse(_plates(1.0), with_beam(lidar, max_returns=2, range_resolution_m=0.5))
    assert two.return_number.tolist() == [1, 2]


@pytest.mark.parametrize("compress", [False, True])
def test_las_round_trip_read_back_by_laspy(compress):
    import io

    laspy = pytest.importorskip("laspy")
    if compress:
        pytest.importorskip("lazrs")
    scene = S.ScanScene().add({"box_m": [2.0, 2.0, 2.0]}, position_m=(6.0, 1.0))
    lidar = with_beam(S.Lidar.preset("vlp16"), footprint_rays=19, divergence_deg=1.0, max_returns=4, range_resolution_m=0.3)
    s = S.scan(
        scene,
        lidar,
        seed=1,
        reflectivity=0.5,
        azimuth_range_deg=(-60, 60),
        frame="world",
    )
    assert (s.number_of_returns > 1).any()
    las = laspy.read(io.BytesIO(s.to_las_bytes(compress)))
    assert las.header.version.major == 1 and las.header.version.minor == 4 and las.header.point_format.id == 6
    assert len(las) == len(s)
    xyz = np.column_stack([las.x, las.y, las.z])
    assert np.abs(xyz - s.points.astype(np.float64)).max() <= 0.0005 + 1e-6  # 1 mm steps
    np.testing.assert_array_equal(np.asarray(las.return_number), s.return_number)
    np.testing.assert_array_equal(np.asarray(las.number_of_returns), s.number_of_returns)
    np.testing.assert_array_equal(np.asarray(las.gps_time), GPS_START_S + s.gps_time)  # adjusted standard GPS time
    np.testing.assert_allclose(np.asarray(las.scan_angle) * 0.006, s.scan_angle_deg, atol=0.003)
    # the preset's beam scales the received energy to counts (intensity_scale, the scan keeps it)
    assert s.intensity_scale == lidar.beam.intensity_scale
    np.testing.assert_array_equal(np.asarray(las.intensity), lidar.beam.intensity_counts(s.intensity, s.range_m))


def test_las_intensity_stops_at_the_beams_max_intensity():
    """A return's LAS intensity is ``min(rint(E · R² · intensity_scale), max_intensity)`` for a Velodyne's calibrated
    reflectivity (Beam's docstring): an 8-bit reflectivity stops at 255, however bright the retro-reflector."""
    import io

    laspy = pytest.importorskip("laspy")
    scene = S.ScanScene().add({"box_m": [2.0, 2.0, 2.0]}, position_m=(6.0, 1.0))
    lidar = S.Lidar.preset("vlp16")
    s = S.scan(scene, lidar, seed=1, reflectivity=[0.5, 4.0], azimuth_range_deg=(-60, 60), frame="world")
    beyond = s.intensity * s.range_m**2 * lidar.beam.intensity_scale > 255
    assert lidar.beam.max_intensity == 255 and np.any(beyond)  # the retro-reflecting box beyond 8 bits
    las = laspy.read(io.BytesIO(s.to_las_bytes(False)))
    np.testing.assert_array_equal(np.asarray(las.intensity), lidar.beam.intensity_counts(s.intensity, s.range_m))


def test_scan_command_writes_las_and_laz(tmp_path, capsys):
    laspy = pytest.importorskip("laspy")
    pytest.importorskip("lazrs")
    from zbuf_occlude.cli.main import main

    for fmt in ("las", "laz"):
        out = tmp_path / fmt
        assert (
            main(
                [
                    "scan",
                    "box",
                    "--extents",
                    "4.5,1.8,1.5",
                    "--format",
                    fmt,
                    "--out",
                    str(out),
                ]
            )
            == 0
        )
        files = sorted(out.glob(f"*.{fmt}"))
        assert len(files) == 1
        las = laspy.read(files[0])
        assert len(las) > 100 and las.header.point_format.id == 6
        assert np.all(np.asarray(las.return_number) == 1) and np.all(np.asarray(las.number_of_returns) == 1)
        assert np.ptp(np.asarray(las.gps_time)) > 0
    capsys.readouterr()
