"""The families fitted to real crops (``experiment sim2real --fit-families``) and ``--sets``."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.sim2real.families import _simulated, crop_shapes, families_of, family_meshes, fit_families
from zbuf_occlude.mesh.families.fitted import parse_families_fit
from zbuf_occlude.mesh.sizes import CLASS_SIZES_M
from zbuf_occlude.sensors.kinds import sensor_from_name

HDL32E = sensor_from_name("hdl32e")


def _family_crops(family: str, width: float, seed: int, objects: int = 6, crops: int = 3) -> list[np.ndarray]:
    """Crops of ``family`` stretched by ``width``, scanned as the lidar set scans them: stand-ins for real crops."""
    from zbuf_occlude.mesh.families import FAMILIES

    return _simulated(family, CLASS_SIZES_M[FAMILIES[family].class_name], HDL32E, (width, width), objects=objects, crops=crops, seed=seed)


def test_the_statistics_are_of_proportions_not_of_size_or_place() -> None:
    rng = np.random.default_rng(0)
    crops = [rng.uniform([-0.5, -0.2, 0.0], [0.5, 0.2, 2.0], (200, 3)) for _ in range(6)]
    moved = [3.0 * c + [10.0, -4.0, 1.0] for c in crops]  # another unit, another place
    a, b = crop_shapes(crops), crop_shapes(moved)
    assert a["crops"] == b["crops"] == 6
    assert a["height_to_width"] == pytest.approx(b["height_to_width"]) and a["height_shares"] == pytest.approx(b["height_shares"])
    assert a["height_to_width"][1] == pytest.approx(2.0, rel=0.05)  # 2 m tall, 1 m along its longer horizontal axis
    assert crop_shapes([np.zeros((1, 3))])["crops"] == 0  # a crop of one point has no proportions
    assert a["plan_elongation"] == pytest.approx(b["plan_elongation"]) and a["plan_elongation"][1] == pytest.approx(2.5, rel=0.1)
    line = np.column_stack([np.linspace(0.0, 1.0, 50), np.zeros(50), np.linspace(0.0, 2.0, 50)])  # a footprint of no breadth
    assert crop_shapes([*crops, line])["plan_elongation"] == pytest.approx(a["plan_elongation"], rel=0.2)  # left out, not NaN


@pytest.mark.parametrize(("family", "stretch"), [("shrub", 1.6), ("pedestrian", 1.4)])
def test_the_fit_recovers_the_stretch_of_crops_made_with_a_known_one(family: str, stretch: float) -> None:
    cls = {"shrub": "bush", "pedestrian": "pedestrian"}[family]
    real = {cls: _family_crops(family, stretch, seed=1)}  # other objects than the fit draws (seed 0)
    fit = fit_families(real, HDL32E, CLASS_SIZES_M, objects=6, crops=3, iterations=3, seed=0)
    assert family in families_of(cls)
    (lo, hi) = fit.classes[cls][family].width_scale
    assert stretch / 1.25 <= np.sqrt(lo * hi) <= stretch * 1.25, (lo, hi)
    tried = fit.record["classes"][cls]["tried"][family]
    assert tried["steps"][0]["width_scale"] == [1.0, 1.0]  # the first range tried is the family as drawn
    assert tried["distance"] == min(s["distance"] for s in tried["steps"])  # the nearest range tried is kept
    assert tried["distance"] < tried["steps"][0]["distance"]  # and it is nearer than no stretch
    # the record is the file: it reads back as the same fit
    assert parse_families_fit(json.loads(json.dumps(fit.record))).classes == fit.classes


def test_the_fit_chooses_the_family_the_crops_came_from_and_leaves_classes_without_one() -> None:
    real = {"pole": _family_crops("sign_post", 1.0, seed=3, objects=4, crops=3), "car": [np.random.default_rng(0).random((50, 3))] * 6}
    fit = fit_families(real, HDL32E, CLASS_SIZES_M, objects=4, crops=3, iterations=1, seed=0)
    assert set(fit.classes) == {"pole"}  # no family writes cars
    tried = fit.record["classes"]["pole"]["tried"]
    assert set(tried) == set(families_of("pole")) == {"trunk", "utility_pole", "street_light", "sign_post"}
    nearest = min((t["distance"], name) for name, t in tried.items() if t["distance"] is not None)
    assert nearest[1] == "sign_post" and next(iter(fit.classes["pole"])) == "sign_post"  # the nearest first
    assert fit.record["classes"]["pole"]["chosen_distance"] <= nearest[0]  # a family joins only to come nearer
    assert sum(c.share for c in fit.classes["pole"].values()) == pytest.approx(1.0)


def test_a_class_of_two_kinds_of_crops_takes_both_families_and_one_kind_the_one() -> None:
    """Real poles that are half sign posts and half trunks: the fit takes both families, the union's crops nearer than
    either's; real poles that are sign posts alone: sign posts alone (no family joins that moves the crops away)."""
    posts, trunks = (_family_crops(f, 1.0, seed=3, objects=4, crops=3) for f in ("sign_post", "trunk"))
    mixed = fit_families({"pole": posts + trunks}, HDL32E, CLASS_SIZES_M, objects=4, crops=3, iterations=1, seed=0)
    entry = mixed.record["classes"]["pole"]
    assert set(mixed.classes["pole"]) == {"sign_post", "trunk"}
    assert entry["chosen_distance"] < min(entry["tried"][f]["distance"] for f in ("sign_post", "trunk"))
    assert [c.share for c in mixed.classes["pole"].values()] == [0.5, 0.5]
    alone = fit_families({"pole": posts}, HDL32E, CLASS_SIZES_M, objects=4, crops=3, iterations=1, seed=0)
    assert set(alone.classes["pole"]) == {"sign_post"}


