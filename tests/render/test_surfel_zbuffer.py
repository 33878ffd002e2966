"""The GPU surfel z-buffer (zbuf_occlude.render.surfel_zbuffer) against the numba kernel it mirrors,
and the ``backend`` switch of point-only visibility.

The GPU computes with the kernel's float64 operations and breaks ties as it does (the least
``t``, then the lowest id), so the buffers are the kernel's bit for bit, and so are the masks.
These run on Mesa llvmpipe headless, as the other GL tests, and never skip.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.render import surfel_zbuffer
from zbuf_occlude.render.surfel_zbuffer import SLICES, DecisionRule, SurfelZBuffer, shared_surfel_zbuffer, tiles
from zbuf_occlude.visibility import point_kernels
from zbuf_occlude.visibility.point_kernels import EDGE_ON_COS, splat_surfels
from zbuf_occlude.visibility.splat_image import splat_image

#: The image in one tile (the GL's own limit), in bands of whole rows (up to 4,096 pixels a tile),
#: or each row in parts (up to 128 pixels a tile).
PASSES = {"one tile": {}, "bands": {"max_tile_bytes": 8 * 4096}, "row parts": {"max_tile_bytes": 8 * 128}}


def _view(mesh_path, n, pose, normals=False):
    mesh = zo.load_mesh(mesh_path)
    points, face_index = zo.sample_surface(mesh, n, seed=0)
    surfels = zo.point_surfels(points, mesh.face_normals[face_index] if normals else None)
    camera = zo.camera_on_sphere(*pose)
    rotation, translation = camera.extrinsics[:, :3], camera.extrinsics[:, 3]
    cam = surfels.points @ rotation.T + translation
    image = splat_image(cam, surfels.radius, camera.in_frustum(surfels.points), camera)
    return cam, surfels.normals @ rotation.T, surfels.radius, (image.pix, image.x0, image.y0, image.width, image.height)


def _assert_buffers_equal(cam, normal, radius, image, gpu):
    depth_cpu, ids_cpu = splat_surfels(cam, normal, radius, *image)
    depth_gpu, ids_gpu = gpu
    assert depth_gpu.dtype == np.float64 and ids_gpu.dtype == np.int32
    assert np.array_equal(ids_gpu, ids_cpu) and np.array_equal(depth_gpu, depth_cpu)
    return int(np.count_nonzero(ids_cpu >= 0))


def _random_surfels(n=800, seed=0):
    """Disks of random position, tilt and size in front of the camera: no two coplanar."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(2.0, 4.0, n)
    cam = np.stack([rng.uniform(-0.5, 0.5, n) * z, rng.uniform(-0.4, 0.4, n) * z, z], axis=1)
    normal = rng.normal(size=(n, 3)) + [0.0, 0.0, -2.0]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return cam, normal, rng.uniform(0.01, 0.1, n)


@pytest.mark.parametrize("setting", PASSES)
def test_buffers_match_the_cpu_kernel_on_random_disks(setting):
    cam, normal, radius = _random_surfels()
    image = (0.004, -0.6, -0.45, 300, 225)
    with SurfelZBuffer() as zbuffer:
        for name, value in PASSES[setting].items():
            setattr(zbuffer, name, value)
        gpu = zbuffer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)
    assert _assert_buffers_equal(cam, normal, radius, image, gpu) > 0.5 * 300 * 225


@pytest.mark.parametrize("setting", PASSES)
def test_buffers_match_the_cpu_kernel_on_a_sampled_mesh(sample_mesh_files, setting):
    """Neighbours on one flat sheet tie at many pixels (a tenth of them here, decided by
    float64 rounding): the GPU's rounding and its tie rule are the kernel's."""
    chair = next(p for p in sample_mesh_files if "chair" in p.name)
    with SurfelZBuffer() as zbuffer:
        for name, value in PASSES[setting].items():
            setattr(zbuffer, name, value)
        for pose in ((30.0, 45.0), (-20.0, 200.0)):
            cam, normal, radius, image = _view(chair, 2048, pose)
            gpu = zbuffer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)
            assert _assert_buffers_equal(cam, normal, radius, image, gpu) > 1000


