"""The return model of a scanner fitted to the user's own LAS/LAZ scans: what the echo model can set, with its uncertainty.

The echo model (:mod:`zbuf_occlude.sensors.beam.echoes`) sends back from each surface a pulse's
sub-ray meets the energy ``w · ρ · |cos θ| / R²`` (m⁻², :func:`~zbuf_occlude.sensors.beam.echoes.hit_energy`),
merges echoes closer than the range resolution, drops those below the detection threshold and
keeps the first ``max_returns``.  Measured on the points of a scan
(:class:`~zbuf_occlude.io.las.LasPoints`, grouped into pulses by
:func:`~zbuf_occlude.sensors.fit.las_pulses.las_pulses`):

``range_resolution_m``
    The least range between two returns of one pulse (``c·τ/2``): the lower end of the gaps
    between consecutive returns of a pulse (3D distance, metres; a pulse's returns lie on its
    beam axis, so that is their range difference), told from their 1st and 2nd percentiles
    (:func:`lower_end`, :data:`RESOLUTION_QUANTILE`): not the minimum, which one pair of noisy
    returns moves, and not the 1st percentile, which lies above the bound by the density there.
    Gaps are measured where the pulse holds both returns, complete or not.
``max_returns``
    The most returns any pulse of the scan recorded (``number_of_returns``).
``detection_threshold_counts``
    The weakest echo detected, in intensity counts: the lower end (:func:`lower_end`,
    :data:`DETECTION_QUANTILE`) of the intensities of every return, zeros left out (ASPRS LAS
    1.4 R15 §2.6: an intensity of 0 means none was recorded).
``intensity_scale``
    Counts per unit of received energy, from single returns on the ground (class
    :data:`GROUND_CLASS` when it holds :data:`MIN_CLASS_POINTS` single returns; else the lowest
    single returns, those within :data:`LOWEST_SLAB_M` of the lowest return of their
    :data:`LOWEST_CELL_M` cell; within :data:`MAX_SCAN_ANGLE_DEG` of nadir): the median of ``I / E`` with ``E = hit_energy(1, ρ_g, cos θ,
    H / cos θ)``, ``ρ_g`` the ground's reflectance (a parameter, :data:`GROUND_REFLECTANCE` by
    default), ``θ`` the point's scan angle (flat ground: the incidence is the scan angle) and
    ``H`` the flying height above the ground (a parameter: a LAS file records no sensor position).
``detection_threshold``
    ``detection_threshold_counts / intensity_scale``, m⁻², the model's threshold
    (:func:`~zbuf_occlude.sensors.beam.echoes.resolve_echoes`), each resample's ratio.
``beam_divergence_deg``
    **Not measurable from the points**: a scanner places every return of a pulse on the beam's
    axis (the point is the origin plus range times the axis), so the returns of one pulse show
    no lateral spread to read a footprint from: in the IGN LiDAR HD sample the middle return of
    a three-return pulse lies a median 5 mm off the line through the other two (709 pulses; the
    coordinates are stored in 1 cm steps), where a 0.25 mrad beam's footprint at 1,500 m is
    0.37 m wide.  It is fitted by simulation instead (:func:`~zbuf_occlude.sensors.fit.divergence.fit_divergence`,
    :func:`~zbuf_occlude.sensors.fit.divergence.divergence_from_shares`, :mod:`.divergence`): the multi-return share simulated at several divergences,
    inverted at the measured share (a simulated survey of a 2° beam over a box gives 2.01 ± 0.11°
    back; ``fit-sensor --divergence-shares`` reads the curve from a table, :func:`~zbuf_occlude.sensors.fit.divergence.divergence_curve`).
    Without such a curve it is reported not measured and the sensor keeps its own.
``intensity_ratio_ground``, ``intensity_sum_ratio``
    Checks of the energy model: the median intensity of first-of-several returns on the ground
    over that of single returns there (the model gives the share of the footprint the first
    surface takes), and the median summed intensity of a complete pulse of several returns over
    the median single return (the model conserves the footprint's energy: 1 where every surface
    has the ground's reflectance, incidence and range).
Per class of the file with :data:`MIN_CLASS_POINTS` points: ``range_resolution_m_class_<c>``
(gaps whose farther return is of class c), ``detection_threshold_counts_class_<c>``,
``intensity_ratio_class_<c>`` and ``reflectance_class_<c>``, the apparent reflectance of the
class's single returns against the ground's: ``ρ_g`` times the ratio of the medians of
``I · R² / cos θ`` (no reflectance in the model is measured on its own; this is the class's
reflectance where the footprint is filled).  The ground's class has no ratio or reflectance of
its own when it is the ground (``intensity_ratio_ground``; its reflectance is the one given).

The intensity scale and the threshold in m⁻² depend on the flying height and the ground's
reflectance given (the scale goes as ``H² / ρ_g``); nothing else does.

Uncertainties: the standard deviation over a bootstrap over pulses
(:func:`~zbuf_occlude.sensors.fit.returns.pulse_bootstrap`, seeded), as the return statistics'
(:func:`~zbuf_occlude.sensors.fit.returns.return_statistics`, which the fit reports beside).
Coordinates are in metres where the file states its unit; where it does not (a file without a
coordinate reference system, as ours), metres are assumed and the fit says so.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.geometry.arguments import described
from zbuf_occlude.io.las import LasPoints
from zbuf_occlude.resources import check_memory
from zbuf_occlude.sensors.beam.echoes import hit_energy
from zbuf_occlude.sensors.checks import MAX_RANGE_M, given, real, text
from zbuf_occlude.sensors.fit.divergence import check_curve, divergence_from_shares
from zbuf_occlude.sensors.fit.lidar import BOOTSTRAP, Estimate, estimates_markdown
from zbuf_occlude.sensors.fit.las_pulses import check_pulses, check_return_pairs, las_pulses
from zbuf_occlude.sensors.fit.returns import (
    VEGETATION_CLASSES, PulseValues, ReturnStatistics, check_classes, multi_return_shares, pulse_bootstrap, pulse_statistics,
)  # fmt: skip
from zbuf_occlude.sensors.scene.materials import reflectance

__all__ = [
    "ALS_WAVELENGTH_NM", "DETECTION_QUANTILE", "FIT_BYTES_PER_POINT", "GROUND_CLASS", "GROUND_MATERIAL",
    "GROUND_REFLECTANCE", "LOWEST_CELL_M", "LOWEST_SLAB_M", "MAX_SCAN_ANGLE_DEG", "MIN_CLASS_POINTS", "RESOLUTION_QUANTILE", "ReturnModelFit",
    "fit_return_model", "lower_end", "merge_scans",
]  # fmt: skip

#: The low quantile q of the gaps between a pulse's returns whose line to 2q tells the range
#: resolution (:func:`lower_end`; IGN LiDAR HD sample: Q(0.01) 0.87 m, Q(0.02) 0.90 m, its
#: minimum 0.82 m rests on one pair).
RESOLUTION_QUANTILE = 0.01
#: The same q for the (non-zero) intensities: the weakest echo detected.
DETECTION_QUANTILE = 0.01
#: ASPRS class of the ground (R15, Table 17).
GROUND_CLASS = 2
#: The ground's material when no reflectance is given, and the wavelength of airborne scanners
#: (Nd:YAG, 1064 nm: RIEGL's LMS-Q and VQ series, Leica's ALS): open ground of a survey is a mix
#: of soil (0.33), grass (0.50) and roads (0.17); soil is its middle.
GROUND_MATERIAL, ALS_WAVELENGTH_NM = "soil", 1064.0
#: The ground's reflectance when none is given: :data:`GROUND_MATERIAL` at :data:`ALS_WAVELENGTH_NM`
#: in the cited table (:func:`~zbuf_occlude.sensors.scene.materials.reflectance`, ASTER soils).  It
#: scales ``intensity_scale`` and ``detection_threshold`` inversely: give your ground's.
GROUND_REFLECTANCE = reflectance(GROUND_MATERIAL, ALS_WAVELENGTH_NM)
#: Fewest points of a class for its own figures (and single ground returns for the ground's).
MIN_CLASS_POINTS = 100
#: Without a ground class: the cell, metres, whose lowest return starts its ground...
LOWEST_CELL_M = 10.0
#: ... and the slab above that lowest return counted as ground, metres.
LOWEST_SLAB_M = 0.5
#: Largest scan angle from nadir, degrees, of the returns the energy figures (intensity scale, threshold in m⁻²,
#: reflectances) use: they take the flat ground's range ``H / cos θ`` and incidence θ, which at grazing angles no longer
#: hold (cos 75° = 0.26; airborne scanners sweep within ±40°: RIEGL VQ-1560 ±29°); a file's angles may reach ±180°.
MAX_SCAN_ANGLE_DEG = 75.0
#: Bytes per point the fit holds at once (sorted copies, per-figure sorted values and their pulses;
#: a class's figures hold its points only): tracemalloc's peak was 279 on the IGN sample (7
#: classes) and 198 on Autzen (2).
FIT_BYTES_PER_POINT = 384


@dataclass(frozen=True)
class ReturnModelFit:
    """The return model fitted to a scan (module docstring), with the scan's return statistics.

    Attributes
    ----------
    estimates : dict of str to Estimate
        The fitted quantities (module docstring), each ``value ± std`` with its unit, count and
        how it was measured; NaN where the scan does not tell it.
    statistics : ReturnStatistics
        The per-pulse figures the fit rests on (:func:`~zbuf_occlude.sensors.fit.returns.return_statistics`).
    altitude_m : float
        The flying height above the ground assumed, metres.
    ground_reflectance : float
    ground : str
        Which returns were the ground: ``"class 2"`` or ``"lowest returns"`` (or ``"none"``).
    unit_m : float
        Metres per coordinate unit used.
    unit_assumed : bool
        Whether the file did not state its unit (metres assumed).
    why_not_measured : dict of str to str
        Per estimate left NaN, why.
    """

    estimates: dict[str, Estimate]
    statistics: ReturnStatistics
    altitude_m: float
    ground_reflectance: float
    ground: str
    unit_m: float
    unit_assumed: bool
    why_not_measured: dict[str, str]

    def sets(self, sensor: Any) -> tuple[str, ...]:
        """The estimates :meth:`apply` sets in ``sensor``'s beam: those measured
        (:func:`~zbuf_occlude.sensors.fit.fitted_beam.fitted_sets`)."""
        from zbuf_occlude.sensors.fit.fitted_beam import fitted_sets

        return fitted_sets(self.estimates, sensor)

    def apply(self, sensor: Any) -> Any:
        """``sensor`` (a spinning LiDAR or an airborne scanner) with the fitted return model in its beam (:meth:`applied`)."""
        return self.applied(sensor)[0]

    def applied(self, sensor: Any) -> tuple[Any, dict]:
        """``sensor`` with the fitted return model, and where each of its beam's changed fields came from.

        The beam's ``max_returns``, ``range_resolution_m``, ``detection_threshold``, ``intensity_scale`` (with 16-bit
        ``max_intensity``) and a fitted ``divergence_deg`` are the fit's; a beam of several returns and one ray gets the
        data sheet's divergence and :data:`~zbuf_occlude.sensors.beam.footprint.FOOTPRINT_RAYS` sub-rays; every other field
        is the base's; an airborne scanner's ``altitude_m`` becomes the flying height the fit assumed
        (:func:`~zbuf_occlude.sensors.fit.fitted_beam.fitted_sensor`, which says what the dict holds).  The name gains
        ``-fitted`` and the source says what was fitted.

        Raises
        ------
        ArgumentTypeError
            ``sensor`` is not a LiDAR or an airborne scanner.
        InvalidInputError
            A detection threshold so low that it rests on a wrong altitude (naming it); fitted values that make a beam
            its checks refuse (naming the field).
        """
        from zbuf_occlude.sensors.fit.fitted_beam import fitted_sensor

        return fitted_sensor(self.estimates, sensor, altitude_m=self.altitude_m, n_pulses=self.statistics.n_pulses)

    def markdown(self, sensor: Any = None) -> str:
        """The fit's table (quantity, value ± std, unit, n, whether it sets ``sensor``, how measured), what was
        assumed, then the return statistics' table."""
        sets = set(self.sets(sensor)) if sensor is not None else set()
        shown = {name: replace(e, set_in_sensor=name in sets) for name, e in self.estimates.items()}
        unit = "metres assumed (the file states no unit)" if self.unit_assumed else f"{self.unit_m:g} m per coordinate unit"
        note = ""
        if sensor is not None and sensor.beam.footprint_rays == 1 and sensor.beam.max_returns > 1:
            note = (f"\n{sensor.name} casts one ray per pulse, which meets one surface: it records one return per pulse until its "
                    "beam is given a divergence_deg and footprint_rays above 1 (in its file), or a divergence fitted by simulation "
                    "(fit_divergence).\n")  # fmt: skip
        return (
            f"Flying height {self.altitude_m:g} m above the ground (given), ground reflectance {self.ground_reflectance:g} "
            f"({'soil at 1064 nm, sensors.reflectance' if self.ground_reflectance == GROUND_REFLECTANCE else 'given'}), "
            f"ground: {self.ground}; coordinates: {unit}.\n\n"
            + estimates_markdown(shown, self.why_not_measured)
            + note
            + "\nThe return statistics the fit rests on:\n\n"
            + self.statistics.markdown()
        )

    def to_json(self) -> dict[str, Any]:
        """The fit as a strict-JSON object (``null`` where not measured), the statistics under ``"statistics"``."""
        return {
            "altitude_m": self.altitude_m, "ground_reflectance": self.ground_reflectance, "ground": self.ground,
            "unit_m": self.unit_m, "unit_assumed": self.unit_assumed, "why_not_measured": dict(self.why_not_measured),
            "estimates": {name: e.to_json() for name, e in self.estimates.items()}, "statistics": self.statistics.to_json(),
        }  # fmt: skip


