"""Materials named by a mesh file (an OBJ's ``usemtl``, a glTF primitive's material) are kept per face and looked up
first by the reflectance table: a pane named ``glass`` and a crown named ``foliage`` are scanned as glass and foliage,
not as the default concrete.  The files are written here: a box whose top and bottom are glass (OBJ + MTL) and a tree
of a foliage crown on a bark trunk (GLB)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
from trimesh.visual.material import PBRMaterial

from zbuf_occlude.mesh.flatten import flatten_scene
from zbuf_occlude.mesh.scene import FACE_MATERIALS, face_materials, face_materials_of
from zbuf_occlude.sensors.beam.echo_energy import surface_optics
from zbuf_occlude.sensors.scene.materials import MATERIALS, SPINNING_WAVELENGTH_NM, scene_optics
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject

OBJ = """mtllib box.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
usemtl concrete_wall
f 1 2 6
f 1 6 5
f 2 3 7
f 2 7 6
usemtl glass
f 1 3 2
f 1 4 3
f 5 6 7
f 5 7 8
usemtl concrete_wall
f 3 4 8
f 3 8 7
f 4 1 5
f 4 5 8
"""
MTL = "newmtl glass\nKd 0.8 0.8 0.8\nnewmtl concrete_wall\nKd 0.5 0.5 0.5\n"


@pytest.fixture
def box_obj(tmp_path: Path) -> Path:
    (tmp_path / "box.obj").write_text(OBJ)
    (tmp_path / "box.mtl").write_text(MTL)
    return tmp_path / "box.obj"


@pytest.fixture
def tree_glb(tmp_path: Path) -> Path:
    crown = trimesh.creation.box((2.0, 2.0, 2.0))
    crown.apply_translation([0.0, 0.0, 2.5])  # 1.5 m to 3.5 m, above the trunk's 0 to 1 m
    crown.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(name="foliage"))
    trunk = trimesh.creation.cylinder(0.2, 1.0, sections=8)
    trunk.apply_translation([0.0, 0.0, 0.5])
    trunk.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(name="Bark_brown"))
    path = tmp_path / "tree.glb"
    trimesh.Scene({"crown": crown, "trunk": trunk}).export(path)
    return path


def _loaded(path: Path) -> trimesh.Trimesh:
    """The file flattened as the loader flattens it, with its faces' materials as the loader keeps them."""
    scene = trimesh.load_scene(path, process=False)
    mesh = flatten_scene(scene)
    mesh.metadata[FACE_MATERIALS] = face_materials(scene)
    return mesh


def _names(mesh: trimesh.Trimesh) -> np.ndarray:
    found = face_materials_of(mesh)
    assert found is not None
    return np.array(found.names)[found.index]


def test_each_face_keeps_the_material_its_file_gives_it_in_the_flattened_order(box_obj: Path, tree_glb: Path) -> None:
    box = _loaded(box_obj)
    names = _names(box)
    z = box.triangles[:, :, 2]
    horizontal = np.ptp(z, axis=1) == 0  # the top and bottom: the glass of the file
    assert (names == "glass").sum() == 4 and np.array_equal(names == "glass", horizontal)
    assert set(names[~horizontal]) == {"concrete_wall"}
    tree = _loaded(tree_glb)
    names = _names(tree)
    in_crown = tree.triangles[:, :, 2].min(axis=1) >= 1.5 - 1e-9
    assert np.array_equal(names == "foliage", in_crown) and set(names[~in_crown]) == {"Bark_brown"}


def test_a_changed_mesh_has_no_face_materials(box_obj: Path) -> None:
    box = _loaded(box_obj)
    assert face_materials_of(trimesh.Trimesh(box.vertices, box.faces[:5], process=False)) is None  # made anew
    box.metadata[FACE_MATERIALS] = face_materials_of(box).select(np.arange(5))
    assert face_materials_of(box) is None  # 5 materials for 12 faces: not this mesh's


