"""``scan`` with an airborne scanner: its points are in the world frame (``--frame sensor`` is refused), and a
radiometric multi-return beam takes the materials' reflectances and foliage's gap fraction unless told otherwise."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.sensors.scan_data import read_scan_npz

#: A 60 m × 60 m ground with a wide "bush" cylinder and a "car" box beside it, under a low, dense flight.
SCENE = {"ground": {"half_extent_m": 12.0}, "objects": [
    {"mesh": {"cylinder": {"radius_m": 3.0, "height_m": 6.0}}, "class": "bush", "position_m": [0.0, 0.0]},
    {"mesh": {"box_m": [4.5, 1.8, 1.5]}, "class": "car", "position_m": [7.0, 0.0]}]}  # fmt: skip


def _sensor(tmp_path: Path) -> Path:
    """riegl-q1560 flown at 300 m: its beam (19 sub-rays, 15 returns, IGN intensity scale) over a small scene, fast."""
    path = tmp_path / "low.json"
    path.write_text(json.dumps({"kind": "airborne", "preset": "riegl-q1560", "altitude_m": 300.0}))
    return path


def _scan(tmp_path: Path, name: str, *extra: str, capsys) -> tuple[int, str]:
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(SCENE))
    code = cli_main(["scan", str(scene), "--sensor", str(_sensor(tmp_path)), "--no-progress", "--out", str(tmp_path / name), *extra])
    return code, capsys.readouterr().err.strip()


def test_an_airborne_scan_is_written_in_the_world_frame_and_refuses_the_sensor_frame(tmp_path: Path, capsys) -> None:
    code, err = _scan(tmp_path, "sensor", "--frame", "sensor", capsys=capsys)
    assert code == 2 and "\n" not in err and "--frame sensor" in err and "world frame" in err, err
    code, err = _scan(tmp_path, "default", capsys=capsys)
    assert code == 0, err
    s = read_scan_npz(next((tmp_path / "default").glob("*.npz")))
    assert s.frame == "world" and s.points[:, 2].min() > -0.5 and s.points[:, 2].max() < 7.0  # ground and objects, not ~300 m below


def test_an_airborne_scan_takes_the_material_table_unless_told_otherwise(tmp_path: Path, capsys) -> None:
    shares = {}
    for name, extra in (
        ("default", ()),
        ("opaque", ("--transmittance", "0")),
        ("table", ("--transmittance", "table", "--reflectance-table")),
    ):
        code, err = _scan(tmp_path, name, *extra, capsys=capsys)
        assert code == 0, err
        s = read_scan_npz(next((tmp_path / name).glob("*.npz")))
        bush = s.object_id == 1
        shares[name] = (float(np.mean(s.number_of_returns[bush] > 1)), s)
    default, table = shares["default"][1], shares["table"][1]
    for key in ("points", "intensity", "number_of_returns"):
        assert np.array_equal(getattr(default, key), getattr(table, key)), key  # the default is the table
    assert shares["default"][0] > shares["opaque"][0] + 0.05  # the canopy lets pulses through to the ground


@pytest.mark.parametrize("sensor", ["hdl32e", "livox-mid70"])
def test_a_ground_sensor_keeps_opaque_surfaces_and_its_sensor_frame(tmp_path: Path, capsys, sensor: str) -> None:
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(SCENE | {"sensor": {"height_m": 1.8, "position_m": [-10.0, 0.0]}}))
    code = cli_main(["scan", str(scene), "--sensor", sensor, "--no-progress", "--out", str(tmp_path / sensor)])
    assert code == 0, capsys.readouterr().err
    s = read_scan_npz(next((tmp_path / sensor).glob("*.npz")))
    assert s.frame == "sensor" and len(s) > 0 and np.all(s.number_of_returns == 1)