def merge_scans(scans: Sequence[LasPoints], names: Sequence[str] | None = None) -> LasPoints:
    """Several scans (tiles or crops of one survey) as one: their points, one after the other.

    The returns of a pulse cut by a tile's edge come together again (pulses are keyed by GPS
    time, point source and channel).  Every scan must state the same coordinate unit (or none).

    Raises
    ------
    ArgumentTypeError
        An item is not a :class:`~zbuf_occlude.io.las.LasPoints`.
    InvalidInputError
        No scans; scans of different units or of which some have GPS times and others not (naming them).
    """
    scans = list(scans)
    names = list(names) if names is not None else [f"scan {i}" for i in range(len(scans))]
    if not scans:
        raise InvalidInputError("no scans to merge")
    for s in scans:
        if not isinstance(s, LasPoints):
            raise ArgumentTypeError(f"scans must be LasPoints (read them with zbuf_occlude.io.las.read_las), got {described(s)}")
    if len(scans) == 1:
        return scans[0]
    first = scans[0]
    for s, name in zip(scans[1:], names[1:], strict=True):
        same_unit = s.linear_unit_m == first.linear_unit_m or not (math.isfinite(s.linear_unit_m) or math.isfinite(first.linear_unit_m))
        if not same_unit:
            raise InvalidInputError(f"{name}: its coordinates are in {s.linear_unit_m:g} m units, {names[0]}'s in {first.linear_unit_m:g}: "
                                    "fit scans of one unit together")  # fmt: skip
        if s.has_gps_time != first.has_gps_time:
            raise InvalidInputError(f"{name}: point format {s.point_format_id} {'has' if s.has_gps_time else 'has no'} GPS time, "
                                    f"{names[0]}'s {first.point_format_id} {'has' if first.has_gps_time else 'has no'}")  # fmt: skip
    arrays = {key: np.concatenate([getattr(s, key) for s in scans]) for key in ("points", *LasPoints._DTYPES)}
    return LasPoints(**arrays, has_gps_time=first.has_gps_time, point_format_id=first.point_format_id, version=first.version,
                     linear_unit_m=first.linear_unit_m)  # fmt: skip


