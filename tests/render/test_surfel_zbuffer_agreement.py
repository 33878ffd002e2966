"""The GPU surfel z-buffer breaks ties as the numba kernel does, and rounds as it does: surfels
at the same depth go to the lowest id whatever order the GPU runs them in and however the image is
tiled, a division that is not correctly rounded is corrected, and the masks of every shipped mesh
are the CPU's.  These run on
Mesa llvmpipe headless, as the other GL tests, and never skip.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.render import surfel_zbuffer
from zbuf_occlude.render.surfel_zbuffer import SurfelZBuffer
from zbuf_occlude.visibility import point_kernels
from zbuf_occlude.visibility.point_kernels import EDGE_ON_COS, splat_surfels

#: The image in one tile, in bands of 4 rows, or each row in parts of 16 pixels.
PASSES = {"one tile": {}, "bands": {"max_tile_bytes": 8 * 40 * 4}, "row parts": {"max_tile_bytes": 8 * 16}}
#: A 40 × 30 image over the normalised square [-0.2, 0.2) × [-0.15, 0.15).
IMAGE = (0.01, -0.2, -0.15, 40, 30)


def _splat(cam, normal, radius, image=IMAGE, **settings):
    with SurfelZBuffer() as zbuffer:
        for name, value in settings.items():
            setattr(zbuffer, name, value)
        return zbuffer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)


@pytest.mark.parametrize("setting", PASSES)
def test_surfels_at_the_same_depth_go_to_the_lowest_id(setting):
    # three copies of one disk facing the camera, with a smaller one in front of them
    cam = np.array([[0.0, 0.0, 2.0], [0.05, 0.0, 1.5], [0.0, 0.0, 2.0], [0.0, 0.0, 2.0]])
    normal = np.tile([0.0, 0.0, 1.0], (4, 1))
    radius = np.array([0.6, 0.02, 0.6, 0.6])  # the image in full
    depth, ids = _splat(cam, normal, radius, **PASSES[setting])
    depth_cpu, ids_cpu = splat_surfels(cam, normal, radius, *IMAGE)
    assert np.array_equal(ids, ids_cpu) and np.array_equal(depth, depth_cpu)
    assert set(np.unique(ids)) == {0, 1}


@pytest.mark.parametrize("setting", PASSES)
def test_the_tie_goes_to_the_lowest_id_whatever_the_order_of_the_surfels(setting):
    """Eight copies of one disk, in the plane z = 2, tie at every pixel; a ninth, smaller, in
    front.  Whichever of the copies comes first or last in the arrays, the lowest id of them
    wins every pixel the small disk leaves, as in the kernel (which keeps a depth only if less)."""
    rng = np.random.default_rng(2)
    for _ in range(4):
        copies = rng.permutation(8)
        cam = np.tile([0.0, 0.0, 2.0], (9, 1))
        cam[8] = [0.05, 0.02, 1.5]
        normal = np.tile([0.0, 0.0, 1.0], (9, 1))
        radius = np.append(np.full(8, 0.6), 0.02)[np.append(copies, 8)]
        depth, ids = _splat(cam, normal, radius, **PASSES[setting])
        depth_cpu, ids_cpu = splat_surfels(cam, normal, radius, *IMAGE)
        assert np.array_equal(ids, ids_cpu) and np.array_equal(depth, depth_cpu)
        assert set(np.unique(ids)) == {0, 8}


def test_coplanar_neighbours_tie_as_on_the_cpu():
    # a tilted plane sampled on a grid, disks overlapping twice over: their depths at a pixel
    # differ by float64 rounding only, and the kernel's rounding picks the winner
    u, v = np.meshgrid(np.linspace(-0.3, 0.3, 25), np.linspace(-0.2, 0.2, 17))
    normal_1 = np.array([0.3, -0.2, -1.0]) / np.linalg.norm([0.3, -0.2, -1.0])
    e1 = np.cross(normal_1, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal_1, e1)
    cam = np.array([0.0, 0.0, 2.0]) + u.reshape(-1, 1) * e1 + v.reshape(-1, 1) * e2
    normal = np.tile(normal_1, (len(cam), 1))
    radius = np.full(len(cam), 0.05)
    depth_cpu, ids_cpu = splat_surfels(cam, normal, radius, *IMAGE)
    for setting in PASSES.values():
        depth, ids = _splat(cam, normal, radius, **setting)
        assert np.array_equal(ids, ids_cpu) and np.array_equal(depth, depth_cpu)


def test_the_boxes_are_the_kernels():
    assert surfel_zbuffer._BOX_MARGIN == point_kernels.BOX_MARGIN


@settings(max_examples=25, deadline=None)
@given(
    axis=st.integers(0, 2), tilt=st.one_of(st.floats(0.0, 1e-3), st.floats(0.0, 2.0)), turn=st.floats(0.0, 2 * np.pi),
    x=st.floats(-0.3, 0.3), y=st.floats(-0.2, 0.2), z=st.floats(1.2, 3.0), radius=st.floats(0.02, 0.5),
)  # fmt: skip
def test_a_disk_thin_along_an_axis_fills_what_the_kernel_fills(axis, tilt, turn, x, y, z, radius):
    """The box of a disk is its own extent along each axis (``r sqrt(1 - n_a²)``): every pixel the
    disk test passes is in it, for any tilt of the normal from an axis (a disk whose normal lies
    within 1e-3 of one is all but flat along it)."""
    normal = np.zeros(3)
    normal[axis] = 1.0
    normal[(axis + 1) % 3] = tilt * np.cos(turn)
    normal[(axis + 2) % 3] = tilt * np.sin(turn)
    normal /= np.linalg.norm(normal)
    cam = np.array([[x * z, y * z, z]])
    if z - radius <= 0.0:
        return
    depth, ids = _splat(cam, normal[None], np.array([radius]))
    depth_cpu, ids_cpu = splat_surfels(cam, normal[None], np.array([radius]), *IMAGE)
    assert np.array_equal(ids, ids_cpu) and np.array_equal(depth, depth_cpu)


def _with_division(monkeypatch, old: str, new: str) -> None:
    """The compute shader with ``old`` replaced by ``new`` (a division rounded otherwise)."""
    load = surfel_zbuffer.load_shader

    def patched(name, defines=()):
        source = load(name, defines)
        if name == "point_splat.comp":
            assert old in source
            source = source.replace(old, new)
        return source

    monkeypatch.setattr(surfel_zbuffer, "load_shader", patched)


#: The shader's quotient, and one that is an ulp off where the reciprocal rounds.
DIVISION, RECIPROCAL = "precise double t0 = nq / den;", "precise double t0 = nq * (1.0 / den);"
CORRECTION, NONE = "t0 + residual(nq, t0, den) / den;", "t0;"


@pytest.mark.parametrize("corrected", [True, False], ids=["corrected", "not-corrected"])
def test_a_division_an_ulp_off_is_corrected(monkeypatch, corrected):
    """A driver whose float64 division is not correctly rounded (here: by the reciprocal) gives
    the kernel's depths after the shader's correction, and other depths without it."""
    rng = np.random.default_rng(1)
    n = 300
    cam = np.stack([rng.uniform(-0.2, 0.2, n) * 3, rng.uniform(-0.15, 0.15, n) * 3, rng.uniform(2.5, 3.5, n)], axis=1)
    normal = rng.normal(size=(n, 3)) + [0.0, 0.0, -2.0]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    radius = rng.uniform(0.02, 0.1, n)
    _with_division(monkeypatch, DIVISION, RECIPROCAL)
    if not corrected:
        _with_division(monkeypatch, CORRECTION, NONE)
    depth, _ = _splat(cam, normal, radius)
    depth_cpu, _ = splat_surfels(cam, normal, radius, *IMAGE)
    assert np.array_equal(depth, depth_cpu) == corrected


def test_masks_equal_on_every_shipped_mesh(sample_mesh_files):
    """The GPU backend's masks are the CPU's on each shipped mesh (estimated normals, 2 poses)."""
    cameras = [zo.camera_on_sphere(el, az) for el, az in zo.view_schedule("fibonacci:2")]
    for path in sample_mesh_files:
        mesh = zo.load_mesh(path)
        surfels = zo.point_surfels(zo.sample_surface(mesh, 512, seed=0)[0])
        for camera in cameras:
            assert np.array_equal(surfels.visible(camera, backend="gpu"), surfels.visible(camera)), path.name


def test_the_agreement_benchmark_reports_equal_masks_and_buffers(sample_mesh_files, monkeypatch):
    """benchmarks/agreement_point_splats.py (run by benchmarks/gpu.sh), at a tiny size."""
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from agreement_point_splats import agreement

    row = agreement(sample_mesh_files[:1], 256, [zo.camera_on_sphere(30.0, 45.0)], normals=False)
    assert (row["masks"], row["ids"], row["depth"], row["point_views"]) == (1.0, 1.0, 0.0, 256)


def _count_cpu_decisions(monkeypatch) -> list[int]:
    """Count the CPU kernel's decisions (:func:`point_kernels.decide` and its threaded twin)."""
    calls = []
    for name in ("decide", "decide_threaded"):
        kernel = getattr(point_kernels, name)
        monkeypatch.setattr(point_kernels, name, lambda *a, _k=kernel: calls.append(1) or _k(*a))
    return calls


