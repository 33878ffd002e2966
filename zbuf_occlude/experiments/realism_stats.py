"""Per-cloud statistics of object clouds, for comparing generated scans with real ones.

For each object cloud, in a frame centred on the sensor with z up (metres):

* rings (:func:`ring_labels`) and ring spacing (:func:`ring_spacings_deg`): point elevations
  ``asin(z / |p|)`` are grouped into rings (a gap larger than ``ring_gap_deg`` starts a new ring);
  the spacing is the difference of consecutive ring elevations (median elevation per ring), degrees;
* range: distance from the sensor to the cloud's centroid, metres; the point count against it
  gives the exponent ``b`` of ``count ∝ range^b`` (:func:`fit_count_exponent`: least squares in
  log–log over the clouds), and the median count per range bin (:func:`range_bin_medians`);
* nearest-neighbour spacing: median distance of a point to its nearest other point, metres;
* vertical extent: ``max z − min z``, metres;
* across-sight width: how wide the cloud shows across the line of sight, metres
  (:func:`zbuf_occlude.sensors.fit.across_sight_width`);
* outline share (:func:`outline_share`): within each ring, the points sorted by azimuth split into
  runs (:func:`scan_line_runs`) where the azimuth gap to the next point exceeds
  :data:`OUTLINE_GAP_FACTOR` times the ring's azimuth step; the two ends of each run (one point for
  a run of one) are the outline (:func:`outline_mask`).  Its share of the points is the share whose
  neighbouring footprint along the scan line falls off the object: the points where a beam's
  footprint straddles the object's edge (mixed pixels), which a multi-ray footprint model adds and
  a real receiver may drop.

:func:`cloud_stats` gathers them for one cloud.

For any cloud, in any frame with z up (airborne crops record no sensor position, so neither rings
nor ranges), :func:`shape_stats` gives its points; its height (``max z − min z``) over its width
(the x–y extent along the footprint's principal axis, so that a crop's heading does not matter);
and how its points spread over the height, each point's height above the crop's lowest over the
crop's height (0 at the bottom, 1 at the top): its median, and the share of points in each tenth
of the height.  :func:`class_summary` takes their medians over a class's crops, and for clouds in
a sensor frame also the median points per crop in range bins (:data:`RANGE_BINS_M`), the count
exponent over the crops and the median outline share.

:mod:`zbuf_occlude.experiments.realism` reads the sets and compares them with these statistics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.fit import across_sight_width

__all__ = [
    "ObjectCloud", "RING_GAP_DEG", "OUTLINE_GAP_FACTOR", "SAME_AZIMUTH_DEG", "RANGE_BINS_M", "HEIGHT_BINS",
    "ring_labels", "ring_spacings_deg", "outline_mask", "scan_line_runs", "break_depths_m", "outline_share", "range_bin_medians",
    "fit_count_exponent", "cloud_stats", "shape_stats", "class_summary", "profile_distance",
]  # fmt: skip

#: Elevation gap that separates two rings, degrees: a third of the HDL-32E's 1.33° spacing,
#: far above the elevation jitter of one ring (noise is along the beam).
RING_GAP_DEG = 0.4
#: A ring's run of points ends where the azimuth gap to the next point exceeds this many azimuth
#: steps: a missed pulse or two (a dropout, a hole in the object) is more than one step and less
#: than two, half-way between; a gap a step wide is the scan line going on.
OUTLINE_GAP_FACTOR = 1.5
#: Points of one ring whose azimuths differ by at most this are one pulse's returns, degrees: a
#: step of a spinning scanner is 0.08-0.4° (HDL-32E: 0.166°), float32 points round at 1e-5°.
SAME_AZIMUTH_DEG = 1e-3
#: Edges of the range bins of a class's points per crop, metres: the ``lidar`` set's 5-25 m
#: (:data:`zbuf_occlude.experiments.sim2real.placement.LIDAR_PLACEMENT`) in 5 m steps.
RANGE_BINS_M = (5.0, 10.0, 15.0, 20.0, 25.0)
#: Bins of a crop's height for its vertical profile: tenths.
HEIGHT_BINS = 10


@dataclass
class ObjectCloud:
    """One object's returns.

    Attributes
    ----------
    points_m : (N, 3) float64
        Sensor at the origin, world axes (z up), metres.
    label : str
    source : str
    """

    points_m: NDArray[np.float64]
    label: str
    source: str


def _sensor_points(points_m, what: str = "points_m") -> NDArray[np.float64]:
    """``points_m`` as ``(N, 3) float64``, finite and none at the sensor (whose direction is undefined).

    Raises
    ------
    InvalidInputError
        Another shape, a value not finite, or a point at the origin, naming ``what``.
    """
    p = np.asarray(points_m, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InvalidInputError(f"{what} must be an (N, 3) array of points, got shape {p.shape}")
    if not np.isfinite(p).all():
        raise InvalidInputError(f"{what}: every coordinate must be finite")
    if len(p) and not (np.abs(p).max(axis=1) > 0).all():
        raise InvalidInputError(f"{what}: a point at the sensor (the origin) has no direction")
    return p


def _elevations_deg(p: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.degrees(np.arcsin(np.clip(p[:, 2] / np.linalg.norm(p, axis=1), -1, 1)))


def ring_labels(points_m: NDArray[np.floating], *, ring_gap_deg: float = RING_GAP_DEG) -> NDArray[np.int64]:
    """Each point's ring, from its elevation alone (module docstring).

    Parameters
    ----------
    points_m : (N, 3) float
        Sensor at the origin, z up, metres.
    ring_gap_deg : float
        An elevation gap wider than this between consecutive points (sorted by elevation) starts a
        new ring, degrees (:data:`RING_GAP_DEG`).

    Returns
    -------
    (N,) int64
        0 for the lowest ring, counting up.

    Raises
    ------
    InvalidInputError
        ``points_m`` not ``(N, 3)``, not finite, or a point at the origin.
    """
    p = _sensor_points(points_m)
    elev = _elevations_deg(p)
    order = np.argsort(elev, kind="stable")
    labels = np.empty(len(p), dtype=np.int64)
    labels[order] = np.concatenate([[0], np.cumsum(np.diff(elev[order]) > ring_gap_deg)]) if len(p) else []
    return labels


def ring_spacings_deg(points_m: NDArray[np.floating], *, ring_gap_deg: float = RING_GAP_DEG) -> NDArray[np.float64]:
    """(R − 1,) float64: elevation differences of consecutive rings (:func:`ring_labels`), each ring
    at its points' median elevation, degrees (module docstring)."""
    p = _sensor_points(points_m)
    if len(p) < 2:
        return np.zeros(0)
    elev, labels = _elevations_deg(p), ring_labels(p, ring_gap_deg=ring_gap_deg)
    return np.diff([np.median(elev[labels == r]) for r in range(labels.max() + 1)])


