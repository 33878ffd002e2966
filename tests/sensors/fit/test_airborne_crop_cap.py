"""The airborne fit (sensors/fit/airborne.py) on crops of millions of points: measured on a capped, seeded subsample."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from zbuf_occlude.sensors.patterns.airborne import AIRBORNE_IDEAL_BEAM, AirborneScanner
from zbuf_occlude.sensors.scan import scan_airborne
from zbuf_occlude.sensors.fit import airborne


def _scanner(name: str, density_m2: float, altitude_m: float, swath_deg: float, noise_m: float) -> AirborneScanner:
    """A single-line scanner of the given flat-ground density, its lines as far apart as its pulses (a square pattern)."""
    speed = 60.0
    width = 2.0 * altitude_m * math.tan(math.radians(swath_deg / 2.0))
    prr = density_m2 * speed * width
    line_rate = math.sqrt(prr * speed / (altitude_m * math.radians(swath_deg)))
    return AirborneScanner(name, swath_deg=swath_deg, pulse_rate_hz=prr, line_rate_hz=line_rate, altitude_m=altitude_m,
                           speed_mps=speed, beam=AIRBORNE_IDEAL_BEAM.with_(range_noise_m=noise_m))  # fmt: skip


def _dense_box_crop(y_m: float = 200.0, seed: int = 1) -> np.ndarray:
    """A car-sized box 200 m across track of a 600 points/m² scanner (~7,000 points): a scan angle of atan(200 / 500)."""
    scanner = _scanner("dense", 600.0, 500.0, 60.0, 0.005)
    box = trimesh.creation.box(extents=[4.5, 2.0, 1.5])
    box.apply_transform(trimesh.transformations.rotation_matrix(0.4, [0, 0, 1]))
    box.apply_translation([0.0, y_m, 0.75])
    return np.asarray(scan_airborne(box, scanner, center_xy=(0.0, y_m), half_size_m=4.0, seed=seed).points, dtype=np.float64)


class _Stop(Exception):
    """Raised by the spy once it has seen what it came for: the rest of the fit need not run."""


def _spy_local_planes(monkeypatch, sizes: list[int], stop: bool = False) -> None:
    real = airborne._local_planes

    def spy(points):
        sizes.append(len(points))
        if stop:
            raise _Stop
        return real(points)

    monkeypatch.setattr(airborne, "_local_planes", spy)


def test_a_crop_above_the_cap_is_measured_on_a_subsample_of_the_cap_with_the_same_figures(monkeypatch) -> None:
    crop = _dense_box_crop()
    cap = 2000
    assert len(crop) > 3 * cap
    full = airborne.crop_faces(crop, max_points=len(crop))
    sizes: list[int] = []
    _spy_local_planes(monkeypatch, sizes)
    capped = airborne.crop_faces(crop, max_points=cap)
    assert sizes and max(sizes) <= cap  # the (n, k, 3) neighbourhoods are built for the subsample only
    # the same kind of result: the densities scaled back to the whole crop, the angle and the noise as on all points
    assert capped.n_points == full.n_points == len(crop)
    assert capped.footprint_m2 == pytest.approx(full.footprint_m2, rel=1e-12)  # the hull of every point
    assert capped.top_density_m2 == pytest.approx(full.top_density_m2, rel=0.05)
    assert np.isfinite(full.incidence_deg) and abs(capped.incidence_deg - full.incidence_deg) <= 2.0
    assert abs(capped.incidence_deg - math.degrees(math.atan2(200.0, 500.0))) <= 3.0
    assert math.sqrt(capped.plane_variance_m2) == pytest.approx(math.sqrt(full.plane_variance_m2), rel=0.2)
    # seeded: the same seed gives the same figures, bit for bit
    again = airborne.crop_faces(crop, max_points=cap)
    assert again.top_density_m2 == capped.top_density_m2 and again.incidence_deg == capped.incidence_deg
    other = airborne.crop_faces(crop, max_points=cap, seed=1)
    assert other.top_density_m2 != capped.top_density_m2


def test_a_crop_at_or_below_the_cap_is_measured_on_every_point(monkeypatch) -> None:
    crop = _dense_box_crop()
    sizes: list[int] = []
    _spy_local_planes(monkeypatch, sizes, stop=True)
    with pytest.raises(_Stop):
        airborne.crop_faces(crop, max_points=len(crop))
    assert sizes == [len(crop)]


def test_the_fit_of_crops_of_millions_of_points_works_on_at_most_the_default_cap(monkeypatch) -> None:
    # what fit-sensor --sensor dales-q1560 does with a crop of 5e6 points: no neighbourhoods for all of them
    n = airborne.MAX_CROP_POINTS + 50_000
    rng = np.random.default_rng(0)
    slab = np.column_stack([rng.uniform(0.0, 40.0, n), rng.uniform(0.0, 40.0, n), rng.normal(0.0, 0.02, n)])
    sizes: list[int] = []
    _spy_local_planes(monkeypatch, sizes, stop=True)
    with pytest.raises(_Stop):
        airborne.fit_airborne([slab, slab], _scanner("base", 20.0, 500.0, 60.0, 0.02), bootstrap=2)
    assert sizes == [airborne.MAX_CROP_POINTS]
