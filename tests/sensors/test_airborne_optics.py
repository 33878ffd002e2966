"""An airborne scan's reflectivity and transmittance: the spinning LiDAR's surface optics and
all-hits casting (one implementation, :func:`zbuf_occlude.sensors.beam.echo_energy.surface_optics`) on an
airborne scanner's footprint.

Scene: flat ground at z = 0 under a thin plate (a 5 cm box: a top and a bottom face) at
``PLATE_Z``, wider than the scanned square, so every pulse meets the plate first.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors import AirborneScanner, scan_airborne
from zbuf_occlude.sensors.beam.fields import Beam

ALTITUDE_M = 100.0
PLATE_Z = 10.0


def _plate_over_ground() -> trimesh.Trimesh:
    v = [[-500.0, -500.0, 0.0], [500.0, -500.0, 0.0], [500.0, 500.0, 0.0], [-500.0, 500.0, 0.0]]
    ground = trimesh.Trimesh(vertices=v, faces=[[0, 1, 2], [0, 2, 3]], process=False)
    plate = trimesh.creation.box(extents=(200.0, 200.0, 0.05))
    plate.apply_translation((0.0, 0.0, PLATE_Z))
    return trimesh.util.concatenate([ground, plate])


def _beam(**changes) -> Beam:
    fields = {"wavelength_nm": 1064.0, "divergence_deg": 0.5, "footprint_rays": 7, "max_returns": 3, "range_resolution_m": 0.5}
    return Beam(**{**fields, **changes})


def _scanner(**beam_changes) -> AirborneScanner:
    return AirborneScanner("test-als", 10.0, 2000.0, 20.0, ALTITUDE_M, 10.0, beam=_beam(**beam_changes))


def _scan(**optics):
    return scan_airborne(_plate_over_ground(), _scanner(), (0.0, 0.0), 5.0, seed=3, phase_s=0.0, **optics)


def test_opaque_surfaces_give_the_scan_of_before_bit_for_bit() -> None:
    before, opaque = _scan(), _scan(transmittance=0.0, reflectivity=1.0)
    for name, value in before.arrays().items():
        np.testing.assert_array_equal(opaque.arrays()[name], value, err_msg=name)
    assert np.all(before.number_of_returns == 1) and np.allclose(before.points[:, 2], PLATE_Z + 0.025, atol=0.01)


def test_a_half_transmitting_plate_gives_the_ground_behind_it_at_its_share_of_the_energy() -> None:
    s = _scan(transmittance=0.5)
    assert len(s) and np.all(s.number_of_returns == 2), np.bincount(s.number_of_returns)
    first, last = s.return_number == 1, s.return_number == 2
    np.testing.assert_array_equal(s.pulse_id[first], s.pulse_id[last])
    np.testing.assert_allclose(s.points[first, 2], PLATE_Z, atol=0.05)
    np.testing.assert_allclose(s.points[last, 2], 0.0, atol=0.05)
    # plate: its top (1) and its bottom behind it (0.5) in one echo; the ground behind both: 0.25;
    # each at ρ cos θ / R², the ranges in the ratio (h − PLATE_Z) / h along one pulse
    ratio = s.intensity[last] / s.intensity[first]
    np.testing.assert_allclose(ratio, 0.25 / 1.5 * ((ALTITUDE_M - PLATE_Z) / ALTITUDE_M) ** 2, rtol=0.02)


def test_reflectivity_per_object_id_weighs_each_echo() -> None:
    # a bare mesh is one object (id 1; id 0, the ground of a scene, is absent): every echo is its
    plain, weighed = _scan(transmittance=0.5), _scan(transmittance=0.5, reflectivity=[0.2, 0.8])
    assert np.all(plain.object_id == 1)
    np.testing.assert_allclose(weighed.intensity, 0.8 * plain.intensity, rtol=1e-6)


def test_the_cited_table_gives_the_scene_values_at_the_airborne_wavelength() -> None:
    from zbuf_occlude.sensors.scene.materials import AIRBORNE_WAVELENGTH_NM, scene_optics
    from zbuf_occlude.sensors.scan import build_scene

    table = scene_optics(build_scene(_plate_over_ground()), AIRBORNE_WAVELENGTH_NM)
    plain, tabled = _scan(), _scan(reflectivity="table")
    ids = plain.object_id
    np.testing.assert_allclose(tabled.intensity, table.reflectivity[ids] * plain.intensity, rtol=1e-6)


@pytest.mark.parametrize(
    ("optics", "message"),
    [
        ({"transmittance": 1.5}, "transmittance must be one value in [0, 1]"),
        ({"transmittance": [0.5, 0.5, 0.5]}, "transmittance must be one value in [0, 1] or 2"),
        ({"reflectivity": -1.0}, "reflectivity must be one value >= 0"),
        ({"reflectivity": "tabel"}, "reflectivity must be a number, one per object id, or 'table', got 'tabel'"),
    ],
)
def test_bad_optics_are_refused_naming_the_value(optics, message) -> None:
    with pytest.raises(InvalidInputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        _scan(**optics)


def test_optics_need_the_multi_return_model() -> None:
    one = _scanner(footprint_rays=1, max_returns=1, divergence_deg=0.0, range_resolution_m=0.0)
    with pytest.raises(InvalidInputError, match="max_returns above 1"):
        scan_airborne(_plate_over_ground(), one, (0.0, 0.0), 5.0, transmittance=0.5)


def test_the_detection_threshold_drops_the_weak_echoes_and_frees_their_slot() -> None:
    plain = _scan(transmittance=0.5)
    ground = plain.intensity[plain.return_number == 2]
    plate = plain.intensity[plain.return_number == 1]
    between = float(ground.max() * 1.01)
    assert between < plate.min()
    s = scan_airborne(_plate_over_ground(), _scanner(detection_threshold=between), (0.0, 0.0), 5.0, seed=3, phase_s=0.0, transmittance=0.5)
    assert len(s) == len(plate) and np.all(s.number_of_returns == 1) and np.all(s.return_number == 1)
    np.testing.assert_array_equal(s.intensity, plate)
    # without reflectivity the threshold weighs the echoes with rho 1; a threshold of 0 keeps every echo
    np.testing.assert_array_equal(
        _scan(transmittance=0.5).intensity,
        scan_airborne(
            _plate_over_ground(), _scanner(detection_threshold=0.0), (0.0, 0.0), 5.0, seed=3, phase_s=0.0, transmittance=0.5
        ).intensity,
    )


@pytest.mark.parametrize("value", [-1e-9, float("nan"), float("inf"), "1e-6", True])
def test_a_bad_detection_threshold_is_refused_naming_the_field(value) -> None:
    with pytest.raises(InvalidInputError, match=r"beam: detection_threshold"):
        _scanner(detection_threshold=value)


def test_a_detection_threshold_with_one_return_drops_the_weak_pulses_with_rho_1() -> None:
    """One return per pulse (the centre ray's first hit): the threshold applies to its energy |cos θ| / R² (ρ = 1 without
    reflectivities), and the intensity is that energy; a threshold between the weakest and the strongest keeps those above it."""
    one = {"footprint_rays": 1, "max_returns": 1, "divergence_deg": 0.0, "range_resolution_m": 0.0}
    every = scan_airborne(_plate_over_ground(), _scanner(**one, detection_threshold=1e-30), (0.0, 0.0), 5.0, seed=3, phase_s=0.0)
    assert len(every) and np.all(every.number_of_returns == 1)
    expected = np.abs(np.cos(np.radians(every.incidence_deg.astype(np.float64)))) / every.range_m.astype(np.float64) ** 2
    np.testing.assert_allclose(every.intensity, expected, rtol=1e-4)
    tau = float(np.median(every.intensity))
    s = scan_airborne(_plate_over_ground(), _scanner(**one, detection_threshold=tau), (0.0, 0.0), 5.0, seed=3, phase_s=0.0)
    assert 0 < len(s) < len(every)
    np.testing.assert_array_equal(np.sort(s.pulse_id), np.sort(every.pulse_id[every.intensity >= tau]))