@pytest.mark.parametrize("kind", ["estimated", "given", "oriented"])
def test_the_gpu_decides_each_point_as_the_kernel_does(sample_mesh_files, monkeypatch, kind):
    """The decision runs on the GPU (the CPU kernel is never called) and gives the kernel's mask,
    for each kind of normals and at tolerances 0 and 1 (the splats alone, no hull test)."""
    mesh = zo.load_mesh(next(p for p in sample_mesh_files if "chair" in p.name))
    points, face_index = zo.sample_surface(mesh, 2048, seed=0)
    normals = None if kind == "estimated" else mesh.face_normals[face_index]
    surfels = zo.point_surfels(points, normals, oriented=kind == "oriented")
    cameras = [zo.camera_on_sphere(el, az) for el, az in zo.view_schedule("fibonacci:6")]
    expected = [[surfels.visible(c, tolerance=tol, hull_test=False) for tol in (0.0, 1.0)] for c in cameras]
    calls = _count_cpu_decisions(monkeypatch)
    got = [[surfels.visible(c, tolerance=tol, hull_test=False, backend="gpu") for tol in (0.0, 1.0)] for c in cameras]
    assert not calls
    assert all(np.array_equal(g, e) for gs, es in zip(got, expected) for g, e in zip(gs, es))
    assert 0.2 < np.mean([e.mean() for es in expected for e in es]) < 0.8


