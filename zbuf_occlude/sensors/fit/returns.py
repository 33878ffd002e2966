"""Per-pulse return statistics of a real scan: the figures a return model is fitted to.

Measured on the points of a LAS/LAZ file (:class:`~zbuf_occlude.io.las.LasPoints`), with the fields
of the ASPRS LAS 1.4 specification R15 (§2.6: return number, number of returns, GPS time, point
source id, scanner channel, classification, intensity):

* a **pulse** is the set of points that share a GPS time within one point source (flight line)
  and one scanner channel: the returns of one pulse carry its emission time;
* a pulse is **complete** when it holds ``number_of_returns`` points that all say so, with the
  return numbers 1 to n, each once.  Thinned or cropped files lose returns of some pulses; the
  shares of returns per pulse are measured on complete pulses only;
* **returns per pulse**: the shares of complete pulses with 1, 2, 3, 4 and 5 or more returns;
* **multi-return points**: the share of points whose ``number_of_returns`` is above 1 (the
  scanner's count, which every point keeps, so a thinned pulse counts too), over the file, per
  class, and on a class set (:data:`VEGETATION_CLASSES` by default);
* **gaps**: the 3D distance between returns k and k + 1 of one pulse, for every pulse that holds
  both (complete or not); its minimum (the receiver's range resolution shows there), 5th
  percentile, median and count.  In metres where the file states its unit
  (:attr:`~zbuf_occlude.io.las.LasPoints.linear_unit_m`, applied to z too), else in its coordinate unit;
* **intensity**: the median intensity of single returns (``number_of_returns`` 1) and of
  first-of-several returns (return 1 of a pulse of more), and their ratio, over the file and on
  the class set.

Uncertainties: the shares of complete pulses are binomial (pulses are independent draws): the
standard deviation ``√(p(1 − p)/n)``.  Every other figure pools points of one pulse, which are not
independent, so its standard deviation is a bootstrap over pulses (:data:`BOOTSTRAP` resamples,
seeded): each resample draws pulses with replacement and weighs every point by its pulse's draws;
quantiles of a resample are its weighted inverted-CDF quantiles.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.geometry.arguments import described
from zbuf_occlude.io.las import LasPoints
from zbuf_occlude.resources import check_memory
from zbuf_occlude.sensors.fit.las_pulses import LasPulses, check_pulses, las_pulses
from zbuf_occlude.sensors.fit.lidar import BOOTSTRAP, Estimate, check_bootstrap, check_fit_seed

__all__ = [
    "BYTES_PER_POINT", "GAP_QUANTILE", "MAX_RETURNS_BIN", "VEGETATION_CLASSES", "PulseValues", "ReturnStatistics",
    "check_classes", "multi_return_shares", "pulse_bootstrap", "pulse_statistics", "return_statistics",
]  # fmt: skip

#: ASPRS classes of low, medium and high vegetation (R15, Table 17): the default class set.
VEGETATION_CLASSES = (3, 4, 5)
#: Returns per pulse counted apart; pulses with more share the last bin ("5+").
MAX_RETURNS_BIN = 5
#: The low quantile of the gaps reported beside the minimum (the minimum alone rests on one pair).
GAP_QUANTILE = 0.05
#: Bytes per point this measure holds at once (sort orders, sorted copies, per-pulse counts of each
#: class): tracemalloc's peak was 163 on Autzen (2 classes) and 254 on the IGN sample (7 classes).
BYTES_PER_POINT = 256
#: Bytes of a float64 or int64.
_FLOAT_BYTES = 8


@dataclass(frozen=True)
class ReturnStatistics:
    """The per-pulse figures of one scan (module docstring), each an :class:`~zbuf_occlude.sensors.fit.Estimate`.

    Attributes
    ----------
    estimates : dict of str to Estimate
        ``returns_1`` to ``returns_4`` and ``returns_5+`` (shares of complete pulses, binomial sd);
        ``multi_return_points``, ``multi_return_points_class_<c>`` for each class in the file and
        ``multi_return_points_<set>`` on the class set; ``gap_min``, ``gap_p05``, ``gap_median``,
        ``gap_count``; ``intensity_single``, ``intensity_first_of_several``, ``intensity_ratio``
        and the same on the class set (``..._<set>``, e.g. ``intensity_ratio_classes_3_4_5``).
        Shares have unit ``"share"`` (0 to 1); NaN where nothing was there to measure.
    n_points, n_pulses, n_complete_pulses : int
    classes : tuple of int
        The class set.
    gap_unit : str
        ``"m"``, or ``"coordinate unit"`` where the file does not state its unit.
    seed, bootstrap : int
        Of the bootstrap.
    """

    estimates: dict[str, Estimate]
    n_points: int
    n_pulses: int
    n_complete_pulses: int
    classes: tuple[int, ...]
    gap_unit: str
    seed: int
    bootstrap: int

    def markdown(self) -> str:
        """A Markdown table: figure, value ± standard deviation (shares in %), unit, n, how the uncertainty was found."""
        lines = [
            (
                f"{self.n_points:,} points, {self.n_pulses:,} pulses, {self.n_complete_pulses:,} complete; "
                f"class set {', '.join(map(str, self.classes)) or 'none'}"
            ),
            "",
            "| figure | value ± sd | unit | n | uncertainty |",
            "|---|---|---|---|---|",
        ]
        for name, e in self.estimates.items():
            scale, unit = (100.0, "%") if e.unit == "share" else (1.0, e.unit)
            if not math.isfinite(e.value):
                value = "not measured"
            elif e.method == "count":
                value = f"{e.value:,.0f}"
            else:
                value = f"{scale * e.value:.4g} ± {scale * e.std:.2g}"
            lines.append(f"| {name} | {value} | {unit} | {e.n:,} | {e.method} |")
        return "\n".join(lines) + "\n"

    def to_json(self) -> dict[str, Any]:
        """The figures as a strict-JSON object (``null`` where not measured)."""
        return {
            "n_points": self.n_points, "n_pulses": self.n_pulses, "n_complete_pulses": self.n_complete_pulses,
            "classes": list(self.classes), "gap_unit": self.gap_unit, "seed": self.seed, "bootstrap": self.bootstrap,
            "estimates": {name: e.to_json() for name, e in self.estimates.items()},
        }  # fmt: skip


class PulseValues:
    """Values with the pulse of each, sorted once, for point estimates and weighted bootstrap quantiles.

    Parameters
    ----------
    values : (M,) float64
        One value per point (or per pair of points, per pulse...).
    pulses : (M,) int64
        The pulse of each value (:attr:`LasPulses.pulse`), which :func:`pulse_bootstrap`'s weights index.
    """

    def __init__(self, values: NDArray[np.float64], pulses: NDArray[np.int64]) -> None:
        order = np.argsort(values, kind="stable")
        self.values, self.pulses = values[order], pulses[order]

    def __len__(self) -> int:
        return len(self.values)

    def quantile(self, q: float, weights: NDArray[np.float64] | None = None) -> float:
        """The ``q`` quantile of the values (NaN if none); with ``weights`` (per pulse, the draws of a resample), the
        weighted inverted-CDF quantile, each value weighed by its pulse's draws (NaN if no drawn pulse holds one)."""
        if len(self.values) == 0:
            return math.nan
        if weights is None:
            return float(np.quantile(self.values, q))
        cumulative = np.cumsum(weights[self.pulses])
        if cumulative[-1] == 0:
            return math.nan
        # inverted CDF: the smallest value whose cumulative weight reaches q (q = 0: the first drawn)
        index = np.searchsorted(cumulative, q * cumulative[-1], side="right" if q == 0 else "left")
        return float(self.values[min(index, len(self.values) - 1)])


