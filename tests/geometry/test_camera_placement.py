"""A camera where the CLI would not put one warns, once per call, from the Python functions:
inside the object's bounding box, or so far that the object spans less than a pixel
(zbuf_occlude.geometry.placement).  The CLI normalises every object, so it never warns.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.cli.main import main
from zbuf_occlude.geometry.placement import placement_problem

#: A cloud on a box of largest side 1, centred (as the CLI normalises every object).
BOX = trimesh.creation.box(extents=(1.0, 0.6, 0.4))
POINTS = trimesh.sample.sample_surface(BOX, 300, seed=0)[0]
CAMERA = zo.camera_on_sphere(20.0, 30.0)  # the default radius, 4


def _placement_warnings(call) -> list[warnings.WarningMessage]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    return [w for w in caught if issubclass(w.category, zo.CameraPlacementWarning)]


def test_a_cloud_in_millimetres_with_the_default_camera_warns_once_naming_distance_and_extent():
    caught = _placement_warnings(lambda: zo.visible_mask_points(1000.0 * POINTS, CAMERA))
    assert len(caught) == 1
    message = str(caught[0].message)
    assert "inside the object's bounding box" in message
    assert "the camera is 4 object units from the centre" in message and "largest side is 1e+03" in message
    assert caught[0].filename == __file__  # it points at the caller's line


def test_the_default_placement_does_not_warn():
    mesh = zo.normalize_mesh(trimesh.creation.icosphere())  # largest side 1, centred
    points, face_index = zo.sample_surface(mesh, 200, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", zo.CameraPlacementWarning)
        zo.visible_mask_points(POINTS, CAMERA)
        zo.visible_mask(mesh, points, CAMERA, "oracle", face_index=face_index)
        with zo.VisibilitySession(mesh, points, face_index, method="oracle") as session:
            session.visible(CAMERA)


def test_a_camera_inside_a_mesh_warns_once_from_each_entry_point():
    room = trimesh.creation.box(extents=(20.0, 20.0, 20.0))  # the camera at radius 4 is inside
    points, face_index = trimesh.sample.sample_surface(room, 200, seed=0)
    assert len(_placement_warnings(lambda: zo.visible_mask(room, points, CAMERA, "oracle", face_index=face_index))) == 1
    with zo.VisibilitySession(room, points, face_index, method="oracle") as session:
        assert len(_placement_warnings(lambda: session.visible(CAMERA))) == 1


def test_point_splat_through_visible_mask_warns_once_not_twice():
    # visible_mask calls the registered point-splat method, which calls visible_mask_points
    cloud = 1000.0 * POINTS
    mesh = trimesh.Trimesh(1000.0 * BOX.vertices, BOX.faces)
    caught = _placement_warnings(lambda: zo.visible_mask(mesh, cloud, CAMERA, "point-splat"))
    assert len(caught) == 1 and caught[0].filename == __file__


def test_an_object_smaller_than_a_pixel_warns():
    caught = _placement_warnings(lambda: zo.visible_mask_points(1e-4 * POINTS, CAMERA))
    assert len(caught) == 1 and "would span 0.0" in str(caught[0].message) and "pixels" in str(caught[0].message)


@pytest.mark.parametrize("points", [np.zeros((0, 3)), np.ones((1, 3)), np.ones((5, 3))], ids=["none", "one", "coincident"])
def test_an_object_of_no_extent_has_nothing_to_say(points):
    assert placement_problem(CAMERA, points) is None


@settings(max_examples=60, deadline=None)
@given(
    el=st.floats(-90.0, 90.0), az=st.floats(0.0, 360.0), radius=st.floats(0.9, 1e4),
    sides=st.tuples(*[st.floats(0.01, 1.0)] * 3),
)  # fmt: skip
def test_no_camera_the_cli_can_place_warns_for_a_normalised_object(el, az, radius, sides):
    """The CLI's cameras: on a sphere outside the bounding sphere (camera_on_sphere refuses
    radius <= 0.883), the field of view fitted to it, around an object of largest side 1."""
    scale = np.array(sides) / max(sides)
    camera = zo.camera_on_sphere(el, az, radius, resolution=64)
    assert placement_problem(camera, 0.5 * np.array([-scale, scale])) is None


def test_the_cli_never_warns_for_objects_in_their_files_units(tmp_path, capfd):
    """It normalises them first (a mesh with ``oracle``: a method without a session, called
    through ``visible_mask`` per pose, which checks the placement; a cloud with point-splat).
    The work runs in a worker process: its warnings reach file descriptor 2."""
    meshes, clouds = tmp_path / "meshes", tmp_path / "clouds"
    meshes.mkdir()
    clouds.mkdir()
    trimesh.Trimesh(1000.0 * BOX.vertices, BOX.faces).export(meshes / "box_mm.off")
    np.save(clouds / "cloud_mm.npy", 1000.0 * POINTS)
    tiny = ["--views", "0:0,45:90", "--points", "64", "--samples-per-view", "1", "--no-progress"]
    with warnings.catch_warnings():
        warnings.simplefilter("error", zo.CameraPlacementWarning)
        assert main(["generate", str(meshes), "--out", str(tmp_path / "out_mesh"), "--method", "oracle", *tiny]) == 0
        assert main(["generate", str(clouds), "--out", str(tmp_path / "out_cloud"), *tiny]) == 0
    out, err = capfd.readouterr()
    assert "CameraPlacementWarning" not in out + err, err
