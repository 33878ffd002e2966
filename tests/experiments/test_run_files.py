"""The experiments read their runs' files through zbuf_occlude.io: regular files, inside the run's folder.

``combine_elevation`` reads each run's ``run.json``, ``results.csv`` and Fig. 12's cached curve;
the elevation run reads the curve cached in its data folder and the farm's list of meshes an
earlier version wrote; sim2real resumes from its ``runs.jsonl``; the CLI prints ``table.md``.  A
FIFO is refused at once (it would block the reader), a link out of the folder the file was named
from is refused, and a file that is not ours is one line naming it.
"""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import pytest

pytest.importorskip("matplotlib")

from zbuf_occlude.cli.sim2real import print_table
from zbuf_occlude.errors import InvalidInputError, UnsafePathError
from zbuf_occlude.experiments.table3 import common, elevation
from zbuf_occlude.experiments.table3.config import SCALES
from zbuf_occlude.io.owned import LEDGER_FILE

needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
CURVE = [{"elevation_deg": float(e), "area_xy": 0.5, "area_yz": 0.25, "area_xz": 0.125} for e in (-90, 0, 90)]


def _write_csv(path: Path, rows: list[dict]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _run(root: Path, model: str, *, curve: bool = True) -> Path:
    """The files of an ``experiment elevation`` run that ``combine_elevation`` reads."""
    run = root / model
    (run / "data").mkdir(parents=True)
    (run / "run.json").write_text(json.dumps({"model": model, "overall_accuracy": 0.5, "mean_class_accuracy": 0.5}))
    _write_csv(run / "results.csv", [{"model": model, "elevation_deg": e, "n_test": 4, "accuracy": 0.5, "paper_accuracy": 0.6}
                                     for e in (-80.0, 0.0, 80.0)])  # fmt: skip
    if curve:
        _write_csv(run / "data" / "visible_area.csv", CURVE)
    return run


def test_combine_reads_every_run_and_the_first_curve(tmp_path: Path) -> None:
    runs = [_run(tmp_path, "pointnet"), _run(tmp_path, "voxnet", curve=False)]
    out = elevation.combine_elevation(runs, tmp_path / "out")
    with open(out / "results.csv", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["model"] for r in rows] == ["pointnet"] * 3 + ["voxnet"] * 3 and float(rows[1]["accuracy"]) == 0.5
    assert "| pointnet (ours) |" in (out / "table.md").read_text() and (out / "accuracy_vs_elevation.png").read_bytes()[:4] == b"\x89PNG"


@needs_fifo
@pytest.mark.parametrize("name", ["results.csv", "run.json", "data/visible_area.csv"])
def test_combine_refuses_a_runs_file_that_is_a_fifo_without_blocking(tmp_path: Path, name: str) -> None:
    run = _run(tmp_path, "pointnet")
    (run / name).unlink()
    os.mkfifo(run / name)
    with pytest.raises(InvalidInputError, match=rf"{name}: is a FIFO; only regular files are read"):
        elevation.combine_elevation([run], tmp_path / "out")
    assert not (tmp_path / "out" / "results.csv").exists()


@pytest.mark.parametrize("name", ["results.csv", "run.json", "data/visible_area.csv"])
def test_combine_refuses_a_runs_file_linked_out_of_the_run(tmp_path: Path, name: str) -> None:
    run, other = _run(tmp_path, "pointnet"), _run(tmp_path / "elsewhere", "voxnet")
    (run / name).unlink()
    (run / name).symlink_to(other / name)
    with pytest.raises(UnsafePathError, match=rf"{name} leads outside"):
        elevation.combine_elevation([run], tmp_path / "out")


def test_combine_reads_the_curve_of_a_data_folder_the_run_names(tmp_path: Path, monkeypatch) -> None:
    run = _run(tmp_path, "pointnet", curve=False)
    shared = tmp_path / "shared-data"
    shared.mkdir()
    _write_csv(shared / "visible_area.csv", CURVE)
    (run / "run.json").write_text(json.dumps({"model": "pointnet", "data_dir": str(shared)}))
    seen = []
    real = elevation.plot_elevation
    monkeypatch.setattr(elevation, "plot_elevation", lambda rows, curve: seen.append(curve) or real(rows, curve))
    elevation.combine_elevation([run], tmp_path / "out")
    assert seen == [CURVE]


def test_combine_does_not_read_a_curve_from_the_current_folder(tmp_path: Path, monkeypatch) -> None:
    """A run.json without ``data_dir`` named ``./visible_area.csv``, wherever the command ran."""
    run = _run(tmp_path, "pointnet", curve=False)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    (cwd / "visible_area.csv").write_text("elevation_deg\nnot a number\n")
    monkeypatch.chdir(cwd)
    elevation.combine_elevation([run], tmp_path / "out")  # the stray file is not read: no error


@pytest.mark.parametrize(
    "damage, message",
    [(lambda run: (run / "run.json").write_text("[1, 2]"), r"run\.json is not the run\.json of an elevation run"),
     (lambda run: (run / "results.csv").write_text("model,accuracy\npointnet,high\n"), r"results\.csv: not a table of ours"),
     (lambda run: (run / "results.csv").write_text("model,accuracy\npointnet\n"), r"results\.csv: not a table of ours"),
     (lambda run: (run / "results.csv").write_bytes(b"model,accuracy\n\xff\n"), r"results\.csv: not UTF-8")],
    ids=["run.json", "word", "short-row", "not-utf8"],
)  # fmt: skip
def test_combine_names_a_file_that_is_not_ours_in_one_line(tmp_path: Path, damage, message: str) -> None:
    run = _run(tmp_path, "pointnet")
    damage(run)
    with pytest.raises(InvalidInputError, match=message):
        elevation.combine_elevation([run], tmp_path / "out")


def test_the_cached_curve_is_read_back_and_a_link_out_of_the_data_folder_refused(tmp_path: Path) -> None:
    data = tmp_path / "data"
    data.mkdir()
    _write_csv(data / "visible_area.csv", CURVE)
    assert elevation._visible_area_curve([], data, SCALES["quick"], "zbuffer", False) == CURVE
    (data / "visible_area.csv").unlink()
    _write_csv(tmp_path / "elsewhere.csv", CURVE)
    (data / "visible_area.csv").symlink_to(tmp_path / "elsewhere.csv")
    with pytest.raises(UnsafePathError, match=r"visible_area\.csv leads outside"):
        elevation._visible_area_curve([], data, SCALES["quick"], "zbuffer", False)


@needs_fifo
def test_a_cached_curve_that_is_a_fifo_is_refused_not_skipped(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "visible_area.csv")
    with pytest.raises(InvalidInputError, match=r"visible_area\.csv: is a FIFO"):
        elevation._visible_area_curve([], tmp_path, SCALES["quick"], "zbuffer", False)


def test_a_mesh_list_an_earlier_version_wrote_is_adopted_only_when_it_holds_this_runs_meshes(tmp_path: Path) -> None:
    (tmp_path / "meshes.txt").write_text("a.off chair train\n")
    common.write_mesh_list(tmp_path, "a.off chair train\n")  # the same list: taken as ours, rewritten
    assert "meshes.txt" in (tmp_path / LEDGER_FILE).read_text()
    other = tmp_path / "other"
    other.mkdir()
    (other / "meshes.txt").write_text("b.off chair train\n")
    with pytest.raises(UnsafePathError, match=r"meshes\.txt was not recorded by a run of ours"):
        common.write_mesh_list(other, "a.off chair train\n")
    assert (other / "meshes.txt").read_text() == "b.off chair train\n"


# -- sim2real's runs.jsonl, the CLI's table.md --------------------------------------------------
def _load_runs(path: Path) -> dict:
    pytest.importorskip("torch")
    from zbuf_occlude.experiments.sim2real.outputs import load_runs as load

    return load(path)


def test_the_runs_of_runs_jsonl_are_read_back_by_set_and_seed(tmp_path: Path) -> None:
    runs = [{"train_set": "complete", "seed": 0, "overall_accuracy": 0.5}, {"train_set": "lidar", "seed": 1}]
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(r) + "\n" for r in runs) + "\n")
    assert _load_runs(tmp_path / "runs.jsonl") == {("complete", 0): runs[0], ("lidar", 1): runs[1]}
    assert _load_runs(tmp_path / "missing.jsonl") == {}


