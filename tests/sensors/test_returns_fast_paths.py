"""The multi-return scan's fast paths give the general paths' results bit for bit.

* :func:`~zbuf_occlude.sensors.beam.footprint.subray_directions`, one coordinate at a time, against
  the (N, K, 3) formula it replaced (``np.cross``, ``np.linalg.norm``);
* the exact ray parameter on a known hit face (Embree's hits, and the per-face numerator from
  one origin) against :func:`~zbuf_occlude.sensors.raycast.embree.ray_triangle_f64`, degenerate faces
  and rays in a face's plane included;
* the float32 rays :func:`~zbuf_occlude.sensors.raycast.embree.cast_embree` hands Embree against those
  trimesh's ``intersects_first`` hands it (the same bytes, so the same faces);
* :func:`~zbuf_occlude.sensors.beam.echoes.resolve_echoes` on rows sorted by pulse (each pulse's
  rows sorted in a table; runs of two tied rows swapped in place) against the same rows in
  another order (sorts of all rows), and the one-surface echoes' shortcut against the grouping
  by surface.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.sensors.beam import echoes as E
from zbuf_occlude.sensors.raycast import embree as raycast
from zbuf_occlude.sensors.beam.footprint import footprint_offsets, subray_directions
from zbuf_occlude.sensors.raycast.embree import _exact_distance, _ray_parameter, cast_embree, ray_triangle_f64


def _subray_directions_reference(d: np.ndarray, off: np.ndarray) -> np.ndarray:
    """The (N, K, 3) formula of subray_directions before it worked one coordinate at a time."""
    out = np.empty((len(d), len(off), 3))
    centre = off[:, 0] == 0.0
    out[:, centre] = d[:, None, :]
    ring = np.flatnonzero(~centre)
    helper = np.where(np.abs(d[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(d, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(d, u)
    tan = np.array([math.tan(theta) for theta in off[ring, 0]])
    phi = off[ring, 1]
    rays = d[:, None, :] + tan[None, :, None] * (np.cos(phi)[None, :, None] * u[:, None, :] + np.sin(phi)[None, :, None] * v[:, None, :])
    rays /= np.linalg.norm(rays, axis=2, keepdims=True)
    out[:, ring] = rays
    return out


def _directions(seed: int, n: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d[: n // 4, 2] *= 30.0  # |d_z| >= 0.9: the x helper
    d[n // 4 : n // 3, 2] = 0.0  # horizontal beams (zeros of either sign in the products)
    d = np.concatenate([d, [[0.0, 0.0, 1.0], [0.0, -0.0, -1.0], [-0.0, 1.0, 0.0]]])  # the poles, an axis
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 300), st.integers(1, 61), st.floats(1e-3, 20.0))
def test_subray_directions_are_the_full_formulas_bits(seed, n, k, divergence_deg) -> None:
    d = _directions(seed, n)
    off = footprint_offsets(k, divergence_deg)[0]
    assert subray_directions(d, off).tobytes() == _subray_directions_reference(d, off).tobytes()


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 100), st.integers(2, 19), st.floats(1e-3, 20.0))
def test_subray_directions_with_centre_rays_anywhere_are_the_full_formulas_bits(seed, n, k, divergence_deg) -> None:
    # offsets in any row order, a second centre ray among them: the ring's rows are not one slice
    off = footprint_offsets(k, divergence_deg)[0]
    off = np.random.default_rng(seed).permutation(np.concatenate([off, [[0.0, 0.5]]]))
    d = _directions(seed, n)
    assert subray_directions(d, off).tobytes() == _subray_directions_reference(d, off).tobytes()


def _soup(n_faces: int, seed: int) -> trimesh.Trimesh:
    """Random triangles in a 10 m box around (20, 0, 0)."""
    rng = np.random.default_rng(seed)
    v = rng.uniform(-5.0, 5.0, (3 * n_faces, 3)) + [20.0, 0.0, 0.0]
    return trimesh.Trimesh(v, np.arange(3 * n_faces).reshape(-1, 3), process=False)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 200), st.integers(1, 400), st.booleans())
def test_the_exact_range_on_a_hit_face_is_ray_triangle_f64s(seed, n_faces, n_rays, one_origin) -> None:
    # fewer or more rays than faces: the numerator per face (one origin) or per ray
    mesh = _soup(n_faces, seed)
    rng = np.random.default_rng(seed + 1)
    d = rng.normal(size=(n_rays, 3)) + [3.0, 0.0, 0.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    face = rng.integers(0, n_faces, n_rays)
    origin = rng.normal(size=3) if one_origin else rng.normal(size=(n_rays, 3))
    tri = np.asarray(mesh.triangles, dtype=np.float64)[face]
    if one_origin:
        expected = ray_triangle_f64(origin, d, tri)[0]
    else:  # ray_triangle_f64 takes one origin: one ray at a time
        expected = np.concatenate([ray_triangle_f64(origin[i], d[i : i + 1], tri[i : i + 1])[0] for i in range(n_rays)])
    assert _ray_parameter(mesh, origin, d, face).tobytes() == expected.tobytes()


def test_embree_ranges_are_ray_triangle_f64s_on_the_hit_faces() -> None:
    mesh = _soup(300, 7)
    d = _directions(8, 2000) + [2.0, 0.0, 0.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    face, t = cast_embree(mesh, np.zeros(3), d)
    hit = face >= 0
    assert 100 < hit.sum() < len(d)
    assert np.all(np.isinf(t[~hit]))
    expected = ray_triangle_f64(np.zeros(3), d[hit], np.asarray(mesh.triangles, dtype=np.float64)[face[hit]])[0]
    assert t[hit].tobytes() == expected.tobytes()


def test_degenerate_faces_and_rays_in_a_faces_plane_have_no_range() -> None:
    # a face of one point, one of three points on a line, and a ray lying in a face's plane: det 0 or
    # a range that is not finite, so inf, as ray_triangle_f64 gives it; a miss (face -1) is inf too
    v = np.array([[5.0, 0, 0], [5, 0, 0], [5, 0, 0], [5, -1, 0], [5, 0, 0], [5, 1, 0], [5, -1, -1], [5, 1, -1], [5, 0, 1]])
    mesh = trimesh.Trimesh(v, np.arange(9).reshape(3, 3), process=False)
    d = np.array([[1.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 0, 0]])
    origin = np.array([0.0, 0, 0])
    face = np.array([0, 1, 2, 2, -1])
    t = _exact_distance(mesh, origin, d, face)
    expected = ray_triangle_f64(origin, d[:4], np.asarray(mesh.triangles, dtype=np.float64)[face[:4]])[0]
    assert t[:4].tobytes() == expected.tobytes() and np.isinf(t[[0, 1, 2, 4]]).all() and t[3] == 5.0


class _Recorder:
    """Stands in for an Embree scene: keeps the float32 rays each ``run`` is given, then runs them."""

    def __init__(self, scene) -> None:
        self.scene, self.calls = scene, []

    def run(self, origins, directions, *args, **kwargs):
        self.calls.append((np.array(origins), np.array(directions)))
        return self.scene.run(origins, directions, *args, **kwargs)


def _odd_directions(seed: int, n: int) -> np.ndarray:
    """Unit rays, and others trimesh's unitize treats alike: long, short, tiny components, a zero ray."""
    rng = np.random.default_rng(seed)
    d = _directions(seed, n) + [1.5, 0.0, 0.0]
    d *= 10.0 ** rng.uniform(-3.0, 3.0, (len(d), 1)) * (rng.random((len(d), 1)) < 0.3) + (rng.random((len(d), 1)) >= 0.3)
    d[rng.random(len(d)) < 0.2, 2] *= 1e-9
    d[0] = 0.0
    d[1] = [1e-300, 0.0, 0.0]
    return d


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 400), st.booleans())
def test_embree_is_given_the_float32_rays_trimesh_gives_it(seed, n, one_origin) -> None:
    mesh = _soup(200, seed)
    d = _odd_directions(seed, n)
    rng = np.random.default_rng(seed + 2)
    origin = rng.normal(size=3) if one_origin else rng.normal(size=(len(d), 3))
    intersector = raycast._intersector(mesh)
    wrap = intersector._scene
    recorder = _Recorder(wrap.scene)
    wrap.scene = recorder
    try:
        ours = raycast._first_faces(mesh, origin, d)
        theirs = intersector.intersects_first(np.broadcast_to(origin, d.shape), d)
    finally:
        wrap.scene = recorder.scene
    (o1, d1), (o2, d2) = recorder.calls
    assert o1.dtype == d1.dtype == np.float32
    assert o1.tobytes() == o2.tobytes() and d1.tobytes() == d2.tobytes()
    assert np.array_equal(ours, theirs) and ours.dtype == np.int64


