"""The point-splat kernels (zbuf_occlude.visibility.point_kernels): the splatting of each disk in its
box equals testing every pixel of the image, the threaded kernels equal the serial ones bit
for bit, and a winner at a point's own depth is its own sheet (a plate thinner than the normals'
neighbourhood)."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numba
import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.visibility import point_kernels as kernels
from zbuf_occlude.visibility.metrics import agreement


def _every_pixel(cam, normal, radius, pix, x0, y0, width, height):
    """The z-buffer of :func:`splat_surfels` by its definition: every surfel against every pixel."""
    depth = np.full((height, width), np.inf)
    ids = np.full((height, width), -1, np.int32)
    x = x0 + (np.arange(width) + 0.5) * pix
    y = y0 + (np.arange(height) + 0.5) * pix
    x, y = np.meshgrid(x, y)
    for k in range(len(cam)):
        q, n, r = cam[k], normal[k], radius[k]
        if q[2] - r <= 0.0 or r <= 0.0:
            continue
        # the kernel's own arithmetic, term by term and in its order, in float64 elementwise numpy:
        # `n @ q` is BLAS's ddot, which sums in another order (OpenBLAS's Prescott kernel) or fuses
        # a multiply and an add into one rounding (FMA, its SkylakeX kernel), and a depth one ulp off
        # moves a tie's winner. numba (fastmath=False) never fuses a*b + c: _splat_rows' assembly has
        # no vfmadd on an AVX2+FMA host (znver3), nor compiled for skylake-avx512 (NUMBA_CPU_NAME).
        nq = n[0] * q[0] + n[1] * q[1] + n[2] * q[2]
        den = n[0] * x + n[1] * y + n[2]
        w2 = (nq * x - den * q[0]) ** 2 + (nq * y - den * q[1]) ** 2 + (nq - den * q[2]) ** 2
        hit = (den * den >= kernels.EDGE_ON_COS2 * (x * x + y * y + 1.0)) & (w2 <= r * r * den * den)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = nq / den
        better = hit & (t < depth)
        depth[better], ids[better] = t[better], k
    return depth, ids


@st.composite
def disks(draw):
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    n = draw(st.integers(1, 40))
    cam = np.column_stack([rng.uniform(-0.5, 0.5, n), rng.uniform(-0.5, 0.5, n), rng.uniform(1.5, 3.0, n)])
    normal = rng.normal(size=(n, 3))
    if draw(st.booleans()):  # some nearly edge-on to their rays: the span's quadratic degenerates
        normal[: n // 2] = np.cross(cam[: n // 2], rng.normal(size=(n // 2, 3))) + 1e-3 * rng.normal(size=(n // 2, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    radius = rng.uniform(0.002, 0.2, n) * draw(st.sampled_from([0.1, 1.0, 5.0]))
    size = draw(st.integers(1, 60))
    pix = 0.6 / size
    return cam, normal, radius, pix, -0.3, -0.3 + draw(st.floats(-0.05, 0.05)), size, size + draw(st.integers(0, 7))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(disks())
def test_the_splatting_covers_what_every_pixel_would(case):
    depth, ids = kernels.splat_surfels(*case)
    want_depth, want_ids = _every_pixel(*case)
    np.testing.assert_array_equal(ids, want_ids)
    np.testing.assert_array_equal(depth, want_depth)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(disks(), st.integers(1, 9))
def test_the_threaded_splatting_gives_the_same_buffers_in_any_number_of_bands(case, bands):
    depth, ids = kernels.splat_surfels(*case)
    threaded_depth, threaded_ids = kernels.splat_surfels_threaded(*case, bands)
    np.testing.assert_array_equal(threaded_ids, ids)
    np.testing.assert_array_equal(threaded_depth, depth)


@pytest.fixture(scope="module")
def chair():
    mesh = zo.load_mesh(Path(__file__).resolve().parents[2] / "data" / "samples" / "chair" / "train" / "chair_0001.off")
    points, _ = zo.sample_surface(mesh, 3_000, seed=0)
    return zo.point_surfels(points)


def test_a_view_on_threads_is_the_view_on_one(chair, monkeypatch):
    cameras = [zo.camera_on_sphere(el, az) for el, az in zo.view_schedule("fibonacci:4")]
    serial = [chair.visible(c) for c in cameras]
    monkeypatch.setattr(kernels, "THREADED_MIN_POINTS", 1)
    with kernels.threads_for(len(chair.points)) as threads:
        assert threads == numba.get_num_threads()
    for camera, mask in zip(cameras, serial):
        np.testing.assert_array_equal(chair.visible(camera), mask)


def test_threads_only_for_large_clouds_and_when_numba_has_them(monkeypatch):
    with kernels.threads_for(kernels.THREADED_MIN_POINTS - 1) as threads:
        assert threads == 1
    monkeypatch.setattr(numba, "get_num_threads", lambda: 1)
    with kernels.threads_for(10**6) as threads:
        assert threads == 1


def test_threads_are_not_shared_between_python_threads_nor_after_a_fork(monkeypatch):
    monkeypatch.setattr(numba, "get_num_threads", lambda: 4)
    # another caller while a threaded view runs
    with kernels.threads_for(10**6) as outer, kernels.threads_for(10**6) as inner:
        assert (outer, inner) == (4, 1)
    with kernels.threads_for(10**6) as again:
        assert again == 4  # released
    monkeypatch.setattr(kernels, "_threads_pid", [os.getpid() + 1])  # a parent ran them, then forked
    with kernels.threads_for(10**6) as child:
        assert child == 1


def test_a_plate_thinner_than_the_normals_neighbourhood_shows_its_top_face():
    # without normals, the two faces of a plate 0.005 thick (a third of the spacing) tilt the
    # estimated normals by tens of degrees; a winner at the point's own depth is its own sheet
    plate = trimesh.creation.box(extents=(1.0, 1.0, 0.005))
    points, face_index = zo.sample_surface(plate, 10_000, seed=2)
    top = plate.face_normals[face_index][:, 2] > 0.9
    surfels = zo.point_surfels(points)
    for elevation, least in ((30.0, 0.88), (60.0, 0.93)):
        camera = zo.camera_on_sphere(elevation, 20.0)
        # convex: a point is visible iff its face faces the eye
        truth = np.einsum("ij,ij->i", plate.face_normals[face_index], camera.eye - points) > 0
        visible = surfels.visible(camera)
        # measured 0.897 and 0.943 of the top face (0.825 and 0.830 without the depth slack)
        assert visible[top].mean() >= least
        assert agreement(visible, truth)["accuracy"] >= least - 0.03  # measured 0.869 and 0.900


def _tilted_winner(normals):
    """Point 0 faces the camera 10 away; point 1 stands 0.2 spacings in front of it and 0.6 to the
    side, its disk (radius 0.7) tilted 30° so that it just covers point 0's pixel, about 0.5 in
    front (camera frame); beyond that pixel point 0's own disk shows, so no gap test hides it."""
    theta = np.radians(30.0)
    cam = np.array([[0.0, 0.0, 10.0], [0.6, 0.0, 9.8]])
    normal = np.array([[0.0, 0.0, -1.0], [np.sin(theta), 0.0, -np.cos(theta)]])
    radius, spacing = np.array([1.0, 0.7]), np.ones(2)
    box, size = (0.01, -0.5, -0.5), 100
    depth, ids = kernels.splat_surfels(cam, normal, radius, *box, size, size)
    assert ids[50, 50] == 1 and 10.0 - depth[50, 50] > 0.5  # the tilted disk wins point 0's pixel, far in front
    return kernels.decide(cam, normal, radius, spacing, depth, ids, box, 0.05, 0.9, normals, np.zeros(2, dtype=bool))


