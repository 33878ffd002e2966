"""The fast preparation of point-only visibility (zbuf_occlude.visibility.point_preparation): the
same normals as the numpy statement of the method (geometry.normals.robust_normals, the reference)
on the shipped meshes, the same spacing as a k-d tree query, a 3 x 3 eigensolver that agrees
with LAPACK's, and the sides of thin walls as their statement in numpy below finds them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

import zbuf_occlude as zo
from zbuf_occlude.geometry.grouping import morton_order
from zbuf_occlude.geometry.normals import covariance_normals, robust_normals
from zbuf_occlude.visibility.point_neighbours import nearest_neighbours
from zbuf_occlude.visibility.point_preparation import plane_fits as fit_planes
from zbuf_occlude.visibility import point_preparation as prep
from zbuf_occlude.visibility.point_kernels import COPLANAR
from zbuf_occlude.visibility.point_preparation import surfel_geometry

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
MESHES = sorted(SAMPLES.glob("*/*/*.off"))


def plane_fits(points, neighbours, sizes):
    """The kernel's fits of every point."""
    normals, variation = np.empty((len(sizes), len(points), 3)), np.empty((len(sizes), len(points)))
    fit_planes(points, neighbours, np.asarray(sizes, dtype=np.int64), 0, len(points), normals, variation)
    return normals, variation


def _angle_deg(a, b):
    """Angle between the lines of unit vectors ``a`` and ``b`` (sign ignored), stable near 0."""
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.abs(np.einsum("ij,ij->i", a, b))))


@pytest.mark.parametrize("mesh_path", MESHES, ids=[p.stem for p in MESHES])
def test_the_fast_normals_are_the_reference_normals_on_the_shipped_meshes(mesh_path):
    mesh = zo.load_mesh(mesh_path)
    for n in (2_048, 10_000):
        points, _ = zo.sample_surface(mesh, n, seed=0)  # area-weighted
        points = np.asarray(points, dtype=np.float64)
        _, fast, _, _ = surfel_geometry(points, 4)
        angle = _angle_deg(fast, robust_normals(points))
        # measured: every point within 1e-6 degrees (rounding) on all 8 meshes at both sizes
        assert np.count_nonzero(angle > 1.0) == 0, (n, np.sort(angle)[-5:])
        assert angle.max() < 1e-3, (n, angle.max())


@pytest.mark.parametrize("n", [2, 3, 5, 7, 9, 15])
def test_tiny_clouds_get_the_reference_normals(n):
    points = np.random.default_rng(n).normal(size=(n, 3))
    _, fast, _, _ = surfel_geometry(points, 4)
    assert np.all(_angle_deg(fast, robust_normals(points)) < 1e-6)


@pytest.mark.parametrize("k", [1, 4, 20])
@pytest.mark.parametrize("estimate", [False, True])
def test_the_spacing_is_the_distance_to_the_k_th_neighbour_and_the_order_morton_s(k, estimate):
    points = np.random.default_rng(k).normal(size=(500, 3))
    given = None if estimate else np.tile([0.0, 0.0, 1.0], (len(points), 1))
    spacing, normals, sided, order = surfel_geometry(points, k, given)
    expected = cKDTree(points).query(points, k=k + 1)[0][:, -1]
    np.testing.assert_array_equal(spacing, expected)
    assert np.array_equal(order, morton_order(points))
    assert normals.shape == (len(points), 3) and sided.shape == (len(points),)
    if not estimate:  # given normals come back as given, but turned out of a wall where sided
        np.testing.assert_array_equal(np.abs(normals), np.abs(given))


def test_the_one_call_uses_the_fast_preparation():
    mesh = zo.load_mesh(MESHES[0])
    points, _ = zo.sample_surface(mesh, 3_000, seed=1)
    surfels = zo.point_surfels(points)
    assert np.all(_angle_deg(surfels.normals, robust_normals(np.asarray(points, dtype=np.float64))) < 1e-3)
    assert np.array_equal(surfels.order, morton_order(surfels.points))


matrices = st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=3 * 14, max_size=3 * 14)


@settings(max_examples=60, deadline=None)
@given(values=matrices, squash=st.sampled_from([1.0, 1e-3, 1e-9, 0.0]), scale=st.sampled_from([1e-80, 1.0, 1e80]))
@example(values=[0.0] * 39 + [1.0] * 3, squash=1.0, scale=1e80)  # a line (rank 1) whose products of entries overflow
def test_the_plane_fits_agree_with_lapack(values, squash, scale):
    # 14 points, flattened along z by ``squash`` (0: exactly planar), at any scale
    points = np.asarray(values).reshape(14, 3) * [1.0, 1.0, squash] * scale
    neighbours = np.tile(np.arange(14), (14, 1))
    normals, variation = plane_fits(points, neighbours, np.array([6, 9, 14]))
    for s, k in enumerate((6, 9, 14)):
        want_normal, want_variation = covariance_normals(points, neighbours[:, :k])
        np.testing.assert_allclose(variation[s], want_variation, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(normals[s], axis=1), 1.0, rtol=1e-12)
        values_k = np.linalg.eigvalsh(np.cov(points[:k].T, bias=True))
        spread = values_k[2] - values_k[0]
        if spread > 0 and values_k[1] - values_k[0] > 1e-3 * spread:  # the normal is well defined
            assert np.all(_angle_deg(normals[s], want_normal) < 1e-6)


