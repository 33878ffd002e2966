"""``scan --ray-table FILE``: a table of directions as the sensor; each point at its row's time, exactly, in
NPZ and LAS; one sensor per scan (``--ray-table`` with ``--sensor`` is a usage error naming both), and a
hostile table is one line naming the file."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.io.ray_tables import ray_table_bytes
from zbuf_occlude.sensors.patterns.ray_table import rosette_table
from zbuf_occlude.sensors.scan_data import GPS_START_S, read_scan_npz


def _table(tmp_path: Path, suffix: str = ".csv", *, n: int = 4000) -> tuple[Path, np.ndarray]:
    table = rosette_table(n, duration_s=0.04)
    time_s = table.time_s + 1.6e9  # GPS-like seconds
    path = tmp_path / f"avia{suffix}"
    path.write_bytes(ray_table_bytes(time_s, table.azimuth_deg, table.elevation_deg, suffix=suffix))
    return path, time_s


def _run(argv: list[str], capsys) -> tuple[int, str]:
    code = cli_main(argv)
    return code, capsys.readouterr().err.strip()


@pytest.mark.parametrize("suffix", [".csv", ".npy"])
def test_a_mesh_scanned_by_a_ray_table_carries_each_rows_time(tmp_path: Path, capsys, suffix: str) -> None:
    path, time_s = _table(tmp_path, suffix)
    code, err = _run(["scan", "box", "--ray-table", str(path), "--distance", "6", "--no-progress", "--out", str(tmp_path / "o")], capsys)
    assert code == 0, err
    (npz,) = (tmp_path / "o").glob("box_avia_s000.npz")
    s = read_scan_npz(npz)
    assert len(s) > 100 and s.sensor == "avia" and s.ring is None
    assert s.gps_time.tobytes() == time_s[s.pulse_id].tobytes()  # bit for bit


def test_a_scene_scanned_by_a_ray_table_writes_las_with_the_times(tmp_path: Path, capsys) -> None:
    laspy = pytest.importorskip("laspy")
    path, time_s = _table(tmp_path)
    scene = tmp_path / "scene.json"
    scene.write_text(
        json.dumps({"ground": {"half_extent_m": 20.0}, "objects": [{"mesh": {"box_m": [1.0, 3.0, 3.0]}, "position_m": [8.0, 0.0]}]})
    )
    code, err = _run(
        ["scan", str(scene), "--ray-table", str(path), "--format", "las", "--no-progress", "--out", str(tmp_path / "o")], capsys
    )
    assert code == 0, err
    las = laspy.read(tmp_path / "o" / "scene_avia_s000.las")
    assert len(las.points) > 100
    # LAS stores GPS time as float64: every point's time is one of the table's after the start, exactly
    assert np.isin(np.asarray(las.gps_time), GPS_START_S + time_s).all()


@pytest.mark.parametrize("sensor", ["vlp16", "hdl32e", "kinect-v1"])
def test_a_ray_table_and_a_sensor_are_a_usage_error_naming_both(tmp_path: Path, capsys, sensor: str) -> None:
    path, _ = _table(tmp_path, n=10)
    code, err = _run(["scan", "box", "--ray-table", str(path), "--sensor", sensor, "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "\n" not in err, err
    assert f"--ray-table {path} is the sensor: give --ray-table or --sensor {sensor}, not both" in err
    assert not (tmp_path / "o").exists()


def test_return_physics_options_change_a_ray_tables_beam(tmp_path: Path, capsys) -> None:
    path, _ = _table(tmp_path, n=10)
    code, err = _run(["scan", "box", "--ray-table", str(path), "--footprint", "--divergence", "0.5", "--max-returns", "3",
                      "--range-resolution", "0.5", "--out", str(tmp_path / "o")], capsys)  # fmt: skip
    assert code == 0, err  # accepted (what the options do to a table's beam: test_beam_options)
    # a table file's beam is a generic receiver (ranges 1-100 m, 0.02 m noise, as --help says) without a divergence: no
    # footprint until --divergence gives it one
    code, err = _run(["scan", "box", "--ray-table", str(path), "--footprint", "--out", str(tmp_path / "p")], capsys)
    assert code == 2 and "\n" not in err, err
    assert f"--footprint samples the beam's divergence cone, and {path}'s beam (generic-905) has no divergence" in err


@pytest.mark.parametrize(
    "text, match",
    [
        ("time_s,azimuth_deg,elevation_deg\n1,0,0\n0,0,0\n", "time_s must not decrease"),
        ("time_s,azimuth_deg,elevation_deg\n0,nan,0\n", r"azimuth_deg\[0\] must be a finite number"),
        ("t,a,e\n0,0,0\n", "must be the header time_s,azimuth_deg,elevation_deg"),
        ("time_s,azimuth_deg,elevation_deg\n", "has no rows"),
    ],
)
def test_a_hostile_table_is_one_line_naming_the_file(tmp_path: Path, capsys, text: str, match: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    code, err = _run(["scan", "box", "--ray-table", str(path), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert str(path) in err and re.search(match, err), err
    assert not (tmp_path / "o").exists()


def test_without_either_the_default_sensor_scans(tmp_path: Path, capsys) -> None:
    code, err = _run(["scan", "box", "--no-progress", "--out", str(tmp_path / "o")], capsys)
    assert code == 0, err
    assert (tmp_path / "o" / "box_hdl32e_s000.npz").is_file()


def test_a_ray_table_is_a_sensor_by_its_file_name_too(tmp_path: Path, capsys) -> None:
    path, _ = _table(tmp_path)
    base = ["scan", "box", "--distance", "6", "--no-progress"]
    assert _run([*base, "--ray-table", str(path), "--out", str(tmp_path / "a")], capsys)[0] == 0
    assert _run([*base, "--sensor", str(path), "--out", str(tmp_path / "b")], capsys)[0] == 0
    same = (tmp_path / "a" / "box_avia_s000.npz").read_bytes() == (tmp_path / "b" / "box_avia_s000.npz").read_bytes()
    assert same  # one reader: the sensor's name


def test_a_ray_table_option_takes_a_ray_table_file_only(tmp_path: Path, capsys) -> None:
    spec = tmp_path / "lidar.json"
    spec.write_text('{"preset": "vlp16"}')
    code, err = _run(["scan", "box", "--ray-table", str(spec), "--no-progress", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "--ray-table must be a .csv or .npy file" in err and err.count("\n") == 0, err
