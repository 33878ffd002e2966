"""``scan --format las|laz`` writes a survey's fields, read back with laspy: classes (by the rule, by ``--class-map``),
object ids and class names, point source ids, adjusted standard GPS time (``--gps-start``), ``--crs``; bad values are
one-line usage errors (exit 2) naming the value."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.io.las import CLASS_NAMES_RECORD_ID, CLASS_NAMES_USER_ID
from zbuf_occlude.sensors.scan_data import GPS_START_S

laspy = pytest.importorskip("laspy")
pytest.importorskip("lazrs")

ROOT = Path(__file__).resolve().parents[2]
CHAIR = ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"
STREET = ROOT / "data" / "scenes" / "street.json"


def _run(argv: list[str], capsys) -> tuple[int, str]:
    code = cli_main([*argv, "--no-progress"])
    return code, capsys.readouterr().err.strip()


def _names(las) -> list[str]:
    (vlr,) = las.header.vlrs.get_by_id(CLASS_NAMES_USER_ID, [CLASS_NAMES_RECORD_ID])
    return json.loads(vlr.record_data.decode("utf-8"))


def test_a_mesh_scan_writes_classes_names_sources_and_gps_time(tmp_path: Path, capsys) -> None:
    code, err = _run(["scan", str(CHAIR), "--format", "las", "--samples", "2", "--out", str(tmp_path / "o")], capsys)
    assert code == 0, err
    for k in (0, 1):
        las = laspy.read(tmp_path / "o" / f"chair_0001_hdl32e_s{k:03d}.las")
        assert _names(las) == ["ground", "chair_0001"]
        ids = np.asarray(las.object_id)
        assert set(ids.tolist()) == {0, 1}
        assert (las.classification[ids == 0] == 2).all() and (las.classification[ids == 1] == 1).all()
        assert (np.asarray(las.class_index) == ids).all()
        assert (las.point_source_id == k).all()
        assert las.header.global_encoding.value & 1 == 1
        times = np.asarray(las.gps_time)
        assert GPS_START_S <= times.min() and times.max() < GPS_START_S + 1.0  # one revolution


def _scene(tmp_path: Path) -> Path:
    """A 6 m tree (a cylinder), a house and a low bush before an hdl32e 1.8 m up."""
    path = tmp_path / "plot.json"
    path.write_text(json.dumps({
        "ground": {"half_extent_m": 30.0},
        "objects": [{"mesh": {"cylinder": {"radius_m": 0.6, "height_m": 6.0}}, "class": "oak_tree", "position_m": [8.0, 0.0]},
                    {"mesh": {"box_m": [4.0, 4.0, 5.0]}, "class": "house", "position_m": [12.0, 8.0]},
                    {"mesh": {"box_m": [1.0, 1.0, 0.4]}, "class": "bush", "position_m": [6.0, -4.0]}],
        "occluders": [{"mesh": {"box_m": [0.5, 2.0, 1.0]}, "class": "car", "position_m": [7.0, 4.0]}],
    }))  # fmt: skip
    return path


def test_a_scene_scan_classes_by_the_rule_and_the_class_map(tmp_path: Path, capsys) -> None:
    scene = _scene(tmp_path)
    code, err = _run(["scan", str(scene), "--format", "laz", "--frame", "world", "--out", str(tmp_path / "rule")], capsys)
    assert code == 0, err
    las = laspy.read(tmp_path / "rule" / "plot_hdl32e_s000.laz")
    assert _names(las) == ["ground", "oak_tree", "house", "bush", "car"]
    ids, cls, z = np.asarray(las.object_id), np.asarray(las.classification), np.asarray(las.z)
    assert set(ids.tolist()) == {0, 1, 2, 3, 4}
    assert (cls[ids == 0] == 2).all() and (cls[ids == 2] == 6).all() and (cls[ids == 4] == 1).all()
    tree = ids == 1
    assert np.array_equal(cls[tree], np.where(z[tree] < 0.5, 3, np.where(z[tree] < 1.5, 4, 5)))
    assert {3, 4, 5} <= set(cls[tree].tolist()) and (cls[ids == 3] == 3).all()
    mapping = tmp_path / "classes.json"
    mapping.write_text(json.dumps({"car": 64, "oak_tree": 5}))
    code, err = _run(["scan", str(scene), "--format", "las", "--frame", "world", "--class-map", str(mapping), "--out",
                      str(tmp_path / "mapped")], capsys)  # fmt: skip
    assert code == 0, err
    mapped = laspy.read(tmp_path / "mapped" / "plot_hdl32e_s000.las")
    ids, cls = np.asarray(mapped.object_id), np.asarray(mapped.classification)
    assert (cls[ids == 1] == 5).all() and (cls[ids == 4] == 64).all() and (cls[ids == 2] == 6).all()


def test_the_street_scene_and_gps_start(tmp_path: Path, capsys) -> None:
    code, err = _run(["scan", str(STREET), "--format", "las", "--gps-start", "1000", "--out", str(tmp_path / "o")], capsys)
    assert code == 0, err
    las = laspy.read(tmp_path / "o" / "street_hdl32e_s000.las")
    assert _names(las)[:3] == ["ground", "car", "pole"]
    assert 1000.0 <= np.asarray(las.gps_time).min() and np.asarray(las.gps_time).max() < 1001.0


def test_crs_is_written_as_wkt(tmp_path: Path, capsys) -> None:
    pytest.importorskip("pyproj", reason="the crs extra")
    code, err = _run(
        ["scan", str(STREET), "--format", "laz", "--frame", "world", "--crs", "epsg:2154", "--out", str(tmp_path / "o")], capsys
    )
    assert code == 0, err
    las = laspy.read(tmp_path / "o" / "street_hdl32e_s000.laz")
    assert las.header.parse_crs().to_epsg() == 2154
    code, err = _run(["scan", str(STREET), "--format", "las", "--crs", "EPSG:4326", "--out", str(tmp_path / "deg")], capsys)
    assert code == 2 and "--crs EPSG:4326" in err and "degree" in err and len(err.splitlines()) == 1


def test_crs_without_pyproj_names_the_extra(tmp_path: Path, capsys, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pyproj", None)
    code, err = _run(["scan", str(STREET), "--format", "las", "--frame", "world", "--crs", "EPSG:2154", "--out", str(tmp_path / "o")],
                     capsys)  # fmt: skip
    assert code == 2 and "needs pyproj" in err and "crs" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--crs", "WGS84"], r"--crs must be an EPSG code, EPSG:N \(EPSG:2154\), got WGS84"),
        (["--crs", "EPSG:x"], r"--crs EPSG:x: crs must be an EPSG code"),
        (["--gps-start", "-1"], r"--gps-start must be a number >= 0 seconds, got -1"),
        (["--gps-start", "nan"], r"--gps-start must be a finite number of seconds, got nan"),
        (["--gps-start", "inf"], r"--gps-start must be a finite number of seconds, got inf"),
        (["--class-map", "missing.json"], r"--class-map .*missing.json"),
        (["--format", "npz", "--class-map", "{map}"], r"--class-map fills LAS/LAZ files: it needs --format las or laz, not npz"),
        (["--format", "ply", "--gps-start", "5"], r"--gps-start fills LAS/LAZ files"),
        (["--class-map", "{bad}"], r"--class-map .*bad.json: 'car': the ASPRS code is one LAS 1.4 reserves"),
        (["--crs", "EPSG:2154", "--frame", "sensor"], r"--crs EPSG:2154 labels world coordinates: it needs --frame world"),
    ],
)
def test_bad_las_options_are_one_line_usage_errors(tmp_path: Path, capsys, options: list[str], message: str) -> None:
    if "EPSG:2154" in options:
        pytest.importorskip("pyproj", reason="the crs extra")
    good, bad = tmp_path / "map.json", tmp_path / "bad.json"
    good.write_text('{"car": 1}')
    bad.write_text('{"car": 12}')
    options = [o.format(map=good, bad=bad) for o in options]
    argv = ["scan", str(CHAIR), *(["--format", "las"] if "--format" not in options else []), *options, "--out", str(tmp_path / "o")]
    code, err = _run(argv, capsys)
    assert code == 2, err
    assert len(err.splitlines()) == 1
    assert re.search(message, err), err
    assert not (tmp_path / "o").exists()