@pytest.mark.parametrize("setting", PASSES)
def test_a_surfel_wider_than_the_image_fills_what_the_kernel_fills(setting):
    """A disk just in front of the camera covers a 2,000 × 40 strip: its box spans every column and
    row, each of its invocations tests 40 / SLICES rows, and in tiles it is tested in each; three
    small disks behind it stay hidden where it covers them and show where it does not."""
    pix = 1.0 / 1000
    image = (pix, -0.75, -20 * pix, 2000, 40)

    def at(column: float, row: float, z: float) -> list[float]:  # a point at z seen at pixel (column, row)
        return [z * (image[1] + column * pix), z * (image[2] + row * pix), z]

    # disk 0 faces the camera 0.1 mm beyond its own radius: it spans x/z in ±0.990099, the strip's
    # left three quarters and more; disks 1-3 lie behind its plane, 1 under it, 2 and 3 right of it
    cam = np.array([[0.0, 0.0, 0.0101], at(500, 20, 1.5), at(1900, 5, 2.0), at(1950, 30, 2.0)])
    normal = np.tile([0.0, 0.0, 1.0], (4, 1))
    radius = np.array([0.01, 7 * pix * 1.5, 2.5 * pix * 2.0, 2.5 * pix * 2.0])
    with SurfelZBuffer() as zbuffer:
        for name, value in PASSES[setting].items():
            setattr(zbuffer, name, value)
        depth, ids = zbuffer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)
    depth_cpu, ids_cpu = splat_surfels(cam, normal, radius, *image)
    assert np.array_equal(ids, ids_cpu) and np.array_equal(depth, depth_cpu)
    assert (ids == 0).sum() >= 1700 * 40 > 8 * SLICES and set(np.unique(ids).tolist()) == {-1, 0, 2, 3}


@settings(deadline=None)
@given(width=st.integers(1, 80), height=st.integers(1, 80), max_pixels=st.integers(1, 2000))
def test_tiles_cover_the_image_once_within_the_limit(width, height, max_pixels):
    """Every pixel in exactly one tile, no tile over ``max_pixels``, and whole rows whenever a row fits."""
    covered = np.zeros((height, width), dtype=int)
    for i0, j0, w, h in tiles(width, height, max_pixels):
        assert w * h <= max_pixels and w >= 1 and h >= 1
        assert w == width or (h == 1 and width > max_pixels)
        covered[j0 : j0 + h, i0 : i0 + w] += 1
    assert (covered == 1).all()


def test_nothing_drawable_gives_empty_buffers():
    cam = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 0.005]])  # behind the camera; its sphere crosses z = 0
    normal = np.tile([0.0, 0.0, 1.0], (2, 1))
    radius = np.array([0.1, 0.01])
    depth, ids = shared_surfel_zbuffer().splat(cam, normal, radius, 0.01, -1.0, -1.0, 20, 10, edge_on_cos=EDGE_ON_COS)
    assert depth.shape == (10, 20) and np.isinf(depth).all() and (ids == -1).all()


@pytest.mark.parametrize("n, width, height", [(0, 20, 10), (1, 0, 10), (1, 20, 0)])
def test_no_surfels_or_no_pixels_give_empty_buffers(n, width, height):
    cam, normal, radius = np.tile([0.0, 0.0, 2.0], (n, 1)), np.tile([0.0, 0.0, 1.0], (n, 1)), np.full(n, 0.1)
    depth, ids = shared_surfel_zbuffer().splat(cam, normal, radius, 0.01, -0.1, -0.1, width, height, edge_on_cos=EDGE_ON_COS)
    assert depth.shape == ids.shape == (height, width) and np.isinf(depth).all() and (ids == -1).all()