@needs_fifo
def test_a_runs_jsonl_that_is_a_fifo_is_refused_not_skipped(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "runs.jsonl")
    with pytest.raises(InvalidInputError, match=r"runs\.jsonl: is a FIFO"):
        _load_runs(tmp_path / "runs.jsonl")


def test_a_runs_jsonl_linked_out_of_the_output_folder_is_refused(tmp_path: Path) -> None:
    (tmp_path / "elsewhere.jsonl").write_text(json.dumps({"train_set": "complete", "seed": 0}) + "\n")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "runs.jsonl").symlink_to(tmp_path / "elsewhere.jsonl")
    with pytest.raises(UnsafePathError, match=r"runs\.jsonl leads outside"):
        _load_runs(tmp_path / "out" / "runs.jsonl")


@pytest.mark.parametrize("line", ["[1, 2]", '{"train_set": "complete"}', '{"train_set": ["a"], "seed": 0}'])
def test_a_line_of_runs_jsonl_that_is_not_a_run_names_the_file_and_line(tmp_path: Path, line: str) -> None:
    (tmp_path / "runs.jsonl").write_text(json.dumps({"train_set": "complete", "seed": 0}) + "\n" + line + "\n")
    with pytest.raises(InvalidInputError, match=r"runs\.jsonl: line 2 is not a run of ours"):
        _load_runs(tmp_path / "runs.jsonl")


def test_the_table_printed_is_read_inside_the_output_folder(tmp_path: Path, capsys) -> None:
    (tmp_path / "table.md").write_text("| a |\n")
    assert print_table(str(tmp_path), {"wall_s": {"total": 3.0}}) == 0
    assert capsys.readouterr().out == f"{tmp_path}/table.md\n| a |\nwall time 3 s\n"
    (tmp_path / "table.md").unlink()
    (tmp_path / "elsewhere.md").write_text("not the run's\n")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "table.md").symlink_to(tmp_path / "elsewhere.md")
    with pytest.raises(UnsafePathError, match=r"table\.md leads outside"):
        print_table(str(tmp_path / "out"), {"wall_s": {"total": 3.0}})
