"""PCN's protocol against the recipe's formulas (wentaoyuan/pcn, render/render_depth.py, render/process_exr.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

import zbuf_occlude as zo
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.protocols import ProtocolOptions, get_protocol, pcn, project, read_arrays_h5, run_protocol

CHAIR = Path(__file__).resolve().parents[2] / "data" / "samples" / "chair" / "train" / "chair_0001.off"


def _their_random_pose():  # render_depth.py::random_pose, global np.random as they use it
    angle_x = np.random.uniform() * 2 * np.pi
    angle_y = np.random.uniform() * 2 * np.pi
    angle_z = np.random.uniform() * 2 * np.pi
    Rx = np.array([[1, 0, 0], [0, np.cos(angle_x), -np.sin(angle_x)], [0, np.sin(angle_x), np.cos(angle_x)]])
    Ry = np.array([[np.cos(angle_y), 0, np.sin(angle_y)], [0, 1, 0], [-np.sin(angle_y), 0, np.cos(angle_y)]])
    Rz = np.array([[np.cos(angle_z), -np.sin(angle_z), 0], [np.sin(angle_z), np.cos(angle_z), 0], [0, 0, 1]])
    R = np.dot(Rz, np.dot(Ry, Rx))
    return np.concatenate([np.concatenate([R, np.expand_dims(R[:, 2], 1)], 1), [[0, 0, 0, 1]]], 0)


@pytest.fixture(scope="module")
def chair():
    return pcn.pcn_mesh(zo.load_mesh(CHAIR))


@pytest.mark.parametrize("seed", [0, 1, 99])
def test_poses_are_theirs(seed):
    np.random.seed(seed)
    theirs = [_their_random_pose() for _ in range(8)]
    rs = np.random.RandomState(seed)
    for t in theirs:
        pose = pcn.random_pose(rs)
        assert np.abs(pose - t).max() < 1e-12
        # camera 1 unit from the origin, its −z axis (Blender's view direction) towards it
        assert abs(np.linalg.norm(pose[:3, 3]) - 1.0) < 1e-12
        assert np.isclose(-pose[:3, 2] @ (-pose[:3, 3]), 1.0, atol=1e-12)


def test_intrinsics_are_theirs():
    assert np.array_equal(pcn.intrinsics(), [[100, 0, 80], [0, 100, 60], [0, 0, 1]])
    # Blender's horizontal angle 2·atan(W/2/f) and the OpenCV focal length agree
    K = pcn.opencv_intrinsics()
    assert np.isclose(2 * np.arctan(pcn.WIDTH / 2 / K[0, 0]), 2 * np.arctan(80 / 100), atol=1e-15)


def test_mesh_is_y_up_with_unit_diagonal():
    m = zo.load_mesh(CHAIR)
    p = pcn.pcn_mesh(m)
    lo, hi = p.vertices.min(0), p.vertices.max(0)
    assert np.isclose(np.linalg.norm(hi - lo), 1.0) and np.allclose(lo + hi, 0, atol=1e-12)
    ext = m.vertices.max(0) - m.vertices.min(0)
    assert np.allclose((hi - lo) * np.linalg.norm(ext), ext[[0, 2, 1]])  # y extent is the old z extent
    # z up becomes y up (not down), x stays: (x, y, z) → (x, z, −y)
    assert np.argmax(p.vertices[:, 1]) == np.argmax(m.vertices[:, 2]) and np.argmax(p.vertices[:, 0]) == np.argmax(m.vertices[:, 0])
    with pytest.raises(InvalidInputError, match="'x'"):
        pcn.pcn_mesh(m, "x")


def test_partial_points_are_theirs_half_a_pixel_off(chair):
    views = pcn.pcn_views(chair, np.random.RandomState(3), n_views=3)
    for i in range(3):
        part = views["partial"][views["partial_offsets"][i] : views["partial_offsets"][i + 1]].astype(np.float64)
        depth = views["depth"][i]
        # the recipe's own formula on our depth image gives our partial cloud
        assert np.allclose(part, pcn.depth2pcd(depth, pcn.intrinsics(), views["pose"][i]), atol=1e-6)
        # ... whose points project half a pixel left of and below their pixel's centre
        uv, z = project(part, views["K_opencv"], views["extrinsics"][i])
        rows, cols = np.nonzero(np.flipud(depth) > 0)
        u, v = cols, depth.shape[0] - 1 - rows
        assert np.abs(uv[:, 0] - (u - 0.5)).max() < 1e-3 and np.abs(uv[:, 1] - (v + 0.5)).max() < 1e-3
        assert np.allclose(z, depth[v, u], rtol=1e-6)
        # and with the pixel centres (cx = W/2 − ½ in depth2pcd's bottom-up rows) the points lie on their faces
        exact = pcn.depth2pcd(depth, pcn.opencv_intrinsics(), views["pose"][i])
        face = views["partial_face_index"][views["partial_offsets"][i] : views["partial_offsets"][i + 1]]
        closest = trimesh.triangles.closest_point(np.asarray(chair.triangles)[face], exact)
        dist = np.linalg.norm(closest - exact, axis=1)
        assert (dist < 4 * 2.0**-24 * 2.0).mean() > 0.998 and dist.max() < 1e-4


def test_protocol_writes_pairs(tmp_path):
    run = run_protocol(get_protocol("pcn"), [CHAIR], tmp_path, ProtocolOptions(seed=5), progress=False)
    assert run.done == 1 and not run.failures
    d = read_arrays_h5(next((tmp_path / "shards").glob("pcn_*.h5")))
    assert d["depth"].shape == (8, 120, 160) and d["pose"].shape == (8, 4, 4) and d["extrinsics"].shape == (8, 3, 4)
    assert d["complete"].shape == (pcn.COMPLETE_POINTS, 3)
    counts = (d["depth"] > 0).reshape(8, -1).sum(1)
    assert np.array_equal(np.diff(d["partial_offsets"]), counts)
    assert len(d["partial"]) == len(d["partial_face_index"]) == counts.sum()
    for pose, ext in zip(d["pose"], d["extrinsics"]):  # the two camera conventions describe one camera
        assert np.allclose(np.linalg.inv(pose @ np.diag([1.0, -1, -1, 1]))[:3], ext, atol=1e-12)
    # same seed, same bytes
    again = run_protocol(get_protocol("pcn"), [CHAIR], tmp_path / "again", ProtocolOptions(seed=5), progress=False)
    assert again.done == 1
    d2 = read_arrays_h5(next((tmp_path / "again" / "shards").glob("pcn_*.h5")))
    assert np.array_equal(d["partial"], d2["partial"]) and np.array_equal(d["complete"], d2["complete"])
