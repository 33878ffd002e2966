"""The outline over the height: its measure on scans, its fit to real scans, and the warp that gives a mesh's crops that outline."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.crops import object_crop
from zbuf_occlude.sensors.placement import CropDistributions, draw_placement
from zbuf_occlude.sensors.fit import (
    across_sight_width,
    crop_placement_json,
    fit_crop_width_profile,
    fit_width_profile,
    median_width_profile,
    sight_coordinates,
    width_profile,
)
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.patterns.spinning import lidar_preset
from zbuf_occlude.sensors.scene.object_shapes import FACE_ROWS, width_profile_factors
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject


def _stack(widths: list[float], distance: float = 8.0, height: float = 1.6) -> np.ndarray:
    """A scan straight ahead (+x): ``len(widths)`` equal height bins, each with two rings spread across the sight (y) over its width."""
    rows = []
    n = len(widths)
    for k, w in enumerate(widths):
        for z in (k + 0.2, k + 0.8):
            rows += [[distance + 0.01 * i, y, z * height / n] for i, y in enumerate(np.linspace(-w / 2, w / 2, 5))]
    return np.array(rows)


def _box_under_box(lower: tuple[float, float, float], upper: tuple[float, float, float], upper_z: float) -> trimesh.Trimesh:
    """A normalised test mesh: a box with a second box centred ``upper_z`` above its centre (a sign's plate, a person's arms)."""
    top = trimesh.creation.box(extents=upper)
    top.apply_translation((0.0, 0.0, upper_z))
    return trimesh.util.concatenate([trimesh.creation.box(extents=lower), top])


def _median_outline(mesh, lidar, dist: CropDistributions, n: int) -> np.ndarray:
    """The median :func:`width_profile` of ``n`` crops of ``mesh`` (placements from a fixed seed)."""
    rng = np.random.default_rng(11)
    return np.nanmedian([width_profile(object_crop(mesh, lidar, draw_placement(dist, rng), seed=k).scan.points) for k in range(n)], axis=0)


def test_width_profile_is_each_bins_width_over_the_scans_width() -> None:
    # four bins (two 0.15 m bands each at 1.6 m tall): widths 0.2, 0.4, 0.4, 0.8; the scan's width is the median band, 0.4
    profile = width_profile(_stack([0.2, 0.4, 0.4, 0.8]), n_bins=4)
    np.testing.assert_allclose(profile, [0.5, 1.0, 1.0, 2.0])
    # depth along the sight does not count; a bin of one return is NaN; a scan that shows no width is NaN throughout
    lone = np.array([[8.0, -0.2, 0.0], [9.0, 0.2, 0.05], [8.0, -0.2, 1.0], [8.5, 0.2, 1.05], [8.0, 0.0, 0.5]])
    np.testing.assert_allclose(width_profile(lone, n_bins=3), [1.0, np.nan, 1.0])
    assert np.all(np.isnan(width_profile(np.array([[5.0, 0.0, 0.0], [5.0, 0.0, 1.0]]), n_bins=2)))
    with pytest.raises(InvalidInputError, match="n_bins"):
        width_profile(lone, n_bins=1)
    with pytest.raises(InvalidInputError, match="scan"):
        width_profile(np.array([[1.0, np.inf, 0.0]]))


@settings(max_examples=40, deadline=None)
@given(turn=st.floats(-np.pi, np.pi), stretch=st.floats(0.2, 5.0), lift=st.floats(-3.0, 3.0),
       widths=st.lists(st.floats(0.05, 3.0), min_size=2, max_size=6))  # fmt: skip
def test_width_profile_is_a_shape_not_a_size(turn: float, stretch: float, lift: float, widths: list[float]) -> None:
    """Laws: turning the scan about the vertical axis, stretching x and y alike, or raising it changes no bin."""
    scan = _stack(widths)
    c, s = np.cos(turn), np.sin(turn)
    turned = scan @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T
    for other in (turned, scan * [stretch, stretch, 1.0], scan + [0.0, 0.0, lift]):
        np.testing.assert_allclose(width_profile(other, len(widths)), width_profile(scan, len(widths)), rtol=1e-6, atol=1e-9)


def test_fit_crop_width_profile_is_the_median_per_bin() -> None:
    clouds = [_stack([0.2 * f, 0.4, 0.4, 0.8 * g]) for f, g in ((1, 1), (2, 1), (3, 2), (1, 3))]
    # the scans' widths (median of 8 bands) are 0.4, 0.4, 0.5 and 0.4 m; the third's bins are 1.2, 0.8, 0.8, 3.2
    # bottom: median(0.5, 1.0, 1.2, 0.5) = 0.75; middle: median(1, 1, 0.8, 1) = 1; top: median(2, 2, 3.2, 6) = 2.6
    np.testing.assert_allclose(fit_crop_width_profile(clouds, n_bins=4), [0.75, 1.0, 1.0, 2.6])
    # a bin no scan fills is 1 (no warp); too few scans that show a width is an error
    holes = [np.vstack([c[:10], c[-10:]]) for c in clouds]  # the bottom and top bins only
    np.testing.assert_allclose(fit_crop_width_profile(holes, n_bins=4)[1:3], [1.0, 1.0])
    with pytest.raises(InvalidInputError, match="at least 3"):
        fit_crop_width_profile(clouds[:2] + [np.array([[5.0, 0.0, 0.0], [5.0, 0.0, 1.0]])], n_bins=4)
    assert crop_placement_json(clouds[:3], ["a"] * 3)["across_sight_profile"]["a"] == pytest.approx(fit_crop_width_profile(clouds[:3]))


def test_median_width_profile_is_the_median_per_bin_and_nan_where_no_scan_fills_it() -> None:
    """The same medians as the fit's, with no minimum of scans and NaN (not 1) where no scan fills a bin."""
    clouds = [_stack([0.2 * f, 0.4, 0.4, 0.8 * g]) for f, g in ((1, 1), (2, 1), (3, 2), (1, 3))]
    np.testing.assert_allclose(median_width_profile(clouds, n_bins=4), [0.75, 1.0, 1.0, 2.6])
    holes = [np.vstack([c[:10], c[-10:]]) for c in clouds]  # the bottom and top bins only
    got = median_width_profile(holes, n_bins=4)
    assert np.isnan(got[1:3]).all() and np.isfinite(got[[0, 3]]).all()
    np.testing.assert_allclose(median_width_profile(clouds[:1], n_bins=4), width_profile(clouds[0], n_bins=4))
    assert median_width_profile([], n_bins=3).shape == (3,) and np.isnan(median_width_profile([], n_bins=3)).all()
    with pytest.raises(InvalidInputError, match="n_bins"):
        median_width_profile(clouds, n_bins=1)