def _binomial(hits: int, n: int, what: str) -> Estimate:
    if n == 0:
        return Estimate(math.nan, math.nan, 0, f"binomial, over {what}", "share")
    p = hits / n
    return Estimate(p, math.sqrt(p * (1.0 - p) / n), n, f"binomial, over {what}", "share")


def _share_classes(classification: NDArray) -> list[int]:
    """The classes with a multi-return share of their own: every class present, none in a file that never
    classified (class 0 only)."""
    present = np.unique(classification).tolist()
    return [] if present in ([], [0]) else present


def multi_return_shares(las: LasPoints, classes: Sequence[int] | None) -> list[str]:
    """The names of the multi-return shares :func:`return_statistics` gives for ``las`` and the class set ``classes``
    (checked by :func:`check_classes`), without measuring them."""
    names = ["multi_return_points", *(f"multi_return_points_class_{c}" for c in _share_classes(las.classification))]
    checked = tuple(sorted({int(c) for c in classes or ()}))
    return names + ([f"multi_return_points_classes_{'_'.join(map(str, checked))}"] if checked else [])


def _figures(las: LasPoints, pulses: LasPulses, classes: tuple[int, ...], unit_m: float) -> dict[str, tuple]:
    """Every bootstrapped figure as ``(kind, data, n, unit)``: kind ``share`` (per-pulse counts),
    ``quantile`` (a :class:`PulseValues` and q) or ``ratio`` (two medians)."""
    order, pulse = pulses.order, pulses.pulse
    number, first = las.number_of_returns[order], las.return_number[order] == 1
    cls, intensity = las.classification[order], las.intensity[order].astype(np.float64)
    suffix = "classes_" + "_".join(map(str, classes))
    multi = number > 1

    def share(mask: NDArray[np.bool_]) -> tuple:
        counts = np.stack([np.bincount(pulse[mask], minlength=pulses.count),
                           np.bincount(pulse[mask & multi], minlength=pulses.count)], axis=1)  # fmt: skip
        return ("share", counts.astype(np.float64), int(mask.sum()), "share")

    out = {"multi_return_points": share(np.ones(len(order), dtype=bool))}
    out.update({f"multi_return_points_class_{c}": share(cls == c) for c in _share_classes(cls)})
    in_set = np.isin(cls, classes)
    if classes:
        out[f"multi_return_points_{suffix}"] = share(in_set)
    # consecutive returns k, k + 1 of one pulse: neighbours in the sorted order
    points = las.points[order]
    pair = pulses.pairs(las.return_number)
    gaps = PulseValues(np.linalg.norm(points[1:][pair] - points[:-1][pair], axis=1) * unit_m, pulse[:-1][pair])
    gap_unit = "m" if math.isfinite(las.linear_unit_m) else "coordinate unit"
    out |= {"gap_min": ("quantile", (gaps, 0.0), len(gaps.values), gap_unit),
            "gap_p05": ("quantile", (gaps, GAP_QUANTILE), len(gaps.values), gap_unit),
            "gap_median": ("quantile", (gaps, 0.5), len(gaps.values), gap_unit)}  # fmt: skip
    subsets = {"": np.ones(len(order), dtype=bool)} | ({f"_{suffix}": in_set} if classes else {})
    for name, where in subsets.items():
        single = PulseValues(intensity[where & ~multi], pulse[where & ~multi])
        several = PulseValues(intensity[where & multi & first], pulse[where & multi & first])
        out |= {f"intensity_single{name}": ("quantile", (single, 0.5), len(single.values), ""),
                f"intensity_first_of_several{name}": ("quantile", (several, 0.5), len(several.values), ""),
                f"intensity_ratio{name}": ("ratio", (several, single), min(len(several.values), len(single.values)), "")}  # fmt: skip
    return out


