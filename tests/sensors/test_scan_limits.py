"""The limits of a scan's LAS options and return physics, in the library: a GPS start whose float64 times keep
:data:`~zbuf_occlude.sensors.scan_data.GPS_TIME_RESOLUTION_S`, a CRS a scan's metres can be in (projected, or
compound with a vertical CRS), a ``power_noise`` within :data:`~zbuf_occlude.sensors.beam.echoes.MAX_POWER_NOISE`; and
a scan at those limits raises no numpy warning."""

from __future__ import annotations

import io
import math
import warnings

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors import Lidar, scan
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.beam.echo_energy import Radiometry
from zbuf_occlude.sensors.beam.echoes import MAX_POWER_NOISE
from zbuf_occlude.sensors.scan_data import GPS_TIME_RESOLUTION_S, Scan, check_gps_start

#: The pulse interval of the fastest preset, seconds (riegl-q1560: 800 kHz).
FASTEST_PULSE_S = 1.0 / 800_000.0


def _scan(gps_time) -> Scan:
    """Returns at the given times (seconds from the scan's first firing), world frame."""
    n = len(gps_time)
    return Scan(np.zeros((n, 3), np.float32), None, None, np.ones(n, np.float32), np.zeros(n, np.int64), np.zeros(n, np.int32),
                np.zeros((n, 3), np.float32), np.zeros(n, np.float32), frame="world", sensor_to_world=np.eye(4),
                gps_time=np.asarray(gps_time, np.float64))  # fmt: skip


# -- GPS start ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(("start", "words"), [(1e17, "at 1e17 s float64 GPS times are 16 s apart"), (1e300, "1.5e284 s apart")])
def test_a_gps_start_beyond_the_resolution_is_refused_naming_the_step(start: float, words: str) -> None:
    with pytest.raises(InvalidInputError) as info:
        _scan([0.0, 0.05, 0.1]).to_las_bytes(gps_start_s=start)
    message = str(info.value)
    assert message.startswith(f"gps_start_s {start:g}".replace("e+", "e")) and words in message, message
    assert "a start below about 8.6e9 s keeps the 1 µs" in message, message


def test_the_latest_start_named_is_the_last_one_kept() -> None:
    times = [0.0, 0.25]
    check_gps_start(math.nextafter(2.0**33 - 0.25, 0.0), times)  # the last time just below 2**33: steps of 2**-20 s
    with pytest.raises(InvalidInputError, match=r"a start below about 8589934591.75 s keeps the 1 µs"):
        check_gps_start(2.0**33 - 0.25, times)  # the last time at 2**33: steps of 2**-19 s
    with pytest.raises(InvalidInputError, match=r"^--gps-start 8.6e9: .* below about 8.59e9 s"):
        check_gps_start(8.6e9, name="--gps-start")  # the caller's name; the start and the limit told apart


@settings(max_examples=200, deadline=None)
@given(start=st.floats(min_value=0.0, max_value=1e20), duration=st.floats(min_value=0.0, max_value=3600.0))
def test_an_accepted_start_keeps_the_fastest_pulses_apart_and_a_refused_one_would_not_keep_the_resolution(
    start: float, duration: float
) -> None:
    times = np.array([0.0, duration])
    try:
        check_gps_start(start, times)
    except InvalidInputError:
        last = np.float64(start) + duration
        assert np.spacing(last) > GPS_TIME_RESOLUTION_S  # refused: float64 times there are coarser than the resolution
        return
    # accepted: pulses one fastest interval apart, anywhere in the scan, keep distinct times in firing order
    for t in (0.0, duration):
        written = np.float64(start) + (t + FASTEST_PULSE_S * np.arange(4))
        assert np.all(np.diff(written) > 0), (start, t)


def test_the_resolution_keeps_the_fastest_preset_apart() -> None:
    from zbuf_occlude.sensors.patterns.airborne_presets import AIRBORNE_PRESETS

    fastest = max(p.pulse_rate_hz for p in AIRBORNE_PRESETS.values())
    assert GPS_TIME_RESOLUTION_S < 1.0 / fastest


def test_a_negative_time_is_still_refused_first() -> None:
    with pytest.raises(InvalidInputError, match="gps_start_s 100 puts the scan's first time at -20 s"):
        check_gps_start(100.0, [-120.0, 0.0])


