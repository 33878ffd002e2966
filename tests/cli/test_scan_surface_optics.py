"""``scan --reflectance-table`` and ``scan --transmittance SPEC``: a scene file's objects reflect as the cited table
says and let part of each sub-ray through; bad values are usage errors (exit 2) naming the value."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.sensors.scan_data import read_scan_npz

RETURNS = ["--sensor", "vlp16", "--footprint", "--max-returns", "3", "--range-resolution", "0.5", "--no-progress"]


def _scene(tmp_path: Path) -> Path:
    scene = tmp_path / "street.json"
    scene.write_text(json.dumps({"ground": {"half_extent_m": 20.0}, "objects": [
        {"mesh": {"cylinder": {"radius_m": 1.0, "height_m": 2.5}}, "class": "bush", "position_m": [6.0, 0.0]},
        {"mesh": {"box_m": [1.0, 3.0, 3.0]}, "class": "wall", "position_m": [9.0, 0.0]}]}))  # fmt: skip
    return scene


def _run(argv: list[str], capsys) -> tuple[int, str]:
    code = cli_main(argv)
    return code, capsys.readouterr().err.strip()


def test_a_transmitting_bush_gives_returns_from_the_wall_behind_it(tmp_path: Path, capsys) -> None:
    scene = _scene(tmp_path)
    scans = {}
    for name, extra in (
        ("opaque", []),
        ("through", ["--transmittance", "bush=0.5"]),
        ("table", ["--transmittance", "table", "--reflectance-table"]),
    ):
        code, err = _run(["scan", str(scene), *RETURNS, *extra, "--out", str(tmp_path / name)], capsys)
        assert code == 0, err
        (npz,) = (tmp_path / name).glob("*.npz")
        scans[name] = read_scan_npz(npz)
    behind = [int(np.sum((s.object_id == 2) & (s.return_number > 1))) for s in scans.values()]
    assert behind[1] > 2 * behind[0] and behind[2] > 2 * behind[0]  # the wall seen through the bush as a later return
    assert np.any(scans["through"].number_of_returns[scans["through"].object_id == 1] > 1)


@pytest.mark.parametrize(
    ("spec", "words"),
    [("1.5", "--transmittance must be a transmittance in [0, 1], got 1.5"), ("nan", "--transmittance must be a finite number, got nan"),
     ("-0.1", "--transmittance must be a number >= 0, got -0.1"), ("bush=", "CLASS=VALUE,... (bush=0.3,tree=0.3), got bush="),
     ("bush=0.3,Bush=0.2", "gives the class Bush twice"), ("bush=2", "in [0, 1], got bush=2"),
     ("opaque", "--transmittance must be a finite number, got opaque")],
)  # fmt: skip
def test_bad_transmittance_values_exit_2_naming_the_value(tmp_path: Path, capsys, spec: str, words: str) -> None:
    code, err = _run(["scan", str(_scene(tmp_path)), *RETURNS, "--transmittance", spec, "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert words in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("argv", "words"),
    [(["--transmittance", "0.3", "--no-progress"], "--transmittance 0.3 gives hits behind a surface, which only several returns per pulse resolve"),
     ([*RETURNS, "--transmittance", "0.3", "--backend", "zbuffer"], "which --backend zbuffer cannot give"),
     ([*RETURNS, "--transmittance", "tree=0.3"], "--transmittance tree=0.3: no object of the scene has the class 'tree'"),
     (["--transmittance", "0.3", "--sensor", "kinect-v1"], "model the surfaces a pulsed LiDAR's beam meets; kinect-v1 is a depth camera"),
     (["--reflectance-table", "--reflectivity", "0.3"], "--reflectance-table gives each surface its material's reflectivity; --reflectivity")],
)  # fmt: skip
def test_transmittance_where_it_cannot_apply_exits_2(tmp_path: Path, capsys, argv: list[str], words: str) -> None:
    code, err = _run(["scan", str(_scene(tmp_path)), *argv, "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert words in err, err
