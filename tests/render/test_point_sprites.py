"""The GPU surfel z-buffer (zbuf_occlude.render.point_sprites) against the numba kernel it mirrors,
and the ``backend`` switch of point-only visibility.

The GPU computes in float32 where the kernel computes in float64, so where two surfels' depths at
a pixel differ by less than float32 can tell, either may win: every pixel whose id differs must
be such a near-tie (:data:`NEAR_TIE`), and no pixel may be covered by one and not the other unless
its centre lies on a disk's rim to float32 precision (:data:`RIM_TIE`).  These run on Mesa
llvmpipe headless, as the other GL tests, and never skip.
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

#: Relative depth difference below which two surfels tie at a pixel: float32 keeps about 6e-8 of
#: the depth, the 24-bit depth buffer 6e-8 of the view's depth range, the shader adds a few ulps.
NEAR_TIE = 1e-6
#: |h|² / r² within this of 1: the pixel centre lies on the disk's rim to float32 precision.
RIM_TIE = 1e-5
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


def _at_pixels(cam, normal, radius, k, rows, cols, image):
    """float64 depth t and |h|²/r² of surfel ``k`` (per pixel) at pixels ``(rows, cols)``."""
    pix, x0, y0 = image[:3]
    ray = np.stack([x0 + (cols + 0.5) * pix, y0 + (rows + 0.5) * pix, np.ones(len(rows))], axis=1)
    t = np.einsum("ij,ij->i", normal[k], cam[k]) / np.einsum("ij,ij->i", normal[k], ray)
    h = ray * t[:, None] - cam[k]
    return t, np.einsum("ij,ij->i", h, h) / radius[k] ** 2


def _assert_buffers_agree(cam, normal, radius, image, gpu):
    depth_cpu, ids_cpu = splat_surfels(cam, normal, radius, *image)
    depth_gpu, ids_gpu = gpu
    assert depth_gpu.shape == depth_cpu.shape and ids_gpu.dtype == np.int32 and depth_gpu.dtype == np.float64
    same = ids_cpu == ids_gpu
    both = same & (ids_cpu >= 0)
    assert np.all(np.abs(depth_gpu[both] - depth_cpu[both]) <= NEAR_TIE * depth_cpu[both])
    assert np.all(np.isinf(depth_gpu[ids_gpu < 0]))
    rows, cols = np.nonzero(~same)
    a, b = ids_cpu[rows, cols], ids_gpu[rows, cols]
    one_side = (a < 0) | (b < 0)  # covered by one backend only: on a rim
    covering = np.where(a >= 0, a, b)[one_side]
    _, rim = _at_pixels(cam, normal, radius, covering, rows[one_side], cols[one_side], image)
    assert np.all(np.abs(rim - 1.0) <= RIM_TIE), rim
    two = ~one_side  # two different winners: tied in depth, or one on its rim
    ta, rim_a = _at_pixels(cam, normal, radius, a[two], rows[two], cols[two], image)
    tb, rim_b = _at_pixels(cam, normal, radius, b[two], rows[two], cols[two], image)
    on_rim = (np.abs(rim_a - 1.0) <= RIM_TIE) | (np.abs(rim_b - 1.0) <= RIM_TIE)
    assert np.all((np.abs(ta - tb) <= NEAR_TIE * ta) | on_rim)
    return int(np.count_nonzero(~same)), int(np.count_nonzero(ids_cpu >= 0))


def _random_surfels(n=800, seed=0):
    """Disks of random position, tilt and size in front of the camera: no two coplanar."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(2.0, 4.0, n)
    cam = np.stack([rng.uniform(-0.5, 0.5, n) * z, rng.uniform(-0.4, 0.4, n) * z, z], axis=1)
    normal = rng.normal(size=(n, 3)) + [0.0, 0.0, -2.0]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return cam, normal, rng.uniform(0.01, 0.1, n)


#: Pixels whose id may differ in the random case (a near-tie or a rim pixel each): 800 disks
#: crossing each other at random meet a pixel centre within float32 of a tie about once.
RANDOM_CASE_DIFFERENCES = 3