@settings(max_examples=30, deadline=None)
@given(turn_deg=st.floats(-180.0, 180.0), lift=st.floats(-3.0, 3.0))
def test_sight_coordinates_turn_with_the_scan_and_measure_what_the_width_measures(turn_deg: float, lift: float) -> None:
    """A scan straight ahead (+x): along is x and across is y; turned about the sensor's vertical axis or raised,
    its coordinates stay; the extent across per band is what :func:`across_sight_width` takes the median of."""
    scan = _stack([0.3, 0.5, 0.5, 0.4])
    np.testing.assert_allclose(sight_coordinates(scan), scan[:, :2], atol=1e-12)
    a = np.radians(turn_deg)
    turned = scan @ np.array([[np.cos(a), np.sin(a), 0.0], [-np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]]) + [0.0, 0.0, lift]
    np.testing.assert_allclose(sight_coordinates(turned), scan[:, :2], atol=1e-9)
    across, z = sight_coordinates(turned)[:, 1], turned[:, 2]
    bands = np.floor((z - z.min()) / 0.1).astype(int)
    widths = [np.ptp(across[bands == b]) for b in np.unique(bands) if (bands == b).sum() >= 2]
    assert across_sight_width(turned, band_m=0.1) == pytest.approx(np.median(widths))
    assert sight_coordinates(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0]])) == pytest.approx(np.zeros((2, 2)))  # straight above
    with pytest.raises(InvalidInputError):
        sight_coordinates(np.array([[np.nan, 0.0, 0.0]]))


