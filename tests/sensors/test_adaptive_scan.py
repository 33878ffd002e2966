"""``scan(footprint=...)``: the adaptive footprint through the one pipeline, the default cast ("auto"), and where each is refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.sensors import Lidar, ScanScene, SceneObject, scan, scan_airborne, with_beam
from zbuf_occlude.sensors.patterns.airborne_presets import airborne_preset
from zbuf_occlude.sensors.patterns.depth_camera import depth_camera_preset

TABLE = Path(__file__).resolve().parents[2] / "data" / "samples" / "table" / "test" / "table_0393.off"


def _scene() -> ScanScene:
    table = SceneObject(load_mesh(TABLE), class_name="table", position_m=(6.0, 0.0), size_m=1.2)
    return ScanScene(objects=[table], ground=True, ground_half_extent_m=20.0)


def _returns(**beam) -> Lidar:
    return with_beam(Lidar.preset("vlp16"), footprint_rays=7, max_returns=3, range_resolution_m=0.5, **beam)


def test_an_adaptive_scan_is_the_exact_one_where_footprints_are_not_one_plane():
    exact = scan(_scene(), _returns(), seed=1, azimuth_range_deg=(-40.0, 40.0), footprint="exact")
    fast = scan(_scene(), _returns(), seed=1, azimuth_range_deg=(-40.0, 40.0), footprint="adaptive")
    share = fast.meta["footprint_uniform_share"]
    assert 0.3 < share < 1.0  # the ground's footprints are skipped, the table's cast
    assert "footprint_uniform_share" not in exact.meta
    # the same returns, to rounding: counts within a few, return numbers and object ids alike
    assert abs(len(fast) - len(exact)) <= 3
    for obj in (0, 1):
        assert abs(np.sum(fast.object_id == obj) - np.sum(exact.object_id == obj)) <= 3
        assert np.median(fast.range_m[fast.object_id == obj]) == pytest.approx(np.median(exact.range_m[exact.object_id == obj]), abs=0.01)


def test_the_adaptive_footprint_of_an_airborne_preset():
    q = airborne_preset("riegl-q1560")
    fast = scan_airborne(_scene(), q, half_size_m=4.0, seed=2, footprint="adaptive")
    exact = scan_airborne(_scene(), q, half_size_m=4.0, seed=2, footprint="exact")
    assert "footprint_uniform_share" not in exact.meta
    assert fast.meta["footprint_uniform_share"] > 0.5 and abs(len(fast) - len(exact)) <= 3


@pytest.mark.parametrize(
    ("call", "words"),
    [
        (lambda: scan(_scene(), _returns(), footprint="fast"), "footprint must be one of auto, exact, adaptive, got 'fast'"),
        (lambda: scan(_scene(), Lidar.preset("vlp16"), footprint="adaptive"), "resolves none"),
        (lambda: scan(_scene(), with_beam(Lidar.preset("vlp16"), footprint_rays=7), footprint="adaptive"), "resolves none"),
        (lambda: scan(_scene(), _returns(), footprint="adaptive", backend="zbuffer"), "casts rays with Embree"),
        (lambda: scan(_scene(), depth_camera_preset("kinect-v1"), np.eye(4), footprint="adaptive"), "has no beam"),
        (
            lambda: scan(_scene(), depth_camera_preset("kinect-v1"), np.eye(4), footprint="fast"),
            "'auto' or 'exact'; 'adaptive' is for a LiDAR",
        ),
    ],
    ids=["unknown", "one-ray", "no-echoes", "zbuffer", "camera", "camera-unknown"],
)
def test_the_adaptive_footprint_is_refused_where_it_does_not_apply(call, words):
    with pytest.raises(InvalidInputError, match=words):
        call()


def test_the_adaptive_footprint_applies_the_partial_echo_threshold_to_the_pulses_it_does_not_cast():
    """A threshold that drops the ground's grazing echoes: the adaptive scan drops the same ones."""
    beam = {"min_echo_reflectance": 0.6}
    exact = scan(_scene(), _returns(**beam), seed=1, azimuth_range_deg=(-40.0, 40.0), footprint="exact")
    fast = scan(_scene(), _returns(**beam), seed=1, azimuth_range_deg=(-40.0, 40.0), footprint="adaptive")
    every = scan(_scene(), _returns(), seed=1, azimuth_range_deg=(-40.0, 40.0), footprint="adaptive")
    assert np.sum(every.object_id == 0) > np.sum(exact.object_id == 0) + 50  # the threshold drops ground echoes
    for obj in (0, 1):
        assert abs(np.sum(fast.object_id == obj) - np.sum(exact.object_id == obj)) <= 3


def test_the_footprint_mode_must_be_text():
    with pytest.raises(InvalidInputError, match="footprint must be one of"):
        scan(_scene(), _returns(), footprint=np.array(["adaptive"]))


def _same_scan(a, b) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(a.arrays().values(), b.arrays().values())) and a.arrays().keys() == b.arrays().keys()


def test_the_default_cast_is_the_adaptive_one_where_it_applies():
    """A beam that resolves a footprint's echoes, with Embree: the default scan is the adaptive scan, bit for bit."""
    sector = (-40.0, 40.0)
    default = scan(_scene(), _returns(), seed=1, azimuth_range_deg=sector)
    assert _same_scan(default, scan(_scene(), _returns(), seed=1, azimuth_range_deg=sector, footprint="adaptive"))
    assert default.meta["footprint_uniform_share"] > 0.3  # sub-rays skipped: what the exact cast never does
    assert "footprint_uniform_share" not in scan(_scene(), _returns(), seed=1, azimuth_range_deg=sector, footprint="exact").meta
    q = airborne_preset("riegl-q1560")
    assert _same_scan(
        scan_airborne(_scene(), q, half_size_m=4.0, seed=2), scan_airborne(_scene(), q, half_size_m=4.0, seed=2, footprint="adaptive")
    )


@pytest.mark.parametrize(
    ("sensor", "backend"),
    [
        (Lidar.preset("vlp16"), "embree"),  # one ray
        (with_beam(Lidar.preset("vlp16"), footprint_rays=7), "embree"),  # a footprint's strongest surface, no echoes resolved
        (_returns(), "zbuffer"),  # echoes resolved, but no rays to cast
    ],
    ids=["one-ray", "no-echoes", "zbuffer"],
)
def test_the_default_cast_is_the_exact_one_where_the_adaptive_one_does_not_apply(sensor, backend):
    default = scan(_scene(), sensor, seed=3, azimuth_range_deg=(-40.0, 40.0), backend=backend)
    exact = scan(_scene(), sensor, seed=3, azimuth_range_deg=(-40.0, 40.0), backend=backend, footprint="exact")
    assert "footprint_uniform_share" not in default.meta and _same_scan(default, exact)


@pytest.mark.parametrize("footprint", ["auto", "exact"])
def test_a_depth_camera_takes_the_casts_that_need_no_beam(footprint):
    camera = depth_camera_preset("kinect-v1")
    pose = np.array([[0, 0, 1, 0], [-1, 0, 0, 0], [0, -1, 0, 1.0], [0, 0, 0, 1]], dtype=float)  # looking along +x, 1 m up
    assert _same_scan(scan(_scene(), camera, pose, footprint=footprint), scan(_scene(), camera, pose))
