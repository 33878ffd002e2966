"""An airborne preset out of the box: every echo it keeps reads at least its receiver's floor (12 counts, the IGN RIEGL
receiver's weakest echo), one surface's intensities spread as a real receiver's do, and an optic given alone leaves the other to the material table."""

from __future__ import annotations

import io

import laspy
import numpy as np
import pytest

import zbuf_occlude as zo
from zbuf_occlude.sensors import AirborneScanner, airborne_preset, scan_airborne
from zbuf_occlude.sensors.kinds import with_beam


def _las(scene, scanner, **optics) -> laspy.LasData:
    s = scan_airborne(scene, scanner, (0.0, 0.0), 8.0, seed=2, **optics)
    return laspy.read(io.BytesIO(s.to_las_bytes()))


@pytest.fixture(scope="module")
def plot():
    """Flat ground and a box standing on it, as a scene."""
    return zo.ScanScene(ground_half_extent_m=40.0).add({"box_m": [3.0, 3.0, 2.0]}, position_m=(2.0, 1.0), class_name="building")


@pytest.mark.parametrize("name", ["riegl-q1560", "leica-als50-ii", "optech-galaxy"])
def test_no_kept_echo_reads_zero_and_the_ground_spreads_as_a_receivers_do(plot, name: str) -> None:
    las = _las(plot, airborne_preset(name))
    intensity = np.asarray(las.intensity, np.float64)
    assert len(las) > 400 and intensity.min() >= 12  # the detection floor: the IGN receiver's weakest echo, 12 counts
    beam = airborne_preset(name).beam
    assert beam.detection_threshold * beam.intensity_scale == pytest.approx(12.0)
    ground = intensity[(np.asarray(las.classification) == 2) & (np.asarray(las.number_of_returns) == 1)]
    p5, p95 = np.percentile(ground, [5, 95])
    assert 1.85 <= p95 / p5 <= 5.55  # the IGN sample's single ground returns: 87 / 326, 3.7, ± 50 %


def test_the_ideal_beam_keeps_one_value(plot) -> None:
    """The spread is the presets' receiver, not the scene's: the ideal airborne beam has none."""
    ideal = AirborneScanner("ideal-als", 58.0, 800_000.0, 209.0, 1300.0, 72.0)
    s = scan_airborne(plot, ideal, (0.0, 0.0), 8.0, seed=2)
    assert np.unique(s.intensity).size == 1


def test_a_transmittance_given_alone_keeps_the_materials_reflectances(plot) -> None:
    scanner = airborne_preset("riegl-q1560")
    ground = lambda las: np.asarray(las.intensity)[(np.asarray(las.classification) == 2) & (np.asarray(las.number_of_returns) == 1)]  # noqa: E731
    default, with_tau, rho_1 = (np.median(ground(_las(plot, scanner, **o))) for o in ({}, {"transmittance": 0.3}, {"reflectivity": None}))
    assert with_tau == pytest.approx(default, rel=0.05) and rho_1 > 2.0 * default  # the soil's 0.33, not ρ = 1


def test_echoes_weaker_than_the_receivers_floor_are_not_recorded(plot) -> None:
    """A dark ground (ρ 0.012: its returns about the floor) loses the echoes the floor cuts, and only those: the same
    scan detecting from one count keeps them, below 12 counts, and the same echoes above."""
    preset = airborne_preset("riegl-q1560")
    one_count = with_beam(preset, detection_threshold=1.0 / preset.beam.intensity_scale)
    dark = {"reflectivity": [0.012, 0.3]}
    floor, low = (np.asarray(_las(plot, s, **dark).intensity, np.float64) for s in (preset, one_count))
    assert floor.min() >= 12 and (low < 12).sum() > 500  # the floor drops them
    # and nothing else: the same echoes above it (an echo of 11.5 to 12 counts reads 12, but is below the floor)
    assert np.array_equal(np.sort(low[low > 12]), np.sort(floor[floor > 12]))
    assert (floor == 12).sum() < (low == 12).sum()
