"""What a preset writes as intensity is what its device reports: a spinning or solid-state unit's calibrated
reflectivity (``Beam.intensity_unit`` "reflectivity", E · R²), independent of range; an airborne receiver's counts of
the received energy."""

from __future__ import annotations

import io

import laspy
import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors import sensor_from_name
from zbuf_occlude.sensors.beam.fields import Beam, device_quantity, intensity_counts
from zbuf_occlude.sensors.scan import scan
from zbuf_occlude.sensors.scan_data import read_scan_npz

#: Counts a diffuse surface of reflectance 1 met head-on reads, by preset (their manuals: Velodyne and Ouster 0–100,
#: Livox 0–150 for 0–100 %).
WHITE_COUNTS = {"hdl32e": 100, "vlp16": 100, "hdl64e": 100, "os1-64": 100, "livox-mid70": 150}
DISTANCES_M = (2.0, 5.0, 10.0, 20.0, 35.0, 50.0)


def _wall_intensities(name: str, rho: float) -> tuple[np.ndarray, np.ndarray]:
    """LAS intensities and ranges of a wall of reflectance ``rho`` facing the sensor at each of :data:`DISTANCES_M`,
    sized to the same angle at every distance (so that the incidence angles are the same)."""
    sensor = sensor_from_name(name)
    counts, ranges = [], []
    for d in DISTANCES_M:
        wall = trimesh.creation.box((0.05 * d, 0.4 * d, 0.4 * d))
        wall.apply_translation((d, 0.0, 0.0))
        sector = None if name == "livox-mid70" else (-15.0, 15.0)
        s = scan(wall, sensor, np.eye(4), seed=3, reflectivity=rho, azimuth_range_deg=sector)
        las = laspy.read(io.BytesIO(s.to_las_bytes()))
        counts.append(np.asarray(las.intensity, np.float64))
        ranges.append(np.asarray(s.range_m, np.float64))
    return np.concatenate(counts), np.concatenate(ranges)


@pytest.mark.parametrize("name", sorted(WHITE_COUNTS))
def test_a_diffuse_wall_reads_the_same_calibrated_reflectivity_at_2_to_50_m(name: str) -> None:
    counts, ranges = _wall_intensities(name, 0.5)
    assert len(counts) > 500 and ranges.min() < 2.5 and ranges.max() > 45.0
    assert abs(np.corrcoef(counts, ranges)[0, 1]) < 0.1
    assert np.mean(counts >= 255) < 0.01 and counts.min() > 0
    # ρ |cos θ| at 100 (150) counts a unit: half of white, a little less off the wall's normal
    assert 0.45 * WHITE_COUNTS[name] <= np.median(counts) <= 0.5 * WHITE_COUNTS[name] + 1


def test_the_reflectivity_follows_the_surface_not_the_range() -> None:
    dark, _ = _wall_intensities("hdl32e", 0.1)
    bright, _ = _wall_intensities("hdl32e", 0.9)
    assert 8 <= np.median(dark) <= 10 and 85 <= np.median(bright) <= 90


def test_the_airborne_presets_write_the_received_energy() -> None:
    for name in ("riegl-q1560", "dales-q1560"):
        assert sensor_from_name(name).beam.intensity_unit == "energy"
    for name in WHITE_COUNTS:
        beam = sensor_from_name(name).beam
        assert (beam.intensity_unit, beam.intensity_scale, beam.max_intensity) == ("reflectivity", WHITE_COUNTS[name], 255)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 1e-2), st.floats(0.5, 300.0)), min_size=1, max_size=20))
def test_a_reflectivity_is_the_energy_times_the_range_squared(rows: list[tuple[float, float]]) -> None:
    energy, range_m = (np.array(c) for c in zip(*rows))
    assert np.array_equal(device_quantity(energy, range_m, "energy"), energy)
    assert np.allclose(device_quantity(energy, range_m, "reflectivity"), energy * range_m**2, rtol=1e-12, atol=0.0)
    beam = Beam("b", intensity_scale=100.0, max_intensity=255, intensity_unit="reflectivity")
    assert np.array_equal(beam.intensity_counts(energy, range_m), intensity_counts(energy * range_m**2, 100.0, 255))


def test_a_bad_unit_or_a_reflectivity_without_ranges_is_refused() -> None:
    with pytest.raises(InvalidInputError, match="intensity_unit"):
        Beam("b", intensity_unit="photons")
    beam = Beam("b", intensity_scale=100.0, intensity_unit="reflectivity")
    with pytest.raises(InvalidInputError, match="range"):
        beam.intensity_counts(np.ones(3))
    with pytest.raises(InvalidInputError, match="range"):
        device_quantity(np.ones(3), np.ones(2), "reflectivity")


def test_a_scan_file_keeps_its_unit_and_a_hostile_one_is_refused(tmp_path) -> None:
    wall = trimesh.creation.box((0.2, 4.0, 4.0))
    wall.apply_translation((10.0, 0.0, 0.0))
    s = scan(wall, sensor_from_name("vlp16"), np.eye(4), seed=0, reflectivity=0.3, azimuth_range_deg=(-15.0, 15.0))
    back = read_scan_npz(s.to_npz(tmp_path / "a.npz"))
    assert back.intensity_unit == "reflectivity" and back.to_las_bytes() == s.to_las_bytes()
    for bad in (np.array("photons-secret"), np.array([1.0, 2.0]), np.array(3)):
        arrays = {**s.arrays(), "intensity_unit": bad}
        path = tmp_path / "bad.npz"
        np.savez(path, **arrays)
        with pytest.raises(InvalidInputError, match="bad.npz: intensity_unit") as e:
            read_scan_npz(path)
        assert "secret" not in str(e.value)
