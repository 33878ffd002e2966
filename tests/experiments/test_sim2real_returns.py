"""``experiment sim2real --returns N``: the lidar set's scanner with several returns per pulse."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

pytest.importorskip("torch")

from zbuf_occlude.cli.main import main
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig
from zbuf_occlude.sensors.request import RETURNS_RANGE_RESOLUTION_M, kept_returns
from zbuf_occlude.experiments.sim2real.data import SetRecipe, build_set
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes
from zbuf_occlude.sensors import lidar_preset
from zbuf_occlude.sensors.beam.footprint import FOOTPRINT_RAYS


def _bush(seed: int = 0, leaves: int = 600) -> trimesh.Trimesh:
    """A bush-like mesh: a trunk under a crown of small scattered leaves (triangles a few cm wide
    spread through a ball), so that one footprint can meet leaves far apart along the beam."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(leaves, 3))
    centres = centres / np.linalg.norm(centres, axis=1, keepdims=True) * rng.uniform(0.0, 1.0, (leaves, 1)) ** (1 / 3)
    centres = centres * [1.0, 1.0, 0.8] + [0.0, 0.0, 1.6]
    corners = centres[:, None, :] + rng.normal(scale=0.06, size=(leaves, 3, 3))
    crown = trimesh.Trimesh(corners.reshape(-1, 3), np.arange(3 * leaves).reshape(-1, 3), process=False)
    trunk = trimesh.creation.cylinder(
        radius=0.06, height=1.2, sections=10, transform=trimesh.transformations.translation_matrix([0, 0, 0.6])
    )
    return trimesh.util.concatenate([trunk, crown])


def _mesh_root(tmp_path: Path) -> Path:
    root = tmp_path / "meshes"
    for cls in ("bush", "pole"):
        (root / cls).mkdir(parents=True)
    _bush(0).export(root / "bush" / "shrub.obj")
    _bush(1, leaves=300).export(root / "bush" / "sparse.obj")
    trimesh.creation.cylinder(radius=0.08, height=4.0, sections=12).export(root / "pole" / "post.obj")
    trimesh.creation.cylinder(radius=0.12, height=6.0, sections=12).export(root / "pole" / "mast.obj")
    return root


def test_one_return_per_pulse_is_the_sensor_as_given_and_todays_lidar_set(tmp_path: Path) -> None:
    hdl = lidar_preset("hdl32e")
    assert kept_returns(hdl, 1) is hdl and Sim2RealConfig("m", "r", returns=1).sensor == hdl == Sim2RealConfig("m", "r").sensor
    meshes = find_class_meshes(_mesh_root(tmp_path))
    today = build_set("lidar", meshes, ["bush", "pole"], 3, 32, 7, SetRecipe(sensor=hdl))
    one = build_set("lidar", meshes, ["bush", "pole"], 3, 32, 7, SetRecipe(sensor=Sim2RealConfig("m", "r", returns=1).sensor))
    assert one.points.tobytes() == today.points.tobytes() and one.labels.tolist() == today.labels.tolist()
    # pinned: the clouds of this set as made before --returns existed (one centre ray per pulse)
    assert hashlib.sha256(one.points.tobytes()).hexdigest()[:16] == PINNED_ONE_RETURN
    several = build_set("lidar", meshes, ["bush", "pole"], 3, 32, 7, SetRecipe(sensor=Sim2RealConfig("m", "r", returns=3).sensor))
    assert several.points.shape == one.points.shape and several.points.tobytes() != one.points.tobytes()


PINNED_ONE_RETURN = "8f0df6f70b7bf0d5"


@pytest.mark.parametrize("mode", ["strongest", "last"])
def test_one_return_keeps_a_velodyne_single_return_mode_and_rewrites_a_beam_of_several(mode: str) -> None:
    from zbuf_occlude.sensors.patterns.airborne_presets import airborne_preset
    from zbuf_occlude.sensors.kinds import with_beam

    velodyne = with_beam(lidar_preset("hdl32e"), footprint_rays=7, return_mode=mode, max_returns=1, range_resolution_m=0.75)
    assert kept_returns(velodyne, 1) is velodyne  # the device's mode, its range resolution and threshold as given
    q = airborne_preset("riegl-q1560")
    one = kept_returns(q, 1).beam
    assert (one.max_returns, one.return_mode, one.range_resolution_m, one.footprint_rays) == (1, "all", 0.0, q.beam.footprint_rays)


