"""The one CPU kernel of the segment-triangle test, its numpy form and its GLSL twin agree bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import BackendUnavailable
from zbuf_occlude.visibility.kernels import pair_occludes_one
from zbuf_occlude.visibility.segment_triangle import pack_planes, pair_occludes, triangle_planes

TOLERANCE = 1e-9


def _pairs(seed: int, n_faces: int, n_pairs: int, tie_fraction: float):
    """Random triangles, and points and eyes of which some lie on a face's plane, edge or corner
    (the near-ties where float64 rounding decides)."""
    rng = np.random.default_rng(seed)
    tri = rng.normal(size=(n_faces, 3, 3))
    faces = rng.integers(0, n_faces, n_pairs)
    points = rng.normal(size=(n_pairs, 3))
    eyes = rng.normal(scale=4.0, size=(n_pairs, 3))
    ties = rng.random(n_pairs) < tie_fraction
    # a segment aimed at a random point of the face's boundary: the crossing is on an edge
    w = rng.random((n_pairs, 3)) * (rng.random((n_pairs, 3)) > 0.4)
    w /= np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    target = np.einsum("kj,kjd->kd", w, tri[faces])
    eyes[ties] = points[ties] + (target[ties] - points[ties]) * rng.uniform(1.0, 3.0, (ties.sum(), 1))
    return tri, faces, points, eyes


def _cpu(packed, faces, points, eyes):
    out = np.zeros(len(points), dtype=bool)
    for k in range(len(points)):
        p, e = points[k], eyes[k]
        sx, sy, sz = e[0] - p[0], e[1] - p[1], e[2] - p[2]
        seg_len = np.sqrt(sx * sx + sy * sy + sz * sz)
        out[k] = pair_occludes_one(p[0], p[1], p[2], sx, sy, sz, seg_len, packed[faces[k]], TOLERANCE)
    return out


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), tie_fraction=st.sampled_from([0.0, 0.5, 1.0]))
def test_the_kernel_equals_its_numpy_form(seed: int, tie_fraction: float) -> None:
    tri, faces, points, eyes = _pairs(seed, 20, 300, tie_fraction)
    planes = triangle_planes(tri)
    seg = eyes - points
    seg_len = np.sqrt(np.einsum("ij,ij->i", seg, seg))
    numpy_form = pair_occludes(points, seg, seg_len, planes, faces, None, TOLERANCE)
    np.testing.assert_array_equal(_cpu(pack_planes(planes), faces, points, eyes), numpy_form)


def test_the_kernel_sees_hits_misses_and_the_closed_boundary() -> None:
    tri = np.array([[[0.0, -1.0, -1.0], [0.0, 1.0, -1.0], [0.0, 0.0, 1.0]]])
    planes = triangle_planes(tri)
    # through the face, beside it, away from it, exactly through its edge (0, 0, -1) and its
    # corner (0, 0, 1) (closed triangle: both occlude), and a face within the self-hit tolerance
    points = np.array([[-1.0, 0.0, 0.0], [-1.0, 5.0, 0.0], [-1.0, 0.0, 0.0], [-1.0, 0.0, -1.0], [-1.0, 0.0, 1.0],
                       [-1e-12, 0.0, 0.0]])  # fmt: skip
    eyes = np.array([[3.0, 0.0, 0.0], [3.0, 5.0, 0.0], [-3.0, 0.0, 0.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0],
                     [3.0, 0.0, 0.0]])  # fmt: skip
    expected = [True, False, False, True, True, False]
    faces = np.zeros(len(points), dtype=int)
    np.testing.assert_array_equal(_cpu(pack_planes(planes), faces, points, eyes), expected)
    seg = eyes - points
    seg_len = np.sqrt(np.einsum("ij,ij->i", seg, seg))
    np.testing.assert_array_equal(pair_occludes(points, seg, seg_len, planes, faces, None, TOLERANCE), expected)


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), tie_fraction=st.sampled_from([0.0, 0.5, 1.0]))
def test_the_glsl_twin_decides_every_pair_as_the_kernel(seed: int, tie_fraction: float) -> None:
    try:
        from zbuf_occlude.render.probe import HIT, MISS, TIE, pair64_on_gpu
    except BackendUnavailable as exc:  # pragma: no cover - CI has Mesa's llvmpipe
        pytest.skip(str(exc))
    tri, faces, points, eyes = _pairs(seed, 20, 500, tie_fraction)
    packed = pack_planes(triangle_planes(tri))
    gpu = pair64_on_gpu(packed, points, eyes, faces, TOLERANCE)
    cpu = _cpu(packed, faces, points, eyes)
    assert set(np.unique(gpu)) <= {MISS, HIT, TIE}
    decided = gpu != TIE
    np.testing.assert_array_equal(gpu[decided] == HIT, cpu[decided])  # a tie goes to the CPU: no claim
    assert decided.mean() > (0.98 if tie_fraction == 0.0 else 0.5)  # a twin that calls everything a tie proves nothing
    assert cpu[decided].any() and (~cpu[decided]).any()


def test_the_triangle_is_closed_where_a_crossing_lies_exactly_on_an_edge_plane() -> None:
    # a hand-packed face: plane x = 0, edges y >= 0.5, -y >= -10, z >= -10; the segment crosses at
    # (0, 0.5, 0), exactly on the first edge plane (0.5 >= 0.5): closed, so it occludes
    row = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.5, -10.0, -10.0])
    assert pair_occludes_one(-1.0, 0.5, 0.0, 2.0, 0.0, 0.0, 2.0, row, TOLERANCE)
    assert not pair_occludes_one(-1.0, 0.25, 0.0, 2.0, 0.0, 0.0, 2.0, row, TOLERANCE)  # just outside
