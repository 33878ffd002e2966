"""Return physics of a LiDAR: radiometric detection (Lambertian range equation), footprint.

Laws checked on analytic scenes: a wall (plane x = D) where each firing's range and incidence
are known in closed form, and a thin pole seen with and without the beam footprint.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy.stats import norm

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors import Lidar, SceneObject, scan
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.scene.objects import BuiltScene

D = 10.0  # wall distance, metres


def _wall(d: float = D, half: float = 200.0) -> trimesh.Trimesh:
    v = np.array([[d, -half, -half], [d, half, -half], [d, half, half], [d, -half, half]], dtype=np.float64)
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


#: τ = ρ / R² of a receiver that detects ρ = 0.8 at 27 m, m⁻².
TAU = 0.8 / 27.0**2


def _beam(**changes) -> Beam:
    return Beam(**({"min_range_m": 0.1, "max_range_m": 10_000.0, "detection_threshold": TAU} | changes))


def _lidar(elevations_deg=tuple(np.linspace(-40.0, 40.0, 9)), firing_rate_hz: float = 3600.0, **beam_changes) -> Lidar:
    # 1° azimuth steps, 9 rings from -40° to +40°: incidences 0–85° on the wall
    return Lidar("test", elevations_deg, rotation_hz=10.0, firing_rate_hz=firing_rate_hz, beam=_beam(**beam_changes))


def _firings(lidar: Lidar, sector=(-85.0, 85.0)):
    d, ring, az = lidar.rays(sector)
    cos = d[:, 0]  # cos θ on the wall = cos e cos a; range D / cos θ
    return ring, az, cos


def _firing_keys(ring, azimuth_deg) -> set[tuple[int, int]]:
    """(ring, azimuth in 1/100°, wrapped to [0, 360)) of each firing or return."""
    a = np.round(np.mod(np.asarray(azimuth_deg, dtype=np.float64), 360.0) * 100).astype(np.int64) % 36000
    return set(zip(np.asarray(ring).tolist(), a.tolist()))


def _return_azimuths(s) -> np.ndarray:
    return np.degrees(np.arctan2(s.points[:, 1].astype(np.float64), s.points[:, 0]))


@pytest.mark.parametrize("rho", [0.2, 0.5, 0.9])
def test_sharp_threshold_keeps_exactly_the_firings_the_range_equation_allows(rho):
    lidar = _lidar()
    s = scan(_wall(), lidar, np.zeros(3), reflectivity=rho, azimuth_range_deg=(-85.0, 85.0))
    ring, az, cos = _firings(lidar)
    power = rho * cos / (D / cos) ** 2  # ρ cos θ / R², R = D / cos θ
    assert np.all(np.abs(power / lidar.beam.detection_threshold - 1.0) > 1e-6)  # no firing on the edge
    keep = power >= lidar.beam.detection_threshold
    assert _firing_keys(s.ring, _return_azimuths(s)) == _firing_keys(ring[keep], az[keep])
    assert 0 < keep.sum() < len(ring)  # the threshold cuts inside the scene
    # equivalently: kept iff cos θ ≥ (τ D² / ρ)^(1/3), since ρ cos³θ / D² = τ on the wall
    cut = (lidar.beam.detection_threshold * D**2 / rho) ** (1 / 3)
    assert np.all(np.cos(np.radians(s.incidence_deg)) >= cut - 1e-5)
    assert len(s) == int(np.sum(cos >= cut))


def test_without_reflectivity_every_hit_returns():
    lidar = _lidar()
    s = scan(_wall(), lidar, np.zeros(3), azimuth_range_deg=(-85.0, 85.0))
    assert len(s) == len(_firings(lidar)[0])


def test_power_noise_gives_the_lognormal_return_probability():
    # P(return) = Φ(ln(ρ cos θ / (τ R²)) / σ), over many firings binned by predicted probability
    sigma, rho = 0.5, 0.5
    lidar = _lidar(firing_rate_hz=36_000.0, power_noise=sigma)  # 0.1° steps: 15,300 firings
    ring, az, cos = _firings(lidar)
    p = norm.cdf(np.log(rho * cos / (D / cos) ** 2 / lidar.beam.detection_threshold) / sigma)
    index = {k: i for i, k in enumerate(sorted(_firing_keys(ring, az)))}
    order = np.array([index[k] for k in zip(ring.tolist(), (np.round(np.mod(az, 360.0) * 100).astype(np.int64) % 36000).tolist())])
    p = p[np.argsort(order)]  # p in the order of the sorted firing keys
    returned = np.zeros(len(ring), dtype=bool)
    for seed in range(4):
        s = scan(_wall(), lidar, np.zeros(3), reflectivity=rho, azimuth_range_deg=(-85.0, 85.0), seed=seed)
        hits = [index[k] for k in _firing_keys(s.ring, _return_azimuths(s))]
        mask = np.zeros(len(ring), dtype=bool)
        mask[hits] = True
        for lo in np.arange(0.05, 0.95, 0.1):
            sel = (p >= lo) & (p < lo + 0.1)
            if sel.sum() < 200:
                continue
            expected, n = p[sel].mean(), sel.sum()
            assert abs(mask[sel].mean() - expected) < 4.5 * math.sqrt(expected * (1 - expected) / n) + 1e-3, (lo, n)
        returned |= mask
    assert 0.1 < returned.mean() < 1.0


def test_footprint_rays_lie_on_the_divergence_cone_equal_area_radius():
    lidar = _lidar(divergence_deg=0.3, footprint_rays=7)
    d, _, _ = lidar.rays()
    rays = lidar.beam.footprint_directions(d)
    assert rays.shape == (len(d), 7, 3)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=2), 1.0, atol=1e-12)
    angle = np.degrees(np.arccos(np.clip(np.einsum("nkj,nj->nk", rays, d), -1, 1)))
    np.testing.assert_allclose(angle[:, 0], 0.0, atol=1e-5)
    np.testing.assert_allclose(angle[:, 1:], 0.15 * math.sqrt(4 / 7), rtol=1e-6)


def test_footprint_widens_a_thin_pole_by_the_footprint_radius():
    # a pole of radius r at distance d returns on azimuths within asin(r/d) of its centre with
    # the centre ray only, and within asin(r/d) + the footprint rays' offset with 7 rays
    r, d, div = 0.05, 20.0, 0.5
    pole = trimesh.creation.cylinder(radius=r, height=40.0, sections=256)
    pole.apply_translation([d, 0.0, 0.0])
    lidar = _lidar(firing_rate_hz=72_000.0, divergence_deg=div)  # 0.05° steps
    centre = scan(pole, lidar, np.zeros(3), azimuth_range_deg=(-3.0, 3.0))
    wide = scan(pole, with_beam(lidar, footprint_rays=7), np.zeros(3), azimuth_range_deg=(-3.0, 3.0))
    half = lambda s: np.degrees(np.abs(np.arctan2(s.points[:, 1], s.points[:, 0]))).max()  # noqa: E731
    step = lidar.azimuth_step_deg
    assert abs(half(centre) - math.degrees(math.asin(r / d))) <= step + 1e-6
    assert abs(half(wide) - (math.degrees(math.asin(r / d)) + div / 2 * math.sqrt(4 / 7))) <= step + 1e-6
    assert len(wide) > 2 * len(centre)
    # points still lie along their firing's centre direction: rings keep their elevations
    el = np.degrees(np.arctan2(wide.points[:, 2], np.hypot(wide.points[:, 0], wide.points[:, 1])))
    np.testing.assert_allclose(el, np.asarray(lidar.elevations_deg)[wide.ring], atol=1e-3)
    # a partly covered footprint receives its fraction of the energy: with τ = 0.25 / d², firings
    # whose footprint puts only one or two of its 7 rays on the pole (energy ≤ 2/7 · ρ / d²)
    # drop, those centred on it (5 of 7 rays: 0.066 m ray offset, 0.05 m radius) stay
    full = scan(pole, with_beam(lidar, footprint_rays=7, detection_threshold=0.8 / 1e4**2), np.zeros(3), azimuth_range_deg=(-3.0, 3.0),
                reflectivity=1.0)  # fmt: skip
    tau = with_beam(lidar, footprint_rays=7, detection_threshold=1.0 / (2.0 * d) ** 2)
    edge = scan(pole, tau, np.zeros(3), azimuth_range_deg=(-3.0, 3.0), reflectivity=1.0)
    assert len(full) == len(wide) and 0 < len(edge) < len(full)
    assert half(edge) < half(full) - step


def test_strongest_echo_picks_the_surface_with_more_energy():
    # a near wall (x = 5 m, object 1) covering azimuths < 0 in front of a far wall (x = 10 m,
    # object 2); 2° divergence: the 6 outer rays sit 0.756° from the centre, at horizontal
    # offsets ±0.756°, ±0.378°, ±0.378°.  Energy per ray ∝ 1/R²: at azimuth 0.1° three rays
    # hit the near wall (3/25 > 4/100): near wins; at 0.5° one ray does (1/25 < 6/100): far wins
    near = _wall(5.0)
    near.vertices[:, 1] = np.clip(near.vertices[:, 1], -200.0, 0.0)
    far = _wall(10.0)
    mesh = trimesh.util.concatenate([near, far])
    built = BuiltScene(mesh, np.array([1, 1, 2, 2], np.int32), np.array([0, 1, 0, 1]), [SceneObject(near), SceneObject(far)],
                       [np.eye(4)] * 3, [None, near, far])  # fmt: skip
    lidar = _lidar(elevations_deg=(0.0,), firing_rate_hz=36_000.0, divergence_deg=2.0, footprint_rays=7)
    s = scan(built, lidar, np.zeros(3), azimuth_range_deg=(-1.0, 1.0))
    az = _return_azimuths(s)
    at = lambda a: int(np.argmin(np.abs(az - a)))  # noqa: E731
    assert abs(az[at(0.1)] - 0.1) < 1e-3 and abs(az[at(0.5)] - 0.5) < 1e-3
    assert abs(s.range_m[at(0.1)] - 5.0) < 0.01 and s.object_id[at(0.1)] == 1
    assert abs(s.range_m[at(0.5)] - 10.0) < 0.01 and s.object_id[at(0.5)] == 2
    # with the centre ray only, the centre decides: far wall at 0.1°
    centre = scan(built, with_beam(lidar, footprint_rays=1), np.zeros(3), azimuth_range_deg=(-1.0, 1.0))
    assert centre.object_id[int(np.argmin(np.abs(_return_azimuths(centre) - 0.1)))] == 2


def _two_walls(near_m: float, far_m: float) -> BuiltScene:
    """A near wall (x = near_m, object 1) over azimuths < 0 in front of a far wall (x = far_m, object 2)."""
    near = _wall(near_m)
    near.vertices[:, 1] = np.clip(near.vertices[:, 1], -200.0, 0.0)
    far = _wall(far_m)
    return BuiltScene(trimesh.util.concatenate([near, far]), np.array([1, 1, 2, 2], np.int32), np.array([0, 1, 0, 1]),
                      [SceneObject(near), SceneObject(far)], [np.eye(4)] * 3, [None, near, far])  # fmt: skip


def test_unresolved_echoes_merge_into_a_mixed_pixel_at_a_shallow_depth_edge():
    # walls 5.0 m and 5.5 m away, 2° divergence, echoes within 0.75 m unresolved.  At azimuth
    # 0.1° three rays of 7 (at 0.1° − 0.756°, 0.1° − 0.378° twice) hit the near wall: energies
    # 3/25 against 4/30.25, the
    # far wall is the strongest echo, and the near rays merge into it at the weighted range
    built = _two_walls(5.0, 5.5)
    lidar = _lidar(elevations_deg=(0.0,), firing_rate_hz=36_000.0, divergence_deg=2.0, footprint_rays=7)
    sharp = scan(built, lidar, np.zeros(3), azimuth_range_deg=(-2.0, 2.0))
    mixed = scan(built, with_beam(lidar, echo_separation_m=0.75), np.zeros(3), azimuth_range_deg=(-2.0, 2.0))
    az = _return_azimuths(mixed)
    np.testing.assert_allclose(az, _return_azimuths(sharp), atol=1e-5)  # the same firings return (0.1° apart)
    i = int(np.argmin(np.abs(az - 0.1)))
    expected = (5.0 * 3 / 25 + 5.5 * 4 / 30.25) / (3 / 25 + 4 / 30.25)
    assert mixed.range_m[i] == pytest.approx(expected, abs=3e-3) and mixed.object_id[i] == 2
    assert sharp.range_m[i] == pytest.approx(5.5, abs=3e-3)
    # mixed pixels lie strictly between the walls, only where the footprint straddles the edge
    straddle = np.abs(az) < 0.756 + 0.01
    between = (mixed.range_m > 5.0 + 0.01) & (mixed.range_m < 5.5 - 0.01)
    assert between.sum() >= 12 and not np.any(between & ~straddle)
    np.testing.assert_array_equal(mixed.range_m[~straddle], sharp.range_m[~straddle])


def test_echoes_further_apart_than_the_separation_stay_apart():
    built = _two_walls(5.0, 10.0)
    lidar = _lidar(elevations_deg=(0.0, 3.0), firing_rate_hz=36_000.0, divergence_deg=2.0, footprint_rays=7, range_noise_m=0.01)
    sharp = scan(built, lidar, np.zeros(3), azimuth_range_deg=(-2.0, 2.0), seed=4)
    mixed = scan(built, with_beam(lidar, echo_separation_m=0.75), np.zeros(3), azimuth_range_deg=(-2.0, 2.0), seed=4)
    for name in ("points", "range_m", "object_id", "face_index", "ring"):
        np.testing.assert_array_equal(getattr(mixed, name), getattr(sharp, name))


@pytest.mark.parametrize(
    "changes, words",
    [({"footprint_rays": 3}, "footprint_rays above 1 needs divergence_deg > 0"), ({"footprint_rays": 7, "divergence_deg": 0.0}, "divergence_deg"),
     ({"power_noise": -1.0}, "power_noise"), ({"detection_threshold": -1e-9}, "detection_threshold"),
     ({"detection_threshold": math.inf}, "detection_threshold"),
     ({"echo_separation_m": 0.75}, "echo_separation_m 0.75 needs footprint_rays above 1"), ({"echo_separation_m": -1.0}, "echo_separation_m")],
)  # fmt: skip
def test_bad_physics_parameters_are_clear_errors(changes, words):
    """The beam refuses them, naming itself and the field (the rules moved from Lidar to Beam)."""
    with pytest.raises(InvalidInputError, match="^beam: .*" + words):
        _lidar(**changes)


def test_bad_reflectivity_is_a_clear_error():
    with pytest.raises(InvalidInputError, match="reflectivity"):
        scan(_wall(), _lidar(), np.zeros(3), reflectivity=[0.1, 0.2, 0.3])


def test_pole_sizes_drawn_per_sample_with_a_round_cross_section():
    from zbuf_occlude.sensors.placement import CropDistributions, draw_placement

    dist = CropDistributions(extents_m=((0.1, 0.4), (0.1, 0.4), (3.0, 9.0)), round_xy=True, reflectivity=(0.1, 0.5))
    rng = np.random.default_rng(0)
    drawn = [draw_placement(dist, rng) for _ in range(200)]
    x, y, z = np.array([p.extents_m for p in drawn]).T
    assert np.array_equal(x, y) and 0.1 <= x.min() and x.max() <= 0.4 and 3.0 <= z.min() and z.max() <= 9.0
    assert np.ptp(x) > 0.25 and np.ptp(z) > 5.0  # really drawn, over the whole interval
    assert all(0.1 <= p.reflectivity <= 0.5 and p.size_m == max(p.extents_m) for p in drawn)
    # fixed extents draw nothing more: the generator stream (and older data sets) stay as they were
    a, b = np.random.default_rng(5), np.random.default_rng(5)
    draw_placement(CropDistributions(extents_m=(0.3, 0.3, 6.0)), a)
    draw_placement(CropDistributions(), b)
    assert a.integers(2**63) == b.integers(2**63)
