"""An airborne preset out of the box: every echo it keeps reads at least its receiver's floor (23 counts, the IGN RIEGL
receiver's as fit-sensor measures it), one surface's intensities spread as a real receiver's do, an optic given alone
leaves the other to the material table, and vegetation returns as in the IGN tile."""

from __future__ import annotations

import io
import os
from pathlib import Path

import laspy
import numpy as np
import pytest

import zbuf_occlude as zo
from zbuf_occlude.experiments.returns import IGN_ALTITUDE_M, PLOT_TREES, plot_scene
from zbuf_occlude.io.atomic import write_bytes
from zbuf_occlude.io.las import LasPoints, read_las
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.sensors import AirborneScanner, airborne_preset, scan_airborne
from zbuf_occlude.sensors.fit.return_model import fit_return_model
from zbuf_occlude.sensors.fit.returns import return_statistics
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.patterns.airborne_presets import AIRBORNE_PRESETS


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
    assert len(las) > 400 and intensity.min() >= 23  # the detection floor: the IGN receiver's, 23 counts
    beam = airborne_preset(name).beam
    assert beam.detection_threshold * beam.intensity_scale == pytest.approx(23.0)
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
    """A dark ground (ρ 0.023: its returns about the floor) loses the echoes the floor cuts, and only those: the same
    scan detecting from one count keeps them, below 23 counts, and the same echoes above."""
    preset = airborne_preset("riegl-q1560")
    one_count = with_beam(preset, detection_threshold=1.0 / preset.beam.intensity_scale)
    dark = {"reflectivity": [0.023, 0.3]}
    floor, low = (np.asarray(_las(plot, s, **dark).intensity, np.float64) for s in (preset, one_count))
    assert floor.min() >= 23 and (low < 23).sum() > 500  # the floor drops them
    # and nothing else: the same echoes above it (an echo of 22.5 to 23 counts reads 23, but is below the floor)
    assert np.array_equal(np.sort(low[low > 23]), np.sort(floor[floor > 23]))
    assert (floor == 23).sum() < (low == 23).sum()


SHARED = Path(os.environ.get("ZBUF_OCCLUDE_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
IGN_TILE = SHARED / "als_returns" / "ign_lidarhd_sample.laz"
BUSHES = SHARED / "street_objects" / "bush"
needs_ign = pytest.mark.skipif(not IGN_TILE.is_file(), reason="../shared/data/als_returns not present")


@needs_ign
def test_the_presets_receiver_is_the_ign_riegl_receiver_as_fit_sensor_measures_it() -> None:
    """The RIEGL presets' range resolution and every airborne preset's floor and scale: fit-sensor's figures on the IGN
    LiDAR HD sample (at its flying height of 1,500 m), within their spread over 20 resamples."""
    fit = fit_return_model(read_las(IGN_TILE), altitude_m=IGN_ALTITUDE_M, bootstrap=20).estimates
    for name in AIRBORNE_PRESETS:
        beam = airborne_preset(name).beam
        assert beam.detection_threshold * beam.intensity_scale == pytest.approx(fit["detection_threshold_counts"].value, abs=1.0)
        assert beam.intensity_scale == pytest.approx(fit["intensity_scale"].value, rel=0.01)
        if name.startswith(("riegl", "dales")):
            assert beam.range_resolution_m == pytest.approx(fit["range_resolution_m"].value, abs=0.01)


def _vegetation_figures(las: LasPoints) -> tuple[float, float, float]:
    """High vegetation's (class 5) share of points from pulses of several returns and the median intensity of its
    first-of-several returns over its single returns' (fit-sensor's measure, :func:`return_statistics`), and the
    single ground returns' p95 / p5."""
    e = return_statistics(las, classes=(5,), bootstrap=2).estimates
    ground = las.intensity[(las.classification == 2) & (las.number_of_returns == 1)].astype(np.float64)
    p5, p95 = np.percentile(ground, [5, 95])
    return e["multi_return_points_class_5"].value, e["intensity_ratio_classes_5"].value, float(p95 / p5)


@needs_ign
@pytest.mark.skipif(not BUSHES.is_dir(), reason="../shared/data/street_objects not present")
def test_the_riegl_preset_records_vegetation_as_the_ign_tile_does(tmp_path) -> None:
    """Out of the box, over the plot of the shared vegetation meshes at their sizes: the multi-return share and the
    first-of-several / single intensity ratio of high vegetation within ±20 % of the IGN tile's, the single ground
    returns' p95 / p5 within ±50 %."""
    meshes = [load_mesh(BUSHES / tree.file, up=tree.up) for tree in PLOT_TREES]
    scene, _ = plot_scene(meshes, [tree.size_m for tree in PLOT_TREES], spacing_m=14.0)
    s = scan_airborne(scene, airborne_preset("riegl-q1560"), (0.0, 0.0), 28.0, seed=0)
    share, ratio, spread = _vegetation_figures(read_las(write_bytes(tmp_path / "plot.las", s.to_las_bytes())))
    tile_share, tile_ratio, tile_spread = _vegetation_figures(read_las(IGN_TILE))
    assert 0.8 <= share / tile_share <= 1.2, (share, tile_share)
    assert 0.8 <= ratio / tile_ratio <= 1.2, (ratio, tile_ratio)
    assert 0.5 <= spread / tile_spread <= 1.5, (spread, tile_spread)
