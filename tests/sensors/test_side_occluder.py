"""A side occluder: part of an object hidden behind a panel between it and the sensor, and its fit to real widths."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import trimesh
from hypothesis import example, given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.crops import (
    CropDistributions,
    Placement,
    draw_placement,
    object_crop,
)
from zbuf_occlude.sensors.scene.occluders import side_occluders
from zbuf_occlude.sensors.fit import (
    across_sight_width,
    fit_object_shape,
    fit_visible_across_sight,
    fit_width_scale,
)
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.patterns.spinning import lidar_preset
from zbuf_occlude.sensors.kinds import sensor_from_name

CAR = trimesh.creation.box(extents=(1.0, 0.4, 0.33))  # a normalised car-like box: 4.5 m long at size_m 4.5
PLACED = Placement(distance_m=7.0, height_m=1.8, azimuth_deg=30.0, yaw_deg=90.0, size_m=4.5)


def _azimuths_deg(points: np.ndarray) -> np.ndarray:
    return np.degrees(np.arctan2(points[:, 1], points[:, 0]))


@pytest.mark.parametrize("visible", [0.3, 0.5, 0.8])
def test_a_side_occluder_hides_the_asked_share_of_the_object_from_the_asked_side(visible: float) -> None:
    lidar = with_beam(lidar_preset("hdl32e"), range_noise_m=0.0)
    whole = object_crop(CAR, lidar, PLACED, seed=1)
    lo, hi = np.percentile(_azimuths_deg(whole.scan.points), [0, 100])
    for side in (1.0, -1.0):
        part = object_crop(CAR, lidar, replace(PLACED, visible_across_sight=visible, occluder_side=side), seed=1)
        az = _azimuths_deg(part.scan.points)
        shown = (az.max() - az.min()) / (hi - lo)
        assert shown == pytest.approx(visible, abs=0.04)  # within an azimuth step or two of 43°
        # side +1 hides the counter-clockwise end (larger azimuths), -1 the other
        kept_end = az.min() if side > 0 else az.max()
        assert kept_end == pytest.approx(lo if side > 0 else hi, abs=0.3)
        # the object keeps id 1 and its own returns only; the panel's (id 2) are in the full sweep, not in the crop
        assert set(np.unique(part.full.object_id)) == {0, 1, 2} and np.all(part.scan.object_id == 1)
        # what is shown is unchanged where it is not hidden: the same returns of the same rays
        assert len(part.scan) < len(whole.scan)
        seen = {tuple(p) for p in whole.scan.points.round(4).tolist()}
        assert np.mean([tuple(p) in seen for p in part.scan.points.round(4).tolist()]) > 0.97


def test_a_share_of_one_hides_nothing_and_the_draw_is_capped_and_checked() -> None:
    lidar = with_beam(lidar_preset("hdl32e"), range_noise_m=0.0)
    whole = object_crop(CAR, lidar, PLACED, seed=1)
    same = object_crop(CAR, lidar, replace(PLACED, visible_across_sight=1.0, occluder_side=1.0), seed=1)
    assert np.array_equal(same.scan.points, whole.scan.points) and set(np.unique(same.full.object_id)) == {0, 1}
    # drawn last, capped at 1, with the side; the earlier draws are those of the same distributions without it
    rng = lambda: np.random.default_rng(4)  # noqa: E731
    plain = draw_placement(CropDistributions(hidden_below_m=(0.0, 0.5)), rng())
    shares, sides = [], set()
    for seed in range(40):
        drawn = draw_placement(CropDistributions(hidden_below_m=(0.0, 0.5), visible_across_sight=(0.5, 1.5)), np.random.default_rng(seed))
        shares.append(drawn.visible_across_sight)
        sides.add(drawn.occluder_side)
    drawn = draw_placement(CropDistributions(hidden_below_m=(0.0, 0.5), visible_across_sight=(0.5, 1.5)), rng())
    assert {k: v for k, v in drawn.to_dict().items() if k in plain.to_dict()} == plain.to_dict()
    assert min(shares) >= 0.5 and max(shares) == 1.0 and 0.3 < np.mean(np.asarray(shares) == 1.0) < 0.7 and sides == {1.0, -1.0}
    for bad in (0.0, (-0.1, 0.5), (0.6, 0.5), "half"):
        with pytest.raises(InvalidInputError, match="visible_across_sight"):
            CropDistributions(visible_across_sight=bad)
    # an airborne scanner flies over the object: nothing stands between, and the share is refused, not ignored
    with pytest.raises(InvalidInputError, match="airborne"):
        object_crop(CAR, sensor_from_name("riegl-q1560"), replace(PLACED, visible_across_sight=0.5, occluder_side=1.0), seed=1)


@settings(max_examples=40, deadline=None)
@given(
    azimuth=st.floats(-180.0, 180.0),
    distance=st.floats(3.0, 30.0),
    length=st.floats(0.3, 12.0),  # up to 127° wide seen from 3 m: hidden sectors that take several panels
    visible=st.floats(0.05, 0.95),
    side=st.sampled_from([1.0, -1.0]),
)
@example(azimuth=57.0, distance=4.0, length=2.0, visible=0.5, side=-1.0)  # a vertex on the panel's edge
def test_the_panel_stands_between_and_covers_the_hidden_azimuths(azimuth: float, distance: float, length: float, visible: float,
                                                                  side: float) -> None:  # fmt: skip
    """Law: every ray from the sensor to a vertex in the hidden share of the azimuths meets the panel before the vertex."""
    a = math.radians(azimuth)
    centre = np.array([distance * math.cos(a), distance * math.sin(a), 0.0])
    across = np.array([-math.sin(a), math.cos(a), 0.0])
    vertices = np.array([centre + t * across + [0, 0, z] for t in np.linspace(-length / 2, length / 2, 9) for z in (0.0, 2.5)])
    sensor = np.array([0.0, 0.0, 1.8])
    panels = []
    for panel in side_occluders(vertices, sensor, visible, side):
        local, to_world = panel.build()
        panels.append(trimesh.Trimesh(np.asarray(local.vertices) @ to_world[:3, :3].T + to_world[:3, 3], local.faces))
    panel_world = trimesh.util.concatenate(panels)
    phi = np.arctan2(vertices[:, 1], vertices[:, 0]) - a
    phi = (phi + np.pi) % (2 * np.pi) - np.pi
    span = phi.max() - phi.min()
    # a vertex on the panel's edge is a grazing ray either way: the law holds a hair inside the hidden share
    hidden = phi >= phi.max() - (1 - visible) * span + 0.002 * span if side > 0 else phi <= phi.min() + (1 - visible) * span - 0.002 * span
    shown = phi < phi.max() - (1 - visible) * span - 0.02 * span if side > 0 else phi > phi.min() + (1 - visible) * span + 0.02 * span
    rays = vertices - sensor
    lengths = np.linalg.norm(rays, axis=1)
    locations, index, _ = panel_world.ray.intersects_location(np.repeat(sensor[None], len(rays), 0), rays / lengths[:, None])
    first = np.full(len(rays), np.inf)
    np.minimum.at(first, index, np.linalg.norm(locations - sensor, axis=1))
    assert np.all(first[hidden] < lengths[hidden])  # each hidden vertex lies behind the panel
    assert np.all(np.isinf(first[shown]) | (first[shown] > lengths[shown]))  # the rest stays in view


def test_side_occluders_refuse_a_bad_share_and_stand_nowhere_around_the_sensor() -> None:
    box = np.array([[5.0, -1.0, 0.0], [5.0, 1.0, 2.0]])
    for bad in (0.0, 1.0, 1.2):
        with pytest.raises(InvalidInputError, match="visible share"):
            side_occluders(box, [0.0, 0.0, 1.8], bad, 1.0)
    around = np.array([[5.0, 0.0, 0.0], [-5.0, 0.1, 0.0], [0.0, 5.0, 1.0]])  # the sensor inside the object
    assert side_occluders(around, [0.0, 0.0, 1.8], 0.5, 1.0) == []  # nothing stands between a sensor and what surrounds it
    # a long wall close by (120° of azimuth): 95 % of it hidden takes three panels of 60° at most, half of it two
    wall = np.array([[2.0, -3.5, 0.0], [2.0, 3.5, 0.0], [2.0, 0.0, 3.0]])
    assert len(side_occluders(wall, [0.0, 0.0, 1.8], 0.05, -1.0)) == 3 and len(side_occluders(wall, [0.0, 0.0, 1.8], 0.5, 1.0)) == 2


def test_fit_visible_across_sight_makes_wide_crops_as_wide_as_asked_and_leaves_narrow_ones_whole() -> None:
    lidar = with_beam(lidar_preset("hdl32e"), range_noise_m=0.0)
    dist = CropDistributions(distance_m=(5.0, 9.0), height_m=1.8, size_m=4.5)
    lo, hi = fit_visible_across_sight(CAR, lidar, dist, (1.5, 2.5))
    assert hi / lo == pytest.approx(2.5 / 1.5) and 0.3 < lo < hi < 0.8
    rng = np.random.default_rng(5)
    hidden = CropDistributions(distance_m=(5.0, 9.0), height_m=1.8, size_m=4.5, visible_across_sight=((lo + hi) / 2,) * 2)
    widths = [across_sight_width(object_crop(CAR, lidar, draw_placement(hidden, rng), seed=k).scan.points) for k in range(24)]
    assert np.median(widths) == pytest.approx(2.0, rel=0.15)
    # the mesh's own occluder is ignored: the share is fitted to the whole mesh
    assert fit_visible_across_sight(CAR, lidar, hidden, (1.5, 2.5)) == (lo, hi)
    # real scans wider than the crops: nothing hidden in any draw (shares of 1 or more)
    assert min(fit_visible_across_sight(CAR, lidar, dist, (6.0, 9.0))) > 1.0
    post = trimesh.creation.cylinder(radius=0.002, height=1.0, sections=16)  # thinner than the sensor resolves
    assert fit_visible_across_sight(post, lidar, CropDistributions(distance_m=(5.0, 9.0), height_m=1.8, size_m=3.0), (0.1, 0.3)) == (
        1.0,
        1.0,
    )
    for bad in ((0.6, 0.3), (0.0, 0.0), ("a", 1)):
        with pytest.raises(InvalidInputError, match="width_m"):
            fit_visible_across_sight(CAR, lidar, dist, bad)
    with pytest.raises(InvalidInputError, match="spinning LiDAR"):
        fit_visible_across_sight(CAR, sensor_from_name("riegl-q1560"), dist, (1.5, 2.5))


def test_fit_object_shape_meets_the_widths_by_an_occluder_or_a_stretch() -> None:
    lidar = with_beam(lidar_preset("hdl32e"), range_noise_m=0.0)
    dist = CropDistributions(distance_m=(5.0, 9.0), height_m=1.8, size_m=4.5)
    assert fit_object_shape(CAR, lidar, dist, (1.5, 2.5), occlude=True) == {
        "visible_across_sight": fit_visible_across_sight(CAR, lidar, dist, (1.5, 2.5))
    }
    assert fit_object_shape(CAR, lidar, dist, (1.5, 2.5)) == {"width_scale": fit_width_scale(CAR, lidar, dist, (1.5, 2.5))}
    assert fit_object_shape(CAR, lidar, dist, occlude=True) == {}


def test_scan_occlude_option(tmp_path) -> None:
    from zbuf_occlude.cli.main import main
    from zbuf_occlude.sensors.scan_data import read_scan_npz

    base = [
        "scan",
        "box",
        "--size",
        "4.5",
        "--distance",
        "6:8",
        "--height",
        "1.8",
        "--azimuth",
        "0",
        "--yaw",
        "80:100",
        "--samples",
        "6",
        "--seed",
        "2",
        "--crop",
    ]
    box = str(tmp_path / "box.obj")
    CAR.export(box)
    base[1] = box
    assert main([*base, "--across-sight-width", "1.5", "--occlude", "--out", str(tmp_path / "o")]) == 0
    assert main([*base, "--out", str(tmp_path / "w")]) == 0
    assert main([*base, "--across-sight-width", "1.5", "--out", str(tmp_path / "s")]) == 0
    scans = {tag: [read_scan_npz(p) for p in sorted((tmp_path / tag).glob("*.npz"))] for tag in "ows"}
    widths = {tag: np.median([across_sight_width(s.points) for s in v]) for tag, v in scans.items()}
    assert widths["o"] == pytest.approx(1.5, rel=0.2) and widths["s"] == pytest.approx(1.5, rel=0.2) and widths["w"] > 3.0
    # the object straight ahead (+x): an occluded crop shows one end of it, off the line of sight; a stretched one its middle
    aside = {tag: np.median([abs(s.points[:, 1].mean()) for s in v]) for tag, v in scans.items()}
    assert aside["o"] > 0.8 and aside["s"] < 0.3 and aside["w"] < 0.3
    # hidden, not squeezed: as tall as the whole crops, with fewer returns
    assert np.median([np.ptp(s.points[:, 2]) for s in scans["o"]]) == pytest.approx(
        np.median([np.ptp(s.points[:, 2]) for s in scans["w"]]), abs=0.1
    )
    assert main([*base, "--occlude", "--out", str(tmp_path / "x")]) == 2  # needs --across-sight-width


def test_an_occluded_crop_builds_its_object_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """The panels are placed from the built object; the scene built again with them reuses that build."""
    from zbuf_occlude.sensors.scene.objects import SceneObject

    calls = []
    real = SceneObject.build

    def counted(self, base=None, **kwargs):
        calls.append(self.class_name)
        return real(self, base, **kwargs)

    monkeypatch.setattr(SceneObject, "build", counted)
    placement = replace(PLACED, visible_across_sight=0.5, occluder_side=1.0, width_profile=(1.0, 1.2, 0.9, 1.0))
    crop = object_crop(CAR, with_beam(lidar_preset("hdl32e"), range_noise_m=0.0), placement, seed=1, class_name="car")
    assert set(np.unique(crop.full.object_id)) == {0, 1, 2}
    assert calls.count("car") == 1 and calls.count("occluder") == 1
