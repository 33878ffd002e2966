"""Cameras and pose schedules (Sryamkin et al. 2023, §3.3, §4.1, Eq. 11-12)."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.errors import CameraError, InvalidInputError

UNIT_BOX_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])


def test_paper100_has_the_papers_counts_and_angles():
    poses = zo.view_schedule("paper100")
    assert len(poses) == 100
    per_elevation = Counter(el for el, _ in poses)
    for i in range(1, 20):
        el = (i - 1) * 10 - 90
        assert per_elevation[el] == min(i, 20 - i)
        azimuths = sorted(az for e, az in poses if e == el)
        assert np.allclose(np.diff(azimuths), 360.0 / min(i, 20 - i)) if len(azimuths) > 1 else azimuths == [0.0]


def test_grid25_is_the_product_of_five_elevations_and_five_azimuths():
    poses = zo.view_schedule("grid25")
    assert sorted(set(el for el, _ in poses)) == [-80, -40, 0, 40, 80]
    assert sorted(set(az for _, az in poses)) == [0, 72, 144, 216, 288]
    assert len(set(poses)) == 25


def test_fibonacci_is_near_uniform_on_the_sphere():
    poses = zo.view_schedule("fibonacci:400")
    assert len(poses) == 400
    z = np.sin(np.radians([el for el, _ in poses]))
    # uniform on the sphere <=> z uniform on [-1, 1]: mean 0, variance 1/3
    assert abs(z.mean()) < 0.01 and abs(z.var() - 1 / 3) < 0.01


def test_explicit_list_and_bad_specs():
    assert zo.view_schedule("30:45, -90:0") == [(30.0, 45.0), (-90.0, 0.0)]
    for bad in ("", "paper99", "fibonacci:0", "fibonacci:x", "30", "30:45:1", "100:0", "nan:0"):
        with pytest.raises(InvalidInputError):
            zo.view_schedule(bad)


def test_camera_on_sphere_uses_the_matlab_convention():
    cam = zo.camera_on_sphere(30.0, 45.0, 4.0)
    el, az = math.radians(30), math.radians(45)
    assert np.allclose(cam.eye, 4 * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]))
    uv, depth = cam.project(np.zeros((1, 3)))
    assert np.allclose(uv, [[(cam.width - 1) / 2, (cam.height - 1) / 2]]) and np.isclose(depth[0], 4.0)
    # world z (up) projects upwards in the image (smaller row index)
    uv_up, _ = cam.project(np.array([[0.0, 0.0, 0.1]]))
    assert uv_up[0, 1] < (cam.height - 1) / 2


@pytest.mark.parametrize("elevation", [-90.0, 90.0])
@pytest.mark.parametrize("azimuth", [0.0, 123.0])
def test_poles_are_well_defined(elevation, azimuth):
    cam = zo.camera_on_sphere(elevation, azimuth, 4.0)
    r = cam.view_matrix[:3, :3]
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.all(np.isfinite(cam.view_matrix))
    assert cam.in_frustum(UNIT_BOX_CORNERS).all()


@settings(max_examples=60, deadline=None)
@given(el=st.floats(-90, 90), az=st.floats(-720, 720), radius=st.floats(1.0, 50.0), res=st.integers(16, 2048))
def test_projection_matrix_agrees_with_K_and_the_whole_box_is_in_view(el, az, radius, res):
    cam = zo.camera_on_sphere(el, az, radius, resolution=res)
    assert cam.in_frustum(UNIT_BOX_CORNERS * 0.999).all()
    pts = np.random.default_rng(0).uniform(-0.5, 0.5, (50, 3))
    clip = np.c_[pts, np.ones(len(pts))] @ (cam.projection_matrix @ cam.view_matrix).T
    ndc = clip[:, :3] / clip[:, 3:]
    uv_gl = np.c_[(ndc[:, 0] + 1) / 2 * cam.width, (1 - ndc[:, 1]) / 2 * cam.height]  # window coordinates
    uv_cv, depth = cam.project(pts)
    assert np.allclose(uv_gl - 0.5, uv_cv, atol=1e-6 * res)  # GL's pixel centres are at +0.5, OpenCV's at integers
    assert np.allclose(depth, clip[:, 3])  # w_clip == linear depth
    assert np.all((ndc[:, 2] > -1) & (ndc[:, 2] < 1))  # tight near/far still contain the box


def test_camera_inside_the_object_and_bad_poses_are_refused():
    with pytest.raises(CameraError, match="inside"):
        zo.camera_on_sphere(0.0, 0.0, 0.5)
    with pytest.raises(CameraError):
        zo.camera_on_sphere(91.0, 0.0)
    with pytest.raises(CameraError):
        zo.camera_on_sphere(float("nan"), 0.0)
    with pytest.raises(CameraError):
        zo.Camera(eye=np.zeros(3), target=np.zeros(3), up=np.array([0, 0, 1.0]), yfov_deg=30, width=8, height=8, znear=1, zfar=2)
    with pytest.raises(CameraError):
        zo.Camera(eye=np.array([0, 0, 4.0]), target=np.zeros(3), up=np.array([0, 0, 1.0]), yfov_deg=30, width=8, height=8, znear=1, zfar=2)


def test_schedule_cameras_default_radius_is_four_max_dimensions():
    cams = zo.cameras_from_schedule("grid25", resolution=64)
    assert len(cams) == 25
    assert all(np.isclose(np.linalg.norm(c.eye), 4.0) for c in cams)


# -- exact values and boundaries (mutation testing, docs/development/testing.md) -----------------------------
def _cam(**kw):
    args = dict(eye=np.array([0.0, 0.0, 4.0]), target=np.zeros(3), up=np.array([0.0, 1.0, 0.0]), yfov_deg=60.0,
                width=40, height=20, znear=1.0, zfar=10.0)  # fmt: skip
    return zo.Camera(**{**args, **kw})


def test_camera_checks_every_bound_and_keeps_exact_values():
    for bad in (dict(eye=np.array([np.nan, 0, 4.0])), dict(target=np.array([0, np.inf, 0.0])), dict(up=np.array([0, np.nan, 1.0])),
                dict(yfov_deg=0.0), dict(yfov_deg=180.0), dict(width=0), dict(height=0), dict(znear=0.0), dict(znear=10.0),
                dict(zfar=float("inf")), dict(up=np.array([0.0, 0.0, 2.0]))):  # fmt: skip
        with pytest.raises(CameraError):
            _cam(**bad)
    cam = _cam(yfov_deg=179.9, width=1, height=1, znear=1e-9)  # the legal extremes
    assert cam.resolution == (1, 1)
    cam = _cam(width=40.0, height=20.0, up=[0, 3.0, 0])  # ints and any up length
    assert (cam.width, cam.height) == (40, 20) and isinstance(cam.width, int) and np.array_equal(cam.up, [0, 3.0, 0])
    # looking down -z from z = 4 with y up: the OpenGL view is a pure translation
    assert np.allclose(cam.view_matrix, [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -4], [0, 0, 0, 1]])
    assert np.allclose(cam.extrinsics, [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 4]])


def test_intrinsics_and_projection_have_the_textbook_values():
    cam = _cam()
    f = 10.0 / math.tan(math.radians(30.0))  # half height / tan(half fov)
    assert math.isclose(cam.focal_px, f) and np.allclose(cam.K, [[f, 0, 19.5], [0, f, 9.5], [0, 0, 1]])
    t = 1 / math.tan(math.radians(30.0))
    expected = np.array([[t / 2, 0, 0, 0], [0, t, 0, 0], [0, 0, -11 / 9, -20 / 9], [0, 0, -1, 0]])
    assert np.allclose(cam.projection_matrix, expected)
    # a point 1 right, 0.5 up, 2 in front of the camera
    uv, depth = cam.project(np.array([[1.0, 0.5, 2.0]]))
    assert np.allclose(depth, [2.0]) and np.allclose(uv, [[19.5 + f / 2, 9.5 - f / 4]])
    assert np.allclose(cam.pixel_size_at(np.array([2.0, 4.0])), [2 / f, 4 / f])


@pytest.mark.parametrize("size", [(640, 480), (1080, 720), (160, 120), (7, 5), (1, 1)])
def test_K_is_opencv_and_open3d_pixel_centres_at_integers(size):
    """One convention for every intrinsics in the package: OpenCV's, as Open3D's
    ``PinholeCameraIntrinsic`` (its PrimeSense default, 640 x 480, has cx = 319.5, cy = 239.5)
    and ModelNet40-C's ``get_default_camera_intrinsic`` (cx = W/2 - 0.5) have it."""
    from zbuf_occlude.protocols import PinholeView, project
    from zbuf_occlude.protocols.modelnet40c import intrinsics as modelnet40c_intrinsics

    width, height = size
    cam = zo.camera_on_sphere(25.0, 60.0, 4.0, resolution=size)
    assert cam.K[0, 2] == (width - 1) / 2 and cam.K[1, 2] == (height - 1) / 2
    if size == (640, 480):
        assert (cam.K[0, 2], cam.K[1, 2]) == (319.5, 239.5)  # Open3D's PrimeSenseDefault
    assert np.array_equal(modelnet40c_intrinsics(width, height)[:2, 2], cam.K[:2, 2])
    # K applied by hand, Camera.project and the protocols' project give the same pixels
    pts = np.random.default_rng(1).uniform(-0.5, 0.5, (20, 3))
    cam_pts = pts @ cam.extrinsics[:, :3].T + cam.extrinsics[:, 3]
    by_hand = (cam_pts @ cam.K.T)[:, :2] / cam_pts[:, 2:]
    uv, _ = cam.project(pts)
    view = PinholeView.from_camera(cam)
    assert np.allclose(uv, by_hand, atol=1e-9) and np.array_equal(view.K, cam.K)
    assert np.allclose(project(pts, view.K, view.extrinsics)[0], uv, atol=1e-9)
    # the optical axis goes through the image's centre: the middle of the border pixels' outer edges
    assert cam.in_frustum(np.zeros((1, 3)))[0] and np.allclose(cam.project(np.zeros((1, 3)))[0], cam.K[:2, 2])


