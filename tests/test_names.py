"""Public names: one route per name, and the old routes of the flat layout are gone."""

from __future__ import annotations

import importlib
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


def test_the_session_is_the_one_route_to_many_poses() -> None:
    mesh = trimesh.creation.box()
    points, face_index = trimesh.sample.sample_surface(mesh, 300, seed=2)
    camera = zo.camera_on_sphere(25.0, 40.0, 4.0, resolution=128)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the one route warns about nothing
        with zo.VisibilitySession(mesh, points, face_index, method="zbuffer") as session:
            assert np.array_equal(session.visible(camera), zo.visible_mask(mesh, points, camera, "zbuffer", face_index=face_index))
    assert zo.method_info("zbuffer").session is zbuffer.ResidentPoints
    for old in ("Scene", "ResidentPoints", "no_such_name"):
        with pytest.raises(AttributeError):
            getattr(zo, old)
    assert not hasattr(zbuffer, "Scene")


@pytest.mark.parametrize("old", ["cameras", "sampling", "mesh_formats", "profile", "verify", "layout", "visibility.pruning"])
def test_old_module_paths_of_the_flat_layout_are_gone(old: str) -> None:
    # the package was never released with them: one import path per module
    sys.modules.pop(f"zbuf_occlude.{old}", None)
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(f"zbuf_occlude.{old}")
    assert elevation_profile.__name__ == "zbuf_occlude.experiments.elevation_profile"


@pytest.mark.parametrize("name", ["FarmObject", "discover_objects", "add_farm_parser"])
def test_names_that_left_the_farm_are_not_there(name: str) -> None:
    import zbuf_occlude.farm as farm

    with pytest.raises(AttributeError):
        getattr(farm, name)


def test_one_version_and_one_renderer_cache() -> None:
    assert zo.__version__ == _version.__version__ == worker.package_version()
    assert zbuffer.renderer_for is zo.render.renderer_for