def test_another_trimesh_wrapper_is_asked_through_its_own_call(monkeypatch) -> None:
    # a wrapper without the scene, shift and scale this mirrors: trimesh's intersects_first, as it is
    class Intersector:
        _scene = object()

        def intersects_first(self, origins, directions):
            self.given = (np.array(origins), np.array(directions))
            return np.full(len(directions), 3, np.int32)

    intersector = Intersector()
    monkeypatch.setattr(raycast, "_intersector", lambda mesh: intersector)
    d = _directions(1, 10)
    face = raycast._first_faces(None, np.ones(3), d)
    assert face.dtype == np.int64 and np.all(face == 3)
    assert np.array_equal(intersector.given[0], np.ones((len(d), 3))) and np.array_equal(intersector.given[1], d)


@st.composite
def scan_hits(draw):
    """Hits of a few pulses as a scan gives them: rows by pulse, ranges on a coarse grid (runs of
    two, three or more rows of one pulse at one range), a few surfaces, energies that tie."""
    n_pulses = draw(st.integers(1, 12))
    per_pulse = draw(st.lists(st.integers(1, 9), min_size=n_pulses, max_size=n_pulses))
    if draw(st.booleans()):  # one pulse with many rows: the sort of all rows
        per_pulse[0] = 60
    pulse = np.repeat(np.arange(n_pulses) * 3, per_pulse)
    m = len(pulse)
    ranges = st.integers(0, 12).map(lambda i: 0.25 * i) | st.just(-0.0)  # -0 ties with 0
    r = np.array(draw(st.lists(ranges, min_size=m, max_size=m)))
    # energies that tie, and others whose sums depend on the order of the rows
    energies = st.sampled_from([0.0, 0.5, 1.0]) | st.floats(0.01, 3.0)
    e = np.array(draw(st.lists(energies, min_size=m, max_size=m)))
    s = np.array(draw(st.lists(st.integers(0, 2), min_size=m, max_size=m)), np.int64)
    return pulse, r, e, s


