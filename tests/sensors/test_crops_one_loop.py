"""One crop loop: ``scan --crop`` and ``farm --sensor`` draw the same placements and returns for one seed
(both through :func:`zbuf_occlude.sensors.crops.object_crops`)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import trimesh

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.sensors import Lidar
from zbuf_occlude.sensors.crops import object_crop, object_crops
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.placement import CropDistributions, draw_placement

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
MESH = SAMPLES / "chair" / "train" / "chair_0001.off"
#: The placement both commands draw: farm's azimuth and yaw (0:360) given to scan, whose own are 0.
PLACEMENT = ["--distance", "6:14", "--height", "1.6:2.0", "--size", "3:4.5"]
SEED, SCANS = "4", 2


def _sensor_local(meta: dict, mesh: trimesh.Trimesh) -> np.ndarray:
    """The sensor in the sample's mesh frame, from the recorded direction and radius (mesh units)."""
    el, az = np.radians(meta["elevation_deg"]), np.radians(meta["azimuth_deg"])
    return mesh.bounds.mean(axis=0) + meta["radius"] * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def test_scan_crop_and_farm_sensor_give_the_same_placements_and_returns_for_one_seed(tmp_path: Path) -> None:
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    shutil.copy(MESH, meshes / MESH.name)
    common = ["--sensor", "hdl32e", "--seed", SEED, "--no-progress", *PLACEMENT]
    assert cli_main(["farm", str(meshes), "--out", str(tmp_path / "ds"), "--samples-per-view", str(SCANS), "--points", "1024",
                     "--workers", "1", *common]) == 0  # fmt: skip
    assert cli_main(["scan", str(meshes / MESH.name), "--out", str(tmp_path / "scan"), "--samples", str(SCANS), "--crop",
                     "--azimuth", "0:360", "--yaw", "0:360", *common]) == 0  # fmt: skip
    ds, mesh = OccludedDataset(tmp_path / "ds"), load_mesh(MESH)
    assert len(ds) == SCANS
    for i in range(SCANS):
        points, _, meta = ds[i]
        k = meta["pose_index"]
        scanned = np.load(tmp_path / "scan" / f"{MESH.stem}_hdl32e_s{k:03d}.npz")
        # the same sensor height and the same returns: as many, at the same ranges
        assert scanned["sensor_to_world"][2, 3] == meta["sensor_height_m"]
        assert len(scanned["points"]) == meta["n_visible"] < 1024  # every return is in the farm's sample
        metres_per_unit = meta["size_m"] / np.ptp(mesh.bounds, axis=0).max()
        farm_ranges = np.unique(np.linalg.norm(points.astype(np.float64) - _sensor_local(meta, mesh), axis=1) * metres_per_unit)
        np.testing.assert_allclose(farm_ranges, np.sort(scanned["range_m"].astype(np.float64)), atol=1e-4)
        assert 6.0 <= meta["distance_m"] <= 14.0 and 3.0 <= meta["size_m"] <= 4.5


def test_object_crops_draws_crop_k_from_its_own_generator_whatever_the_crops_before_it() -> None:
    box = trimesh.creation.box(extents=(1.0, 0.5, 0.8))
    lidar = with_beam(Lidar.preset("vlp16"), range_noise_m=0.0)
    dist = CropDistributions(distance_m=(4.0, 8.0), size_m=(2.0, 3.0))
    three = list(object_crops(box, lidar, dist, name="box", n_samples=3, seed=2))
    assert [c.index for c in three] == [0, 1, 2]
    again = list(object_crops(box, lidar, dist, name="box", n_samples=2, seed=2))
    for a, b in zip(three, again):
        assert a.crop.placement == b.crop.placement
        np.testing.assert_array_equal(a.crop.scan.points, b.crop.scan.points)
    assert len({c.crop.placement.distance_m for c in three}) == 3  # each its own draw
    other = next(object_crops(box, lidar, dist, name="other", n_samples=1, seed=2))
    assert other.crop.placement != three[0].crop.placement  # the name is the seed's key
    # crop k is object_crop at the placement its generator draws first, the scan's seed next
    from zbuf_occlude.geometry.samples import derive_rng, object_key
    from zbuf_occlude.sensors.crops import CROP_STREAM

    rng = derive_rng(2, object_key("box"), CROP_STREAM, 1)
    placement = draw_placement(dist, rng)
    alone = object_crop(box, lidar, placement, seed=int(rng.integers(2**63)))
    assert placement == three[1].crop.placement
    np.testing.assert_array_equal(alone.scan.points, three[1].crop.scan.points)
    assert three[1].rng.integers(2**63) == rng.integers(2**63)  # the generator handed on is where the loop left it
