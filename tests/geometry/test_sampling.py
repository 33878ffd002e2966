"""Tests of zbuf_occlude.geometry.sampling (Sryamkin et al. 2023, §3.4, Algorithms 1 and 2).

Statistical tests use fixed seeds, so they are deterministic; their thresholds
(p > P_MIN, or a few standard deviations) are loose enough that a correct sampler
passes for essentially any seed and tight enough that a biased one fails.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import real_mesh as real_mesh_path
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import stats

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.geometry.sampling import points_from_barycentric, sample_faces, sample_surface, triangles_of
from zbuf_occlude.mesh.load import load_mesh

#: Smallest p-value accepted from a goodness-of-fit test.
P_MIN = 1e-3
#: Half-width, in standard deviations, of the accepted band for a count.
N_SIGMA = 5.0
#: A sampled point lies on its face's plane to this distance (float64, unit-size mesh).
PLANE_TOL = 1e-12


@pytest.fixture(scope="module")
def real_mesh() -> trimesh.Trimesh:
    """A normalised real ModelNet mesh of very unequal face areas: bathtub_0003 (19 870
    faces) from the subset, else the shipped desk_0201 (7608 faces)."""
    return load_mesh(real_mesh_path("ModelNet10/bathtub/train/bathtub_0003.off", substitute="ModelNet40/desk/test/desk_0201.off"))


@pytest.fixture(scope="module")
def sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=2)


def _plane_distance(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return np.abs(np.einsum("ij,ij->i", points - triangles[:, 0], normal))


def _barycentric_of(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N, 3) barycentric coordinates of points projected onto their triangles, recomputed
    independently of the sampler (Ericson, Real-Time Collision Detection, §3.4)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((v0, v0), (v0, v1), (v1, v1)))
    d20, d21 = np.einsum("ij,ij->i", v2, v0), np.einsum("ij,ij->i", v2, v1)
    denom = d00 * d11 - d01 * d01
    w1 = (d11 * d20 - d01 * d21) / denom
    w2 = (d00 * d21 - d01 * d20) / denom
    return np.column_stack([1.0 - w1 - w2, w1, w2])


# -- geometry: every sample lies on its face ---------------------------------------------


@pytest.mark.parametrize("mode", [{"count": 50_000}, {"density": 20_000.0}])
def test_points_lie_on_their_faces(real_mesh: trimesh.Trimesh, mode: dict) -> None:
    face_index, bary = sample_faces(real_mesh, seed=3, **mode)
    points, face_index_2 = sample_surface(real_mesh, seed=3, **mode)
    assert np.array_equal(face_index, face_index_2)
    assert face_index.dtype == np.int64 and bary.dtype == np.float64 and points.dtype == np.float64
    assert bary.shape == (len(face_index), 3) and points.shape == (len(face_index), 3)
    assert np.all(bary >= 0.0)
    np.testing.assert_allclose(bary.sum(axis=1), 1.0, rtol=0, atol=1e-15)
    triangles = triangles_of(real_mesh)[face_index]
    assert _plane_distance(triangles, points).max() < PLANE_TOL
    # Algorithm 2's form of the same point
    manual = triangles[:, 0] + bary[:, 1:2] * (triangles[:, 1] - triangles[:, 0]) + bary[:, 2:3] * (triangles[:, 2] - triangles[:, 0])
    np.testing.assert_allclose(points, manual, rtol=0, atol=1e-14)


nondegenerate_triangle = arrays(np.float64, (3, 3), elements=st.floats(-100.0, 100.0, allow_nan=False, allow_infinity=False)).filter(
    # well-shaped enough that the independent barycentric recomputation is accurate:
    # area at least 1e-3 of the squared longest edge
    lambda t: (
        np.linalg.norm(np.cross(t[1] - t[0], t[2] - t[0]))
        > 2e-3 * max(np.sum((t[1] - t[0]) ** 2), np.sum((t[2] - t[1]) ** 2), np.sum((t[0] - t[2]) ** 2))
    )
)


@settings(max_examples=60, deadline=None)
@given(triangle=nondegenerate_triangle, seed=st.integers(0, 2**32 - 1))
def test_samples_inside_random_triangles(triangle: np.ndarray, seed: int) -> None:
    triangles = triangle[None]
    points, face_index = sample_surface(triangles, 200, seed=seed)
    assert np.all(face_index == 0)
    edge = max(np.linalg.norm(triangle[i] - triangle[j]) for i, j in ((0, 1), (1, 2), (2, 0)))
    tri = np.repeat(triangles, len(points), axis=0)
    assert _plane_distance(tri, points).max() <= 1e-12 * max(edge, np.abs(triangle).max())
    # recomputed (not returned) barycentrics: inside, up to rounding
    assert _barycentric_of(tri, points).min() >= -1e-9
    lo, hi = triangle.min(axis=0), triangle.max(axis=0)
    slack = 1e-12 * np.abs(triangle).max()
    assert np.all(points >= lo - slack) and np.all(points <= hi + slack)


# -- determinism -------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", [{"count": 1000}, {"density": 500.0}])
def test_same_seed_same_bytes_other_seed_differs(sphere: trimesh.Trimesh, mode: dict) -> None:
    a_points, a_faces = sample_surface(sphere, seed=7, **mode)
    b_points, b_faces = sample_surface(sphere, seed=7, **mode)
    assert a_points.tobytes() == b_points.tobytes() and a_faces.tobytes() == b_faces.tobytes()
    g_points, g_faces = sample_surface(sphere, seed=np.random.default_rng(7), **mode)
    assert g_points.tobytes() == a_points.tobytes() and g_faces.tobytes() == a_faces.tobytes()
    c_points, _ = sample_surface(sphere, seed=8, **mode)
    assert c_points.shape != a_points.shape or not np.array_equal(c_points, a_points)


def test_generator_is_advanced(sphere: trimesh.Trimesh) -> None:
    rng = np.random.default_rng(1)
    first, _ = sample_surface(sphere, 100, seed=rng)
    second, _ = sample_surface(sphere, 100, seed=rng)
    assert not np.array_equal(first, second)


# -- counts --------------------------------------------------------------------------------------


@pytest.mark.parametrize("count", [0, 1, 2, 999, 10_000])
def test_count_mode_exact_count(sphere: trimesh.Trimesh, count: int) -> None:
    points, face_index = sample_surface(sphere, count, seed=0)
    assert points.shape == (count, 3) and points.dtype == np.float64
    assert face_index.shape == (count,) and face_index.dtype == np.int64
    face_index, bary = sample_faces(sphere, count, seed=0)
    assert face_index.shape == (count,) and bary.shape == (count, 3) and bary.dtype == np.float64


def test_density_mode_is_algorithm_1(real_mesh: trimesh.Trimesh) -> None:
    density = 3_000.0
    face_index, _ = sample_faces(real_mesh, density=density, seed=11)
    expected = real_mesh.area_faces * density
    per_face = np.bincount(face_index, minlength=len(expected))
    whole = np.floor(expected)
    # every face gets floor(A s) or floor(A s) + 1 points, in face order
    assert np.all((per_face == whole) | (per_face == whole + 1))
    assert np.all(np.diff(face_index) >= 0)
    # the +1 happens with probability frac(A s): total ~ sum(A) s, variance sum f (1 - f)
    frac = expected - whole
    sigma = np.sqrt(np.sum(frac * (1.0 - frac)))
    assert abs(len(face_index) - real_mesh.area * density) < N_SIGMA * sigma
    # and it is not just always rounding up or down: faces with frac < 0.1 rarely get
    # the extra point, faces with frac > 0.9 usually do
    extra = per_face - whole
    assert extra[frac < 0.1].mean() < 0.15 and extra[frac > 0.9].mean() > 0.85


def test_density_mode_mean_count_over_seeds(sphere: trimesh.Trimesh) -> None:
    density = 37.3  # sphere area ~12.5 -> ~466 points, every face fractional
    counts = np.array([len(sample_faces(sphere, density=density, seed=s)[0]) for s in range(200)])
    expected = sphere.area * density
    frac = sphere.area_faces * density % 1.0
    sigma_mean = np.sqrt(np.sum(frac * (1 - frac)) / len(counts))
    assert abs(counts.mean() - expected) < N_SIGMA * sigma_mean


# -- uniformity ----------------------------------------------------------------------------------


def test_count_mode_chi_square_against_areas(real_mesh: trimesh.Trimesh) -> None:
    n = 200_000
    face_index, _ = sample_faces(real_mesh, n, seed=5)
    areas = real_mesh.area_faces
    # group consecutive faces into bins of about equal area so that every expected
    # count is large (single faces range over 6 orders of magnitude of area)
    # (a face larger than one bin leaves bins empty: renumber the non-empty ones)
    mid = (np.cumsum(areas) - areas / 2.0) / areas.sum()
    _, bin_of_face = np.unique(np.minimum((mid * 100).astype(int), 99), return_inverse=True)
    n_bins = int(bin_of_face.max()) + 1
    assert n_bins > 50
    observed = np.bincount(bin_of_face[face_index], minlength=n_bins)
    expected = n * np.bincount(bin_of_face, weights=areas, minlength=n_bins) / areas.sum()
    assert expected.min() > 5
    assert stats.chisquare(observed, expected).pvalue > P_MIN
    # the same test rejects picking faces uniformly, the classic mistake
    uniform = np.random.default_rng(5).integers(0, len(areas), n)
    assert stats.chisquare(np.bincount(bin_of_face[uniform], minlength=n_bins), expected).pvalue < 1e-12


@pytest.mark.parametrize("mode", [{"count": 40_000}, {"density": 20_000.0}])
def test_two_triangles_area_ratio_1_to_3(mode: dict) -> None:
    triangles = np.array(
        [
            [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],  # area 0.5
            [[5.0, 0.0, 0.0], [8.0, 0.0, 0.0], [5.0, 1.0, 0.0]],  # area 1.5
        ]
    )
    face_index, _ = sample_faces(triangles, seed=2, **mode)
    n, k = len(face_index), int(np.sum(face_index == 1))
    if "count" in mode:
        assert n == mode["count"]
        assert stats.binomtest(k, n, 0.75).pvalue > P_MIN
    else:
        # Algorithm 1 gives exactly floor(A s) (+1 with prob frac): 10 000 and 30 000
        assert (n - k, k) == (10_000, 30_000)


def test_zero_area_faces_are_never_sampled() -> None:
    good = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    flat = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]
    triangles = np.array([flat, good, flat, good, flat])  # flat first, between and last
    for mode in ({"count": 20_000}, {"density": 10_000.0}):
        face_index, _ = sample_faces(triangles, seed=0, **mode)
        assert set(np.unique(face_index)) == {1, 3}


def test_uniform_inside_a_triangle() -> None:
    triangle = np.array([[[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [1.0, 2.0, 0.5]]])
    n = 40_000
    _, bary = sample_faces(triangle, n, seed=9)
    # the medial triangle (corners at edge midpoints) holds 1/4 of the area: a point is
    # in it when every barycentric coordinate is <= 1/2
    in_medial = int(np.sum(np.all(bary <= 0.5, axis=1)))
    assert stats.binomtest(in_medial, n, 0.25).pvalue > P_MIN
    # each barycentric coordinate of a uniform point has CDF 1 - (1 - x)^2
    for k in range(3):
        assert stats.kstest(bary[:, k], lambda x: 1.0 - (1.0 - np.clip(x, 0, 1)) ** 2).pvalue > P_MIN
    # the same KS test rejects the unfolded square sample, clipped into the triangle
    r = np.random.default_rng(9).random((n, 2))
    clipped = np.clip(1.0 - r.sum(axis=1), 0.0, None)
    assert stats.kstest(clipped, lambda x: 1.0 - (1.0 - np.clip(x, 0, 1)) ** 2).pvalue < 1e-12


# -- points_from_barycentric ---------------------------------------------------------------------


def test_points_from_barycentric_corners_and_mesh_or_triangles(sphere: trimesh.Trimesh) -> None:
    faces = np.array([0, 5, 5, 17], dtype=np.int64)
    bary = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1 / 3, 1 / 3, 1 / 3]])
    points = points_from_barycentric(sphere, faces, bary)
    corners = sphere.vertices[sphere.faces]
    np.testing.assert_array_equal(points[0], corners[0, 0])
    np.testing.assert_array_equal(points[1], corners[5, 1])
    np.testing.assert_array_equal(points[2], corners[5, 2])
    np.testing.assert_allclose(points[3], sphere.triangles_center[17], atol=1e-15)
    np.testing.assert_array_equal(points_from_barycentric(corners, faces, bary), points)
    empty = points_from_barycentric(sphere, np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
    assert empty.shape == (0, 3) and empty.dtype == np.float64


@pytest.mark.parametrize(
    ("face_index", "bary", "match"),
    [
        (np.array([0, 1]), np.zeros((3, 3)), "shape"),
        (np.array([[0]]), np.zeros((1, 3)), "face_index"),
        (np.array([0.5]), np.zeros((1, 3)), "integer"),
        (np.array([10_000]), np.full((1, 3), 1 / 3), "spans"),
        (np.array([-1]), np.full((1, 3), 1 / 3), "spans"),
        (np.array([0]), np.array([[np.nan, 0.5, 0.5]]), "NaN"),
    ],
)
def test_points_from_barycentric_rejects_bad_input(sphere: trimesh.Trimesh, face_index: np.ndarray, bary: np.ndarray, match: str) -> None:
    with pytest.raises(InvalidInputError, match=match):
        points_from_barycentric(sphere, face_index, bary)


# -- errors ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"count": -1}, ">= 0"),
        ({"count": 1.5}, "integer"),
        ({"count": True}, "integer"),
        ({}, "exactly one"),
        ({"count": 10, "density": 1.0}, "exactly one"),
        ({"density": 0.0}, "> 0"),
        ({"density": -3.0}, "> 0"),
        ({"density": float("nan")}, "finite"),
        ({"density": float("inf")}, "finite"),
        ({"density": 1e308}, "too large"),
        ({"count": 1, "seed": "abc"}, None),
    ],
)
def test_bad_arguments(sphere: trimesh.Trimesh, kwargs: dict, match: str | None) -> None:
    if match is None:
        # an invalid seed is numpy's to reject, with its own TypeError/ValueError
        with pytest.raises((TypeError, ValueError)):
            sample_faces(sphere, **kwargs)
        return
    with pytest.raises(InvalidInputError, match=match):
        sample_faces(sphere, **kwargs)
    with pytest.raises(InvalidInputError, match=match):
        sample_surface(sphere, **kwargs)


@pytest.mark.parametrize(
    "mesh",
    [
        np.zeros((0, 3, 3)),
        np.array([[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]]]),
        trimesh.Trimesh(vertices=np.eye(3), faces=np.zeros((0, 3), dtype=np.int64), process=False),
    ],
    ids=["no-faces", "collinear", "trimesh-without-faces"],
)
def test_zero_total_area_is_rejected(mesh: object) -> None:
    for mode in ({"count": 10}, {"count": 0}, {"density": 1.0}):
        with pytest.raises(InvalidInputError, match="zero total area"):
            sample_surface(mesh, seed=0, **mode)


@pytest.mark.parametrize(
    ("triangles", "match"),
    [(np.zeros((2, 3)), "shape"), (np.full((1, 3, 3), np.nan), "NaN"), ([["a", "b", "c"]], "float")],
)
def test_bad_triangles(triangles: object, match: str) -> None:
    with pytest.raises(InvalidInputError, match=match):
        sample_surface(triangles, 10)


def test_a_file_name_is_not_a_mesh() -> None:
    with pytest.raises(ArgumentTypeError, match=r"zo.load_mesh"):
        sample_surface("chair.off", 10)


@pytest.mark.parametrize(
    "seed", [10**5000, -(10**5000), 2**64, [0] * 1_000_000, "x" * 1_000_000], ids=["10**5000", "-10**5000", "2**64", "list", "str"]
)
def test_check_seed_refuses_huge_values_in_one_short_line(seed: object) -> None:
    """Python will not write an int of over 4,300 digits as text (a bare ValueError while the
    message was built); a huge list or string must not fill the message either."""
    from zbuf_occlude.geometry.sampling import check_seed

    with pytest.raises(InvalidInputError) as info:
        check_seed(seed)
    text = str(info.value)
    assert "\n" not in text and len(text) < 200 and text.startswith("seed must be")
