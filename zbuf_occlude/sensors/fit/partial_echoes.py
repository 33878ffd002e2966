"""The detection of partial echoes fitted by simulation: a beam's ``min_echo_reflectance`` from real object scans.

Where a pulse's footprint straddles an object's outline, a sliver of it meets the object; whether
the receiver reports that partial echo decides how far an object's scan reaches past its outline.
A scan records each return on the pulse's axis, so no point shows the footprint it came from; the
threshold is read from what it does to whole objects instead.  Real scans of objects of some
classes give, per scan, a statistic the threshold moves (the share of points that end a run along
their ring, ``realism.outline_share``; points per object at range); the same statistic of
simulated scans of meshes of those classes, made with the beam at each threshold of a grid,
gives a curve per class.  The fitted threshold minimises

    J(τ) = Σ_c ((m_c(τ) − r_c) / r_c)²

over τ, with ``m_c(τ)`` the median of the simulated scans of class ``c`` (linear between the grid's
thresholds) and ``r_c`` the median of the real ones: each class weighs alike, whatever its count.
Its spread is the bootstrap's: the real scans and the simulated ones resampled within each class
(one draw of the simulated scans' rows for every threshold, so each resample's curve stays a
curve), the minimum found again.

The caller simulates (the meshes, the placements and the statistic are its own); this module
only fits, so that it serves a spinning LiDAR's object scans and any other statistic alike.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.fit.lidar import BOOTSTRAP, Estimate, check_bootstrap, check_fit_seed

__all__ = ["FIT_GRID", "PartialEchoFit", "fit_min_echo_reflectance"]

#: The thresholds a fit simulates (apparent reflectance, :attr:`Beam.min_echo_reflectance
#: <zbuf_occlude.sensors.beam.fields.Beam.min_echo_reflectance>`): from none to half the footprint of a white surface met head on.
FIT_GRID = (0.0, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5)
#: Step of the search between the grid's thresholds.
_SEARCH_STEP = 0.0025


@dataclass(frozen=True)
class PartialEchoFit:
    """A fitted ``min_echo_reflectance`` and the curves behind it.

    Attributes
    ----------
    estimate : Estimate
        The threshold (apparent reflectance, no unit) ± its bootstrap standard deviation, ``n`` the real scans.
    grid : tuple of float
        The thresholds simulated, increasing.
    real : dict of str to float
        Per class, the median statistic of the real scans.
    simulated : dict of str to tuple of float
        Per class, the median statistic of the simulated scans at each threshold of ``grid``.
    objective : tuple of float
        ``J`` at each threshold of ``grid`` (module docstring).
    """

    estimate: Estimate
    grid: tuple[float, ...]
    real: dict[str, float]
    simulated: dict[str, tuple[float, ...]]
    objective: tuple[float, ...]

    def markdown(self) -> str:
        """A table: per class, the real median and the simulated one at each threshold; then ``J``."""
        head = "| class | real | " + " | ".join(f"τ = {t:g}" for t in self.grid) + " |"
        rows = [head, "|---|---|" + "---|" * len(self.grid)]
        for name, real in self.real.items():
            rows.append(f"| {name} | {real:.3f} | " + " | ".join(f"{v:.3f}" for v in self.simulated[name]) + " |")
        rows.append("| J | | " + " | ".join(f"{v:.4f}" for v in self.objective) + " |")
        e = self.estimate
        rows.append(f"\nfitted min_echo_reflectance {e.value:.3f} ± {e.std:.3f} (bootstrap; {e.n} real scans)")
        return "\n".join(rows) + "\n"


def _values(values: ArrayLike, where: str) -> NDArray[np.float64]:
    """(n,) float64 of a class's per-scan statistic: 1-D, finite, at least one."""
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.full(0, np.nan)
    if a.ndim != 1 or len(a) == 0 or not np.all(np.isfinite(a)):
        raise InvalidInputError(f"{where} must be a non-empty 1-D array of finite numbers, got shape {np.shape(a)}")
    return a


