"""What real object scans show, per class: where the crops stand, how tall their objects are, how much
of each is hidden below, how wide it shows across the line of sight and its outline over the height.

Input: segmented object scans of one class, each ``(N, 3) float64`` with the sensor at the origin,
z up, metres (:attr:`zbuf_occlude.real_scans.records.RealScan.points_sensor_m`).  This is the
scene's, not the sensor's (:mod:`zbuf_occlude.sensors.fit.lidar`): the sensor's horizontal
distance to each scan's centroid (:func:`fit_crop_distances`), each scan's height
(:func:`fit_crop_heights`: its top above the ground) and how high above the ground its lowest
return lies (:func:`fit_crop_bottoms`, with the ground from :func:`fit_sensor_height`) and how
wide it shows across the line of sight (:func:`fit_crop_widths`), as percentile intervals to
draw uniformly, and its outline over the height (:func:`fit_crop_width_profile`);
:func:`crop_placement_json` gathers them per class.  Nothing depends on file names or class labels.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.fit.lidar import _checked_scan

__all__ = [
    "across_sight_width", "crop_placement_json", "DISTANCE_QUANTILES", "fit_crop_bottoms", "fit_crop_distances",
    "fit_crop_heights", "fit_crop_width_profile", "fit_crop_widths", "fit_sensor_height", "median_width_profile",
    "MIN_PLACEMENT_SCANS", "SENSOR_HEIGHT_QUANTILE", "sight_coordinates", "WIDTH_BAND_M", "width_profile",
    "WIDTH_PROFILE_BINS",
]  # fmt: skip
#: Non-empty scans a class needs for its crops' distances and heights (:func:`crop_placement_json`).
MIN_PLACEMENT_SCANS = 3
#: Percentiles of the real scans' distances that bound the fitted crop distances (:func:`fit_crop_distances`).
DISTANCE_QUANTILES = (10.0, 90.0)
#: Percentile of the scans' lowest-return depths below the sensor taken as the ground's (:func:`fit_sensor_height`).
SENSOR_HEIGHT_QUANTILE = 75.0
#: Height of the horizontal bands in which :func:`across_sight_width` measures a scan, metres
#: (about one HDL-32E ring beyond 7 m).
WIDTH_BAND_M = 0.15
#: Bins of relative height of :func:`width_profile`.
WIDTH_PROFILE_BINS = 8
_MIN_HEIGHT_M = 0.05  # a fitted object height is at least this (a scan whose top lies at or below the fitted ground)


def _per_scan(clouds: Sequence[NDArray[np.floating]], measure, what: str) -> NDArray[np.float64]:
    values = []
    for i, c in enumerate(clouds):
        p = _checked_scan(i, c)
        if len(p):
            values.append(float(measure(p)))
    if len(values) < MIN_PLACEMENT_SCANS:
        raise InvalidInputError(f"{what} needs at least {MIN_PLACEMENT_SCANS} non-empty scans, got {len(values)}")
    return np.asarray(values)


def _percentiles_per_scan(
    clouds: Sequence[NDArray[np.floating]], quantiles: tuple[float, float], measure, what: str
) -> tuple[float, float]:
    lo_q, hi_q = (float(q) for q in quantiles)
    if not 0.0 <= lo_q <= hi_q <= 100.0:
        raise InvalidInputError(f"quantiles must satisfy 0 <= lo <= hi <= 100, got {quantiles!r}")
    lo, hi = np.percentile(_per_scan(clouds, measure, what), [lo_q, hi_q])
    return float(lo), float(hi)


def fit_crop_distances(clouds: Sequence[NDArray[np.floating]], quantiles: tuple[float, float] = DISTANCE_QUANTILES) -> tuple[float, float]:
    """The interval of sensor-to-object distances of real object scans, for the crops' placement.

    The distance of a scan is the horizontal distance (xy) from the sensor to the centroid of its
    returns; the interval is their ``quantiles`` percentiles, to be drawn uniformly as
    :class:`~zbuf_occlude.sensors.placement.CropDistributions` ``distance_m``.  The centroid of the
    visible surface lies nearer than the object's centre by up to half the object's depth, so
    the fitted crops stand slightly nearer than the real objects did.

    Parameters
    ----------
    clouds : sequence of (N_i, 3) float
        Segmented object scans of one class; sensor at the origin, z up, metres.
    quantiles : (lo, hi)
        Percentiles in [0, 100], lo <= hi.

    Returns
    -------
    (lo_m, hi_m) : tuple of float
        Metres.

    Raises
    ------
    InvalidInputError
        Fewer than 3 non-empty scans, a scan that is not finite (N, 3), or bad quantiles.
    """
    return _percentiles_per_scan(clouds, quantiles, lambda p: np.hypot(*p[:, :2].mean(axis=0)), "fit_crop_distances")


def fit_crop_heights(clouds: Sequence[NDArray[np.floating]], sensor_height_m: float,
                     quantiles: tuple[float, float] = DISTANCE_QUANTILES) -> tuple[float, float]:  # fmt: skip
    """The interval of the objects' heights in real object scans, for the crops' sizes.

    An object's height is how high above the ground its top return lies, ``max z +
    sensor_height_m`` (z up, metres); the interval is their ``quantiles`` percentiles, to be
    drawn uniformly as a :class:`~zbuf_occlude.mesh.sizes.SizeRange` of dimension ``"height"``.
    Measured from the ground, not from the lowest return, it stays the object's height where
    the bottom is hidden (:func:`fit_crop_bottoms` gives how much), so a crop scaled to it and
    cut as fitted shows what the real scan showed.  It is what the sensor saw at the top: an
    object taller than the top beam reaches at its distance counts as shorter, and the crops
    are made as tall as that.

    Parameters
    ----------
    clouds : sequence of (N_i, 3) float
        Segmented object scans of one class; sensor at the origin, z up, metres.
    sensor_height_m : float
        :func:`fit_sensor_height` of the user's scans, metres.
    quantiles : (lo, hi)
        Percentiles in [0, 100], lo <= hi.

    Returns
    -------
    (lo_m, hi_m) : tuple of float
        Metres, > 0.

    Raises
    ------
    InvalidInputError
        As :func:`fit_crop_distances`, or a sensor height that is not finite.
    """
    h = _check_height(sensor_height_m)
    return _percentiles_per_scan(clouds, quantiles, lambda p: max(float(p[:, 2].max()) + h, _MIN_HEIGHT_M), "fit_crop_heights")


def fit_sensor_height(clouds: Sequence[NDArray[np.floating]], quantile: float = SENSOR_HEIGHT_QUANTILE) -> float:
    """The sensor's height above the ground the scanned objects stand on, from their lowest returns.

    Each scan's lowest return lies ``−min z`` below the sensor: at the ground (within the beam
    gap) for an object seen down to its foot, higher for one whose bottom is hidden.  The
    ground's depth is the ``quantile`` percentile of these depths over all scans, of every class
    (75: at least a quarter of the scans must reach the ground; sloped ground spreads them).

    Parameters
    ----------
    clouds : sequence of (N_i, 3) float
        Segmented object scans; sensor at the origin, z up, metres.
    quantile : float
        Percentile in [0, 100].

    Returns
    -------
    float
        Metres (may be <= 0 for scans that were not taken from above the ground).

    Raises
    ------
    InvalidInputError
        Fewer than 3 non-empty scans, a scan that is not finite (N, 3), or a bad quantile.
    """
    return _percentiles_per_scan(clouds, (quantile, quantile), lambda p: -p[:, 2].min(), "fit_sensor_height")[0]


def fit_crop_bottoms(clouds: Sequence[NDArray[np.floating]], sensor_height_m: float,
                     quantiles: tuple[float, float] = DISTANCE_QUANTILES) -> tuple[float, float]:  # fmt: skip
    """The interval of heights above the ground of real scans' lowest returns, for the crops' ``hidden_below_m``.

    A scan's lowest return lies ``min z + sensor_height_m`` above the ground (clipped at 0);
    the interval is their ``quantiles`` percentiles, to be drawn uniformly as
    :class:`~zbuf_occlude.sensors.placement.CropDistributions` ``hidden_below_m`` (metres, >= 0).  A
    real bottom includes the gap between the ground and the lowest beam that hits the object,
    which the simulated scan makes again under the cut, so the simulated bottoms lie slightly
    higher.

    Parameters, returns and errors as :func:`fit_crop_heights`.
    """
    h = _check_height(sensor_height_m)
    return _percentiles_per_scan(clouds, quantiles, lambda p: max(float(p[:, 2].min()) + h, 0.0), "fit_crop_bottoms")


def across_sight_width(points: NDArray[np.floating], band_m: float = WIDTH_BAND_M) -> float:
    """How wide an object scan shows across the line of sight, metres.

    The returns are cut into horizontal bands ``band_m`` high; in each band of two or more
    returns, the width is their extent along the horizontal direction perpendicular to the
    line of sight (from the sensor to the scan's centroid, in the ground plane).  The scan's
    width is the median over those bands: a trunk's diameter, a person's shoulders, a post's
    thickness under its sign, whatever the scan's outline.  A ring's returns sample the outline
    at the sensor's azimuth step, so measure real and simulated scans of one sensor alike.

    Parameters
    ----------
    points : (N, 3) float
        One object scan; sensor at the origin, z up, metres.
    band_m : float
        Band height, metres, > 0.

    Returns
    -------
    float
        Metres, >= 0; 0 when no band holds two returns.

    Raises
    ------
    InvalidInputError
        ``points`` not a finite (N, 3) array, or a bad ``band_m``.
    """
    p = _checked_scan(0, points)
    if not (math.isfinite(band_m) and band_m > 0):
        raise InvalidInputError(f"band_m must be a number > 0 metres, got {band_m!r}")
    return _across_sight_width(p, band_m)


def _across_sight_width(p: NDArray[np.float64], band_m: float = WIDTH_BAND_M) -> float:
    """:func:`across_sight_width` of a checked ``(N, 3) float64`` scan."""
    return _band_width(_across_sight(p), p[:, 2], band_m) if len(p) >= 2 else 0.0


def _band_width(across: NDArray[np.float64], z: NDArray[np.float64], band_m: float) -> float:
    """The median over ``band_m`` high bands of two or more returns of their extent in ``across`` (0 when none)."""
    _, extent, counts = _extent_per_group(across, np.floor((z - z.min()) / band_m).astype(np.int64))
    widths = extent[counts >= 2]
    return float(np.median(widths)) if len(widths) else 0.0


def _extent_per_group(values: NDArray[np.float64], groups: NDArray[np.int64]):
    """For each group id present in ``groups (N,)``: the id, ``max − min`` of its ``values (N,)``, and its count."""
    order = np.argsort(groups, kind="stable")
    sorted_groups = groups[order]
    starts = np.flatnonzero(np.r_[True, np.diff(sorted_groups) != 0])
    extent = np.maximum.reduceat(values[order], starts) - np.minimum.reduceat(values[order], starts)
    return sorted_groups[starts], extent, np.diff(np.r_[starts, len(values)])


def sight_coordinates(points: NDArray[np.floating]) -> NDArray[np.float64]:
    """Each return's horizontal coordinates along and across the line of sight, metres.

    The line of sight runs from the sensor (the origin) to the scan's centroid, in the ground plane;
    across is perpendicular to it, 90 degrees counter-clockwise seen from above (the direction
    :func:`across_sight_width` and :func:`width_profile` measure in).  For a centroid straight above the
    sensor, across is x and along is −y.

    Parameters
    ----------
    points : (N, 3) float
        One object scan; sensor at the origin, z up, metres.

    Returns
    -------
    (N, 2) float64
        Along, then across the line of sight.

    Raises
    ------
    InvalidInputError
        ``points`` not a finite (N, 3) array.
    """
    p = _checked_scan(0, points)
    sight = _sight_unit(p)
    return np.column_stack([p[:, :2] @ sight, _across_sight(p, sight)])


def _sight_unit(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """The unit horizontal direction from the sensor (the origin) to the scan's centroid; −y for a centroid straight above."""
    sight = p[:, :2].mean(axis=0) if len(p) else np.zeros(2)
    norm = float(np.hypot(*sight))
    return sight / norm if norm > 0 else np.array([0.0, -1.0])


def _across_sight(p: NDArray[np.float64], sight: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """``(N,)`` each return's coordinate along the horizontal direction perpendicular to the line
    of sight ``sight`` (:func:`_sight_unit` by default); along x for a centroid straight above."""
    sight = _sight_unit(p) if sight is None else sight
    return p[:, :2] @ np.array([-sight[1], sight[0]])


def fit_crop_widths(clouds: Sequence[NDArray[np.floating]]) -> tuple[float, float]:
    """The interval of real object scans' widths across the line of sight (:func:`across_sight_width`), for :func:`fit_width_scale`.

    The uniform interval with the scans' median width ``m`` and interquartile range ``q``:
    ``(max(m − q, 0), m + q)``.  Widths have a long upper tail (two objects segmented as one),
    so a uniform draw between outer percentiles would make the crops wider than most scans.

    Parameters
    ----------
    clouds : sequence of (N_i, 3) float
        Segmented object scans of one class; sensor at the origin, z up, metres.

    Returns
    -------
    (lo_m, hi_m) : tuple of float
        Metres, >= 0.

    Raises
    ------
    InvalidInputError
        Fewer than 3 non-empty scans, or a scan that is not finite (N, 3).
    """
    q25, m, q75 = np.percentile(_per_scan(clouds, _across_sight_width, "fit_crop_widths"), [25.0, 50.0, 75.0])
    return max(float(m - (q75 - q25)), 0.0), float(m + (q75 - q25))


def width_profile(points: NDArray[np.floating], n_bins: int = WIDTH_PROFILE_BINS) -> NDArray[np.float64]:
    """An object scan's outline over its height: how wide it shows across the line of sight per bin of relative height, over its width.

    The scan's vertical extent is cut into ``n_bins`` equal bins (0: its lowest return, 1: its
    top); a bin of two or more returns has their extent along the horizontal direction
    perpendicular to the line of sight (as :func:`across_sight_width`), divided by the scan's
    :func:`across_sight_width`.  Unitless: a real person's knees show about 0.5 of their width
    and their shoulders 1.2; a trunk about 1 throughout.

    Parameters
    ----------
    points : (N, 3) float
        One object scan; sensor at the origin, z up, metres.
    n_bins : int
        Bins, >= 2.

    Returns
    -------
    (n_bins,) float64
        NaN for a bin of fewer than two returns, and everywhere when the scan shows no width.

    Raises
    ------
    InvalidInputError
        ``points`` not a finite (N, 3) array, or ``n_bins`` < 2.
    """
    if int(n_bins) < 2:
        raise InvalidInputError(f"n_bins must be >= 2, got {n_bins!r}")
    return _width_profile(_checked_scan(0, points), int(n_bins))


def _width_profile(p: NDArray[np.float64], n_bins: int) -> NDArray[np.float64]:
    """:func:`width_profile` of a checked ``(N, 3) float64`` scan."""
    out = np.full(n_bins, np.nan)
    if len(p) < 2:
        return out
    across, z = _across_sight(p), p[:, 2]
    width = _band_width(across, z, WIDTH_BAND_M)
    if not width > 0:
        return out
    height = float(np.ptp(z))
    bins = np.zeros(len(p), np.int64) if height <= 0 else np.minimum(((z - z.min()) / height * n_bins).astype(np.int64), n_bins - 1)
    ids, extent, counts = _extent_per_group(across, bins)
    out[ids[counts >= 2]] = extent[counts >= 2] / width
    return out


def fit_crop_width_profile(clouds: Sequence[NDArray[np.floating]], n_bins: int = WIDTH_PROFILE_BINS) -> tuple[float, ...]:
    """The outline over the height of one class of real object scans: the median of their :func:`width_profile`, bin by bin.

    Parameters
    ----------
    clouds : sequence of (N_i, 3) float
        Segmented object scans of one class; sensor at the origin, z up, metres.
    n_bins : int
        Bins, >= 2.

    Returns
    -------
    tuple of ``n_bins`` float
        Widths over the scans' widths; 1.0 in a bin that no scan fills (no information: no warp).

    Raises
    ------
    InvalidInputError
        Fewer than 3 scans that show a width, a scan that is not finite (N, 3), or ``n_bins`` < 2.
    """
    rows = [row for row in _profile_rows(clouds, n_bins) if np.isfinite(row).any()]
    if len(rows) < MIN_PLACEMENT_SCANS:
        raise InvalidInputError(f"fit_crop_width_profile needs at least {MIN_PLACEMENT_SCANS} scans that show a width, got {len(rows)}")
    return _nan_median_or_one(np.array(rows))


def median_width_profile(clouds: Sequence[NDArray[np.floating]], n_bins: int = WIDTH_PROFILE_BINS) -> NDArray[np.float64]:
    """The median of object scans' :func:`width_profile`, bin by bin, over the scans that fill the bin.

    Parameters
    ----------
    clouds : sequence of (N_i, 3) float
        Object scans; sensor at the origin, z up, metres.
    n_bins : int
        Bins, >= 2.

    Returns
    -------
    (n_bins,) float64
        NaN in a bin that no scan fills (and everywhere for no scans).

    Raises
    ------
    InvalidInputError
        A scan that is not finite (N, 3), or ``n_bins`` < 2.
    """
    rows = _profile_rows(clouds, n_bins)
    return _nan_median(np.array(rows).reshape(len(rows), int(n_bins)))


def _profile_rows(clouds: Sequence[NDArray[np.floating]], n_bins) -> list[NDArray[np.float64]]:
    """:func:`width_profile` of each scan (checked; all NaN for one that shows no width), ``n_bins`` checked first."""
    if int(n_bins) < 2:
        raise InvalidInputError(f"n_bins must be >= 2, got {n_bins!r}")
    return [_width_profile(_checked_scan(i, c), int(n_bins)) for i, c in enumerate(clouds)]


def _nan_median(rows: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per column of ``rows (K, B)``, the median of its finite values; NaN where it has none."""
    filled = np.isfinite(rows).any(axis=0)
    median = np.full(rows.shape[1], np.nan)
    median[filled] = np.nanmedian(rows[:, filled], axis=0)
    return median


def _nan_median_or_one(rows: NDArray[np.float64]) -> tuple[float, ...]:
    """:func:`_nan_median` with 1.0 (no warp) where a column has no finite value."""
    return tuple(float(v) if math.isfinite(v) else 1.0 for v in _nan_median(rows))


def _check_height(sensor_height_m) -> float:
    h = float(sensor_height_m)
    if not math.isfinite(h):
        raise InvalidInputError(f"sensor_height_m must be finite metres, got {sensor_height_m!r}")
    return h


def crop_placement_json(clouds: Sequence[NDArray[np.floating]], labels: Sequence[str]) -> dict:
    """:func:`fit_crop_distances`, :func:`fit_crop_heights`, :func:`fit_crop_bottoms`, :func:`fit_crop_widths` and :func:`fit_crop_width_profile` per label: the ``crops`` block of a fitted sensor's ``fit``.

    Returns ``{"quantiles": [lo, hi], "sensor_height_m": h, "distance_m": {label: [lo_m, hi_m]},
    "object_height_m": {label: [lo_m, hi_m]}, "hidden_below_m": {label: [lo_m, hi_m]},
    "across_sight_width_m": {label: [lo_m, hi_m]}, "across_sight_profile": {label: [K values]}}``
    (labels sorted; ``h`` is :func:`fit_sensor_height` over every scan).

    Raises
    ------
    InvalidInputError
        A label with fewer than 3 non-empty scans (naming it), or ``labels`` not one per cloud.
    """
    if len(labels) != len(clouds):
        raise InvalidInputError(f"crop_placement_json: {len(labels)} labels for {len(clouds)} scans")
    height = fit_sensor_height(clouds)
    out: dict = {"quantiles": list(DISTANCE_QUANTILES), "sensor_height_m": height, "distance_m": {}, "object_height_m": {}, "hidden_below_m": {},
                 "across_sight_width_m": {}, "across_sight_profile": {}}  # fmt: skip
    for label in sorted(set(labels)):
        of_label = [c for c, y in zip(clouds, labels) if y == label]
        try:
            out["distance_m"][label] = list(fit_crop_distances(of_label))
            out["object_height_m"][label] = list(fit_crop_heights(of_label, height))
            out["hidden_below_m"][label] = list(fit_crop_bottoms(of_label, height))
            out["across_sight_width_m"][label] = list(fit_crop_widths(of_label))
            out["across_sight_profile"][label] = list(fit_crop_width_profile(of_label))
        except InvalidInputError as exc:
            raise InvalidInputError(f"class {label!r}: {exc}") from None
    return out
