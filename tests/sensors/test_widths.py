"""Object widths across the line of sight: the measure, its fit to real scans, and the horizontal stretch of the crops."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.crops import object_crop
from zbuf_occlude.sensors.placement import CropDistributions, draw_placement
from zbuf_occlude.sensors.fit import WIDTH_BAND_M, across_sight_width, crop_placement_json, fit_crop_widths, fit_width_scale
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.patterns.spinning import lidar_preset
from zbuf_occlude.sensors.kinds import sensor_from_name
from zbuf_occlude.sensors.scan_data import read_scan_npz
from zbuf_occlude.sensors.scene.objects import SceneObject


def _rings(widths: list[float], distance: float = 8.0) -> np.ndarray:
    """A scan straight ahead (+x) at ``distance``: one band per width, its returns spread across the sight (y) over that width."""
    rows = []
    for k, w in enumerate(widths):
        z = -1.5 + (k + 0.5) * WIDTH_BAND_M
        rows += [[distance + 0.01 * i, y, z] for i, y in enumerate(np.linspace(-w / 2, w / 2, 5))]
    return np.array(rows)


def test_width_is_the_median_over_bands_of_the_extent_across_the_sight() -> None:
    scan = _rings([0.2, 0.3, 1.5])
    assert across_sight_width(scan) == pytest.approx(0.3)
    # depth along the sight does not count: a band 2 m deep and 0.1 m wide is 0.1 m wide
    deep = np.array([[6.0, -0.05, 0.0], [8.0, 0.05, 0.0]])
    assert across_sight_width(deep) == pytest.approx(0.1)
    # bands of one return have no width and are left out of the median; none with two: 0
    lone = np.vstack([_rings([0.4]), [[8.0, 0.0, 0.5], [8.0, 0.0, 0.8], [8.0, 0.0, 1.1]]])
    assert across_sight_width(lone) == pytest.approx(0.4)
    assert across_sight_width(np.array([[5.0, 0.0, 0.0], [5.0, 0.5, 1.0]])) == 0.0
    assert across_sight_width(np.zeros((0, 3))) == 0.0
    with pytest.raises(InvalidInputError, match="scan"):
        across_sight_width(np.array([[1.0, np.nan, 0.0]]))
    with pytest.raises(InvalidInputError, match="band_m"):
        across_sight_width(scan, 0.0)


@settings(max_examples=40, deadline=None)
@given(turn=st.floats(-np.pi, np.pi), stretch=st.floats(0.2, 5.0), widths=st.lists(st.floats(0.0, 3.0), min_size=1, max_size=6))
def test_width_turns_with_the_scan_and_scales_with_its_horizontal_axes(turn: float, stretch: float, widths: list[float]) -> None:
    """Laws: turning the scan about the sensor's vertical axis keeps its width; stretching x and y by s multiplies it by s."""
    scan = _rings(widths)
    c, s = np.cos(turn), np.sin(turn)
    turned = scan @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T
    assert across_sight_width(turned) == pytest.approx(across_sight_width(scan), abs=1e-9)
    assert across_sight_width(scan * [stretch, stretch, 1.0]) == pytest.approx(stretch * across_sight_width(scan), abs=1e-9)


def test_fit_crop_widths_is_the_median_plus_minus_the_interquartile_range() -> None:
    clouds = [_rings([w, w]) for w in np.arange(1, 12) / 10]  # 0.1 ... 1.1 m: median 0.6, quartiles 0.35 and 0.85
    assert fit_crop_widths(clouds) == pytest.approx((0.1, 1.1))
    # a long upper tail widens the interval by its interquartile range only; the low end stops at 0
    assert fit_crop_widths([_rings([w, w]) for w in (0.2, 0.2, 0.3, 0.4, 9.0)]) == pytest.approx((0.1, 0.5))
    assert fit_crop_widths([_rings([w, w]) for w in (0.0, 0.0, 0.1, 1.0, 1.0)]) == pytest.approx((0.0, 1.1))
    with pytest.raises(InvalidInputError, match="at least 3"):
        fit_crop_widths(clouds[:2])
    crops = crop_placement_json(clouds, ["a"] * 5 + ["b"] * 6)
    assert crops["across_sight_width_m"] == {"a": pytest.approx([0.1, 0.5]), "b": pytest.approx([0.6, 1.1])}


def test_scene_object_stretches_its_horizontal_axes_only() -> None:
    box = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    for w in (0.25, 1.0, 3.0):
        local, to_world = SceneObject(box, size_m=4.0, yaw_deg=30.0, width_scale=w).build()
        world = trimesh.transform_points(local.vertices, to_world)
        unturned = (
            world
            @ np.array(
                [[np.cos(np.radians(30)), np.sin(np.radians(30)), 0], [-np.sin(np.radians(30)), np.cos(np.radians(30)), 0], [0, 0, 1]]
            ).T
        )
        np.testing.assert_allclose(np.ptp(unturned, axis=0), [4.0 * w, 2.0 * w, 1.0], atol=1e-9)
        assert world[:, 2].min() == pytest.approx(0.0)  # still standing on the ground
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(InvalidInputError, match="width_scale"):
            SceneObject(box, width_scale=bad).build()


