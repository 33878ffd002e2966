"""The GPU surfel z-buffer (zbuf_occlude.render.point_sprites) against the numba kernel it mirrors,
and the ``backend`` switch of point-only visibility.

The GPU computes with the kernel's float64 operations and breaks ties as it does (the least
``t``, then the lowest id), so the buffers are the kernel's bit for bit, and so are the masks.
These run on Mesa llvmpipe headless, as the other GL tests, and never skip.
"""

from __future__ import annotations

import numpy as np
import pytest

import zbuf_occlude as zo
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.render import point_sprites
from zbuf_occlude.render.point_sprites import PointSpriteRenderer, shared_point_sprites
from zbuf_occlude.visibility.point_kernels import EDGE_ON_COS, splat_surfels
from zbuf_occlude.visibility.point_splats import splat_image

#: Every surfel a sprite (the GL's own limit), every surfel a quad, or 32-pixel tiles.
PASSES = {"sprites": {}, "quads": {"max_point_size": 1.0}, "tiles": {"max_tile": 32}}


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
    with PointSpriteRenderer() as renderer:
        for name, value in PASSES[setting].items():
            setattr(renderer, name, value)
        gpu = renderer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)
    assert _assert_buffers_equal(cam, normal, radius, image, gpu) > 0.5 * 300 * 225


@pytest.mark.parametrize("setting", PASSES)
def test_buffers_match_the_cpu_kernel_on_a_sampled_mesh(sample_mesh_files, setting):
    """Neighbours on one flat sheet tie at many pixels (a tenth of them here, decided by
    float64 rounding): the GPU's rounding and its tie rule are the kernel's."""
    chair = next(p for p in sample_mesh_files if "chair" in p.name)
    with PointSpriteRenderer() as renderer:
        for name, value in PASSES[setting].items():
            setattr(renderer, name, value)
        for pose in ((30.0, 45.0), (-20.0, 200.0)):
            cam, normal, radius, image = _view(chair, 2048, pose)
            gpu = renderer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)
            assert _assert_buffers_equal(cam, normal, radius, image, gpu) > 1000


def test_a_surfel_beyond_the_largest_point_size_is_drawn_as_a_quad(monkeypatch):
    # a disk facing the camera 0.1 mm beyond its own radius covers nearly all of an image one
    # sprite wider than the GL allows; one centred off the image reaches into it; small ones
    # lie behind them
    cam = np.array([[0.0, 0.0, 0.0101], [-1.1, 0.0, 1.0], [0.5, 0.5, 2.0], [-0.5, 0.2, 2.0]])
    normal = np.tile([0.0, 0.0, 1.0], (4, 1))
    radius = np.array([0.01, 0.2, 0.05, 0.05])
    split, routes = point_sprites._Boxes.split, []
    monkeypatch.setattr(point_sprites._Boxes, "split", lambda box, *args: routes.append(split(box, *args)) or routes[-1])
    with PointSpriteRenderer() as renderer:
        side = int(renderer.max_point_size) + 16
        image = (2.0 / side, -1.0, -1.0, side, side)
        depth, ids = renderer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)
    ((sprites, quads),) = routes
    assert list(quads) == [0] and list(sprites) == [1, 2, 3]
    depth_cpu, ids_cpu = splat_surfels(cam, normal, radius, *image)
    assert np.array_equal(ids, ids_cpu) and np.array_equal(depth, depth_cpu)
    assert (ids == 0).mean() > 0.7 and (ids == 1).sum() > 0  # the near disk; the off-image one


def test_nothing_drawable_gives_empty_buffers():
    cam = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 0.005]])  # behind the camera; its sphere crosses z = 0
    normal = np.tile([0.0, 0.0, 1.0], (2, 1))
    radius = np.array([0.1, 0.01])
    depth, ids = shared_point_sprites().splat(cam, normal, radius, 0.01, -1.0, -1.0, 20, 10, edge_on_cos=EDGE_ON_COS)
    assert depth.shape == (10, 20) and np.isinf(depth).all() and (ids == -1).all()


def test_release_frees_every_gl_object():
    renderer = PointSpriteRenderer()
    cam, normal, radius = np.array([[0.0, 0.0, 2.0]]), np.array([[0.0, 0.0, 1.0]]), np.array([0.1])
    renderer.splat(cam, normal, radius, 0.01, -0.1, -0.1, 20, 20, edge_on_cos=EDGE_ON_COS)
    target = renderer._target
    objects = [*renderer._programs.values(), target.draw, target.read, *target.images]
    renderer.release()
    renderer.release()  # twice is fine
    assert all(type(obj.mglo).__name__ == "InvalidObject" for obj in objects)
    with pytest.raises(RuntimeError, match="released"):
        renderer.splat(cam, normal, radius, 0.01, -0.1, -0.1, 20, 20, edge_on_cos=EDGE_ON_COS)


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

    monkeypatch.setattr(point_sprites, "shared_context", no_gl)
    monkeypatch.setattr(point_sprites, "_shared", {})
    surfels = zo.point_surfels(np.random.default_rng(0).normal(size=(50, 3)))
    with pytest.raises(BackendUnavailable, match="OpenGL"):
        surfels.visible(zo.camera_on_sphere(0.0, 0.0), backend="gpu")
    assert surfels.visible(zo.camera_on_sphere(0.0, 0.0)).shape == (50,)  # the CPU needs no GL