def test_a_line_and_a_single_place_give_defined_normals():
    line = np.outer(np.linspace(0.0, 1.0, 14), [1.0, 2.0, 3.0])
    same = np.ones((14, 3))
    neighbours = np.tile(np.arange(14), (14, 1))
    for points in (line, same):
        normals, variation = plane_fits(points, neighbours, np.array([6, 9, 14]))
        np.testing.assert_allclose(np.linalg.norm(normals, axis=2), 1.0)
        np.testing.assert_allclose(variation, 0.0, atol=1e-12)
    normals, _ = plane_fits(line, neighbours, np.array([14]))
    assert np.all(np.abs(normals[0] @ np.array([1.0, 2.0, 3.0])) < 1e-9)  # across the line


clouds = st.sampled_from(["sphere", "plane", "line", "clusters", "duplicates", "one place", "gaussian", "tiny", "huge"])


def _cloud(kind: str, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if kind == "sphere":
        p = rng.normal(size=(n, 3))
        return p / np.linalg.norm(p, axis=1, keepdims=True)
    if kind == "plane":
        return np.column_stack([rng.uniform(-1, 1, size=(n, 2)), np.zeros(n)])
    if kind == "line":
        return np.outer(rng.uniform(0, 1, n), [1.0, -2.0, 0.5])
    if kind == "clusters":  # two knots far apart: most of the box empty
        return rng.normal(size=(n, 3)) * 1e-3 + np.where(rng.uniform(size=(n, 1)) < 0.5, 0.0, 1e3)
    if kind == "duplicates":
        return np.repeat(rng.normal(size=((n + 3) // 4, 3)), 4, axis=0)[:n]
    if kind == "one place":
        return np.full((n, 3), 2.5)
    if kind in ("tiny", "huge"):  # a span of subnormals; coordinates near MAX_SPLAT_COORDINATE
        return rng.normal(size=(n, 3)) * (1e-320 if kind == "tiny" else 1e99)
    return rng.normal(size=(n, 3)) * [1.0, 10.0, 0.01]


@settings(max_examples=40, deadline=None)
@given(kind=clouds, n=st.integers(2, 3_000), k=st.integers(1, 64), seed=st.integers(0, 2**31))
def test_the_grid_finds_the_k_d_tree_s_neighbours(kind, n, k, seed):
    points = _cloud(kind, n, seed)
    k = min(k, n)
    distance, index = nearest_neighbours(points, k)
    want_distance, want_index = cKDTree(points).query(points, k=k)
    want_distance, want_index = want_distance.reshape(n, k), want_index.reshape(n, k)
    np.testing.assert_array_equal(distance, want_distance)
    # the same neighbours up to the order of equally far ones (duplicates)
    got = np.linalg.norm(points[index] - points[:, None, :], axis=2)
    np.testing.assert_array_equal(got, np.linalg.norm(points[want_index] - points[:, None, :], axis=2))


def test_the_grid_s_threads_give_the_serial_answer():
    points = _cloud("sphere", 20_000, 3)
    one = nearest_neighbours(points, 9, workers=1)
    many = nearest_neighbours(points, 9, workers=3)
    assert all(np.array_equal(a, b) for a, b in zip(one, many))


def _thin_wall_sides(points, normals, spacing):
    """thin_wall_sides stated in numpy: Otsu's split of each neighbourhood's offsets along the
    point's normal, a wall where it explains THIN_WALL_SPLIT of their variance."""
    size = prep.THIN_WALL_NEIGHBOURS
    _, idx = cKDTree(points).query(points, k=size)
    near = points[idx]
    offsets = np.einsum("nkd,nd->nk", near - near.mean(axis=1, keepdims=True), normals)
    ordered = np.sort(offsets, axis=1)
    m = np.arange(1, size)
    below = np.cumsum(ordered, axis=1)[:, :-1]
    total = ordered.sum(axis=1, keepdims=True)
    mu0, mu1 = below / m, (total - below) / (size - m)
    between = (m / size) * (1 - m / size) * (mu1 - mu0) ** 2
    at = between.argmax(axis=1)
    rows = np.arange(len(points))
    share, gap = (at + 1) / size, (mu1 - mu0)[rows, at]
    sided = (
        (offsets.var(axis=1) > 0)
        & (between[rows, at] >= prep.THIN_WALL_SPLIT * offsets.var(axis=1))
        & (share >= prep.THIN_WALL_LEAST_SHARE) & (share <= 1 - prep.THIN_WALL_LEAST_SHARE)
        & (gap > COPLANAR * spacing) & (gap <= prep.THIN_WALL_MOST_GAP * spacing)
    )  # fmt: skip
    lower = offsets[:, 0] <= 0.5 * (ordered[rows, at] + ordered[rows, at + 1])
    return sided, np.where((sided & lower)[:, None], -normals, normals)


@pytest.mark.parametrize("mesh_path", MESHES, ids=[p.stem for p in MESHES])
def test_the_sides_of_thin_walls_are_those_the_method_states(mesh_path):
    mesh = zo.load_mesh(mesh_path)
    points, face_index = zo.sample_surface(mesh, 2_048, seed=0)
    points = np.asarray(points, dtype=np.float64)
    given_normals = mesh.face_normals[face_index]
    spacing, normals, sided, _ = surfel_geometry(points, 4, given_normals)
    expected, turned = _thin_wall_sides(points, given_normals, spacing)
    # the kernel sums in another order: a split within rounding of the limit may go either way
    assert np.count_nonzero(sided != expected) <= 2, np.flatnonzero(sided != expected)
    same = sided == expected
    np.testing.assert_allclose(normals[same], turned[same], atol=1e-12)
    assert expected.any() or not sided.any()