def outline_mask(points_m: NDArray[np.floating], *, ring_gap_deg: float = RING_GAP_DEG, azimuth_step_deg: float | None = None,
                 gap_factor: float = OUTLINE_GAP_FACTOR) -> NDArray[np.bool_]:  # fmt: skip
    """Which points end a run of their ring's scan line: the outline of a spinning LiDAR's object cloud.

    Points are grouped into rings (:func:`ring_labels`); within a ring they are sorted by azimuth,
    measured from the azimuth of the cloud's centroid (so that a cloud behind the sensor, across
    ±180°, is one span; a ring of nearly a full turn is also cut where ±180° from that azimuth
    falls inside it), and split into runs where the gap to the next point exceeds ``gap_factor``
    times the ring's azimuth step.  The first and the last point of each run are outline points;
    a run of one point is one outline point.  Points of one pulse (several returns, azimuths
    within :data:`SAME_AZIMUTH_DEG`) never split a run, and ties keep the points' order.

    Parameters
    ----------
    points_m : (N, 3) float
        One object's cloud, sensor at the origin, z up, metres.
    ring_gap_deg : float
        :func:`ring_labels`' elevation gap, degrees.
    azimuth_step_deg : float, optional
        The scanner's azimuth step, degrees, for every ring; None: each ring's median gap between
        distinct azimuths (gaps above :data:`SAME_AZIMUTH_DEG`; a ring without such a gap is one run).
    gap_factor : float
        :data:`OUTLINE_GAP_FACTOR`.

    Returns
    -------
    (N,) bool
        True at outline points.

    Raises
    ------
    InvalidInputError
        ``points_m`` not ``(N, 3)``, not finite, or a point at the origin; ``azimuth_step_deg``
        or ``gap_factor`` not a finite number above 0.
    """
    p = _sensor_points(points_m)
    mask = np.zeros(len(p), dtype=bool)
    for ring, breaks in _ring_runs(p, ring_gap_deg, azimuth_step_deg, gap_factor):
        mask[ring[np.concatenate([[0], breaks + 1])]] = True  # run starts
        mask[ring[np.concatenate([breaks, [len(ring) - 1]])]] = True  # run ends
    return mask


