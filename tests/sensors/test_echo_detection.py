"""Detection of partial echoes relative to the full footprint (``Beam.min_echo_reflectance``).

An echo is detected where its apparent reflectance, energy × range², reaches the beam's
``min_echo_reflectance``: ``ρ · |cos θ|`` times the share of the footprint its surfaces take.
Analytic cases: an edge that covers a known share of the footprint, at two ranges and for several
sub-ray counts K; laws: the rule does not change when the scene is scaled about the sensor, and a
higher threshold keeps a subset of the echoes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude.sensors as S
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.fields import IDEAL_BEAM, Beam
from zbuf_occlude.sensors.beam.echoes import MAX_RETURNS, hit_energy, resolve_echoes
from zbuf_occlude.sensors.beam.footprint import footprint_offsets, subray_directions
from zbuf_occlude.sensors.scene.objects import BuiltScene, SceneObject

DIVERGENCE = 2.0  # degrees


def _segment_share(c: float) -> float:
    """Share of the unit disc with ``y < -c`` (a circular segment; ``c`` in radii, |c| < 1)."""
    return (math.acos(c) - c * math.sqrt(1.0 - c * c)) / math.pi


def _edge_pulse(range_m: float, c: float, k: int, rho: float = 0.5):
    """One pulse along +x: a plate at ``range_m`` covering the footprint where y < −c · (its half-width).

    Returns the hits on the plate (range, energy) and the share of the pulse's energy they carry."""
    offsets, weights = footprint_offsets(k, DIVERGENCE)
    d = subray_directions([[1.0, 0.0, 0.0]], offsets)[0]
    half = math.tan(math.radians(DIVERGENCE) / 2.0)
    on = d[:, 1] / d[:, 0] < -c * half
    r = range_m / d[on, 0]
    return r, hit_energy(weights[on], rho, d[on, 0], r), float(weights[on].sum())


def _detected(r, e, **kw) -> int:
    args = {"range_resolution_m": 0.75, "detection_threshold": 0.0, "max_returns": 5} | kw
    echoes = resolve_echoes(np.zeros(len(r), np.int64), r, e, np.ones(len(r), np.int64), **args)
    return len(echoes)


@pytest.mark.parametrize("range_m", [5.0, 1500.0])
def test_an_edge_covering_a_third_of_the_footprint_is_detected_alike_at_5_m_and_1500_m(range_m):
    # the plate takes a third of the footprint (c with a segment of 1/3): apparent reflectance ≈ ρ/3 = 0.167
    c = 0.2649  # _segment_share(c) ≈ 1/3
    assert _segment_share(c) == pytest.approx(1 / 3, abs=1e-3)
    r, e, share = _edge_pulse(range_m, c, k=127)
    assert share == pytest.approx(1 / 3, abs=0.03)
    assert _detected(r, e, min_echo_reflectance=0.12) == 1
    assert _detected(r, e, min_echo_reflectance=0.22) == 0
    # an absolute threshold in m⁻² tells the two ranges apart: the one at 5 m is kept, the other lost
    tau = 0.5 / 3 / 100.0**2
    assert _detected(r, e, detection_threshold=tau) == (1 if range_m < 100 else 0)


@pytest.mark.parametrize("c", [0.0, 0.5, -0.4])
def test_the_apparent_reflectance_of_an_edge_converges_with_k_to_the_covered_area(c):
    """ρ · share from the sub-rays tends to ρ times the segment's area as K grows: the rule does not drift with K."""
    errors = []
    for k in (7, 19, 61, 271, 1024):
        r, e, _ = _edge_pulse(12.0, c, k)
        apparent = float(np.sum(e * r**2))
        errors.append(abs(apparent - 0.5 * _segment_share(c)))
    assert errors[-1] < 0.005
    assert max(errors[2:]) < 0.04  # K ≥ 61 within 4 points of reflectance
    # a threshold below the covered area's, with a margin: every K from 19 on detects the echo
    margin = 0.5 * _segment_share(c) - 0.05
    for k in (19, 61, 271, 1024):
        r, e, _ = _edge_pulse(12.0, c, k)
        assert _detected(r, e, min_echo_reflectance=margin) == 1


hits = st.lists(
    st.tuples(st.integers(0, 3), st.floats(0.5, 50.0), st.floats(1e-6, 1.0), st.integers(0, 2)),
    min_size=1,
    max_size=40,
)


