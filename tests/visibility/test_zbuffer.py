"""Image-space HSR (z-buffer methods) against the exact oracle, on real meshes and on laws."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.visibility.metrics import agreement
from zbuf_occlude.visibility.zbuffer import ResidentPoints as Scene

#: z-buffer vs oracle agreement at 1024² over the grid25 poses, 20k points per mesh.
#: Measured (Mesa llvmpipe): worst pose 0.99730 (bathtub_0003) over the 27 meshes of
#: ../shared, 0.99850 (chair_0001) over the 8 shipped ones; worst per-mesh mean 0.99932
#: (airplane_0001), 0.99965 shipped.  Bars: 1.5x the measured worst error rates.
MIN_AGREEMENT = 0.9960
MIN_MEAN_AGREEMENT = 0.9990
POINTS_PER_MESH = 20_000


def _sweep(path, method="zbuffer", **options):
    mesh = zo.load_mesh(path)
    points, face_index = zo.sample_surface(mesh, count=POINTS_PER_MESH, seed=0)
    scores = []
    scene = Scene(mesh, points, face_index) if method == "zbuffer" else None
    for el, az in zo.view_schedule("grid25"):
        camera = zo.camera_on_sphere(el, az, 4.0, resolution=1024)
        truth = zo.visible_mask(mesh, points, camera, "oracle", face_index=face_index)
        if scene is not None:
            pred = scene.visible(camera, **options)
        else:
            pred = zo.visible_mask(mesh, points, camera, method, face_index=face_index, **options)
        scores.append(((el, az), agreement(pred, truth)))
    if scene is not None:
        scene.release()
    return scores


def _assert_sweep(scores, path, minimum, minimum_mean=MIN_MEAN_AGREEMENT):
    (el, az), worst = min(scores, key=lambda s: s[1]["accuracy"])
    mean = np.mean([s[1]["accuracy"] for s in scores])
    print(f"{path.name}: mean {mean:.5f}, worst {worst['accuracy']:.5f} at el={el} az={az}")
    assert mean >= minimum_mean, f"{path}: mean agreement {mean:.4%} over grid25"
    assert worst["accuracy"] >= minimum, (
        f"{path}: worst pose el={el} az={az}: agreement {worst['accuracy']:.4%} "
        f"(false visible {worst['false_visible']:.3%}, false hidden {worst['false_hidden']:.3%})"
    )


@pytest.mark.slow
def test_zbuffer_agrees_with_the_oracle_on_real_modelnet_meshes(modelnet_off_file):
    # the 27 meshes of ../shared when present, else the 8 shipped ones (conftest)
    _assert_sweep(_sweep(modelnet_off_file), modelnet_off_file, MIN_AGREEMENT)


@pytest.mark.slow
def test_zbuffer_tolerance_is_a_weaker_but_sane_baseline(sample_mesh_files):
    # measured on chair_0001 at 1024²: mean ~93 %, worst pose ~82 % (thin parts, slivers);
    # the default method must beat it on average
    path = next(p for p in sample_mesh_files if "chair" in p.name)
    tol = _sweep(path, method="zbuffer-tolerance")
    default = _sweep(path)
    assert np.mean([s[1]["accuracy"] for s in tol]) > 0.9
    assert np.mean([s[1]["accuracy"] for s in default]) > np.mean([s[1]["accuracy"] for s in tol])


def test_results_are_deterministic_and_pose_order_does_not_matter(sample_mesh_files):
    mesh = zo.load_mesh(sample_mesh_files[0])
    points, face_index = zo.sample_surface(mesh, count=5000, seed=1)
    cams = [zo.camera_on_sphere(el, az, resolution=512) for el, az in zo.view_schedule("grid25")[:6]]
    with Scene(mesh, points, face_index) as scene:
        first = [scene.visible(c) for c in cams]
        second = [scene.visible(c) for c in reversed(cams)][::-1]
    assert all(np.array_equal(a, b) for a, b in zip(first, second))


def test_points_outside_the_frustum_are_not_visible():
    mesh = trimesh.creation.box([0.5, 0.5, 0.5])
    points, face_index = zo.sample_surface(mesh, count=2000, seed=0)
    narrow = zo.camera_on_sphere(0.0, 0.0, 4.0, resolution=256, yfov_deg=2.0)  # sees only the middle
    mask = zo.visible_mask(mesh, points, narrow, "zbuffer", face_index=face_index, resolution=None)
    assert mask.any() and not mask[~narrow.in_frustum(points)].any()


def test_without_a_face_index_it_still_agrees(sample_mesh_files):
    mesh = zo.load_mesh(next(p for p in sample_mesh_files if "monitor" in p.name))
    points, face_index = zo.sample_surface(mesh, count=10_000, seed=0)
    cam = zo.camera_on_sphere(30.0, 45.0)
    truth = zo.visible_mask(mesh, points, cam, "oracle", face_index=face_index)
    assert agreement(zo.visible_mask(mesh, points, cam, "zbuffer"), truth)["accuracy"] > 0.98


def _icosphere():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    return sphere, *zo.sample_surface(sphere, count=20_000, seed=3)


_SPHERE = None


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(el=st.floats(-90, 90), az=st.floats(0, 360), radius=st.floats(1.5, 12.0))
def test_a_convex_closed_mesh_shows_the_cap_fraction_of_its_area(el, az, radius):
    global _SPHERE
    if _SPHERE is None:
        _SPHERE = _icosphere()
    sphere, points, face_index = _SPHERE
    cam = zo.camera_on_sphere(el, az, radius, resolution=512)
    visible = zo.visible_mask(sphere, points, cam, "zbuffer", face_index=face_index, resolution=512).mean()
    expected = (1 - 0.5 / radius) / 2  # a sphere of radius r seen from distance d shows (1 - r/d)/2
    n = len(points)
    # 5 binomial sigmas + the icosphere's discretisation
    assert abs(visible - expected) < 5 * np.sqrt(expected * (1 - expected) / n) + 0.01


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    el=st.floats(-60, 60), az=st.floats(0, 360), size=st.floats(0.1, 0.4), gap=st.floats(0.02, 0.3),
    u=st.floats(-0.3, 0.3), v=st.floats(-0.3, 0.3),
)  # fmt: skip
def test_a_point_behind_an_occluding_quad_is_hidden(el, az, size, gap, u, v):
    cam = zo.camera_on_sphere(el, az, 4.0, resolution=256)
    view_dir = -cam.eye / np.linalg.norm(cam.eye)
    right, up = cam.view_matrix[0, :3], cam.view_matrix[1, :3]
    # an occluding quad facing the camera, a little in front of the origin
    centre = -0.1 * view_dir
    corners = [centre + size * (sx * right + sy * up) for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    quad = trimesh.Trimesh(np.array(corners), [[0, 1, 2], [0, 2, 3]], process=False)
    # a tiny far triangle to carry the test points: behind the quad, along rays through it
    through = centre + size * (u * right + v * up)
    behind = through + gap * (through - cam.eye) / np.linalg.norm(through - cam.eye)
    beside = centre + (size + 0.05) * right + gap * view_dir
    tri = [behind + 1e-3 * right, behind + 1e-3 * up, behind - 1e-3 * right]
    tri2 = [beside + 1e-3 * right, beside + 1e-3 * up, beside - 1e-3 * right]
    mesh = trimesh.Trimesh(np.vstack([quad.vertices, tri, tri2]), [[0, 1, 2], [0, 2, 3], [4, 5, 6], [7, 8, 9]], process=False)
    # `through` lies on the quad: in face 0 (corners (-1,-1), (1,-1), (1,1)) iff u >= v
    on_quad_face = 0 if u >= v else 1
    points = np.array([behind, beside, through])
    face_index = np.array([2, 3, on_quad_face])
    assert abs(np.dot(through - centre, view_dir)) < 1e-12  # the premise: in the quad's plane
    mask = zo.visible_mask(mesh, points, cam, "zbuffer", face_index=face_index, resolution=256)
    oracle = zo.visible_mask(mesh, points, cam, "oracle", face_index=face_index)
    assert not mask[0] and not oracle[0]  # behind the quad: hidden
    assert mask[1] and oracle[1]  # beside it: visible
    assert mask[2] and oracle[2]  # on the quad itself: visible


def test_bad_inputs_get_clear_errors(sample_mesh_files):
    mesh = zo.load_mesh(sample_mesh_files[0])
    cam = zo.camera_on_sphere(0.0, 0.0)
    with pytest.raises(InvalidInputError, match="NaN"):
        zo.visible_mask(mesh, np.array([[0.0, np.nan, 0.0]]), cam)
    with pytest.raises(InvalidInputError, match="shape"):
        zo.visible_mask(mesh, np.zeros((4, 2)), cam)
    with pytest.raises(InvalidInputError, match="unknown visibility method"):
        zo.visible_mask(mesh, np.zeros((1, 3)), cam, method="raytrace-magic")
    with pytest.raises(InvalidInputError, match="face_index"):
        zo.visible_mask(mesh, np.zeros((1, 3)), cam, face_index=np.array([len(mesh.faces)]))
    assert zo.visible_mask(mesh, np.zeros((0, 3)), cam).shape == (0,)


# -- options and limits of the zbuffer method ---------------------------------------------------
#: The chair's false-visible rate (fraction of all points, mean over grid25 at 1024², 20k
#: points): measured 0.0338 %.  The GPU's segment test uses a 1e-5 self-hit tolerance; a
#: 1000x larger one lets near occluders pass and raises it to 0.100 %.
CHAIR_MAX_MEAN_FALSE_VISIBLE = 0.0005


def test_false_visible_rate_on_the_chair_is_the_measured_one(sample_mesh_files):
    path = next(p for p in sample_mesh_files if "chair" in p.name)
    scores = _sweep(path)
    mean_fv = np.mean([s[1]["false_visible"] for s in scores])
    assert mean_fv <= CHAIR_MAX_MEAN_FALSE_VISIBLE, f"{mean_fv:.4%}"
    assert max(s[1]["false_hidden"] for s in scores) <= 0.0002  # measured 0.01 % at worst


@pytest.fixture(scope="module")
def chair_scene(sample_mesh_files):
    mesh = zo.load_mesh(next(p for p in sample_mesh_files if "chair" in p.name))
    points, face_index = zo.sample_surface(mesh, count=20_000, seed=0)
    with Scene(mesh, points, face_index) as scene:
        yield mesh, points, face_index, scene


CHAIR_POSES = ((30.0, 45.0), (-40.0, 200.0), (0.0, 0.0))


def test_resolve_none_keeps_the_gpu_answer_for_uncertain_points(chair_scene):
    # "none" answers "visible" where the centre pixel does not show the point's own face;
    # "embree" decides those exactly.  Measured at 512²: 75 / 258 / 700 points differ, all
    # of them hidden by the oracle; the certain answers are the same.
    mesh, points, face_index, scene = chair_scene
    for el, az in CHAIR_POSES:
        camera = zo.camera_on_sphere(el, az, 4.0, resolution=512)
        truth = zo.visible_mask(mesh, points, camera, "oracle", face_index=face_index)
        exact, gpu = scene.visible(camera), scene.visible(camera, resolve="none")
        assert not (exact & ~gpu).any()  # "none" only adds visible points
        extra = gpu & ~exact
        assert extra.sum() > 50
        assert np.mean(truth[extra]) < 0.05  # the added ones are (nearly all) false visible
        assert np.mean(exact == truth) > np.mean(gpu == truth)
        assert np.array_equal(zo.visible_mask(mesh, points, camera, "zbuffer", face_index=face_index, resolution=512, resolve="none"), gpu)
    with pytest.raises(InvalidInputError, match="resolve"):
        scene.visible(camera, resolve="cuda")


def test_a_larger_neighborhood_finds_more_occluders(chair_scene):
    # The GPU tests the faces seen in (2r + 1)² pixels around each point: a larger window
    # only adds candidate occluders, so (resolve="none") the visible sets nest.  Measured
    # at 512², el=-40 az=200: 12 857 / 11 084 / 10 911 / 10 877 / 10 857 visible for
    # r = 0..4; with the exact resolve the agreement rises 0.9969 -> 0.9990 from r=0 to 1.
    mesh, points, face_index, scene = chair_scene
    camera = zo.camera_on_sphere(-40.0, 200.0, 4.0, resolution=512)
    visible = [scene.visible(camera, neighborhood=r, resolve="none") for r in range(5)]
    for r in range(4):
        assert not (visible[r + 1] & ~visible[r]).any(), r
    assert visible[0].sum() > visible[1].sum() + 1000 and visible[1].sum() > visible[4].sum() + 100
    truth = zo.visible_mask(mesh, points, camera, "oracle", face_index=face_index)
    assert np.mean(scene.visible(camera, neighborhood=0) == truth) < np.mean(scene.visible(camera) == truth)
    for bad in (-1, 5):
        with pytest.raises(InvalidInputError, match="neighborhood"):
            scene.visible(camera, neighborhood=bad)


def test_duplicate_faces_are_drawn_once_under_the_lowest_index(chair_scene):
    # Every face twice (the copy after all originals, its own vertices, corners rotated):
    # points on the copies see their own face in the image exactly as points on the
    # originals do (same visible and same uncertain points); without the grouping the
    # original wins the depth test and every copy's point is uncertain.
    from zbuf_occlude.render.renderer_cache import renderer_for

    mesh, points, face_index, _ = chair_scene
    n_faces, n_vertices = len(mesh.faces), len(mesh.vertices)
    doubled = trimesh.Trimesh(
        np.vstack([mesh.vertices, mesh.vertices]), np.vstack([mesh.faces, mesh.faces[:, [1, 2, 0]] + n_vertices]), process=False
    )
    camera = zo.camera_on_sphere(30.0, 45.0, 4.0, resolution=512)
    single, double = renderer_for(mesh), renderer_for(doubled)
    assert np.array_equal(double.canonical[n_faces:], double.canonical[:n_faces])
    assert (double.canonical <= np.arange(2 * n_faces)).all()
    answers = []
    for renderer, fi in ((single, face_index), (double, face_index + n_faces)):
        buffer = renderer.upload_points(points, fi)
        try:
            answers.append(renderer.visible(camera, buffer))
        finally:
            buffer.release()
    (vis_a, unc_a), (vis_b, unc_b) = answers
    assert np.array_equal(vis_a, vis_b) and np.array_equal(unc_a, unc_b)
    assert unc_a.mean() < 0.15  # measured 8.9 % uncertain
    truth = zo.visible_mask(doubled, points, camera, "oracle", face_index=face_index + n_faces)
    assert np.mean(zo.visible_mask(doubled, points, camera, "zbuffer", face_index=face_index + n_faces) == truth) > 0.999


def test_the_face_limit_is_a_clear_error(monkeypatch):
    from zbuf_occlude.render import moderngl_backend

    monkeypatch.setattr(moderngl_backend, "MAX_FACES", 12)
    box = trimesh.creation.box()  # 12 faces: one too many for the lowered limit
    points, face_index = zo.sample_surface(box, count=10, seed=0)
    with pytest.raises(InvalidInputError, match="12 faces"):
        zo.visible_mask(box, points, zo.camera_on_sphere(30.0, 45.0), "zbuffer", face_index=face_index, resolution=64)
    monkeypatch.setattr(moderngl_backend, "MAX_FACES", 13)
    assert zo.visible_mask(box, points, zo.camera_on_sphere(30.0, 45.0), "zbuffer", face_index=face_index, resolution=64).any()
