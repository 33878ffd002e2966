"""The GPU surfel z-buffer (zbuf_occlude.render.point_sprites) against the numba kernel it mirrors,
and the ``backend`` switch of point-only visibility.

The GPU computes with the kernel's float64 operations and breaks ties as it does (the least
``t``, then the lowest id), so the buffers are the kernel's bit for bit, and so are the masks.
These run on Mesa llvmpipe headless, as the other GL tests, and never skip.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import zbuf_occlude as zo
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.render import point_sprites
from zbuf_occlude.render.point_sprites import PointSpriteRenderer, shared_point_sprites
from zbuf_occlude.visibility.point_kernels import EDGE_ON_COS, splat_surfels
from zbuf_occlude.visibility.splat_image import splat_image

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


#: The strip the quad test draws into: the pixels of it the near disk covers beyond the GL's largest
#: point size, the pixels to its right where the small surfels show, and its height.  A strip, not
#: a square: a box's longer side decides the route, and an image as wide and as tall as the largest
#: point size (8192² on some GLs) would cost gigabytes for nothing.
_BEYOND_PX, _GAP_PX, _STRIP_PX = 16, 16, 16
#: The widest strip drawn (16 rows of it take 200 MB on the CPU and the GPU): a GL whose largest point
#: size is near this cannot show a surfel larger than it in an image a test can afford.
_MAX_STRIP_WIDTH_PX = 1 << 20


def test_a_surfel_beyond_the_largest_point_size_is_drawn_as_a_quad(monkeypatch):
    """On any GL, whatever its limits: the strip is sized from the GL's own largest point size (and
    drawn in tiles where it is wider than the GL's images), so that a disk covering its width has a
    box wider than any sprite; small disks beside it stay sprites, and the buffers are the kernel's."""
    split, routes = point_sprites._Boxes.split, []
    monkeypatch.setattr(point_sprites._Boxes, "split", lambda box, *args: routes.append(split(box, *args)) or routes[-1])
    with PointSpriteRenderer() as renderer:
        cover = math.ceil(renderer.max_point_size) + _BEYOND_PX
        width = cover + _GAP_PX
        if width > _MAX_STRIP_WIDTH_PX:
            pytest.skip(f"the GL's largest point size is {renderer.max_point_size:g} pixels: no affordable image is wider")
        # disk 0 faces the camera 0.1 mm beyond its own radius: it spans x/z in ±0.990099, and the
        # strip ends cover pixels right of its left edge, which lies far left of the strip
        near_edge = 0.01 / 0.0101
        pix = 1.0 / cover
        image = (pix, near_edge - cover * pix, -0.5 * _STRIP_PX * pix, width, _STRIP_PX)

        def at(column: float, row: float, z: float) -> list[float]:  # a point at z seen at pixel (column, row)
            return [z * (image[1] + column * pix), z * (image[2] + row * pix), z]

        # disk 1 centred 2 px right of the strip, reaching 5 px into it; 2 and 3 small, in the gap, behind disk 0's plane
        cam = np.array([[0.0, 0.0, 0.0101], at(width + 2, 8, 1.5), at(cover + 5, 5, 2.0), at(cover + 11, 10, 2.0)])
        normal = np.tile([0.0, 0.0, 1.0], (4, 1))
        radius = np.array([0.01, 7 * pix * 1.5, 2.5 * pix * 2.0, 2.5 * pix * 2.0])
        depth, ids = renderer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)
        small_are_sprites = renderer.max_point_size >= max(_GAP_PX, _STRIP_PX) + 2  # every small box fits the gap
    assert len(routes) == math.ceil(width / renderer.max_tile)  # one split a tile
    for sprites, quads in routes:
        assert 0 in quads and 0 not in sprites, routes
    sprites_seen = set().union(*(set(sprites.tolist()) for sprites, _ in routes))
    assert sprites_seen == ({1, 2, 3} if small_are_sprites else set()), (routes, renderer.max_point_size)
    depth_cpu, ids_cpu = splat_surfels(cam, normal, radius, *image)
    assert np.array_equal(ids, ids_cpu) and np.array_equal(depth, depth_cpu)
    assert (ids == 0).sum() >= (cover - 1) * _STRIP_PX and {1, 2, 3} <= set(np.unique(ids).tolist())  # the near disk; the rest in the gap


def test_the_quad_test_sizes_its_strip_from_the_gl_it_runs_on(monkeypatch):
    """The same test under other GLs' limits, by the renderer's queried values: a largest point size
    of 2047 (NVIDIA), 8192, and one equal to the largest image (16384 with the image at 16384 is
    drawn in two tiles; here scaled down, 64 with 64-pixel tiles, to keep the strip small)."""
    init = PointSpriteRenderer.__init__
    for max_point_size, max_tile in ((2047.0, None), (8192.0, None), (64.0, 64)):

        def limited(self, *args, _size=max_point_size, _tile=max_tile, **kwargs):
            init(self, *args, **kwargs)
            self.max_point_size = _size
            self.max_tile = _tile or self.max_tile

        with monkeypatch.context() as patched:
            patched.setattr(PointSpriteRenderer, "__init__", limited)
            test_a_surfel_beyond_the_largest_point_size_is_drawn_as_a_quad(patched)


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
