"""The comparison engine (zbuf_occlude.experiments.compare) and the elevation profile (zbuf_occlude.profile)."""

from __future__ import annotations

import argparse
import csv
import math
import os
from pathlib import Path

import numpy as np
import pytest
import trimesh
from conftest import real_mesh

import zbuf_occlude as zo
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError, UnsafePathError
from zbuf_occlude.experiments import compare as cmp
from zbuf_occlude.experiments import elevation_profile as prof

#: A tiny real mesh: bathtub_0002 (664 faces) from ../shared, else the shipped sofa_0681 (224).
TINY = real_mesh("ModelNet40/bathtub/train/bathtub_0002.off", substitute="ModelNet10/sofa/test/sofa_0681.off")


def _tiny_path() -> Path:
    return TINY


def _gl_or_skip() -> None:
    try:
        mesh = trimesh.creation.box()
        zo.visible_mask(mesh, np.zeros((1, 3)) + 0.5, zo.camera_on_sphere(30, 30), "zbuffer", resolution=64)
    except BackendUnavailable as exc:
        pytest.skip(str(exc))


# -----------------------------------------------------------------------------------------
# Metrics
# -----------------------------------------------------------------------------------------
def test_chamfer_distance() -> None:
    a = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    assert cmp.chamfer_distance(a, a) == 0.0
    b = a + [0.0, 0.5, 0.0]
    assert cmp.chamfer_distance(a, b) == pytest.approx(0.5)
    assert cmp.chamfer_distance(np.zeros((0, 3)), np.zeros((0, 3))) == 0.0
    assert math.isnan(cmp.chamfer_distance(a, np.zeros((0, 3))))


def test_parsers() -> None:
    assert cmp.parse_int_list("1000,10k, 50K") == [1000, 10000, 50000]
    assert cmp.parse_methods("oracle, og32,oracle") == ["oracle", "og32"]
    with pytest.raises(InvalidInputError):
        cmp.parse_methods("oracle,no-such-method")
    with pytest.raises(InvalidInputError):
        cmp.parse_int_list("10,abc")
    with pytest.raises(InvalidInputError):
        cmp.parse_int_list("0")


# -----------------------------------------------------------------------------------------
# End to end on a tiny input
# -----------------------------------------------------------------------------------------
@pytest.mark.slow
def test_compare_end_to_end_on_tiny_input(tmp_path: Path) -> None:
    _gl_or_skip()
    path = _tiny_path()
    out = tmp_path / "cmp"
    config = cmp.CompareConfig(
        "zbuffer,oracle,paper-exact,paper-pruned,paper-vertex,og32,og64,naive-zbuffer",
        "200,400",
        "30:45,-40:200",
        256,
        0,
        resolution_sweep="128,256",
        grid_sweep="16,32",
        memory=True,
    )
    report = cmp.run_compare([path, tmp_path / "missing.off"], out, config, progress=False)
    assert report == out / "report.md"
    for name in ("results.csv", "report.md", "time_vs_points.png", "agreement_vs_resolution.png", "agreement_vs_grid.png"):
        assert (out / name).is_file(), name
    rows = cmp.read_csv(out / "results.csv")
    ok = [r for r in rows if not r["error"]]
    # 2 counts × 2 views × 8 methods, plus sweeps at 200 points: 2 views × (2 res × 2 z-buffer methods + 2 grids).
    assert len(ok) == 2 * 2 * 8 + 2 * (4 + 2)
    exact = [r for r in ok if r["method"] in ("paper-exact", "zbuffer", "oracle", "paper-pruned") and not r["sweep"]]
    assert all(r["accuracy"] == 1.0 and r["chamfer"] == 0.0 for r in exact)
    failures = [r for r in rows if r["error"]]
    assert [r["mesh"] for r in failures] == ["missing"]  # reported, not fatal
    text = report.read_text()
    assert "| paper-exact |" in text and "missing" in text and "agreement_vs_grid.png" in text
    assert any(r["peak_mib"] != "" for r in ok)