def _columns(rows):
    p, r, w, s = (np.array(c) for c in zip(*rows))
    return p.astype(np.int64), r.astype(float), w.astype(float), s.astype(np.int64)


@settings(max_examples=40, deadline=None)
@given(rows=hits, scale=st.sampled_from([0.25, 3.0, 40.0]), tau=st.floats(0.0, 1.0))
def test_scaling_the_scene_about_the_sensor_detects_the_same_echoes(rows, scale, tau):
    """Ranges × c and energies / c² (the same surfaces c times farther): the same echoes, numbered alike."""
    p, r, w, s = _columns(rows)
    e = hit_energy(w, 1.0, 1.0, r)
    kw = {"detection_threshold": 0.0, "max_returns": MAX_RETURNS, "min_echo_reflectance": tau}
    a = resolve_echoes(p, r, e, s, range_resolution_m=0.75, **kw)
    b = resolve_echoes(p, r * scale, hit_energy(w, 1.0, 1.0, r * scale), s, range_resolution_m=0.75 * scale, **kw)
    # away from the threshold itself (rounding may fall either side of it, in either scene)
    apparent = np.concatenate([a.energy * a.range_m**2, b.energy * b.range_m**2])
    if np.any(np.isclose(apparent, tau, rtol=1e-9)):
        return
    np.testing.assert_array_equal(a.pulse, b.pulse)
    np.testing.assert_array_equal(a.return_number, b.return_number)
    np.testing.assert_allclose(a.range_m * scale, b.range_m, rtol=1e-9)


@settings(max_examples=40, deadline=None)
@given(rows=hits, low=st.floats(0.0, 1.0), high=st.floats(0.0, 1.0))
def test_a_higher_threshold_keeps_a_subset_of_the_echoes(rows, low, high):
    low, high = sorted((low, high))
    p, r, w, s = _columns(rows)
    e = hit_energy(w, 1.0, 1.0, r)
    kw = {"range_resolution_m": 0.75, "detection_threshold": 0.0, "max_returns": MAX_RETURNS}
    a = resolve_echoes(p, r, e, s, min_echo_reflectance=low, **kw)
    b = resolve_echoes(p, r, e, s, min_echo_reflectance=high, **kw)
    kept = set(zip(a.pulse.tolist(), a.range_m.tolist()))
    assert set(zip(b.pulse.tolist(), b.range_m.tolist())) <= kept
    assert np.all(b.energy * b.range_m**2 >= high)


@pytest.mark.parametrize("value", [-0.1, 1.5, float("nan"), True, "0.3"])
def test_the_threshold_is_checked_by_name(value):
    with pytest.raises(InvalidInputError, match="min_echo_reflectance"):
        Beam(min_echo_reflectance=value)
    with pytest.raises(InvalidInputError, match="min_echo_reflectance"):
        resolve_echoes([0], [1.0], [1.0], [0], range_resolution_m=0.5, detection_threshold=0.0, max_returns=1,
                       min_echo_reflectance=value)  # fmt: skip


# -- in a scan ------------------------------------------------------------------------------------


def _tilted_floor() -> BuiltScene:
    """A large floor z = −2 around the sensor (object 1)."""
    v = np.array([[-50, -50, -2], [50, -50, -2], [50, 50, -2], [-50, 50, -2]], dtype=float)
    floor = trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)
    return BuiltScene(floor, np.array([1, 1], np.int32), np.array([0, 1]), [SceneObject(floor)], [np.eye(4)] * 2, [None, floor])


def _rings(beam: Beam) -> S.Lidar:
    return S.Lidar("rings", tuple(float(e) for e in range(-80, -1, 3)), rotation_hz=10.0, firing_rate_hz=3600.0, beam=beam)


def test_one_ray_per_pulse_loses_the_hits_at_grazing_incidence_below_the_threshold():
    """One ray, ρ = 1: the apparent reflectance is |cos θ|, so 0.5 keeps the floor within 60° of its normal."""
    beam = IDEAL_BEAM.with_(max_range_m=1000.0)
    every = S.scan(_tilted_floor(), _rings(beam), np.zeros(3))
    kept = S.scan(_tilted_floor(), _rings(beam.with_(min_echo_reflectance=0.5)), np.zeros(3))
    steep = every.incidence_deg <= 60.0
    assert 0 < steep.sum() < len(every)
    np.testing.assert_array_equal(kept.points, every.points[steep])
    # the default 0: the same bytes as the idealised scan
    again = S.scan(_tilted_floor(), _rings(beam.with_(min_echo_reflectance=0.0)), np.zeros(3))
    np.testing.assert_array_equal(again.points, every.points)