def test_in_frustum_includes_the_near_far_and_top_left_edges_only():
    cam = _cam()
    f = cam.focal_px

    def at(u, v, depth):  # world point that projects to pixel (u, v) at this depth
        return [(u - 20.0) * depth / f, -(v - 10.0) * depth / f, 4.0 - depth]

    inside = [at(20, 10, 1.0), at(20, 10, 10.0), at(0.0, 0.0, 5.0), at(39.99, 19.99, 5.0)]
    outside = [at(20, 10, 0.999), at(20, 10, 10.001), at(-0.01, 10, 5.0), at(20, -0.01, 5.0), at(40.0, 10, 5.0), at(20, 20.0, 5.0)]
    assert cam.in_frustum(np.array(inside)).tolist() == [True] * 4
    assert cam.in_frustum(np.array(outside)).tolist() == [False] * 6


def test_camera_on_sphere_fits_the_bounding_sphere_with_its_margin():
    cam = zo.camera_on_sphere(0.0, 0.0, 4.0, resolution=(64, 32), bounding_radius=1.0)
    r_fit = 1.02
    assert (cam.width, cam.height) == (64, 32)
    assert math.isclose(cam.yfov_deg, 2 * math.degrees(math.asin(r_fit / 4.0)))
    assert math.isclose(cam.znear, 4.0 - r_fit) and math.isclose(cam.zfar, 4.0 + r_fit)
    assert (cam.elevation_deg, cam.azimuth_deg, cam.radius) == (0.0, 0.0, 4.0)
    assert np.allclose(cam.up, [0, 0, 1]) and np.allclose(cam.target, 0)
    assert zo.camera_on_sphere(0.0, 0.0, 4.0, yfov_deg=20.0).yfov_deg == 20.0
    assert zo.camera_on_sphere(0.0, 0.0, 4.0).resolution == (1024, 1024)
    # up is the tangent of increasing elevation
    cam = zo.camera_on_sphere(30.0, 90.0, 4.0)
    assert np.allclose(cam.up, [0.0, -0.5, math.sqrt(3) / 2])
    # just outside the fitted sphere is legal, on it is not; elevations ±90 are legal
    zo.camera_on_sphere(0.0, 0.0, 1.0201, bounding_radius=1.0)
    with pytest.raises(CameraError):
        zo.camera_on_sphere(0.0, 0.0, 1.02, bounding_radius=1.0)
    for bad in (dict(azimuth_deg=float("inf")), dict(radius=float("nan")), dict(bounding_radius=float("inf")), dict(elevation_deg=-90.01)):
        with pytest.raises(CameraError):
            zo.camera_on_sphere(**{"elevation_deg": 0.0, "azimuth_deg": 0.0, "radius": 4.0, **bad})


