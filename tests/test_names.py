"""Renamed public names: the new ones work, the old ones keep working with a DeprecationWarning."""

from __future__ import annotations

import sys
import warnings

import numpy as np
import pytest
import trimesh

import zbuf_occlude as zo
from zbuf_occlude import _version
from zbuf_occlude.experiments import elevation_profile
from zbuf_occlude.farm import worker
from zbuf_occlude.visibility import zbuffer


def test_resident_points_and_the_deprecated_scene_alias() -> None:
    mesh = trimesh.creation.box()
    points, face_index = trimesh.sample.sample_surface(mesh, 300, seed=2)
    camera = zo.camera_on_sphere(25.0, 40.0, 4.0, resolution=128)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the one route warns about nothing
        with zo.VisibilitySession(mesh, points, face_index, method="zbuffer") as session:
            expected = session.visible(camera)
    with pytest.warns(DeprecationWarning, match="VisibilitySession"):
        scene = zo.Scene(mesh, points, face_index)
    with scene:
        assert np.array_equal(scene.visible(camera), expected)
    with pytest.warns(DeprecationWarning, match="VisibilitySession"):
        assert isinstance(scene, zo.ResidentPoints)
    assert zo.method_info("zbuffer").session is zbuffer.ResidentPoints


def test_profile_module_renamed() -> None:
    vars(zo).pop("profile", None)  # an earlier import of the old path set the attribute
    sys.modules.pop("zbuf_occlude.profile", None)
    with pytest.warns(DeprecationWarning, match="elevation_profile"):
        from zbuf_occlude import profile
    assert profile is elevation_profile
    with pytest.raises(AttributeError):
        zo.no_such_name  # noqa: B018


def test_one_version_and_one_renderer_cache() -> None:
    assert zo.__version__ == _version.__version__ == worker.package_version()
    assert zbuffer.renderer_for is zo.render.renderer_for
