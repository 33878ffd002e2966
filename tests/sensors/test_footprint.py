"""A beam's footprint sampled by sub-rays: equal-area cells, weights, and today's 7-ray layout kept bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.beam.footprint import (
    MAX_SUBRAYS,
    footprint_offsets,
    subray_directions,
)
from zbuf_occlude.sensors.patterns.spinning import Lidar

COUNTS = [1, 2, 3, 5, 7, 8, 12, 13, 14, 19, 20, 37, 50, 61, 100, 257]


def _directions() -> np.ndarray:
    """Beams of a spinning LiDAR over every azimuth, near the poles too (both local-frame helpers)."""
    lidar = Lidar(
        "t",
        (-89.5, -60.0, -10.0, 0.0, 7.5, 64.0, 89.5),
        rotation_hz=10.0,
        firing_rate_hz=3600.0,
    )
    return lidar.rays()[0]


@pytest.mark.parametrize("divergence", [0.172, 0.3, 3.0, 45.0])
def test_seven_subrays_are_lidar_footprint_directions_bit_for_bit(
    divergence: float,
) -> None:
    d = _directions()
    lidar = Lidar("t", (0.0,), beam=Beam(footprint_rays=7, divergence_deg=divergence))
    offsets, weights = footprint_offsets(7, divergence)
    assert np.array_equal(subray_directions(d, offsets), lidar.beam.footprint_directions(d))
    assert np.array_equal(weights, np.full(7, 1 / 7))
    assert np.array_equal(lidar.beam.footprint_weights(), weights)


def test_one_subray_is_the_beam_itself() -> None:
    d = _directions()
    offsets, weights = footprint_offsets(1, 0.3)
    assert np.array_equal(offsets, [[0.0, 0.0]]) and np.array_equal(weights, [1.0])
    assert np.array_equal(subray_directions(d, offsets), Lidar("t", (0.0,)).beam.footprint_directions(d))
    assert np.array_equal(Lidar("t", (0.0,)).beam.footprint_weights(), [1.0])
    assert np.array_equal(subray_directions(d, offsets)[:, 0], d)


@pytest.mark.parametrize("k", COUNTS)
@pytest.mark.parametrize("profile", ["tophat", "gaussian"])
def test_weights_sum_to_one_and_subrays_lie_inside_the_cone(k: int, profile: str) -> None:
    divergence = 2.0
    offsets, weights = footprint_offsets(k, divergence, profile=profile)
    assert offsets.shape == (k, 2) and weights.shape == (k,) and offsets.dtype == weights.dtype == np.float64
    assert weights.sum() == pytest.approx(1.0, abs=1e-12) and np.all(weights > 0)
    d = _directions()
    rays = subray_directions(d, offsets)
    assert rays.shape == (len(d), k, 3)
    assert np.allclose(np.linalg.norm(rays, axis=2), 1.0, atol=1e-12)
    angle = np.arccos(np.clip(np.einsum("nkj,nj->nk", rays, d), -1.0, 1.0))
    assert angle.max() < math.radians(divergence) / 2
    # each sub-ray sits at its offset: angle off the axis as given (to arccos's rounding near 0)
    assert np.allclose(angle, offsets[None, :, 0], atol=1e-7)
    assert len(np.unique(np.round(rays[0], 12), axis=0)) == k  # no two sub-rays coincide


@pytest.mark.parametrize("k", COUNTS)
def test_tophat_cells_have_equal_areas(k: int) -> None:
    """Each ring's rays sit at the mean-area radius of an annulus holding exactly their cells
    (cells of area 1/K each), and a uniform disc splits about evenly among the nearest sub-rays."""
    half = math.radians(3.0) / 2
    offsets, weights = footprint_offsets(k, 3.0)
    assert np.allclose(weights, 1.0 / k, rtol=0, atol=1e-15)
    radius = offsets[:, 0] / half
    assert radius[0] == 0.0 and np.all(radius[1:] > 0) and np.all(np.diff(radius) >= 0)  # centre, then rings outward
    rings, n_per_ring = np.unique(np.round(radius[1:], 12), return_counts=True)
    inside = 1 + np.concatenate([[0], np.cumsum(n_per_ring)])  # cells within each ring's edges
    assert inside[-1] == k
    assert np.allclose(rings**2, (inside[:-1] + inside[1:]) / (2 * k), rtol=1e-12)
    # Monte Carlo: the Voronoi cells of the sub-rays in the (tangent) footprint disc
    rng = np.random.default_rng(0)
    p = rng.uniform(-1, 1, (60_000, 2))
    p = p[np.hypot(*p.T) <= 1.0]
    sub = np.column_stack([radius * np.cos(offsets[:, 1]), radius * np.sin(offsets[:, 1])])
    nearest = np.argmin(((p[:, None, :] - sub[None, :, :]) ** 2).sum(axis=2), axis=1)
    share = np.bincount(nearest, minlength=k) / len(p)
    if k >= 4:  # a centre ray and 1 or 2 more cannot split a disc evenly among nearest rays
        assert np.all(np.abs(share * k - 1) < 0.35), share * k


@pytest.mark.parametrize("k", [7, 19, 37, 100])
def test_gaussian_weights_are_the_beam_energy_in_each_cell(k: int) -> None:
    """A TEM00 beam whose 1/e² radius is the half-divergence, sampled by Monte Carlo and cut at the cone."""
    half = math.radians(1.0) / 2
    offsets, weights = footprint_offsets(k, 1.0, profile="gaussian")
    rng = np.random.default_rng(1)
    rho = np.hypot(*rng.normal(0.0, 0.5, (2, 400_000)))  # exp(-2ρ²): σ = 1/2 in half-divergences
    rho = rho[rho <= 1.0]
    radius = offsets[:, 0] / half
    # the centre cell (radius sqrt(1/K)) and ring by ring: energy between cell edges
    assert weights[0] == pytest.approx(np.mean(rho**2 <= 1.0 / k), abs=0.005)
    assert np.all(np.diff(weights[np.argsort(radius, kind="stable")]) <= 1e-15)  # outward, never heavier
    tophat = footprint_offsets(k, 1.0)[0]
    assert np.array_equal(offsets, tophat)  # the same cells; only the weights change


def test_bad_arguments_are_refused_naming_them() -> None:
    with pytest.raises(InvalidInputError, match="n_subrays"):
        footprint_offsets(0, 1.0)
    with pytest.raises(InvalidInputError, match="n_subrays"):
        footprint_offsets(MAX_SUBRAYS + 1, 1.0)
    with pytest.raises(InvalidInputError, match="n_subrays"):
        footprint_offsets(True, 1.0)
    with pytest.raises(InvalidInputError, match="divergence_deg"):
        footprint_offsets(7, float("nan"))
    with pytest.raises(InvalidInputError, match="divergence_deg > 0"):
        footprint_offsets(7, 0.0)
    with pytest.raises(InvalidInputError, match="profile"):
        footprint_offsets(7, 1.0, profile="flat")
    assert np.array_equal(footprint_offsets(1, 0.0)[0], [[0.0, 0.0]])  # one ray needs no cone
    with pytest.raises(InvalidInputError, match="directions"):
        subray_directions(np.zeros((4, 2)), footprint_offsets(7, 1.0)[0])
    with pytest.raises(InvalidInputError, match="offsets"):
        subray_directions(np.eye(3), np.zeros((0, 2)))
    with pytest.raises(InvalidInputError, match="directions"):
        subray_directions("beams.npy", footprint_offsets(7, 1.0)[0])
    assert subray_directions(np.zeros((0, 3)), footprint_offsets(7, 1.0)[0]).shape == (
        0,
        7,
        3,
    )