def test_schedules_have_their_exact_poses():
    assert zo.view_schedule("paper100")[:4] == [(-90.0, 0.0), (-80.0, 0.0), (-80.0, 180.0), (-70.0, 0.0)]
    assert zo.view_schedule(" grid25 ")[:2] == [(-80.0, 0.0), (-80.0, 72.0)]
    golden = math.pi * (3 - math.sqrt(5))
    fib = zo.view_schedule("fibonacci:3")
    assert np.allclose(
        fib, [(math.degrees(math.asin(1 - 2 * (k + 0.5) / 3)), math.degrees((k * golden) % (2 * math.pi))) for k in range(3)]
    )
    assert zo.view_schedule("fibonacci:1") == [(0.0, 0.0)]
    assert zo.view_schedule("90:0,-90:1,") == [(90.0, 0.0), (-90.0, 1.0)]
    for bad in ("fibonacci:-2", "30:inf", "-90.5:0", "a:b"):
        with pytest.raises(InvalidInputError):
            zo.view_schedule(bad)
    cams = zo.cameras_from_schedule("10:20", 3.0, resolution=16)
    assert [(c.elevation_deg, c.azimuth_deg, c.radius, c.resolution) for c in cams] == [(10.0, 20.0, 3.0, (16, 16))]


def test_camera_stores_float64_vectors_and_int_sizes_whatever_it_is_given():
    cam = _cam(eye=[[0, 0, 4]], target=(0, 0, 0), up=[0, 1, 0], width=40.0, height=20.0, yfov_deg=0.5)  # ints, lists, (1, 3)
    for v in (cam.eye, cam.target, cam.up):
        assert isinstance(v, np.ndarray) and v.dtype == np.float64 and v.shape == (3,)
    assert type(cam.width) is int and type(cam.height) is int and cam.resolution == (40, 20)
    assert cam.pixel_size_at(np.array([2.0], dtype=np.float32)).dtype == np.float64
    for field in ("eye", "target", "up"):  # the message names the bad vector
        with pytest.raises(CameraError, match=f"camera {field} must be finite"):
            _cam(**{field: np.array([0.0, np.nan, 1.0])})


def test_projecting_a_point_in_the_camera_plane_warns_nothing():
    import warnings

    cam = _cam()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        uv, depth = cam.project(np.array([[1.0, 0.0, 4.0], [0.0, 0.0, 4.0]]))  # depth 0: x/0 and 0/0
    assert depth.tolist() == [0.0, 0.0] and np.isinf(uv[0, 0]) and np.isnan(uv[1]).all()
    assert not cam.in_frustum(np.array([[1.0, 0.0, 4.0]])).any()


def test_schedule_and_pose_edge_cases():
    az = np.array([a for _, a in zo.view_schedule("fibonacci:50")])
    assert (az >= 0).all() and (az < 360).all() and az.max() > 300  # wrapped at 360 degrees
    cam = zo.camera_on_sphere(30.0, 0.0, 4.0)
    assert np.allclose(cam.up, [-0.5, 0.0, math.sqrt(3) / 2])
    for bad in ("fibonacci:3:4", "90.5:0"):
        with pytest.raises(InvalidInputError, match="bad view schedule"):
            zo.view_schedule(bad)
    with pytest.raises(InvalidInputError, match="paper100, grid25, fibonacci:N"):
        zo.view_schedule("30")
