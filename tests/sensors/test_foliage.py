"""Leaves inside a crown (sensors/scene/foliage.py): their count, where they lie, and the gap law of the turbid medium they form."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude.sensors.scene.foliage as foliage
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.scene.foliage import add_foliage, crown_region_volume, in_metres, leaf_quads


def _leaves(mesh: trimesh.Trimesh, grown: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """The added leaves' centres (n, 3) and unit normals (n, 3)."""
    corners = np.asarray(grown.vertices[len(mesh.vertices) :]).reshape(-1, 4, 3)
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return corners.mean(axis=1), normals / np.linalg.norm(normals, axis=1, keepdims=True)


def test_a_ball_is_filled_with_as_many_leaves_as_its_density_asks() -> None:
    ball = trimesh.creation.icosphere(subdivisions=3, radius=2.0)
    grown = add_foliage(ball, leaf_area_density=1.5, leaf_side_m=0.2, shell_m=5.0, seed=3)
    volume = ball.volume  # the icosphere's, a little under the sphere's
    n = (len(grown.faces) - len(ball.faces)) // 2
    assert n == pytest.approx(1.5 * volume / 0.2**2, rel=0.02)
    assert crown_region_volume(ball, shell_m=5.0, seed=3) == pytest.approx(ball.volume, rel=0.01)
    # the mesh first, unchanged; two triangles a leaf, each a square of the side asked for
    assert np.array_equal(grown.vertices[: len(ball.vertices)], ball.vertices) and np.array_equal(
        grown.faces[: len(ball.faces)], ball.faces
    )
    assert len(grown.faces) - len(ball.faces) == 2 * n and len(grown.vertices) - len(ball.vertices) == 4 * n
    leaf_area = grown.area_faces[len(ball.faces) :]
    assert leaf_area.sum() == pytest.approx(n * 0.2**2, rel=1e-9)
    centres, _ = _leaves(ball, grown)
    assert np.all(np.linalg.norm(centres, axis=1) <= 2.0 + 1e-9)  # inside the hull


def test_leaves_fill_only_a_shell_under_the_surface() -> None:
    ball = trimesh.creation.icosphere(subdivisions=4, radius=3.0)
    grown = add_foliage(ball, leaf_area_density=1.0, leaf_side_m=0.1, shell_m=1.0, seed=0)
    r = np.linalg.norm(_leaves(ball, grown)[0], axis=1)
    # within 1 m of the surface (the k-d tree of surface samples overstates distances by at most about shell/5)
    assert r.min() >= 2.0 - 0.25 and r.max() <= 3.0 + 1e-9
    shell_volume = 4.0 / 3.0 * math.pi * (3.0**3 - 2.0**3)
    assert crown_region_volume(ball, shell_m=1.0) == pytest.approx(shell_volume, rel=0.03)
    assert len(r) == pytest.approx(1.0 * shell_volume / 0.01, rel=0.03)


def test_the_leaves_normals_are_spherical() -> None:
    grown = add_foliage(box := trimesh.creation.box(extents=(4.0, 4.0, 4.0)), leaf_area_density=2.0, leaf_side_m=0.1, shell_m=4.0)
    _, normals = _leaves(box, grown)
    # uniform on the sphere: each component's |mean| 0 and mean |n_z| = 1/2 (the projection G of the gap law)
    se = 1.0 / math.sqrt(len(normals))
    assert np.abs(normals.mean(axis=0)).max() < 5 * se
    assert np.abs(normals[:, 2]).mean() == pytest.approx(0.5, abs=5 * se)


@pytest.mark.parametrize("lad", [0.5, 1.0, 2.0])
def test_a_vertical_ray_passes_a_slab_of_leaves_with_the_turbid_mediums_gap_probability(lad: float) -> None:
    depth, side = 2.0, 0.1
    slab = trimesh.creation.box(extents=(12.0, 12.0, depth))
    grown = add_foliage(slab, leaf_area_density=lad, leaf_side_m=side, shell_m=depth, seed=1)
    leaves = trimesh.Trimesh(grown.vertices, grown.faces[len(slab.faces) :], process=False)
    rng = np.random.default_rng(0)
    xy = rng.uniform(-4.0, 4.0, (20_000, 2))  # away from the slab's sides
    origins = np.column_stack([xy, np.full(len(xy), depth)])
    hit = leaves.ray.intersects_any(origins, np.tile([0.0, 0.0, -1.0], (len(xy), 1)))
    expected = math.exp(-0.5 * lad * depth)  # exp(-G · LAD · L), G = 1/2
    # leaves shadow about 50 rays each: an error of a few hundredths is the spread of one slab
    assert 1.0 - hit.mean() == pytest.approx(expected, abs=0.04)