@settings(max_examples=40, deadline=None)
@given(profile=st.lists(st.floats(0.125, 8.0), min_size=2, max_size=8), z=st.lists(st.floats(-5.0, 5.0), min_size=2, max_size=30))
def test_width_profile_factors_interpolate_between_bin_centres(profile: list[float], z: list[float]) -> None:
    factors = width_profile_factors(np.array(z), tuple(profile))
    assert np.all(factors >= min(profile) - 1e-12) and np.all(factors <= max(profile) + 1e-12)
    k = len(profile)
    lo, hi = min(z), max(z)
    # a span float64 resolves into bins (one a few ulps wide, 5.0 to 4.999999999999999, rounds every centre onto an end):
    if hi - lo > 1e-9:  # at the bin centres, the profile itself; below the first centre and above the last, the end values
        centres = lo + (np.arange(k) + 0.5) / k * (hi - lo)
        np.testing.assert_allclose(width_profile_factors(np.r_[lo, hi, centres], tuple(profile))[2:], profile, rtol=1e-9)
        np.testing.assert_allclose(width_profile_factors(np.r_[lo, hi], tuple(profile)), [profile[0], profile[-1]], rtol=1e-9)
        middles = (centres[1:] + centres[:-1]) / 2  # linear between centres: halfway, the mean of the two
        np.testing.assert_allclose(width_profile_factors(np.r_[lo, hi, middles], tuple(profile))[2:],
                                   (np.array(profile[1:]) + profile[:-1]) / 2, rtol=1e-9)  # fmt: skip


def test_a_warped_object_follows_its_profile_and_keeps_its_size_and_faces() -> None:
    post = trimesh.creation.box(extents=(0.2, 0.2, 1.0))  # vertices at its ends only: the warp must cut its sides
    profile = (0.5, 1.0, 1.0, 3.0)
    local, to_world = SceneObject(post, size_m=2.0, width_profile=profile).build()
    world = trimesh.transform_points(local.vertices, to_world)
    assert np.ptp(world[:, 2]) == pytest.approx(2.0)  # size_m measures the mesh as loaded: as tall
    for k, f in enumerate(profile):  # at each bin centre, as wide as the profile asks (0.4 m before the warp)
        z = (k + 0.5) / 4 * 2.0
        section = trimesh.intersections.mesh_plane(trimesh.Trimesh(world, local.faces), [0, 0, 1], [0, 0, z])
        assert np.ptp(section.reshape(-1, 3)[:, 0]) == pytest.approx(0.4 * f, rel=1e-6)
    rows = local.metadata[FACE_ROWS]
    assert len(rows) == len(local.faces) > len(post.faces) and set(rows) == set(range(len(post.faces)))
    built = ScanScene(objects=[SceneObject(post, size_m=2.0, width_profile=profile)], ground=False).build()
    np.testing.assert_array_equal(built.face_local, rows)  # the scene reports the faces as loaded
    for bad in ((1.0,), (1.0, 0.0), (1.0, float("nan")), "wide"):
        with pytest.raises(InvalidInputError, match="width_profile"):
            SceneObject(post, class_name="p", width_profile=bad).build()
        with pytest.raises(InvalidInputError, match="width_profile"):
            CropDistributions(width_profile=bad)


def test_width_profile_draws_nothing_and_reaches_the_crop() -> None:
    rng = lambda: np.random.default_rng(5)  # noqa: E731
    plain = draw_placement(CropDistributions(width_scale=(1.0, 2.0)), rng())
    warped = draw_placement(CropDistributions(width_scale=(1.0, 2.0), width_profile=[1, 2]), rng())
    assert warped == replace(plain, width_profile=(1.0, 2.0))
    post = trimesh.creation.box(extents=(0.2, 0.2, 1.0))
    lidar = with_beam(lidar_preset("hdl32e"), range_noise_m=0.0)
    placement = draw_placement(CropDistributions(distance_m=5.0, height_m=1.8, size_m=2.0, yaw_deg=0.0), rng())
    crop = object_crop(post, lidar, replace(placement, width_profile=(0.5, 0.5, 4.0, 4.0)), seed=1)
    low, high = crop.local_points[:, 2] < -0.3, crop.local_points[:, 2] > 0.3  # the mesh frame keeps the warp
    assert np.ptp(crop.local_points[low, 1]) < 0.11 and np.ptp(crop.local_points[high, 1]) > 0.6


