"""The beam divergence fitted by simulation: a simulated multi-return share curve inverted at a scan's share.

A scanner places every return of a pulse on the beam's axis, so a scan's points do not show its
footprint (:mod:`.return_model`, ``beam_divergence_deg``).  The share of multi-return points
does: the wider the beam, the more pulses meet two surfaces.  So the divergence is fitted by
simulation: a scanner flown as the scan's was, over a scene like the scan's, at several
divergences (:func:`fit_divergence` calls the simulation; a table of its shares reads with
:func:`divergence_curve`), and the curve of simulated shares inverted at the measured share
(:func:`divergence_from_shares`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.geometry.arguments import described
from zbuf_occlude.sensors.fit.lidar import Estimate
from zbuf_occlude.sensors.beam.footprint import MAX_DIVERGENCE_DEG

__all__ = ["DIVERGENCE_GRID_DEG", "MAX_CURVE_ROWS", "check_curve", "divergence_curve", "divergence_from_shares", "fit_divergence"]

#: Divergences, degrees, that :func:`fit_divergence` simulates by default: 0.05 to 3 mrad.
DIVERGENCE_GRID_DEG = tuple(float(v) for v in np.degrees(np.geomspace(0.05e-3, 3e-3, 9)))
#: Most rows of a table of simulated shares (:func:`divergence_curve`).
MAX_CURVE_ROWS = 1_000


def divergence_from_shares(divergences_deg: ArrayLike, simulated_shares: ArrayLike, measured: Estimate,
                           simulated_std: ArrayLike | None = None) -> Estimate:  # fmt: skip
    """The beam divergence at which a simulated multi-return share meets the measured one.

    The share of multi-return points grows with the footprint: the wider the beam, the more
    pulses meet two surfaces.  Given that share simulated at several divergences (a scanner of
    the scan's flying height over a scene like the scan's: trees and ground), the divergence is
    the curve's inverse at the measured share (linear between the simulated points), and its
    uncertainty the measured share's ``± std`` (and the simulation's, added in quadrature)
    carried through the curve's slope: half the divergence interval between the inverses of
    ``share ± σ``.

    Parameters
    ----------
    divergences_deg : (M,) float
        Full-angle divergences, degrees, > 0, strictly increasing, at most
        :data:`~zbuf_occlude.sensors.beam.footprint.MAX_DIVERGENCE_DEG`, M >= 2.
    simulated_shares : (M,) float
        The share in [0, 1] simulated at each.  It must grow with the divergence (non-decreasing;
        ties are taken as the curve's flat parts) and rise somewhere.
    measured : Estimate
        The measured share (a :class:`~zbuf_occlude.sensors.fit.returns.ReturnStatistics` estimate,
        unit ``"share"``).
    simulated_std : (M,) float, optional
        The simulated shares' standard deviations (e.g. binomial over the simulated points).

    Returns
    -------
    Estimate
        Degrees; NaN (not measured) where the measured share lies outside the simulated range
        (simulate wider or narrower beams) or is NaN; its std is NaN where ``share ± σ`` leaves it.

    Raises
    ------
    InvalidInputError
        Arrays of other shapes or lengths, non-finite values, divergences not increasing, not
        positive or above :data:`~zbuf_occlude.sensors.beam.footprint.MAX_DIVERGENCE_DEG`, shares outside [0, 1], decreasing or
        flat everywhere.
    ArgumentTypeError
        ``measured`` is not an :class:`~zbuf_occlude.sensors.fit.Estimate`.
    """
    if not isinstance(measured, Estimate):
        raise ArgumentTypeError(f"measured must be an Estimate (a share of the return statistics), got {described(measured)}")
    d = np.asarray(divergences_deg, dtype=np.float64)
    s = np.asarray(simulated_shares, dtype=np.float64)
    sd = np.zeros_like(s) if simulated_std is None else np.asarray(simulated_std, dtype=np.float64)
    if d.ndim != 1 or len(d) < 2 or s.shape != d.shape or sd.shape != d.shape:
        raise InvalidInputError(f"divergences_deg, simulated_shares and simulated_std must be (M,) arrays of one length M >= 2, "
                                f"got shapes {d.shape}, {s.shape}, {sd.shape}")  # fmt: skip
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(s)) and np.all(np.isfinite(sd))):
        raise InvalidInputError("divergences_deg, simulated_shares and simulated_std must be finite")
    if not (d[0] > 0 and np.all(np.diff(d) > 0)):
        raise InvalidInputError("divergences_deg must be > 0 and strictly increasing")
    if d[-1] > MAX_DIVERGENCE_DEG:
        raise InvalidInputError(
            f"divergences_deg must be at most {MAX_DIVERGENCE_DEG:g} degrees (a sensor's widest beam), got a larger one"
        )
    if s.min() < 0 or s.max() > 1 or sd.min() < 0:
        raise InvalidInputError("simulated_shares must be shares in [0, 1] (and simulated_std >= 0)")
    if np.any(np.diff(s) < 0) or s[-1] == s[0]:
        raise InvalidInputError("simulated_shares must grow with the divergence (non-decreasing, rising somewhere)")
    method = (f"divergence whose simulated share meets the measured {measured.value:.4g} ± {measured.std:.2g} (linear between "
              f"{len(d)} simulated divergences, {d[0]:.3g}° to {d[-1]:.3g}°)")  # fmt: skip

    def inverse(share: float) -> float:
        if not (math.isfinite(share) and s[0] <= share <= s[-1]):
            return math.nan
        # the rising parts only: on a flat part any divergence gives the share; take its middle
        lo, hi = np.searchsorted(s, share, side="left"), np.searchsorted(s, share, side="right")
        if lo < hi:
            return float((d[lo] + d[hi - 1]) / 2.0)
        # the share's place between its two points, then the divergence there: not np.interp, whose slope
        # (d1 - d0) / (s1 - s0) overflows to inf where the shares differ by a subnormal step
        where = (share - s[lo - 1]) / (s[lo] - s[lo - 1])
        return float(d[lo - 1] + (d[lo] - d[lo - 1]) * where)

    value = inverse(measured.value)
    if math.isfinite(value):
        sim_sd = float(np.interp(value, d, sd))
        sigma = math.hypot(measured.std, sim_sd) if math.isfinite(measured.std) else math.nan
        lo, hi = inverse(measured.value - sigma), inverse(measured.value + sigma)
        std = (hi - lo) / 2.0 if math.isfinite(lo) and math.isfinite(hi) else math.nan
    else:
        std = math.nan
    return Estimate(value, std, measured.n, method, "deg")


def check_curve(curve: object, name: str = "divergence_shares") -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """A simulated share curve ``(divergences_deg, shares[, stds])`` checked before any fit rests on it.

    Parameters
    ----------
    curve : tuple of 2 or 3 array_like
        As :func:`divergence_from_shares` takes them (:func:`divergence_curve` reads them from a table).
    name : str
        The argument named in messages.

    Returns
    -------
    divergences_deg, shares, stds : (M,) float64
        ``stds`` zeros when not given.

    Raises
    ------
    ArgumentTypeError
        Not a tuple or list of 2 or 3 arrays of numbers.
    InvalidInputError
        What :func:`divergence_from_shares` refuses (non-finite values, divergences not increasing or above
        :data:`~zbuf_occlude.sensors.beam.footprint.MAX_DIVERGENCE_DEG`, shares outside [0, 1] or not growing), naming ``name``.
    """
    if not (isinstance(curve, (tuple, list)) and len(curve) in (2, 3)):
        raise ArgumentTypeError(f"{name} must be (divergences_deg, shares) or (divergences_deg, shares, stds), got {described(curve)}")
    arrays = []
    for part, item in zip(("divergences_deg", "shares", "stds"), curve, strict=False):
        try:
            arrays.append(np.asarray(item, dtype=np.float64))
        except (TypeError, ValueError):
            raise ArgumentTypeError(f"{name}: {part} must be an array of numbers, got {described(item)}") from None
    d, s, *sd = arrays
    sd = sd[0] if sd else np.zeros_like(s)
    try:
        divergence_from_shares(d, s, Estimate(math.nan, math.nan, 0, "", "share"), sd)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{name}: {exc}") from None
    return d, s, sd


def divergence_curve(
    rows: Sequence[Mapping[str, Any]], name: str
) -> tuple[str, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """A simulated share curve from a table's rows: ``divergence_deg``, then the figure's name, then optionally ``std``.

    The table a simulation writes for :func:`fit_return_model` (``fit-sensor --divergence-shares``):
    a header ``divergence_deg,<figure>[,std]`` whose second column names the return statistics'
    share it simulated (``multi_return_points``, ``multi_return_points_class_5``, ...), then one
    row per simulated divergence (degrees), increasing.

    Parameters
    ----------
    rows : sequence of mapping
        The rows as :func:`~zbuf_occlude.io.tables.read_csv_rows` gives them (column -> text).
    name : str
        The table's file, for messages.

    Returns
    -------
    figure : str
    divergences_deg, shares, stds : (M,) float64
        ``stds`` zeros without a ``std`` column.

    Raises
    ------
    InvalidInputError
        Naming the file: no rows or more than :data:`MAX_CURVE_ROWS`, columns other than those,
        a figure that is not a multi-return share, a value that is not a finite number, or a curve
        :func:`divergence_from_shares` cannot invert.
    """
    if not rows or len(rows) > MAX_CURVE_ROWS:
        raise InvalidInputError(f"{name}: a table of simulated shares needs 2 to {MAX_CURVE_ROWS:,} rows, got {len(rows):,}")
    columns = list(rows[0])
    if not (2 <= len(columns) <= 3 and columns[0] == "divergence_deg" and str(columns[1]).startswith("multi_return_points")
            and columns[2:] in ([], ["std"])):  # fmt: skip
        raise InvalidInputError(
            f"{name}: the header must be divergence_deg,<a multi_return_points figure>[,std], got {len(columns)} columns of other names"
        )
    values = np.full((len(rows), 3), 0.0)
    for i, row in enumerate(rows):
        for j, column in enumerate(columns):
            try:
                values[i, j] = float(row[column])
            except (TypeError, ValueError):
                raise InvalidInputError(f"{name}: row {i + 2}: {column} is not a number") from None
    try:
        divergence_from_shares(values[:, 0], values[:, 1], Estimate(math.nan, math.nan, 0, "", "share"), values[:, 2])
    except InvalidInputError as exc:
        raise InvalidInputError(f"{name}: {exc}") from None
    return str(columns[1]), values[:, 0], values[:, 1], values[:, 2]


def fit_divergence(
    simulate: Callable[[float], float | tuple[float, float]],
    measured: Estimate,
    *,
    divergences_deg: Sequence[float] = DIVERGENCE_GRID_DEG,
) -> tuple[Estimate, NDArray[np.float64], NDArray[np.float64]]:
    """The divergence fitted by simulation: ``simulate`` at each divergence, inverted at ``measured`` (:func:`divergence_from_shares`).

    Parameters
    ----------
    simulate : callable
        ``simulate(divergence_deg) -> share`` or ``-> (share, std)``: the multi-return share of
        a simulated scan of a scanner of that full-angle divergence (degrees), the same figure as
        ``measured`` (e.g. ``return_statistics(read_las(simulated_laz)).estimates["multi_return_points"]``
        of a scene like the scan's, flown at its height).
    measured : Estimate
        The measured share.
    divergences_deg : sequence of float
        Where to simulate, increasing (default :data:`DIVERGENCE_GRID_DEG`, 0.05 to 3 mrad).

    Returns
    -------
    estimate : Estimate
        Degrees.
    divergences_deg, shares : (M,) float64
        The simulated curve, to report.

    Raises
    ------
    InvalidInputError
        What :func:`divergence_from_shares` refuses (a simulated curve that does not grow with the divergence...).
    """
    d = np.asarray(divergences_deg, dtype=np.float64)
    shares, stds = np.empty(len(d)), np.zeros(len(d))
    for i, divergence in enumerate(d):
        out = simulate(float(divergence))
        shares[i], stds[i] = (out, 0.0) if np.ndim(out) == 0 else out
    return divergence_from_shares(d, shares, measured, stds), d, shares
