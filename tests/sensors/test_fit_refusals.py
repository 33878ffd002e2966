"""The fits and the scans refuse a bad argument or a scan they cannot measure in one line naming it, before any work:
seeds by the house's one rule, a capped bootstrap, a curve of shares checked before the scan is measured, GPS times that
do not identify pulses, and a scan of first returns only."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import zbuf_occlude as zo
from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.io.las import LasPoints
from zbuf_occlude.sensors.patterns.airborne import AirborneScanner
from zbuf_occlude.sensors.scan import scan_airborne
from zbuf_occlude.sensors.fit import fit_airborne, fit_lidar, fit_return_model, return_statistics
from zbuf_occlude.sensors.fit.lidar import MAX_BOOTSTRAP
from zbuf_occlude.sensors.fit.las_pulses import MAX_AMBIGUOUS_SHARE, las_pulses
from zbuf_occlude.sensors.fit.returns import pulse_bootstrap
from zbuf_occlude.sensors.patterns.spinning import Lidar

#: Flying height of the synthetic survey, metres.
H = 1000.0


def _survey(n_pulses: int = 600, seed: int = 0) -> LasPoints:
    """Pulses over flat ground 1 m apart: every third has 3 returns (trees, class 5) 1.5 m apart, the rest one (ground,
    class 2); each pulse's returns share its GPS time."""
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n_pulses):
        n = 3 if i % 3 == 0 else 1
        for k in range(1, n + 1):
            z = 1.5 * (n - k) + 0.01 * rng.standard_normal()
            rows.append((float(i), 0.0, z, 50 + int(rng.integers(0, 100)), k, n, i * 1e-3, 0.0, 2 if k == n else 5))
    c = [np.array(v) for v in zip(*rows, strict=True)]
    n_points = len(rows)
    return LasPoints(points=np.stack(c[:3], axis=1), intensity=c[3], return_number=c[4], number_of_returns=c[5], gps_time=c[6],
                     scan_angle_deg=c[7], classification=c[8], point_source_id=np.zeros(n_points), scanner_channel=np.zeros(n_points),
                     linear_unit_m=1.0)  # fmt: skip


def _first_returns(las: LasPoints) -> LasPoints:
    keep = las.return_number == 1
    return LasPoints(points=las.points[keep], has_gps_time=True, point_format_id=las.point_format_id, version=las.version,
                     linear_unit_m=las.linear_unit_m, **{k: getattr(las, k)[keep] for k in LasPoints._DTYPES})  # fmt: skip


@pytest.fixture(scope="module")
def survey() -> LasPoints:
    return _survey()


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"bootstrap": 10**9}, InvalidInputError, rf"^bootstrap must be at most {MAX_BOOTSTRAP:,} \(MAX_BOOTSTRAP\), got 1000000000$"),
        ({"bootstrap": 2.5}, ArgumentTypeError, "^bootstrap must be an integer, got float 2.5$"),
        ({"seed": 2**70}, InvalidInputError, r"^seed must be at most 2\*\*63 - 1"),
        ({"seed": -1}, InvalidInputError, "^seed must be a non-negative integer, got -1$"),
        ({"seed": "a"}, InvalidInputError, "^seed must be a non-negative integer .*got 'a'$"),
        ({"seed": None}, ArgumentTypeError, r"^seed must be a non-negative integer \(a fit records its seed\), got NoneType$"),
        ({"divergence_shares": "abc"}, ArgumentTypeError, "^divergence_shares must be .*, got str 'abc'$"),
        ({"divergence_shares": (["a", "b"], [0.1, 0.2])}, ArgumentTypeError, "^divergence_shares: divergences_deg must be an array of numbers"),
        ({"divergence_shares": ([0.1, 1e308], [0.1, 0.2])}, InvalidInputError, "^divergence_shares: divergences_deg must be at most 90 degrees"),
        ({"divergence_shares": ([0.1, 0.2], [0.1, 0.2]), "divergence_share": 5}, InvalidInputError, "^divergence_share must be a string, got a whole number$"),
        ({"divergence_shares": ([0.1, 0.2], [0.1, 0.2]), "divergence_share": "multi_return_points_class_9"}, InvalidInputError,
         r"^divergence_share 'multi_return_points_class_9' is not a figure .*\(they hold multi_return_points, "
         r"multi_return_points_class_2, multi_return_points_class_5, multi_return_points_classes_3_4_5\)$"),
        ({"altitude_m": 2e6}, InvalidInputError, r"^altitude_m must be in \(0, 1e\+06\], got a number outside that range$"),
    ],
)  # fmt: skip
def test_a_bad_argument_of_the_return_model_fit_is_one_line_naming_it_before_any_work(survey, monkeypatch, kwargs, error, match):
    import zbuf_occlude.sensors.fit.return_model as module

    def measured(*args, **kw):
        raise AssertionError("the scan was measured before the arguments were checked")

    monkeypatch.setattr(module, "pulse_statistics", measured)
    monkeypatch.setattr(module, "las_pulses", measured)
    with pytest.raises(error, match=match):
        fit_return_model(survey, **({"altitude_m": H} | kwargs))


