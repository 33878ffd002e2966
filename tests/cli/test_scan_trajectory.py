"""``scan SCENE --trajectory CSV``: the sensor sweeps while it moves along the trajectory, sample after sample; the
option is refused where it cannot apply, and a hostile trajectory file is one line naming it."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.sensors.scan_data import read_scan_npz

SCENE = str(Path(__file__).resolve().parents[2] / "data" / "scenes" / "street.json")


def _trajectory(tmp_path: Path, speed: float = 10.0) -> Path:
    path = tmp_path / "drive.csv"
    path.write_text(f"time_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n100,-5,0,1.8,0,0,0\n101,{-5 + speed},0,1.8,0,0,0\n")
    return path


def _run(argv: list[str], capsys) -> tuple[int, str]:
    code = cli_main(argv)
    return code, capsys.readouterr().err.strip()


def test_each_sample_sweeps_further_along_the_trajectory(tmp_path: Path, capsys) -> None:
    code, err = _run(["scan", SCENE, "--trajectory", str(_trajectory(tmp_path)), "--samples", "2", "--frame", "world",
                      "--no-progress", "--out", str(tmp_path / "o")], capsys)  # fmt: skip
    assert code == 0, err
    scans = [read_scan_npz(f) for f in sorted((tmp_path / "o").glob("*.npz"))]
    assert len(scans) == 2
    for k, s in enumerate(scans):  # the HDL-32E's revolution is 0.1 s: sample k sweeps [100 + 0.1 k, 100 + 0.1 (k + 1)]
        assert 100.0 + 0.1 * k - 1e-9 <= s.gps_time.min() and s.gps_time.max() <= 100.0 + 0.1 * (k + 1) + 1e-9
    # the car 10 m ahead is seen from 1 m further on in the second sweep: the same pulse meets it at another range
    car = [s.object_id == 1 for s in scans]
    assert all(c.sum() > 100 for c in car)
    assert abs(np.median(scans[0].range_m[car[0]]) - np.median(scans[1].range_m[car[1]]) - 1.0) < 0.3


def test_the_raw_sweep_is_in_each_pulse_sensor_frame(tmp_path: Path, capsys) -> None:
    out = {}
    for frame in ("sensor", "world"):
        code, err = _run(["scan", SCENE, "--trajectory", str(_trajectory(tmp_path)), "--frame", frame, "--no-progress",
                          "--out", str(tmp_path / frame)], capsys)  # fmt: skip
        assert code == 0, err
        out[frame] = read_scan_npz(next((tmp_path / frame).glob("*.npz")))
    raw, world = out["sensor"], out["world"]
    moved = raw.points.astype(np.float64) + np.c_[-5.0 + 10.0 * (raw.gps_time - 100.0), np.zeros(len(raw)), np.full(len(raw), 1.8)]
    assert np.abs(moved - world.points).max() < 2e-3  # the sensor turned no way: each point is its pulse's origin plus it


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--sensor", "riegl-q1560"], "flies its own plan"),
        (["--sensor", "kinect-v1"], "takes one pose"),
    ],
)
def test_a_trajectory_is_refused_where_it_cannot_apply(tmp_path: Path, capsys, argv: list[str], words: str) -> None:
    code, err = _run(["scan", SCENE, "--trajectory", str(_trajectory(tmp_path)), *argv, "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and words in err and "\n" not in err, err
    mesh = str(Path(__file__).resolve().parents[2] / "data" / "samples" / "chair" / "train" / "chair_0001.off")
    code, err = _run(["scan", mesh, "--trajectory", str(_trajectory(tmp_path)), "--out", str(tmp_path / "m")], capsys)
    assert code == 2 and "give a scene file" in err, err


@pytest.mark.parametrize(
    "write",
    [
        lambda p: p.write_text("time_s,x_m\n0,1\n"),  # another header
        lambda p: p.write_text("time_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n1,0,0,0,0,0,0\n0,0,0,0,0,0,0\n"),  # time goes back
        lambda p: p.write_text("time_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,nan,0,0,0,0,0\n1,0,0,0,0,0,0\n"),
        lambda p: os.mkfifo(p),
        lambda p: p.mkdir(),
        lambda p: p.write_bytes(b"\xff\xfe" * 100),
    ],
)
def test_a_hostile_trajectory_is_one_line_naming_the_file(tmp_path: Path, capsys, write) -> None:
    path = tmp_path / "bad.csv"
    write(path)
    code, err = _run(["scan", SCENE, "--trajectory", str(path), "--no-progress", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "\n" not in err and "Traceback" not in err and str(path) in err, err


def test_more_sweeps_than_the_trajectory_lasts_are_refused_before_any_is_written(tmp_path: Path, capsys) -> None:
    code, err = _run(["scan", SCENE, "--trajectory", str(_trajectory(tmp_path)), "--samples", "11", "--no-progress",
                      "--out", str(tmp_path / "o")], capsys)  # fmt: skip
    assert code == 2 and "lasts 1 s, and --samples 11 sweeps of hdl32e take 1.1 s" in err, err
    assert not (tmp_path / "o").exists()


def test_fit_sensor_class_codes_must_be_ascii_digits(tmp_path: Path, capsys) -> None:
    code, err = _run(
        ["fit-sensor", str(tmp_path), "--sensor", "riegl-q1560", "--classes", "5,²", "--out", str(tmp_path / "f.json")], capsys
    )
    assert code == 2 and "--classes must be ASPRS class codes" in err and "Traceback" not in err, err


def test_a_moving_scan_written_as_las_needs_the_world_frame(tmp_path: Path, capsys) -> None:
    argv = ["scan", SCENE, "--trajectory", str(_trajectory(tmp_path)), "--format", "las", "--no-progress"]
    code, err = _run([*argv, "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "give --frame world" in err, err
    code, err = _run([*argv, "--frame", "world", "--out", str(tmp_path / "w")], capsys)
    assert code == 0, err


def test_a_refused_trajectory_leaves_a_foreign_file_in_out_alone(tmp_path: Path, capsys) -> None:
    out = tmp_path / "o"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    for extra in (["--samples", "11"], ["--format", "las"]):  # too short for the sweeps; LAS in the sensor frame
        code, err = _run(["scan", SCENE, "--trajectory", str(_trajectory(tmp_path)), *extra, "--no-progress", "--out", str(out)], capsys)
        assert code == 2, err
        assert sorted(p.name for p in out.iterdir()) == ["notes.txt"] and (out / "notes.txt").read_text() == "mine"


def test_a_moving_scan_written_as_las_writes_its_sweep_s_trajectory_beside_it(tmp_path: Path, capsys) -> None:
    """As an airborne flight's: ``<stem>_trajectory.csv`` on the LAS clock (``--gps-start`` added), read back by
    ``load_trajectory``; the sensor of every return's pulse lies on it."""
    import laspy

    from zbuf_occlude.sensors.platform import load_trajectory

    out = tmp_path / "o"
    code, err = _run(["scan", SCENE, "--trajectory", str(_trajectory(tmp_path)), "--samples", "2", "--frame", "world",
                      "--format", "las", "--gps-start", "1000", "--no-progress", "--out", str(out)], capsys)  # fmt: skip
    assert code == 0, err
    written = sorted(out.glob("*_trajectory.csv"))
    assert [p.name.replace("_trajectory.csv", "") for p in written] == [p.stem for p in sorted(out.glob("*.las"))]
    for k, path in enumerate(written):
        flown = load_trajectory(path)
        las = laspy.read(path.with_name(path.name.replace("_trajectory.csv", ".las")))
        t = np.asarray(las.gps_time)
        assert flown.start_s <= t.min() + 1e-6 and t.max() <= flown.end_s + 1e-6  # the sweep's own part, on the LAS clock
        assert 1100.0 + 0.1 * k - 1e-6 <= t.min()
        x = flown.poses_at(t)[1][:, 0]  # positions; the car drives along +x at 10 m/s from x = -5 at t = 1100
        np.testing.assert_allclose(x, -5.0 + 10.0 * (t - 1100.0), atol=1e-6)
    assert sorted(p.name for p in tmp_path.glob("*.csv")) == ["drive.csv"]  # nothing written beside the input