# -- CRS ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("crs", "kind"),
    [("EPSG:5703", "is a vertical CRS"), (4978, "is a geocentric CRS"), ("EPSG:4326", "has axes in degree: it is a geographic 2D CRS"),
     ("EPSG:4326+5703", "is a geographic 2D CRS + vertical CRS"), ("EPSG:2263", "has axes in US survey foot"),
     ("EPSG:2263+6360", "has axes in US survey foot")],
)  # fmt: skip
def test_a_crs_a_scan_cannot_be_in_is_refused_naming_its_kind(crs, kind: str) -> None:
    pytest.importorskip("pyproj", reason="the crs extra")
    with pytest.raises(InvalidInputError) as info:
        _scan([0.0]).to_las_bytes(crs=crs)
    message = str(info.value)
    assert kind in message and "a scan needs a projected CRS in metres (e.g. EPSG:32633)" in message, message
    assert "\n" not in message


@pytest.mark.parametrize("crs", ["EPSG:32633", "EPSG:2154+5720", 7415])
def test_a_projected_crs_in_metres_or_its_compound_reads_back_in_metres(crs) -> None:
    pytest.importorskip("pyproj", reason="the crs extra")
    laspy = pytest.importorskip("laspy")
    from zbuf_occlude.io.las_crs import epsg_crs, linear_unit_m

    header = laspy.read(io.BytesIO(_scan([0.0, 0.1]).to_las_bytes(crs=crs))).header
    assert linear_unit_m(header) == 1.0  # the project's own reader finds the unit it was written in
    assert header.parse_crs() == epsg_crs(crs)


def test_a_malformed_compound_code_is_refused() -> None:
    pytest.importorskip("pyproj", reason="the crs extra")
    from zbuf_occlude.io.las_crs import epsg_crs

    with pytest.raises(InvalidInputError, match=r"EPSG:N \(EPSG:2154\) or EPSG:H\+V"):
        epsg_crs("EPSG:2154+5720+5703")
    with pytest.raises(InvalidInputError, match=r"crs EPSG:2154\+2154 is not a pair of a horizontal and a vertical CRS PROJ knows"):
        epsg_crs("EPSG:2154+2154")


# -- power noise -------------------------------------------------------------------------------------
@pytest.mark.parametrize("sigma", [MAX_POWER_NOISE * 1.0001, 50.0, 1e308, -0.1])
def test_a_power_noise_outside_its_range_is_refused_naming_the_field(sigma: float) -> None:
    with pytest.raises(InvalidInputError, match=r"power_noise must be a finite number in \[0, 2\]"):
        Beam(power_noise=sigma)
    with pytest.raises(InvalidInputError, match=r"^power_noise must be a finite number in \[0, 2\]"):
        Radiometry(np.ones(2), 0.0, sigma, np.random.default_rng(0))


def _wall(d: float = 10.0, half: float = 60.0) -> trimesh.Trimesh:
    v = np.array([[d, -half, -half], [d, half, -half], [d, half, half], [d, -half, half]], dtype=np.float64)
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


@pytest.mark.parametrize(
    "beam",
    [{}, {"divergence_deg": 2.0, "footprint_rays": 7, "echo_separation_m": 1e6},
     {"divergence_deg": 2.0, "footprint_rays": 19, "max_returns": 15, "range_resolution_m": 1e-3, "min_echo_reflectance": 1.0},
     {"divergence_deg": 2.0, "footprint_rays": 7, "max_returns": 2, "return_mode": "dual", "range_resolution_m": 0.01,
      "echo_rule": "waveform"}],
)  # fmt: skip
def test_a_scan_at_the_limits_raises_no_numpy_warning(beam: dict) -> None:
    lidar = Lidar("edge", (-30.0, 0.0, 30.0), rotation_hz=10.0, firing_rate_hz=3600.0,
                  beam=Beam(power_noise=MAX_POWER_NOISE, detection_threshold=1e-12, intensity_scale=1e12, max_intensity=65535,
                            min_range_m=0.0, max_range_m=1e6, dropout=0.5, dropout_range_per_m=0.01, **beam))  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for footprint in ("exact", "auto"):
            s = scan(_wall(), lidar, np.zeros(3), reflectivity=1.0, azimuth_range_deg=(-60.0, 60.0), seed=3, footprint=footprint)
            s.to_las_bytes(gps_start_s=math.nextafter(2.0**33 - 0.1, 0.0))
    assert len(s) > 0 and np.all(np.isfinite(s.intensity))
