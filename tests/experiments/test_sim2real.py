"""``experiment sim2real``: whole-mesh validation, the training sets, real sizes, and the command end to end."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

pytest.importorskip("torch")

from zbuf_occlude.cli.main import main  # noqa: E402
from zbuf_occlude.errors import InvalidInputError  # noqa: E402
from zbuf_occlude.experiments.sim2real.data import FITTED_PLACED, FITTED_SETS, TRAINING_SETS, SetRecipe, build_set, build_sets, mix_sets
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes, split_whole_meshes
from zbuf_occlude.experiments.sim2real.real import KEEP_SCALE_UNIT_M
from zbuf_occlude.sensors.fit.class_placement import ClassPlacement, CropPlacement, MeshShape  # noqa: E402
from zbuf_occlude.mesh.sizes import CLASS_SIZES_M, SizeRange, parse_sizes, size_interval  # noqa: E402


def _mesh_root(tmp_path: Path) -> Path:
    """Two classes of two procedural meshes each: cars (long low boxes, one as Y-up glTF) and poles."""
    root = tmp_path / "meshes"
    (root / "car").mkdir(parents=True)
    (root / "pole").mkdir(parents=True)
    trimesh.creation.box(extents=(4.5, 1.8, 1.5)).export(root / "car" / "sedan.obj")
    # a Y-up glTF car: length along x, height along y
    # (relabelled as Blender's: trimesh's own glTF files are read as stored, zbuf_occlude.mesh.scene)
    glb = trimesh.creation.box(extents=(3.8, 1.4, 1.7)).export(file_type="glb")
    trimesh_generator = b'"https://github.com/mikedh/trimesh"'
    (root / "car" / "hatch.glb").write_bytes(
        glb.replace(trimesh_generator, b'"Khronos glTF Blender I/O v4.1.63"'.ljust(len(trimesh_generator)))
    )
    trimesh.creation.cylinder(radius=0.08, height=4.0, sections=12).export(root / "pole" / "post.obj")
    lamp = trimesh.util.concatenate([trimesh.creation.cylinder(radius=0.1, height=6.0, sections=12),
                                     trimesh.creation.box(extents=(1.0, 0.2, 0.2), transform=trimesh.transformations.translation_matrix([0.4, 0, 3.0]))])  # fmt: skip
    lamp.export(root / "pole" / "lamp.obj")
    return root


def _real_root(tmp_path: Path) -> Path:
    """A tiny "real" data set: half-visible boxes and poles as .xyz files in class folders (metres, z up)."""
    root = tmp_path / "real"
    rng = np.random.default_rng(0)
    for cls, shape in (
        ("Car", trimesh.creation.box(extents=(4.2, 1.7, 1.5))),
        ("Trunk", trimesh.creation.cylinder(radius=0.15, height=3.0)),
    ):
        (root / cls).mkdir(parents=True)
        for i in range(6):
            pts, _ = trimesh.sample.sample_surface(shape, 300, seed=int(rng.integers(1000)))
            pts = pts[pts[:, 0] <= np.quantile(pts[:, 0], 0.6)]  # the side facing the sensor
            np.savetxt(root / cls / f"{i}.xyz", pts + [20.0 + i, 0.0, 0.0])
    return root


def test_whole_mesh_validation_split(tmp_path: Path) -> None:
    meshes = find_class_meshes(_mesh_root(tmp_path))
    for seed in range(5):
        train, val = split_whole_meshes(meshes, 0.2, seed)
        assert not {m.name for m in train} & {m.name for m in val}  # no mesh on both sides
        assert {m.name for m in train} | {m.name for m in val} == {m.name for m in meshes}
        for cls in ("car", "pole"):
            assert sum(m.class_name == cls for m in val) == 1 and sum(m.class_name == cls for m in train) == 1


def test_gltf_car_arrives_lying_down(tmp_path: Path) -> None:
    car = [m for m in find_class_meshes(_mesh_root(tmp_path)) if m.name == "car/hatch"][0]
    ext = car.mesh.extents
    assert ext[0] == pytest.approx(1.0) and ext[2] < 0.5 and ext[1] > ext[2]  # +y rotated to +z


def test_training_sets_have_equal_class_counts_and_real_sizes(tmp_path: Path) -> None:
    from zbuf_occlude.sensors import lidar_preset

    meshes = find_class_meshes(_mesh_root(tmp_path))
    names = ["car", "pole"]
    for kind in TRAINING_SETS:
        s = build_set(kind, meshes, names, 6, 48, 0, SetRecipe(sensor=lidar_preset("hdl32e"), resolution=128, dense_points=2000))
        assert s.points.shape == (12, 48, 3) and np.bincount(s.labels).tolist() == [6, 6], kind
        np.testing.assert_allclose((s.points.max(axis=1) - s.points.min(axis=1)).max(axis=1), 1.0, atol=1e-5)
    metric = build_set("complete", meshes, names, 6, 200, 1, SetRecipe(keep_scale=True))
    height = (metric.points[:, :, 2].max(axis=1) - metric.points[:, :, 2].min(axis=1)) * KEEP_SCALE_UNIT_M
    poles = height[metric.labels == 1]
    assert (poles > 2.5 * 0.95).all() and (poles < 9.0 * 1.001).all()  # CLASS_SIZES_M's pole heights
    assert height[metric.labels == 0].max() < 2.0  # a car is low


def test_mix_sets_takes_half_of_each() -> None:
    from zbuf_occlude.learn.data import CloudSet

    def cs(value: float) -> CloudSet:
        return CloudSet(np.full((10, 4, 3), value, np.float32), np.repeat([0, 1], 5), np.full(10, np.nan), np.arange(10))

    mixed = mix_sets(cs(1.0), cs(2.0), 0)
    assert len(mixed) == 10 and np.bincount(mixed.labels).tolist() == [5, 5]
    assert (mixed.points[:, 0, 0] == 1.0).sum() == 6  # 3 of 5 per class (rounded up) from the first


def test_size_interval_and_parse_sizes() -> None:
    lo, hi = size_interval([1.0, 0.4, 0.3], CLASS_SIZES_M["car"])  # length is the largest side
    assert (lo, hi) == (3.6, 5.2)
    lo, hi = size_interval([0.2, 0.2, 1.0], CLASS_SIZES_M["car"])  # a "car" standing up: length 0.2
    assert lo == pytest.approx(18.0)
    sizes = parse_sizes("tree=height:4-20,car=max:4-5")
    assert sizes["tree"] == SizeRange("height", 4.0, 20.0) and sizes["car"].dimension == "max"
    for bad in ("tree=4-20", "tree=height:4", "tree=width:1-2", "tree=height:5-1"):
        with pytest.raises(InvalidInputError):
            parse_sizes(bad)


@pytest.mark.slow
def test_sim2real_command_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    meshes, real, out = _mesh_root(tmp_path), _real_root(tmp_path), tmp_path / "out"
    argv = ["experiment", "sim2real", str(meshes), "--real", str(real), "--out", str(out), "--label-map", "Trunk=pole",
            "--points", "32", "--epochs", "2", "--per-class", "8", "--seeds", "2", "--threads", "1", "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    for name in ("settings.json", "runs.jsonl", "results.csv", "summary.csv", "table.md", "run.json", "confusion_complete.csv"):
        assert (out / name).is_file(), name
    with open(out / "results.csv", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert sorted((r["train_set"], r["seed"]) for r in rows) == sorted((s, str(k)) for s in (*TRAINING_SETS, "real→real") for k in range(2))
    for r in rows:  # every row on the held-out half; the mesh-only sets on every scan as well, real→real not (it trained on half)
        assert r["best_epoch_by"] == "loss" and float(r["best_val_loss"]) >= 0.0  # the stable recipe's signal, recorded
        assert int(r["n_test"]) == 6 and int(r["n_test_all_scans"]) == (0 if r["train_set"] == "real→real" else 12)
        assert 0.0 <= float(r["mean_class_accuracy"]) <= 1.0
        assert (r["train_set"] == "real→real") == (r["all_scans_mean_class_accuracy"] == "nan")
    split = _rows(out / "real_split.csv")
    assert sorted((r["class"], r["half"]) for r in split) == sorted([(c, h) for c in ("car", "pole") for h in ("train", "scored")] * 3)
    settings = json.loads((out / "settings.json").read_text())
    assert settings["classes"] == ["car", "pole"] and settings["real_scans"] == {"car": 6, "pole": 6}
    assert "fixed_at" in settings
    # the occluded set's elevations: those the default sensor (hdl32e) sees objects from, and where they came from
    assert settings["occluded_elevation_deg"] == pytest.approx([3.66, 21.80], abs=0.01) and "hdl32e" in settings["occluded_elevation_from"]
    table = (out / "table.md").read_text()
    assert "| complete | 2 |" in table and "| chance | 0 | 0.500" in table and "p vs complete" in table
    assert "mean class acc., all scans" in table and "held-out half of the real scans (6 of 12 scans" in table
    summary = {r["train_set"]: r for r in csv.DictReader(open(out / "summary.csv", encoding="utf-8"))}
    assert (
        summary["complete"]["all_scans_mean_class_accuracy_mean"] != ""
        and summary["real→real"]["all_scans_mean_class_accuracy_mean"] == "nan"
    )
    assert 1 / 6 - 1e-9 <= float(summary["occluded"]["p_vs_complete"]) <= 1.0  # C(4, 2) = 6 splits
    # a rerun resumes (no training) and other settings are refused with exit status 2
    before = (out / "runs.jsonl").read_bytes()
    assert main(argv) == 0 and (out / "runs.jsonl").read_bytes() == before
    lo, hi = settings["occluded_elevation_deg"]  # the same elevations given as an option: the same run, resumed
    assert main([*argv, "--occluded-elevation", f"{lo!r}:{hi!r}"]) == 0 and (out / "runs.jsonl").read_bytes() == before
    other = list(argv)
    other[other.index("--points") + 1] = "16"
    assert main(other) == 2
    assert "other settings" in (err := capsys.readouterr().err) and "points" in err  # naming what differs
    # the aspect augmentation is a setting of every run (its train_config), and needs the augmentation keep_scale turns off
    assert main([*argv, "--augment", "aspect"]) == 2
    assert "other settings" in capsys.readouterr().err
    assert main([*argv, "--augment", "aspect", "--keep-scale"]) == 2
    assert "--augment aspect" in capsys.readouterr().err
    assert main([*argv, "--augment", "partial"]) == 2  # so is the partial one
    assert "other settings" in capsys.readouterr().err
    assert main([*argv, "--augment", "partial", "--keep-scale"]) == 2
    assert "--augment partial" in capsys.readouterr().err


@pytest.mark.parametrize("option, value", [("--seeds", "0"), ("--points", "-3"), ("--per-class", "x"), ("--up", "y")])
def test_bad_options_exit_2_naming_the_value(tmp_path: Path, option: str, value: str, capsys: pytest.CaptureFixture) -> None:
    try:  # argparse's own refusals exit; the checked options return 2 with one line
        status = main(["experiment", "sim2real", str(tmp_path), "--real", str(tmp_path), "--out", str(tmp_path / "o"), option, value])
    except SystemExit as exc:
        status = exc.code
    assert status == 2 and value in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_real_clouds_label_map_and_keep_scale() -> None:
    from zbuf_occlude.experiments.sim2real.real import real_clouds
    from zbuf_occlude.real_scans.records import RealScan, normalize_points

    tall = np.array([[0.0, 0.0, 0.0], [0.2, 0.1, 1.8], [0.1, 0.0, 0.9]])
    scans = [RealScan(normalize_points(tall * k), label, f"{label}{k}", "test", (tall * k).max(axis=0))
             for k, label in ((1.0, "Pedestrian"), (4.0, "Trunk"), (2.0, "Tree"))]  # fmt: skip
    pts, labels, sources = real_clouds(scans, ["pedestrian", "pole"], {"Trunk": "pole"}, 16, 0)
    assert labels.tolist() == [0, 1] and sources == ["Pedestrian1.0", "Trunk4.0"]  # Tree has no class: left out
    np.testing.assert_allclose(np.ptp(pts, axis=1).max(axis=1), 1.0, atol=1e-6)
    metric, _, _ = real_clouds(scans, ["pedestrian", "pole"], {"Trunk": "pole"}, 16, 0, keep_scale=True)
    heights = np.ptp(metric[:, :, 2], axis=1) * KEEP_SCALE_UNIT_M
    np.testing.assert_allclose(heights, [1.8, 7.2], rtol=1e-5)
    with pytest.raises(InvalidInputError, match="label-map"):
        real_clouds(scans[2:], ["pedestrian", "pole"], {}, 16, 0)


def test_an_airborne_lidar_set(tmp_path: Path) -> None:
    from zbuf_occlude.sensors import airborne_preset

    meshes = find_class_meshes(_mesh_root(tmp_path))
    als = airborne_preset("riegl-q1560", altitude_m=300.0)  # ~33 points/m²: a few returns on a pole's top
    s = build_set("lidar", meshes, ["car", "pole"], 4, 32, 0, SetRecipe(sensor=als, min_returns=2))
    assert np.bincount(s.labels).tolist() == [4, 4]
    with pytest.raises(InvalidInputError, match="min-returns"):
        build_set("lidar", meshes, ["car", "pole"], 2, 32, 0, SetRecipe(sensor=als, min_returns=10_000))


# -- --classes, --occluded-elevation, the LiDAR pre-check ----------------------------------------


def test_classes_real_trains_only_the_real_sets_classes(tmp_path: Path) -> None:
    from types import SimpleNamespace

    from zbuf_occlude.experiments.sim2real.run import _classes

    root = _mesh_root(tmp_path)
    (root / "bush").mkdir()  # a class the real scans do not have
    scans = [SimpleNamespace(label=label) for label in ("Car", "Trunk", "Car")]
    assert _classes("real", root, scans, {"Trunk": "pole"}) == ["car", "pole"]
    assert _classes(None, root, scans, {}) is None  # every folder
    assert _classes(["bush", "car"], root, scans, {}) == ["bush", "car"]
    with pytest.raises(InvalidInputError, match="label-map"):
        _classes("real", root, scans, {})  # Trunk matches no folder: one class left
    with pytest.raises(InvalidInputError, match="tree"):
        _classes(["car", "tree"], root, scans, {})


def test_occluded_set_draws_its_elevations_in_the_range_given(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import zbuf_occlude.pipeline as pipeline

    meshes = find_class_meshes(_mesh_root(tmp_path))
    seen: list[float] = []
    real = pipeline.occlude_object

    def spy(mesh, poses, **kw):
        seen.extend(el for el, _ in poses)
        return real(mesh, poses, **kw)

    monkeypatch.setattr(pipeline, "occlude_object", spy)
    build_set("occluded", meshes, ["car", "pole"], 2, 32, 0, SetRecipe(dense_points=500, resolution=64, elevation_deg=(60.0, 80.0)))
    assert seen and min(seen) >= 60.0 and max(seen) <= 80.0
    seen.clear()
    build_set("occluded", meshes, ["car", "pole"], 2, 32, 0, SetRecipe(dense_points=500, resolution=64))
    assert seen and min(seen) >= -5.0 and max(seen) <= 30.0  # the ground sensor's default


def test_the_occluded_sets_elevations_default_to_those_the_sensor_sees_objects_from(tmp_path: Path) -> None:
    """Airborne: 90° minus the flight plan's incidence angles (nadir to half the swath); spinning:
    atan(height / distance) over the lidar set's mount; given: as given."""
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig
    from zbuf_occlude.sensors.fit.class_placement import LIDAR_PLACEMENT
    from zbuf_occlude.sensors import airborne_preset
    from zbuf_occlude.sensors.kinds import sensor_to_json

    dales = Sim2RealConfig("m", "r", sensor="dales-q1560")
    assert dales.occluded_elevation_deg == (61.0, 90.0) and "dales-q1560" in dales.occluded_elevation_from
    narrow = tmp_path / "narrow.json"  # an airborne sensor file with a 40° swath: incidence up to 20°
    narrow.write_text(json.dumps(sensor_to_json(airborne_preset("riegl-q1560", swath_deg=40.0).with_(name="narrow"))))
    assert Sim2RealConfig("m", "r", sensor=str(narrow)).occluded_elevation_deg == (70.0, 90.0)
    (h_lo, h_hi), (d_lo, d_hi) = LIDAR_PLACEMENT["height_m"], LIDAR_PLACEMENT["distance_m"]
    ground = Sim2RealConfig("m", "r", sensor="hdl32e")
    assert ground.occluded_elevation_deg == pytest.approx((np.degrees(np.arctan(h_lo / d_hi)), np.degrees(np.arctan(h_hi / d_lo))))
    assert ground.occluded_elevation_deg == pytest.approx((3.66, 21.80), abs=0.01) and "hdl32e" in ground.occluded_elevation_from
    given = Sim2RealConfig("m", "r", sensor="dales-q1560", occluded_elevation_deg=(30.0, 80.0))
    assert given.occluded_elevation_deg == (30.0, 80.0) and given.occluded_elevation_from == "option"
    assert given.identity()["occluded_elevation_deg"] == [30.0, 80.0]