def test_failing_method_is_reported_not_fatal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = _tiny_path()

    def boom(*args, **kwargs):
        raise RuntimeError("kaboom")

    from zbuf_occlude.visibility import registry

    monkeypatch.setitem(registry._METHODS, "paper-vertex", boom)
    rows = cmp.compare([path], cmp.CompareConfig(["oracle", "paper-vertex", "og32"], [300], "10:20", 128, 0), progress=False)
    by_method = {r["method"]: r for r in rows}
    assert "kaboom" in by_method["paper-vertex"]["error"]
    assert by_method["og32"]["error"] == "" and by_method["og32"]["accuracy"] > 0.8


def test_method_budget_skips_larger_counts(tmp_path: Path) -> None:
    path = _tiny_path()
    config = cmp.CompareConfig(["oracle", "paper-exact"], [100, 200], "10:20", 128, 0, method_budget_s=0.0)
    rows = cmp.compare([path], config, progress=False)
    exact = {r["n_points"]: r for r in rows if r["method"] == "paper-exact"}
    assert exact[100]["error"] == ""
    assert exact[200]["error"].startswith("skipped")


def _cells(table: str, mesh: str) -> list[str]:
    [line] = [row for row in table.splitlines() if row.startswith(f"| {mesh} ")]
    return [c.strip() for c in line.strip("|").split("|")]


def test_tables_1a_1b_hold_the_measured_values() -> None:
    path = _tiny_path()
    config = cmp.CompareConfig(["oracle", "paper-exact", "paper-pruned", "og32", "og64"], [300], "20:30,-10:200", 128, 0)
    rows = cmp.compare([path], config, progress=False)
    by = {m: [r for r in rows if r["method"] == m] for m in ("paper-exact", "paper-pruned", "og32", "og64")}
    mean = {m: {k: np.mean([r[k] for r in rs]) for k in ("time_s", "accuracy", "false_hidden_rate")} for m, rs in by.items()}
    n_faces = len(zo.load_mesh(path).faces)
    cells = _cells(cmp.table_1a(rows), path.stem)
    # mesh (faces) | points | views | exact (s) | pruned (s) | reduction | paper | accuracy | false hidden
    assert cells[0] == f"{path.stem} ({n_faces})" and cells[1] == "300" and cells[2] == "2"
    exact_s, pruned_s = float(cells[3]), float(cells[4])
    assert exact_s == pytest.approx(mean["paper-exact"]["time_s"], rel=5e-3)  # printed with 3 significant digits
    assert pruned_s == pytest.approx(mean["paper-pruned"]["time_s"], rel=5e-3)  # printed with 3 significant digits
    reduction = 100.0 * (1.0 - mean["paper-pruned"]["time_s"] / mean["paper-exact"]["time_s"])
    assert float(cells[5].rstrip(" %")) == pytest.approx(reduction, abs=0.051)
    assert float(cells[7]) == pytest.approx(mean["paper-pruned"]["accuracy"], abs=5e-5)
    assert float(cells[8]) == pytest.approx(mean["paper-pruned"]["false_hidden_rate"], abs=5e-5)
    cells = _cells(cmp.table_1b(rows, methods=("og32", "og64")), path.stem)
    for cell, method in zip(cells[4:6], ("og32", "og64")):
        seconds, red, acc = (c.strip() for c in cell.split("/"))
        assert float(seconds) == pytest.approx(mean[method]["time_s"], rel=5e-3)  # printed with 3 significant digits
        expected = 100.0 * (1.0 - mean[method]["time_s"] / mean["paper-exact"]["time_s"])
        assert float(red.rstrip(" %")) == pytest.approx(expected, abs=0.051)
        assert float(acc) == pytest.approx(mean[method]["accuracy"], abs=5e-5)