def test_with_estimated_normals_a_winner_whose_centre_is_within_the_depth_slack_is_the_points_own_sheet():
    # an estimated normal off by 30° tilts its disk about 0.5 spacings toward the camera; its centre stands 0.2 in front
    assert _tilted_winner(kernels.NORMALS_ESTIMATED)[0]
    # given normals are exact: the disk is the surface, and it hides the point
    assert not _tilted_winner(kernels.NORMALS_GIVEN)[0]
    assert not _tilted_winner(kernels.NORMALS_ORIENTED)[0]


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**31 - 1), st.floats(-80.0, 80.0), st.floats(0.0, 360.0))
def test_estimated_normals_only_ever_add_visible_points(seed, elevation, azimuth):
    # the winner's centre is a second depth a point may be within the slack of: never a reason to hide (a law of
    # the splats' decision; the hull test after it takes the hull of what they keep, and more kept points may hide more)
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(400, 3)) * rng.uniform(0.05, 1.0, 3)
    surfels = zo.point_surfels(points)
    given = dataclasses.replace(surfels, estimated=False)
    camera = zo.camera_on_sphere(elevation, azimuth)
    estimated, exact = surfels.visible(camera, hull_test=False), given.visible(camera, hull_test=False)
    assert not (exact & ~estimated).any()