def test_the_occluded_elevation_help_gives_the_ranges_the_sensors_give(capsys: pytest.CaptureFixture) -> None:
    from zbuf_occlude.experiments.sim2real.data import sensor_elevation_deg
    from zbuf_occlude.sensors import airborne_preset, lidar_preset

    with pytest.raises(SystemExit):
        main(["experiment", "sim2real", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    (a_lo, a_hi), _ = sensor_elevation_deg(airborne_preset("dales-q1560"))
    (g_lo, g_hi), _ = sensor_elevation_deg(lidar_preset("hdl32e"))
    assert f"{a_lo:g}:{a_hi:g} for dales-q1560" in text and f"{g_lo:.1f}:{g_hi:.1f}" in text and "30:80" not in text


def _sets_found(n: int = 4):
    """What prepare_sets finds, as little as _fix_settings reads: two classes of n/2 real scans, no mesh."""
    from zbuf_occlude.experiments.sim2real.run import Sim2RealSets

    y = np.repeat([0, 1], n // 2)
    return Sim2RealSets(["car", "pole"], [], [], np.zeros((n, 8, 3), np.float32), y, [f"{i}.xyz" for i in range(n)],
                        np.array([0, 2]), np.array([1, 3]))  # fmt: skip


def test_settings_hold_the_sensor_in_full_and_only_the_placement_its_kind_uses(tmp_path: Path) -> None:
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig
    from zbuf_occlude.experiments.sim2real.run import _fix_settings
    from zbuf_occlude.sensors.fit.class_placement import LIDAR_PLACEMENT
    from zbuf_occlude.sensors import lidar_preset
    from zbuf_occlude.sensors.kinds import sensor_from_name, sensor_to_json, with_beam

    airborne = Sim2RealConfig("m", "r", sensor="dales-q1560")
    _fix_settings(airborne, _sets_found(), tmp_path / "als")
    written = json.loads((tmp_path / "als" / "settings.json").read_text())
    assert written["lidar_placement"] == {"distance_m": list(LIDAR_PLACEMENT["distance_m"])}  # no mount height: it flies at its altitude
    assert written["sensor_spec"] == sensor_to_json(airborne.sensor) and written["sensor_spec"]["kind"] == "airborne"
    (tmp_path / "als.json").write_text(json.dumps(written["sensor_spec"]))
    assert sensor_from_name(str(tmp_path / "als.json")) == airborne.sensor  # the sensor itself, not just its name
    ground = Sim2RealConfig("m", "r", sensor="hdl32e")
    _fix_settings(ground, _sets_found(), tmp_path / "hdl")
    written = json.loads((tmp_path / "hdl" / "settings.json").read_text())
    assert written["lidar_placement"] == {k: list(v) for k, v in LIDAR_PLACEMENT.items()}
    assert written["sensor_spec"] == sensor_to_json(lidar_preset("hdl32e"))
    # a sensor file under the preset's name, with another field: another run, refused, naming what differs
    (tmp_path / "noisy.json").write_text(json.dumps(sensor_to_json(with_beam(lidar_preset("hdl32e"), range_noise_m=0.1))))
    with pytest.raises(InvalidInputError, match="other settings.*sensor_spec"):
        _fix_settings(Sim2RealConfig("m", "r", sensor=str(tmp_path / "noisy.json")), _sets_found(), tmp_path / "hdl")


def test_a_run_from_before_the_held_out_half_scores_is_refused_saying_so(tmp_path: Path) -> None:
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig
    from zbuf_occlude.experiments.sim2real.run import _fix_settings

    config = Sim2RealConfig("m", "r")
    _fix_settings(config, _sets_found(), tmp_path)
    old = json.loads((tmp_path / "settings.json").read_text())
    del old["real_split"]  # as written before every set was scored on real→real's held-out half
    (tmp_path / "settings.json").write_text(json.dumps(old))
    with pytest.raises(InvalidInputError, match="real_split differ; it was made before every set was scored on the same held-out half"):
        _fix_settings(config, _sets_found(), tmp_path)


def test_a_mesh_without_a_lidar_crop_is_skipped_before_the_work_naming_it(tmp_path: Path, monkeypatch, caplog) -> None:
    import zbuf_occlude.experiments.sim2real.data as data
    from zbuf_occlude.experiments.sim2real.data import check_lidar_meshes
    from zbuf_occlude.sensors import lidar_preset

    root = _mesh_root(tmp_path)
    trimesh.creation.box(extents=(4.0, 1.8, 1.4)).export(root / "car" / "van.obj")
    meshes = find_class_meshes(root)
    real_lidar = data._lidar

    def no_crop_for_the_van(entry, *args, **kw):
        if entry.name == "car/van":
            raise InvalidInputError(f"{entry.path}: no LiDAR crop with 30 returns in 6 rounds")
        return real_lidar(entry, *args, **kw)

    monkeypatch.setattr(data, "_lidar", no_crop_for_the_van)
    kept, skipped = check_lidar_meshes(meshes, lidar_preset("hdl32e"), CLASS_SIZES_M, 32)
    assert skipped == [str(root / "car" / "van.obj")] and len(kept) == len(meshes) - 1
    assert any("van.obj" in r.getMessage() and r.levelname == "WARNING" for r in caplog.records)
    # a class left with one mesh cannot be validated: refused before any set is made, naming what was skipped
    monkeypatch.setattr(data, "_lidar", lambda entry, *a, **k: (_ for _ in ()).throw(InvalidInputError("no crop"))
                        if entry.class_name == "pole" else real_lidar(entry, *a, **k))  # fmt: skip
    with pytest.raises(InvalidInputError, match="post.obj"):
        check_lidar_meshes(meshes, lidar_preset("hdl32e"), CLASS_SIZES_M, 32)


# -- --fit-sensor: a sensor fitted on one fixed half, every row scored on the other -------------


def _fit_spy(monkeypatch: pytest.MonkeyPatch) -> list[list[str]]:
    """Replace the fit by a spy that records the scans it is given and returns the HDL-32E preset,
    crops 15-20 m away and the default sizes."""
    import zbuf_occlude.experiments.sim2real.run as s2r
    from zbuf_occlude.sensors import lidar_preset

    calls: list[list[str]] = []

    def spy(scans, base, labels, names):
        calls.append([s.source for s in scans])
        placement = {n: {"distance_m": (15.0, 20.0), "hidden_below_m": (0.0, 0.1)} for n in names}
        return lidar_preset("hdl32e"), placement, CLASS_SIZES_M, {"name": "fitted-by-spy", "base": base.name}

    monkeypatch.setattr(s2r, "_fit_sensor", spy)
    return calls


def _test_clouds(monkeypatch: pytest.MonkeyPatch) -> list[np.ndarray]:
    """Record the clouds every trained model is scored on (predict's calls outside training)."""
    from zbuf_occlude.learn import training

    scored: list[np.ndarray] = []
    real_train, real_predict = training.train, training.predict
    inside = [False]

    def train(*a, **kw):
        inside[0] = True
        try:
            return real_train(*a, **kw)
        finally:
            inside[0] = False

    def predict(model, points, **kw):
        if not inside[0]:
            scored.append(np.array(points))
        return real_predict(model, points, **kw)

    monkeypatch.setattr(training, "train", train)
    monkeypatch.setattr(training, "predict", predict)
    return scored


def _cloud_set(clouds: np.ndarray) -> list[bytes]:
    """A stack of clouds as a sorted list of their bytes: the same clouds in any order compare equal."""
    return sorted(np.ascontiguousarray(c).tobytes() for c in clouds)


def _rows(path: Path) -> list[dict]:
    with open(path, encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow
def test_fit_sensor_fits_on_one_half_and_scores_every_row_on_the_other(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from zbuf_occlude.experiments.sim2real.data import FITTED_PLACED, FITTED_SETS
    from zbuf_occlude.experiments.sim2real.real import real_clouds
    from zbuf_occlude.real_scans.datasets import load_real_scans

    meshes, real, out = _mesh_root(tmp_path), _real_root(tmp_path), tmp_path / "out"
    fits, scored = _fit_spy(monkeypatch), _test_clouds(monkeypatch)
    argv = ["experiment", "sim2real", str(meshes), "--real", str(real), "--label-map", "Trunk=pole", "--fit-sensor",
            "--points", "32", "--epochs", "1", "--per-class", "4", "--threads", "1", "--no-progress"]  # fmt: skip
    assert main([*argv, "--out", str(out), "--seeds", "2"]) == 0
    split = _rows(out / "real_split.csv")
    fit = {r["source"] for r in split if r["half"] == "fit"}
    held = {r["source"] for r in split if r["half"] == "scored"}
    assert len(split) == 12 and not fit & held and len(fit) == len(held) == 6
    assert sorted(r["class"] for r in split if r["half"] == "fit") == ["car"] * 3 + ["pole"] * 3  # stratified
    assert len(fits) == 1 and sorted(fits[0]) == sorted(fit)  # the fit saw the fit half, nothing else
    assert json.loads((out / "fitted_sensor.json").read_text()) == {"name": "fitted-by-spy", "base": "hdl32e"}
    # every row, the mesh-only sets and real→real alike, is scored on the held-out half; the mesh-only sets on every scan too
    pts, _, sources = real_clouds(load_real_scans(real), ["car", "pole"], {"Trunk": "pole"}, 32, 0)
    expected = _cloud_set(pts[[i for i, s in enumerate(sources) if s in held]])
    results = _rows(out / "results.csv")
    assert sorted((r["train_set"], r["seed"]) for r in results) == sorted(
        (s, str(k)) for s in (*TRAINING_SETS, *FITTED_SETS, "real→real") for k in range(2)
    )
    assert [_cloud_set(x) for x in scored] == [
        c for r in results for c in ([expected] if r["train_set"] == "real→real" else [expected, _cloud_set(pts)])
    ]
    assert all(int(r["n_test"]) == 6 for r in results)
    summary = {r["train_set"]: r for r in _rows(out / "summary.csv")}
    for kind in FITTED_SETS:
        assert 1 / 6 - 1e-9 <= float(summary[kind]["p_vs_lidar"]) <= 1.0 and "diff_vs_lidar" in summary[kind]
        assert f"| {kind} | 2 |" in (out / "table.md").read_text() and f"{kind} vs lidar" in (out / "table.md").read_text()
    assert (out / "confusion_fitted.csv").is_file() and (out / f"confusion_{FITTED_PLACED.replace('+', '_')}.csv").is_file()
    settings = json.loads((out / "settings.json").read_text())
    assert settings["fit_sensor"]["fit_scans"] == settings["fit_sensor"]["scored_scans"] == {"car": 3, "pole": 3}
    # the same split and the same runs again: the split does not depend on the run's seeds
    again = tmp_path / "again"
    assert main([*argv, "--out", str(again), "--seeds", "1"]) == 0
    assert (again / "real_split.csv").read_bytes() == (out / "real_split.csv").read_bytes()
    timing = ("data_s", "train_s")
    first = [{k: v for k, v in r.items() if k not in timing} for r in map(json.loads, (out / "runs.jsonl").read_text().splitlines())]
    second = [{k: v for k, v in r.items() if k not in timing} for r in map(json.loads, (again / "runs.jsonl").read_text().splitlines())]
    assert second == [r for r in first if r["seed"] == 0]


def test_the_held_out_half_and_the_real_clouds_depend_on_the_scans_content_not_their_file_names(tmp_path: Path) -> None:
    import shutil

    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig
    from zbuf_occlude.experiments.sim2real.run import prepare_sets

    meshes, real = _mesh_root(tmp_path), _real_root(tmp_path)
    renamed = tmp_path / "renamed"  # the same scans, their names in the other order (and other folder names)
    for cls, new in (("Car", "Vehicle"), ("Trunk", "Stem")):
        files = sorted((real / cls).iterdir())
        (renamed / new).mkdir(parents=True)
        for f, g in zip(files, reversed(files)):
            shutil.copy(f, renamed / new / f"scan_{g.stem}.xyz")
    found = [prepare_sets(Sim2RealConfig(meshes, root, label_map=labels, points=32))
             for root, labels in ((real, {"Trunk": "pole"}), (renamed, {"Vehicle": "car", "Stem": "pole"}))]  # fmt: skip
    for half in ("half_a", "half_b"):
        a, b = ({(int(s.real_labels[i]), s.real_points[i].tobytes()) for i in getattr(s, half)} for s in found)
        assert a == b and len(a) == 6, half  # the same scans in each half, and each the same cloud
    assert sorted(np.bincount(found[0].real_labels[found[0].half_b]).tolist()) == [3, 3]  # stratified


@pytest.mark.slow
def test_a_resumed_run_makes_only_the_sets_it_still_trains_and_they_come_out_the_same(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from zbuf_occlude.experiments.sim2real import outputs, run

    _fit_spy(monkeypatch)
    out = tmp_path / "out"
    argv = ["experiment", "sim2real", str(_mesh_root(tmp_path)), "--real", str(_real_root(tmp_path)), "--out", str(out),
            "--label-map", "Trunk=pole", "--fit-sensor", "--points", "32", "--epochs", "1", "--per-class", "4", "--seeds", "1",
            "--threads", "1", "--no-progress"]  # fmt: skip
    asked: list[list[str]] = []
    real_build = run.build_sets

    def build_sets(*a, kinds=None, **kw):
        asked.append(list(kinds))
        return real_build(*a, kinds=kinds, **kw)

    monkeypatch.setattr(run, "build_sets", build_sets)
    assert main(argv) == 0
    timing = ("data_s", "train_s")
    rows = [{k: v for k, v in json.loads(line).items() if k not in timing} for line in (out / "runs.jsonl").read_text().splitlines()]
    assert asked == [[*TRAINING_SETS, *FITTED_SETS]] * 2  # the training clouds and those of the held-out meshes
    # two rows lost (an interrupted run): only their sets are made again, and they train to the same rows
    kept = [
        line for line in (out / "runs.jsonl").read_text().splitlines() if json.loads(line)["train_set"] not in ("occluded", FITTED_PLACED)
    ]
    # written as a run that stopped there wrote it, through the output layer (a file changed by hand is refused)
    from zbuf_occlude.io.owned import OwnedFolder

    with OwnedFolder(out, names=outputs.SIM2REAL_OUTPUTS) as folder:
        folder.write_text("runs.jsonl", "\n".join(kept) + "\n")
    assert main(argv) == 0 and asked[2:] == [["occluded", FITTED_PLACED]] * 2
    again = {r["train_set"]: r for r in ({k: v for k, v in json.loads(line).items() if k not in timing}
                                         for line in (out / "runs.jsonl").read_text().splitlines())}  # fmt: skip
    assert again == {r["train_set"]: r for r in rows}
    # nothing left to train: no set is made
    assert main(argv) == 0 and len(asked) == 4


@pytest.mark.slow
def test_without_fit_sensor_no_fitted_set_and_every_row_scored_on_real_to_reals_held_out_half(tmp_path: Path,
                                                                                             monkeypatch: pytest.MonkeyPatch) -> None:  # fmt: skip
    fits, scored, out = _fit_spy(monkeypatch), _test_clouds(monkeypatch), tmp_path / "out"
    argv = ["experiment", "sim2real", str(_mesh_root(tmp_path)), "--real", str(_real_root(tmp_path)), "--out", str(out),
            "--label-map", "Trunk=pole", "--points", "32", "--epochs", "1", "--per-class", "4", "--seeds", "1", "--threads", "1",
            "--no-progress"]  # fmt: skip
    assert main(argv) == 0 and fits == []
    assert not (out / "fitted_sensor.json").exists()
    results = _rows(out / "results.csv")
    assert [r["train_set"] for r in results] == [*TRAINING_SETS, "real→real"]
    settings = json.loads((out / "settings.json").read_text())
    assert "fit_sensor" not in settings and settings["real_split"]["scored_scans"] == {"car": 3, "pole": 3}
    # the primary scores of a mesh-only set and of real→real: the same clouds, the half real→real did not train on
    real_to_real_test = _cloud_set(scored[-1])
    assert len(scored) == 2 * len(TRAINING_SETS) + 1 and all(_cloud_set(x) == real_to_real_test for x in scored[0:-1:2])
    held = {r["source"] for r in _rows(out / "real_split.csv") if r["half"] == "scored"}
    assert len(held) == 6 and len(scored[0]) == 6 and len(scored[1]) == 12


def test_fit_sensor_needs_sensor_frame_points_and_a_spinning_lidar() -> None:
    from types import SimpleNamespace

    from zbuf_occlude.experiments.sim2real.run import _fit_sensor
    from zbuf_occlude.sensors import airborne_preset, lidar_preset

    with pytest.raises(InvalidInputError, match="spinning LiDAR"):
        _fit_sensor([], airborne_preset("riegl-q1560"), np.zeros(0), [])
    with pytest.raises(InvalidInputError, match="Car/0.xyz"):
        _fit_sensor([SimpleNamespace(source="Car/0.xyz", points_sensor_m=None)], lidar_preset("hdl32e"), np.zeros(1), ["car"])


def test_an_airborne_sensor_with_fit_sensor_is_refused_before_anything_is_read(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                              capsys: pytest.CaptureFixture) -> None:  # fmt: skip
    import zbuf_occlude.experiments.sim2real.run as s2r
    import zbuf_occlude.real_scans.datasets as datasets

    read: list[str] = []
    monkeypatch.setattr(datasets, "load_real_scans", lambda *a, **k: read.append("scans") or [])
    monkeypatch.setattr(s2r, "find_class_meshes", lambda *a, **k: read.append("meshes") or [])
    argv = ["experiment", "sim2real", str(_mesh_root(tmp_path)), "--real", str(tmp_path), "--out", str(tmp_path / "o"),
            "--sensor", "dales-q1560", "--fit-sensor", "--no-progress"]  # fmt: skip
    assert main(argv) == 2 and read == []
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--fit-sensor" in err and "--sensor dales-q1560" in err and "airborne" in err
    assert not (tmp_path / "o").exists()


def test_fit_sensor_says_what_it_reads_and_fits_before_and_after_the_fit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import zbuf_occlude.experiments.sim2real.run as s2r
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig
    from zbuf_occlude.experiments.sim2real.run import prepare_sets

    said: list[str] = []
    fits = _fit_spy(monkeypatch)
    spy = s2r._fit_sensor
    monkeypatch.setattr(s2r, "_fit_sensor", lambda *a: said.append("<fit>") or spy(*a))
    config = Sim2RealConfig(_mesh_root(tmp_path), _real_root(tmp_path), label_map={"Trunk": "pole"}, fit_sensor=True, points=32)
    prepare_sets(config, say=said.append)
    assert len(fits) == 1
    fit_at = said.index("<fit>")
    assert str(tmp_path / "real") in said[0]  # what it reads, first
    assert "fitting hdl32e" in said[fit_at - 1] and "6 scans" in said[fit_at - 1]  # a line before the fit ...
    assert said[fit_at + 1].startswith("fitted hdl32e in")  # ... and one after it


def test_the_fit_takes_one_return_a_pulse_and_the_lidar_set_keeps_its_returns(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--returns 2 --fit-sensor``: the sensor is fitted to the real scans (one return a pulse) from the preset as it is,
    and the lidar set's crops keep up to two returns a pulse."""
    import zbuf_occlude.experiments.sim2real.run as s2r
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig
    from zbuf_occlude.sensors import lidar_preset

    fitted_from: list = []
    _fit_spy(monkeypatch)
    spy = s2r._fit_sensor
    monkeypatch.setattr(s2r, "_fit_sensor", lambda scans, sensor, *a: fitted_from.append(sensor) or spy(scans, sensor, *a))
    config = Sim2RealConfig(_mesh_root(tmp_path), _real_root(tmp_path), label_map={"Trunk": "pole"}, fit_sensor=True, points=32, returns=2)
    assert config.sensor.beam.max_returns == 2 and config.identity()["lidar_returns"]["max_returns"] == 2
    s2r.prepare_sets(config)
    assert fitted_from == [lidar_preset("hdl32e")]


def _box_scan(distance: float, seed: int) -> np.ndarray:
    from zbuf_occlude.sensors import lidar_preset, scan

    box = trimesh.creation.box(extents=(1.5, 1.5, 1.5))
    box.apply_translation((distance, 0.0, 0.75 - 1.8))
    return np.asarray(scan(box, lidar_preset("hdl32e"), np.eye(4), seed=seed, azimuth_range_deg=(-30.0, 30.0)).points, np.float64)


def test_fit_sensor_fits_crop_distances_and_heights_per_class() -> None:
    """Each class's crops are placed at the distances its own real scans were taken from, as tall as they look."""
    from types import SimpleNamespace

    from zbuf_occlude.experiments.sim2real.run import _fit_sensor
    from zbuf_occlude.sensors import lidar_preset

    near, far = [4.0, 5.0, 6.0, 7.0], [12.0, 14.0, 16.0, 18.0]
    clouds = [_box_scan(d, i) for i, d in enumerate(near + far)]
    scans = [SimpleNamespace(source=f"{i}.xyz", points_sensor_m=c) for i, c in enumerate(clouds)]
    labels = np.array([0] * 4 + [1] * 4)
    _, placement, sizes, spec = _fit_sensor(scans, lidar_preset("hdl32e"), labels, ["car", "pole"])
    distances = {k: v["distance_m"] for k, v in placement.items()}
    # the centroid of the visible faces lies up to half the box (0.75 m) nearer than its centre
    assert 4.0 - 0.8 < distances["car"][0] < distances["car"][1] < 7.0 and 12.0 - 0.8 < distances["pole"][0] < distances["pole"][1] < 18.0
    crops = spec["fit"]["crops"]
    assert crops["quantiles"] == [10.0, 90.0] and crops["distance_m"] == {k: list(v) for k, v in distances.items()}
    # 1.5 m boxes: the near ones seen whole, the far ones between beams 1.33 degrees (0.3-0.4 m) apart
    assert sizes["car"].dimension == "height" and 1.2 < sizes["car"].lo_m <= sizes["car"].hi_m <= 1.5 + 0.1  # range noise 2 cm
    assert 0.9 < sizes["pole"].lo_m <= sizes["pole"].hi_m < sizes["car"].hi_m
    assert crops["object_height_m"]["pole"] == [sizes["pole"].lo_m, sizes["pole"].hi_m]
    # boxes on the ground: their bottoms are seen, within a ring of it, and the placement carries them
    assert {k: list(v["hidden_below_m"]) for k, v in placement.items()} == crops["hidden_below_m"]
    assert all(0.0 <= lo <= hi < 0.5 for lo, hi in crops["hidden_below_m"].values())
    # and their widths across the line of sight: 1.5 m boxes face-on, less at most an azimuth step at each edge (0.11 m at 18 m)
    assert {k: list(v["across_sight_width_m"]) for k, v in placement.items()} == crops["across_sight_width_m"]
    assert all(1.39 < lo <= hi < 1.52 for lo, hi in crops["across_sight_width_m"].values())
    with pytest.raises(InvalidInputError, match="--fit-sensor: class 'pole'.*at least 3"):
        _fit_sensor(scans[:6], lidar_preset("hdl32e"), labels[:6], ["car", "pole"])


def test_fit_crop_distances_are_percentiles_of_the_horizontal_distances() -> None:
    from zbuf_occlude.sensors.fit import fit_crop_distances

    # one point per scan, at horizontal distance d (and some height): the distance is d exactly
    clouds = [np.array([[d * np.cos(a), d * np.sin(a), -1.0]]) for d, a in zip(np.arange(1.0, 12.0), np.linspace(0, 6, 11))]
    assert fit_crop_distances(clouds) == pytest.approx((2.0, 10.0))
    assert fit_crop_distances(clouds, (0.0, 100.0)) == pytest.approx((1.0, 11.0))
    with pytest.raises(InvalidInputError, match="at least 3"):
        fit_crop_distances(clouds[:2])
    with pytest.raises(InvalidInputError, match="quantiles"):
        fit_crop_distances(clouds, (90.0, 10.0))


@pytest.mark.slow
def test_the_fitted_placed_set_draws_the_fitted_distances_and_the_others_the_preset_ones(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from zbuf_occlude.experiments.sim2real.data import FITTED, FITTED_PLACED, build_sets
    from zbuf_occlude.sensors.fit.class_placement import LIDAR_PLACEMENT
    from zbuf_occlude.sensors import crops, lidar_preset

    seen: list[tuple[str, tuple[float, float]]] = []
    widths: list[tuple[str, tuple[float, float], tuple[float, float] | None]] = []
    real = crops.lidar_object_samples

    def spy(mesh, sensor, **kw):
        seen.append((sensor.name, kw["distributions"].distance_m, kw["distributions"].hidden_below_m))
        widths.append((sensor.name, kw["distributions"].distance_m, kw["distributions"].width_scale))
        return real(mesh, sensor, **kw)

    monkeypatch.setattr(crops, "lidar_object_samples", spy)
    meshes = find_class_meshes(_mesh_root(tmp_path))
    fitted = lidar_preset("hdl32e").with_(name="fitted")
    heights = {"car": SizeRange("height", 1.0, 1.0), "pole": SizeRange("height", 2.0, 2.0)}
    placed = CropPlacement.from_keywords({"car": {"distance_m": (6.0, 7.0), "hidden_below_m": (0.2, 0.4)},
                                          "pole": {"distance_m": (8.0, 9.0), "across_sight_width_m": (0.4, 0.8)}})  # fmt: skip
    sets = build_sets(meshes, ["car", "pole"], 2, 32, 0, SetRecipe(sensor=lidar_preset("hdl32e"), resolution=128, dense_points=2000, keep_scale=True),
                      fitted_sensor=fitted, fitted_placement=placed, fitted_sizes=heights)  # fmt: skip
    assert sets[FITTED].points.shape == sets[FITTED_PLACED].points.shape == (4, 32, 3)
    # kept in metres: the placed crops are as tall as the fitted heights at most, the others' poles taller (2.5-9 m)
    tall = lambda s, label: float(np.ptp(s.points[s.labels == label][..., 2], axis=1).max()) * KEEP_SCALE_UNIT_M  # noqa: E731
    assert tall(sets[FITTED_PLACED], 0) <= 1.0 + 1e-3 and tall(sets[FITTED_PLACED], 1) <= 2.0 + 1e-3
    assert tall(sets["lidar"], 1) > 2.0 and tall(sets[FITTED], 1) > 2.0
    # the preset sensor and the fitted set at the preset's distances; the placed set at the fitted ones
    assert {(d, h) for name, d, h in seen if name == "hdl32e"} == {(LIDAR_PLACEMENT["distance_m"], None)}
    assert {(d, h) for name, d, h in seen if name == "fitted"} == {
        (LIDAR_PLACEMENT["distance_m"], None),
        ((6.0, 7.0), (0.2, 0.4)),
        ((8.0, 9.0), None),
    }
    # only the placed poles are stretched, each pole mesh to the fitted widths (twice as wide at the top as at the bottom)
    stretched = [w for name, d, w in widths if w is not None]
    assert {d for name, d, w in widths if w is not None} == {(8.0, 9.0)} and all(hi == pytest.approx(2 * lo) for lo, hi in stretched)
    assert sets[FITTED_PLACED].points[sets[FITTED_PLACED].labels == 1].shape == (2, 32, 3)


def test_build_sets_makes_the_sets_asked_for_and_refuses_one_it_cannot_make(tmp_path: Path) -> None:
    from zbuf_occlude.sensors import lidar_preset

    meshes = find_class_meshes(_mesh_root(tmp_path))
    recipe = SetRecipe(sensor=lidar_preset("hdl32e"), resolution=128, dense_points=2000)
    every = build_sets(meshes, ["car", "pole"], 2, 32, 0, recipe)
    assert list(every) == list(TRAINING_SETS)
    some = build_sets(meshes, ["car", "pole"], 2, 32, 0, recipe, kinds=["lidar+complete", "occluded"])
    assert list(some) == ["occluded", "lidar+complete"]  # in report order
    assert all(np.array_equal(some[k].points, every[k].points) and np.array_equal(some[k].labels, every[k].labels) for k in some)
    with pytest.raises(InvalidInputError, match=r"\['fitted\+placed'\]"):
        build_sets(meshes, ["car", "pole"], 2, 32, 0, recipe, kinds=[FITTED_PLACED])


def test_the_pooled_set_is_the_three_lidar_sets_of_its_seed_in_one(tmp_path: Path) -> None:
    from zbuf_occlude.experiments.sim2real.data import FITTED, POOLED
    from zbuf_occlude.sensors import lidar_preset
    from zbuf_occlude.sensors.kinds import with_beam

    meshes = find_class_meshes(_mesh_root(tmp_path))
    recipe = SetRecipe(sensor=lidar_preset("hdl32e"))
    options = dict(fitted_sensor=with_beam(lidar_preset("hdl32e"), range_noise_m=0.0).with_(name="fitted"),
                   fitted_placement=CropPlacement.from_keywords({"car": {"distance_m": (6.0, 7.0)}, "pole": {"distance_m": (8.0, 9.0)}}),
                   fitted_sizes={"car": SizeRange("height", 1.0, 1.5), "pole": SizeRange("height", 2.0, 3.0)})  # fmt: skip
    every = build_sets(meshes, ["car", "pole"], 3, 32, 0, recipe, **options)
    assert list(every) == [*TRAINING_SETS, FITTED, FITTED_PLACED, POOLED]
    pooled = build_sets(meshes, ["car", "pole"], 3, 32, 0, recipe, kinds=[POOLED], **options)[POOLED]
    parts = [every[k] for k in ("lidar", FITTED, FITTED_PLACED)]
    assert np.array_equal(pooled.points, np.concatenate([s.points for s in parts]))
    assert np.array_equal(pooled.labels, np.concatenate([s.labels for s in parts])) and np.bincount(pooled.labels).tolist() == [9, 9]
    # the three differ (the sensor, then the placements): pooling them is not one set three times
    assert not np.array_equal(parts[0].points, parts[1].points) and not np.array_equal(parts[1].points, parts[2].points)


@pytest.mark.slow
def test_validate_on_fit_half_validates_mesh_sets_on_the_fit_half_and_trains_on_every_mesh(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from zbuf_occlude.experiments.sim2real.data import FITTED_SETS
    from zbuf_occlude.learn import training

    meshes, real, out = _mesh_root(tmp_path), _real_root(tmp_path), tmp_path / "out"
    _fit_spy(monkeypatch)
    seen: list[tuple[int, np.ndarray]] = []
    real_train = training.train

    def train(train_set, n_classes, cfg, *, val_set, **kw):
        seen.append((set(train_set.object_index.tolist()), np.array(val_set.points)))
        return real_train(train_set, n_classes, cfg, val_set=val_set, **kw)

    monkeypatch.setattr(training, "train", train)
    argv = ["experiment", "sim2real", str(meshes), "--real", str(real), "--label-map", "Trunk=pole", "--fit-sensor",
            "--points", "32", "--epochs", "1", "--per-class", "8", "--threads", "1", "--no-progress", "--seeds", "1"]  # fmt: skip
    assert main([*argv, "--out", str(out), "--validate-on", "fit-half"]) == 0
    results = _rows(out / "results.csv")
    kinds = [r["train_set"] for r in results]
    assert kinds == [*TRAINING_SETS, *FITTED_SETS, "real→real"]
    from zbuf_occlude.experiments.sim2real.real import real_clouds
    from zbuf_occlude.real_scans.datasets import load_real_scans

    pts, _, sources = real_clouds(load_real_scans(real), ["car", "pole"], {"Trunk": "pole"}, 32, 0)
    fit_half = {r["source"] for r in _rows(out / "real_split.csv") if r["half"] == "fit"}
    expected = pts[[i for i, s in enumerate(sources) if s in fit_half]]
    for kind, (objects, val) in zip(kinds, seen):
        if kind == "real→real":  # its own 10 % of the fit half, as without the option
            assert len(val) < len(expected) and all(any(np.array_equal(v, x) for x in expected) for v in val)
        else:  # every mesh trains; the whole fit half validates
            assert _cloud_set(val) == _cloud_set(expected), kind
            assert len(objects) == 4, (kind, objects)
    assert all(int(r["n_val"]) == 6 for r in results if r["train_set"] != "real→real")
    assert json.loads((out / "settings.json").read_text())["validate_on"] == "fit-half"
    assert "fit half's real scans" in (out / "table.md").read_text()
    chosen = {r["train_set"]: r for r in _rows(out / "summary.csv")}["chosen on fit half"]
    best = max((r for r in map(json.loads, (out / "runs.jsonl").read_text().splitlines()) if r["train_set"] != "real→real"),
               key=lambda r: (r["best_val_mean_class_accuracy"], -r["best_val_loss"]))  # ties: the lower loss  # fmt: skip
    assert chosen["chosen_sets"] == best["train_set"] and float(chosen["mean_class_accuracy_mean"]) == pytest.approx(
        best["mean_class_accuracy"]
    )
    assert "| chosen on fit half | 1 |" in (out / "table.md").read_text()
    # without --fit-sensor there is no fit half: a usage error naming the option
    assert main([*argv[:7], *argv[8:], "--out", str(tmp_path / "o2"), "--validate-on", "fit-half"]) == 2


@pytest.mark.slow
def test_fitted_shape_gives_the_placed_meshes_the_fitted_widths_or_outline_or_neither(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                                       capsys: pytest.CaptureFixture) -> None:  # fmt: skip
    from zbuf_occlude.experiments.sim2real import run

    from zbuf_occlude.sensors import lidar_preset

    meshes, real = _mesh_root(tmp_path), _real_root(tmp_path)

    def fit(scans, base, labels, names):  # the fit, with widths and an outline per class
        shaped = {"distance_m": (6.0, 9.0), "across_sight_width_m": (0.3, 0.5), "across_sight_profile": (1.0,) * 8}
        return lidar_preset("hdl32e"), {n: dict(shaped) for n in names}, CLASS_SIZES_M, {"name": "fitted-by-spy", "base": base.name}

    monkeypatch.setattr(run, "_fit_sensor", fit)
    asked: list[set[str]] = []
    real_fit = run.fit_mesh_shapes

    def spy(meshes, sensor, sizes, placement):
        asked.append({key for c in placement.per_class.values() for key in ("across_sight_width_m", "across_sight_profile")
                      if getattr(c, key) is not None})  # fmt: skip
        return real_fit(meshes, sensor, sizes, placement)

    monkeypatch.setattr(run, "fit_mesh_shapes", spy)
    argv = ["experiment", "sim2real", str(meshes), "--real", str(real), "--label-map", "Trunk=pole", "--fit-sensor", "--points", "32",
            "--epochs", "1", "--per-class", "4", "--threads", "1", "--no-progress", "--seeds", "1", "--validate-on", "fit-half"]  # fmt: skip
    scales = []
    real_build = run.build_sets

    shares = []

    def build_sets(*a, fitted_placement=None, **kw):  # the stretches and visible shares the fitted+placed set is given
        scales.append({name: v.width_scale for name, v in fitted_placement.per_mesh.items() if v.width_scale is not None})
        shares.append({name: v.visible_across_sight for name, v in fitted_placement.per_mesh.items() if v.visible_across_sight is not None})
        return real_build(*a, fitted_placement=fitted_placement, **kw)

    monkeypatch.setattr(run, "build_sets", build_sets)
    for shape, out in (("none", "o1"), ("outline", "o2"), ("widths,outline", "o3"), ("widen", "o6"), ("occlude", "o8")):
        assert main([*argv, "--out", str(tmp_path / out), "--fitted-shape", shape]) == 0
        assert json.loads((tmp_path / out / "settings.json").read_text())["fit_sensor"]["fitted_shape"] == (
            [] if shape == "none" else shape.split(",")
        )
    assert [{"across_sight_width_m", "across_sight_profile"} & keys for keys in asked] == [
        set(),
        {"across_sight_profile"},
        {"across_sight_width_m", "across_sight_profile"},
        {"across_sight_width_m"},
        {"across_sight_width_m"},
    ]
    assert scales[0] == scales[1] == scales[4] == {} and scales[2] and scales[3]
    # occlude: no stretch, a visible share per mesh, below 1 for the meshes wider than 0.3-0.5 m
    assert not any(shares[:4]) and set(shares[4]) == set(scales[2]) and any(lo < 1.0 for lo, _ in shares[4].values())
    assert min(v for lo_hi in scales[3].values() for v in lo_hi) >= 1.0  # widen: never narrower
    assert any(lo < 1.0 for lo, _ in scales[2].values())  # these meshes are wider than 0.3-0.5 m somewhere: widths narrows them
    # a shape that does not exist, or one without --fit-sensor: usage errors naming the value or the option
    capsys.readouterr()
    assert main([*argv, "--out", str(tmp_path / "o4"), "--fitted-shape", "outlines"]) == 2
    assert "'outlines'" in capsys.readouterr().err
    for both in ("widths,widen", "occlude,widths,outline"):
        assert main([*argv, "--out", str(tmp_path / "o7"), "--fitted-shape", both]) == 2
        assert "not both" in capsys.readouterr().err
    assert main([*argv[:7], *argv[8:-2], "--out", str(tmp_path / "o5"), "--fitted-shape", "outline"]) == 2
    assert "--fit-sensor" in capsys.readouterr().err


def test_the_set_chosen_on_the_fit_half_is_the_best_validated_per_seed_never_the_best_scored() -> None:
    from zbuf_occlude.experiments.sim2real.outputs import CHOSEN_ON_FIT_HALF
    from zbuf_occlude.experiments.sim2real.report import summarise

    def run(kind: str, seed: int, val: float, scored: float) -> dict:
        return {"train_set": kind, "seed": seed, "best_val_mean_class_accuracy": val, "mean_class_accuracy": scored}

    runs = [
        run("complete", 0, 0.50, 0.60),
        run("lidar", 0, 0.80, 0.70),
        run("fitted", 0, 0.70, 0.95),
        run("complete", 1, 0.60, 0.55),
        run("lidar", 1, 0.90, 0.99),
        run("occluded", 1, 0.90, 0.65),  # a tie: the first set
        run("real→real", 0, 0.99, 0.90),
        run("real→real", 1, 0.99, 0.92),
    ]  # its validation never counts
    rows = {r["train_set"]: r for r in summarise(runs, ["car", "pole"], chosen_on_fit_half=True)}
    chosen = rows[CHOSEN_ON_FIT_HALF]
    assert chosen["chosen_sets"] == "lidar occluded" and chosen["n_seeds"] == 2
    assert chosen["mean_class_accuracy_mean"] == pytest.approx(0.675)
    assert chosen["diff_vs_real_to_real"] == pytest.approx(0.675 - 0.91)
    assert chosen["p_real_to_real_above"] == pytest.approx(1 / 6)  # both real→real seeds above both chosen ones
    assert chosen["diff_vs_complete"] == pytest.approx(0.675 - 0.575)
    assert CHOSEN_ON_FIT_HALF not in {r["train_set"] for r in summarise(runs, ["car", "pole"])}


def test_a_validation_accuracy_tie_goes_to_the_lower_validation_loss() -> None:
    from zbuf_occlude.experiments.sim2real.outputs import CHOSEN_ON_FIT_HALF
    from zbuf_occlude.experiments.sim2real.report import summarise

    def run(kind: str, val: float, loss: float | None, scored: float) -> dict:
        return {"train_set": kind, "seed": 0, "best_val_mean_class_accuracy": val, "best_val_loss": loss, "mean_class_accuracy": scored}

    both_saturated = [
        run("complete", 1.0, 0.40, 0.6),
        run("occluded", 1.0, 0.10, 0.8),
        run("lidar", 1.0, 0.25, 0.7),
        run("real→real", 1.0, 0.01, 0.9),
    ]
    rows = {r["train_set"]: r for r in summarise(both_saturated, ["car", "pole"], chosen_on_fit_half=True)}
    assert rows[CHOSEN_ON_FIT_HALF]["chosen_sets"] == "occluded"
    no_loss = [run("complete", 1.0, None, 0.6), run("lidar", 1.0, 0.3, 0.7)]  # an older record without a loss ranks last
    rows = {r["train_set"]: r for r in summarise(no_loss, ["car", "pole"], chosen_on_fit_half=True)}
    assert rows[CHOSEN_ON_FIT_HALF]["chosen_sets"] == "lidar"


@pytest.mark.slow
def test_a_class_outline_warps_each_mesh_then_stretches_it_under_the_warp(tmp_path: Path) -> None:
    from zbuf_occlude.sensors.fit.class_placement import fit_mesh_shapes
    from zbuf_occlude.sensors import lidar_preset

    meshes = [m for m in find_class_meshes(_mesh_root(tmp_path)) if m.class_name == "pole"]
    sensor = lidar_preset("hdl32e")
    sizes = {"pole": SizeRange("height", 3.0, 4.0)}
    widths = {"distance_m": (5.0, 9.0), "across_sight_width_m": (0.3, 0.5)}
    outline = (0.5, 0.5, 1.0, 1.0, 1.0, 1.0, 2.0, 2.0)
    placement = CropPlacement.from_keywords({"pole": {**widths, "across_sight_profile": outline}})
    plain = fit_mesh_shapes(meshes, sensor, sizes, CropPlacement.from_keywords({"pole": widths}))
    warped = fit_mesh_shapes(meshes, sensor, sizes, placement)
    for m in meshes:
        assert plain[m.name].width_profile is None and len(warped[m.name].width_profile) == len(outline)
        assert warped[m.name].width_profile[0] < warped[m.name].width_profile[-1]  # narrower at the foot than at the top
        assert warped[m.name].width_scale != plain[m.name].width_scale  # stretched again under the warp
    only = fit_mesh_shapes(
        meshes, sensor, sizes, CropPlacement.from_keywords({"pole": {"distance_m": (5.0, 9.0), "across_sight_profile": outline}})
    )
    assert all(set(v.keywords) == {"width_profile"} for v in only.values()) and len(only) == len(meshes)  # a warp without a stretch
    recipe = SetRecipe(sensor=sensor, sizes=sizes, placement=placement)
    every_draw = build_set("lidar", meshes, ["pole"], 2, 64, 3, recipe)
    once = build_set(
        "lidar", meshes, ["pole"], 2, 64, 3, SetRecipe(sensor=sensor, sizes=sizes, placement=placement.with_mesh_shapes(warped))
    )
    np.testing.assert_array_equal(once.points, every_draw.points)
    unwarped = CropPlacement.from_keywords({"pole": widths}).with_mesh_shapes(plain)
    assert not np.array_equal(
        once.points, build_set("lidar", meshes, ["pole"], 2, 64, 3, SetRecipe(sensor=sensor, sizes=sizes, placement=unwarped)).points
    )


@pytest.mark.slow
def test_width_scales_fitted_once_give_the_crops_of_fitting_them_in_every_draw(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from zbuf_occlude.sensors.fit.class_placement import fit_mesh_shapes
    from zbuf_occlude.sensors import lidar_preset
    from zbuf_occlude.sensors.fit import shapes

    meshes = find_class_meshes(_mesh_root(tmp_path))
    sensor = lidar_preset("hdl32e")
    sizes = {"car": SizeRange("height", 1.5, 1.5), "pole": SizeRange("height", 3.0, 4.0)}
    placement = CropPlacement.from_keywords(
        {"car": {"distance_m": (6.0, 8.0)}, "pole": {"distance_m": (5.0, 9.0), "across_sight_width_m": (0.3, 0.5)}}
    )
    every_draw = build_set("lidar", meshes, ["car", "pole"], 4, 64, 3, SetRecipe(sensor=sensor, sizes=sizes, placement=placement))
    once = fit_mesh_shapes(meshes, sensor, sizes, placement)
    assert sorted(once) == sorted(m.name for m in meshes if m.class_name == "pole")  # the classes that give widths
    assert once["pole/post"] != once["pole/lamp"]  # each mesh its own stretch
    calls = []
    monkeypatch.setattr(shapes, "fit_width_scale", lambda *a, **k: calls.append(a) or (1.0, 1.0))
    merged = build_set(
        "lidar", meshes, ["car", "pole"], 4, 64, 3, SetRecipe(sensor=sensor, sizes=sizes, placement=placement.with_mesh_shapes(once))
    )
    np.testing.assert_array_equal(merged.points, every_draw.points)
    assert calls == []  # not fitted again


@pytest.mark.slow
def test_widen_is_never_narrower_whether_fitted_once_or_in_the_draw(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``across_sight_width_by: widen`` raises each stretch below 1 to 1, in fit_mesh_shapes and in a set's own fit alike."""
    from zbuf_occlude.sensors.fit.class_placement import fit_mesh_shapes
    from zbuf_occlude.sensors import crops, lidar_preset

    meshes = [m for m in find_class_meshes(_mesh_root(tmp_path)) if m.class_name == "pole"]
    sensor = lidar_preset("hdl32e")
    sizes = {"pole": SizeRange("height", 3.0, 4.0)}
    narrow = {"distance_m": (5.0, 9.0), "across_sight_width_m": (0.05, 0.08)}  # narrower than every pole mesh
    widen = CropPlacement.from_keywords({"pole": {**narrow, "across_sight_width_by": "widen"}})
    stretched = fit_mesh_shapes(meshes, sensor, sizes, CropPlacement.from_keywords({"pole": narrow}))
    widened = fit_mesh_shapes(meshes, sensor, sizes, widen)
    assert all(v.width_scale[0] < 1.0 for v in stretched.values())
    assert all(v.width_scale == (1.0, 1.0) for v in widened.values())
    seen = []
    real = crops.lidar_object_samples

    def spy(mesh, sensor, **kw):
        seen.append(kw["distributions"].width_scale)
        return real(mesh, sensor, **kw)

    monkeypatch.setattr(crops, "lidar_object_samples", spy)
    build_set("lidar", meshes, ["pole"], 2, 32, 0, SetRecipe(sensor=sensor, sizes=sizes, placement=widen))
    assert seen and all(s == (1.0, 1.0) for s in seen)


# -- CropPlacement: class placements and mesh shapes in two typed tables, checked once -----------


def test_a_placement_keeps_classes_and_meshes_apart_and_checks_each_value_once() -> None:
    placement = CropPlacement.from_keywords({"pole": {"distance_m": [5, 9], "hidden_below_m": 0.2, "across_sight_width_m": (0.3, 0.5)}},
                                            {"pole/post": {"width_scale": (1.5, 2.0)}})  # fmt: skip
    pole = placement.per_class["pole"]
    assert pole == ClassPlacement(distance_m=(5.0, 9.0), hidden_below_m=(0.2, 0.2), across_sight_width_m=(0.3, 0.5))
    assert pole.crop_keywords == {"distance_m": (5.0, 9.0), "hidden_below_m": (0.2, 0.2)} and pole.shapes_meshes
    assert placement.per_mesh == {"pole/post": MeshShape(width_scale=(1.5, 2.0))} and "pole/post" not in placement.per_class
    assert placement.of_class("car") == ClassPlacement()  # a class not given: the published placement, its own shapes
    merged = placement.with_mesh_shapes({"pole/lamp": MeshShape(width_profile=(1.0, 2.0))})
    assert set(merged.per_mesh) == {"pole/post", "pole/lamp"} and set(placement.per_mesh) == {"pole/post"}
    with pytest.raises(AttributeError):
        pole.distance_m = (1.0, 2.0)  # frozen
    # each bad value refused where the placement is made, naming the class or mesh and the key
    for per_class, per_mesh, match in (
        ({"pole": {"across_sight_width_by": "squeeze"}}, None, r"class 'pole'.*across_sight_width_by"),
        ({"pole": {"distance_m": (9.0, 5.0)}}, None, r"class 'pole'.*distance_m"),
        ({"pole": {"across_sight_profile": (1.0,)}}, None, r"class 'pole'.*across_sight_profile"),
        ({"pole": {"width_scale": (1.0, 2.0)}}, None, r"class 'pole'.*unknown keys \['width_scale'\]"),
        ({}, {"pole/post": {"distance_m": (5.0, 9.0)}}, r"mesh 'pole/post'.*unknown keys \['distance_m'\]"),
        ({}, {"pole/post": {"width_scale": (-1.0, 2.0)}}, r"mesh 'pole/post'.*width_scale"),
    ):
        with pytest.raises(InvalidInputError, match=match):
            CropPlacement.from_keywords(per_class, per_mesh)
    with pytest.raises(TypeError, match="ClassPlacement"):  # a dict where a typed placement goes
        CropPlacement({"pole": {"distance_m": (5.0, 9.0)}})
    with pytest.raises(TypeError, match="CropPlacement"):
        SetRecipe(placement={"pole": {"distance_m": (5.0, 9.0)}})


def test_build_set_takes_its_settings_as_one_recipe() -> None:
    import inspect

    from zbuf_occlude.experiments.sim2real import data as sim2real_data

    for fn in (sim2real_data.build_set, sim2real_data.build_sets, sim2real_data.check_lidar_meshes):
        assert len(inspect.signature(fn).parameters) <= 12, fn.__name__
    assert SetRecipe().sizes is CLASS_SIZES_M and SetRecipe().placement is None


# -- Sim2RealConfig: checked once, and the identity settings.json holds ------------------------------


def test_every_run_chooses_its_best_epoch_by_the_validation_loss_unless_told_otherwise() -> None:
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig

    assert Sim2RealConfig("m", "r").train_config(0).select == "loss"
    assert Sim2RealConfig("m", "r", recipe="plain").train_config(0).select == "accuracy"
    told = Sim2RealConfig("m", "r", best_epoch_by="mean_class_accuracy")
    assert told.train_config(0).select == "mean_class_accuracy" and told.identity()["train_config"]["select"] == "mean_class_accuracy"
    assert Sim2RealConfig("m", "r").identity()["train_config"]["select"] == "loss"


def test_config_messages_name_the_fields_or_the_flags_given() -> None:
    from zbuf_occlude.cli.sim2real import OPTION_NAMES
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig

    cases = [({"validate_on": "fit-half"}, "validate_on fit-half needs fit_sensor", "--validate-on fit-half needs --fit-sensor"),
             ({"aspect": True, "keep_scale": True}, "aspect needs augmentation, which keep_scale", "--augment aspect needs augmentation, which --keep-scale"),
             ({"partial": True, "keep_scale": True}, "partial needs augmentation, which keep_scale", "--augment partial needs augmentation, which --keep-scale"),
             ({"partial": True, "aspect": True}, "aspect and partial are two augmentations", "--augment aspect and --augment partial are two"),
             ({"fitted_shape": ("outline",)}, "fitted_shape needs fit_sensor", "--fitted-shape needs --fit-sensor"),
             ({"occluded_elevation_deg": (10.0, 95.0)}, "occluded_elevation_deg must be", "--occluded-elevation must be"),
             ({"seeds": 0}, "seeds must be >= 1", "--seeds must be >= 1"),
             ({"best_epoch_by": "f1"}, "best_epoch_by must be one of", "--best-epoch-by must be one of"),
             ({"sensor": "kinect-v1"}, "sensor kinect-v1: the lidar training set needs", "--sensor kinect-v1: the lidar training set needs"),
             ({"sensor": "dales-q1560", "fit_sensor": True}, "fit_sensor fits a spinning LiDAR, but sensor dales-q1560",
              "--fit-sensor fits a spinning LiDAR, but --sensor dales-q1560")]  # fmt: skip
    for bad, field_words, flag_words in cases:
        with pytest.raises(InvalidInputError, match=field_words):
            Sim2RealConfig("m", "r", **bad)
        with pytest.raises(InvalidInputError, match=flag_words):
            Sim2RealConfig("m", "r", **bad, option_names=OPTION_NAMES)


def _recorded_settings() -> list[Path]:
    """The settings of the sim2real runs under docs/results, except those made with a sensor
    file that is not kept (``*-physics``): a config cannot name that sensor again."""
    paths = sorted((Path(__file__).resolve().parents[2] / "docs" / "results").glob("**/sim2real*/*/settings.json"))
    return [p for p in paths if not json.loads(p.read_text())["sensor"].endswith("-physics")]


RECORDED_SETTINGS = _recorded_settings()


def test_recorded_runs_are_found():
    assert len(RECORDED_SETTINGS) >= 2, RECORDED_SETTINGS  # not an empty parametrisation


@pytest.mark.parametrize("path", RECORDED_SETTINGS, ids=lambda p: "/".join(p.parts[-3:-1]))
def test_the_identity_of_a_config_is_what_recorded_runs_hold_so_they_resume(path: Path) -> None:
    from zbuf_occlude.experiments.sim2real.config import SIM2REAL_SCALES, Sim2RealConfig
    from zbuf_occlude.mesh.sizes import SizeRange

    s = json.loads(path.read_text())
    tc = s["train_config"]
    fit = s.get("fit_sensor") or {}
    config = Sim2RealConfig(
        s["mesh_root"], s["real"], model=s["model"], sensor=s["sensor"], scale=s["scale"], points=s["points"], epochs=tc["epochs"],
        per_class=s["scale_values"]["per_class"], seeds=s["seeds"], keep_scale=s["keep_scale"], label_map=s["label_map"], up=s["up"],
        up_map=s["up_map"], sizes={k: SizeRange(**v) for k, v in s["sizes_m"].items()}, min_returns=s.get("lidar_min_returns", 30),
        method=s["method"], occluded_elevation_deg=tuple(s["occluded_elevation_deg"]), fit_sensor=bool(fit),
        recipe="stable" if tc.get("balance") == "sampler" else "plain", best_epoch_by=tc.get("select", "accuracy"),
        validate_on=s.get("validate_on", "meshes"),
        fitted_shape=tuple(fit.get("fitted_shape", ())), aspect=tc.get("aspect", False), partial=tc.get("partial", False), sets=tuple(s.get("sets", ())),
        **({"fit_families": True, "family_count": s["fit_families"]["objects_per_class"]} if "fit_families" in s else {}),
    )  # fmt: skip
    identity = json.loads(json.dumps(config.identity(), default=float))  # as run_sim2real compares it
    if "fit_families" in s:  # the run adds what it fitted to what was asked for
        assert identity["fit_families"].items() <= s["fit_families"].items()
        identity["fit_families"] = s["fit_families"]
    assert SIM2REAL_SCALES[s["scale"]].per_class != s["scale_values"]["per_class"] or identity["scale_values"] == s["scale_values"]
    assert identity == {k: s[k] for k in identity if k in s}
    assert set(identity) <= set(s) or "lidar_min_returns" not in s  # a run from before the option lacks it
