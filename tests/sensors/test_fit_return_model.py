"""The return model fitted to LAS scans: synthetic scans of known resolution, threshold and intensity scale give them back
within the fit's stated uncertainty; the divergence's inversion of a simulated curve; applying the fit to sensors."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.io.atomic import write_bytes
from zbuf_occlude.io.las import LasPoints, las_bytes, read_las
from zbuf_occlude.sensors.patterns.airborne import AIRBORNE_IDEAL_BEAM
from zbuf_occlude.sensors.patterns.airborne_presets import airborne_preset
from zbuf_occlude.sensors.beam.echoes import hit_energy
from zbuf_occlude.sensors.fit import (
    Estimate,
    divergence_from_shares,
    fit_divergence,
    fit_return_model,
    merge_scans,
)
from zbuf_occlude.sensors.fit.return_model import lower_end
from zbuf_occlude.sensors.beam.footprint import FOOTPRINT_RAYS
from zbuf_occlude.sensors.fit.returns import PulseValues
from zbuf_occlude.sensors.kinds import sensor_from_name, with_beam

#: The synthetic survey's truth: flying height, ground reflectance, intensity scale (counts·m²), range resolution (m),
#: detection threshold (counts).
H, RHO, SCALE, RESOLUTION, THRESHOLD = 1200.0, 0.3, 2.0e10, 0.9, 40


def _survey(n_pulses: int = 4000, seed: int = 0, multi_share: float = 0.35, classes: bool = True) -> dict[str, np.ndarray]:
    """Pulses fired from ``(x, 0, H)`` at scan angles within ±15°: single returns on flat ground (class 2) of intensity
    ``SCALE · hit_energy(1, RHO, cos θ, H / cos θ)`` (lognormal noise, median 1); the rest 2 to 4 returns, the last on the
    ground, the others in trees (class 5) at gaps ``RESOLUTION + Exp(2 m)`` above, of intensity ``THRESHOLD + Exp(60)``."""
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n_pulses):
        theta = math.radians(round(rng.uniform(-15, 15) / 0.006) * 0.006)
        origin, axis = np.array([0.5 * i, 0.0, H]), np.array([0.0, math.sin(theta), -math.cos(theta)])
        ground = H / math.cos(theta)
        n = int(rng.integers(2, 5)) if rng.random() < multi_share else 1
        ranges = ground - np.concatenate([np.cumsum(RESOLUTION + rng.exponential(2.0, n - 1))[::-1], [0.0]])
        for k, r in enumerate(ranges, start=1):
            on_ground = k == n
            if n == 1:
                intensity = SCALE * hit_energy(1.0, RHO, math.cos(theta), ground) * math.exp(0.1 * rng.standard_normal())
            else:
                intensity = THRESHOLD + rng.exponential(60.0)
            rows.append((*(origin + r * axis), round(intensity), k, n, i * 1e-4, math.degrees(theta), 2 if on_ground or not classes else 5))
    cols = [np.array(c) for c in zip(*rows, strict=True)]
    return {"points": np.stack(cols[:3], axis=1), "intensity": cols[3].astype(np.int64), "return_number": cols[4].astype(np.int64),
            "number_of_returns": cols[5].astype(np.int64), "gps_time": cols[6], "scan_angle_deg": cols[7],
            "classification": (cols[8] if classes else np.zeros(len(rows))).astype(np.int64)}  # fmt: skip


@pytest.fixture(scope="module")
def survey_las(tmp_path_factory) -> LasPoints:
    path = tmp_path_factory.mktemp("las") / "survey.laz"
    write_bytes(path, las_bytes(**_survey(), compress=True))
    return read_las(path)


@pytest.fixture(scope="module")
def survey_fit(survey_las):
    return fit_return_model(survey_las, altitude_m=H, ground_reflectance=RHO, classes=(5,))


def _within(e: Estimate, truth: float, slack: float = 0.0) -> bool:
    return abs(e.value - truth) <= 3.0 * e.std + slack


def test_a_synthetic_survey_gives_back_its_resolution_threshold_and_scale_within_the_stated_uncertainty(survey_fit) -> None:
    e = survey_fit.estimates
    assert _within(e["range_resolution_m"], RESOLUTION, 0.001) and e["range_resolution_m"].std < 0.05  # 1 mm coordinate steps
    assert _within(e["detection_threshold_counts"], THRESHOLD, 0.5)  # whole counts
    assert _within(e["intensity_scale"], SCALE) and e["intensity_scale"].std < 0.01 * SCALE
    assert e["detection_threshold"].value == pytest.approx(e["detection_threshold_counts"].value / e["intensity_scale"].value)
    assert _within(e["detection_threshold"], THRESHOLD / SCALE, 0.5 / SCALE)
    assert e["max_returns"].value == 4 and e["max_returns"].std == 0
    assert survey_fit.ground == "class 2" and survey_fit.unit_assumed and survey_fit.unit_m == 1.0
    assert math.isnan(e["beam_divergence_deg"].value) and "beam axis" in survey_fit.why_not_measured["beam_divergence_deg"]
    # per class: the trees' gaps and intensities hold the same bounds; their apparent reflectance is theirs over the ground's
    assert _within(e["range_resolution_m_class_5"], RESOLUTION, 0.001) and _within(e["detection_threshold_counts_class_5"], THRESHOLD, 0.5)
    assert "intensity_ratio_class_2" not in e and "reflectance_class_2" not in e  # the ground's are the given ones


def test_the_lower_end_is_neither_the_minimum_nor_the_first_percentile() -> None:
    rng = np.random.default_rng(1)
    values = np.concatenate([[0.2], 1.0 + rng.uniform(0.0, 5.0, 20_000)])  # one outlier below a flat density from 1
    v = PulseValues(values, np.arange(len(values)))
    assert lower_end(v, 0.01) == pytest.approx(1.0, abs=0.01)
    assert v.quantile(0.01) == pytest.approx(1.05, abs=0.01) and v.quantile(0.0) == 0.2
    few = PulseValues(np.array([3.0, 4.0]), np.arange(2))
    assert lower_end(few, 0.01) == 3.0  # never below the least value
    assert math.isnan(lower_end(PulseValues(np.zeros(0), np.zeros(0, np.int64)), 0.01))


@settings(max_examples=25, deadline=None)
@given(altitude=st.floats(10.0, 5000.0), reflectance=st.floats(0.01, 1.0))
def test_law_the_scale_grows_as_the_altitude_squared_over_the_reflectance_and_counts_do_not_move(survey_las, altitude, reflectance) -> None:
    """E = ρ cos θ / R² with R = H / cos θ: the counts per unit energy are ∝ H² / ρ; what is in counts or metres stays."""
    base = fit_return_model(survey_las, altitude_m=H, ground_reflectance=RHO, classes=None, bootstrap=2)
    other = fit_return_model(survey_las, altitude_m=altitude, ground_reflectance=reflectance, classes=None, bootstrap=2)
    factor = (altitude / H) ** 2 * RHO / reflectance
    assert other.estimates["intensity_scale"].value == pytest.approx(factor * base.estimates["intensity_scale"].value, rel=1e-9)
    assert other.estimates["detection_threshold"].value == pytest.approx(base.estimates["detection_threshold"].value / factor, rel=1e-9)
    for name in (
        "range_resolution_m",
        "detection_threshold_counts",
        "max_returns",
        "intensity_sum_ratio",
        "detection_threshold_counts_class_5",
    ):
        assert other.estimates[name].value == pytest.approx(base.estimates[name].value, rel=1e-12)


def test_the_files_unit_scales_the_gaps_and_tiles_merge_into_the_whole(survey_las) -> None:
    fields = {k: getattr(survey_las, k) for k in ("points", *LasPoints._DTYPES)}
    feet = LasPoints(**fields, linear_unit_m=0.3048)
    whole = fit_return_model(survey_las, altitude_m=H, classes=None, bootstrap=2)
    in_feet = fit_return_model(feet, altitude_m=H, classes=None, bootstrap=2)
    assert in_feet.estimates["range_resolution_m"].value == pytest.approx(0.3048 * whole.estimates["range_resolution_m"].value)
    assert not in_feet.unit_assumed and in_feet.unit_m == 0.3048
    # two tiles cut through the middle of the survey, pulses split between them: merged, the figures are the whole's
    west = survey_las.points[:, 0] < np.median(survey_las.points[:, 0])
    tiles = [LasPoints(**{k: v[mask] for k, v in fields.items()}) for mask in (west, ~west)]
    merged = fit_return_model(merge_scans(tiles, ["west.laz", "east.laz"]), altitude_m=H, classes=None, bootstrap=2)
    assert {k: e.value for k, e in merged.estimates.items()} == pytest.approx({k: e.value for k, e in whole.estimates.items()}, nan_ok=True)
    with pytest.raises(InvalidInputError, match=r"east\.laz: its coordinates are in 0\.3048 m units"):
        merge_scans([tiles[0], replace(tiles[1], linear_unit_m=0.3048)], ["west.laz", "east.laz"])
    with pytest.raises(ArgumentTypeError, match="LasPoints"):
        merge_scans([tiles[0], "east.laz"])
    with pytest.raises(InvalidInputError, match="no scans"):
        merge_scans([])


def test_without_a_ground_class_the_lowest_single_returns_are_the_ground() -> None:
    columns = _survey(n_pulses=1500, classes=False)
    n = len(columns["points"])
    las = LasPoints(**columns, point_source_id=np.zeros(n, np.int64), scanner_channel=np.zeros(n, np.int64))
    fit = fit_return_model(las, altitude_m=H, ground_reflectance=RHO, bootstrap=20)
    assert fit.ground.startswith("single returns within 0.5 m of the lowest return")
    assert _within(fit.estimates["intensity_scale"], SCALE)


def test_applied_to_sensors(survey_fit) -> None:
    e = survey_fit.estimates
    preset = airborne_preset("riegl-q1560")
    airborne, origin = survey_fit.applied(preset)
    assert (airborne.beam.max_returns, airborne.beam.range_resolution_m) == (4, e["range_resolution_m"].value)
    assert airborne.name == "riegl-q1560-fitted" and "returns fitted to 4,000 pulses" in airborne.source and airborne.altitude_m == H
    # no divergence measured; the intensity scale measured is applied, in 16-bit counts
    assert survey_fit.sets(airborne) == ("range_resolution_m", "max_returns", "detection_threshold", "intensity_scale")
    assert airborne.beam.detection_threshold == e["detection_threshold"].value
    assert (airborne.beam.intensity_scale, airborne.beam.max_intensity) == (e["intensity_scale"].value, 65_535)
    # the rest of the beam is the data sheet's: its footprint, wavelength, range noise
    fitted_fields = ("max_returns", "range_resolution_m", "detection_threshold", "intensity_scale", "max_intensity")
    assert airborne.beam == preset.beam.with_(**{name: getattr(airborne.beam, name) for name in fitted_fields})
    assert set(origin["fitted"]) == {"max_returns", "range_resolution_m", "detection_threshold", "intensity_scale"}
    assert origin["data_sheet"] == {} and origin["model"] == {"max_intensity": 65_535} and "riegl-q1560" in origin["kept"]
    lidar, origin = survey_fit.applied(sensor_from_name("hdl32e"))
    assert lidar.beam.detection_threshold == pytest.approx(e["detection_threshold"].value)
    assert "| detection_threshold |" in survey_fit.markdown(lidar) and "| yes |" in survey_fit.markdown(lidar)
    # a spinning LiDAR of one ray: several returns need a footprint, the data sheet's divergence with FOOTPRINT_RAYS sub-rays
    assert (lidar.beam.max_returns, lidar.beam.footprint_rays, lidar.beam.divergence_deg) == (4, FOOTPRINT_RAYS, 0.16)
    assert origin["data_sheet"] == {"divergence_deg": 0.16} and origin["model"]["footprint_rays"] == FOOTPRINT_RAYS
    assert "HDL-32E" in origin["source"]
    # a divergence fitted by simulation: the scanner gets it, and keeps its footprint of sub-rays
    with_divergence = replace(survey_fit, estimates={**e, "beam_divergence_deg": Estimate(0.02, 0.002, 10, "simulated", "deg")})
    fitted = with_divergence.apply(preset)
    assert fitted.beam.divergence_deg == 0.02 and fitted.beam.footprint_rays == preset.beam.footprint_rays
    one_ray = with_divergence.apply(with_beam(preset, footprint_rays=1))
    assert one_ray.beam.divergence_deg == 0.02 and one_ray.beam.footprint_rays == FOOTPRINT_RAYS
    # one return per pulse: no resolution; the footprint gives the strongest echo, the threshold applies
    single = replace(survey_fit, estimates={**with_divergence.estimates, "max_returns": Estimate(1.0, 0.0, 10, "count")})
    one = single.apply(preset)
    assert (one.beam.max_returns, one.beam.range_resolution_m) == (1, 0.0)
    assert one.beam.detection_threshold == e["detection_threshold"].value
    with pytest.raises(ArgumentTypeError, match="Lidar or an AirborneScanner"):
        survey_fit.apply("riegl-q1560")


def test_a_beam_without_a_footprint_gets_its_presets_data_sheet_divergence(survey_fit) -> None:
    """A scanner file of the preset's name whose beam lost its footprint (one ray, no divergence) gets the preset's back."""
    preset = airborne_preset("riegl-q1560")
    bare = with_beam(preset, footprint_rays=1, divergence_deg=0.0)
    fitted, origin = survey_fit.applied(bare)
    assert (fitted.beam.divergence_deg, fitted.beam.footprint_rays) == (preset.beam.divergence_deg, FOOTPRINT_RAYS)
    assert origin["data_sheet"] == {"divergence_deg": preset.beam.divergence_deg} and origin["source"] == preset.beam.source
    # no preset of its name: no divergence to give, one ray kept, and the table says why it records one return
    other = replace(bare, name="my-scanner")
    fitted, origin = survey_fit.applied(other)
    assert (fitted.beam.divergence_deg, fitted.beam.footprint_rays, origin["data_sheet"]) == (0.0, 1, {})
    assert "casts one ray per pulse" in survey_fit.markdown(fitted)


def test_per_class_statistics_are_each_class_points_multi_return_share_and_median_intensity(survey_las, survey_fit) -> None:
    from zbuf_occlude.sensors.fit.engine import class_statistics

    # every third return recorded no intensity (0): left out of the medians
    las = replace(
        survey_las, intensity=np.where(np.arange(len(survey_las)) % 3 == 0, 0, survey_las.intensity).astype(survey_las.intensity.dtype)
    )
    per_class = class_statistics(las, survey_fit.statistics)
    assert list(per_class) == ["2", "5"]  # ground and high vegetation, in code order
    for code, figures in per_class.items():
        mine = las.classification == int(code)
        assert figures["points"] == int(mine.sum())
        assert figures["multi_return_share"] == pytest.approx(float(np.mean(las.number_of_returns[mine] > 1)))
        assert 0 <= figures["multi_return_share_std"] < 0.05
        recorded = las.intensity[mine & (las.intensity > 0)]
        assert figures["intensity_median"] == float(np.median(recorded))
    assert per_class["5"]["multi_return_share"] == 1.0 and per_class["2"]["multi_return_share"] < 1.0  # trees: first of several
    assert per_class["2"]["multi_return_share_std"] > 0
    json.dumps(per_class, allow_nan=False)  # strict JSON
    # a scan never classified (class 0 everywhere) has no per-class figures
    columns = _survey(n_pulses=300, classes=False)
    n = len(columns["points"])
    bare = LasPoints(**columns, point_source_id=np.zeros(n, np.int64), scanner_channel=np.zeros(n, np.int64))
    assert class_statistics(bare, fit_return_model(bare, altitude_m=H, bootstrap=5).statistics) == {}


def test_the_fit_reads_as_strict_json_and_a_table(survey_fit) -> None:
    out = json.loads(json.dumps(survey_fit.to_json(), allow_nan=False))
    assert out["estimates"]["beam_divergence_deg"]["value"] is None and out["altitude_m"] == H
    assert out["statistics"]["n_pulses"] == 4000 and out["ground"] == "class 2"
    text = survey_fit.markdown()
    assert "metres assumed" in text and "not measured (returns lie on the beam axis" in text and "| returns_1 |" in text


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"altitude_m": 0.0}, InvalidInputError, r"altitude_m must be in \(0, 1e\+06\], got a number outside that range"),
        ({"altitude_m": math.nan}, InvalidInputError, r"altitude_m must be in \(0, 1e\+06\], got NaN"),
        ({"altitude_m": True}, ArgumentTypeError, "altitude_m must be a number"),
        ({"altitude_m": "1000"}, ArgumentTypeError, "altitude_m must be a number"),
        ({"altitude_m": 1000.0, "ground_reflectance": 1.5}, InvalidInputError, r"ground_reflectance must be in \(0, 1\], got a number outside that range"),
        ({"altitude_m": 1000.0, "divergence_shares": ([0.01, 0.02], [0.1, 0.2]), "divergence_share": "multi_return_points_class_9"},
         InvalidInputError, "'multi_return_points_class_9' is not a figure"),
        ({"altitude_m": 1000.0, "bootstrap": 1}, InvalidInputError, "bootstrap must be >= 2"),
    ],
)  # fmt: skip
def test_bad_arguments_are_refused_naming_them(survey_las, kwargs, error, match) -> None:
    with pytest.raises(error, match=match):
        fit_return_model(survey_las, **kwargs)


def test_a_scan_is_a_las_points_with_gps_times(survey_las) -> None:
    with pytest.raises(ArgumentTypeError, match="LasPoints"):
        fit_return_model(np.zeros((3, 3)), altitude_m=100.0)
    with pytest.raises(InvalidInputError, match="no GPS time"):
        fit_return_model(replace(survey_las, has_gps_time=False, point_format_id=0), altitude_m=100.0)


def _share(d):
    """A multi-return share that grows with the divergence (degrees) and saturates."""
    return 1.0 - np.exp(-np.asarray(d) / 0.02)


def test_the_divergence_is_the_simulated_curves_inverse_at_the_measured_share() -> None:
    grid = np.linspace(0.005, 0.1, 60)
    truth, sigma = 0.03, 0.005
    e = divergence_from_shares(grid, _share(grid), Estimate(float(_share(truth)), sigma, 1000, "measured", "share"))
    assert e.value == pytest.approx(truth, rel=1e-3) and e.unit == "deg"
    slope = math.exp(-truth / 0.02) / 0.02  # d share / d divergence
    assert e.std == pytest.approx(sigma / slope, rel=0.02)
    # the simulation's own spread adds in quadrature
    noisy = divergence_from_shares(grid, _share(grid), Estimate(float(_share(truth)), sigma, 1000, "m", "share"), np.full(60, sigma))
    assert noisy.std == pytest.approx(math.sqrt(2) * e.std, rel=0.02)
    # fit_divergence calls the simulation at each divergence
    calls = []
    fitted, simulated, shares = fit_divergence(lambda x: (calls.append(x), (float(_share(x)), 0.0))[1],
                                       Estimate(float(_share(truth)), sigma, 1000, "m", "share"), divergences_deg=grid)  # fmt: skip
    assert (
        calls == pytest.approx(grid.tolist()) == simulated.tolist()
        and fitted.value == pytest.approx(truth, rel=1e-3)
        and shares == pytest.approx(_share(grid))
    )
    outside = divergence_from_shares(grid, _share(grid), Estimate(0.999, 0.01, 10, "m", "share"))
    assert math.isnan(outside.value) and math.isnan(outside.std)


@pytest.mark.parametrize(
    ("d", "s", "match"),
    [([0.01], [0.1], "M >= 2"), ([0.02, 0.01], [0.1, 0.2], "strictly increasing"), ([0.0, 0.01], [0.1, 0.2], "> 0"),
     ([0.01, 0.02], [0.3, 0.2], "must grow"), ([0.01, 0.02], [0.2, 0.2], "must grow"), ([0.01, 0.02], [0.1, 1.2], r"\[0, 1\]"),
     ([0.01, np.nan], [0.1, 0.2], "finite")],
)  # fmt: skip
def test_a_curve_that_cannot_be_inverted_is_refused(d, s, match) -> None:
    with pytest.raises(InvalidInputError, match=match):
        divergence_from_shares(d, s, Estimate(0.15, 0.01, 10, "m", "share"))


@settings(max_examples=60, deadline=None)
@given(steps=st.lists(st.floats(0.0, 0.2), min_size=2, max_size=12), where=st.floats(0.0, 1.0))
def test_law_the_inverse_meets_the_curve(steps, where) -> None:
    """Any non-decreasing curve that rises: the share at the fitted divergence (linear between the points) is the measured one."""
    shares = np.minimum(np.cumsum(steps), 1.0)
    if shares[-1] == shares[0]:
        return
    grid = np.linspace(0.01, 0.01 * len(shares), len(shares))
    target = float(shares[0] + where * (shares[-1] - shares[0]))
    e = divergence_from_shares(grid, shares, Estimate(target, 0.0, 1, "m", "share"))
    assert grid[0] <= e.value <= grid[-1]
    assert np.interp(e.value, grid, shares) == pytest.approx(target, abs=1e-9)


def test_a_simulated_survey_gives_back_its_divergence_within_the_stated_uncertainty() -> None:
    """The user's scan: a 19-ray airborne scanner of a 2° beam over a 10 m box; its multi-return share, inverted through
    the same scanner simulated at other divergences (other seeds), gives 2° back."""
    import trimesh

    import zbuf_occlude as zo
    from zbuf_occlude.sensors import AirborneScanner, scan_airborne
    from zbuf_occlude.sensors.fit import return_statistics

    scene = zo.ScanScene(objects=[zo.SceneObject(trimesh.creation.box((1, 1, 1)), "box", (0.0, 0.0), 0.0, (6.0, 6.0, 10.0))])

    def share(divergence_deg: float, seed: int) -> Estimate:
        als = AirborneScanner("als", swath_deg=20.0, pulse_rate_hz=4000.0, line_rate_hz=20.0, altitude_m=100.0, speed_mps=10.0,
                              beam=AIRBORNE_IDEAL_BEAM.with_(divergence_deg=divergence_deg, footprint_rays=19, max_returns=4,
                                                             range_resolution_m=1.0))  # fmt: skip
        s = scan_airborne(scene, als, (0.0, 0.0), 10.0, seed=seed)
        zeros = np.zeros(len(s), np.int64)
        las = LasPoints(points=s.points.astype(np.float64), intensity=zeros, return_number=s.return_number, number_of_returns=s.number_of_returns,
                        gps_time=s.gps_time, scan_angle_deg=s.scan_angle_deg, classification=zeros, point_source_id=zeros, scanner_channel=zeros)  # fmt: skip
        return return_statistics(las, classes=None, bootstrap=20).estimates["multi_return_points"]

    measured = share(2.0, seed=7)

    def simulate(divergence_deg: float) -> tuple[float, float]:
        e = share(divergence_deg, seed=0)
        return e.value, e.std

    fitted, _, shares = fit_divergence(simulate, measured, divergences_deg=np.linspace(0.5, 4.0, 6))
    assert np.all(np.diff(shares) > 0)  # a wider beam clips the box's edges on more pulses
    assert _within(fitted, 2.0) and 0 < fitted.std < 0.3, fitted


def test_a_scan_too_large_for_the_memory_is_refused_before_the_fit(survey_las, monkeypatch) -> None:
    from zbuf_occlude import resources
    from zbuf_occlude.errors import InsufficientMemoryError
    from zbuf_occlude.sensors.fit.return_model import FIT_BYTES_PER_POINT

    # enough for the return statistics (256 bytes a point), not for the fit's
    monkeypatch.setattr(resources, "MIN_CHECKED_BYTES", 0)
    monkeypatch.setattr(resources, "available_memory", lambda: (len(survey_las) * (FIT_BYTES_PER_POINT - 64), "test budget"))
    with pytest.raises(InsufficientMemoryError, match="the return model fit of 6,"):
        fit_return_model(survey_las, altitude_m=H, bootstrap=2)


def test_a_table_of_simulated_shares_reads_as_a_curve(survey_las) -> None:
    from zbuf_occlude.sensors.fit import divergence_curve

    rows = [{"divergence_deg": str(d), "multi_return_points": str(s), "std": "0.01"} for d, s in ((0.01, 0.1), (0.03, 0.9))]
    figure, d, s, sd = divergence_curve(rows, "curve.csv")
    assert figure == "multi_return_points" and d.tolist() == [0.01, 0.03] and s.tolist() == [0.1, 0.9] and sd.tolist() == [0.01] * 2
    fit = fit_return_model(survey_las, altitude_m=H, divergence_shares=(d, s, sd), divergence_share=figure, bootstrap=5)
    share = fit.statistics.estimates[figure]
    assert 0.1 < share.value < 0.9
    assert fit.estimates["beam_divergence_deg"].value == pytest.approx(0.01 + 0.02 * (share.value - 0.1) / 0.8)
    assert fit.estimates["beam_divergence_deg"].std > 0.02 * 0.01 / 0.8  # the simulation's 0.01 adds to the share's spread
    with pytest.raises(InvalidInputError, match=r"curve\.csv: row 2: std is not a number"):
        divergence_curve([{**rows[0], "std": "n/a"}, rows[1]], "curve.csv")


def test_a_detection_threshold_below_any_sensor_names_the_altitude_it_rests_on(survey_las) -> None:
    from zbuf_occlude.sensors.fit.fitted_beam import MIN_DETECTION_THRESHOLD

    lidar = sensor_from_name("hdl32e")
    fit = fit_return_model(survey_las, altitude_m=1e6, ground_reflectance=RHO, classes=(5,), bootstrap=5)
    assert fit.estimates["detection_threshold"].value < MIN_DETECTION_THRESHOLD
    with pytest.raises(InvalidInputError, match=r"^the fitted detection threshold .* m⁻² is below the energy a white target returns from "
                                                r"1e\+06 m, .*altitude_m 1e\+06 is likely not the scans' flying height$"):  # fmt: skip
        fit.apply(lidar)