def test_release_frees_every_gl_object():
    zbuffer = SurfelZBuffer()
    cam, normal, radius = np.array([[0.0, 0.0, 2.0]]), np.array([[0.0, 0.0, 1.0]]), np.array([0.1])
    zbuffer.splat(cam, normal, radius, 0.01, -0.1, -0.1, 20, 20, edge_on_cos=EDGE_ON_COS)
    rule = DecisionRule(0.25, 0.9, False, True, point_kernels.COPLANAR, point_kernels.DEPTH_SLACK, point_kernels.CURVATURE_SLACK, 2.0)
    assert zbuffer.visible(
        cam, normal, radius, np.ones(1), np.zeros(1, bool), (0.01, -0.1, -0.1, 20, 20), edge_on_cos=EDGE_ON_COS, rule=rule
    ).all()
    objects = [zbuffer._shader, zbuffer._resolve, zbuffer._decide, *zbuffer._buffers.values()]
    assert len(objects) == 3 + 9  # the surfels and points, a blank, three keys, the depth, the mask, the staging buffer
    zbuffer.release()
    zbuffer.release()  # twice is fine
    assert all(type(obj.mglo).__name__ == "InvalidObject" for obj in objects)
    with pytest.raises(RuntimeError, match="released"):
        zbuffer.splat(cam, normal, radius, 0.01, -0.1, -0.1, 20, 20, edge_on_cos=EDGE_ON_COS)


@pytest.mark.parametrize("normals", [False, True], ids=["estimated", "given"])
def test_masks_agree_with_the_cpu_backend_on_a_shipped_mesh(sample_mesh_files, normals):
    """The decision reads which surfel wins each point's pixel, and on a flat face many surfels
    tie there to float64 rounding: the GPU breaks each tie as the CPU does."""
    chair = zo.load_mesh(next(p for p in sample_mesh_files if "chair" in p.name))
    points, face_index = zo.sample_surface(chair, 2048, seed=0)
    surfels = zo.point_surfels(points, chair.face_normals[face_index] if normals else None)
    for el, az in zo.view_schedule("fibonacci:16"):
        camera = zo.camera_on_sphere(el, az)
        assert np.array_equal(surfels.visible(camera, backend="gpu"), surfels.visible(camera)), (el, az)


def test_visible_mask_points_takes_the_backend():
    points = np.random.default_rng(0).normal(size=(500, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    camera = zo.camera_on_sphere(20.0, 30.0, 4.0)
    cpu = zo.visible_mask_points(points, camera)
    gpu = zo.visible_mask_points(points, camera, backend="gpu")
    assert gpu.shape == (500,) and gpu.dtype == bool and np.array_equal(gpu, cpu)


@pytest.mark.parametrize("backend", ["cuda", "GPU", None, 1])
def test_an_unknown_backend_is_refused_by_name(backend):
    points = np.random.default_rng(0).normal(size=(50, 3))
    with pytest.raises(InvalidInputError, match=f"backend must be 'cpu' or 'gpu', got {backend!r}"):
        zo.visible_mask_points(points, zo.camera_on_sphere(0.0, 0.0), backend=backend)


def test_the_gpu_backend_without_opengl_is_backend_unavailable(monkeypatch):
    def no_gl():
        raise BackendUnavailable("no headless OpenGL 4.3 context could be created (test)")

    monkeypatch.setattr(surfel_zbuffer, "shared_context", no_gl)
    monkeypatch.setattr(surfel_zbuffer, "_shared", {})
    surfels = zo.point_surfels(np.random.default_rng(0).normal(size=(50, 3)))
    with pytest.raises(BackendUnavailable, match="OpenGL"):
        surfels.visible(zo.camera_on_sphere(0.0, 0.0), backend="gpu")
    assert surfels.visible(zo.camera_on_sphere(0.0, 0.0)).shape == (50,)  # the CPU needs no GL