def _entries(family: str, width: float, seed: int, objects: int) -> list:
    """Objects of ``family`` stretched by ``width`` as MeshEntry (the user's meshes of its class, for the fit)."""
    from zbuf_occlude.mesh.inputs.class_folders import MeshEntry
    from zbuf_occlude.mesh.families.fitted import draw_object
    from zbuf_occlude.mesh.families.registry import FAMILIES
    from zbuf_occlude.mesh.load import normalize_mesh

    fam = FAMILIES[family]
    return [MeshEntry(None, fam.class_name, f"mine/{family}_{k}", normalize_mesh(draw_object(fam, seed, k, (width, width))[1]))
            for k in range(objects)]  # fmt: skip


def test_a_class_whose_meshes_come_nearer_the_real_crops_than_every_family_keeps_them_alone() -> None:
    """The real crops are the fit's own scans of the user's meshes (other shrubs than the fit draws): no family can
    come nearer, so none is added."""
    from zbuf_occlude.experiments.sim2real import families as fam

    mine = _entries("shrub", 1.6, seed=1, objects=4)
    clouds = fam._scanned(mine, CLASS_SIZES_M["bush"], HDL32E, crops=3, seed=0)
    fit = fit_families({"bush": clouds}, HDL32E, CLASS_SIZES_M, objects=4, crops=3, iterations=1, seed=0, meshes={"bush": mine})
    assert fit.classes == {} and fit.counts(8) == {} and family_meshes(fit, 8, seed=0) == []
    kept = fit.record["meshes_kept"]["bush"]
    assert kept["meshes"]["distance"] == pytest.approx(0.0, abs=1e-12) and kept["meshes"]["objects"] == 4
    assert all(t["distance"] > 0 for t in kept["tried"].values())
    assert parse_families_fit(json.loads(json.dumps(fit.record))).classes == {}  # the record reads back: nothing chosen


