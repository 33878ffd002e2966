"""Headless rendering: moderngl depth and face index, pyrender cross-check, contexts, shaders."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import trimesh

import zbuf_occlude as zo
from zbuf_occlude.errors import BackendUnavailable
from zbuf_occlude.render import renderer_for
from zbuf_occlude.render.context import create_context
from zbuf_occlude.render.moderngl_backend import ModernGLRenderer
from zbuf_occlude.visibility.segment_triangle import segment_hits_triangles

SPHERE_RADIUS = 0.5


@pytest.fixture(scope="module")
def sphere():
    return trimesh.creation.icosphere(subdivisions=5, radius=SPHERE_RADIUS)


def _analytic_sphere_depth(cam):
    """Linear depth of the ray through each pixel centre to a sphere at the origin (0 = miss)."""
    u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    d_cam = np.stack([(u - cam.width / 2) / cam.focal_px, (v - cam.height / 2) / cam.focal_px, np.ones_like(u)], -1)
    d = d_cam @ cam.extrinsics[:, :3]  # world directions scaled so that depth == s
    a, b, c = (d**2).sum(-1), 2 * d @ cam.eye, cam.eye @ cam.eye - SPHERE_RADIUS**2
    disc = b * b - 4 * a * c
    return np.where(disc > 0, (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a), 0.0), disc


def test_moderngl_depth_is_linear_depth_in_object_units(sphere):
    cam = zo.camera_on_sphere(20.0, 70.0, 4.0, resolution=128)
    depth = ModernGLRenderer(sphere).render(cam).depth
    truth, disc = _analytic_sphere_depth(cam)
    inner = disc > 0.05 * disc.max()  # away from the silhouette
    assert (depth[inner] > 0).all()
    # the icosphere's flat faces lie inside the sphere by up to ~1.5e-4 (sagitta), more along
    # slanted rays; float32 depth adds ~1e-6
    err = np.abs(depth[inner] - truth[inner])
    assert np.median(err) < 3e-4 and err.max() < 1.5e-3
    assert ((depth > 0) == (truth > 0)).mean() > 0.995


def test_face_index_buffer_names_the_face_the_pixel_ray_hits_first(sample_mesh_files):
    mesh = zo.load_mesh(next(p for p in sample_mesh_files if "chair" in p.name))
    cam = zo.camera_on_sphere(30.0, 45.0, 4.0, resolution=96)
    frame = renderer_for(mesh).render(cam)
    rows, cols = np.nonzero(frame.mask)
    rng = np.random.default_rng(0)
    pick = rng.choice(len(rows), size=min(300, len(rows)), replace=False)
    correct = 0
    for r, c in zip(rows[pick], cols[pick]):
        d_cam = np.array([(c + 0.5 - cam.width / 2) / cam.focal_px, (r + 0.5 - cam.height / 2) / cam.focal_px, 1.0])
        far_point = cam.eye + 10.0 * (d_cam @ cam.extrinsics[:, :3])
        hit, dist = segment_hits_triangles(far_point, cam.eye, mesh.triangles)
        nearest_to_eye = dist[hit].max()  # distances are measured from far_point
        face = frame.face_index[r, c]
        # ModelNet soup has coplanar duplicate faces: any face at the first hit's depth is right
        correct += int(hit[face] and abs(dist[face] - nearest_to_eye) < 1e-5)
    assert correct / len(pick) > 0.99


def test_pyrender_and_moderngl_depth_maps_agree(sample_mesh_files):
    # pyrender picks its platform when first imported: headless EGL, as the backend asks
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    try:
        import pyrender  # noqa: F401
    except ImportError as exc:  # not installed, or pyglet's GLU missing (seen on an NVIDIA machine)
        pytest.skip(f"pyrender cannot be imported here: {exc}")
    from zbuf_occlude.render.pyrender_backend import PyrenderRenderer

    for path in sample_mesh_files[:4]:
        mesh = zo.load_mesh(path)
        cam = zo.camera_on_sphere(30.0, 200.0, 4.0, resolution=200)
        ours = renderer_for(mesh).render(cam).depth
        with PyrenderRenderer(mesh) as pr:
            theirs = pr.render_depth(cam)
        both = (ours > 0) & (theirs > 0)
        assert ((ours > 0) ^ (theirs > 0)).mean() < 0.01, path
        # pyrender's 4x MSAA resolves depth from a sub-sample up to ~0.4 px off the pixel
        # centre: allow half a pixel's depth change (from our own map's gradient)
        gy, gx = np.gradient(ours.astype(np.float64))
        allowed = 0.5 * (np.abs(gx) + np.abs(gy)) + 1e-4
        within = (np.abs(ours - theirs) <= allowed)[both]
        assert within.mean() > 0.95, (path, within.mean())
    # moderngl keeps working after pyrender made its own EGL context current
    assert (renderer_for(mesh).render(cam).depth == ours).all()


def test_many_poses_reuse_one_upload(sample_mesh_files):
    mesh = zo.load_mesh(sample_mesh_files[0])
    r = renderer_for(mesh)
    vbo = r._vbo.glo
    for el in (-60.0, 0.0, 60.0):
        assert renderer_for(mesh) is r
        r.render(zo.camera_on_sphere(el, 10.0, resolution=32))
    assert r._vbo.glo == vbo


def test_osmesa_fallback_renders_the_same_depth(sphere):
    import ctypes.util

    if ctypes.util.find_library("OSMesa") is None:
        pytest.skip("libOSMesa not installed (apt-get install libosmesa6)")
    cam = zo.camera_on_sphere(0.0, 0.0, 4.0, resolution=64)
    egl = ModernGLRenderer(sphere, context=create_context("egl")).render(cam).depth
    osmesa = ModernGLRenderer(sphere, context=create_context("osmesa")).render(cam).depth
    assert np.allclose(egl, osmesa, atol=1e-6)


@pytest.mark.slow
def test_missing_egl_gives_a_clear_error():
    code = (
        "from zbuf_occlude.render.context import create_context\n"
        "from zbuf_occlude.errors import BackendUnavailable\n"
        "try:\n    create_context('egl')\nexcept BackendUnavailable as e:\n    print('ERR', e)\n"
    )
    env = {**os.environ, "GLCONTEXT_LINUX_LIBEGL": "/nonexistent/libEGL.so"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120).stdout
    assert out.startswith("ERR") and "apt-get install" in out and "egl" in out


def test_unknown_backend_is_refused():
    with pytest.raises(BackendUnavailable, match="unknown OpenGL backend"):
        create_context("vulkan")


# -- the compute shaders' exact segment test (shaders/common.glsl) -------------------------
def _zbuffer(mesh, points, cam, **options):
    # no face_index: no point is "uncertain", so the GPU alone decides every point
    return zo.visible_mask(mesh, points, cam, "zbuffer", resolve="none", resolution=cam.resolution, **options)


def test_gpu_self_hit_tolerance_is_a_distance_not_a_segment_parameter():
    """A quad hides points below it iff their distance to it exceeds the tolerance; the
    segments are ~4 long, so t = distance / 4 would let the 1.2e-3 and 2e-3 ones through."""
    quad = trimesh.Trimesh(vertices=[[-0.4, -0.4, 0.0], [0.4, -0.4, 0.0], [0.4, 0.4, 0.0], [-0.4, 0.4, 0.0]], faces=[[0, 1, 2], [0, 2, 3]])
    cam = zo.camera_on_sphere(90.0, 0.0, 4.0, resolution=128)
    tol = 1e-3
    d = np.array([0.5, 0.8, 1.3, 2.0]) * tol
    points = np.stack([np.full(4, 0.13), np.full(4, -0.07), -d], axis=1)
    visible = _zbuffer(quad, points, cam, tolerance=tol)
    assert visible.tolist() == [True, True, False, False]


def test_gpu_sight_lines_through_a_shared_edge_never_leak():
    """Points seen exactly through the edge shared by two faces (non-dyadic, so the crossing
    rounds off the edge in float32) are hidden: the barycentric bounds are widened."""
    rng = np.random.default_rng(4)
    a, b = np.array([-0.31, -0.11, 0.023]), np.array([0.347, 0.123, -0.031])
    mid = (a + b) / 2
    across = np.cross(b - a, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    c1, c2 = mid + 0.29 * across + [0, 0, 0.047], mid - 0.33 * across - [0, 0, 0.052]
    patch = trimesh.Trimesh(vertices=[a, b, c1, c2], faces=[[0, 1, 2], [1, 0, 3]], process=False)
    cam = zo.camera_on_sphere(90.0, 0.0, 4.0, resolution=128)
    s = rng.uniform(0.05, 0.95, 400)
    on_edge = a + s[:, None] * (b - a)
    to_eye = cam.eye - on_edge
    points = on_edge - 0.2 * to_eye / np.linalg.norm(to_eye, axis=1, keepdims=True)
    assert not zo.visible_mask(patch, points, cam, "oracle").any()
    visible = _zbuffer(patch, points, cam)
    assert not visible.any(), f"{visible.sum()} of {len(points)} points seen through the shared edge"


def test_gpu_bit_masks_do_not_depend_on_the_point_count(sample_mesh_files):
    """The shader packs visible and uncertain flags in 32-bit words, uncertain ones after
    ceil(N / 32) visible words: a point's flags must not change with the number of points
    uploaded with it (1000 is not a multiple of 32), and uncertain implies visible."""
    mesh = zo.load_mesh(next(p for p in sample_mesh_files if "chair" in p.name))
    points, face_index = zo.sample_surface(mesh, count=1024, seed=2)
    renderer = renderer_for(mesh)
    cam = zo.camera_on_sphere(30.0, 45.0, 4.0, resolution=128)
    masks = {}
    for n in (1024, 1000, 37):
        buffer = renderer.upload_points(points[:n], face_index[:n])
        try:
            masks[n] = renderer.visible(cam, buffer, rule="candidates", neighborhood=1, tolerance=1e-5)
        finally:
            with renderer.ctx:
                buffer.release()
    visible, uncertain = masks[1024]
    assert 0 < uncertain.sum() and 0 < visible.sum() < len(visible)  # not vacuous
    assert not (uncertain & ~visible).any()
    for n in (1000, 37):
        assert np.array_equal(masks[n][0], visible[:n]) and np.array_equal(masks[n][1], uncertain[:n]), n
    # Uncertain = visible, but the centre pixel shows another face than the point's own (as
    # the image holds it: the lowest index of its group of identical faces).  Points within
    # 0.01 px of a pixel border are left out: float32 may put them in the next pixel.
    uv, _ = cam.project(points)  # OpenCV pixels: centres at integers
    inner = np.all(np.abs(uv - np.round(uv)) < 0.49, axis=1) & cam.in_frustum(points)
    pix = np.round(uv[inner]).astype(int)
    centre = renderer.render(cam).face_index[pix[:, 1], pix[:, 0]]
    other_face = centre != renderer.canonical[face_index[inner]]
    assert np.array_equal(uncertain[inner], visible[inner] & other_face)


def _through_pixel(cam, u, v, depth):
    """World points at linear ``depth`` on the rays through image points (u, v) (OpenCV pixels)."""
    u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
    d_cam = np.stack([(u - cam.width / 2) / cam.focal_px, (v - cam.height / 2) / cam.focal_px, np.ones_like(u)], -1)
    return cam.eye + depth * (d_cam @ cam.extrinsics[:, :3])


def test_a_point_projected_with_K_lands_on_the_pixel_the_renderer_lights():
    """Camera.K is OpenCV's (pixel centres at integers, cx = (W - 1)/2): a tiny triangle
    around the point K puts at pixel (u, v) lights that pixel and no other.  With the
    principal point at W/2 the point would sit on a pixel corner, 0.7 px from every centre."""
    cam = zo.camera_on_sphere(35.0, 20.0, 4.0, resolution=(48, 32))  # W != H: cx and cy both count
    K_inv, R, t = np.linalg.inv(cam.K), cam.extrinsics[:, :3], cam.extrinsics[:, 3]
    pixels = [(0, 0), (47, 31), (23, 15), (24, 16), (5, 27), (40, 3)]
    tris = []
    for u, v in pixels:
        corners = np.array([[u - 0.3, v - 0.2, 1.0], [u + 0.3, v - 0.2, 1.0], [u, v + 0.4, 1.0]])  # centroid (u, v)
        tris.append((3.9 * corners @ K_inv.T - t) @ R)  # camera frame at depth 3.9 -> world
    mesh = trimesh.Trimesh(vertices=np.concatenate(tris), faces=np.arange(3 * len(tris)).reshape(-1, 3), process=False)
    face = renderer_for(mesh).render(cam).face_index
    lit = {(int(c), int(r)): int(face[r, c]) for r, c in zip(*np.nonzero(face >= 0))}
    assert lit == {uv: i for i, uv in enumerate(pixels)}
    uv, _ = cam.project(mesh.triangles_center)  # Camera.project applies the same K
    assert np.allclose(uv, pixels, atol=1e-9)


def test_gpu_candidate_window_covers_the_rows_above_and_below():
    """A thin triangle drawn only in the pixel row just below (above) a point's pixel still
    hides it: the candidate window is symmetric.  Each triangle spans 0.7 px in v, its long
    edge 0.05 px past the point's sight line, its apex in the next row, whose pixel centres
    near the point's column it covers; the point's own row shows nothing."""
    cam = zo.camera_on_sphere(90.0, 0.0, 4.0, resolution=64)
    r, c = 30, 20
    points, tris = [], []
    for col, v0, edge, apex in ((c, r + 0.95, r + 0.9, r + 1.6), (c + 16, r + 0.05, r + 0.1, r - 0.6)):
        points.append(_through_pixel(cam, col + 0.5, v0, 4.1))  # depths inside the near/far planes
        tris.append(_through_pixel(cam, [col - 9.5, col + 10.5, col + 0.5], [edge, edge, apex], 3.7))
    bars = trimesh.Trimesh(vertices=np.concatenate(tris), faces=np.arange(3 * len(tris)).reshape(-1, 3), process=False)
    points = np.array(points)
    frame = renderer_for(bars).render(cam)
    assert (frame.face_index[r] < 0).all()  # the points' own row shows no face
    assert (frame.face_index[r + 1, c - 1 : c + 2] == 0).all() and (frame.face_index[r - 1, c + 15 : c + 18] == 1).all()
    assert not zo.visible_mask(bars, points, cam, "oracle").any()
    assert not _zbuffer(bars, points, cam, neighborhood=1).any()
    assert _zbuffer(bars, points, cam, neighborhood=0).all()  # the centre pixel alone sees nothing


def _tolerance_rule(mesh, points, cam, face_index=None, **constants):
    return zo.visible_mask(mesh, points, cam, "zbuffer-tolerance", face_index=face_index, resolution=cam.resolution, **constants)


def test_gpu_depth_rule_shows_points_on_the_background():
    """zbuffer-tolerance: a point whose pixel shows no surface has nothing in front of it."""
    quad = trimesh.Trimesh(vertices=[[-0.2, -0.2, 0], [0.2, -0.2, 0], [0.2, 0.2, 0], [-0.2, 0.2, 0]], faces=[[0, 1, 2], [0, 2, 3]])
    cam = zo.camera_on_sphere(90.0, 0.0, 4.0, resolution=64)
    beside = np.array([[0.35, 0.0, 0.0], [-0.3, 0.3, -0.1]])
    behind = np.array([[0.05, 0.02, -0.2]])
    got = _tolerance_rule(quad, np.concatenate([beside, behind]), cam, depth_tolerance=0.0, slope_scale=0.0)
    assert got.tolist() == [True, True, False]


def test_gpu_depth_rule_slope_term_uses_the_angle_of_the_own_face():
    """A plane at 80 degrees to the sight lines: a point's depth differs from its pixel
    centre's by up to 0.5 px x tan(80°) ≈ 2.8 pixel footprints, so with no constant term
    only the slope term (1 x footprint x tan θ) keeps the points visible."""
    tilt = np.radians(80.0)
    axis_u, axis_w = np.array([1.0, 0.0, 0.0]), np.array([0.0, np.cos(tilt), np.sin(tilt)])  # normal at 80° to z
    corners = np.array(
        [-0.3 * axis_u - 0.3 * axis_w, 0.3 * axis_u - 0.3 * axis_w, 0.3 * axis_u + 0.3 * axis_w, -0.3 * axis_u + 0.3 * axis_w]
    )
    plane = trimesh.Trimesh(vertices=corners, faces=[[0, 1, 2], [0, 2, 3]])
    points, face_index = zo.sample_surface(plane, count=2000, seed=3)
    cam = zo.camera_on_sphere(90.0, 0.0, 4.0, resolution=128)
    slope = _tolerance_rule(plane, points, cam, face_index, depth_tolerance=0.0, slope_scale=1.0, max_slope=20.0)
    flat = _tolerance_rule(plane, points, cam, face_index, depth_tolerance=0.0, slope_scale=0.0)
    in_view = cam.in_frustum(points)
    assert slope[in_view].mean() > 0.99  # a lone plane: everything in view is visible
    assert flat[in_view].mean() < 0.8  # without the slope term about half fail


def test_gpu_depth_rule_slope_of_a_back_facing_face_is_its_angle_not_the_clamp():
    """Points on a face wound away from the camera, 0.05 behind an occluder: |cos θ| keeps
    their slope term small (θ ≈ 0), so they stay hidden; a signed cos would clamp the slope
    to max_slope and let them through."""
    front = [[-0.2, -0.2, 0.0], [0.2, -0.2, 0.0], [0.2, 0.2, 0.0], [-0.2, 0.2, 0.0]]
    back = [[-0.15, -0.15, -0.05], [-0.15, 0.15, -0.05], [0.15, 0.15, -0.05], [0.15, -0.15, -0.05]]  # normal -z
    mesh = trimesh.Trimesh(vertices=front + back, faces=[[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], process=False)
    assert mesh.face_normals[2, 2] < 0  # wound away from a camera above
    cam = zo.camera_on_sphere(90.0, 0.0, 4.0, resolution=128)
    points, face_index = zo.sample_surface(mesh, count=4000, seed=5)
    on_back = face_index >= 2
    got = _tolerance_rule(mesh, points, cam, face_index, depth_tolerance=0.0, slope_scale=1.0, max_slope=10.0)
    assert not got[on_back].any()
    assert got[~on_back].mean() > 0.99
