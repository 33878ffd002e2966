"""The hull test of hidden point removal (zbuf_occlude.visibility.point_hull): Katz et al.'s flipping,
their hull on closed forms, the veto's laws, degenerate clouds, and its place in a view of splats."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import zbuf_occlude as zo
from zbuf_occlude.errors import ArgumentTypeError
from zbuf_occlude.defaults import HULL_RADIUS_FACTOR_PER_POINT, HULL_VETO_MAX_POINTS
from zbuf_occlude.visibility import point_splats
from zbuf_occlude.visibility.point_hull import MAX_VETOED_SHARE, flipped, hull_veto, on_flipped_hull

ROOT = Path(__file__).resolve().parents[2]
coordinates = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)
clouds = arrays(np.float64, st.tuples(st.integers(0, 60), st.just(3)), elements=coordinates)
eyes = arrays(np.float64, 3, elements=st.floats(-30.0, 30.0, allow_nan=False, allow_infinity=False))


@settings(max_examples=60, deadline=None)
@given(clouds, eyes, st.floats(1.0, 1e4))
@example(np.full((1, 3), 7.47e-160), np.zeros(3), 1.0)  # squares below the smallest normal float64
@example(np.array([[5e-324, 0.0, 0.0], [0.0, 0.0, 0.0]]), np.full(3, 5e-324), 1.0)  # subnormal offsets from the eye
def test_law_a_flipped_point_stays_on_its_ray_at_twice_the_radius_less_its_distance(points, eye, factor):
    image = flipped(points, eye, factor)
    p = points - eye
    largest = np.abs(p).max(initial=0.0)
    p = p / largest if largest > 0.0 else p  # subnormal differences: their distances would round to one ulp
    d = np.hypot(np.hypot(p[:, 0], p[:, 1]), p[:, 2])  # no square to underflow at 1e-160
    unit = d.max(initial=0.0)  # the farthest point's distance: the images' unit of length
    away = d > 1e-9 * unit
    assert np.allclose(np.linalg.norm(image[away], axis=1), 2.0 * factor - d[away] / unit, rtol=1e-9, atol=0.0)
    assert np.allclose(np.cross(image[away], p[away] / unit), 0.0, atol=1e-9 * (factor + 1.0))
    assert np.all(np.einsum("ij,ij->i", image[away], p[away]) > 0.0)  # the same side of the eye
    assert np.array_equal(image[d == 0.0], np.zeros((np.count_nonzero(d == 0.0), 3)))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([1e-90, 1e-6, 1e6, 1e90]))
def test_law_the_hull_test_does_not_depend_on_the_cloud_s_unit(seed, scale):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(300, 3)) * rng.uniform(0.2, 1.0, size=3)
    eye = np.array([0.0, 0.0, 6.0])
    visible = rng.random(len(points)) < 0.7
    assert np.array_equal(hull_veto(points * scale, visible, eye * scale, 150.0), hull_veto(points, visible, eye, 150.0))


@settings(max_examples=60, deadline=None)
@given(clouds, eyes, st.floats(1.0, 1e4), st.integers(0, 2**32 - 1))
def test_law_the_veto_only_hides_points_the_splats_called_visible(points, eye, factor, seed):
    visible = np.random.default_rng(seed).random(len(points)) < 0.6
    kept = hull_veto(points, visible, eye, factor)
    assert kept.dtype == np.bool_ and kept.shape == visible.shape
    assert not np.any(kept & ~visible)


def test_the_near_half_of_a_sphere_is_on_the_hull_and_the_far_half_is_not():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    points, _ = zo.sample_surface(mesh, 4_000, seed=0)
    eye = np.array([0.0, 0.0, 3.0])
    cos = np.einsum("ij,ij->i", points / 0.5, eye - points) / np.linalg.norm(eye - points, axis=1)
    on = on_flipped_hull(points, eye, 100.0)
    # Katz et al.: away from the rim (the grazing band) the hull is the visible set
    assert on[cos > 0.1].all()
    assert not on[cos < -0.1].any()
    # a larger radius flattens the flipped cloud until the far half's images, a spacing behind the
    # near half's, rise through the hull between them: more points on it, never fewer here
    wide = on_flipped_hull(points, eye, 5_000.0)
    assert wide[on].all() and wide[cos < -0.1].any()


def test_a_point_behind_a_small_plate_is_vetoed_and_the_plate_kept():
    u, v = np.meshgrid(np.linspace(-0.1, 0.1, 11), np.linspace(-0.1, 0.1, 11))
    plate = np.column_stack([u.ravel(), v.ravel(), np.full(u.size, 1.0)])
    behind, beside = [0.0, 0.0, 0.0], [2.0, 0.0, 0.0]
    points = np.vstack([plate, [behind, beside]])
    eye = np.array([0.0, 0.0, 5.0])
    kept = hull_veto(points, np.ones(len(points), dtype=bool), eye, 100.0)
    assert kept[: len(plate)].all()
    assert not kept[len(plate)]  # straight behind the plate's centre
    assert kept[len(plate) + 1]  # in the open


def test_a_plate_seen_exactly_edge_on_keeps_what_the_splats_saw():
    # the eye in the plate's mid-plane: the flipped plate is a flat hull holding its own points, which
    # HPR would hide (most of the view); the veto is not taken
    mesh = trimesh.creation.box(extents=(1.0, 0.0125, 0.6))
    points, _ = zo.sample_surface(mesh, 2_048, seed=0)
    eye = np.array([0.4, 0.0, 3.0])
    assert np.count_nonzero(~on_flipped_hull(points, eye, 1_024.0)) > MAX_VETOED_SHARE * len(points)
    assert hull_veto(points, np.ones(len(points), dtype=bool), eye, 1_024.0).all()
    seen = np.arange(len(points)) % 3 == 0
    assert np.array_equal(hull_veto(points, seen, eye, 1_024.0), seen)


def test_a_duplicated_hull_point_keeps_both_copies():
    rng = np.random.default_rng(3)
    points = rng.normal(size=(200, 3))
    eye = np.array([0.0, 0.0, 10.0])
    on = on_flipped_hull(points, eye, 100.0)
    doubled = np.vstack([points, points[on][:5]])
    on2 = on_flipped_hull(doubled, eye, 100.0)
    assert on2[len(points) :].all()
    assert np.array_equal(on2[: len(points)], on)


@pytest.mark.parametrize(
    "points",
    [
        np.zeros((0, 3)),
        np.array([[0.0, 0.0, 0.0]]),
        np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]),
        np.column_stack([np.linspace(0, 1, 9), np.zeros(9), np.zeros(9)]),  # a line through the eye's plane
        np.column_stack([np.linspace(0, 1, 9), np.linspace(0, 2, 9), np.zeros(9)]),  # flat with the eye
        np.tile([[1.0, 2.0, 0.0]], (7, 1)),  # one point seven times
    ],
)
def test_a_cloud_with_no_hull_keeps_every_point(points):
    eye = np.array([0.0, 0.0, 0.0]) if len(points) > 3 else np.array([0.0, 0.0, 4.0])
    assert on_flipped_hull(points, eye, 100.0).all()


def test_a_point_at_the_eye_is_kept():
    rng = np.random.default_rng(0)
    points = np.vstack([rng.normal(size=(50, 3)) + [0, 0, -5], [[0.0, 0.0, 0.0]]])
    assert on_flipped_hull(points, np.zeros(3), 100.0)[-1]


@pytest.fixture(scope="module")
def chair_view():
    """A shipped chair's 2,048 points prepared, one camera, and the splats' answer alone (no hull test)."""
    mesh = zo.load_mesh(ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off")
    points, _ = zo.sample_surface(mesh, 2_048, seed=0)
    surfels = zo.point_surfels(points)
    camera = zo.camera_on_sphere(20.0, 60.0)
    return points, surfels, camera, surfels.visible(camera, hull_test=False)


def test_a_view_of_few_enough_points_is_the_splats_veto_and_of_more_the_splats_alone(chair_view, monkeypatch):
    points, surfels, camera, alone = chair_view
    expected = hull_veto(points, alone, camera.eye, HULL_RADIUS_FACTOR_PER_POINT * len(points))
    assert np.array_equal(surfels.visible(camera), expected)
    assert np.count_nonzero(alone & ~expected) > 0  # the veto decides something on a chair
    monkeypatch.setattr(point_splats, "HULL_VETO_MAX_POINTS", len(points) - 1)
    assert np.array_equal(surfels.visible(camera), alone)
    assert HULL_VETO_MAX_POINTS >= 10_000


def test_the_hull_test_is_taken_always_or_never_when_asked(chair_view, monkeypatch):
    points, surfels, camera, alone = chair_view
    monkeypatch.setattr(point_splats, "HULL_VETO_MAX_POINTS", -1)
    assert np.array_equal(surfels.visible(camera), alone)  # hull_test=False is the splats alone
    assert np.array_equal(surfels.visible(camera, hull_test=True), hull_veto(points, alone, camera.eye, 0.5 * len(points)))
    assert np.array_equal(zo.visible_mask_points(points, camera, hull_test=True), surfels.visible(camera, hull_test=True))
    with pytest.raises(ArgumentTypeError, match="hull_test"):
        surfels.visible(camera, hull_test=1)
