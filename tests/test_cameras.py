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
    assert np.allclose(uv, [[cam.width / 2, cam.height / 2]]) and np.isclose(depth[0], 4.0)
    # world z (up) projects upwards in the image (smaller row index)
    uv_up, _ = cam.project(np.array([[0.0, 0.0, 0.1]]))
    assert uv_up[0, 1] < cam.height / 2


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
    uv_gl = np.c_[(ndc[:, 0] + 1) / 2 * cam.width, (1 - ndc[:, 1]) / 2 * cam.height]
    uv_cv, depth = cam.project(pts)
    assert np.allclose(uv_gl, uv_cv, atol=1e-6 * res)
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