def test_width_scale_is_drawn_last_and_checked() -> None:
    rng = lambda: np.random.default_rng(3)  # noqa: E731
    plain = draw_placement(CropDistributions(hidden_below_m=(0.0, 0.5)), rng())
    drawn = draw_placement(CropDistributions(hidden_below_m=(0.0, 0.5), width_scale=(2.0, 3.0)), rng())
    assert {k: v for k, v in drawn.to_dict().items() if k in plain.to_dict()} == plain.to_dict() and 2.0 <= drawn.width_scale <= 3.0
    fixed = rng()
    assert draw_placement(CropDistributions(width_scale=2.5), fixed).width_scale == 2.5
    assert fixed.uniform() == (same := rng(), draw_placement(CropDistributions(), same), same.uniform())[2]  # a fixed value draws nothing
    for bad in (0.0, -1.0, (3.0, 2.0), "thick"):
        with pytest.raises(InvalidInputError, match="width_scale"):
            CropDistributions(width_scale=bad)


def test_a_stretched_post_is_scanned_whole_and_as_wide_as_stretched() -> None:
    """A thin post stretched 6x: every return of the wider object is in the crop (the LiDAR's sector grows with it)."""
    post = trimesh.creation.box(extents=(0.1, 0.1, 1.0))  # a normalised mesh: 0.1 of its height thick
    lidar = with_beam(lidar_preset("hdl32e"), range_noise_m=0.0)
    placement = draw_placement(CropDistributions(distance_m=4.0, height_m=1.8, size_m=3.0, yaw_deg=0.0), np.random.default_rng(0))
    thin = object_crop(post, lidar, placement, seed=1)
    for w in (6.0, 20.0):  # 1.8 m and 6 m wide at 4 m: the second wider than the default sector
        wide = object_crop(post, lidar, replace(placement, width_scale=w), seed=1)
        whole = object_crop(post, lidar, replace(placement, width_scale=w), seed=1, sector_margin_deg=180.0)
        assert len(wide.scan) == len(whole.scan) > len(thin.scan)
        assert np.ptp(wide.scan.points[:, 2]) == pytest.approx(
            np.ptp(thin.scan.points[:, 2]), abs=0.1
        )  # as tall, within a ring (0.09 m at 4 m)
        if w == 6.0:  # (the 6 m box's near face is 1 m from the sensor: it shows only part of its width)
            assert across_sight_width(wide.scan.points) == pytest.approx(w * across_sight_width(thin.scan.points), rel=0.15)


@pytest.mark.parametrize("stretch", [0.3, 2.5])
def test_a_stretched_crop_keeps_its_stretch_in_the_mesh_frame(stretch: float) -> None:
    """The crop's mesh-frame points (the training clouds) show the object as scanned: as wide as stretched, as tall.

    The local frame inverts the object's transform; without the stretch kept, a crop of a
    stretched box would show the box's own proportions, and training would never see the widths.
    """
    box = trimesh.creation.box(extents=(0.5, 0.5, 1.0))
    lidar = with_beam(lidar_preset("hdl32e"), range_noise_m=0.0)
    placement = draw_placement(CropDistributions(distance_m=6.0, height_m=1.8, size_m=2.0, yaw_deg=0.0), np.random.default_rng(0))
    plain = object_crop(box, lidar, placement, seed=1)
    wide = object_crop(box, lidar, replace(placement, width_scale=stretch), seed=1)
    assert np.all(np.abs(wide.local_points[:, :2]) <= 0.25 * stretch + 1e-6)  # on the stretched box
    assert np.ptp(wide.local_points[:, 1]) == pytest.approx(stretch * np.ptp(plain.local_points[:, 1]), rel=0.1)  # across the sight (+x)
    assert np.ptp(wide.local_points[:, 2]) == pytest.approx(np.ptp(plain.local_points[:, 2]), abs=0.05)
    # the sensor in the same frame: the metric scene over the object's size (2 m), unchanged by the stretch
    assert wide.sensor_local == pytest.approx(plain.sensor_local, abs=1e-9)
    assert np.hypot(*(plain.sensor_local[:2])) == pytest.approx(6.0 / 2.0, abs=1e-9)