def _ring_runs(p: NDArray[np.float64], ring_gap_deg: float, azimuth_step_deg: float | None, gap_factor: float):
    """Per ring, lowest first: its points' indices in azimuth order, and the positions in that order after which a run
    ends inside the ring (:func:`outline_mask`'s rule; ``p`` checked, the options checked here)."""
    from zbuf_occlude.sensors.checks import real

    factor = real(gap_factor, "gap_factor", low=0.0, low_open=True)
    step_given = None if azimuth_step_deg is None else real(azimuth_step_deg, "azimuth_step_deg", low=0.0, low_open=True)
    if not len(p):
        return
    centre = p.mean(axis=0)
    azimuth = np.degrees(np.arctan2(p[:, 1], p[:, 0])) - math.degrees(math.atan2(centre[1], centre[0]))
    azimuth = (azimuth + 180.0) % 360.0 - 180.0
    labels = ring_labels(p, ring_gap_deg=ring_gap_deg)
    order = np.lexsort((azimuth, labels))  # by ring, then azimuth; stable on ties
    starts = np.flatnonzero(np.diff(labels[order], prepend=-1))
    for ring in np.split(order, starts[1:]):
        gaps = np.diff(azimuth[ring])
        if step_given is None:
            distinct = gaps[gaps > SAME_AZIMUTH_DEG]
            step = float(np.median(distinct)) if len(distinct) else math.inf
        else:
            step = step_given
        yield ring, np.flatnonzero(gaps > factor * step)


def scan_line_runs(points_m: NDArray[np.floating], *, ring_gap_deg: float = RING_GAP_DEG, azimuth_step_deg: float | None = None,
                   gap_factor: float = OUTLINE_GAP_FACTOR) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # fmt: skip
    """The runs of a cloud's scan lines (:func:`outline_mask`'s, which takes the same options): each run's ring and length.

    With ``R`` runs over ``G`` rings and ``N`` points, ``(R − G) / (N − G)`` is the share of the
    gaps between neighbours along a ring that break it (missed pulses, holes, occluders).

    Returns
    -------
    ring : (R,) int64
        The run's ring (:func:`ring_labels`), runs ordered by ring, then azimuth.
    length : (R,) int64
        Its points, each at least 1; they sum to ``N``.

    Raises
    ------
    InvalidInputError
        As :func:`outline_mask`.
    """
    rings, lengths = [], []
    for r, (ring, breaks) in enumerate(_ring_runs(_sensor_points(points_m), ring_gap_deg, azimuth_step_deg, gap_factor)):
        lengths.append(np.diff(np.concatenate([[0], breaks + 1, [len(ring)]])))
        rings.append(np.full(len(breaks) + 1, r, dtype=np.int64))
    if not rings:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(rings), np.concatenate(lengths).astype(np.int64)


def break_depths_m(points_m: NDArray[np.floating], *, ring_gap_deg: float = RING_GAP_DEG, azimuth_step_deg: float | None = None,
                   gap_factor: float = OUTLINE_GAP_FACTOR) -> NDArray[np.float64]:  # fmt: skip
    """How deep each break of a cloud's scan lines is: the range step across it, metres (the runs of :func:`scan_line_runs`,
    which takes the same options).

    A break is the gap between two runs of one ring; its depth is ``|R_after − R_before|``, the ranges of the
    last point of the run before it and the first of the run after it (in azimuth order about the cloud's
    centroid).  A break where the line leaves the object at its outline and comes back on a nearer or farther
    part is deep; a missed pulse on one surface leaves a shallow one.

    Returns
    -------
    (B,) float64
        One depth per break, ring by ring, then by azimuth; empty where no ring breaks.

    Raises
    ------
    InvalidInputError
        As :func:`outline_mask`.
    """
    p = _sensor_points(points_m)
    r = np.linalg.norm(p, axis=1)
    depths = [np.abs(r[ring[breaks + 1]] - r[ring[breaks]]) for ring, breaks in _ring_runs(p, ring_gap_deg, azimuth_step_deg, gap_factor)]
    return np.concatenate(depths) if depths else np.zeros(0)


