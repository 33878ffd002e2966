"""``scan``'s options at their limits: ``--gps-start`` where float64 times lose the microsecond, ``--crs`` of a kind a scan's
metres cannot be in, ``--power-noise`` beyond what a receiver meets, ``--footprint-cast`` on a depth camera: each a
one-line usage error (exit 2) naming the option and the value, nothing written; and a scan at the limits that are
kept prints no numpy warning."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.cli.main import main as cli_main

ROOT = Path(__file__).resolve().parents[2]
STREET = ROOT / "data" / "scenes" / "street.json"


def _run(argv: list[str], capsys) -> tuple[int, str]:
    code = cli_main([*argv, "--no-progress"])
    return code, capsys.readouterr().err.strip()


def _refused(options: list[str], tmp_path: Path, capsys, pattern: str) -> str:
    code, err = _run(["scan", str(STREET), *options, "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert re.search(pattern, err), err
    assert not (tmp_path / "o").exists()
    return err


@pytest.mark.parametrize(
    ("start", "step"), [("1e17", "16 s apart"), ("1e300", "1.5e284 s apart"), ("8.6e9", "1.9e-6 s apart")],
)  # fmt: skip
def test_a_gps_start_that_loses_the_microsecond_is_a_usage_error(tmp_path: Path, capsys, start: str, step: str) -> None:
    err = _refused(["--format", "las", "--gps-start", start], tmp_path, capsys, rf"--gps-start {re.escape(start)}: ")
    assert f"float64 GPS times are {step}" in err and "a start below about 8.6e9 s keeps the 1 µs" in err.replace("8.59e9", "8.6e9")


def test_a_gps_start_whose_scan_runs_past_the_microsecond_is_refused_before_it_is_written(tmp_path: Path, capsys) -> None:
    # the start alone keeps 1 µs; the scan's own times (up to a 0.1 s revolution) reach 2**33 s, where steps are 2 µs
    start = repr(2.0**33 - 0.01)
    _refused(
        ["--format", "laz", "--gps-start", start], tmp_path, capsys, r"^zbuf-occlude: error: --gps-start .*GPS times are 1.9e-6 s apart"
    )


def test_a_gps_start_that_keeps_the_microsecond_is_written(tmp_path: Path, capsys) -> None:
    laspy = pytest.importorskip("laspy")
    start = 2.0**33 - 1.0  # a revolution later, still below 2**33: steps of 2**-20 s
    code, err = _run(["scan", str(STREET), "--format", "las", "--gps-start", repr(start), "--out", str(tmp_path / "o")], capsys)
    assert code == 0, err
    times = np.asarray(laspy.read(tmp_path / "o" / "street_hdl32e_s000.las").gps_time)
    assert times.min() >= start and len(np.unique(times)) > 1000  # the firings keep their own times


@pytest.mark.parametrize(
    ("crs", "kind"),
    [("EPSG:5703", "is a vertical CRS"), ("EPSG:4978", "is a geocentric CRS"), ("EPSG:2263", "has axes in US survey foot"),
     ("EPSG:4326+5703", "is a geographic 2D CRS \\+ vertical CRS")],
)  # fmt: skip
def test_a_crs_a_scan_cannot_be_in_is_a_usage_error_naming_its_kind(tmp_path: Path, capsys, crs: str, kind: str) -> None:
    pytest.importorskip("pyproj", reason="the crs extra")
    _refused(["--format", "las", "--frame", "world", "--crs", crs], tmp_path, capsys,
             rf"--crs {re.escape(crs)}: crs {re.escape(crs)} \(.*\) .*{kind}.*a scan needs a projected CRS in metres \(e.g. EPSG:32633\)")  # fmt: skip


def test_a_compound_of_a_projected_and_a_vertical_crs_is_written(tmp_path: Path, capsys) -> None:
    pytest.importorskip("pyproj", reason="the crs extra")
    laspy = pytest.importorskip("laspy")
    from zbuf_occlude.io.las import read_las

    code, err = _run(["scan", str(STREET), "--format", "las", "--frame", "world", "--crs", "epsg:2154+5720", "--out",
                      str(tmp_path / "o")], capsys)  # fmt: skip
    assert code == 0, err
    path = tmp_path / "o" / "street_hdl32e_s000.las"
    assert laspy.read(path).header.parse_crs().name == "RGF93 v1 / Lambert-93 + NGF-IGN69 height"
    assert read_las(path).linear_unit_m == 1.0


@pytest.mark.parametrize("sigma", ["1e308", "50", "2.5"])
def test_a_power_noise_beyond_a_receivers_is_a_usage_error(tmp_path: Path, capsys, sigma: str) -> None:
    _refused(["--reflectance-table", "--power-noise", sigma], tmp_path, capsys, rf"--power-noise must be a number <= 2, got {sigma}$")


def test_a_scan_at_the_largest_power_noise_prints_no_warning(tmp_path: Path, capsys) -> None:
    laspy = pytest.importorskip("laspy")
    options = ["--reflectance-table", "--power-noise", "2", "--footprint", "--max-returns", "15", "--range-resolution", "0.01",
               "--footprint-cast", "exact", "--format", "las"]  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code, err = _run(["scan", str(STREET), *options, "--out", str(tmp_path / "o")], capsys)
    assert code == 0 and err == "", err
    intensity = np.asarray(laspy.read(tmp_path / "o" / "street_hdl32e_s000.las").intensity)
    assert len(np.unique(intensity)) > 10 and (intensity < intensity.max()).mean() > 0.5  # spread, not every one at the top


@pytest.mark.parametrize(
    ("options", "named"),
    [(["--footprint-cast", "exact"], "--footprint-cast"), (["--footprint-cast", "auto"], "--footprint-cast"),
     (["--max-returns", "2", "--footprint-cast", "exact"], "--max-returns, --footprint-cast")],
)  # fmt: skip
def test_a_depth_camera_refuses_the_footprint_cast_as_it_refuses_the_beam_options(tmp_path: Path, capsys, options, named) -> None:
    _refused(["--sensor", "kinect-v1", *options], tmp_path, capsys,
             rf"error: {named}: kinect-v1 is a depth camera, which has no beam to change \(a pulsed LiDAR has one\)$")  # fmt: skip
