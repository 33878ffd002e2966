"""ModelNet40-C's occlusion and LiDAR protocols against the recipe's own formulas.

The ``_their_*`` functions transcribe jiachens/ModelNet40-C (``data/occlusion.py``,
``data/generate_c.py``, ``data/util.py``) with the global ``np.random`` as they use it; the
protocol, with its own ``RandomState``, must give the same numbers for the same seed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

import zbuf_occlude as zo
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.protocols import (
    PinholeView,
    ProtocolOptions,
    back_project,
    get_protocol,
    project,
    render_depth_image,
    run_protocol,
)
from zbuf_occlude.protocols import modelnet40c as mc

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
CHAIR = SAMPLES / "chair" / "train" / "chair_0001.off"


def _their_random_pose(severity):  # occlusion.py::random_pose
    theta = 2 * np.pi * severity / 5
    delta = np.pi / 5
    angle_x = np.random.uniform(2.0 / 3.0 * np.pi, 5.0 / 6.0 * np.pi)
    angle_y = 0
    angle_z = np.random.uniform(theta - delta, theta + delta)
    Rx = np.array([[1, 0, 0], [0, np.cos(angle_x), -np.sin(angle_x)], [0, np.sin(angle_x), np.cos(angle_x)]])
    Ry = np.array([[np.cos(angle_y), 0, np.sin(angle_y)], [0, 1, 0], [-np.sin(angle_y), 0, np.cos(angle_y)]])
    Rz = np.array([[np.cos(angle_z), -np.sin(angle_z), 0], [np.sin(angle_z), np.cos(angle_z), 0], [0, 0, 1]])
    R = np.dot(Rz, np.dot(Ry, Rx))
    t = np.expand_dims(-R[:, 2] * 3.0, 1)
    return np.concatenate([np.concatenate([R.T, -np.dot(R.T, t)], 1), [[0, 0, 0, 1]]], 0)


def _their_lidar_angle_z(severity):  # occlusion.py::lidar_pose, its only draw
    theta = 2 * np.pi * severity / 5
    return np.random.uniform(theta - np.pi / 5, theta + np.pi / 5)


def _their_downsample(points, n_points=1024):  # core_occlusion + occlusion_1 after the depth image
    ratio = int(points.shape[0] / n_points)
    if ratio > 0:
        idx = np.arange(points.shape[0])
        np.random.shuffle(idx)
        points = points[idx][::ratio]  # uniform_down_sample(ratio)
    if points.shape[0] < n_points:
        points = points[np.random.choice(points.shape[0], n_points)]
    return points[:n_points]


@pytest.fixture(scope="module")
def their_chair():
    m = zo.load_mesh(CHAIR)
    return trimesh.Trimesh(mc.normalize(np.asarray(m.vertices)), m.faces, process=False)


@pytest.mark.parametrize("severity", [1, 2, 3, 4, 5])
@pytest.mark.parametrize("seed", [0, 2021])
def test_occlusion_pose_is_theirs(severity, seed):
    np.random.seed(seed)
    theirs = _their_random_pose(severity)
    ours = mc.occlusion_pose(severity, np.random.RandomState(seed))
    assert np.abs(ours - theirs).max() < 1e-12
    # camera 3 units from the origin, looking at it: the origin projects to the principal point
    view = PinholeView(mc.intrinsics(), ours[:3], mc.WIDTH, mc.HEIGHT)
    assert abs(np.linalg.norm(view.center) - 3.0) < 1e-12
    uv, z = project(np.zeros((1, 3)), view.K, view.extrinsics)
    assert np.abs(uv - [[539.5, 359.5]]).max() < 1e-9 and abs(z[0] - 3.0) < 1e-12
    # elevation = angle_x − 90° in [30°, 60°] (z up), azimuth = angle_z + 90° within θ ± 36°
    el = np.degrees(np.arcsin(view.center[2] / 3.0))
    az = np.degrees(np.arctan2(view.center[1], view.center[0]))
    assert 30.0 - 1e-9 <= el <= 60.0 + 1e-9
    assert abs((az - 90.0 - 72.0 * severity + 180.0) % 360.0 - 180.0) <= 36.0 + 1e-9


@pytest.mark.parametrize("severity", [1, 4])
def test_lidar_pose_is_theirs(severity):
    np.random.seed(7)
    angle_z = _their_lidar_angle_z(severity)
    extrinsic, pose = mc.lidar_pose(severity, np.random.RandomState(7))
    R = np.dot(mc._rz(angle_z), np.dot(mc._ry(0), mc._rx(5.0 / 8.0 * np.pi)))
    assert np.abs(pose[:3, :3] - R).max() < 1e-12 and np.abs(pose[:3, 3] + 5 * R[:, 2]).max() < 1e-12
    assert np.abs(extrinsic @ pose - np.eye(4)).max() < 1e-12


def test_intrinsics_are_theirs():
    K = mc.intrinsics(1080, 720)
    assert np.array_equal(K, [[365, 0, 539.5], [0, 365, 359.5], [0, 0, 1]])


@pytest.mark.parametrize("severity", [2, 5])
def test_depth_cloud_follows_their_downsampling(their_chair, severity):
    extrinsic = mc.occlusion_pose(severity, np.random.RandomState(3))
    view = PinholeView(mc.intrinsics(), extrinsic[:3], mc.WIDTH, mc.HEIGHT)
    lifted = back_project(render_depth_image(their_chair, view, cull_back_faces=True).depth, view.K, view.extrinsics)[0]
    for n_points in (1024, len(lifted) + 17):  # the shuffle + every-k path, and the with-replacement path
        np.random.seed(11)
        theirs = _their_downsample(lifted, n_points)
        ours, n_visible = mc.depth_cloud(their_chair, extrinsic, np.random.RandomState(11), n_points=n_points)
        assert n_visible == len(lifted) and np.array_equal(ours, theirs)


def test_occlusion_points_lie_on_the_mesh(their_chair):
    rs = np.random.RandomState(5)
    pts, n_visible = mc.depth_cloud(their_chair, mc.occlusion_pose(3, rs), rs)
    assert pts.shape == (1024, 3) and n_visible > 1024
    _, dist, _ = trimesh.proximity.closest_point(their_chair, pts)
    # depth rounded to float32 (rays shorter than 4); Embree picks the face in float32, so a ray
    # through a crack within ~1e-5 of an edge may land on the face's plane just off the face
    assert (dist < 5 * 2.0**-24 * 4.0).mean() > 0.998 and dist.max() < 1e-4


def test_axis_change_is_minus_x_z_y():
    p = np.random.default_rng(0).normal(size=(20, 3))
    assert np.allclose(mc.to_modelnet40c_axes(p), np.column_stack([-p[:, 0], p[:, 2], p[:, 1]]), atol=1e-15)


def test_normalize_is_theirs():
    p = np.random.default_rng(1).normal(size=(50, 3)) * [3, 1, 2] + 5
    q = mc.normalize(p)
    assert np.allclose((q.max(0) + q.min(0)) / 2, 0, atol=1e-12)
    assert np.isclose((q.max(0) - q.min(0)).max(), 2.0)
    assert np.allclose(q, (p - (p.max(0) + p.min(0)) / 2) * 2 / (p.max(0) - p.min(0))[0])


def test_simulate_lidar_keeps_ring_centres():
    rs = np.random.RandomState(4)
    extrinsic, pose = mc.lidar_pose(2, rs)
    pts = np.random.default_rng(2).uniform(-1, 1, size=(1024, 3))
    out = mc.simulate_lidar(pts, pose, np.random.RandomState(9))
    assert out.shape == (768, 3)
    rel = out - pose[:3, 3]
    polar = np.arctan2(np.linalg.norm(rel[:, :2], axis=1), rel[:, 2])
    rel_in = pts - pose[:3, 3]
    lo = np.arctan2(np.linalg.norm(rel_in[:, :2], axis=1), rel_in[:, 2]).min()
    k = (polar - lo) / mc.RING_STEP_RAD - 0.5  # every kept point sits on a ring centre lo + (k + ½)·1°
    assert np.abs(k - np.round(k)).max() < 1e-6
    # every output point is an input point moved only in polar angle (same radius from the sensor)
    r_in = np.sort(np.linalg.norm(rel_in, axis=1))
    r_out = np.linalg.norm(rel, axis=1)
    assert np.abs(r_in[np.clip(np.searchsorted(r_in, r_out), 0, len(r_in) - 1)] - r_out).min() < 1e-9


def test_back_faces_are_culled_as_open3d_does():
    # two squares, the upper one wound away from a camera above it: Open3D's default culls it
    sq = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]])
    verts = np.vstack([sq + [0, 0, 0.25], sq + [0, 0, -0.25]])
    faces = [[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7]]  # upper: normal -z; lower: +z
    mesh = trimesh.Trimesh(verts, faces, process=False)
    view = PinholeView(np.array([[40.0, 0, 15.5], [0, 40.0, 15.5], [0, 0, 1]]), [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 3]], 32, 32)
    centre = (16, 16)
    assert np.isclose(render_depth_image(mesh, view).depth[centre], 2.75)
    assert np.isclose(render_depth_image(mesh, view, cull_back_faces=True).depth[centre], 3.25)


@pytest.mark.parametrize("protocol,corruption,n", [("modelnet40-c-occlusion", "occlusion", 1024), ("modelnet40-c-lidar", "lidar", 768)])
def test_protocol_writes_their_layout(tmp_path, protocol, corruption, n):
    run = run_protocol(get_protocol(protocol), [CHAIR], tmp_path, ProtocolOptions(severity=3), progress=False)
    assert not run.failures
    data = np.load(tmp_path / f"data_{corruption}_3.npy")
    assert data.shape == (1, n, 3) and data.dtype == np.float32
    label = np.load(tmp_path / "label.npy")
    assert label.shape == (1, 1) and label.dtype == np.uint8 and label[0, 0] == mc.MODELNET40_CLASSES.index("chair")
    if corruption == "occlusion":  # normalised again after the axis change: longest side exactly 2
        assert np.isclose((data[0].max(0) - data[0].min(0)).max(), 2.0)


@pytest.mark.parametrize("severity", [0, 6, "3", 2.5, None])
def test_bad_severity_is_named(tmp_path, severity):
    with pytest.raises(InvalidInputError, match="severity"):
        run_protocol(get_protocol("modelnet40-c-occlusion"), [CHAIR], tmp_path, ProtocolOptions(severity=severity), progress=False)
