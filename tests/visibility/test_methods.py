"""Visibility v2 (issue 11): one definition, decided exactly by zbuffer-exact, embree-fast, auto.

Laws tested:
* a thin occluder, narrower than a pixel, in front of a plane hides the points behind it at
  every resolution (the GPU's candidate set is complete, not sampled at pixel centres);
* sliver faces: zbuffer-exact equals the oracle bit for bit;
* results with and without ``face_index`` are equal;
* the edge-on rule: points on a face seen exactly edge-on are hidden by every method, and
  the two oracles agree bit for bit there;
* ``auto`` picks a valid method on llvmpipe (EGL) and on OSMesa.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.visibility import available_methods, visible_mask
from zbuf_occlude.visibility.definition import EDGE_ON_SIN, edge_on_any, edge_on_own
from zbuf_occlude.visibility.embree_fast import FastScene
from zbuf_occlude.visibility.gpu_exact import ExactScene
from zbuf_occlude.visibility.segment_triangle import mesh_planes

REPO_ROOT = Path(__file__).resolve().parents[2]
SAMPLES = REPO_ROOT / "data" / "samples"
EXACT_METHODS = ("oracle", "oracle-numpy", "zbuffer-exact", "embree-fast", "auto")


def _plane_and_sliver(width: float, height: float, cam: zo.Camera):
    """A 2×2 floor (z = 0) and, ``height`` above it, a sliver triangle ``width`` wide
    (object units) and 0.6 long along x; plus floor points right behind the sliver's
    mid-line as seen from ``cam``, and floor points well beside it."""
    floor = trimesh.creation.box([2.0, 2.0, 1e-3])
    floor.apply_translation([0.0, 0.0, -5e-4])  # top face at z = 0
    sliver = trimesh.Trimesh([[-0.3, -width / 2, height], [0.3, -width / 2, height], [0.0, width / 2, height]], [[0, 1, 2]])
    mesh = trimesh.util.concatenate([floor, sliver])
    # Points of the sliver's middle third, on its mid-line, projected from the eye to z = 0.
    xs = np.linspace(-0.08, 0.08, 9)
    on_sliver = np.stack([xs, np.zeros_like(xs), np.full_like(xs, height)], axis=1)
    ray = on_sliver - cam.eye
    behind = cam.eye + ray * (-cam.eye[2] / ray[:, 2])[:, None]
    beside = behind + np.array([0.0, 0.25, 0.0])
    return mesh, np.concatenate([behind, beside])


@settings(max_examples=12, deadline=None)
@given(
    resolution=st.sampled_from([32, 64, 128, 256, 512, 1024]),
    width_px=st.floats(0.02, 0.9),
    height=st.floats(0.02, 0.3),
    el=st.floats(35.0, 80.0),
    az=st.floats(0.0, 360.0),
)
def test_a_sliver_narrower_than_a_pixel_hides_the_floor_behind_it(resolution, width_px, height, el, az):
    cam = zo.camera_on_sphere(el, az, resolution=resolution)
    # width_px pixels wide at the sliver's depth (so no pixel centre need sample it)
    depth = float(np.linalg.norm(cam.eye - np.array([0.0, 0.0, height])))
    width = width_px * depth / cam.focal_px
    mesh, points = _plane_and_sliver(width, height, cam)
    n = len(points) // 2
    want = np.r_[np.zeros(n, bool), np.ones(n, bool)]
    assert np.array_equal(visible_mask(mesh, points, cam, "oracle"), want)
    got = visible_mask(mesh, points, cam, "zbuffer-exact", resolution=resolution)
    assert np.array_equal(got, want), (got, want)
    assert np.array_equal(visible_mask(mesh, points, cam, "embree-fast"), want)


def _sliver_mesh(seed: int) -> trimesh.Trimesh:
    """A wavy sheet whose quads are cut into fans of needle triangles, over a box."""
    rng = np.random.default_rng(seed)
    n = 12
    x, y = np.meshgrid(np.linspace(-0.4, 0.4, n), np.linspace(-0.4, 0.4, n))
    z = 0.1 * np.sin(5 * x + rng.uniform(0, 6)) * np.cos(4 * y)
    verts = [np.stack([x.ravel(), y.ravel(), z.ravel()], 1)]
    faces = []
    idx = np.arange(n * n).reshape(n, n)
    base = n * n
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = idx[i, j], idx[i, j + 1], idx[i + 1, j + 1], idx[i + 1, j]
            # split the edge b-c at 8 points: a fan of needles from a
            t = np.linspace(0, 1, 9)[1:-1]
            mid = verts[0][b] * (1 - t)[:, None] + verts[0][c] * t[:, None]
            ids = np.arange(base, base + len(mid))
            verts.append(mid)
            base += len(mid)
            chain = [b, *ids, c]
            faces += [[a, chain[k], chain[k + 1]] for k in range(len(chain) - 1)]
            faces.append([a, c, d])
    sheet = trimesh.Trimesh(np.concatenate(verts), np.array(faces), process=False)
    box = trimesh.creation.box([0.5, 0.5, 0.3])
    box.apply_translation([0.1, -0.1, -0.3])
    return trimesh.util.concatenate([sheet, box])


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**16), el=st.floats(-80.0, 80.0), az=st.floats(0.0, 360.0))
def test_zbuffer_exact_equals_the_oracle_on_sliver_faces(seed, el, az):
    mesh = _sliver_mesh(seed)
    points, fi = zo.sample_surface(mesh, 3000, seed=seed)
    cam = zo.camera_on_sphere(el, az, resolution=256)
    truth = visible_mask(mesh, points, cam, "oracle", face_index=fi)
    assert 0.05 < truth.mean() < 0.95
    with ExactScene(mesh, points, fi) as with_fi, ExactScene(mesh, points) as without:
        assert np.array_equal(with_fi.visible(cam), truth)
        assert np.array_equal(without.visible(cam), truth)


def _sample(name: str, n: int):
    mesh = zo.load_mesh(SAMPLES / name)
    points, fi = zo.sample_surface(mesh, n, seed=3)
    return mesh, points, fi


def test_with_and_without_face_index_agree_and_match_the_oracle():
    mesh, points, fi = _sample("chair/train/chair_0001.off", 4000)
    for el, az in ((30.0, 20.0), (-60.0, 200.0), (0.0, 90.0)):
        cam = zo.camera_on_sphere(el, az, resolution=512)
        truth = visible_mask(mesh, points, cam, "oracle", face_index=fi)
        for method in ("zbuffer-exact", "embree-fast", "oracle", "oracle-numpy"):
            a = visible_mask(mesh, points, cam, method, face_index=fi)
            b = visible_mask(mesh, points, cam, method)
            if method == "embree-fast":  # float32 rays: near-exact
                assert (a == b).mean() >= 0.999 and (a == truth).mean() >= 0.999
            else:  # exact: bit for bit, with or without face_index
                assert np.array_equal(a, b), method
                assert np.array_equal(a, truth), method


def _shelf():
    """A cube with a shelf: a square in the plane y = 0 through the origin, plus an
    off-centre box, so that from azimuth 0, elevation 0, the shelf is seen exactly edge-on."""
    shelf = trimesh.Trimesh([[-0.4, 0.0, -0.4], [0.4, 0.0, -0.4], [0.4, 0.0, 0.4], [-0.4, 0.0, 0.4]], [[0, 1, 2], [0, 2, 3]])
    block = trimesh.creation.box([0.2, 0.2, 0.2])
    block.apply_translation([0.0, 0.3, 0.0])
    return trimesh.util.concatenate([shelf, block])


def test_points_on_a_face_seen_edge_on_are_hidden_by_every_method():
    mesh = _shelf()
    points, fi = zo.sample_surface(mesh, 2000, seed=0)
    on_shelf = fi < 2
    cam = zo.camera_on_sphere(0.0, 0.0, resolution=256)  # eye on the x axis: in the shelf's plane
    ref = None
    for method in EXACT_METHODS:
        for f in (fi, None):
            got = visible_mask(mesh, points, cam, method, face_index=f)
            assert not got[on_shelf].any(), (method, f is None)
            assert got[~on_shelf].any()
            ref = got if ref is None else ref
            assert np.array_equal(got, ref), (method, f is None)  # one definition, bit for bit
    # Turned by 100 times the edge-on angle (0.01°), the shelf shows: many of its points are visible.
    tilt = np.degrees(2 * EDGE_ON_SIN) * 50
    cam = zo.camera_on_sphere(0.0, tilt, resolution=256)
    for method in EXACT_METHODS:
        assert visible_mask(mesh, points, cam, method, face_index=fi)[on_shelf].mean() > 0.3, method


def test_edge_on_rule_without_face_index_finds_the_face_containing_the_point():
    mesh = _shelf()
    points, fi = zo.sample_surface(mesh, 500, seed=1)
    planes = mesh_planes(mesh)
    eye = np.array([3.0, 0.0, 0.0])
    own = edge_on_own(planes.normal[fi], points, eye)
    assert own.any() and np.array_equal(own, fi < 2)
    assert np.array_equal(edge_on_any(planes, points, eye), own)


def test_edge_on_rule_is_a_threshold_on_the_angle():
    n = np.array([[0.0, 1.0, 0.0]] * 2)
    p = np.zeros((2, 3))
    inside, outside = np.sin(np.radians(0.5)) * EDGE_ON_SIN * 180 / np.pi, 2 * EDGE_ON_SIN
    eye = np.array([[1.0, inside, 0.0], [1.0, outside, 0.0]])
    assert edge_on_own(n[:1], p[:1], eye[0]).tolist() == [True]
    assert edge_on_own(n[1:], p[1:], eye[1]).tolist() == [False]


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["egl", "osmesa"])
def test_auto_picks_a_valid_method_on_each_gl_backend(backend):
    code = (
        "import json, numpy as np, trimesh, zbuf_occlude as zo\n"
        "from zbuf_occlude.visibility import visible_mask\n"
        "from zbuf_occlude.visibility.auto import choose_method, _gl_renderer\n"
        "m = trimesh.creation.icosphere(subdivisions=2)\n"
        "p, fi = zo.sample_surface(m, 500, seed=0)\n"
        "cam = zo.camera_on_sphere(20.0, 30.0, resolution=128)\n"
        "same = bool(np.array_equal(visible_mask(m, p, cam, face_index=fi), visible_mask(m, p, cam, 'oracle', face_index=fi)))\n"
        "print(json.dumps([choose_method(), _gl_renderer(), same]))\n"
    )
    env = {**os.environ, "ZBUF_OCCLUDE_GL": backend, "PYTHONPATH": str(REPO_ROOT)}
    env.pop("ZBUF_OCCLUDE_AUTO", None)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    method, renderer, same = json.loads(out.stdout.strip().splitlines()[-1])
    assert method in ("zbuffer-exact", "embree-fast") and method in available_methods()
    if renderer is not None and "llvmpipe" in renderer.lower():
        assert method == "embree-fast"  # a software rasteriser shares the CPU
    assert same


def test_auto_env_override_is_checked(monkeypatch):
    from zbuf_occlude.errors import InvalidInputError
    from zbuf_occlude.visibility import auto

    auto.choose_method.cache_clear()
    try:
        monkeypatch.setenv(auto.AUTO_ENV, "zbuffer-exact")
        assert auto.choose_method() == "zbuffer-exact"
        auto.choose_method.cache_clear()
        monkeypatch.setenv(auto.AUTO_ENV, "bogus")
        with pytest.raises(InvalidInputError, match="ZBUF_OCCLUDE_AUTO"):
            auto.choose_method()
    finally:
        auto.choose_method.cache_clear()


def test_fast_scene_reports_its_cpu_fraction_and_is_deterministic():
    mesh, points, fi = _sample("chair/train/chair_0001.off", 3000)
    cams = [zo.camera_on_sphere(el, az) for el, az in ((10.0, 0.0), (45.0, 120.0))]
    scene = FastScene(mesh, points, fi, threads=2)
    first = [scene.visible(c) for c in cams]
    assert 0.0 <= scene.last_cpu_fraction < 0.05
    again = [FastScene(mesh, points, fi, threads=1).visible(c) for c in cams]
    assert all(np.array_equal(a, b) for a, b in zip(first, again))
