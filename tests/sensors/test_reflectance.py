"""The reflectance table (:mod:`zbuf_occlude.sensors.scene.materials`) and ``scan(reflectivity="table")``."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import zbuf_occlude.sensors as S
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.scene.materials import (
    DEFAULT_MATERIAL,
    FOLIAGE_GAP_FRACTION,
    MATERIALS,
    WAVELENGTHS_NM,
    material_named,
    material_of,
    reflectance,
    scene_optics,
)
from zbuf_occlude.sensors.scan import build_scene


def test_every_entry_is_a_reflectance_in_0_1_with_a_source():
    for name, m in MATERIALS.items():
        assert len(m.reflectance) == len(WAVELENGTHS_NM), name
        assert all(0.0 < v <= 1.0 for v in m.reflectance), name
        assert 0.0 <= m.transmittance <= 1.0 and m.source, name
    # what the sources say about the shape of the spectra: water absorbs at 1550 nm, not at 905
    for wet in ("foliage", "needles", "grass", "skin"):
        assert reflectance(wet, 1550) < reflectance(wet, 905)
    assert reflectance("foliage", 905) > reflectance("needles", 905) > reflectance("asphalt", 905)


@pytest.mark.parametrize(
    ("name", "material"),
    [("Leaf_Green", "foliage"), ("leaves", "foliage"), ("foliageMat", "foliage"), ("tree", "foliage"), ("Tree_pine", "foliage"),
     ("pine_tree", "needles"), ("Bark", "bark"), ("tree_trunk", "foliage"), ("trunk", "bark"), ("WindowGlass", "glass"),
     ("metallic_grey", "metal"), ("street_lamp", "metal"), ("car", "car_paint"), ("pedestrian", "clothing"),
     ("skin_tone", "skin"), ("car_paint", "car_paint"), ("ground", "asphalt"), ("sidewalk", "concrete"),
     ("manhole", None), ("", None), ("Material.001", None)],
)  # fmt: skip
def test_names_are_looked_up_by_their_words(name, material):
    assert material_named(name) == material


def test_a_mesh_material_name_comes_before_the_class_and_the_file_name():
    mesh = trimesh.creation.box()
    mesh.metadata["name"] = "oak_tree.obj"
    assert material_of(mesh, "") == "foliage"
    assert material_of(mesh, "pole") == "metal"
    mesh.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.SimpleMaterial(name="glass_window"))
    assert material_of(mesh, "pole") == "glass"
    assert material_of(None, "") == DEFAULT_MATERIAL


def test_the_nearest_column_and_wavelengths_far_from_every_column():
    assert reflectance("foliage", 865) == MATERIALS["foliage"].reflectance[0]  # an Ouster: the 905 nm column
    assert reflectance("foliage", 1064) == MATERIALS["foliage"].reflectance[1]
    assert reflectance("foliage", 1535) == MATERIALS["foliage"].reflectance[2]
    for bad in (532, 1300, float("nan"), "red"):
        with pytest.raises(InvalidInputError, match="wavelength_nm"):
            reflectance("foliage", bad)
    with pytest.raises(InvalidInputError, match="unknown material 'unobtainium'"):
        reflectance("unobtainium")


def _street() -> S.ScanScene:
    scene = S.ScanScene()
    scene.add({"box_m": [4.5, 1.8, 1.5]}, class_name="car", position_m=(10.0, 0.0))
    scene.add({"cylinder": {"radius_m": 0.8, "height_m": 2.0}}, class_name="bush", position_m=(7.0, -3.0))
    scene.add({"cylinder": {"radius_m": 0.1, "height_m": 4.0}}, class_name="", position_m=(6.0, 3.0))
    return scene


def test_scene_optics_gives_each_object_id_its_material():
    optics = scene_optics(build_scene(_street()), 1550)
    assert optics.material == ("asphalt", "car_paint", "foliage", DEFAULT_MATERIAL)
    assert optics.wavelength_nm == 1550.0
    np.testing.assert_array_equal(optics.reflectivity, [MATERIALS[m].reflectance[2] for m in optics.material])
    np.testing.assert_array_equal(optics.transmittance, [0.0, 0.0, FOLIAGE_GAP_FRACTION, 0.0])
    over = scene_optics(build_scene(_street()), materials={3: "metal", 0: "grass"})
    assert over.material == ("grass", "car_paint", "foliage", "metal")
    with pytest.raises(InvalidInputError, match="object id 4"):
        scene_optics(build_scene(_street()), materials={4: "metal"})
    with pytest.raises(InvalidInputError, match="unknown material 'jelly'"):
        scene_optics(build_scene(_street()), materials={1: "jelly"})


def test_scan_takes_the_table_as_it_takes_the_values():
    scene = _street()
    lidar = with_beam(S.Lidar.preset("vlp16"), footprint_rays=7, divergence_deg=0.3, max_returns=3, range_resolution_m=0.5)
    optics = scene_optics(build_scene(scene))
    by_table = S.scan(scene, lidar, seed=1, reflectivity="table", transmittance="table")
    by_value = S.scan(scene, lidar, seed=1, reflectivity=optics.reflectivity, transmittance=optics.transmittance)
    for key, value in by_value.arrays().items():
        np.testing.assert_array_equal(by_table.arrays()[key], value, err_msg=key)
    assert np.any(by_table.number_of_returns[by_table.object_id == 2] > 1)  # the bush lets part of its pulses through
    with pytest.raises(InvalidInputError, match="reflectivity must be a number, one per object id, or 'table', got 'tables'"):
        S.scan(scene, lidar, reflectivity="tables")