def test_several_returns_give_a_bush_points_after_the_first_return() -> None:
    from zbuf_occlude.sensors.crops import object_crop
    from zbuf_occlude.sensors.placement import CropDistributions, draw_placement

    sensor = kept_returns(lidar_preset("hdl32e"), 3)
    beam = sensor.beam
    assert (beam.max_returns, beam.footprint_rays, beam.range_resolution_m) == (3, FOOTPRINT_RAYS, RETURNS_RANGE_RESOLUTION_M)
    assert beam.divergence_deg == lidar_preset("hdl32e").beam.divergence_deg == 0.16  # the preset's (HDL-32E data sheet)
    bush, rng = _bush(1), np.random.default_rng(3)
    dist = CropDistributions(distance_m=(5.0, 8.0), size_m=(2.0, 2.5))
    later = []
    for k in range(4):
        placement = draw_placement(dist, rng)
        crop = object_crop(bush, sensor, placement, seed=k)
        s = crop.scan
        assert len(s) > 0 and (s.return_number >= 1).all() and (s.return_number <= s.number_of_returns).all()
        later.append(int((s.return_number > 1).sum()))
        one = object_crop(bush, lidar_preset("hdl32e"), placement, seed=k).scan
        assert (one.return_number == 1).all()  # today's: one return per pulse
    assert sum(n > 0 for n in later) >= 2, later  # leaves behind leaves: later returns on the same bush


@pytest.mark.parametrize("value", ["0", "16", "x", "2.5"])
def test_bad_returns_exit_2_naming_the_value(tmp_path: Path, value: str, capsys: pytest.CaptureFixture) -> None:
    status = main(["experiment", "sim2real", str(tmp_path), "--real", str(tmp_path), "--out", str(tmp_path / "o"), "--returns", value])
    assert status == 2 and "--returns" in (err := capsys.readouterr().err) and value in err
    assert not (tmp_path / "o").exists()


