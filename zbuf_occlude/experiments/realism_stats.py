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

:func:`cloud_stats` gathers them for one cloud.  The rings, scan lines and outline are a spinning LiDAR's
(:mod:`zbuf_occlude.sensors.fit.scan_lines`, which ``fit-sensor --meshes`` fits by too).

For any cloud, in any frame with z up (airborne crops record no sensor position, so neither rings
nor ranges), :func:`shape_stats` gives its points; its height (``max z − min z``) over its width
(the x–y extent along the footprint's principal axis, so that a crop's heading does not matter);
and how its points spread over the height, each point's height above the crop's lowest over the
crop's height (0 at the bottom, 1 at the top): its median, and the share of points in each tenth
of the height.  :func:`class_summary` takes their medians over a class's crops, and for clouds in
a sensor frame also the median points per crop in range bins (:data:`RANGE_BINS_M`), the count
exponent over the crops, the median outline share and the median width profile (how wide each eighth of the
height shows across the line of sight over the crop's width: :func:`zbuf_occlude.sensors.fit.width_profile`; a
person narrow at the knees and widest at the shoulders, a trunk about 1 throughout).

:mod:`zbuf_occlude.experiments.realism` reads the sets and compares them with these statistics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.sensors.fit import across_sight_width, median_width_profile
from zbuf_occlude.sensors.fit.scan_lines import (
    OUTLINE_GAP_FACTOR,
    RING_GAP_DEG,
    SAME_AZIMUTH_DEG,
    break_depths_m,
    outline_mask,
    outline_share,
    ring_labels,
    ring_spacings_deg,
    scan_line_runs,
    sensor_points,
)

__all__ = [
    "ObjectCloud", "RING_GAP_DEG", "OUTLINE_GAP_FACTOR", "SAME_AZIMUTH_DEG", "RANGE_BINS_M", "HEIGHT_BINS",
    "ring_labels", "ring_spacings_deg", "outline_mask", "scan_line_runs", "break_depths_m", "outline_share", "range_bin_medians",
    "fit_count_exponent", "cloud_stats", "shape_stats", "class_summary", "profile_distance",
]  # fmt: skip

#: Edges of the range bins of a class's points per crop, metres: the ``lidar`` set's 5-25 m
#: (:data:`zbuf_occlude.sensors.fit.class_placement.LIDAR_PLACEMENT`) in 5 m steps.
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

    p = sensor_points(cloud.points_m, f"{cloud.source}: points")
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
        or one range), ``outline_share`` (the median of :func:`outline_share`) and ``width_profile``,
        ``(WIDTH_PROFILE_BINS,) float64``: per eighth of the height, bottom to top, the median over the crops of
        their width profiles (:func:`zbuf_occlude.sensors.fit.median_width_profile`; NaN where no crop shows that
        eighth two returns wide).
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
        points = [sensor_points(c.points_m, f"{c.source}: points") for c in clouds]
        summary["outline_share"] = float(np.nanmedian([outline_share(p) for p in points]))
        summary["width_profile"] = median_width_profile(points)
    return summary
