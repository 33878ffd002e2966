"""Per-object LiDAR crops (the farm's --sensor step): placements, frames, determinism."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import zbuf_occlude as zo
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.crops import lidar_object_samples, object_crop
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.placement import CropDistributions, draw_placement

MESH = Path(__file__).resolve().parents[2] / "data" / "samples" / "bed" / "train" / "bed_0001.off"


def test_samples_are_crops_in_the_mesh_frame():
    mesh = zo.load_mesh(MESH)
    dist = CropDistributions(distance_m=(6.0, 12.0), height_m=(1.7, 1.9), size_m=4.5)
    clouds = lidar_object_samples(
        mesh, with_beam(zo.Lidar.preset("hdl32e"), range_noise_m=0.0), name="bed", n_samples=4, n_points=512, seed=3, distributions=dist
    )
    assert len(clouds) == 4
    lo, hi = mesh.bounds
    for c in clouds:
        assert c.points.shape == (512, 3) and c.points.dtype == np.float32
        # noise-free returns lie on the mesh: inside its bounds and on their face's plane
        assert np.all(c.points >= lo - 1e-5) and np.all(c.points <= hi + 1e-5)
        tri = mesh.triangles[c.face_index]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        assert np.abs(np.einsum("ij,ij->i", c.points - tri[:, 0], n)).max() < 1e-5
        # the pose is the sensor seen from the box centre, in mesh units (metres / 4.5)
        d, h = c.extra["distance_m"], c.extra["height_m"]
        assert 6.0 <= d <= 12.0 and 1.7 <= h <= 1.9
        centre_height_m = (hi[2] - lo[2]) / 2 * 4.5
        assert c.radius == pytest.approx(math.hypot(d, h - centre_height_m) / 4.5, rel=1e-6)
        assert c.n_visible == c.extra["n_returns"] > 0


def test_distribution_errors():
    with pytest.raises(InvalidInputError):
        CropDistributions(distance_m=(10.0, 5.0))
    with pytest.raises(InvalidInputError):
        CropDistributions(size_m=0.0)
    p = draw_placement(CropDistributions(extents_m=(1.8, 4.5, 1.5)), np.random.default_rng(0))
    assert p.size_m == 4.5 and p.extents_m == (1.8, 4.5, 1.5)


def test_pose_is_measured_from_the_box_centre_of_an_uncentred_mesh():
    import trimesh

    box = trimesh.creation.box(extents=(1.0, 0.4, 0.3))
    box.apply_translation((5.0, -2.0, 3.0))  # far from the origin of its own frame
    (c,) = lidar_object_samples(box, with_beam(zo.Lidar.preset("vlp16"), range_noise_m=0.0), name="box", n_samples=1, n_points=64,
                                distributions=CropDistributions(distance_m=8.0, height_m=1.8, size_m=4.5, yaw_deg=0.0, azimuth_deg=0.0))  # fmt: skip
    scale = 4.5
    expected = np.array([-8.0, 0.0, 1.8 - 0.3 * scale / 2]) / scale  # sensor minus box centre, mesh units
    assert c.radius == pytest.approx(np.linalg.norm(expected), rel=1e-9)
    assert c.azimuth_deg == pytest.approx(180.0) and c.elevation_deg == pytest.approx(math.degrees(math.atan2(expected[2], 8.0 / scale)))
    assert np.all(np.abs(c.points - box.bounds.mean(axis=0)) <= np.array([0.5, 0.2, 0.15]) + 1e-5)


def _box_6m_away():
    """A 2 x 1 x 1 m box 6 m from a noise-free HDL-32E 1.8 m high: (box, lidar, placement, its bare crop)."""
    import trimesh

    box = trimesh.creation.box(extents=(2.0, 1.0, 1.0))
    dist = CropDistributions(distance_m=6.0, height_m=1.8, size_m=2.0, yaw_deg=30.0, azimuth_deg=10.0)
    lidar = with_beam(zo.Lidar.preset("hdl32e"), range_noise_m=0.0)
    placement = draw_placement(dist, np.random.default_rng(0))
    return box, lidar, placement, object_crop(box, lidar, placement, seed=1)


def test_ground_margin_keeps_the_ground_under_the_object_and_nothing_else():
    box, lidar, placement, bare = _box_6m_away()
    assert np.all(bare.scan.object_id == 1)
    counts = []
    for margin in (0.0, 0.5, 1.5):
        crop = object_crop(box, lidar, replace(placement, ground_margin_m=margin), seed=1)
        ground = crop.scan.object_id == 0
        # the object's own returns are untouched; the ground ones lie in the yawed box grown by the margin
        np.testing.assert_array_equal(crop.scan.points[~ground], bare.scan.points)
        np.testing.assert_array_equal(crop.local_points[~ground], bare.local_points)
        local = crop.local_points[ground]  # mesh frame: 1 unit = 1 m here (size 2 m, extent 2)
        assert np.all(np.abs(local[:, 0]) <= 1.0 + margin + 1e-6) and np.all(np.abs(local[:, 1]) <= 0.5 + margin + 1e-6)
        np.testing.assert_allclose(local[:, 2], -0.5, atol=1e-6)  # on the ground, the box's bottom face
        counts.append(int(ground.sum()))
    assert counts[0] <= 2 < counts[1] < counts[2]  # the box hides the ground inside its own outline
    # every ground return of the sweep inside that outline is kept, and no other
    full = crop.full
    world = full.points.astype(np.float64) + [0.0, 0.0, placement.height_m]  # sensor frame, yaw 0
    yaw, centre = math.radians(30.0), 6.0 * np.array([math.cos(math.radians(10.0)), math.sin(math.radians(10.0))])
    rel = world[:, :2] - centre
    along = rel @ [math.cos(yaw), math.sin(yaw)]
    across = rel @ [-math.sin(yaw), math.cos(yaw)]
    inside = (full.object_id == 0) & (np.abs(along) <= 2.5) & (np.abs(across) <= 2.0)
    assert abs(int(inside.sum()) - counts[2]) <= 2  # 1e-6 m rounding at the outline's edge


def test_ground_returns_have_no_face_of_the_mesh():
    import trimesh

    box = trimesh.creation.box(extents=(2.0, 1.0, 1.0))
    dist = CropDistributions(distance_m=6.0, height_m=1.8, size_m=2.0, ground_margin_m=1.0)
    (c,) = lidar_object_samples(
        box, with_beam(zo.Lidar.preset("hdl32e"), range_noise_m=0.0), name="box", n_samples=1, n_points=4096, distributions=dist
    )
    on_ground = np.abs(c.points[:, 2] + 0.5) < 1e-5
    assert on_ground.any() and np.all(c.face_index[on_ground & (c.face_index >= 0)] < len(box.faces))
    assert np.all(c.face_index[c.face_index < 0] == -1) and np.any(c.face_index == -1)
    with pytest.raises(InvalidInputError, match="ground_margin_m"):
        CropDistributions(ground_margin_m=-1.0)
    with pytest.raises(InvalidInputError, match="ground_margin_m"):
        CropDistributions(ground_margin_m="wide")


def test_hidden_below_drops_exactly_the_object_returns_under_the_cut():
    box, lidar, placement, bare = _box_6m_away()
    bare_z = bare.scan.points[:, 2].astype(np.float64) + placement.height_m  # sensor frame -> above the ground
    counts = []
    for cut in (0.0, 0.3, 0.7, 1.5):
        crop = object_crop(box, lidar, replace(placement, hidden_below_m=cut), seed=1)
        kept = bare_z >= cut
        np.testing.assert_array_equal(crop.scan.points, bare.scan.points[kept])
        np.testing.assert_array_equal(crop.local_points, bare.local_points[kept])
        np.testing.assert_array_equal(crop.full.points, bare.full.points)  # the sweep itself is untouched
        counts.append(len(crop.scan))
    assert counts[0] == len(bare.scan) > counts[1] > counts[2] > counts[3] == 0
    # with a ground margin the ground returns stay: only the object's own are cut
    both = object_crop(box, lidar, replace(placement, hidden_below_m=0.7, ground_margin_m=0.5), seed=1)
    ground = both.scan.object_id == 0
    assert ground.any() and len(both.scan) - int(ground.sum()) == counts[2]


def test_hidden_below_is_drawn_after_the_placement_and_checked():
    rng = lambda: np.random.default_rng(7)  # noqa: E731
    plain = draw_placement(CropDistributions(), rng())
    drawn = draw_placement(CropDistributions(hidden_below_m=(0.2, 0.6)), rng())
    assert {k: v for k, v in drawn.to_dict().items() if k in plain.to_dict()} == plain.to_dict() and 0.2 <= drawn.hidden_below_m <= 0.6
    assert draw_placement(CropDistributions(hidden_below_m=0.4), rng()).hidden_below_m == 0.4
    for bad in (-0.1, (0.5, 0.2), "low"):
        with pytest.raises(InvalidInputError, match="hidden_below_m"):
            CropDistributions(hidden_below_m=bad)