def test_a_family_nearer_than_the_meshes_is_chosen_and_the_meshes_distance_recorded() -> None:
    """Tall boxes as the only meshes of the bush class are far from shrub crops; the shrubs are chosen."""
    from zbuf_occlude.mesh.inputs.class_folders import MeshEntry
    from zbuf_occlude.mesh.load import normalize_mesh

    boxes = [MeshEntry(None, "bush", f"mine/box_{k}", normalize_mesh(trimesh.creation.box(extents=(0.5, 0.4 + 0.1 * k, 2.0))))
             for k in range(3)]  # fmt: skip
    real = {"bush": _family_crops("shrub", 1.6, seed=1, objects=4, crops=3)}
    fit = fit_families(real, HDL32E, CLASS_SIZES_M, objects=4, crops=3, iterations=1, seed=0, meshes={"bush": boxes})
    entry = fit.record["classes"]["bush"]
    assert set(fit.classes["bush"]) == {"shrub"} and fit.record["meshes_kept"] == {}
    assert entry["tried"]["shrub"]["distance"] < entry["meshes"]["distance"]


def test_a_fit_is_the_same_every_run_and_its_objects_are_those_the_families_command_writes(tmp_path: Path) -> None:
    from zbuf_occlude.cli.main import main

    real = {"bush": _family_crops("shrub", 1.3, seed=2, objects=3, crops=2)}
    a = fit_families(real, HDL32E, CLASS_SIZES_M, objects=3, crops=2, iterations=1, seed=5)
    b = fit_families(real, HDL32E, CLASS_SIZES_M, objects=3, crops=2, iterations=1, seed=5)
    assert json.dumps(a.record) == json.dumps(b.record)
    meshes = family_meshes(a, 3, seed=5)
    assert [m.name for m in meshes] == ["families/bush/shrub_0", "families/bush/shrub_1", "families/bush/shrub_2"]
    assert {m.class_name for m in meshes} == {"bush"}
    (tmp_path / "fit.json").write_text(json.dumps(a.record))
    assert (
        main(["families", "shrub", "--fit", str(tmp_path / "fit.json"), "--count", "3", "--seed", "5", "--out", str(tmp_path / "o")]) == 0
    )
    from zbuf_occlude.mesh.load import load_mesh

    for m, k in zip(meshes, range(3)):
        again = load_mesh(tmp_path / "o" / "bush" / f"shrub_{k}.ply")
        assert np.array_equal(again.vertices, m.mesh.vertices) and np.array_equal(again.faces, m.mesh.faces)


@pytest.mark.parametrize("bad", [{"objects": 0}, {"crops": -1}, {"iterations": 0}, {"objects": True}, {"crops": 2.5}])
def test_bad_fit_sizes_are_refused_naming_them(bad: dict) -> None:
    with pytest.raises(InvalidInputError, match=next(iter(bad))):
        fit_families({"bush": []}, HDL32E, CLASS_SIZES_M, **bad)


def test_no_class_to_fit_is_refused_naming_the_classes_families_write() -> None:
    few = {"bush": [np.random.default_rng(0).random((40, 3))] * 4, "car": [np.random.default_rng(1).random((40, 3))] * 9}
    with pytest.raises(InvalidInputError, match="bush.*pole"):
        fit_families(few, HDL32E, CLASS_SIZES_M, objects=1, crops=1, iterations=1)


# --- the config and the command line


def test_sets_are_checked_against_what_the_settings_make_and_kept_in_report_order() -> None:
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig

    c = Sim2RealConfig("m", "r", sets=("pooled", "lidar"), fit_sensor=True)
    assert c.sets == ("lidar", "pooled") and c.training_sets == ("lidar", "pooled")
    assert c.identity()["sets"] == ["lidar", "pooled"]
    assert "sets" not in Sim2RealConfig("m", "r").identity()  # runs without it keep their settings (they resume)
    assert Sim2RealConfig("m", "r").training_sets == ("complete", "occluded", "lidar", "lidar+complete")
    with pytest.raises(InvalidInputError, match="pooled"):
        Sim2RealConfig("m", "r", sets=("pooled",))  # the fitted sets need the fit
    with pytest.raises(InvalidInputError, match="--sets.*'lidr'"):
        Sim2RealConfig("m", "r", sets=("lidr",), option_names={"sets": "--sets"})


@pytest.mark.parametrize("count", [0, 10**9, True, 2.0])
def test_a_family_count_out_of_range_is_refused(count) -> None:
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig

    with pytest.raises(InvalidInputError, match="family_count"):
        Sim2RealConfig("m", "r", fit_families=True, family_count=count)