def _ground(
    las: LasPoints, order: NDArray[np.int64], single: NDArray[np.bool_], points_m: NDArray[np.float64]
) -> tuple[NDArray[np.bool_], str]:
    """Sorted positions of the ground's single returns, and which rule chose them (module docstring)."""
    cls = las.classification[order]
    on_class = single & (cls == GROUND_CLASS)
    if np.count_nonzero(on_class) >= MIN_CLASS_POINTS:
        return on_class, f"class {GROUND_CLASS}"
    cell = np.floor(points_m[:, :2] / LOWEST_CELL_M).astype(np.int64)
    _, key = np.unique(cell, axis=0, return_inverse=True)
    key = key.reshape(-1)
    lowest = np.full(key.max() + 1, np.inf)
    np.minimum.at(lowest, key, points_m[:, 2])
    low = single & (points_m[:, 2] <= lowest[key] + LOWEST_SLAB_M)
    if np.count_nonzero(low) >= MIN_CLASS_POINTS:
        return low, f"single returns within {LOWEST_SLAB_M:g} m of the lowest return of their {LOWEST_CELL_M:g} m cell"
    return np.zeros(len(order), bool), "none"


def _checked_positive(value: Any, name: str, high: float) -> float:
    """``value`` as a float in (0, ``high``]."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ArgumentTypeError(f"{name} must be a number, got {described(value)}")
    return real(value, name, low=0.0, low_open=True, high=high, expected=f"in (0, {high:g}]")


def fit_return_model(
    las: LasPoints,
    *,
    altitude_m: float,
    classes: Sequence[int] | None = VEGETATION_CLASSES,
    ground_reflectance: float = GROUND_REFLECTANCE,
    divergence_shares: tuple[ArrayLike, ...] | None = None,
    divergence_share: str = "multi_return_points",
    seed: int = 0,
    bootstrap: int = BOOTSTRAP,
) -> ReturnModelFit:
    """Fit the return model to a scan: range resolution, returns per pulse, detection threshold, intensity scale (module docstring).

    Parameters
    ----------
    las : LasPoints
        A scan with GPS times (point formats 1 and 3 to 10), from
        :func:`~zbuf_occlude.io.las.read_las` (tiles merged by :func:`merge_scans`).
    altitude_m : float
        Flying height above the ground, metres, > 0 (the range to the ground at nadir): a LAS
        file records no sensor position.  IGN LiDAR HD flies about 1,500 m above the ground.
    classes : sequence of int, optional
        The class set of the return statistics' ``..._classes_...`` figures.
    ground_reflectance : float
        The ground's reflectance at the scanner's wavelength, in (0, 1] (default
        :data:`GROUND_REFLECTANCE`, soil at 1064 nm in the cited table).
    divergence_shares : ((M,) float, (M,) float[, (M,) float]), optional
        Divergences, degrees, and the share ``divergence_share`` that a simulation of this
        scanner over a scene like the scan's gives at each, and optionally its standard
        deviation (:func:`~zbuf_occlude.sensors.fit.divergence.fit_divergence` makes them; :func:`~zbuf_occlude.sensors.fit.divergence.divergence_curve` reads them from a
        table); the divergence is fitted by inverting it (:func:`~zbuf_occlude.sensors.fit.divergence.divergence_from_shares`).  None:
        not measured.
    divergence_share : str
        The return statistics' share the curve gives (``"multi_return_points"``,
        ``"multi_return_points_classes_3_4_5"``, ``"multi_return_points_class_5"``, ...).
    seed, bootstrap : int
        Of the bootstrap over pulses (at least 2 resamples).

    Returns
    -------
    ReturnModelFit

    Raises
    ------
    ArgumentTypeError
        An argument of the wrong kind.
    InvalidInputError
        Before any work: what :func:`~zbuf_occlude.sensors.fit.returns.return_statistics` refuses (no GPS time, no
        points, class codes outside 0..255, a seed or bootstrap out of range, GPS times that do not identify pulses:
        :func:`~zbuf_occlude.sensors.fit.las_pulses.check_pulses`); a scan of first returns only
        (:func:`~zbuf_occlude.sensors.fit.las_pulses.check_return_pairs`); an altitude outside (0,
        :data:`~zbuf_occlude.sensors.checks.MAX_RANGE_M`], a reflectance outside (0, 1]; a curve
        :func:`~zbuf_occlude.sensors.fit.divergence.check_curve` refuses, a ``divergence_share`` the statistics
        would not hold.
    InsufficientMemoryError
        The scan is too large for the memory available.
    """
    # every argument before any work: a bad one is refused in the time it takes to read it
    checked_classes = check_classes(las, classes, seed, bootstrap)
    altitude_m = _checked_positive(altitude_m, "altitude_m", MAX_RANGE_M)
    rho_g = _checked_positive(ground_reflectance, "ground_reflectance", 1.0)
    curve = None if divergence_shares is None else check_curve(divergence_shares)
    text(divergence_share, "divergence_share")
    if curve is not None and divergence_share not in (shares := multi_return_shares(las, classes)):  # a pass over the classes
        raise InvalidInputError(f"divergence_share {given(divergence_share)} is not a figure of the return statistics "
                                f"(they hold {', '.join(shares)})")  # fmt: skip
    check_memory(len(las) * FIT_BYTES_PER_POINT, option=f"the return model fit of {len(las):,} points", hint="fit a crop")
    pulses = las_pulses(las)
    check_pulses(las, pulses)  # GPS times that group the returns into pulses
    check_return_pairs(las, pulses)  # a first-returns-only scan has no gaps to fit the range resolution to
    stats = pulse_statistics(las, pulses, checked_classes, seed=seed, bootstrap=bootstrap)  # the pulses found above
    unit_assumed = not math.isfinite(las.linear_unit_m)
    unit_m = las.metres_per_unit
    figures, units, counts, methods, why = _model_figures(las, pulses, unit_m, altitude_m, rho_g)
    ground = why.pop("_ground")
    spread = pulse_bootstrap(pulses.count, figures, seed=seed, bootstrap=bootstrap)
    boot = f"bootstrap over pulses ({int(bootstrap)}, seed {int(seed)})"
    estimates = {}
    for name in figures:
        value, std = spread[name]
        estimates[name] = Estimate(value, std, counts[name], f"{methods[name]}; {boot}", units[name])
    most = int(las.number_of_returns.max())
    estimates = {"range_resolution_m": estimates.pop("range_resolution_m"),
                 "max_returns": Estimate(float(most), 0.0, len(las), "the most returns a pulse recorded (number_of_returns)", "")} | estimates  # fmt: skip
    if divergence_shares is None:
        estimates["beam_divergence_deg"] = Estimate(math.nan, math.nan, 0, "not measurable from the points (module docstring)", "deg")
        why["beam_divergence_deg"] = "returns lie on the beam axis; give simulated shares (divergence_from_shares)"
    else:
        estimates["beam_divergence_deg"] = divergence_from_shares(*curve[:2], stats.estimates[divergence_share], curve[2])
    for name, e in estimates.items():
        if not math.isfinite(e.value) and name not in why:
            why[name] = (
                "no first-of-several or no single returns there" if name.startswith("intensity_ratio") else "nothing to measure it on"
            )
    return ReturnModelFit(estimates, stats, altitude_m, rho_g, ground, unit_m, unit_assumed, why)


def _model_figures(
    las: LasPoints, pulses: Any, unit_m: float, altitude_m: float, rho_g: float
) -> tuple[dict[str, Callable], dict[str, str], dict[str, int], dict[str, str], dict[str, str]]:
    """Every bootstrapped figure of the fit as a function of the pulses' weights (None: the scan itself),
    with its unit, count, how it is measured and, for the ground, which rule chose it (``why["_ground"]``)."""
    order, pulse = pulses.order, pulses.pulse
    number, rn = las.number_of_returns[order], las.return_number[order].astype(np.int64)
    cls, intensity = las.classification[order], las.intensity[order].astype(np.float64)
    points_m = las.points[order] * unit_m
    single, first_of_several = number == 1, (number > 1) & (rn == 1)
    pair = pulses.pairs(las.return_number)
    gaps = np.linalg.norm(points_m[1:][pair] - points_m[:-1][pair], axis=1)
    gap_pulse, gap_class = pulse[:-1][pair], cls[1:][pair]
    angle = np.abs(las.scan_angle_deg[order].astype(np.float64))
    cos = np.cos(np.radians(angle))
    # the energy a white (ρ = 1) flat ground returns at the scan angle from the flying height: hit_energy's law
    unit_energy = hit_energy(1.0, 1.0, cos, altitude_m / cos)
    # past MAX_SCAN_ANGLE_DEG the flat ground's range H / cos θ and incidence θ are no longer the point's: no energy there
    within = angle <= MAX_SCAN_ANGLE_DEG
    per_energy = np.where(within, intensity / np.where(within, unit_energy, 1.0), np.nan)
    energy_known = np.isfinite(per_energy)
    ground, ground_rule = _ground(las, order, single, points_m)
    recorded = intensity > 0

    figures: dict[str, Callable] = {}
    units: dict[str, str] = {}
    counts: dict[str, int] = {}
    methods: dict[str, str] = {}
    why: dict[str, str] = {"_ground": ground_rule}

    def add(name: str, figure: Callable, n: int, unit: str, method: str) -> None:
        figures[name], units[name], counts[name], methods[name] = figure, unit, n, method

    def quantile(mask: NDArray[np.bool_] | None, values: NDArray, pulses_of: NDArray, q: float) -> tuple[Callable, int]:
        v = PulseValues(values if mask is None else values[mask], pulses_of if mask is None else pulses_of[mask])
        return (lambda w: v.quantile(q, w)), len(v)

    def least(mask: NDArray[np.bool_] | None, values: NDArray, pulses_of: NDArray, q: float) -> tuple[Callable, int]:
        v = PulseValues(values if mask is None else values[mask], pulses_of if mask is None else pulses_of[mask])
        return (lambda w: lower_end(v, q, w)), len(v)

    def ratio(top: tuple[Callable, int], bottom: tuple[Callable, int], scale: float = 1.0) -> tuple[Callable, int]:
        def figure(w: NDArray | None) -> float:
            b = bottom[0](w)
            return scale * top[0](w) / b if b and math.isfinite(b) else math.nan

        return figure, min(top[1], bottom[1])

    q_res, q_det = RESOLUTION_QUANTILE, DETECTION_QUANTILE
    add("range_resolution_m", *least(None, gaps, gap_pulse, q_res), "m",
        f"lower end of the gaps between consecutive returns of a pulse (2·Q({q_res:g}) − Q({2 * q_res:g}))")  # fmt: skip
    threshold = least(recorded, intensity, pulse, q_det)
    add("detection_threshold_counts", *threshold, "counts",
        f"lower end of the intensity of every return, 0s left out (2·Q({q_det:g}) − Q({2 * q_det:g}))")  # fmt: skip
    ground_per = quantile(ground & recorded & energy_known, per_energy, pulse, 0.5)
    scale = ((lambda w, f=ground_per[0]: f(w) / rho_g), ground_per[1])
    add("intensity_scale", *scale, "counts·m²",
        f"median of intensity / hit_energy(1, ρ_g, cos θ, H / cos θ), single returns of the ground ({ground_rule})")  # fmt: skip
    add("detection_threshold", *ratio(threshold, scale), "m⁻²", "detection_threshold_counts / intensity_scale")
    on_ground = cls == GROUND_CLASS if ground_rule.startswith("class") else ground
    single_ground = quantile(on_ground & single & recorded, intensity, pulse, 0.5)
    add("intensity_ratio_ground", *ratio(quantile(on_ground & first_of_several & recorded, intensity, pulse, 0.5), single_ground), "",
        "median intensity of first-of-several over single returns, on the ground")  # fmt: skip
    sums = np.bincount(pulse, weights=intensity, minlength=pulses.count)
    several = np.flatnonzero(pulses.complete & (pulses.returns > 1))
    summed = quantile(None, sums[several], several, 0.5)
    add("intensity_sum_ratio", *ratio(summed, quantile(single & recorded, intensity, pulse, 0.5)), "",
        "median summed intensity of complete pulses of several returns over the median single return")  # fmt: skip
    if counts["intensity_scale"] == 0:
        reason = f"no single returns on the ground within {MAX_SCAN_ANGLE_DEG:g}° of nadir (MAX_SCAN_ANGLE_DEG)"
        why.update({name: reason for name in ("intensity_scale", "detection_threshold")})
    present, sizes = np.unique(cls, return_counts=True)
    for c in present[sizes >= MIN_CLASS_POINTS].tolist():
        mine = cls == c
        add(f"range_resolution_m_class_{c}", *least(gap_class == c, gaps, gap_pulse, q_res), "m",
            f"lower end (as range_resolution_m) of the gaps whose farther return is of class {c}")  # fmt: skip
        add(f"detection_threshold_counts_class_{c}", *least(mine & recorded, intensity, pulse, q_det), "counts",
            f"lower end (as detection_threshold_counts) of the intensity of class {c}'s returns")  # fmt: skip
        if c == GROUND_CLASS and ground_rule.startswith("class"):
            continue  # the ground's ratio is intensity_ratio_ground, its reflectance the one given
        add(f"intensity_ratio_class_{c}", *ratio(quantile(mine & first_of_several & recorded, intensity, pulse, 0.5),
                                                 quantile(mine & single & recorded, intensity, pulse, 0.5)), "",
            f"median intensity of first-of-several over single returns of class {c}")  # fmt: skip
        add(f"reflectance_class_{c}", *ratio(quantile(mine & single & recorded & energy_known, per_energy, pulse, 0.5), ground_per, rho_g), "",
            f"ρ_g × median I·R²/cos θ of class {c}'s single returns over the ground's")  # fmt: skip
    return figures, units, counts, methods, why


def lower_end(values: PulseValues, q: float, weights: NDArray[np.float64] | None = None) -> float:
    """The least value a law bounds from below, told robustly: ``max(2·Q(q) − Q(2q), min)``.

    Where the density is about flat just above the bound ``a`` (gaps of a range resolution,
    intensities above a detection threshold), the quantile function is ``Q(p) ≈ a + p / f``
    for small ``p``, so its line through ``Q(q)`` and ``Q(2q)`` meets ``p = 0`` at ``a``: unbiased
    to first order, where ``Q(q)`` alone lies ``q / f`` above.  The minimum rests on one value
    (an outlier moves it); this on the lowest ``2q`` of them.  Never below the least value.

    Parameters
    ----------
    values : PulseValues
    q : float
        In (0, 0.5].
    weights : (n_pulses,) float64, optional
        A bootstrap resample's draws per pulse (:func:`~zbuf_occlude.sensors.fit.returns.pulse_bootstrap`).

    Returns
    -------
    float
        NaN where there are no values.
    """
    low, high, least = values.quantile(q, weights), values.quantile(2 * q, weights), values.quantile(0.0, weights)
    return max(2.0 * low - high, least) if math.isfinite(low) else math.nan