def test_the_same_seed_gives_the_same_leaves() -> None:
    ball = trimesh.creation.icosphere(subdivisions=2, radius=1.5)
    a, b = (add_foliage(ball, leaf_area_density=1.0, seed=7) for _ in range(2))
    c = add_foliage(ball, leaf_area_density=1.0, seed=8)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert not np.array_equal(a.vertices, c.vertices)
    assert add_foliage(ball, leaf_area_density=0.0) is ball
    alone = add_foliage(ball, leaf_area_density=1.0, seed=7, keep_surface=False)  # the same leaves without the mesh
    assert np.array_equal(alone.vertices, a.vertices[len(ball.vertices) :]) and np.array_equal(
        alone.faces, a.faces[len(ball.faces) :] - len(ball.vertices)
    )


@settings(max_examples=20, deadline=None)
@given(n=st.integers(1, 50), side=st.floats(0.01, 2.0), seed=st.integers(0, 2**32 - 1))
def test_leaf_quads_are_squares_about_their_centres_facing_their_normals(n: int, side: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(n, 3)) * 10
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    vertices, faces = leaf_quads(centres, normals, side, rng)
    corners = vertices.reshape(n, 4, 3)
    assert np.allclose(corners.mean(axis=1), centres, atol=1e-9 * (1 + side))
    edges = np.linalg.norm(np.roll(corners, -1, axis=1) - corners, axis=2)
    assert np.allclose(edges, side, rtol=1e-9)
    assert np.allclose(np.linalg.norm(corners[:, 2] - corners[:, 0], axis=1), side * math.sqrt(2), rtol=1e-9)
    tri = vertices[faces]
    face_normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    face_normals /= np.linalg.norm(face_normals, axis=1, keepdims=True)
    assert np.allclose(face_normals, np.repeat(normals, 2, axis=0), atol=1e-6)  # counter-clockwise seen from the normal


def test_in_metres_scales_the_largest_dimension() -> None:
    box = trimesh.creation.box(extents=(2.0, 1.0, 0.5)).apply_translation((5.0, -3.0, 1.0))
    scaled = in_metres(box, 8.0)
    assert np.ptp(scaled.vertices, axis=0) == pytest.approx([8.0, 4.0, 2.0])
    assert scaled.vertices.min(axis=0) == pytest.approx([0.0, 0.0, 0.0])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"leaf_area_density": -1.0}, "leaf_area_density must be a finite number >= 0, got a number outside that range"),
        ({"leaf_area_density": math.nan}, "leaf_area_density must be a finite number >= 0, got NaN"),
        ({"leaf_area_density": "dense"}, "leaf_area_density must be a finite number >= 0, got a string of 5 characters"),
        ({"leaf_area_density": 1.0, "leaf_side_m": 0.0}, "leaf_side_m must be a finite number >= 0.001, got a number outside that range"),
        ({"leaf_area_density": 1.0, "shell_m": math.inf}, "shell_m must be a finite number > 0, got an infinite number"),
    ],
)
def test_bad_settings_are_refused_naming_the_value(kwargs, message) -> None:
    with pytest.raises(InvalidInputError, match=message):
        add_foliage(trimesh.creation.box(), **kwargs)


def test_meshes_without_a_volume_or_of_another_kind_are_refused() -> None:
    flat = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 3, 2]])
    with pytest.raises(InvalidInputError, match="encloses no volume"):
        add_foliage(flat, leaf_area_density=1.0)
    with pytest.raises(InvalidInputError, match="needs a trimesh.Trimesh, got Scene"):
        add_foliage(trimesh.Scene(), leaf_area_density=1.0)
    with pytest.raises(InvalidInputError, match="no extent"):
        in_metres(trimesh.Trimesh([[1.0, 1.0, 1.0]], []), 3.0)
    with pytest.raises(InvalidInputError, match="size_m must be a finite number > 0"):
        in_metres(trimesh.creation.box(), -2.0)


def test_a_crown_asking_for_too_many_leaves_is_refused_before_they_are_drawn(monkeypatch) -> None:
    monkeypatch.setattr(foliage, "MAX_LEAVES", 100)
    with pytest.raises(InvalidInputError, match=r"leaf_area_density and leaf_side_m ask for more than 100 leaves in this crown"):
        add_foliage(trimesh.creation.box(extents=(3.0, 3.0, 3.0)), leaf_area_density=5.0)