@pytest.mark.parametrize("setting", PASSES)
def test_buffers_match_the_cpu_kernel_on_random_disks(setting):
    cam, normal, radius = _random_surfels()
    image = (0.004, -0.6, -0.45, 300, 225)
    with PointSpriteRenderer() as renderer:
        for name, value in PASSES[setting].items():
            setattr(renderer, name, value)
        gpu = renderer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)
    differ, covered = _assert_buffers_agree(cam, normal, radius, image, gpu)
    assert covered > 0.5 * 300 * 225 and differ <= RANDOM_CASE_DIFFERENCES, differ


@pytest.mark.parametrize("setting", PASSES)
def test_buffers_match_the_cpu_kernel_on_a_sampled_mesh_but_for_near_ties(sample_mesh_files, setting):
    """Neighbours on one flat sheet tie at many pixels (a tenth of them here): each is a
    near-tie, decided by float32 on the GPU and by float64 rounding on the CPU."""
    chair = next(p for p in sample_mesh_files if "chair" in p.name)
    with PointSpriteRenderer() as renderer:
        for name, value in PASSES[setting].items():
            setattr(renderer, name, value)
        for pose in ((30.0, 45.0), (-20.0, 200.0)):
            cam, normal, radius, image = _view(chair, 2048, pose)
            gpu = renderer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)
            differ, covered = _assert_buffers_agree(cam, normal, radius, image, gpu)
            assert covered > 1000


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
    (sprites, quads), = routes
    assert list(quads) == [0] and list(sprites) == [1, 2, 3]
    depth_cpu, ids_cpu = splat_surfels(cam, normal, radius, *image)
    assert np.array_equal(ids, ids_cpu)
    assert np.allclose(depth[ids >= 0], depth_cpu[ids >= 0], rtol=NEAR_TIE)
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
    _, fbo, textures = renderer._target
    objects = [*renderer._programs.values(), fbo, *textures]
    renderer.release()
    renderer.release()  # twice is fine
    assert all(type(obj.mglo).__name__ == "InvalidObject" for obj in objects)
    with pytest.raises(RuntimeError, match="released"):
        renderer.splat(cam, normal, radius, 0.01, -0.1, -0.1, 20, 20, edge_on_cos=EDGE_ON_COS)


#: Least share of point-views whose masks agree between the backends on the shipped chair.
MASK_AGREEMENT = 0.995


@pytest.mark.parametrize("normals", [False, True], ids=["estimated", "given"])
def test_masks_agree_with_the_cpu_backend_on_a_shipped_mesh(sample_mesh_files, normals):
    """The decision reads which surfel wins each point's pixel, and on a flat face many surfels
    tie there exactly (float64 rounding decides on the CPU, float32 on the GPU), so the backends
    differ on a few points in a thousand: about as many as the CPU backend's own answer changes
    when its ties go the other way (surfels drawn in the reverse order)."""
    chair = zo.load_mesh(next(p for p in sample_mesh_files if "chair" in p.name))
    points, face_index = zo.sample_surface(chair, 2048, seed=0)
    surfels = zo.point_surfels(points, chair.face_normals[face_index] if normals else None)
    agree = total = 0
    for el, az in zo.view_schedule("fibonacci:16"):
        camera = zo.camera_on_sphere(el, az)
        agree += np.count_nonzero(surfels.visible(camera, backend="gpu") == surfels.visible(camera))
        total += len(points)
    assert agree / total >= MASK_AGREEMENT, (agree, total)


def test_visible_mask_points_takes_the_backend():
    points = np.random.default_rng(0).normal(size=(500, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    camera = zo.camera_on_sphere(20.0, 30.0, 4.0)
    cpu = zo.visible_mask_points(points, camera)
    gpu = zo.visible_mask_points(points, camera, backend="gpu")
    assert gpu.shape == (500,) and gpu.dtype == bool and np.mean(gpu == cpu) >= 0.99


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
