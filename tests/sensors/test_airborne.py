"""Airborne laser scanner: flat-ground point density against the analytic formula, crops, presets."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors import AirborneScanner, airborne_preset, scan_airborne
from zbuf_occlude.sensors.crops import lidar_object_samples
from zbuf_occlude.sensors.placement import CropDistributions
from zbuf_occlude.sensors.kinds import sensor_from_name

#: Relative tolerance of simulated vs analytic density (the lines' phase moves a few points in or out of a square).
DENSITY_RTOL = 0.03


def _plane(half: float = 3000.0) -> trimesh.Trimesh:
    v = [[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]]
    return trimesh.Trimesh(vertices=v, faces=[[0, 1, 2], [0, 2, 3]], process=False)


@pytest.mark.parametrize("pattern", ["linear", "oscillating"])
@pytest.mark.parametrize("across_m", [0.0, 250.0, 650.0])
def test_local_density_on_flat_ground_matches_the_formula(pattern: str, across_m: float) -> None:
    scanner = airborne_preset("riegl-q1560", pattern=pattern)
    half = 15.0
    s = scan_airborne(_plane(), scanner, (40.0, across_m), half, seed=3)
    inside = (np.abs(s.points[:, 0] - 40.0) <= half) & (np.abs(s.points[:, 1] - across_m) <= half)
    density = inside.sum() / (2 * half) ** 2
    # the formula's ρ(θ) averaged over the square's across-track span (it varies as cos²θ)
    ys = np.linspace(across_m - half, across_m + half, 201)
    expected = np.mean([scanner.density_at_m2(y) for y in ys])
    assert density == pytest.approx(expected, rel=DENSITY_RTOL)
    np.testing.assert_allclose(s.points[:, 2], 0.0, atol=0.2)  # on the ground, 2 cm noise


def test_mean_density_over_the_whole_swath() -> None:
    scanner = AirborneScanner("test", swath_deg=40.0, pulse_rate_hz=100_000.0, line_rate_hz=50.0, altitude_m=500.0, speed_mps=60.0)
    s = scan_airborne(_plane(), scanner, (0.0, 0.0), scanner.swath_width_m / 2 + 1.0, seed=0)
    strip = np.abs(s.points[:, 0]) <= scanner.swath_width_m / 2
    density = strip.sum() / (scanner.swath_width_m * scanner.swath_width_m)
    assert density == pytest.approx(scanner.density_m2, rel=DENSITY_RTOL)
    assert np.abs(s.points[:, 1]).max() <= scanner.swath_width_m / 2 + 0.5  # nothing beyond the swath


def test_preset_numbers() -> None:
    q = airborne_preset("riegl-q1560")
    assert q.altitude_m == 1300.0 and q.swath_deg == 58.0
    assert q.swath_width_m == pytest.approx(2 * 1300 * np.tan(np.radians(29.0)))
    assert q.density_m2 == pytest.approx(800_000 / (72 * q.swath_width_m))
    assert sensor_from_name("riegl-q1560") is airborne_preset("riegl-q1560") or sensor_from_name("RIEGL-Q1560") == q


def test_a_car_seen_from_the_air_is_mostly_its_roof() -> None:
    from zbuf_occlude.mesh.load import normalize_mesh

    clouds = lidar_object_samples(normalize_mesh(trimesh.creation.box(extents=(1.0, 1.0, 1.0))), airborne_preset("riegl-q1560"), name="car", n_samples=4, n_points=64,
                                  distributions=CropDistributions(size_m=4.5, distance_m=(1.0, 300.0)))  # fmt: skip
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))  # the primitive "box" normalised
    assert clouds, "no crop returned"
    for c in clouds:
        assert c.n_visible >= 20  # ~7.7 points/m² on a 4.5 m box top (20 m²)
        assert c.elevation_deg > 60  # the scanner is far above
        top = c.points[:, 2] > box.bounds[1, 2] - 0.05
        assert top.mean() > 0.5


def test_bad_airborne_settings_and_json(tmp_path: Path) -> None:
    for bad in (dict(swath_deg=0.0), dict(swath_deg=200.0), dict(speed_mps=-1.0), dict(pattern="spiral"),
                dict(pulse_rate_hz=10.0, line_rate_hz=100.0)):  # fmt: skip
        with pytest.raises(InvalidInputError):
            airborne_preset("riegl-q1560", **bad)
    spec = tmp_path / "als.json"
    spec.write_text(json.dumps({"kind": "airborne", "name": "als", "swath_deg": 40, "pulse_rate_hz": 1e5, "line_rate_hz": 50,
                                "altitude_m": 800, "speed_mps": 60}))  # fmt: skip
    assert isinstance(sensor_from_name(str(spec)), AirborneScanner)
    with pytest.raises(InvalidInputError, match="unknown airborne"):
        airborne_preset("nope")