def _value(kind: str, data: Any, weights: NDArray[np.float64] | None) -> float:
    if kind == "share":
        totals = data.sum(axis=0) if weights is None else weights @ data
        return float(totals[1] / totals[0]) if totals[0] else math.nan
    if kind == "quantile":
        resampled, q = data
        return resampled.quantile(q, weights)
    numerator, denominator = (d.quantile(0.5, weights) for d in data)
    return numerator / denominator if denominator else math.nan


def check_classes(las: Any, classes: Any, seed: Any, bootstrap: Any) -> tuple[int, ...]:
    """Check the arguments every per-pulse measure takes; the class set, sorted, without repeats.

    Raises
    ------
    ArgumentTypeError
        ``las`` is not a :class:`~zbuf_occlude.io.las.LasPoints`, or ``classes``, ``seed`` or
        ``bootstrap`` of the wrong kind.
    InvalidInputError
        A scan without GPS times or without points; class codes outside 0 to 255; ``bootstrap``
        outside 2 to :data:`~zbuf_occlude.sensors.fit.lidar.MAX_BOOTSTRAP`; a seed
        :func:`~zbuf_occlude.geometry.sampling.check_seed` refuses.
    """
    if not isinstance(las, LasPoints):
        raise ArgumentTypeError(f"las must be a LasPoints (read one with zbuf_occlude.io.las.read_las), got {described(las)}")
    if not las.has_gps_time:
        raise InvalidInputError(f"point format {las.point_format_id} has no GPS time: the returns of one pulse cannot be told apart")
    if len(las) == 0:
        raise InvalidInputError("the scan holds no points: there are no returns to measure")
    check_fit_seed(seed)
    check_bootstrap(bootstrap)
    if classes is None:
        return ()
    if isinstance(classes, (str, bytes)) or not isinstance(classes, Sequence):
        raise ArgumentTypeError(f"classes must be a sequence of ASPRS class codes, got {described(classes)}")
    if not all(isinstance(c, (int, np.integer)) and not isinstance(c, bool) and 0 <= c <= 255 for c in classes):
        raise InvalidInputError(f"classes must be ASPRS class codes 0 to 255, got {list(classes)}")
    return tuple(sorted({int(c) for c in classes}))