@settings(max_examples=300, deadline=None)
@given(scan_hits(), st.sampled_from([0.1, 0.3, 0.6]), st.integers(1, 4))
def test_rows_by_pulse_resolve_as_the_same_rows_in_any_order(hits, resolution, max_returns) -> None:
    pulse, r, e, s = hits
    rules = {"range_resolution_m": resolution, "detection_threshold": 0.5, "max_returns": max_returns}
    fast = E.resolve_echoes(pulse, r, e, s, **rules)
    back = np.arange(len(pulse))[::-1]  # pulses descending: the general sorts
    general = E.resolve_echoes(pulse[back], r[back], e[back], s[back], **rules)
    for field in ("pulse", "range_m", "energy", "surface", "return_number", "number_of_returns"):
        assert getattr(fast, field).tobytes() == getattr(general, field).tobytes() or (
            # rows equal on all four (a range of -0 and one of 0) are interchangeable: either's bits
            field == "range_m" and len(set(zip(pulse, r + 0.0, e, s))) < len(pulse) and np.array_equal(fast.range_m, general.range_m)
        ), field
    for column in (pulse, r, e, s):  # the hit named: the same row, or one just like it
        assert np.array_equal(column[back][general.hit], column[fast.hit])


@settings(max_examples=300, deadline=None)
@given(scan_hits())
def test_the_sort_by_pulse_and_range_is_lexsorts(hits) -> None:
    pulse, r, _, _ = hits
    assert np.array_equal(E._pulse_range_order(pulse, r), np.lexsort((r, pulse)))


@settings(max_examples=300, deadline=None)
@given(scan_hits(), st.sampled_from([0.1, 0.3, 0.6]))
def test_the_one_surface_shortcut_gives_the_grouping_by_surface(hits, resolution) -> None:
    pulse, r, e, s = hits
    order = np.lexsort((s, e, r, pulse))
    p, r, e, s = pulse[order], r[order], e[order], s[order]
    new = np.ones(len(p), bool)
    new[1:] = (p[1:] != p[:-1]) | (np.diff(r) >= resolution)
    echo = np.cumsum(new) - 1
    surface, hit = E._dominant_surface(echo, np.flatnonzero(new), s, e)
    expected_surface, expected_hit = E._dominant_surface_of_mixed(echo, s, e)
    assert np.array_equal(surface, expected_surface) and np.array_equal(hit, expected_hit)
