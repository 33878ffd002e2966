"""``experiment sim2real``'s occluded-points set: the occluded set's clouds with visibility decided from the points alone."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest
import trimesh

pytest.importorskip("torch")

from zbuf_occlude.cli.main import main  # noqa: E402
from zbuf_occlude.errors import InvalidInputError  # noqa: E402
from zbuf_occlude.experiments.sim2real import data as sim2real_data  # noqa: E402
from zbuf_occlude.experiments.sim2real.data import OCCLUDED_POINTS, TRAINING_SETS, SetRecipe, build_set, build_sets
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes

NAMES = ["car", "pole"]
RECIPE = SetRecipe(resolution=128, dense_points=1500)


def _mesh_root(tmp_path: Path) -> Path:
    """Two classes of two procedural meshes each: long low boxes and poles (one with an arm)."""
    root = tmp_path / "meshes"
    (root / "car").mkdir(parents=True)
    (root / "pole").mkdir(parents=True)
    trimesh.creation.box(extents=(4.5, 1.8, 1.5)).export(root / "car" / "sedan.obj")
    trimesh.creation.box(extents=(3.8, 1.7, 1.4)).export(root / "car" / "hatch.obj")
    trimesh.creation.cylinder(radius=0.08, height=4.0, sections=12).export(root / "pole" / "post.obj")
    lamp = trimesh.util.concatenate([trimesh.creation.cylinder(radius=0.1, height=6.0, sections=12),
                                     trimesh.creation.box(extents=(1.0, 0.2, 0.2), transform=trimesh.transformations.translation_matrix([0.4, 0, 3.0]))])  # fmt: skip
    lamp.export(root / "pole" / "lamp.obj")
    return root


def _spy_poses(monkeypatch: pytest.MonkeyPatch) -> list[dict]:
    """Record every pose the occluded sets draw: the mesh, the pose, the options, the mask and the cloud."""
    from zbuf_occlude import pipeline

    calls: list[dict] = []
    real = pipeline.occlude_object

    def spy(mesh, poses, **kw):
        for pose_index, visible, clouds in real(mesh, poses, **kw):
            calls.append({"mesh": mesh, "pose": poses[pose_index], "options": kw, "visible": visible.copy(), "clouds": clouds})
            yield pose_index, visible, clouds

    monkeypatch.setattr(pipeline, "occlude_object", spy)
    return calls


def _raw(monkeypatch: pytest.MonkeyPatch) -> None:
    """Keep the clouds as drawn (no normalisation), to compare them with the dense samples."""
    monkeypatch.setattr(sim2real_data, "_finish", lambda clouds, sizes_m, keep_scale, rng: np.stack(clouds).astype(np.float32))


def _rows_of(cloud: np.ndarray, points: np.ndarray) -> bool:
    """Every row of ``cloud`` is a row of ``points`` (bytes of float32)."""
    have = {row.tobytes() for row in np.ascontiguousarray(points, np.float32)}
    return all(row.tobytes() in have for row in np.ascontiguousarray(cloud, np.float32))


@pytest.mark.slow
def test_occluded_points_clouds_are_subsets_of_the_occluded_sets_dense_samples_seen_by_the_point_splats(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:  # fmt: skip
    from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS, camera_on_sphere
    from zbuf_occlude.geometry.samples import object_key
    from zbuf_occlude.pipeline import dense_cloud
    from zbuf_occlude.visibility.point_splats import point_surfels

    meshes = find_class_meshes(_mesh_root(tmp_path))
    calls = _spy_poses(monkeypatch)
    _raw(monkeypatch)
    mesh_set = build_set("occluded", meshes, NAMES, 4, 48, 3, RECIPE)
    mesh_calls, calls[:] = list(calls), []
    point_set = build_set(OCCLUDED_POINTS, meshes, NAMES, 4, 48, 3, RECIPE)
    # the same meshes, poses and counts, in the same order; only the visibility differs
    assert [(id(c["mesh"]), c["pose"]) for c in calls] == [(id(c["mesh"]), c["pose"]) for c in mesh_calls]
    assert np.array_equal(point_set.labels, mesh_set.labels) and np.array_equal(point_set.object_index, mesh_set.object_index)
    assert {c["options"]["method"] for c in calls} == {"point-splat"} and {c["options"]["draws"].topped_up for c in calls} == {False}
    assert {c["options"]["method"] for c in mesh_calls} == {RECIPE.method}
    assert {c["options"]["draws"].topped_up for c in mesh_calls} == {True}
    assert np.array_equal(point_set.points, np.stack([c["clouds"][0].points for c in calls if c["clouds"]]))
    by_mesh = {id(m.mesh): m for m in meshes}
    for points_call, mesh_call in zip(calls, mesh_calls):
        entry = by_mesh[id(points_call["mesh"])]
        dense = dense_cloud(entry.mesh, object_key(entry.name), seed=3, count=RECIPE.dense_points)
        assert points_call["options"]["dense"].points is mesh_call["options"]["dense"].points or np.array_equal(
            points_call["options"]["dense"].points, dense.points)  # fmt: skip
        # the mask is the point splats' answer from the points alone, no normals
        camera = camera_on_sphere(*points_call["pose"], DEFAULT_RADIUS, resolution=RECIPE.resolution)
        assert np.array_equal(points_call["visible"], point_surfels(dense.points).visible(camera))
        assert 0 < points_call["visible"].sum() < len(dense.points)
        # both clouds are subsets of the same complete (dense) cloud, each of what its method sees
        assert _rows_of(points_call["clouds"][0].points, dense.points[points_call["visible"]])
        assert mesh_call["clouds"][0].n_topped_up == 0 and _rows_of(mesh_call["clouds"][0].points, dense.points[mesh_call["visible"]])


@pytest.mark.slow
def test_occluded_points_is_deterministic_for_a_seed_and_leaves_the_other_sets_as_they_were(tmp_path: Path) -> None:
    meshes = find_class_meshes(_mesh_root(tmp_path))
    one = build_set(OCCLUDED_POINTS, meshes, NAMES, 3, 32, 5, RECIPE)
    assert one.points.shape == (6, 32, 3) and np.bincount(one.labels).tolist() == [3, 3]
    np.testing.assert_allclose((one.points.max(axis=1) - one.points.min(axis=1)).max(axis=1), 1.0, atol=1e-5)  # normalised
    assert build_set(OCCLUDED_POINTS, meshes, NAMES, 3, 32, 5, RECIPE).points.tobytes() == one.points.tobytes()
    assert build_set(OCCLUDED_POINTS, meshes, NAMES, 3, 32, 6, RECIPE).points.tobytes() != one.points.tobytes()
    # made only when asked for, in report order after the four sets, and the others come out the same with it
    every = build_sets(meshes, NAMES, 3, 32, 5, RECIPE, kinds=["complete", "occluded", OCCLUDED_POINTS])
    assert list(every) == ["complete", "occluded", OCCLUDED_POINTS]
    assert every[OCCLUDED_POINTS].points.tobytes() == one.points.tobytes()
    alone = build_sets(meshes, NAMES, 3, 32, 5, RECIPE, kinds=["complete", "occluded"])
    assert all(alone[k].points.tobytes() == every[k].points.tobytes() for k in alone)
    assert OCCLUDED_POINTS not in build_sets(meshes, NAMES, 1, 16, 5, SetRecipe(resolution=64, dense_points=300),
                                             kinds=["complete", "occluded"])  # fmt: skip
    assert OCCLUDED_POINTS not in TRAINING_SETS  # not in a run unless asked for


def test_a_pose_that_shows_too_few_points_repeats_them_and_says_so(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    meshes = [m for m in find_class_meshes(_mesh_root(tmp_path)) if m.name in ("car/sedan", "pole/post")]
    with caplog.at_level(logging.WARNING, logger=sim2real_data.__name__):
        s = build_set(OCCLUDED_POINTS, meshes, NAMES, 1, 256, 0, SetRecipe(resolution=64, dense_points=300))
    assert s.points.shape == (2, 256, 3)  # 300 dense points: no view shows 256 of them
    assert all(len(np.unique(c, axis=0)) < 256 for c in s.points)
    assert "points alone; the cloud repeats points" in caplog.text and "car/sedan" in caplog.text


def test_build_set_names_the_occluded_points_set_among_those_it_makes() -> None:
    with pytest.raises(InvalidInputError, match="occluded-points"):
        build_set("points", [], NAMES, 1, 8, 0)


def test_occluded_points_with_a_point_method_or_an_unknown_one_is_refused_naming_the_flags() -> None:
    from zbuf_occlude.cli.sim2real import OPTION_NAMES
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig

    with pytest.raises(InvalidInputError, match="occluded_points compares point-splat .* method point-splat is point-splat already"):
        Sim2RealConfig("m", "r", occluded_points=True, method="point-splat")
    with pytest.raises(InvalidInputError, match="--occluded-points compares point-splat .* --method point-splat"):
        Sim2RealConfig("m", "r", occluded_points=True, method="point-splat", option_names=OPTION_NAMES)
    with pytest.raises(InvalidInputError, match="^--method: unknown visibility method 'zbufer'"):
        Sim2RealConfig("m", "r", occluded_points=True, method="zbufer", option_names=OPTION_NAMES)
    Sim2RealConfig("m", "r", method="point-splat")  # the occluded set from points, without the comparison: allowed


def test_the_identity_holds_the_occluded_points_set_only_when_it_is_made() -> None:
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig

    plain, with_points = Sim2RealConfig("m", "r").identity(), Sim2RealConfig("m", "r", occluded_points=True).identity()
    assert "occluded_points" not in plain  # the runs made without it resume
    assert with_points.pop("occluded_points") == {"set": OCCLUDED_POINTS, "method": "point-splat", "normals": "estimated",
                                                  "topped_up": False}  # fmt: skip
    assert with_points == plain


def test_summary_and_table_compare_occluded_points_with_occluded() -> None:
    from zbuf_occlude.experiments.sim2real.report import summarise
    from zbuf_occlude.experiments.sim2real.report import table_md

    def run(kind: str, seed: int, score: float) -> dict:
        return {"train_set": kind, "seed": seed, "mean_class_accuracy": score, "overall_accuracy": score}

    runs = [run(kind, s, base + 0.01 * s) for s in range(3)
            for kind, base in (("complete", 0.5), ("occluded", 0.7), (OCCLUDED_POINTS, 0.8), ("real→real", 0.9))]  # fmt: skip
    rows = {r["train_set"]: r for r in summarise(runs, NAMES)}
    assert list(rows) == ["complete", "occluded", OCCLUDED_POINTS, "real→real", "chance"]
    points = rows[OCCLUDED_POINTS]
    assert points["diff_vs_occluded"] == pytest.approx(0.1) and points["diff_vs_complete"] == pytest.approx(0.3)
    assert points["p_vs_occluded"] == pytest.approx(1 / 20) and points["p_occluded_above"] == pytest.approx(1.0)  # C(6, 3) splits
    assert "diff_vs_occluded" not in rows["occluded"]
    table = table_md(list(rows.values()), {"classes": NAMES, "model": "voxnet", "points": 32, "scale": "quick", "sensor": "hdl32e",
                                           "keep_scale": False})  # fmt: skip
    assert "occluded-points vs occluded (visibility from the points alone vs from the mesh): Δ +0.100" in table
    assert "one-sided p 0.05 (occluded-points above occluded), 1 (occluded above occluded-points)" in table


def test_the_occluded_points_flag_reaches_the_config_and_its_refusal_exits_2(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                              capsys: pytest.CaptureFixture) -> None:  # fmt: skip
    from zbuf_occlude.experiments import sim2real

    configs = []

    def run_sim2real(config, out, **kw):
        configs.append(config)
        raise InvalidInputError("stopped before any work")

    monkeypatch.setattr(sim2real, "run_sim2real", run_sim2real)
    argv = ["experiment", "sim2real", str(tmp_path), "--real", str(tmp_path), "--out", str(tmp_path / "o")]
    assert main(argv) == 2 and main([*argv, "--occluded-points"]) == 2
    assert [c.occluded_points for c in configs] == [False, True]
    capsys.readouterr()
    assert main([*argv, "--occluded-points", "--method", "point-splat"]) == 2 and len(configs) == 2
    err = capsys.readouterr().err
    assert "--occluded-points compares point-splat" in err and "--method point-splat" in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_a_run_with_occluded_points_trains_scores_and_reports_it(tmp_path: Path) -> None:
    root, real, out = _mesh_root(tmp_path), tmp_path / "real", tmp_path / "out"
    rng = np.random.default_rng(0)
    for cls, shape in (
        ("Car", trimesh.creation.box(extents=(4.2, 1.7, 1.5))),
        ("Trunk", trimesh.creation.cylinder(radius=0.15, height=3.0)),
    ):
        (real / cls).mkdir(parents=True)
        for i in range(4):
            pts, _ = trimesh.sample.sample_surface(shape, 300, seed=int(rng.integers(1000)))
            np.savetxt(real / cls / f"{i}.xyz", pts[pts[:, 0] <= np.quantile(pts[:, 0], 0.6)] + [20.0 + i, 0.0, 0.0])
    argv = ["experiment", "sim2real", str(root), "--real", str(real), "--out", str(out), "--label-map", "Trunk=pole",
            "--points", "32", "--epochs", "1", "--per-class", "4", "--seeds", "1", "--threads", "1", "--no-progress",
            "--occluded-points"]  # fmt: skip
    assert main(argv) == 0
    runs = [json.loads(line) for line in (out / "runs.jsonl").read_text().splitlines()]
    assert [r["train_set"] for r in runs] == [*TRAINING_SETS, OCCLUDED_POINTS, "real→real"]
    assert (out / "confusion_occluded-points.csv").is_file() and (out / f"checkpoints/{OCCLUDED_POINTS}/seed0").is_dir()
    assert json.loads((out / "settings.json").read_text())["occluded_points"]["method"] == "point-splat"
    assert "occluded-points vs occluded" in (out / "table.md").read_text()
    assert main(argv[:-1]) == 2  # the same folder without the set: another run's settings