def pulse_bootstrap(
    n_pulses: int, figures: Mapping[str, Callable[[NDArray[np.float64] | None], float]], *, seed: int, bootstrap: int
) -> dict[str, tuple[float, float]]:
    """Each figure's value and its standard deviation over a bootstrap over pulses (module docstring).

    Parameters
    ----------
    n_pulses : int
        Pulses of the scan (:attr:`LasPulses.count`).
    figures : mapping of str to callable
        Each called with None (the scan as it is) and with ``(n_pulses,) float64`` weights (a
        resample: how many times each pulse was drawn), returning a float, NaN where the
        resample holds nothing to measure it on.
    seed, bootstrap : int
        Of the resamples (:func:`~zbuf_occlude.sensors.fit.lidar.check_fit_seed`,
        :func:`~zbuf_occlude.sensors.fit.lidar.check_bootstrap`).

    Returns
    -------
    dict of str to (value, std)
        ``std`` (ddof 1) over the resamples whose value is finite; NaN when fewer than 2 are.

    Raises
    ------
    ArgumentTypeError, InvalidInputError
        A seed or bootstrap the checks refuse (above).
    InsufficientMemoryError
        The resamples' figures would not fit in the memory available.
    """
    seed, bootstrap = check_fit_seed(seed), check_bootstrap(bootstrap)
    # the resamples' figures and one resample's draws and weights, before they are allocated
    check_memory(bootstrap * len(figures) * _FLOAT_BYTES + 2 * n_pulses * _FLOAT_BYTES,
                 option=f"bootstrap {bootstrap:,} over {n_pulses:,} pulses", hint="lower the bootstrap")  # fmt: skip
    rng = np.random.default_rng(seed)
    resampled = np.empty((bootstrap, len(figures)))
    for b in range(bootstrap):
        weights = np.bincount(rng.integers(0, n_pulses, n_pulses), minlength=n_pulses).astype(np.float64)
        resampled[b] = [figure(weights) for figure in figures.values()]
    out = {}
    for j, (name, figure) in enumerate(figures.items()):
        spread = resampled[:, j][np.isfinite(resampled[:, j])]
        out[name] = (figure(None), float(np.std(spread, ddof=1)) if len(spread) > 1 else math.nan)
    return out