def outline_share(points_m: NDArray[np.floating], **options) -> float:
    """The share of a cloud's points on its outline, in (0, 1]: :func:`outline_mask` (which takes
    ``options``) over the point count; NaN for no points.  One run of ``m >= 2`` points gives
    ``2 / m``; a cloud of isolated points, 1.

    Raises
    ------
    InvalidInputError
        As :func:`outline_mask`.
    """
    mask = outline_mask(points_m, **options)
    return float(mask.mean()) if len(mask) else math.nan


def range_bin_medians(range_m, count, bins_m: tuple[float, ...] = RANGE_BINS_M) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The median of ``count`` over the clouds in each range bin, and how many clouds each holds.

    Parameters
    ----------
    range_m, count : (C,) float
        Per cloud: distance from the sensor to its centroid, metres, and its points.
    bins_m : (B + 1,) float
        Increasing bin edges, metres (:data:`RANGE_BINS_M`); bin ``i`` is ``[bins_m[i], bins_m[i + 1])``,
        the last one closed; clouds outside every bin are not counted.

    Returns
    -------
    medians : (B,) float64
        NaN for an empty bin.
    clouds : (B,) int64
    """
    r, n = np.asarray(range_m, dtype=np.float64), np.asarray(count, dtype=np.float64)
    edges = np.asarray(bins_m, dtype=np.float64)
    which = np.searchsorted(edges, r, side="right") - 1
    which[r == edges[-1]] = len(edges) - 2  # the last bin is closed
    medians = np.full(len(edges) - 1, math.nan)
    clouds = np.zeros(len(edges) - 1, dtype=np.int64)
    for b in range(len(edges) - 1):
        inside = which == b
        clouds[b] = int(inside.sum())
        if clouds[b]:
            medians[b] = float(np.median(n[inside]))
    return medians, clouds


def fit_count_exponent(range_m, count) -> tuple[float, float, float]:
    """Least-squares fit ``log count = a + b log range``: ``(b, standard error of b, a)``."""
    x, y = np.log(np.asarray(range_m, float)), np.log(np.asarray(count, float))
    if len(x) < 3 or np.ptp(x) == 0:
        return float("nan"), float("nan"), float("nan")
    A = np.column_stack([np.ones_like(x), x])
    coef, res, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ coef
    se = math.sqrt(resid @ resid / (len(x) - 2) / ((x - x.mean()) @ (x - x.mean())))
    return float(coef[1]), se, float(coef[0])


def cloud_stats(cloud: ObjectCloud, *, ring_gap_deg: float = RING_GAP_DEG) -> dict:
    """Per-cloud statistics: ``n_points, range_m, n_rings, ring_spacings_deg, nn_spacing_m, vertical_extent_m, across_sight_width_m,
    outline_share`` (:func:`outline_share`)."""
    from scipy.spatial import cKDTree

    p = _sensor_points(cloud.points_m, f"{cloud.source}: points")
    spacing = ring_spacings_deg(p, ring_gap_deg=ring_gap_deg)
    nn = float(np.median(cKDTree(p).query(p, k=2)[0][:, 1])) if len(p) > 1 else float("nan")
    return {
        "n_points": len(p),
        "range_m": float(np.linalg.norm(p.mean(axis=0))),
        "n_rings": len(spacing) + 1,
        "ring_spacings_deg": spacing,
        "nn_spacing_m": nn,
        "vertical_extent_m": float(np.ptp(p[:, 2])) if len(p) else 0.0,
        "across_sight_width_m": across_sight_width(p),
        "outline_share": outline_share(p, ring_gap_deg=ring_gap_deg),
    }


def shape_stats(points_m: NDArray[np.floating]) -> dict:
    """One crop's size and vertical distribution, in any frame with z up (module docstring).

    Parameters
    ----------
    points_m : (N, 3) float
        Metres, z up; no sensor position needed.

    Returns
    -------
    dict
        ``n_points``; ``height_m`` and ``width_m`` (x–y extent along the footprint's principal
        axis), metres; ``height_to_width`` (NaN for a width of 0); ``plan_elongation``, the footprint's
        spread along its principal axis over its spread across it (the square root of the ratio of the
        x–y covariance's eigenvalues; 1 for a round footprint, NaN for a line); ``median_normalised_height``
        (NaN for a height of 0); ``height_shares``, ``(HEIGHT_BINS,) float64``, the share of the
        points in each tenth of the height, bottom to top (all in the bottom bin for a height of 0).
    """
    p = np.asarray(points_m, dtype=np.float64)
    z = p[:, 2]
    height = float(np.ptp(z)) if len(p) else 0.0
    xy = p[:, :2] - p[:, :2].mean(axis=0) if len(p) else np.zeros((0, 2))
    width, elongation = 0.0, math.nan
    if len(p) > 1:
        spread, axes = np.linalg.eigh(xy.T @ xy)
        width = float(np.ptp(xy @ axes[:, -1]))  # along the largest principal axis
        if spread[0] > 1e-12 * spread[1]:
            elongation = math.sqrt(spread[1] / spread[0])
    u = (z - z.min()) / height if height > 0 else np.zeros(len(z))
    shares = np.bincount(np.minimum((u * HEIGHT_BINS).astype(np.int64), HEIGHT_BINS - 1), minlength=HEIGHT_BINS) / max(len(z), 1)
    return {
        "n_points": len(p), "height_m": height, "width_m": width,
        "height_to_width": height / width if width > 0 else math.nan, "plan_elongation": elongation,
        "median_normalised_height": float(np.median(u)) if height > 0 else math.nan,
        "height_shares": shares.astype(np.float64),
    }  # fmt: skip


def profile_distance(shares_a: NDArray[np.floating], shares_b: NDArray[np.floating]) -> float:
    """How far apart two vertical profiles are: the share of points that would have to move to
    another tenth of the height, ``0.5 · Σ |a − b|`` (total variation; 0 the same, 1 disjoint).

    Parameters
    ----------
    shares_a, shares_b : (HEIGHT_BINS,) float
        Shares of points per tenth of the height (:func:`shape_stats`' ``height_shares``, or a mean of them).
    """
    return 0.5 * float(np.abs(np.asarray(shares_a, np.float64) - np.asarray(shares_b, np.float64)).sum())


def class_summary(clouds: list[ObjectCloud], *, by_range: bool = False, bins_m: tuple[float, ...] = RANGE_BINS_M) -> dict:
    """Medians over a class's crops of :func:`shape_stats`, and the mean of their height shares.

    Parameters
    ----------
    clouds : list of ObjectCloud
        One class's crops (at least one).
    by_range : bool
        The clouds are in a sensor frame (sensor at the origin, z up, metres): add their points
        against range and their outline.
    bins_m : (B + 1,) float
        Range bin edges, metres (:func:`range_bin_medians`).

    Returns
    -------
    dict
        ``crops``; the medians of ``n_points``, ``height_m``, ``width_m``, ``height_to_width``,
        ``plan_elongation`` and ``median_normalised_height`` (NaN where no crop gives a finite one);
        ``height_shares``, ``(HEIGHT_BINS,) float64``; with
        ``by_range`` also ``range_m`` (median distance to the centroid, metres),
        ``n_points_by_range`` and ``crops_by_range`` (:func:`range_bin_medians`, ``(B,)``),
        ``count_exponent`` (:func:`fit_count_exponent` over the crops; NaN for fewer than three
        or one range) and ``outline_share`` (the median of :func:`outline_share`).
    """
    stats = [shape_stats(c.points_m) for c in clouds]
    summary = {"crops": len(stats)}
    for key in ("n_points", "height_m", "width_m", "height_to_width", "plan_elongation", "median_normalised_height"):
        values = np.array([st[key] for st in stats], dtype=np.float64)
        summary[key] = float(np.nanmedian(values)) if np.isfinite(values).any() else math.nan
    summary["height_shares"] = np.mean([st["height_shares"] for st in stats], axis=0)
    if by_range:
        ranges = np.array([np.linalg.norm(c.points_m.mean(axis=0)) for c in clouds])
        counts = np.array([len(c.points_m) for c in clouds])
        summary["range_m"] = float(np.median(ranges))
        summary["n_points_by_range"], summary["crops_by_range"] = range_bin_medians(ranges, counts, bins_m)
        summary["count_exponent"] = fit_count_exponent(ranges, counts)[0]
        summary["outline_share"] = float(np.nanmedian([outline_share(_sensor_points(c.points_m, f"{c.source}: points")) for c in clouds]))
    return summary