def test_a_view_of_several_tiles_is_decided_on_the_cpu(sample_mesh_files, monkeypatch):
    """Where the image does not fit one storage buffer, the GPU fills it in tiles, reads it back,
    and the CPU kernel decides: the same mask."""
    surfels = zo.point_surfels(zo.sample_surface(zo.load_mesh(sample_mesh_files[0]), 1024, seed=0)[0])
    camera = zo.camera_on_sphere(30.0, 45.0)
    expected = surfels.visible(camera, hull_test=False)
    calls = _count_cpu_decisions(monkeypatch)
    monkeypatch.setattr(surfel_zbuffer.shared_surfel_zbuffer(), "max_tile_bytes", 8 * 512)
    assert np.array_equal(surfels.visible(camera, hull_test=False, backend="gpu"), expected)
    assert len(calls) == 1
    with pytest.raises(ValueError, match="several tiles"):
        surfel_zbuffer.shared_surfel_zbuffer().visible(
            np.zeros((1, 3)), np.zeros((1, 3)), np.ones(1), np.ones(1), np.zeros(1, bool), (0.01, 0.0, 0.0, 64, 64),
            edge_on_cos=EDGE_ON_COS, rule=None,
        )  # fmt: skip


@settings(max_examples=20, deadline=None)
@given(
    n=st.integers(1, 300), seed=st.integers(0, 2**16), el=st.floats(-80.0, 80.0), az=st.floats(0.0, 360.0),
    flat=st.booleans(), oriented=st.booleans(),
)  # fmt: skip
def test_masks_equal_on_random_clouds(n, seed, el, az, flat, oriented):
    """Any cloud, any pose: a blob or a thin slab of random points, with or without oriented
    normals (from the origin out), decided on the GPU as on the CPU."""
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(n, 3)) * ([1.0, 1.0, 0.05] if flat else 1.0)
    normals = points / np.maximum(np.linalg.norm(points, axis=1, keepdims=True), 1e-9) if oriented else None
    if oriented:
        normals[np.linalg.norm(normals, axis=1) == 0] = [0.0, 0.0, 1.0]
    surfels = zo.point_surfels(points, normals, oriented=oriented)
    camera = zo.camera_on_sphere(el, az, 6.0)
    assert np.array_equal(surfels.visible(camera, backend="gpu"), surfels.visible(camera))
