"""The targets of ``experiment returns``: real against simulated return statistics, each PASS or FAIL, and the sub-ray count K.

A target passes when the simulated figure lies within the stated relative tolerance of the real
one (:data:`TOLERANCES`); the smallest gap is held to the range resolution the simulation was
given, within :data:`GAP_MIN_TOLERANCE`.  :func:`recommend_k` takes the smallest K whose shares of
returns per vegetation pulse agree with the largest K's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.returns import GROUND_CLASS
from zbuf_occlude.sensors.fit.returns import VEGETATION_CLASSES, ReturnStatistics

__all__ = [
    "TOLERANCES",
    "GAP_MIN_TOLERANCE",
    "RETURN_COUNTS",
    "K_AGREEMENT_SD",
    "estimate_of",
    "class_suffix",
    "comparison_rows",
    "comparison_markdown",
    "cover_markdown",
    "recommend_k",
]

#: Relative tolerances of the targets : returns-per-pulse shares ±20 %, median gap
#: ±30 %, intensity ratio of first-of-several to single returns ±20 %.
TOLERANCES = {"returns": 0.20, "gap_median": 0.30, "intensity_ratio": 0.20}
#: The smallest simulated gap "equals" the range resolution within this relative tolerance (the
#: range noise, 2 cm, moves it either way).
GAP_MIN_TOLERANCE = 0.05
#: Shares of returns per pulse compared (5+ is below 0.01 % in the IGN sample).
RETURN_COUNTS = (1, 2, 3, 4)
#: Standard deviations within which a K's shares count as equal to the largest K's.
K_AGREEMENT_SD = 1.96


def estimate_of(stats: ReturnStatistics, key: str) -> tuple[float, float]:
    e = stats.estimates.get(key)
    return (math.nan, math.nan) if e is None else (e.value, e.std)


def class_suffix(classes: Sequence[int]) -> str:
    return "classes_" + "_".join(map(str, sorted(classes)))


def _verdict(sim: float, real: float, tolerance: float) -> str:
    if not (math.isfinite(sim) and math.isfinite(real)):
        return "not measured"
    if real == 0:
        return "PASS" if sim == 0 else "FAIL"
    return "PASS" if abs(sim / real - 1.0) <= tolerance else "FAIL"


def comparison_rows(real: dict[str, ReturnStatistics], sim: dict[str, ReturnStatistics], *, real_classes: Sequence[int],
                    range_resolution_m: float, label: str) -> list[dict[str, Any]]:  # fmt: skip
    """The targets, real against simulated (module docstring): one row each.

    Parameters
    ----------
    real, sim : dict of str to ReturnStatistics
        ``"all"``, ``"vegetation"`` and ``"ground"`` of each side (:func:`~.returns.simulate`);
        the real ``"all"`` measured with ``real_classes`` as its class set, the simulated with 3–5.
    real_classes : sequence of int
        The real file's vegetation classes.
    range_resolution_m : float
        The simulation's range resolution, the smallest gap's target.
    label : str
        The run's name in the rows (``"IGN"``).

    Returns
    -------
    list of dict
        ``run``, ``figure``, ``real``, ``real_sd``, ``simulated``, ``simulated_sd``, ``target``, ``verdict``.
    """
    rows = []

    def add(figure: str, r: tuple[float, float], s: tuple[float, float], target: str, verdict: str) -> None:
        rows.append({"run": label, "figure": figure, "real": r[0], "real_sd": r[1], "simulated": s[0], "simulated_sd": s[1],
                     "target": target, "verdict": verdict})  # fmt: skip

    for side in ("vegetation", "ground"):
        for k in RETURN_COUNTS:
            r, s = estimate_of(real[side], f"returns_{k}"), estimate_of(sim[side], f"returns_{k}")
            add(f"{side} pulses with {k} return{'s' if k > 1 else ''}", r, s, "±20 %", _verdict(s[0], r[0], TOLERANCES["returns"]))
    real_suffix, sim_suffix = class_suffix(real_classes), class_suffix(VEGETATION_CLASSES)
    r, s = estimate_of(real["all"], f"multi_return_points_{real_suffix}"), estimate_of(sim["all"], f"multi_return_points_{sim_suffix}")
    add(
        "vegetation points from multi-return pulses",
        r,
        s,
        "±20 % (the divergence is fitted to it)",
        _verdict(s[0], r[0], TOLERANCES["returns"]),
    )
    r, s = (
        estimate_of(real["all"], f"multi_return_points_class_{GROUND_CLASS}"),
        estimate_of(sim["all"], f"multi_return_points_class_{GROUND_CLASS}"),
    )
    add(
        "ground points from multi-return pulses",
        r,
        s,
        "±20 % (depends on the plot's tree cover)",
        _verdict(s[0], r[0], TOLERANCES["returns"]),
    )
    r, s = estimate_of(real["all"], "gap_min"), estimate_of(sim["all"], "gap_min")
    add("smallest gap (m)", r, s, f"= range resolution {range_resolution_m:.3g} m ±{GAP_MIN_TOLERANCE:.0%}",
        _verdict(s[0], range_resolution_m, GAP_MIN_TOLERANCE))  # fmt: skip
    r, s = estimate_of(real["all"], "gap_median"), estimate_of(sim["all"], "gap_median")
    add("median gap (m)", r, s, "±30 %", _verdict(s[0], r[0], TOLERANCES["gap_median"]))
    r, s = estimate_of(real["all"], f"intensity_ratio_{real_suffix}"), estimate_of(sim["all"], f"intensity_ratio_{sim_suffix}")
    add("intensity first-of-several / single, vegetation", r, s, "±20 %", _verdict(s[0], r[0], TOLERANCES["intensity_ratio"]))
    return rows


def _shown(value: float, figure: str) -> str:
    if not math.isfinite(value):
        return "–"
    return f"{value:.3g}" if "(m)" in figure or "intensity" in figure else f"{100 * value:.2f} %"


def comparison_markdown(rows: Sequence[dict[str, Any]]) -> str:
    """:func:`comparison_rows` as a Markdown table: run, figure, real ± sd, simulated ± sd, target, verdict."""
    lines = ["| run | figure | real | simulated | target | verdict |", "|---|---|---|---|---|---|"]
    for r in rows:
        real = f"{_shown(r['real'], r['figure'])} ± {_shown(r['real_sd'], r['figure'])}"
        sim = f"{_shown(r['simulated'], r['figure'])} ± {_shown(r['simulated_sd'], r['figure'])}"
        lines.append(f"| {r['run']} | {r['figure']} | {real} | {sim} | {r['target']} | **{r['verdict']}** |")
    return "\n".join(lines) + "\n"


def _percent(e: dict[str, Any]) -> str:
    value, std = (math.nan if e[k] is None else e[k] for k in ("value", "std"))
    return f"{100 * value:.1f} % ± {100 * std:.1f} % ({e['n']:,} cells)" if math.isfinite(value) else "not measured"


def cover_markdown(covers: dict[str, Any], *, tile_only: bool = False) -> str:
    """The tree covers of a run (``run.json``'s ``tree_cover``) as Markdown lines: the tile's, the plot's
    by vertical rays and each compared scan's (``tile_only``: the tile's alone)."""
    rule = (f"the share of {covers['cell_m']:g} m cells holding {covers['min_pulses']} pulses or more whose highest return is "
            f"vegetation rather than ground; ± sd over {covers['block_m']:g} m blocks")  # fmt: skip
    lines = [f"Tree cover ({rule}):", "", f"* the real tile: {_percent(covers['tile'])}"]
    if not tile_only:
        lines.append(f"* the plot, by {covers['rays_per_cell']} vertical rays a cell: {100 * covers['plot_vertical_rays']:.1f} % "
                     f"(trees {covers['spacing_m']:.3g} m apart)")  # fmt: skip
        lines += [f"* {label}: {_percent(e)}" for label, e in covers["scans"].items()]
    return "\n".join(lines) + "\n"


def recommend_k(rows: Sequence[dict[str, Any]]) -> int:
    """The smallest K whose vegetation shares of 1..4 returns per pulse all lie within
    :data:`K_AGREEMENT_SD` combined standard deviations of the largest K's.

    Parameters
    ----------
    rows : sequence of dict
        One per K: ``K`` and ``returns_k`` / ``returns_k_sd`` for k in :data:`RETURN_COUNTS`.

    Raises
    ------
    InvalidInputError
        No row.
    """
    if not rows:
        raise InvalidInputError("recommend_k needs one row per K")
    rows = sorted(rows, key=lambda row: row["K"])
    top = rows[-1]
    for row in rows:
        close = all(abs(row[f"returns_{k}"] - top[f"returns_{k}"]) <= K_AGREEMENT_SD * math.hypot(row[f"returns_{k}_sd"], top[f"returns_{k}_sd"])
                    for k in RETURN_COUNTS)  # fmt: skip
        if close:
            return int(row["K"])
    return int(top["K"])
