"""Ray drop on vegetation, ``Beam.foliage_dropout``: returns from crown surfaces (materials ``foliage`` and
``needles``) are lost with that probability, independently and at every range; other surfaces lose none; 0 is
today's scan.  Scenes are built here: a box of class "bush" (foliage by its class) beside one of class "car", and a
tree whose file names its crown "foliage" and its trunk "Bark_brown"."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from trimesh.visual.material import PBRMaterial

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.flatten import flatten_scene
from zbuf_occlude.mesh.scene import FACE_MATERIALS, face_materials
from zbuf_occlude.sensors import Lidar, scan, with_beam
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.kinds import sensor_from_spec, sensor_to_json
from zbuf_occlude.sensors.scene.materials import CROWN_MATERIALS, MATERIALS, on_crown
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject

#: Classes of the two boxes, by object id (1, 2): only the bush is a crown.
CLASSES = ("bush", "car")


def _boxes(distance_m: float = 6.0) -> ScanScene:
    box, s = trimesh.creation.box((1.0, 1.0, 1.0)), max(1.0, distance_m / 6.0)  # as many returns at every range
    return ScanScene(
        objects=[SceneObject(box, class_name=c, position_m=(distance_m, y * s), size_m=1.5 * s) for c, y in zip(CLASSES, (-1.0, 1.0))],
        ground=False,
    )


def _hits(sensor: Lidar, scene: ScanScene, seed: int = 0):
    s = scan(scene, sensor, seed=seed)
    return s, {c: int((s.object_id == i).sum()) for i, c in enumerate(CLASSES, start=1)}


@pytest.fixture(scope="module")
def lidar() -> Lidar:
    return Lidar.preset("hdl32e")


def test_the_field_is_checked_and_travels_in_a_sensor_file(lidar: Lidar) -> None:
    for bad in (-0.1, 1.0, float("nan"), True, "0.1"):
        with pytest.raises(InvalidInputError, match="foliage_dropout"):
            Beam(foliage_dropout=bad)
    assert Beam().foliage_dropout == 0.0 and Beam().is_ideal and not Beam(foliage_dropout=0.1).is_ideal
    sensor = with_beam(lidar, foliage_dropout=0.12)
    again = sensor_from_spec(json.loads(json.dumps(sensor_to_json(sensor))))
    assert again == sensor and again.beam.foliage_dropout == 0.12


def test_crown_faces_are_the_crown_materials_by_class_and_by_the_files_own_names() -> None:
    built = _boxes().build()
    crown = on_crown(built, np.arange(len(built.face_object)))
    assert np.array_equal(crown, built.face_object == 1)  # the bush; not the car
    # a tree whose file names its crown "foliage" and its trunk "Bark_brown": the trunk is not a crown, whatever its class
    top = trimesh.creation.box((2.0, 2.0, 2.0))
    top.apply_translation([0.0, 0.0, 2.5])
    top.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(name="foliage"))
    trunk = trimesh.creation.cylinder(0.2, 1.0, sections=8)
    trunk.apply_translation([0.0, 0.0, 0.5])
    trunk.visual = trimesh.visual.TextureVisuals(material=PBRMaterial(name="Bark_brown"))
    parts = trimesh.Scene({"crown": top, "trunk": trunk})
    mesh = flatten_scene(parts)
    mesh.metadata[FACE_MATERIALS] = face_materials(parts)
    tree = ScanScene(objects=[SceneObject(mesh, class_name="bush", position_m=(6.0, 0.0), size_m=3.5)], ground=False).build()
    faces = np.arange(len(tree.face_object))
    z = tree.mesh.triangles[:, :, 2]
    high = (z.min(axis=1) - z.min()) / np.ptp(z) > 1.25 / 3.5  # above the trunk's top (1 m of 3.5), below the crown's bottom (1.5 m)
    assert np.array_equal(on_crown(tree, faces), high)
    assert set(CROWN_MATERIALS) <= set(MATERIALS) and MATERIALS["grown_leaf"].transmittance == 0.0  # one leaf is no crown


def test_no_crown_no_loss_and_zero_is_todays_scan(lidar: Lidar) -> None:
    scene = _boxes()
    base, counts = _hits(lidar, scene)
    assert min(counts.values()) > 300
    same, _ = _hits(with_beam(lidar, foliage_dropout=0.0), scene)
    assert np.array_equal(base.points, same.points) and np.array_equal(base.intensity, same.intensity)
    dropped, lost = _hits(with_beam(lidar, foliage_dropout=0.4), scene)
    assert lost["car"] == counts["car"]  # the car's returns are all kept, at their very ranges
    car = base.object_id == 2
    assert np.array_equal(dropped.points[dropped.object_id == 2], base.points[car])
    # the bush's are a subset of the scan without it, one draw per return
    kept = {tuple(p) for p in dropped.points[dropped.object_id == 1]}
    assert kept <= {tuple(p) for p in base.points[base.object_id == 1]}


@pytest.mark.parametrize("distance_m", [5.0, 20.0])
@pytest.mark.parametrize("footprint", [False, True])
def test_the_crown_loses_its_share_at_every_range_one_ray_or_footprint(lidar: Lidar, distance_m: float, footprint: bool) -> None:
    p = 0.3
    sensor = lidar
    if footprint:  # the device's mode: 7 sub-rays over the data sheet's divergence, the strongest echo
        sensor = with_beam(lidar, footprint_rays=7, return_mode="strongest", range_resolution_m=0.75)
    scene = _boxes(distance_m)
    _, before = _hits(sensor, scene)
    _, after = _hits(with_beam(sensor, foliage_dropout=p), scene)
    n = before["bush"]
    assert n > 100
    kept = after["bush"] / n
    assert abs(kept - (1 - p)) < 4 * np.sqrt(p * (1 - p) / n)  # binomial, 4 standard errors
    assert after["car"] == before["car"]


@settings(max_examples=15, deadline=None)
@given(low=st.floats(0.0, 0.9), high=st.floats(0.0, 0.9), seed=st.integers(0, 2**31 - 1))
def test_more_ray_drop_keeps_a_subset_of_the_crowns_returns(lidar: Lidar, low: float, high: float, seed: int) -> None:
    low, high = sorted((low, high))
    scene = _boxes()
    a, _ = _hits(with_beam(lidar, foliage_dropout=low), scene, seed)
    b, _ = _hits(with_beam(lidar, foliage_dropout=high), scene, seed)
    kept_a = {tuple(p) for p in a.points}
    assert {tuple(p) for p in b.points} <= kept_a  # the same draws, compared with a larger probability