def test_fit_families_is_in_the_identity_only_when_asked_for() -> None:
    from zbuf_occlude.experiments.sim2real.config import FAMILIES_SEED, Sim2RealConfig

    assert "fit_families" not in Sim2RealConfig("m", "r").identity()
    assert Sim2RealConfig("m", "r", fit_families=True, family_count=5).identity()["fit_families"] == {
        "objects_per_class": 5, "seed": FAMILIES_SEED}  # fmt: skip


@pytest.mark.parametrize(
    "extra, says",
    [
        (["--family-count", "3"], "--family-count 3"),
        (["--sets", "lidar,nope"], "'nope'"),
        (["--family-count", "0"], "--family-count"),
        (["--sets", " , "], "--sets must name"),
        (["--fit-family-heights"], "--fit-family-heights fits the heights of the classes the families write to: it needs --fit-families"),
    ],
)
def test_bad_family_and_set_options_exit_2_naming_the_value(tmp_path: Path, extra: list, says: str, capsys) -> None:
    from zbuf_occlude.cli.main import main

    try:
        status = main(["experiment", "sim2real", str(tmp_path), "--real", str(tmp_path), "--out", str(tmp_path / "o"), *extra])
    except SystemExit as exc:
        status = exc.code
    assert status == 2 and says in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


# --- a run end to end


def _scene(tmp_path: Path) -> tuple[Path, Path]:
    """Meshes (two cars, two round bushes) and real crops: 16 scans of each class, the bushes wide shrubs seen by the HDL-32E."""
    meshes, real = tmp_path / "meshes", tmp_path / "real"
    for cls in ("car", "bush"):
        (meshes / cls).mkdir(parents=True)
    trimesh.creation.box(extents=(4.5, 1.8, 1.5)).export(meshes / "car" / "sedan.obj")
    trimesh.creation.box(extents=(3.9, 1.7, 1.4)).export(meshes / "car" / "hatch.obj")
    trimesh.creation.icosphere(subdivisions=2, radius=1.0).export(meshes / "bush" / "ball.obj")
    trimesh.creation.icosphere(subdivisions=1, radius=0.7).export(meshes / "bush" / "small.obj")
    rng = np.random.default_rng(0)
    box = trimesh.creation.box(extents=(4.2, 1.7, 1.5))
    bushes = _family_crops("shrub", 1.5, seed=7, objects=4, crops=4)
    for cls, clouds in (("Car", [trimesh.sample.sample_surface(box, 300, seed=i)[0] for i in range(16)]), ("Bush", bushes[:16])):
        (real / cls).mkdir(parents=True)
        for i, pts in enumerate(clouds):
            np.savetxt(real / cls / f"{i}.xyz", pts * (1 if cls == "Car" else 2.0) + [15.0 + rng.random(), 0.0, 0.0])
    return meshes, real


def test_a_run_with_fitted_families_adds_their_objects_records_the_fit_and_trains_only_the_sets_named(tmp_path: Path) -> None:
    pytest.importorskip("torch")
    from zbuf_occlude.cli.main import main

    meshes, real = _scene(tmp_path)
    out = tmp_path / "out"
    argv = ["experiment", "sim2real", str(meshes), "--real", str(real), "--out", str(out), "--points", "32",
            "--epochs", "1", "--per-class", "6", "--seeds", "1", "--threads", "1", "--no-progress", "--fit-families", "--family-count", "3",
            "--sets", "lidar"]  # fmt: skip
    assert main(argv) == 0
    fit = json.loads((out / "fitted_families.json").read_text())
    first_half = sum(r["half"] == "train" for r in csv.DictReader(open(out / "real_split.csv", encoding="utf-8")))
    assert set(fit["classes"]) == {"bush"} and fit["fitted_on"].endswith(f": {first_half} scans")  # the first half only
    assert fit["classes"]["bush"]["real"]["crops"] == first_half // 2  # its bushes, not the scored half's
    settings = json.loads((out / "settings.json").read_text())
    assert settings["sets"] == ["lidar"]
    assert settings["fit_families"]["chosen"] == {"bush": fit["classes"]["bush"]["chosen"]}
    assert settings["fit_families"]["objects"] == {"shrub": 3} and settings["meshes"] == {"bush": 5, "car": 2}
    with open(out / "results.csv", encoding="utf-8") as fh:
        assert sorted(r["train_set"] for r in csv.DictReader(fh)) == ["lidar", "real→real"]