def test_fit_width_profile_gives_a_sign_post_a_trunks_outline() -> None:
    """A post with a plate on its upper third, fitted to a uniform outline: the plate is pulled in, the post is kept."""
    sign = _box_under_box((0.06, 0.06, 1.0), (0.3, 0.3, 0.3), 0.3)
    lidar = with_beam(lidar_preset("hdl32e"), range_noise_m=0.0)
    dist = CropDistributions(distance_m=(4.0, 6.0), height_m=1.8, size_m=3.0)

    def outline(d) -> np.ndarray:
        return _median_outline(sign, lidar, d, 12)

    target = (1.0,) * 8
    warp = fit_width_profile(sign, lidar, dist, target, n_samples=8, name="sign")
    assert max(warp[:4]) == pytest.approx(1.0, abs=0.15) and max(warp[-2:]) < 0.5  # the post kept, the plate pulled in
    before, after = outline(dist), outline(CropDistributions(distance_m=(4.0, 6.0), height_m=1.8, size_m=3.0, width_profile=warp))
    assert np.nanmean(np.abs(after - 1.0)) < 0.5 * np.nanmean(np.abs(before - 1.0))
    # the correction: the plate's bins end up near the trunk's width, not only nearer
    assert np.nanmax(np.abs(after[-3:] - 1.0)) < 0.3
    # With the lower half hidden, the crops' bins span the mesh's upper half only, where the plate (0.65-0.95 of the
    # height) is most of what shows: the scans' width is the plate's, so the post under it (bin 4, 0.5-0.625) is widened
    # to it and the plate (bins 5-6) kept.  The warp is placed on the mesh's own heights, not on the crops' bins.
    hidden = fit_width_profile(sign, lidar, replace(dist, hidden_below_m=1.5), target, n_samples=8, name="sign")
    assert hidden[4] > 3.0 and max(hidden[5:7]) < 1.5, hidden
    with pytest.raises(InvalidInputError, match="width_profile"):
        fit_width_profile(sign, lidar, dist, (1.0,), name="sign")
    with pytest.raises(InvalidInputError, match="spinning"):
        fit_width_profile(sign, object(), dist, target, name="sign")


def test_fit_width_profile_pulls_a_t_posed_persons_arms_in() -> None:
    """Arms held out at 0.75-0.9 of the height show 1.7-1.8 times the body's width; a uniform outline asks them pulled in.
    One round of the fit leaves them at 1.76 (warp 0.62); the correction brings them to about 1.5 (warp 0.50)."""
    person = _box_under_box((0.25, 0.15, 1.0), (0.8, 0.1, 0.15), 0.3)
    lidar = with_beam(lidar_preset("hdl32e"), range_noise_m=0.0)
    dist = CropDistributions(distance_m=(4.0, 9.0), height_m=1.8, size_m=1.7)
    warp = fit_width_profile(person, lidar, dist, (1.0,) * 8, name="person")
    assert warp[6] < 0.56 and min(warp[:5]) > 0.9  # the arms' bin pulled in, the legs and the trunk kept
    outline = _median_outline(person, lidar, replace(dist, width_profile=warp), 24)
    assert outline[6] < 1.65


@pytest.mark.slow
def test_scan_outline_option(tmp_path) -> None:
    """`scan --crop --outline`: a cylinder narrowed at its foot and widened at its top shows that outline, and the option is checked."""
    from zbuf_occlude.cli.main import main
    from zbuf_occlude.sensors.scan_data import read_scan_npz

    base = ["scan", "cylinder", "--size", "2", "--distance", "6:8", "--height", "1.8", "--samples", "6", "--seed", "2"]
    outline = (0.5, 0.5, 1.0, 1.0, 1.0, 1.0, 1.5, 1.5)
    assert main([*base, "--crop", "--outline", ",".join(map(str, outline)), "--out", str(tmp_path / "o")]) == 0
    assert main([*base, "--crop", "--out", str(tmp_path / "p")]) == 0
    shown = {
        tag: np.nanmedian([width_profile(read_scan_npz(p).points) for p in sorted((tmp_path / tag).glob("*.npz"))], axis=0) for tag in "op"
    }
    assert np.nanmax(np.abs(shown["p"] - 1.0)) < 0.15  # a cylinder: as wide at every height
    assert shown["o"][0] < 0.75 * shown["o"][4] and shown["o"][-1] > 1.2 * shown["o"][4]
    assert main([*base, "--crop", "--outline", "1,1", "--across-sight-width", "0.5", "--out", str(tmp_path / "b")]) == 0  # both
    for bad in (["--outline", "1,1"], ["--crop", "--outline", "1"], ["--crop", "--outline", "1,-1"], ["--crop", "--outline", "wide,1"]):
        assert main([*base, *bad, "--out", str(tmp_path / "x")]) == 2
