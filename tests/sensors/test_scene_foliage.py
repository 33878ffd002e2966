"""Leaves in a scene object's crown (SceneObject.foliage, a scene file's ``foliage``): grown in metres, placed by the mesh alone, refused when hostile."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.scene.foliage import LEAF_MATERIAL, MAX_LEAVES, MIN_LEAF_SIDE_M, Foliage, add_foliage
from zbuf_occlude.sensors.scene.materials import MATERIALS, scene_optics
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject
from zbuf_occlude.sensors.scene.files import load_scene

BALL = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
MATERIALS_ROWS = list(MATERIALS)


def _built(**fields):
    return ScanScene(objects=[SceneObject(BALL, fields.pop("class_name", "tree"), (3.0, -2.0), yaw_deg=30.0, **fields)]).build()


def _leaf_sides(built, start: int) -> np.ndarray:
    """The lengths of the first edge of every leaf triangle from face ``start`` on (a leaf's side or its diagonal)."""
    tri = built.mesh.vertices[built.mesh.faces[start:]]
    return np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1)


@pytest.mark.parametrize("size_m", [4.0, (6.0, 3.0, 4.0)])
def test_leaves_are_grown_in_metres_and_the_mesh_is_placed_as_without_them(size_m) -> None:
    bare, leafy = _built(size_m=size_m), _built(size_m=size_m, foliage=Foliage(1.0, leaf_side_m=0.2, seed=3))
    f = len(bare.mesh.faces)
    # the mesh's faces first, where they were: the leaves do not move, size or turn the object
    assert np.array_equal(leafy.mesh.faces[:f], bare.mesh.faces)
    assert np.allclose(leafy.mesh.vertices[: len(bare.mesh.vertices)], bare.mesh.vertices, rtol=0, atol=1e-12)
    assert np.array_equal(leafy.face_local[:f], bare.face_local) and np.array_equal(leafy.face_object[:f], bare.face_object)
    # the leaves: squares of 0.2 m in the world frame, even under a non-uniform scale (two triangles a leaf: a side, then the diagonal)
    sides = _leaf_sides(leafy, f)
    assert len(sides) > 100 and len(sides) % 2 == 0
    assert np.allclose(sides[0::2], 0.2, atol=1e-9) and np.allclose(sides[1::2], 0.2 * np.sqrt(2), atol=1e-9)
    # their rows counted on from the mesh's faces as loaded; their object the tree's
    assert np.array_equal(leafy.face_local[f:], len(BALL.faces) + np.arange(len(sides)))
    assert np.all(leafy.face_object[f:] == 1)


def test_the_leaf_count_is_the_density_times_the_crown_region_in_metres() -> None:
    # a 4 m ball, its region within 1 m of the surface: 4/3 π (2³ − 1³) = 29.3 m³; one-sided area = LAD · V
    for lad in (0.5, 2.0):
        built = _built(size_m=4.0, foliage={"leaf_area_density": lad})
        f = len(_built(size_m=4.0).mesh.faces)
        area = 0.1**2 * (len(built.mesh.faces) - f) / 2
        assert area == pytest.approx(lad * 4.0 / 3.0 * np.pi * 7.0, rel=0.04)


def test_leaves_alone_replace_a_closed_crown_placed_where_it_stood() -> None:
    with_hull = _built(size_m=4.0, foliage=Foliage(1.0, seed=1))
    alone = _built(size_m=4.0, foliage=Foliage(1.0, keep_surface=False, seed=1))
    f = len(_built(size_m=4.0).mesh.faces)
    ground = 2  # the ground's two triangles come first
    assert np.array_equal(alone.face_object[:ground], [0, 0]) and np.all(alone.face_object[ground:] == 1)
    assert len(alone.mesh.faces) == len(with_hull.mesh.faces) - (f - ground)  # the hull's faces gone, the same leaves
    assert np.allclose(alone.mesh.vertices[alone.mesh.faces[ground:]], with_hull.mesh.vertices[with_hull.mesh.faces[f:]], atol=1e-12)
    assert np.array_equal(alone.face_local[ground:], len(BALL.faces) + np.arange(len(alone.mesh.faces) - ground))


def test_leaves_reflect_as_foliage_and_stop_the_ray_whatever_the_objects_class() -> None:
    built = _built(size_m=4.0, class_name="pole", foliage={"leaf_area_density": 1.0})
    f = len(_built(size_m=4.0, class_name="pole").mesh.faces)
    optics = scene_optics(built, 1064.0)
    foliage = scene_optics(_built(size_m=4.0), 1064.0)  # a tree's faces: foliage, with its gap fraction
    assert (
        np.all(optics.face_reflectivity[f:] == foliage.face_reflectivity[-1])
        and optics.face_reflectivity[f - 1] != foliage.face_reflectivity[-1]
    )
    # a grown leaf is opaque: the gaps of the crown are the space between its leaves, not a fraction of each
    assert np.all(optics.face_transmittance[f:] == 0.0) and foliage.face_transmittance[-1] > 0.0
    assert {MATERIALS_ROWS[i] for i in optics.face_material[f:]} == {LEAF_MATERIAL}


