"""A crop's fewest returns of the object (``CropDistributions.min_returns``): short placements are drawn again, those
still short are left out and named, and the placement an airborne crop records is the aircraft's."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import trimesh

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.load import normalize_mesh
from zbuf_occlude.sensors.crops import lidar_object_samples, object_crops, object_returns
from zbuf_occlude.sensors.kinds import sensor_from_name, with_beam
from zbuf_occlude.sensors.placement import MAX_REDRAWS, CropDistributions

#: A 2 m post 4–60 m from a VLP-16 (16 rings 2° apart): far away, few of its rings meet it.
POST = CropDistributions(distance_m=(4.0, 60.0), size_m=(2.0, 2.0))


@pytest.fixture(scope="module")
def post() -> trimesh.Trimesh:
    return normalize_mesh(trimesh.creation.cylinder(radius=0.1, height=1.0))


@pytest.fixture(scope="module")
def vlp16():
    return with_beam(sensor_from_name("vlp16"), range_noise_m=0.0)


def _returns(mesh, sensor, dist, n=12, seed=3):
    return [
        (k, object_returns(crop), crop.placement) for k, crop, _ in object_crops(mesh, sensor, dist, name="post", n_samples=n, seed=seed)
    ]


def test_short_placements_are_drawn_again_and_the_others_kept(post, vlp16) -> None:
    least = 10
    plain = _returns(post, vlp16, POST)
    assert any(n < least for _, n, _ in plain), "the case needs a short crop"  # a precondition: without it nothing is redrawn
    assert any(n >= least for _, n, _ in plain)
    kept = _returns(post, vlp16, CropDistributions(distance_m=(4.0, 60.0), size_m=(2.0, 2.0), min_returns=least))
    assert [k for k, _, _ in kept] == list(range(len(plain)))
    for (_, n, placement), (_, m, again) in zip(plain, kept, strict=True):
        if n >= least:  # the first draw is the stream without the minimum: a crop that had enough is the same crop
            assert (m, again) == (n, placement)
        else:  # drawn again: another placement, with enough returns (this post is seen within 60 m in 9 draws)
            assert again != placement and m >= least


def test_samples_still_short_are_left_out_and_named(post, vlp16, caplog) -> None:
    from zbuf_occlude.farm.sensor_crops import farm_datasets
    from zbuf_occlude.sensors.request import ScanRequest

    never = CropDistributions(distance_m=(40.0, 60.0), size_m=(1.0, 1.0), min_returns=10_000)
    with caplog.at_level(logging.WARNING, logger="zbuf_occlude.farm.sensor_crops"):
        out = farm_datasets(post, ScanRequest(vlp16), name="pole/train/post", label=0, object_index=0, n_samples=2, n_points=16,
                            distributions=never)  # fmt: skip
    assert len(out["data"]) == 0
    (message,) = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert message == f"pole/train/post: samples 0, 1 left out: fewer than 10000 returns of the object in {1 + MAX_REDRAWS} placements"


def test_every_farm_sample_holds_the_minimum(post, vlp16) -> None:
    least = 10
    dist = CropDistributions(distance_m=(4.0, 60.0), size_m=(2.0, 2.0), min_returns=least)
    clouds = lidar_object_samples(post, vlp16, name="post", n_samples=12, n_points=32, seed=3, distributions=dist)
    assert len(clouds) == 12 and min(c.n_visible for c in clouds) >= least


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "12", float("nan"), 10**12])
def test_a_bad_minimum_is_refused_naming_it(bad) -> None:
    with pytest.raises(InvalidInputError, match="^min_returns must be an integer from 1 to"):
        CropDistributions(min_returns=bad)


def test_an_airborne_crop_records_where_the_aircraft_was() -> None:
    """The placement drawn for the ground sets only the object's offset across track; the record says where the
    sensor was: ``height_m`` the aircraft's height above the ground (about its altitude), ``distance_m`` the
    horizontal distance from it, and the elevation seen from the object steep."""
    q = sensor_from_name("riegl-q1560").with_(altitude_m=300.0)
    box = normalize_mesh(trimesh.creation.box(extents=(1.0, 1.0, 1.0)))
    clouds = lidar_object_samples(box, q, name="car", n_samples=3, n_points=32, seed=1,
                                  distributions=CropDistributions(size_m=4.5, distance_m=(1.8, 1.8), height_m=(1.8, 1.8)))  # fmt: skip
    assert clouds
    for c in clouds:
        x = c.extra
        assert 250.0 < x["height_m"] < 350.0  # not the drawn 1.8 m of a car roof
        horizontal = x["height_m"] / np.tan(np.radians(c.elevation_deg))
        assert x["distance_m"] == pytest.approx(horizontal, rel=0.05, abs=1.0)
        assert 0.0 <= x["azimuth_deg"] < 360.0


def test_scan_writes_no_sample_short_of_the_minimum_and_names_it(tmp_path, caplog) -> None:
    """``scan --min-returns``: a sample whose object stays short after its redraws is not written, and is named."""
    from zbuf_occlude.cli.main import main

    out = tmp_path / "o"
    argv = ["scan", "box", "--sensor", "vlp16", "--samples", "2", "--distance", "60:80", "--size", "0.3", "--min-returns", "500",
            "--crop", "--out", str(out), "--no-progress"]  # fmt: skip
    with caplog.at_level(logging.WARNING, logger="zbuf_occlude.sensors.scan_files"):
        assert main(argv) == 0
    said = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert said == [f"box: scan {k} left out: fewer than 500 returns of the object in {1 + MAX_REDRAWS} placements" for k in (0, 1)]
    assert not list(out.glob("*.npz"))
    near = ["scan", "box", "--sensor", "vlp16", "--samples", "2", "--distance", "5:8", "--size", "1", "--min-returns", "20", "--crop",
            "--out", str(tmp_path / "p"), "--no-progress"]  # fmt: skip
    caplog.clear()
    assert main(near) == 0
    assert len(list((tmp_path / "p").glob("*.npz"))) == 2 and not [r for r in caplog.records if r.levelno == logging.WARNING]
