"""A crown's gaps are places: cells that are leaf or gap (:func:`~zbuf_occlude.sensors.beam.attenuation.gap_cells_open`),
so the sub-rays of one footprint pass or stop together, and the scans that meet foliage.

Analytic scenes: parallel plates facing the sensor along +x, as in ``test_all_hits``.
"""

from __future__ import annotations

import io

import laspy
import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors import airborne_preset, scan_airborne
from zbuf_occlude.sensors.beam.attenuation import gap_cells_open
from zbuf_occlude.sensors.beam.echo_energy import Transmission, echo_returns, surface_optics
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.scene.materials import FOLIAGE_GAP_CELL_M, FOLIAGE_GAP_FRACTION
from zbuf_occlude.sensors.raycast.embree import cast_embree
from zbuf_occlude.sensors.scene.objects import BuiltScene, SceneObject

R = 10.0  # the crown plate, metres; the opaque plate stands 2 m behind it


def _distinct_cells(n: int, cell_m: float, seed: int) -> np.ndarray:
    """(n, 3) points at the centres of n distinct cells of side ``cell_m``."""
    rng = np.random.default_rng(seed)
    ijk = np.unique(rng.integers(-(10**6), 10**6, size=(n + n // 10, 3)), axis=0)[:n]
    return (ijk + 0.5) * cell_m


@settings(max_examples=40, deadline=None)
@given(g=st.floats(0.0, 1.0), cell_m=st.floats(0.01, 5.0), seed=st.integers(0, 2**16))
def test_a_surfaces_share_of_gap_cells_is_its_gap_fraction(g: float, cell_m: float, seed: int) -> None:
    n = 20_000
    points = _distinct_cells(n, cell_m, seed)
    share = gap_cells_open(points, np.full(n, g), cell_m).mean()
    assert abs(share - g) <= 5.0 * np.sqrt(g * (1.0 - g) / n) + 1e-12  # one draw per cell, independent


def test_a_cell_is_the_same_for_every_point_in_it_every_call_and_changes_with_the_salt() -> None:
    rng = np.random.default_rng(3)
    centres = _distinct_cells(5_000, 0.1, 4)
    g = np.full(len(centres), 0.3)
    at_centres = gap_cells_open(centres, g, 0.1)
    moved = centres + rng.uniform(-0.0499, 0.0499, size=centres.shape)  # anywhere inside the same cell
    assert np.array_equal(gap_cells_open(moved, g, 0.1), at_centres)
    assert np.array_equal(gap_cells_open(centres, g, 0.1), at_centres)
    other = gap_cells_open(centres, g, 0.1, salt=12345)
    assert 0.3 < np.mean(other != at_centres) < 0.5  # independent patterns differ in 2·0.3·0.7 = 42 % of the cells
    assert not gap_cells_open(centres, np.zeros(len(centres)), 0.1).any()
    assert gap_cells_open(centres, np.ones(len(centres)), 0.1).all()


def test_gap_cells_refuse_bad_arguments() -> None:
    ok = np.zeros((2, 3))
    for points, g, cell, match in (
        (np.zeros((2, 2)), [0.3, 0.3], 0.1, "points"),
        (np.array([[0.0, 0.0, np.nan]] * 2), [0.3, 0.3], 0.1, "points"),
        (ok, [0.3], 0.1, "gap_fraction"),
        (ok, [0.3, 1.5], 0.1, "gap_fraction"),
        (ok, [0.3, 0.3], 0.0, "cell_m"),
        (ok, [0.3, 0.3], float("inf"), "cell_m"),
    ):
        with pytest.raises(InvalidInputError, match=match):
            gap_cells_open(points, g, cell)


def _plates() -> BuiltScene:
    """A crown plate at x = R and an opaque plate 2 m behind it, 400 m across (object ids 1, 2)."""
    plates = []
    for x in (R, R + 2.0):
        v = np.array([[x, -200.0, -200.0], [x, 200.0, -200.0], [x, 200.0, 200.0], [x, -200.0, 200.0]])
        plates.append(trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False))
    return BuiltScene(trimesh.util.concatenate(plates), np.array([1, 1, 2, 2], np.int32), np.tile([0, 1], 2),
                      [SceneObject(p) for p in plates], [np.eye(4)] * 3, [None, *plates])  # fmt: skip


def _pulses_through_the_crown(n_pulses: int, k: int, spread_m: float, cell_m: float, gaps: bool):
    """``n_pulses`` pulses along +x, each of ``k`` parallel sub-rays within ``spread_m`` of its centre, the centres
    at the centres of 200 × 200 cells of the crown plate (gap fraction 0.3, in cells of ``cell_m`` where ``gaps``)."""
    built = _plates()
    rng = np.random.default_rng(0)
    centres = np.zeros((n_pulses, 3))
    centres[:, 1:] = (rng.integers(-100, 100, size=(n_pulses, 2)) + 0.5) * cell_m  # at cell centres: a footprint narrower
    # than a cell lies inside one
    origins = np.repeat(centres, k, axis=0)
    origins[:, 1:] += rng.uniform(-spread_m / 2, spread_m / 2, size=(n_pulses * k, 2))
    rays = np.tile([1.0, 0.0, 0.0], (n_pulses * k, 1))
    face, t = cast_embree(built.mesh, origins, rays)
    assert np.all(built.face_object[face] == 1)  # every sub-ray meets the crown plate first
    tau = np.array([FOLIAGE_GAP_FRACTION, FOLIAGE_GAP_FRACTION, 0.0, 0.0])
    through = Transmission(tau, origins, gaps=np.array([True, True, False, False]) if gaps else None, gap_cell_m=cell_m)
    beam = Beam(
        footprint_rays=k, divergence_deg=0.1, max_returns=3, range_resolution_m=0.5
    )  # the sub-rays are given: only the weights count
    pulse, f, r, e = echo_returns(built, rays, face, t, beam, max_returns=3, through=through)
    behind = built.face_object[f] == 2
    return pulse, behind, e, k


def test_a_footprint_inside_one_cell_goes_on_whole_or_not_at_all() -> None:
    pulse, behind, e, k = _pulses_through_the_crown(2_000, 7, 0.05, 0.8, gaps=True)  # footprints of 5 cm in 0.8 m cells
    full = 1.0 / R**2  # the whole footprint's echo off one plate, ρ 1, head-on
    on_crown = np.bincount(pulse[~behind], minlength=2_000)
    through = np.bincount(pulse[behind], minlength=2_000)
    # each pulse: its crown echo or its echo from behind, never both, each with the whole footprint's energy
    assert np.all(on_crown + through == 1)
    np.testing.assert_allclose(e[~behind], full, rtol=1e-9)
    np.testing.assert_allclose(e[behind], 1.0 / (R + 2.0) ** 2, rtol=1e-9)
    assert abs(through.mean() - FOLIAGE_GAP_FRACTION) < 5.0 * np.sqrt(0.21 / 2_000)


def test_a_gap_fraction_as_a_share_sends_a_weak_echo_behind_every_crown_hit() -> None:
    pulse, behind, e, k = _pulses_through_the_crown(500, 7, 0.05, 1.0, gaps=False)
    assert np.bincount(pulse[behind], minlength=500).tolist() == [1] * 500
    np.testing.assert_allclose(e[behind], FOLIAGE_GAP_FRACTION / (R + 2.0) ** 2, rtol=1e-9)


def test_cells_much_smaller_than_the_footprint_pass_the_gap_fraction_of_its_energy_on_average() -> None:
    # 19 sub-rays over 2 m in 1 cm cells: each sub-ray meets its own cell
    pulse, behind, e, k = _pulses_through_the_crown(2_000, 19, 2.0, 0.01, gaps=True)
    per_pulse = np.bincount(pulse[behind], weights=e[behind], minlength=2_000) * (R + 2.0) ** 2
    assert abs(per_pulse.mean() - FOLIAGE_GAP_FRACTION) < 5.0 * np.sqrt(0.21 / (2_000 * 19))
    crown = np.bincount(pulse[~behind], weights=e[~behind], minlength=2_000) * R**2
    assert abs(crown.mean() - (1.0 - FOLIAGE_GAP_FRACTION)) < 5.0 * np.sqrt(0.21 / (2_000 * 19))  # a gap returns no echo


def test_transmission_checks_its_gaps() -> None:
    built = _plates()
    rays = np.array([[1.0, 0.0, 0.0]])
    through = Transmission(np.array([0.3, 0.3, 0.0, 0.0]), np.zeros(3), gaps=np.array([True, False]))
    with pytest.raises(InvalidInputError, match="gaps must hold one bool per face"):
        echo_returns(built, rays, np.zeros(1, np.int64), np.full(1, R), Beam(max_returns=3, range_resolution_m=0.5), max_returns=3,
                     through=through)  # fmt: skip


def test_a_crowns_faces_are_clumped_whatever_gives_their_transmittance() -> None:
    scene = zo.ScanScene().add({"cylinder": {"radius_m": 1.0, "height_m": 2.0}}, class_name="bush", position_m=(6.0, 0.0))
    scene.add({"box_m": [1.0, 1.0, 1.0]}, class_name="building", position_m=(0.0, 6.0))
    built = scene.build()
    bush = built.face_object == 1
    for transmittance in ("table", 0.4, [0.0, 0.4, 0.4]):
        rho, tau, gaps = surface_optics(built, None, transmittance, wavelength_nm=1064.0, multi_return=True)
        assert np.array_equal(gaps, bush)  # the building transmits as a share; the ground not at all
    assert surface_optics(built, None, [0.0, 0.0, 0.4], wavelength_nm=1064.0, multi_return=True)[2] is None
    assert FOLIAGE_GAP_CELL_M == 0.1


def _crown_scan(class_name: str, seed: int = 1) -> laspy.LasData:
    """The riegl-q1560 over a crown 6 m across (a closed sphere, 3 m above flat ground), its ρ and transmittance the
    same for both classes, so only the clumping of its gaps differs."""
    crown = trimesh.creation.icosphere(subdivisions=3, radius=3.0)
    scene = zo.ScanScene(ground_half_extent_m=30.0).add(crown, class_name=class_name, position_m=(0.0, 0.0, 3.0))
    s = scan_airborne(
        scene, airborne_preset("riegl-q1560"), (0.0, 0.0), 8.0, seed=seed, reflectivity=[0.33, 0.55], transmittance=[0.0, 0.3]
    )
    return laspy.read(io.BytesIO(s.to_las_bytes()))


def test_an_airborne_crown_stops_some_pulses_where_a_share_lets_a_weak_echo_through_each() -> None:
    """The returns of a real canopy: part of the pulses that meet a crown end in it, and those that reach the ground
    bring back a strong echo (the IGN sample: 23 % of its crown pulses reach the ground, at 0.40 of a single ground
    return's median); a gap fraction as a share of every sub-ray's energy sends a weak echo through on every pulse."""
    figures = {}
    for name in ("bush", "building"):
        las = _crown_scan(name)
        t, obj = np.asarray(las.gps_time), np.asarray(las.object_id)
        i = np.asarray(las.intensity, np.float64)
        crown_pulses = np.unique(t[obj == 1])
        reach = np.isin(crown_pulses, t[obj == 0]).mean()
        behind = np.median(i[np.isin(t, crown_pulses) & (obj == 0)])
        figures[name] = (len(crown_pulses), reach, behind)
    (n_bush, reach_bush, behind_bush), (n_share, reach_share, behind_share) = figures["bush"], figures["building"]
    assert n_bush > 200 and n_share > 200
    assert reach_share > 0.97 and reach_bush < 0.9  # seeds 1 and 2: 1.0 and 0.996 against 0.77 and 0.76
    assert behind_bush > 1.2 * behind_share  # 47.5 and 45 counts against 32 and 33
