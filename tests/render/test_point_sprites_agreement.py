"""The GPU surfel z-buffer breaks ties as the numba kernel does, and rounds as it does: surfels
at the same depth go to the lowest id whichever pass draws them, a division that is not
correctly rounded is corrected, and the masks of every shipped mesh are the CPU's.  These run on
Mesa llvmpipe headless, as the other GL tests, and never skip.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.render import point_sprites
from zbuf_occlude.render.point_sprites import PointSpriteRenderer
from zbuf_occlude.visibility import point_kernels
from zbuf_occlude.visibility.point_kernels import EDGE_ON_COS, splat_surfels

#: Every surfel a sprite, every surfel a quad, 8-pixel tiles.
PASSES = {"sprites": {}, "quads": {"max_point_size": 1.0}, "tiles": {"max_tile": 8}}
#: A 40 × 30 image over the normalised square [-0.2, 0.2) × [-0.15, 0.15).
IMAGE = (0.01, -0.2, -0.15, 40, 30)


def _splat(cam, normal, radius, image=IMAGE, **settings):
    with PointSpriteRenderer() as renderer:
        for name, value in settings.items():
            setattr(renderer, name, value)
        return renderer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)


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


#: The tie test's strip (as tests/render/test_point_sprites.py's quad test): the pixels the quad disk
#: covers beyond the GL's largest point size, the empty pixels right of it, and the strip's height;
#: the small disk's radius, and the widest strip drawn (16 rows of it take 200 MB).  A strip, not a
#: square: a box's longer side decides the route, and a square as wide as the largest point size
#: (8192² on some GLs) would cost gigabytes for nothing.
_BEYOND_PX, _GAP_PX, _STRIP_PX, _SMALL_PX, _MAX_STRIP_WIDTH_PX = 16, 16, 16, 5, 1 << 20


@pytest.mark.parametrize("quad", [0, 1], ids=["quad-lowest", "sprite-lowest"])
def test_the_tie_goes_to_the_lowest_id_when_it_is_a_quad_and_the_other_a_sprite(monkeypatch, quad):
    """On any GL, whatever its limits: two disks in the plane z = 2 tie at every pixel of the
    smaller; the larger covers ``ceil(max_point_size) + 16`` pixels of a 16-pixel strip, so its box
    is wider than any sprite and it takes the quad pass, the smaller a sprite.  The tie goes to the
    lower id whichever of the two is the quad (sprites are drawn first, quads last), and the
    buffers are the kernel's bit for bit."""
    sprite = 1 - quad
    split, routes = point_sprites._Boxes.split, []
    monkeypatch.setattr(point_sprites._Boxes, "split", lambda box, *args: routes.append(split(box, *args)) or routes[-1])
    with PointSpriteRenderer() as renderer:
        max_point_size, max_tile = renderer.max_point_size, renderer.max_tile
        cover = math.ceil(max_point_size) + _BEYOND_PX
        width = cover + _GAP_PX
        # a sprite's box is 2 rho + 1 pixels wide, and is drawn 2 pixels wider
        rho = min(_SMALL_PX, (math.floor(max_point_size) - 3) // 2)
        if width > _MAX_STRIP_WIDTH_PX or rho < 1:
            pytest.skip(f"the GL's largest point size is {max_point_size:g} pixels: no affordable strip shows the tie")
        # the quad disk spans x/z in ±0.75: its right edge lies `cover` pixels right of the strip's
        # left edge, its left edge far left of the strip
        pix = 1.0 / cover
        image = (pix, 0.75 - cover * pix, -0.5 * _STRIP_PX * pix, width, _STRIP_PX)
        # the small disk centred on a pixel in the middle of the first tile (or of the quad disk's
        # columns), its box inside that tile
        column, row = min(max_tile, cover) // 2, _STRIP_PX // 2
        cam = np.full((2, 3), 2.0)
        cam[quad, :2] = 0.0
        cam[sprite, :2] = 2.0 * (np.array(image[1:3]) + (np.array([column, row]) + 0.5) * pix)
        normal = np.tile([0.0, 0.0, 1.0], (2, 1))
        radius = np.empty(2)
        radius[quad], radius[sprite] = 1.5, 2.0 * rho * pix
        depth, ids = renderer.splat(cam, normal, radius, *image, edge_on_cos=EDGE_ON_COS)
    # the routes, one split a tile: the large disk a quad in every tile of its columns, the small one a sprite
    assert len(routes) == math.ceil(width / max_tile), routes
    assert all(quad in quads for _, quads in routes[: (cover - 1) // max_tile + 1]), (routes, max_point_size)
    assert not any(quad in sprites for sprites, _ in routes), (routes, max_point_size)
    assert any(sprite in sprites for sprites, _ in routes), (routes, max_point_size)
    assert not any(sprite in quads for _, quads in routes), (routes, max_point_size)
    # the buffers are the kernel's, and every pixel of the smaller disk went to id 0 at depth 2
    depth_cpu, ids_cpu = splat_surfels(cam, normal, radius, *image)
    assert np.array_equal(ids, ids_cpu) and np.array_equal(depth, depth_cpu)
    smaller = splat_surfels(cam[[sprite]], normal[[sprite]], radius[[sprite]], *image)[1] == 0
    assert smaller.sum() >= 2 * rho * rho and np.all(ids[smaller] == 0) and np.all(depth[smaller] == 2.0)
    assert (ids == quad).any(axis=0).sum() >= cover - 1  # the quad disk, wider than any sprite


def test_the_tie_test_sizes_its_strip_from_the_gl_it_runs_on(monkeypatch):
    """The tie test under other GLs' limits, by the renderer's queried values: a largest point
    size of 2047 (NVIDIA), 8192, one equal to the largest image (64 with 64-pixel tiles: the
    strip is drawn in two tiles), and a tiny one (8, with 32-pixel tiles)."""
    init = PointSpriteRenderer.__init__
    for max_point_size, max_tile in ((2047.0, None), (8192.0, None), (64.0, 64), (8.0, 32)):

        def limited(self, *args, _size=max_point_size, _tile=max_tile, **kwargs):
            init(self, *args, **kwargs)
            self.max_point_size = _size
            self.max_tile = _tile or self.max_tile

        for quad in (0, 1):
            with monkeypatch.context() as patched:
                patched.setattr(PointSpriteRenderer, "__init__", limited)
                test_the_tie_goes_to_the_lowest_id_when_it_is_a_quad_and_the_other_a_sprite(patched, quad)


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
    assert point_sprites._BOX_MARGIN == point_kernels.BOX_MARGIN


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
    """The fragment shader with ``old`` replaced by ``new`` (a division rounded otherwise)."""
    load = point_sprites.load_shader

    def patched(name, defines=()):
        source = load(name, defines)
        if name == "point_splat.frag":
            assert old in source
            source = source.replace(old, new)
        return source

    monkeypatch.setattr(point_sprites, "load_shader", patched)


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
    """benchmarks/agreement_point_sprites.py (run by benchmarks/gpu.sh), at a tiny size."""
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from agreement_point_sprites import agreement

    row = agreement(sample_mesh_files[:1], 256, [zo.camera_on_sphere(30.0, 45.0)], normals=False)
    assert (row["masks"], row["ids"], row["depth"], row["point_views"]) == (1.0, 1.0, 0.0, 256)