def test_a_billion_resamples_are_refused_under_a_memory_limit_not_allocated() -> None:
    from memory_limit import run_python_limited

    code = (
        "from zbuf_occlude.errors import InvalidInputError\n"
        "from zbuf_occlude.sensors.fit.returns import pulse_bootstrap\n"
        "try:\n"
        "    pulse_bootstrap(10, {'one': lambda w: 1.0}, seed=0, bootstrap=10**9)\n"
        "except InvalidInputError as exc:\n"
        "    print('refused:', exc)\n"
    )
    done = run_python_limited(code)
    assert done.returncode == 0 and "refused: bootstrap must be at most 10,000" in done.stdout, done.stderr[-2000:]


def test_the_bootstraps_memory_is_checked_before_it_is_allocated(monkeypatch) -> None:
    import zbuf_occlude.resources as resources
    from zbuf_occlude.errors import InsufficientMemoryError

    monkeypatch.setattr(resources, "available_memory", lambda: (1 << 20, "a test"))
    figures = {f"f{i}": (lambda w: 1.0) for i in range(1000)}  # 10,000 resamples of 1,000 figures: 80 MB
    with pytest.raises(InsufficientMemoryError, match="bootstrap 10,000 over 10 pulses"):
        pulse_bootstrap(10, figures, seed=0, bootstrap=MAX_BOOTSTRAP)


@pytest.mark.parametrize("fit", ["lidar", "airborne"])
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"bootstrap": 10**9}, "^bootstrap must be at most 10,000"), ({"seed": -1}, "^seed must be a non-negative integer, got -1$"),
     ({"seed": 2**70}, r"^seed must be at most 2\*\*63 - 1")],
)  # fmt: skip
def test_the_object_scan_fits_check_seed_and_bootstrap_first(fit, kwargs, match) -> None:
    crops = [np.zeros((3, 3))] * 3  # never looked at: the arguments are checked first
    with pytest.raises(InvalidInputError, match=match):
        if fit == "lidar":
            fit_lidar(crops, Lidar.preset("vlp16"), **kwargs)
        else:
            fit_airborne(crops, AirborneScanner("a", swath_deg=20.0, pulse_rate_hz=2000.0, line_rate_hz=20.0, altitude_m=100.0,
                                                speed_mps=10.0), **kwargs)  # fmt: skip


@pytest.mark.parametrize(
    ("seed", "match"),
    [(-1, "^seed must be a non-negative integer, got -1$"), ("a", "^seed must be a non-negative integer .*got 'a'$"),
     (1.5, "^seed must be a non-negative integer .*got 1.5$"), (2**70, r"^seed must be at most 2\*\*63 - 1")],
)  # fmt: skip
def test_scan_refuses_a_bad_seed_in_one_line_naming_it(seed, match) -> None:
    import trimesh

    box = trimesh.creation.box((1.0, 1.0, 1.0))
    with pytest.raises(InvalidInputError, match=match):
        zo.scan(box, Lidar.preset("vlp16"), pose=[5.0, 0.0, 0.0], seed=seed)
    scanner = AirborneScanner("a", swath_deg=20.0, pulse_rate_hz=2000.0, line_rate_hz=20.0, altitude_m=100.0, speed_mps=10.0)
    with pytest.raises(InvalidInputError, match=match):
        scan_airborne(box, scanner, seed=seed)