def return_statistics(
    las: LasPoints,
    *,
    classes: Sequence[int] | None = VEGETATION_CLASSES,
    seed: int = 0,
    bootstrap: int = BOOTSTRAP,
) -> ReturnStatistics:
    """The per-pulse return statistics of a scan: returns per pulse, multi-return points, gaps, intensities (module docstring).

    Parameters
    ----------
    las : LasPoints
        A scan with GPS times (point formats 1 and 3 to 10), from
        :func:`~zbuf_occlude.io.las.read_las`.
    classes : sequence of int, optional
        The class set of the ``..._classes_...`` figures (default :data:`VEGETATION_CLASSES`);
        None or empty: none.  Per-class shares are given for every class in the file anyway.
    seed : int
        Seed of the bootstrap over pulses.
    bootstrap : int
        Resamples (default :data:`~zbuf_occlude.sensors.fit.BOOTSTRAP`), at least 2.

    Returns
    -------
    ReturnStatistics

    Raises
    ------
    ArgumentTypeError
        ``las`` is not a :class:`~zbuf_occlude.io.las.LasPoints`, or ``classes``, ``seed`` or
        ``bootstrap`` of the wrong kind.
    InvalidInputError
        A scan without GPS times (its pulses cannot be told apart) or without points, or whose
        times do not identify its pulses (:func:`check_pulses`); class codes outside 0 to 255;
        ``bootstrap`` outside 2 to :data:`~zbuf_occlude.sensors.fit.lidar.MAX_BOOTSTRAP`; a seed
        :func:`~zbuf_occlude.geometry.sampling.check_seed` refuses.
    InsufficientMemoryError
        The scan is too large for the memory available.
    """
    classes = check_classes(las, classes, seed, bootstrap)
    check_memory(len(las) * BYTES_PER_POINT, option=f"the return statistics of {len(las):,} points", hint="measure a crop")
    pulses = las_pulses(las)
    check_pulses(las, pulses)
    return pulse_statistics(las, pulses, classes, seed=seed, bootstrap=bootstrap)


def pulse_statistics(las: LasPoints, pulses: LasPulses, classes: tuple[int, ...], *, seed: int, bootstrap: int) -> ReturnStatistics:
    """:func:`return_statistics` of a scan whose pulses are found (:func:`las_pulses`) and checked
    (:func:`check_pulses`) and whose arguments are checked (:func:`check_classes` gave ``classes``):
    for a caller that holds them already (:func:`~zbuf_occlude.sensors.fit.return_model.fit_return_model`).
    """
    unit_m = las.metres_per_unit
    estimates: dict[str, Estimate] = {}
    returns = np.minimum(pulses.returns[pulses.complete], MAX_RETURNS_BIN)
    what = f"{len(returns):,} complete pulses"
    for k in range(1, MAX_RETURNS_BIN + 1):
        name = f"returns_{k}" + ("+" if k == MAX_RETURNS_BIN else "")
        estimates[name] = _binomial(int(np.count_nonzero(returns == k)), len(returns), what)
    figures = _figures(las, pulses, classes, unit_m)
    spread = pulse_bootstrap(pulses.count, {name: partial(_value, kind, data) for name, (kind, data, _, _) in figures.items()},
                             seed=seed, bootstrap=bootstrap)  # fmt: skip
    method = f"bootstrap over pulses ({int(bootstrap)}, seed {int(seed)})"
    for name, (_, _, n, unit) in figures.items():
        estimates[name] = Estimate(*spread[name], n, method, unit)
        if name == "gap_median":
            estimates["gap_count"] = Estimate(float(n), 0.0, n, "count", "")
    return ReturnStatistics(estimates, len(las), pulses.count, int(pulses.complete.sum()), classes,
                            estimates["gap_min"].unit, int(seed), int(bootstrap))  # fmt: skip
