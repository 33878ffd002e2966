"""The cameras of an object's poses (zbuf_occlude.pipeline.CameraSphere) are made once per process."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from zbuf_occlude.errors import CameraError
from zbuf_occlude.geometry.cameras import camera_on_sphere
from zbuf_occlude.pipeline import CameraSphere


def _same(a, b) -> bool:
    return all(np.array_equal(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))


@pytest.mark.parametrize(
    ("el", "az", "radius", "resolution"), [(10.0, 20.0, 4.0, 512), (-90.0, 0.0, 2.5, (64, 48)), (33.0, 359.0, 4.0, 1024)]
)
def test_a_pose_gives_camera_on_spheres_camera_made_once(el, az, radius, resolution):
    sphere = CameraSphere(radius, resolution)
    first = sphere.camera(el, az)
    assert _same(first, camera_on_sphere(el, az, radius, resolution=resolution))
    assert CameraSphere(radius, resolution).camera(el, az) is first  # the same pose: the same (immutable) camera
    assert not _same(sphere.camera(el, az + 1.0), first)
    assert np.array_equal(first.extrinsics, camera_on_sphere(el, az, radius, resolution=resolution).extrinsics)


def test_an_unhashable_resolution_still_gives_its_camera():
    cam = CameraSphere(4.0, [64, 48]).camera(5.0, 6.0)  # a list, as a config file may give
    assert (cam.width, cam.height) == (64, 48)


def test_a_bad_pose_raises_every_time():
    sphere = CameraSphere()
    for _ in range(2):  # an error is not cached as a camera
        with pytest.raises(CameraError):
            sphere.camera(float("nan"), 0.0)