def test_cli_main_runs_compare_and_elevation_profile(tmp_path: Path) -> None:
    from zbuf_occlude.cli.main import main

    path = _tiny_path()
    assert main(["compare", str(path), "--methods", "oracle,og32", "--dense-points", "120", "--views", "0:0,45:90",
                 "--resolution", "96", "--out", str(tmp_path / "c"), "--no-progress"]) == 0  # fmt: skip
    with open(tmp_path / "c" / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["method"] for r in rows} == {"oracle", "og32"} and all(r["error"] == "" for r in rows)
    by_method = {r["method"]: r for r in rows}
    assert float(by_method["oracle"]["accuracy"]) == 1.0 and 0.8 < float(by_method["og32"]["accuracy"]) <= 1.0
    assert main(["elevation-profile", str(path), "--method", "oracle", "--dense-points", "400", "--elevations=-90,90",
                 "--azimuths", "2", "--out", str(tmp_path / "p"), "--no-progress"]) == 0  # fmt: skip
    with open(tmp_path / "p" / "elevation_profile.csv") as fh:
        assert [float(r["elevation_deg"]) for r in csv.DictReader(fh)] == [-90.0, 90.0]
    # a bad option value is a usage error (2), not a traceback
    assert main(["compare", str(path), "--methods", "oracle,no-such-method", "--out", str(tmp_path / "x"), "--no-progress"]) == 2


def test_cli_compare_handler_runs(tmp_path: Path) -> None:
    path = _tiny_path()
    parser = argparse.ArgumentParser()
    from zbuf_occlude.cli.compare import add_compare_parser

    add_compare_parser(parser.add_subparsers())
    args = parser.parse_args(
        [
            "compare", str(path), "--methods", "oracle,og32", "--dense-points", "150", "--views", "0:0",
            "--resolution", "128", "--out", str(tmp_path / "o"), "--no-progress",
        ]
    )  # fmt: skip
    assert args.func(args) == 0
    with open(tmp_path / "o" / "results.csv") as fh:
        assert len(list(csv.DictReader(fh))) == 2


@pytest.mark.parametrize(
    "argv, flag",
    [(["--methods", "oracle,no-such-method"], "--methods"), (["--reference", "no-such-method"], "--reference"),
     (["--methods", " , "], "--methods")],
)  # fmt: skip
def test_a_bad_method_is_refused_naming_its_flag_before_anything_is_written(tmp_path: Path, capsys, argv, flag) -> None:
    from zbuf_occlude.cli.main import main

    out = tmp_path / "out"
    assert main(["compare", str(_tiny_path()), *argv, "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error:") and "\n" not in err and flag in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    "field, value",
    [("methods", "oracle,nope"), ("reference", "nope"), ("points", ""), ("points", "10,abc"), ("resolution", 0),
     ("resolution", 2.5), ("resolution_sweep", "0"), ("grid_sweep", [-4]), ("sweep_points", 0), ("seed", -1),
     ("views", "nope"), ("views", [(1.0,)]), ("radius", 0.0), ("radius", float("inf")), ("method_budget_s", -1.0)],
)  # fmt: skip
def test_the_config_is_checked_when_made_naming_the_field_or_its_option(field, value) -> None:
    with pytest.raises(InvalidInputError, match=field):
        cmp.CompareConfig(**{field: value})
    with pytest.raises(InvalidInputError, match="--the-flag"):
        cmp.CompareConfig(**{field: value}, option_names={field: "--the-flag"})


def test_the_config_holds_its_values_parsed() -> None:
    config = cmp.CompareConfig("oracle, og32,oracle", "1000,2k", "10:20,30:40", 128.0, 3, resolution_sweep="64",
                               method_options={"og32": {"grid": 32}})  # fmt: skip
    assert config.methods == ("oracle", "og32") and config.points == (1000, 2000) and config.resolution == 128
    assert config.poses == ((10.0, 20.0), (30.0, 40.0)) and config.resolution_sweep == (64,) and config.grid_sweep == ()
    assert config.sweeps == ["resolution"] and config.seed == 3 and config.method_options == {"og32": {"grid": 32}}
    assert cmp.CompareConfig(views=[(10, 20)]).poses == ((10.0, 20.0),)


