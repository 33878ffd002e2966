"""``scan``'s several-returns options: ``--max-returns N`` and ``--range-resolution M`` checked as usage
errors (exit 2, one line naming the value), applied to the sensor as ``--footprint`` is; ``--echo-separation``
with a sensor file whose footprint has K > 1 sub-rays (not only 7)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.sensors.patterns.spinning import Lidar
from zbuf_occlude.sensors.kinds import sensor_to_json, with_beam


def _write_json(path: Path, spec: dict) -> Path:
    path.write_text(json.dumps(spec))
    return path


def _pole_before_a_wall(tmp_path: Path) -> Path:
    """A pole 6 cm thick 8 m ahead of the sensor, a wall 4 m behind it: footprints straddling the pole see both."""
    return _write_json(tmp_path / "pole_wall.json", {
        "ground": {"half_extent_m": 20.0},
        "objects": [{"mesh": {"cylinder": {"radius_m": 0.03, "height_m": 3.0}}, "position_m": [8.0, 0.0]},
                    {"mesh": {"box_m": [0.2, 6.0, 3.0]}, "position_m": [12.0, 0.0]}],
    })  # fmt: skip


def _wide_beam_sensor(tmp_path: Path, **changes) -> Path:
    """A VLP-16 with a 1° beam (a 14 cm footprint at 8 m), as a sensor file."""
    return _write_json(tmp_path / "wide.json", sensor_to_json(with_beam(Lidar.preset("vlp16"), divergence_deg=1.0, **changes)))


def _run(argv: list[str], capsys) -> tuple[int, str]:
    code = cli_main(argv)
    return code, capsys.readouterr().err.strip()


@pytest.mark.parametrize(
    "options, message",
    [
        (["--max-returns", "0"], r"--max-returns must be an integer >= 1, got '?0'?"),
        (["--max-returns", "16"], r"--max-returns must be at most 15 .*got '?16'?"),
        (["--max-returns", "2.5"], r"--max-returns must be a whole number, got '?2\.5'?"),
        (["--range-resolution", "0"], r"--range-resolution must be .*> 0.*metres, got '?0'?"),
        (["--range-resolution", "nan"], r"--range-resolution must be a finite number of metres, got '?nan'?"),
        (["--range-resolution", "-0.5"], r"--range-resolution must be .*got '?-0\.5'?"),
        (["--footprint", "--max-returns", "3"], r"--max-returns 3 needs --range-resolution"),
        (["--footprint", "--range-resolution", "0.5"], r"--range-resolution 0\.5 .* needs --max-returns above 1 or --return-mode"),
        (
            ["--footprint", "--max-returns", "3", "--range-resolution", "0.5", "--echo-separation", "0.5"],
            r"--echo-separation 0\.5 .*--max-returns 3",
        ),
        (
            ["--sensor", "hdl64e", "--footprint"],
            r"--footprint samples the beam's divergence cone, and hdl64e's beam .* give --divergence DEG",
        ),
        (["--sensor", "kinect-v1", "--max-returns", "3"], r"--max-returns: kinect-v1 is a depth camera, which has no beam to change"),
        (["--sensor", "kinect-v1", "--divergence", "0.2"], r"--divergence: kinect-v1 is a depth camera, which has no beam to change"),
        (["--divergence", "0"], r"--divergence must be a number > 0 degrees, got '?0'?"),
    ],
)
def test_bad_return_options_are_one_line_usage_errors(tmp_path: Path, capsys, options: list, message: str) -> None:
    import re

    code, err = _run(["scan", "box", "--no-progress", "--out", str(tmp_path / "o"), *options], capsys)
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert re.search(message, err), err
    assert not (tmp_path / "o").exists()


def test_echo_separation_takes_a_sensor_files_own_footprint_of_any_k(tmp_path: Path, capsys) -> None:
    sensor = _wide_beam_sensor(tmp_path, footprint_rays=19)
    code, err = _run(["scan", str(_pole_before_a_wall(tmp_path)), "--sensor", str(sensor), "--echo-separation", "0.5",
                      "--no-progress", "--out", str(tmp_path / "o")], capsys)  # fmt: skip
    assert code == 0, err
    assert len(list((tmp_path / "o").glob("*.npz"))) == 1


def test_max_returns_writes_several_returns_per_pulse_to_las(tmp_path: Path, capsys) -> None:
    laspy = pytest.importorskip("laspy")
    scene, sensor = _pole_before_a_wall(tmp_path), _wide_beam_sensor(tmp_path)
    code, err = _run(["scan", str(scene), "--sensor", str(sensor), "--footprint", "--max-returns", "3", "--range-resolution", "0.5",
                      "--format", "las", "--no-progress", "--out", str(tmp_path / "o")], capsys)  # fmt: skip
    assert code == 0, err
    (path,) = (tmp_path / "o").glob("*.las")
    las = laspy.read(path)
    n = np.asarray(las.number_of_returns)
    r = np.asarray(las.return_number)
    assert n.max() >= 2 and n.max() <= 3, np.bincount(n)
    assert np.all((r >= 1) & (r <= n))
    # the first of two returns lies on the pole (about 8 m ahead), the last on the wall behind it
    x = np.asarray(las.x)
    assert np.any((n == 2) & (r == 1) & (np.abs(x - 8.0) < 0.5)) and np.any((n == 2) & (r == 2) & (np.abs(x - 11.9) < 0.5))


def test_without_the_options_a_scan_is_unchanged(tmp_path: Path, capsys) -> None:
    scene = _pole_before_a_wall(tmp_path)
    outs = []
    for name, extra in (("a", []), ("b", ["--max-returns", "1"])):
        assert _run(["scan", str(scene), "--no-progress", "--out", str(tmp_path / name), *extra], capsys)[0] == 0
        (npz,) = (tmp_path / name).glob("*.npz")
        outs.append(npz.read_bytes())
    assert outs[0] == outs[1]


def test_max_returns_applies_to_an_airborne_scanner_file_with_a_footprint(tmp_path: Path, capsys) -> None:
    laspy = pytest.importorskip("laspy")
    from zbuf_occlude.sensors.patterns.airborne import AirborneScanner
    from zbuf_occlude.sensors.beam.fields import Beam

    beam = Beam(wavelength_nm=1064.0, divergence_deg=2.0, footprint_rays=19, max_returns=2, range_resolution_m=0.5)
    als = AirborneScanner("test-als", swath_deg=20.0, pulse_rate_hz=2000.0, line_rate_hz=20.0, altitude_m=100.0, speed_mps=10.0, beam=beam)
    sensor = _write_json(tmp_path / "als.json", sensor_to_json(als))
    code, err = _run(["scan", "box", "--sensor", str(sensor), "--extents", "6,6,10", "--distance", "2", "--max-returns", "4",
                      "--range-resolution", "1", "--format", "las", "--no-progress", "--out", str(tmp_path / "o")], capsys)  # fmt: skip
    assert code == 0, err
    (path,) = (tmp_path / "o").glob("*.las")
    las = laspy.read(path)
    n = np.asarray(las.number_of_returns)
    assert n.max() >= 2 and n.max() <= 4, np.bincount(n)  # the box's roof edge over the ground
    # one return per pulse of the same footprint: its strongest echo (the file's range resolution dropped)
    code, err = _run(["scan", "box", "--sensor", str(sensor), "--extents", "6,6,10", "--distance", "2", "--max-returns", "1",
                      "--format", "las", "--no-progress", "--out", str(tmp_path / "p")], capsys)  # fmt: skip
    assert code == 0, err
    (path,) = (tmp_path / "p").glob("*.las")
    assert set(np.asarray(laspy.read(path).number_of_returns).tolist()) == {1}