def _pole_before_wall() -> BuiltScene:
    """A thin vertical plate (the pole, object 1) 10 m away over 0 ≤ y ≤ 0.3, a wall (object 2) at 30 m behind."""

    def plate(x, y0, y1):
        v = np.array([[x, y0, -5], [x, y1, -5], [x, y1, 5], [x, y0, 5]], dtype=float)
        return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)

    pole, wall = plate(10.0, 0.0, 0.3), plate(30.0, -20.0, 20.0)
    return BuiltScene(trimesh.util.concatenate([pole, wall]), np.array([1, 1, 2, 2], np.int32), np.array([0, 1, 0, 1]),
                      [SceneObject(pole), SceneObject(wall)], [np.eye(4)] * 3, [None, pole, wall])  # fmt: skip


@pytest.mark.parametrize(
    "returns",
    [{"max_returns": 2, "range_resolution_m": 0.75}, {"return_mode": "strongest", "range_resolution_m": 0.75}, {}],
    ids=["two-returns", "strongest", "one-return-strongest-surface"],
)
def test_the_threshold_removes_the_footprints_edge_points_from_a_pole_and_keeps_its_core(returns):
    """Pulses whose footprint only grazes the pole's edge give it a return without the threshold, none with it."""
    beam = Beam(max_range_m=1000.0, divergence_deg=1.0, footprint_rays=19, **returns)
    lidar = S.Lidar("row", (0.0,), rotation_hz=10.0, firing_rate_hz=36_000.0, beam=beam)  # 0.1° a step: the footprint is 10 wide
    window = (-1.0, 3.0)
    every = S.scan(_pole_before_wall(), lidar, np.zeros(3), azimuth_range_deg=window)
    strict = S.scan(_pole_before_wall(), S.Lidar("row", (0.0,), rotation_hz=10.0, firing_rate_hz=36_000.0,
                                                 beam=beam.with_(min_echo_reflectance=0.5)), np.zeros(3), azimuth_range_deg=window)  # fmt: skip
    on_pole = lambda s: s.points[s.object_id == 1]  # noqa: E731
    centre_on = lambda s: (s.points[:, 1] >= 0) & (s.points[:, 1] <= 0.3 * s.points[:, 0] / 10.0)  # noqa: E731
    n_every, n_strict = len(on_pole(every)), len(on_pole(strict))
    # the pole spans 0.3 m / 10 m = 1.72° of azimuth: ~17 pulses' centres; the footprint adds ~0.5° each side
    assert n_strict < n_every
    assert np.all(centre_on(strict)[strict.object_id == 1] | (np.abs(strict.points[strict.object_id == 1, 1]) < 0.05))
    assert n_every - n_strict >= 6  # about half the footprint's width at each edge


def test_power_noise_moves_the_one_ray_threshold_as_it_moves_the_absolute_one():
    """One ray with reflectivities and power noise: the threshold acts on the noisy apparent reflectance E · R²."""
    beam = IDEAL_BEAM.with_(max_range_m=1000.0, min_echo_reflectance=0.5, power_noise=0.5)
    quiet = S.scan(_tilted_floor(), _rings(beam.with_(power_noise=0.0)), np.zeros(3), reflectivity=1.0)
    noisy = S.scan(_tilted_floor(), _rings(beam), np.zeros(3), reflectivity=1.0)
    every = S.scan(_tilted_floor(), _rings(beam.with_(min_echo_reflectance=0.0)), np.zeros(3), reflectivity=1.0)
    # the quiet threshold keeps exactly the hits within 60° of the normal; with noise some beyond are kept, some within lost
    np.testing.assert_array_equal(quiet.points, every.points[every.incidence_deg <= 60.0])
    kept_steep, kept_grazing = np.sum(noisy.incidence_deg <= 60.0), np.sum(noisy.incidence_deg > 60.0)
    assert kept_grazing > 0 and kept_steep < np.sum(every.incidence_deg <= 60.0)
    # the apparent reflectance it kept: its intensity (E) × R² at or above the threshold, to float32
    np.testing.assert_array_less(0.5 * (1 - 1e-6), noisy.intensity.astype(float) * noisy.range_m.astype(float) ** 2 * (1 + 1e-3))
