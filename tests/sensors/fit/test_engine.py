"""fit-sensor's one engine (sensors/fit/engine.py): the command line and the experiments call it; it tells LAS/LAZ scans
from object scans and refuses the LAS options for object scans before reading anything."""

from __future__ import annotations

from pathlib import Path

import pytest

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.fit import engine


def test_the_experiments_and_the_command_line_call_the_engine(tmp_path: Path, monkeypatch) -> None:
    from zbuf_occlude.cli.main import main
    from zbuf_occlude.experiments import sensor_fit

    assert sensor_fit.fit_to_scans is engine.fit_to_scans and sensor_fit.fit_sensor_to_scans is engine.fit_sensor_to_scans
    calls = []

    def fake(real, sensor, out, **options):
        calls.append((real, sensor, out, options))
        return engine.FittedSensor(None, None, Path(out), Path(out).with_suffix(".md"), "| table |\n")

    monkeypatch.setattr(engine, "fit_sensor", fake)
    assert main(["fit-sensor", str(tmp_path), "--sensor", "hdl32e", "--out", str(tmp_path / "f.json"), "--altitude", "120"]) == 0
    ((real, sensor, out, options),) = calls
    assert (real, sensor, out) == (str(tmp_path), "hdl32e", str(tmp_path / "f.json"))
    assert options["las"] == engine.LasFit(altitude_m=120.0)  # classes, bootstrap and the table of shares left to their defaults
    assert options["names"]["altitude_m"] == "--altitude"  # the engine's messages in the command's words


def test_las_inputs_are_the_named_file_or_the_folders_las_and_laz_files(tmp_path: Path) -> None:
    for name in ("b.LAZ", "a.las", "c.txt"):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "d.las").mkdir()  # a folder named .las is not a scan
    assert engine.las_inputs(tmp_path) == [tmp_path / "a.las", tmp_path / "b.LAZ"]
    assert engine.las_inputs(tmp_path / "missing.laz") == [tmp_path / "missing.laz"]  # read_las names it
    (tmp_path / "scans").mkdir()
    assert engine.las_inputs(tmp_path / "scans") is None and engine.las_inputs(tmp_path / "c.txt") is None


@pytest.mark.parametrize(("options", "flags"), [({"altitude_m": 100.0}, "altitude_m"),
                                                ({"classes": (5,), "bootstrap": 5}, "classes, bootstrap")])  # fmt: skip
def test_las_options_for_object_scans_are_refused_naming_them(tmp_path: Path, options: dict, flags: str) -> None:
    (tmp_path / "scans").mkdir()
    with pytest.raises(InvalidInputError, match=rf"^{flags}: for LAS/LAZ scans, and .*scans is neither a .las/.laz file"):
        engine.fit_sensor(tmp_path / "scans", "hdl32e", tmp_path / "f.json", las=engine.LasFit(**options))
    with pytest.raises(InvalidInputError, match=r"^--alt: for LAS/LAZ scans"):  # in the caller's words
        engine.fit_sensor(
            tmp_path / "scans", "hdl32e", tmp_path / "f.json", las=engine.LasFit(altitude_m=9.0), names={"altitude_m": "--alt"}
        )
    assert not (tmp_path / "f.json").exists()


def test_a_sensor_of_another_kind_or_an_out_that_is_not_json_is_refused_before_reading(tmp_path: Path) -> None:
    (tmp_path / "a.laz").write_bytes(b"not a laz file")  # never read
    with pytest.raises(InvalidInputError, match="fit-sensor fits a spinning LiDAR or an airborne scanner, not a DepthCamera"):
        engine.fit_sensor(tmp_path, "kinect-v1", tmp_path / "f.json")
    with pytest.raises(InvalidInputError, match=r"^out .*f\.txt: the fitted sensor is written as a \.json file$"):
        engine.fit_sensor(tmp_path, "riegl-q1560", tmp_path / "f.txt")
