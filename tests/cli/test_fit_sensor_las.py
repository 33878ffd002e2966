"""``fit-sensor`` on LAS/LAZ scans: the return model fitted to a scan our own airborne scanner made, written as a sensor
file that scan reads back; bad options and damaged files are one line."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.io.las import las_bytes, read_las
from zbuf_occlude.sensors.patterns.airborne import AIRBORNE_IDEAL_BEAM, AirborneScanner
from zbuf_occlude.sensors.kinds import sensor_from_name, sensor_to_json

#: The airborne scanner of the scans: a 2° beam of 19 sub-rays, up to 4 returns 1 m apart, 100 m above the ground.
ALS = AirborneScanner("test-als", swath_deg=20.0, pulse_rate_hz=2000.0, line_rate_hz=20.0, altitude_m=100.0, speed_mps=10.0,
                      beam=AIRBORNE_IDEAL_BEAM.with_(divergence_deg=2.0, footprint_rays=19, max_returns=4, range_resolution_m=1.0))  # fmt: skip


def _run(argv: list[str], capsys) -> tuple[int, str, str]:
    code = cli_main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err.strip()


@pytest.fixture(scope="module")
def scans(tmp_path_factory) -> Path:
    """Two LAZ scans of a 6 × 6 × 10 m box on the ground, flown over by :data:`ALS` (written by ``scan --format laz``)."""
    root = tmp_path_factory.mktemp("fit_las")
    (root / "als.json").write_text(json.dumps(sensor_to_json(ALS)))
    assert cli_main(["scan", "box", "--sensor", str(root / "als.json"), "--extents", "6,6,10", "--distance", "2", "--samples", "2",
                     "--format", "laz", "--no-progress", "--out", str(root / "scans")]) == 0  # fmt: skip
    return root / "scans"


def test_a_folder_of_our_own_laz_scans_gives_a_sensor_file_and_a_table(scans: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "fitted.json"
    code, stdout, err = _run(["fit-sensor", str(scans), "--sensor", "riegl-q1560", "--altitude", "100", "--bootstrap", "20",
                              "--seed", "3", "--out", str(out)], capsys)  # fmt: skip
    assert code == 0, err
    assert "reading 2 LAS/LAZ files" in stdout and "| range_resolution_m |" in stdout and f"wrote {out}" in stdout
    spec = json.loads(out.read_text())
    fit = spec["fit"]["returns"]
    assert spec["fit"]["files"] == sorted(p.name for p in scans.glob("*.laz")) and fit["altitude_m"] == 100.0
    resolution = fit["estimates"]["range_resolution_m"]["value"]
    # every gap between a pulse's returns is at least the scanner's resolution: the fit's lower end too (1 mm steps, 2 cm noise)
    assert resolution >= ALS.beam.range_resolution_m - 0.1
    assert 2 <= fit["estimates"]["max_returns"]["value"] <= ALS.beam.max_returns
    assert "bootstrap over pulses (20, seed 3)" in fit["estimates"]["range_resolution_m"]["method"]
    sensor = sensor_from_name(str(out))  # scan --sensor reads it back
    assert sensor.name == "riegl-q1560-fitted" and sensor.beam.range_resolution_m == resolution and sensor.altitude_m == 100.0
    assert sensor.beam.max_returns == fit["estimates"]["max_returns"]["value"]
    text = out.with_suffix(".md").read_text()
    assert text.startswith("# riegl-q1560-fitted: the return model fitted to") and "| returns_1 |" in text
    # the intensity scale measured is the beam's; the preset's footprint is kept, and the file says what came from where
    assert sensor.beam.intensity_scale == fit["estimates"]["intensity_scale"]["value"] and sensor.beam.max_intensity == 65_535
    assert sensor.beam.footprint_rays == 19 and "casts one ray" not in text
    assert set(spec["fit"]["beam"]["fitted"]) >= {"max_returns", "range_resolution_m", "intensity_scale"}
    # per ASPRS class of the scans: points, multi-return share, median intensity
    merged = [read_las(p) for p in sorted(scans.glob("*.laz"))]
    codes = sorted(set(np.concatenate([las.classification for las in merged]).tolist()))
    assert list(spec["fit"]["classes"]) == [str(c) for c in codes]
    for c in codes:
        figures = spec["fit"]["classes"][str(c)]
        assert figures["points"] == sum(int(np.sum(las.classification == c)) for las in merged)
        assert 0.0 <= figures["multi_return_share"] <= 1.0


def test_one_file_and_a_spinning_lidar_that_needs_an_altitude(scans: Path, tmp_path: Path, capsys) -> None:
    laz = min(scans.glob("*.laz"))
    code, _, err = _run(["fit-sensor", str(laz), "--sensor", "hdl32e", "--out", str(tmp_path / "f.json")], capsys)
    assert code == 2 and "--sensor hdl32e is a spinning LiDAR: give --altitude M" in err and "\n" not in err
    assert not (tmp_path / "f.json").exists()
    code, _, err = _run(["fit-sensor", str(laz), "--sensor", "hdl32e", "--altitude", "100", "--bootstrap", "5",
                         "--out", str(tmp_path / "f.json")], capsys)  # fmt: skip
    assert code == 0, err
    spec = json.loads((tmp_path / "f.json").read_text())
    lidar = sensor_from_name(str(tmp_path / "f.json"))
    assert lidar.beam.detection_threshold == spec["fit"]["returns"]["estimates"]["detection_threshold"]["value"] > 0
    # several returns need a footprint: the HDL-32E's data-sheet divergence, FOOTPRINT_RAYS sub-rays; the file says so
    assert (lidar.beam.divergence_deg, lidar.beam.footprint_rays) == (0.16, 7) and lidar.beam.max_returns > 1
    assert spec["fit"]["beam"]["data_sheet"] == {"divergence_deg": 0.16} and spec["fit"]["beam"]["model"]["footprint_rays"] == 7


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--altitude", "0"], r"--altitude must be a number > 0 metres, got 0"),
        (["--altitude", "nan"], r"--altitude must be a finite number of metres, got nan"),
        (["--classes", "3,x"], r"--classes must be ASPRS class codes 0 to 255, C,C,\.\.\. \(or none\), got 3,x"),
        (["--classes", "256"], r"--classes must be ASPRS class codes .*got 256"),
        (["--bootstrap", "1"], r"--bootstrap must be an integer >= 2"),
        (["--bootstrap", "100001"], r"--bootstrap must be at most 10,000 \(MAX_BOOTSTRAP\), got 100001"),
        (["--altitude", "2e6"], r"^zbuf-occlude: error: --altitude must be at most 1e\+06 metres \(a sensor's largest range\), got 2e6$"),
    ],
)
def test_bad_options_are_one_line_usage_errors(scans: Path, tmp_path: Path, capsys, options: list, message: str) -> None:
    code, _, err = _run(["fit-sensor", str(scans), "--sensor", "riegl-q1560", "--out", str(tmp_path / "f.json"), *options], capsys)
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert re.search(message, err), err


def test_las_options_on_object_scans_are_refused(tmp_path: Path, capsys) -> None:
    (tmp_path / "crops").mkdir()
    code, _, err = _run(["fit-sensor", str(tmp_path / "crops"), "--sensor", "hdl32e", "--altitude", "100", "--out",
                         str(tmp_path / "f.json")], capsys)  # fmt: skip
    assert code == 2 and re.search(r"--altitude: for LAS/LAZ scans, and .*crops is neither a \.las/\.laz file nor a folder of them", err), (
        err
    )


def _valid_las(n: int = 6) -> bytes:
    return las_bytes(np.arange(3 * n, dtype=float).reshape(n, 3), intensity=np.full(n, 10), return_number=np.ones(n, int),
                     number_of_returns=np.ones(n, int), gps_time=np.arange(n, dtype=float), scan_angle_deg=np.zeros(n))  # fmt: skip


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("text.las", b"not a LAS file at all\n", r"text\.las: "),
        ("truncated.laz", None, r"truncated\.laz: "),
        ("empty.las", b"", r"empty\.las: "),
        ("header_only.las", "header", r"header_only\.las: "),
        ("lying_count.las", "count", r"lying_count\.las: "),
    ],
)
def test_damaged_files_are_one_line_naming_them(tmp_path: Path, capsys, name: str, content, message: str) -> None:
    good = _valid_las()
    if content is None:  # a LAZ cut in the middle of its points
        whole = las_bytes(np.zeros((500, 3)) + np.arange(500)[:, None], intensity=np.arange(500), return_number=np.ones(500, int),
                          number_of_returns=np.ones(500, int), gps_time=np.arange(500.0), scan_angle_deg=np.zeros(500), compress=True)  # fmt: skip
        content = whole[: len(whole) - 200]
    elif content == "header":
        content = good[:375]
    elif content == "count":  # the header declares a million points the file does not hold
        content = bytearray(good)
        content[247:255] = (1_000_000).to_bytes(8, "little")
        content = bytes(content)
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / name).write_bytes(content)
    code, _, err = _run(["fit-sensor", str(tmp_path / "in"), "--sensor", "riegl-q1560", "--out", str(tmp_path / "f.json")], capsys)
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert re.search(message, err), err
    assert not (tmp_path / "f.json").exists()


def test_a_file_without_gps_times_or_points_is_named(tmp_path: Path, capsys) -> None:
    import laspy

    header = laspy.LasHeader(version="1.2", point_format=0)
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.arange(4.0), np.zeros(4), np.zeros(4)
    las.write(tmp_path / "no_time.las")
    code, _, err = _run(["fit-sensor", str(tmp_path / "no_time.las"), "--sensor", "riegl-q1560", "--out", str(tmp_path / "f.json")], capsys)
    assert code == 2 and re.search(r"no_time\.las: point format 0 has no GPS time", err), err
    empty = las_bytes(np.zeros((0, 3)), intensity=np.zeros(0, int), return_number=np.zeros(0, int), number_of_returns=np.zeros(0, int),
                      gps_time=np.zeros(0), scan_angle_deg=np.zeros(0))  # fmt: skip
    (tmp_path / "none.las").write_bytes(empty)
    assert len(read_las(tmp_path / "none.las")) == 0
    code, _, err = _run(["fit-sensor", str(tmp_path / "none.las"), "--sensor", "riegl-q1560", "--out", str(tmp_path / "f.json")], capsys)
    assert code == 2 and re.search(r"none\.las: holds no points", err), err


def test_a_link_out_of_the_folder_and_a_fifo_are_refused_in_one_line(scans: Path, tmp_path: Path, capsys) -> None:
    import os

    laz = min(scans.glob("*.laz"))
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "elsewhere.laz").symlink_to(laz)  # a readable LAZ, but outside the folder named
    code, _, err = _run(["fit-sensor", str(tmp_path / "in"), "--sensor", "riegl-q1560", "--out", str(tmp_path / "f.json")], capsys)
    assert code == 2 and "\n" not in err and "elsewhere.laz" in err, err
    (tmp_path / "fifo").mkdir()
    os.mkfifo(tmp_path / "fifo" / "pipe.las")  # never opened for reading: it would block
    code, _, err = _run(["fit-sensor", str(tmp_path / "fifo"), "--sensor", "riegl-q1560", "--out", str(tmp_path / "f.json")], capsys)
    assert code == 2 and "\n" not in err and "pipe.las" in err, err
    assert not (tmp_path / "f.json").exists()


def test_divergence_shares_fit_the_divergence(scans: Path, tmp_path: Path, capsys) -> None:
    (tmp_path / "curve.csv").write_text("divergence_deg,multi_return_points\n0.5,0.0\n4.0,1.0\n")  # divergence = 0.5 + 3.5 share
    out = tmp_path / "fitted.json"
    code, _, err = _run(["fit-sensor", str(scans), "--sensor", "riegl-q1560", "--bootstrap", "5", "--divergence-shares",
                         str(tmp_path / "curve.csv"), "--out", str(out)], capsys)  # fmt: skip
    assert code == 0, err
    fit = json.loads(out.read_text())["fit"]["returns"]
    share = fit["statistics"]["estimates"]["multi_return_points"]["value"]
    sensor = sensor_from_name(str(out))
    assert sensor.beam.divergence_deg == pytest.approx(0.5 + 3.5 * share) and sensor.beam.footprint_rays == 19
    assert fit["estimates"]["beam_divergence_deg"]["value"] == pytest.approx(0.5 + 3.5 * share)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        (
            "divergence,multi_return_points\n0.5,0.1\n1,0.2\n",
            r"curve\.csv: the header must be divergence_deg,<a multi_return_points figure>",
        ),
        ("divergence_deg,returns_1\n0.5,0.1\n1,0.2\n", r"curve\.csv: the header must be"),
        ("divergence_deg,multi_return_points\n0.5,0.1\n1,x\n", r"curve\.csv: row 3: multi_return_points is not a number$"),
        ("divergence_deg,multi_return_points\n0.5,0.3\n1,0.2\n", r"curve\.csv: simulated_shares must grow with the divergence"),
        ("divergence_deg,multi_return_points\n0.5,0.3\n", r"curve\.csv: .*M >= 2"),
        ("divergence_deg,multi_return_points\n", r"curve\.csv: a table of simulated shares needs 2 to 1,000 rows, got 0"),
        (
            "divergence_deg,multi_return_points\n0.5,0.1\n1e308,0.2\n",
            r"^zbuf-occlude: error: --divergence-shares \S*curve\.csv: divergences_deg must be at most 90 degrees .*got a larger one$",
        ),
    ],
)
def test_a_bad_table_of_shares_is_one_line_naming_it(scans: Path, tmp_path: Path, capsys, table: str, message: str) -> None:
    (tmp_path / "curve.csv").write_text(table)
    code, out, err = _run(["fit-sensor", str(scans), "--sensor", "riegl-q1560", "--divergence-shares", str(tmp_path / "curve.csv"),
                           "--out", str(tmp_path / "f.json")], capsys)  # fmt: skip
    assert code == 2 and "\n" not in err and re.search(message, err), err
    assert "reading" not in out  # refused before the scans are read
    assert not (tmp_path / "f.json").exists()


def _rewritten(laz: Path, out: Path, change) -> Path:
    """``laz`` written again to ``out`` after ``change(las)`` (laspy), which returns the LasData to write."""
    import laspy

    change(laspy.read(laz)).write(out)
    return out


def test_a_scan_of_first_returns_only_is_refused_naming_the_file_and_why(scans: Path, tmp_path: Path, capsys) -> None:
    import laspy

    def first_only(las):
        kept = laspy.LasData(las.header)
        kept.points = las.points[np.asarray(las.return_number) == 1]
        return kept

    laz = _rewritten(min(scans.glob("*.laz")), tmp_path / "first.laz", first_only)
    assert read_las(laz).number_of_returns.max() > 1 and read_las(laz).return_number.max() == 1
    code, out, err = _run(
        ["fit-sensor", str(laz), "--sensor", "riegl-q1560", "--altitude", "100", "--out", str(tmp_path / "f.json")], capsys
    )
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert re.search(rf"^zbuf-occlude: error: {re.escape(str(laz))}: holds first returns only \(return_number 1 on every point, though "
                     r"its pulses recorded up to \d\): .*range resolution cannot be fitted; give the scan with all its returns$", err), err  # fmt: skip
    assert "fitting" not in out and not (tmp_path / "f.json").exists()


def test_a_scan_whose_gps_times_are_all_zero_is_refused_not_fitted_to_a_wrong_resolution(scans: Path, tmp_path: Path, capsys) -> None:
    def zero_times(las):
        las.gps_time = np.zeros(len(las.points))
        return las

    (tmp_path / "in").mkdir()
    good = min(scans.glob("*.laz"))
    zero = _rewritten(good, tmp_path / "in" / "zero.laz", zero_times)
    code, out, err = _run(
        ["fit-sensor", str(zero), "--sensor", "riegl-q1560", "--altitude", "100", "--out", str(tmp_path / "f.json")], capsys
    )
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert re.search(rf"^zbuf-occlude: error: {re.escape(str(zero))}: its GPS times do not identify pulses \(all [\d,]+ points have GPS "
                     r"time 0; .*give a scan whose points carry their pulse's GPS time", err), err  # fmt: skip
    assert not (tmp_path / "f.json").exists()
    # in a folder beside a good tile: the bad one is named
    (tmp_path / "in" / "a_good.laz").write_bytes(good.read_bytes())
    code, _, err = _run(["fit-sensor", str(tmp_path / "in"), "--sensor", "riegl-q1560", "--altitude", "100", "--out", str(tmp_path / "f.json")],
                        capsys)  # fmt: skip
    assert code == 2 and re.search(r"zero\.laz: its GPS times do not identify pulses", err), err