def test_compare_and_run_compare_take_a_config_not_a_keyword_list() -> None:
    import inspect

    for fn in (cmp.compare, cmp.run_compare):
        assert len(inspect.signature(fn).parameters) <= 12, fn
        assert len(inspect.getsource(fn).splitlines()) < 150, fn


# -----------------------------------------------------------------------------------------
# Fig. 12
# -----------------------------------------------------------------------------------------
def test_projected_areas_of_a_cube_seen_from_above() -> None:
    cube = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    points, fi = zo.sample_surface(cube, count=20000, seed=0)
    camera = zo.camera_on_sphere(90.0, 0.0)
    visible = zo.visible_mask(cube, points, camera, "oracle", face_index=fi)
    areas = prof.projected_areas(cube, fi, visible)
    # Only the top face (area 1, normal +z) is visible from straight above, at this distance.
    assert areas["xy"] == pytest.approx(1.0, rel=0.03)
    assert areas["yz"] == pytest.approx(0.0, abs=1e-9)
    assert areas["xz"] == pytest.approx(0.0, abs=1e-9)


def test_elevation_profile_writes_png_and_csv(tmp_path: Path) -> None:
    path = _tiny_path()
    png = prof.elevation_profile(
        path, tmp_path / "fig12", method="oracle", points=1500, elevations=(-90, 0, 90), azimuths=2, progress=False
    )
    assert png == tmp_path / "fig12" / "elevation_profile.png"
    assert png.is_file() and png.with_suffix(".csv").is_file()
    with open(png.with_suffix(".csv")) as fh:
        rows = list(csv.DictReader(fh))
    assert [float(r["elevation_deg"]) for r in rows] == [-90.0, 0.0, 90.0]
    assert all(0.0 < float(r["area_visible"]) < float(r["surface_area"]) for r in rows)


# -----------------------------------------------------------------------------------------
# results.csv read back through zbuf_occlude.io
# -----------------------------------------------------------------------------------------
_ROW = {"mesh": "m", "n_faces": 12, "n_points": 200, "view": 0, "elevation_deg": 30.0, "azimuth_deg": 45.0,
        "method": "zbuffer", "sweep": "", "param": "", "time_s": 0.25, "accuracy": 1.0, "error": ""}  # fmt: skip


def test_results_read_back_as_written(tmp_path: Path) -> None:
    cmp.write_csv([_ROW, {**_ROW, "sweep": "resolution", "param": 64, "accuracy": float("nan")}], tmp_path / "results.csv")
    rows = cmp.read_csv(tmp_path / "results.csv", within=tmp_path)
    assert rows[0]["n_points"] == 200 and rows[0]["time_s"] == 0.25 and rows[0]["param"] == "" and rows[0]["peak_mib"] == ""
    assert rows[1]["param"] == 64 and math.isnan(rows[1]["accuracy"])


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
def test_a_results_csv_that_is_a_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "results.csv")
    with pytest.raises(InvalidInputError, match=r"results\.csv: is a FIFO"):
        cmp.read_csv(tmp_path / "results.csv")


def test_a_results_csv_linked_out_of_its_folder_is_refused(tmp_path: Path) -> None:
    cmp.write_csv([_ROW], tmp_path / "elsewhere.csv")
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "results.csv").symlink_to(tmp_path / "elsewhere.csv")
    with pytest.raises(UnsafePathError, match=r"results\.csv leads outside"):
        cmp.read_csv(tmp_path / "run" / "results.csv", within=tmp_path / "run")


@pytest.mark.parametrize("value", ["many", "inf"])
def test_a_results_csv_with_a_word_for_a_count_is_one_line(tmp_path: Path, value: str) -> None:
    with open(tmp_path / "results.csv", "w", newline="", encoding="utf-8") as fh:
        csv.writer(fh).writerows([["mesh", "n_points"], ["m", value]])
    with pytest.raises(InvalidInputError, match=r"results\.csv: not a results table of ours"):
        cmp.read_csv(tmp_path / "results.csv")