def test_no_foliage_and_zero_density_build_the_mesh_alone() -> None:
    bare = _built(size_m=4.0)
    for foliage in (None, {"leaf_area_density": 0.0}):
        again = _built(size_m=4.0, foliage=foliage)
        assert np.array_equal(again.mesh.faces, bare.mesh.faces) and np.array_equal(again.mesh.vertices, bare.mesh.vertices)


def test_a_scene_file_grows_leaves(tmp_path) -> None:
    trimesh.creation.icosphere(subdivisions=2).export(tmp_path / "crown.obj")
    spec = {"objects": [{"mesh": "crown.obj", "class": "tree", "size_m": 4.0, "foliage": {"leaf_area_density": 1.0, "seed": 2}}]}
    (tmp_path / "scene.json").write_text(json.dumps(spec))
    scene = load_scene(tmp_path / "scene.json")
    assert scene.objects[0].foliage == Foliage(1.0, seed=2)
    assert len(scene.build().mesh.faces) > 5000


@pytest.mark.parametrize(
    ("foliage", "message"),
    [
        ({"leaf_area_density": 1.0, "leaves": 3}, "unknown foliage keys 'leaves'"),
        ({"leaf_side_m": 0.1}, "foliage needs leaf_area_density"),
        ([1.0], "foliage must be a mapping"),
        ({"leaf_area_density": -1.0}, "leaf_area_density"),
        ({"leaf_area_density": float("nan")}, "leaf_area_density"),
        ({"leaf_area_density": "1"}, "leaf_area_density"),
        ({"leaf_area_density": 1.0, "leaf_side_m": 1e-300}, "leaf_side_m"),
        ({"leaf_area_density": 1.0, "shell_m": 0.0}, "shell_m"),
        ({"leaf_area_density": 1.0, "seed": -1}, "seed"),
        ({"leaf_area_density": 1.0, "seed": 1.5}, "seed"),
        ({"leaf_area_density": 1.0, "keep_surface": "no"}, "keep_surface must be true or false"),
    ],
)  # fmt: skip
def test_a_scene_files_bad_foliage_is_refused_naming_the_file_and_field(tmp_path, foliage, message) -> None:
    spec = {"objects": [{"mesh": {"box_m": [1, 1, 1]}, "foliage": foliage}]}
    (tmp_path / "scene.json").write_text(json.dumps(spec))
    with pytest.raises(InvalidInputError, match=message) as caught:
        load_scene(tmp_path / "scene.json")
    assert "scene.json" in str(caught.value) and "objects[0]" in str(caught.value)


@pytest.mark.parametrize("density", [1e6, 1e308])
def test_a_crown_asking_for_too_many_leaves_is_refused_before_any_is_drawn(density) -> None:
    with pytest.raises(InvalidInputError, match=f"ask for more than {MAX_LEAVES:,} leaves in this crown"):
        _built(size_m=4.0, foliage={"leaf_area_density": density})
    with pytest.raises(InvalidInputError, match="leaf_side_m"):
        add_foliage(BALL, leaf_area_density=1.0, leaf_side_m=MIN_LEAF_SIDE_M / 2)


def test_a_flat_object_cannot_grow_leaves_and_says_which() -> None:
    plate = trimesh.creation.box(extents=(2.0, 2.0, 0.0))
    with pytest.raises(InvalidInputError, match=r"objects\[0\]: foliage: the mesh encloses no volume"):
        ScanScene(objects=[SceneObject(plate, "sign", foliage={"leaf_area_density": 1.0})]).build()


def test_leaves_count_against_the_scenes_triangle_cap_before_they_are_drawn(monkeypatch) -> None:
    import zbuf_occlude.sensors.scene.objects as scene_module

    crown = {"leaf_area_density": 0.5}  # about 1,470 leaves, 2,940 triangles, in a 4 m ball
    first = ScanScene(objects=[SceneObject(BALL, "tree", (0, 0), size_m=4.0, foliage=crown)]).build()
    monkeypatch.setattr(scene_module, "MAX_MESH_FACES", len(first.mesh.faces) + 1_000)
    objects = [SceneObject(BALL, "tree", (x, 0), size_m=4.0, foliage=crown) for x in (0.0, 10.0)]
    drawn = []
    monkeypatch.setattr(
        scene_module.Foliage, "grow", lambda self, mesh, **kw: drawn.append(kw["max_leaves"]) or add_foliage(mesh, **vars(self), **kw)
    )
    with pytest.raises(
        InvalidInputError,
        match=r"objects\[1\]: foliage: leaf_area_density and leaf_side_m ask for more than 3\d\d leaves in this crown here",
    ):
        ScanScene(objects=objects).build()
    assert (
        drawn[0] == (len(first.mesh.faces) + 1_000 - len(BALL.faces)) // 2 and drawn[1] < 500
    )  # the room the cap leaves, in leaves (the ground not counted)


def test_add_foliage_refuses_more_leaves_than_it_is_given_room_for() -> None:
    ball = trimesh.creation.icosphere(subdivisions=2, radius=2.0)
    with pytest.raises(InvalidInputError, match=r"more than 10 leaves in this crown here"):
        add_foliage(ball, leaf_area_density=1.0, max_leaves=10)
    with pytest.raises(InvalidInputError, match="max_leaves"):
        add_foliage(ball, leaf_area_density=1.0, max_leaves=MAX_LEAVES + 1)
    assert len(add_foliage(ball, leaf_area_density=0.001, max_leaves=10).faces) <= len(ball.faces) + 20