def _scene(mesh: trimesh.Trimesh, **kwargs) -> ScanScene:
    # class "building": concrete by its class, so only the file's materials can make a face anything else
    return ScanScene(objects=[SceneObject(mesh, class_name="building", position_m=(6.0, 0.0), size_m=2.0, **kwargs)])


def test_the_reflectance_table_looks_up_each_faces_file_material_first(box_obj: Path, tree_glb: Path) -> None:
    for path, named, other in ((box_obj, "glass", "concrete"), (tree_glb, "foliage", "bark")):
        mesh = _loaded(path)
        built = _scene(mesh).build()
        optics = scene_optics(built, SPINNING_WAVELENGTH_NM)
        own = built.face_object == 1
        file_names = _names(mesh)
        rows = list(MATERIALS)
        assert np.array_equal(optics.face_material[own] == rows.index(named), file_names == named)
        assert set(optics.face_material[own][file_names != named]) == {rows.index(other)}
        assert np.all(optics.face_material[~own] == rows.index("asphalt"))  # the ground
        glass = optics.face_reflectivity[own][file_names == named]
        assert np.all(glass == MATERIALS[named].reflectance[0]) and np.all(optics.face_transmittance[own][file_names == named] > 0)
        # what a scan weighs its hits by: per face, from the table
        rho, tau = surface_optics(built, "table", "table", wavelength_nm=SPINNING_WAVELENGTH_NM, multi_return=True)
        assert np.array_equal(rho, optics.face_reflectivity) and np.array_equal(tau, optics.face_transmittance)
        # an object's material given by id overrides its file's
        forced = scene_optics(built, materials={1: "metal"})
        assert np.all(forced.face_material[own] == rows.index("metal"))


def test_a_warped_object_keeps_its_faces_materials(box_obj: Path) -> None:
    mesh = _loaded(box_obj)
    built = _scene(mesh, width_profile=[1.0, 0.5, 0.8]).build()
    own = built.face_object == 1
    assert own.sum() > len(mesh.faces)  # the walls were split to bend
    optics = scene_optics(built)
    # each face of the warped box is glass where the face of the file it was split from is
    was_glass = _names(mesh)[built.face_local[own]] == "glass"
    assert np.array_equal(optics.face_material[own] == list(MATERIALS).index("glass"), was_glass)


def test_per_object_values_still_apply_to_every_face_of_the_object(box_obj: Path) -> None:
    built = _scene(_loaded(box_obj)).build()
    rho, tau = surface_optics(built, [0.2, 0.7], [0.0, 0.5], wavelength_nm=SPINNING_WAVELENGTH_NM, multi_return=True)
    assert np.array_equal(rho, np.where(built.face_object == 1, 0.7, 0.2)) and np.array_equal(
        tau, np.where(built.face_object == 1, 0.5, 0.0)
    )


def test_a_scene_file_naming_an_obj_and_a_glb_scans_their_glass_and_foliage(box_obj: Path, tree_glb: Path) -> None:
    folder = box_obj.parent
    # a degenerate face among the glass ones, which the loader drops: the materials of the faces it keeps stay theirs
    box_obj.write_text(OBJ.replace("usemtl glass\n", "usemtl glass\nf 1 1 2\n"))
    (folder / "scene.json").write_text(json.dumps({"objects": [
        {"mesh": "box.obj", "class": "building", "position_m": [6, 0], "size_m": 2},
        {"mesh": "tree.glb", "class": "building", "position_m": [0, 6], "size_m": 4, "up": "z"},
    ]}))  # fmt: skip
    from zbuf_occlude.sensors.scene.files import load_scene

    built = load_scene(folder / "scene.json").build()
    optics = scene_optics(built)
    rows = list(MATERIALS)
    assert (optics.face_material[built.face_object == 1] == rows.index("glass")).sum() == 4
    assert (optics.face_material[built.face_object == 2] == rows.index("foliage")).sum() == 12
