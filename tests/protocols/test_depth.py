"""Depth images, back-projection and the ``depth`` protocol (zbuf_occlude.protocols.depth*)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.cameras import camera_on_sphere
from zbuf_occlude.io.clouds import read_h5_clouds
from zbuf_occlude.protocols import (
    PinholeView,
    ProtocolOptions,
    back_project,
    downsample,
    get_protocol,
    project,
    read_arrays_h5,
    render_depth_image,
    run_protocol,
)

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
CHAIR = SAMPLES / "chair" / "train" / "chair_0001.off"


@pytest.fixture(scope="module")
def chair():
    return zo.load_mesh(CHAIR)


def _distance_to_faces(points, mesh, face):
    closest = trimesh.triangles.closest_point(np.asarray(mesh.triangles)[face], points)
    return np.linalg.norm(closest - points, axis=1)


@pytest.mark.parametrize("el,az", [(30.0, 40.0), (-60.0, 200.0), (85.0, 10.0)])
def test_back_projected_pixels_lie_on_their_faces(chair, el, az):
    view = PinholeView.from_camera(camera_on_sphere(el, az, 3.0, resolution=96))
    image = render_depth_image(chair, view)
    points, _, pixels = back_project(image.depth, view.K, view.extrinsics)
    assert len(points) > 100
    face = image.face_index[pixels[:, 1], pixels[:, 0]]
    assert (face >= 0).all()
    # the only error is the float32 rounding of the depth: half an ulp along the ray
    ray_len = np.linalg.norm(points - view.center, axis=1)
    bound = ray_len * 2.0**-24 + 1e-12
    assert (_distance_to_faces(points, chair, face) <= bound).all()


def test_depth_of_a_plane_is_exact():
    # a square in z = 0.25 seen from straight above at distance 3: depth 2.75 at every hit pixel
    square = trimesh.Trimesh([[-0.5, -0.5, 0.25], [0.5, -0.5, 0.25], [0.5, 0.5, 0.25], [-0.5, 0.5, 0.25]], [[0, 1, 2], [0, 2, 3]])
    view = PinholeView.from_camera(camera_on_sphere(90.0, 0.0, 3.0, resolution=64))
    image = render_depth_image(square, view)
    hit = image.depth > 0
    assert hit.sum() > 0.2 * hit.size
    assert np.allclose(image.depth[hit], 2.75, rtol=2.0**-23, atol=0)
    assert (image.face_index[~hit] == -1).all()


def test_project_inverts_back_project(chair):
    view = PinholeView.from_camera(camera_on_sphere(20.0, 130.0, 3.0, resolution=80))
    image = render_depth_image(chair, view)
    points, cam, pixels = back_project(image.depth, view.K, view.extrinsics)
    uv, z = project(points, view.K, view.extrinsics)
    assert np.abs(uv - pixels).max() < 1e-9
    assert np.allclose(z, image.depth[pixels[:, 1], pixels[:, 0]], rtol=1e-12)
    assert np.allclose(points @ view.extrinsics[:, :3].T + view.extrinsics[:, 3], cam, atol=1e-12)


def test_pinhole_view_matches_the_camera(chair):
    camera = camera_on_sphere(10.0, 70.0, 4.0, resolution=(120, 90))
    view = PinholeView.from_camera(camera)
    pts = np.asarray(chair.vertices)[:50]
    uv_cam, z_cam = camera.project(pts)
    uv, z = project(pts, view.K, view.extrinsics)
    # one convention (OpenCV, pixel centres at integers): the same K, the same pixels
    assert np.array_equal(view.K, camera.K)
    assert np.allclose(uv, uv_cam, atol=1e-9) and np.allclose(z, z_cam, atol=1e-12)
    assert np.allclose(PinholeView.from_pose(view.K, view.camera_to_world, 120, 90).extrinsics, view.extrinsics, atol=1e-12)
    assert np.allclose(view.center, camera.eye, atol=1e-12)


def test_pinhole_view_rejects_a_reflection():
    with pytest.raises(InvalidInputError, match="rotation"):
        PinholeView(np.diag([10.0, 10.0, 1.0]), np.column_stack([np.diag([1.0, 1.0, -1.0]), np.zeros(3)]), 8, 8)


@settings(max_examples=25, deadline=None)
@given(n=st.integers(1, 300), k=st.integers(1, 200), method=st.sampled_from(["random", "fps"]), seed=st.integers(0, 2**16))
def test_downsample_takes_every_point_before_repeating(n, k, method, seed):
    pts = np.random.default_rng(seed).normal(size=(n, 3))
    idx = downsample(pts, k, np.random.default_rng(seed), method)
    assert len(idx) == k and idx.min() >= 0 and idx.max() < n
    assert len(np.unique(idx)) == min(n, k)


def test_fps_spreads_points_more_than_random():
    pts = np.random.default_rng(0).random((2000, 3))
    dmin = []
    for method in ("random", "fps"):
        sub = pts[downsample(pts, 64, np.random.default_rng(1), method)]
        d = np.linalg.norm(sub[:, None] - sub[None], axis=2) + np.eye(64) * 9
        dmin.append(d.min())
    assert dmin[1] > 2 * dmin[0]


def test_depth_protocol_shard(tmp_path, chair):
    opts = ProtocolOptions(views="30:0,-20:150", resolution=64, n_points=256, normals=True, camera_frame=True, complete_points=500)
    run = run_protocol(get_protocol("depth"), [CHAIR], tmp_path, opts, progress=False)
    assert run.done == 1 and not run.failures
    shard = next((tmp_path / "shards").glob("*.h5"))
    d = read_arrays_h5(shard)
    assert d["depth"].shape == (2, 64, 64) and d["depth"].dtype == np.float32
    assert d["K"].shape == (2, 3, 3) and d["extrinsics"].shape == (2, 3, 4)
    assert d["data"].shape == (2, 256, 3) and d["complete"].shape == (500, 3)
    for v in range(2):
        rt = d["extrinsics"][v]
        assert np.allclose(d["data"][v] @ rt[:, :3].T + rt[:, 3], d["camera_points"][v], atol=1e-5)
        assert np.allclose(d["normals"][v], chair.face_normals[d["face_index"][v]], atol=1e-6)
        assert (_distance_to_faces(d["data"][v].astype(np.float64), chair, d["face_index"][v]) < 1e-6).all()
        assert d["n_visible"][v] == (d["depth"][v] > 0).sum()
    clouds = read_h5_clouds(shard)  # the io reader reads the clouds of a depth shard
    assert [c.elevation_deg for c in clouds] == [30.0, -20.0] and clouds[0].points.shape == (256, 3)
    # resume: the shard is kept; other options are refused
    assert run_protocol(get_protocol("depth"), [CHAIR], tmp_path, opts, progress=False).resumed == 1
    with pytest.raises(InvalidInputError, match="other options"):
        run_protocol(get_protocol("depth"), [CHAIR], tmp_path, ProtocolOptions(resolution=32), progress=False)
    # other meshes would resume from the chair's shard 0: refused too
    with pytest.raises(InvalidInputError, match="other options or meshes"):
        run_protocol(get_protocol("depth"), [SAMPLES / "stool"], tmp_path, opts, progress=False)
    run = run_protocol(get_protocol("depth"), [SAMPLES / "stool"], tmp_path, opts, progress=False, overwrite=True)
    assert run.done == 1 and run.resumed == 0 and "stool" in read_arrays_h5(shard)["source"][0]


def test_depth_protocol_rejects_bad_options(tmp_path):
    with pytest.raises(InvalidInputError, match="'nearest'"):
        run_protocol(get_protocol("depth"), [CHAIR], tmp_path, ProtocolOptions(downsample="nearest"), progress=False)
    with pytest.raises(InvalidInputError, match="'bogus'"):
        get_protocol("bogus")


def test_empty_views_give_zero_clouds_and_all_empty_is_an_error(chair):
    from zbuf_occlude.protocols.depth_views import depth_views

    seen = PinholeView.from_camera(camera_on_sphere(10.0, 20.0, 3.0, resolution=32))
    # the same camera turned around (180° about its y axis): it looks away from the object
    flip = np.diag([-1.0, 1.0, -1.0])
    away = PinholeView(seen.K, np.column_stack([flip @ seen.extrinsics[:, :3], flip @ seen.extrinsics[:, 3]]), 32, 32)
    out = depth_views(chair, [seen, away], n_points=64, rng=np.random.default_rng(0))
    assert out["n_visible"][0] > 0 and out["n_visible"][1] == 0
    assert not out["data"][1].any() and out["data"].shape == (2, 64, 3)
    with pytest.raises(InvalidInputError, match="outside every view"):
        depth_views(chair, [away], n_points=64, rng=np.random.default_rng(0))
