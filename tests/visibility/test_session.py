"""VisibilitySession: the one route to many poses of one point set, equal to visible_mask view by view."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import zbuf_occlude as zo
from zbuf_occlude.visibility.registry import method_info


@pytest.fixture(scope="module")
def scene():
    # a box in front of a larger box: the back box is partly hidden from +x
    front = trimesh.creation.box(extents=(0.2, 0.5, 0.5))
    back = trimesh.creation.box(extents=(0.2, 1.0, 1.0))
    back.apply_translation((-0.5, 0.0, 0.0))
    mesh = trimesh.util.concatenate([front, back])
    points, face_index = zo.sample_surface(mesh, count=2000, seed=3)
    cameras = [zo.camera_on_sphere(elevation_deg=e, azimuth_deg=a) for e, a in ((0, 0), (30, 45), (-20, 200))]
    return mesh, points, face_index, cameras


@pytest.mark.parametrize("method", ["auto", "oracle", "embree-fast", "paper-exact", "zbuffer"])
def test_session_equals_visible_mask(scene, method: str) -> None:
    mesh, points, face_index, cameras = scene
    with zo.VisibilitySession(mesh, points, face_index, method=method) as session:
        masks = [session.visible(c) for c in cameras]
    for camera, mask in zip(cameras, masks):
        expected = zo.visible_mask(mesh, points, camera, method, face_index=face_index)
        np.testing.assert_array_equal(mask, expected)
    assert 0 < sum(int(m.sum()) for m in masks) < len(points) * len(cameras)  # something hidden, something seen


def test_session_of_a_method_without_one_calls_it_per_view(scene) -> None:
    mesh, points, face_index, cameras = scene
    assert method_info("paper-exact").session is None
    session = zo.VisibilitySession(mesh, points, face_index, method="paper-exact")
    assert session._session is None
    np.testing.assert_array_equal(
        session.visible(cameras[0]), zo.visible_mask(mesh, points, cameras[0], "paper-exact", face_index=face_index)
    )


def test_session_options_apply_to_every_view(scene) -> None:
    mesh, points, face_index, cameras = scene
    with zo.VisibilitySession(mesh, points, face_index, method="zbuffer-tolerance", resolution=64) as coarse:
        low = coarse.visible(cameras[1])
    expected = zo.visible_mask(mesh, points, cameras[1], "zbuffer-tolerance", face_index=face_index, resolution=64)
    np.testing.assert_array_equal(low, expected)


def test_unknown_keyword_is_named(scene) -> None:
    mesh, points, face_index, _ = scene
    with pytest.raises(TypeError, match="tolerence"):
        zo.VisibilitySession(mesh, points, face_index, tolerence=0.5)
    with pytest.raises(zo.InvalidInputError, match="no-such-method"):
        zo.VisibilitySession(mesh, points, face_index, method="no-such-method")