def test_several_returns_need_a_divergence(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert lidar_preset("hdl64e").beam.divergence_deg == 0  # its data sheet gives none
    argv = ["experiment", "sim2real", str(tmp_path), "--real", str(tmp_path), "--out", str(tmp_path / "o"), "--returns", "2"]
    assert main([*argv, "--sensor", "hdl64e"]) == 2
    assert "--returns 2" in (err := capsys.readouterr().err) and "hdl64e" in err and "divergence_deg 0" in err
    for bad in (0, 16, True, 2.0):
        with pytest.raises(InvalidInputError, match="returns"):
            Sim2RealConfig("m", "r", returns=bad)


def _sets_found(names=("car", "pole")):
    """What prepare_sets finds, as little as _fix_settings and _build_seed_sets read (test_sim2real's)."""
    from zbuf_occlude.experiments.sim2real.run import Sim2RealSets

    return Sim2RealSets(list(names), [], [], np.zeros((4, 8, 3), np.float32), np.repeat([0, 1], 2), [f"{i}.xyz" for i in range(4)],
                        np.array([0, 2]), np.array([1, 3]))  # fmt: skip


def test_settings_record_the_returns_only_when_above_one(tmp_path: Path) -> None:
    from zbuf_occlude.experiments.sim2real.run import _fix_settings
    from zbuf_occlude.sensors.kinds import sensor_to_json

    _fix_settings(Sim2RealConfig("m", "r", returns=2), _sets_found(), tmp_path / "two")
    two = json.loads((tmp_path / "two" / "settings.json").read_text())
    assert two["lidar_returns"] == {"max_returns": 2, "footprint_rays": 7, "divergence_deg": 0.16, "range_resolution_m": 0.75,
                                    "profile": "tophat"}  # fmt: skip
    assert two["sensor_spec"]["beam"]["max_returns"] == 2 and two["sensor_spec"]["beam"]["footprint_rays"] == 7
    _fix_settings(Sim2RealConfig("m", "r", returns=1), _sets_found(), tmp_path / "one")
    one = json.loads((tmp_path / "one" / "settings.json").read_text())
    assert "lidar_returns" not in one and one["sensor_spec"] == sensor_to_json(
        lidar_preset("hdl32e")
    )  # the settings of runs before --returns
    with pytest.raises(InvalidInputError, match="other settings"):  # a one-return run is not resumed with returns
        _fix_settings(Sim2RealConfig("m", "r", returns=2), _sets_found(), tmp_path / "one")


def test_the_adaptive_footprint_needs_several_returns_and_is_recorded_only_where_it_is_cast(tmp_path: Path, capsys) -> None:
    from zbuf_occlude.experiments.sim2real.run import _fix_settings

    argv = ["experiment", "sim2real", str(tmp_path), "--real", str(tmp_path), "--out", str(tmp_path / "o"), "--footprint-cast", "adaptive"]
    assert main(argv) == 2
    assert "--footprint-cast adaptive" in (err := capsys.readouterr().err) and "--returns 2" in err and not (tmp_path / "o").exists()
    for bad in ("yes", 1, True):
        with pytest.raises(InvalidInputError, match="footprint_cast must be one of auto, exact, adaptive"):
            Sim2RealConfig("m", "r", returns=2, footprint_cast=bad)
    found = _sets_found()
    casts = {"adaptive": {"returns": 2, "footprint_cast": "adaptive"}, "default": {"returns": 2},
             "exact": {"returns": 2, "footprint_cast": "exact"}, "one-ray": {}}  # fmt: skip
    for name, keywords in casts.items():
        _fix_settings(Sim2RealConfig("m", "r", **keywords), found, tmp_path / name)
    settings = {name: json.loads((tmp_path / name / "settings.json").read_text()) for name in casts}
    assert settings["adaptive"]["lidar_footprint"] == settings["default"]["lidar_footprint"] == "adaptive"
    assert "lidar_footprint" not in settings["exact"] and "lidar_footprint" not in settings["one-ray"]  # earlier runs' settings kept


def test_the_lidar_set_casts_the_footprint_the_run_asks_for(tmp_path: Path, monkeypatch) -> None:
    import zbuf_occlude.experiments.sim2real.run as run
    import zbuf_occlude.sensors.crops as crops

    meshes = find_class_meshes(_mesh_root(tmp_path))
    sensor = kept_returns(lidar_preset("hdl32e"), 2)
    sets = {footprint: build_set("lidar", meshes, ["bush", "pole"], 3, 64, 0, SetRecipe(sensor=sensor, min_returns=1, footprint=footprint))
            for footprint in ("exact", "adaptive")}  # fmt: skip
    # the adaptive cast changes some crops of these leafy bushes, and is the crops' own adaptive cast
    assert not np.array_equal(sets["exact"].points, sets["adaptive"].points)
    cast = []
    real = crops.object_crops
    monkeypatch.setattr(crops, "object_crops", lambda *a, **kw: cast.append(kw["footprint"]) or real(*a, **kw))
    again = build_set("lidar", meshes, ["bush", "pole"], 3, 64, 0, SetRecipe(sensor=sensor, min_returns=1, footprint="adaptive"))
    assert np.array_equal(again.points, sets["adaptive"].points) and set(cast) == {"adaptive"}
    # the run's recipe carries the config's choice
    recipes = []
    monkeypatch.setattr(run, "build_sets", lambda *a, **kw: recipes.append(a[5]) or {})
    found = _sets_found(("bush", "pole"))
    for cast in ("exact", "adaptive", "auto"):
        run._build_seed_sets(Sim2RealConfig("m", "r", returns=2, footprint_cast=cast), found, 0, [], [], {})
    run._build_seed_sets(Sim2RealConfig("m", "r"), found, 0, [], [], {})  # one ray: the default cast is exact
    assert [r.footprint for r in recipes] == ["exact", "exact", "adaptive", "adaptive", "adaptive", "adaptive", "exact", "exact"]