def _minimum(grid: NDArray[np.float64], medians: NDArray[np.float64], real: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
    """The threshold minimising J over a fine search of the piecewise-linear curves, and J on the grid.

    ``medians`` (C, T): per class the simulated medians on ``grid`` (T,); ``real`` (C,)."""
    fine = np.arange(grid[0], grid[-1] + _SEARCH_STEP / 2, _SEARCH_STEP)
    curves = np.stack([np.interp(fine, grid, m) for m in medians])
    j_fine = np.sum(((curves - real[:, None]) / real[:, None]) ** 2, axis=0)
    j_grid = np.sum(((medians - real[:, None]) / real[:, None]) ** 2, axis=0)
    return float(fine[int(np.argmin(j_fine))]), j_grid


def fit_min_echo_reflectance(
    real: Mapping[str, ArrayLike],
    simulated: Mapping[float, Mapping[str, ArrayLike]],
    *,
    seed: int = 0,
    bootstrap: int = BOOTSTRAP,
) -> PartialEchoFit:
    """Fit ``min_echo_reflectance`` from a per-scan statistic of real and simulated scans (module docstring).

    Parameters
    ----------
    real : mapping of class name to (n_c,) float
        The statistic of each real scan of the class (e.g. its outline share), each > 0 in median.
    simulated : mapping of threshold to (mapping of class name to (m_c,) float)
        For each threshold simulated (at least two, in [0, 1]), the statistic of each simulated
        scan of every class of ``real``; the scans of a class in one order for every threshold
        (the same meshes and placements), so that a bootstrap draw takes the same rows of each.
    seed : int
        Of the bootstrap.
    bootstrap : int
        Resamples (:func:`~zbuf_occlude.sensors.fit.lidar.check_bootstrap`).

    Returns
    -------
    PartialEchoFit

    Raises
    ------
    InvalidInputError
        Fewer than two thresholds, one outside [0, 1], a class of ``real`` missing from a threshold,
        a class's simulated scans not one count for every threshold, values not finite, a real
        median of 0.
    """
    seed, bootstrap = check_fit_seed(seed), check_bootstrap(bootstrap)
    if len(simulated) < 2:
        raise InvalidInputError(f"a fit needs the scans simulated at two thresholds or more, got {len(simulated)}")
    grid = np.array(sorted(float(t) for t in simulated), dtype=np.float64)
    if not np.all((grid >= 0) & (grid <= 1)) or len(np.unique(grid)) != len(grid):
        raise InvalidInputError(f"the thresholds simulated must be distinct values in [0, 1], got {grid.tolist()}")
    names = sorted(real)
    if not names:
        raise InvalidInputError("a fit needs the real scans of one class or more")
    by_t = {float(t): v for t, v in simulated.items()}
    real_v = {c: _values(real[c], f"the real scans of {c!r}") for c in names}
    sim_v: dict[str, NDArray[np.float64]] = {}
    for c in names:
        rows = []
        for t in grid:
            if c not in by_t[t]:
                raise InvalidInputError(f"no simulated scans of class {c!r} at threshold {t:g}")
            rows.append(_values(by_t[t][c], f"the simulated scans of {c!r} at threshold {t:g}"))
        if len({len(r) for r in rows}) != 1:
            raise InvalidInputError(f"class {c!r} has {sorted({len(r) for r in rows})} simulated scans at different thresholds: "
                                    "simulate the same scans at every threshold")  # fmt: skip
        sim_v[c] = np.stack(rows)  # (T, m_c)
    real_med = np.array([np.median(real_v[c]) for c in names])
    if np.any(real_med <= 0):
        raise InvalidInputError(f"the real scans' median is 0 for {[c for c, m in zip(names, real_med) if m <= 0]}: nothing to fit on")
    medians = np.stack([np.median(sim_v[c], axis=1) for c in names])
    best, j_grid = _minimum(grid, medians, real_med)
    rng = np.random.default_rng(seed)
    draws = []
    for _ in range(bootstrap):
        r = np.array([np.median(rng.choice(real_v[c], len(real_v[c]))) for c in names])
        m = np.stack([np.median(sim_v[c][:, rng.integers(0, sim_v[c].shape[1], sim_v[c].shape[1])], axis=1) for c in names])
        if np.all(r > 0):
            draws.append(_minimum(grid, m, r)[0])
    std = float(np.std(draws, ddof=1)) if len(draws) >= 2 else math.nan
    n = int(sum(len(v) for v in real_v.values()))
    estimate = Estimate(best, std, n, "simulated scans at each threshold against the real scans' statistic, per class (bootstrap)")
    return PartialEchoFit(
        estimate=estimate,
        grid=tuple(float(t) for t in grid),
        real={c: float(m) for c, m in zip(names, real_med)},
        simulated={c: tuple(float(v) for v in medians[i]) for i, c in enumerate(names)},
        objective=tuple(float(v) for v in j_grid),
    )