# --- the classes' heights from the first half


def _standing(tops: list[float], ground: float = -1.8, seed: int = 0) -> list[np.ndarray]:
    """Crops in a sensor's frame (z up, the ground ``ground`` below it): a column of returns from the ground to each top."""
    rng = np.random.default_rng(seed)
    return [np.column_stack([10 + rng.random(50), rng.random(50), np.linspace(ground, ground + top, 50)]) for top in tops]


def test_family_heights_are_the_crops_heights_above_the_ground_for_the_families_classes() -> None:
    from zbuf_occlude.experiments.sim2real.families import MIN_FIT_CROPS, family_heights
    from zbuf_occlude.mesh.sizes import SizeRange

    poles, bushes = [2.0, 2.5, 3.0, 3.5, 4.0, 4.5], [1.0, 1.2, 1.4, 1.6, 1.8]
    heights = family_heights({"pole": _standing(poles), "bush": _standing(bushes, seed=1), "car": _standing([1.5] * 6, seed=2),
                              "pedestrian": _standing([1.7] * (MIN_FIT_CROPS - 1), seed=3)})  # fmt: skip
    assert set(heights) == {"pole", "bush"}  # cars: no family; too few pedestrians to fit
    assert heights["pole"] == SizeRange("height", *(float(v) for v in np.percentile(poles, [10, 90])))
    assert heights["bush"] == SizeRange("height", *(float(v) for v in np.percentile(bushes, [10, 90])))
    lifted = family_heights({"pole": _standing(poles, ground=-3.0), "bush": _standing(bushes, ground=-3.0, seed=1)})
    assert lifted["pole"].lo_m == pytest.approx(heights["pole"].lo_m)  # measured from the ground, wherever the sensor stands


def test_family_heights_need_the_families_and_are_in_the_identity() -> None:
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig

    with pytest.raises(InvalidInputError, match="^--fit-family-heights fits the heights .* it needs --fit-families"):
        Sim2RealConfig("m", "r", family_heights=True, option_names={"family_heights": "--fit-family-heights",
                                                                   "fit_families": "--fit-families"})  # fmt: skip
    block = Sim2RealConfig("m", "r", fit_families=True, family_heights=True).identity()["fit_families"]
    assert block["heights"] == "the first half's object heights"
    assert "heights" not in Sim2RealConfig("m", "r", fit_families=True).identity()["fit_families"]


def test_a_run_at_the_family_heights_sizes_the_families_classes_from_the_first_half_alone(tmp_path: Path) -> None:
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig
    from zbuf_occlude.experiments.sim2real.families import family_heights
    from zbuf_occlude.experiments.sim2real.run import prepare_sets
    from zbuf_occlude.real_scans.datasets import load_real_scans

    meshes, real = _scene(tmp_path)
    config = Sim2RealConfig(meshes, real, points=32, family_count=2, fit_families=True, family_heights=True)
    sets = prepare_sets(config)
    scans = {Path(s.source).name + s.label: s for s in load_real_scans(real)}
    first = {c: [scans[Path(sets.sources[i]).name + c.title()].points_sensor_m for i in sets.half_a if sets.real_labels[i] == k]
             for k, c in enumerate(sets.names)}  # fmt: skip
    assert sets.sizes(config.sizes)["bush"] == family_heights(first)["bush"] != config.sizes["bush"]  # the scored half is not used
    assert sets.sizes(config.sizes)["car"] == config.sizes["car"]  # no family writes to cars
    assert {m.class_name for m in sets.meshes} == {"bush", "car"} and sets.families_fit is not None