@pytest.mark.slow
def test_fit_width_scale_makes_the_crops_as_wide_as_asked() -> None:
    post = trimesh.creation.cylinder(radius=0.05, height=1.0, sections=32)
    lidar = with_beam(lidar_preset("hdl32e"), range_noise_m=0.0)
    dist = CropDistributions(distance_m=(5.0, 9.0), height_m=1.8, size_m=3.0)
    lo, hi = fit_width_scale(post, lidar, dist, (0.3, 0.6))
    # the post is 0.3 m thick at 3 m tall; its crops show a little less (the outermost returns lie inside the outline)
    assert hi == pytest.approx(2 * lo) and 1.0 < lo < 1.3
    rng = np.random.default_rng(5)
    stretched = CropDistributions(distance_m=(5.0, 9.0), height_m=1.8, size_m=3.0, width_scale=(lo, lo))
    widths = [across_sight_width(object_crop(post, lidar, draw_placement(stretched, rng), seed=k).scan.points) for k in range(24)]
    assert np.median(widths) == pytest.approx(0.3, rel=0.15)
    # its own width_scale is ignored: the stretch is fitted to the mesh's proportions
    assert fit_width_scale(post, lidar, stretched, (0.3, 0.6)) == (lo, hi)
    # posts near the azimuth step (1.5-2.7 cm at 5-9 m): 2.4 cm thick shows no width at all and is widened first; 4.2 cm
    # shows one or two returns a ring, so its width does not grow in proportion, and the second round corrects the first
    for radius in (0.004, 0.007):
        thin = trimesh.creation.cylinder(radius=radius, height=1.0, sections=32)
        t_lo, _ = fit_width_scale(thin, lidar, dist, (0.3, 0.6))
        stretched = CropDistributions(distance_m=(5.0, 9.0), height_m=1.8, size_m=3.0, width_scale=(t_lo, t_lo))
        widths = [across_sight_width(object_crop(thin, lidar, draw_placement(stretched, rng), seed=k).scan.points) for k in range(24)]
        assert np.median(widths) == pytest.approx(0.3, rel=0.1)
    for bad in ((0.6, 0.3), (-0.1, 0.2), ("a", 1), (0.0, 0.0)):
        with pytest.raises(InvalidInputError, match="width_m"):
            fit_width_scale(post, lidar, dist, bad)
    # a sliver shows no width however far it is widened; the error names it
    sliver = trimesh.Trimesh([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1e-7, 1e-7, 0.5]], [[0, 1, 2]], process=False)
    with pytest.raises(InvalidInputError, match="sliver.obj: no crop of 16 shows it two returns wide"):
        fit_width_scale(sliver, lidar, dist, (0.3, 0.6), name="sliver.obj")
    with pytest.raises(InvalidInputError, match="spinning LiDAR"):
        fit_width_scale(post, sensor_from_name("riegl-q1560"), dist, (0.3, 0.6))


@pytest.mark.parametrize("second, stretch", [(1e-9, 0.2), (0.02, 0.1), (0.0025, 0.8), (0.0, 0.2)])
def test_fit_width_scale_corrects_by_at_most_four_times_wider(monkeypatch: pytest.MonkeyPatch, second: float, stretch: float) -> None:
    # a lamp post squeezed towards a 1 cm target showed 2e-9 m in the second round (two returns of one azimuth column in
    # a band), and dividing by it asked for a 5.6e5 x stretch: a correction above 4 x is noise, and the first estimate stays
    from zbuf_occlude.sensors.fit import shapes

    widths = iter([0.05, second])  # the mesh's own crops 5 cm wide; then the crops at the first estimate, 0.2 x
    monkeypatch.setattr(shapes, "_median_crop_width", lambda *args: next(widths))
    post = trimesh.creation.cylinder(radius=0.05, height=1.0, sections=8)
    lo, hi = fit_width_scale(post, lidar_preset("hdl32e"), CropDistributions(distance_m=5.0, height_m=1.8, size_m=3.0), (0.005, 0.015))
    assert (lo, hi) == pytest.approx((0.5 * stretch, 1.5 * stretch))


def test_scan_across_sight_width_option(tmp_path: Path) -> None:
    from zbuf_occlude.cli.main import main

    base = ["scan", "cylinder", "--size", "3", "--distance", "5:8", "--height", "1.8", "--samples", "6", "--seed", "2"]
    assert main([*base, "--crop", "--across-sight-width", "0.8", "--out", str(tmp_path / "w")]) == 0
    assert main([*base, "--crop", "--out", str(tmp_path / "p")]) == 0
    widths = {tag: np.median([across_sight_width(read_scan_npz(p).points) for p in sorted((tmp_path / tag).glob("*.npz"))]) for tag in "wp"}
    assert widths["w"] == pytest.approx(0.8, rel=0.2) and widths["p"] > 2.0  # the unit cylinder at 3 m is 3 m wide
    assert main([*base, "--across-sight-width", "0.8", "--out", str(tmp_path / "x")]) == 2  # needs --crop
    assert main([*base, "--crop", "--across-sight-width=-1", "--out", str(tmp_path / "y")]) == 2
    assert main([*base, "--crop", "--across-sight-width", "wide", "--out", str(tmp_path / "z")]) == 2