def test_gps_times_that_do_not_identify_pulses_are_refused_not_fitted(survey) -> None:
    zero = replace(survey, gps_time=np.zeros(len(survey)))
    message = r"^the scan: its GPS times do not identify pulses \(all 1,000 points have GPS time 0; 1,000 of 1,000 points"
    with pytest.raises(InvalidInputError, match=message):
        fit_return_model(zero, altitude_m=H)
    with pytest.raises(InvalidInputError, match=message):
        return_statistics(zero)
    # times rounded to the second: each group holds a thousand pulses
    with pytest.raises(InvalidInputError, match="its GPS times do not identify pulses .*1 distinct|its GPS times do not identify"):
        fit_return_model(replace(survey, gps_time=np.floor(survey.gps_time)), altitude_m=H)


def test_a_few_points_sharing_a_time_are_left_out_of_the_gaps_and_the_rest_is_fitted(survey) -> None:
    """A duplicated point is no second return: the groups holding one give no gaps, and the fit goes on."""
    n_dup = int(MAX_AMBIGUOUS_SHARE * len(survey) / 4)  # each puts its 3-return pulse's 4 points in an ambiguous group
    second = np.flatnonzero(survey.return_number == 2)[:n_dup]
    copy = survey.points[second] * [1.0, 1.0, 0.0] + [0.0, 0.0, 0.2]  # return 2 again, 0.2 m above the ground's return 3
    points = np.concatenate([survey.points, copy])
    fields = {k: np.concatenate([getattr(survey, k), getattr(survey, k)[second]]) for k in LasPoints._DTYPES}
    duplicated = LasPoints(points=points, linear_unit_m=1.0, **fields)
    assert las_pulses(duplicated).ambiguous.sum() == n_dup >= 1
    clean, stats = return_statistics(survey, bootstrap=5), return_statistics(duplicated, bootstrap=5)
    # the copy's 0.2 m to return 3 is no gap of a pulse: the gaps are those of the other pulses
    assert stats.estimates["gap_min"].value > 1.4 and stats.estimates["gap_count"].value == clean.estimates["gap_count"].value - 2 * n_dup
    assert fit_return_model(duplicated, altitude_m=H, bootstrap=5).estimates["range_resolution_m"].value > 1.4


def test_a_scan_of_first_returns_only_is_refused_naming_why(survey) -> None:
    first = _first_returns(survey)
    assert len(first) < len(survey) and math.isclose(first.number_of_returns.max(), 3)
    with pytest.raises(InvalidInputError, match=r"^the scan: holds first returns only \(return_number 1 on every point, though its "
                                                r"pulses recorded up to 3\): .*range resolution cannot be fitted; give the scan with all"):  # fmt: skip
        fit_return_model(first, altitude_m=H)
    # each return its own time: returns 2 and 3 kept, but no group holds two of one pulse
    own = replace(survey, gps_time=survey.gps_time + 1e-6 * survey.return_number)
    with pytest.raises(InvalidInputError, match=r"^the scan: no two returns of one pulse share a GPS time"):
        fit_return_model(own, altitude_m=H)


def _subset(las: LasPoints, keep: np.ndarray) -> LasPoints:
    return LasPoints(points=las.points[keep], linear_unit_m=las.linear_unit_m, **{k: getattr(las, k)[keep] for k in LasPoints._DTYPES})


@pytest.mark.parametrize("angle", [89.99, 90.0, -180.0, 120.0])
def test_returns_at_grazing_scan_angles_give_no_energy_figures_not_absurd_ones(survey, angle) -> None:
    """Flat ground at 90° from nadir is infinitely far: the intensity scale would be 1e57 (or negative past 90°)."""
    steep = replace(survey, scan_angle_deg=np.full(len(survey), angle))
    fit = fit_return_model(steep, altitude_m=H, bootstrap=5)
    assert math.isnan(fit.estimates["intensity_scale"].value) and math.isnan(fit.estimates["detection_threshold"].value)
    assert "within 75° of nadir" in fit.why_not_measured["intensity_scale"]
    assert (
        fit.estimates["range_resolution_m"].value
        == fit_return_model(survey, altitude_m=H, bootstrap=5).estimates["range_resolution_m"].value
    )
    # a pulse's half beyond the limit: the energy figures are those of the other half alone
    pulse_of = np.round(survey.gps_time * 1e3).astype(int)
    beyond = pulse_of % 2 == 1
    mixed = replace(survey, scan_angle_deg=np.where(beyond, angle, 0.0))
    scale = fit_return_model(mixed, altitude_m=H, bootstrap=5).estimates["intensity_scale"].value
    assert scale == fit_return_model(_subset(survey, ~beyond), altitude_m=H, bootstrap=5).estimates["intensity_scale"].value
