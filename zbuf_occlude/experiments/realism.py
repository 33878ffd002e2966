"""How LiDAR-like are generated object clouds?  Statistics against real scans.

For each object cloud, in a frame centred on the sensor with z up (metres):

* ring spacing: point elevations ``asin(z / |p|)`` are grouped into rings (a gap larger than
  ``ring_gap_deg`` starts a new ring); the spacing is the difference of consecutive ring
  elevations (median elevation per ring), degrees;
* range: distance from the sensor to the cloud's centroid, metres; the point count against it
  gives the exponent ``b`` of ``count ∝ range^b`` (least squares in log–log over the clouds);
* nearest-neighbour spacing: median distance of a point to its nearest other point, metres;
* vertical extent: ``max z − min z``, metres;
* across-sight width: how wide the cloud shows across the line of sight, metres
  (:func:`zbuf_occlude.sensors.fit.across_sight_width`);
* outline share (:func:`outline_share`): within each ring, the points sorted by azimuth split into
  runs where the azimuth gap to the next point exceeds :data:`OUTLINE_GAP_FACTOR` times the ring's
  azimuth step; the two ends of each run (one point for a run of one) are the outline.  Its share
  of the points is the share whose neighbouring footprint along the scan line falls off the
  object: the points where a beam's footprint straddles the object's edge (mixed pixels), which
  a multi-ray footprint model adds and a real receiver may drop.

Per class (:func:`compare_classes`), for any sensor and the only comparison for airborne crops
(which record no sensor position, so neither rings nor ranges): points per crop; height (``max z −
min z``) over width (the x–y extent along the footprint's principal axis, so that a crop's heading
does not matter); and how the points spread over the height, each point's height above the crop's
lowest over the crop's height (0 at the bottom, 1 at the top): its median, and the share of points
in each tenth of the height.  For clouds in a sensor frame (``by_range``), also the median points per
crop in range bins (:data:`RANGE_BINS_M`), the count exponent over the class's crops and the median
outline share.  A pole simulated as a tall shaft has its points spread up the shaft
(median near 0.5, height/width 10 or more), where an aerial crop of a real pole often shows a squat
top (median near 1, height/width near 1): the table shows such a mismatch.

Two sets are compared by :func:`compare_sets` and :func:`compare_classes`; :func:`realism_report`
writes the tables (Markdown and CSV) and a side-by-side figure.  Sets are read by
:func:`read_object_clouds` from scan NPZ files (:meth:`Scan.to_npz`; each non-ground object is one
cloud), LiDARNet v2 CSVs, or class folders of point-cloud files of any format the real-scan
reader takes (:func:`zbuf_occlude.real_scans.datasets.load_real_scans`).  A cloud's class is its
class folder (the first folder under the path given; LiDARNet's ``object`` column).
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.encodings import png_bytes
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.io.safe_paths import check_found_file
from zbuf_occlude.sensors.fit import across_sight_width
from zbuf_occlude.sensors.scan_data import read_scan_npz
from zbuf_occlude.sensors.scene import GROUND_ID

__all__ = [
    "ObjectCloud", "read_object_clouds", "cloud_stats", "ring_spacings_deg", "fit_count_exponent",
    "compare_sets", "markdown_table", "realism_report", "RING_GAP_DEG", "HEIGHT_BINS", "RATIO_TARGET", "shape_stats",
    "compare_classes", "class_table", "REPORT_FILES", "ring_labels", "outline_mask", "outline_share", "scan_line_runs", "range_bin_medians",
    "class_summary", "OUTLINE_GAP_FACTOR", "SAME_AZIMUTH_DEG", "RANGE_BINS_M",
]  # fmt: skip

log = logging.getLogger(__name__)

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
#: A count (or a shape ratio) matches when generated / real lies within this factor either way.
RATIO_TARGET = 1.5
#: The median normalised height matches within a tenth of the object's height (one height bin).
MEDIAN_HEIGHT_TARGET = 0.1
#: The vertical profiles match when at most this share of the points would have to move to another
#: tenth of the height (total variation distance of the class's mean profiles).
PROFILE_TARGET = 0.1


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


# -- reading ------------------------------------------------------------------------------------
def _from_npz(path: Path, ground_in_crops: bool = False, label: str | None = None) -> list[ObjectCloud]:
    """The objects of one scan file, labelled ``label`` (None: ``object<id>``)."""
    s = read_scan_npz(path)
    pts = s.points.astype(np.float64) - s.sensor_position
    if s.frame == "sensor":
        pts = pts @ np.asarray(s.sensor_to_world, dtype=np.float64)[:3, :3].T  # world axes: z up
    objects = [oid for oid in np.unique(s.object_id) if oid != GROUND_ID]
    if ground_in_crops and len(objects) == 1:  # a crop: its ground returns are part of it
        return [ObjectCloud(pts, label or f"object{objects[0]}", f"{path}#{objects[0]}")]
    return [ObjectCloud(pts[s.object_id == oid], label or f"object{oid}", f"{path}#{oid}") for oid in objects]


def read_object_clouds(path: str | os.PathLike, *, min_points: int = 1, ground_in_crops: bool = False) -> list[ObjectCloud]:
    """Object clouds under ``path`` (a file or a folder, searched recursively): scan ``.npz`` files
    and/or LiDARNet v2 ``.csv`` files (duplicates dropped); or, when it holds no ``.npz``, any
    real scans :func:`~zbuf_occlude.real_scans.datasets.load_real_scans` reads (class folders of
    point-cloud files, such as aerial crops; LiDARNet; SUO), in metres as their files give them.

    Each object of a scan file is one cloud, its ground returns (object id 0) left out; with
    ``ground_in_crops``, a file holding one object (a crop made with a ground margin:
    ``scan --crop --ground-margin``) is one cloud with its ground returns, as a real crop that
    a box segmentation cut holds them.  A scan file in a folder under ``path`` takes that
    folder's name as its class (``gen/pole/*.npz``: ``pole``), else ``object<id>``.

    Raises
    ------
    InvalidInputError
        ``path`` missing or holding no cloud, or a file that cannot be read (named).
    """
    from zbuf_occlude.real_scans.datasets import load_real_scans

    root = Path(path)
    if not root.exists():
        raise InvalidInputError(f"realism: {root} does not exist")
    if root.is_file():
        files = [root]
    else:  # a found file linking outside the folder is refused as every scan folder's (io.safe_paths.check_found_file)
        found = sorted(p for p in root.rglob("*") if p.is_file() and p.suffix.lower() in (".npz", ".csv"))
        files = [check_found_file(p, root) for p in found]
    clouds: list[ObjectCloud] = []
    npz = [f for f in files if f.suffix.lower() == ".npz"]
    csvs = [f for f in files if f.suffix.lower() == ".csv" and f.name != "MANIFEST.csv"]
    if csvs or not npz and root.is_dir():
        # discovery, labels, de-duplication; beside scan files only LiDARNet's CSVs
        for real in load_real_scans(root, dataset="lidarnet" if npz else "auto"):
            clouds.append(ObjectCloud(real.points_sensor_m, real.label, real.source))
    for f in npz:
        parts = f.relative_to(root).parts if f != root else ()
        clouds.extend(_from_npz(f, ground_in_crops, parts[0] if len(parts) > 1 else None))
    clouds = [c for c in clouds if len(c.points_m) >= min_points]
    if not clouds:
        raise InvalidInputError(f"realism: no object clouds (scan .npz or LiDARNet .csv) under {root}")
    return clouds


# -- statistics ---------------------------------------------------------------------------------
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
    ±180°, is one span), and split into runs where the gap to the next point exceeds ``gap_factor``
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
        axis), metres; ``height_to_width`` (NaN for a width of 0); ``median_normalised_height``
        (NaN for a height of 0); ``height_shares``, ``(HEIGHT_BINS,) float64``, the share of the
        points in each tenth of the height, bottom to top (all in the bottom bin for a height of 0).
    """
    p = np.asarray(points_m, dtype=np.float64)
    z = p[:, 2]
    height = float(np.ptp(z)) if len(p) else 0.0
    xy = p[:, :2] - p[:, :2].mean(axis=0) if len(p) else np.zeros((0, 2))
    width = 0.0
    if len(p) > 1:
        _, axes = np.linalg.eigh(xy.T @ xy)
        width = float(np.ptp(xy @ axes[:, -1]))  # along the largest principal axis
    u = (z - z.min()) / height if height > 0 else np.zeros(len(z))
    shares = np.bincount(np.minimum((u * HEIGHT_BINS).astype(np.int64), HEIGHT_BINS - 1), minlength=HEIGHT_BINS) / max(len(z), 1)
    return {
        "n_points": len(p), "height_m": height, "width_m": width,
        "height_to_width": height / width if width > 0 else math.nan,
        "median_normalised_height": float(np.median(u)) if height > 0 else math.nan,
        "height_shares": shares.astype(np.float64),
    }  # fmt: skip


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
        ``crops``; the medians of ``n_points``, ``height_m``, ``width_m``, ``height_to_width`` and
        ``median_normalised_height``; ``height_shares``, ``(HEIGHT_BINS,) float64``; with
        ``by_range`` also ``range_m`` (median distance to the centroid, metres),
        ``n_points_by_range`` and ``crops_by_range`` (:func:`range_bin_medians`, ``(B,)``),
        ``count_exponent`` (:func:`fit_count_exponent` over the crops; NaN for fewer than three
        or one range) and ``outline_share`` (the median of :func:`outline_share`).
    """
    stats = [shape_stats(c.points_m) for c in clouds]
    summary = {"crops": len(stats)}
    for key in ("n_points", "height_m", "width_m", "height_to_width", "median_normalised_height"):
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


def compare_classes(generated: list[ObjectCloud], real: list[ObjectCloud], *, by_range: bool = False,
                    ) -> tuple[list[dict], dict[str, dict[str, dict]]]:  # fmt: skip
    """Per class, generated against real: points per crop, height over width and the vertical distribution.

    Classes are the labels both sets have; when they share none, every cloud of each set is pooled
    as one class, ``all``.  With ``by_range`` (both sets in a sensor frame), each summary also
    holds the points per crop by range, the count exponent and the outline share
    (:func:`class_summary`).

    Returns
    -------
    rows : list of dict
        As :func:`compare_sets`'s (``metric`` starts with the class), four per class: median points
        per crop and median height / width (ratio generated / real, within :data:`RATIO_TARGET`),
        median normalised height (difference within :data:`MEDIAN_HEIGHT_TARGET`), and the distance
        between the mean height profiles (within :data:`PROFILE_TARGET`).
    table : dict
        ``{class: {"generated": summary, "real": summary}}``, each summary :func:`class_summary`'s.
    """
    shared = sorted({c.label for c in generated} & {c.label for c in real})
    groups = {k: ([c for c in generated if c.label == k], [c for c in real if c.label == k]) for k in shared} or {"all": (generated, real)}
    rows, table = [], {}
    for k, (g_clouds, r_clouds) in groups.items():
        g, r = class_summary(g_clouds, by_range=by_range), class_summary(r_clouds, by_range=by_range)
        table[k] = {"generated": g, "real": r}
        for name, key in (("median points per crop", "n_points"), ("median height / width", "height_to_width")):
            ratio = g[key] / r[key] if r[key] > 0 else math.nan
            rows.append({"metric": f"{k}: {name} (n={g['crops']}, {r['crops']})", "generated": g[key], "real": r[key],
                         "difference": ratio, "target": f"1/{RATIO_TARGET:g} <= ratio <= {RATIO_TARGET:g}",
                         "met": bool(1 / RATIO_TARGET <= ratio <= RATIO_TARGET) if math.isfinite(ratio) else ""})  # fmt: skip
        d = g["median_normalised_height"] - r["median_normalised_height"]
        rows.append({"metric": f"{k}: median height above the crop's bottom, share of its height", "generated": g["median_normalised_height"],
                     "real": r["median_normalised_height"], "difference": d, "target": f"abs(diff) <= {MEDIAN_HEIGHT_TARGET:g}",
                     "met": bool(abs(d) <= MEDIAN_HEIGHT_TARGET) if math.isfinite(d) else ""})  # fmt: skip
        tv = 0.5 * float(np.abs(g["height_shares"] - r["height_shares"]).sum())
        rows.append({"metric": f"{k}: share of points in another tenth of the height (profile distance)", "generated": "", "real": "",
                     "difference": tv, "target": f"<= {PROFILE_TARGET:g}", "met": bool(tv <= PROFILE_TARGET)})  # fmt: skip
    return rows, table


def _bin_names(bins_m: tuple[float, ...] = RANGE_BINS_M) -> list[str]:
    """``["5-10", "10-15", ...]``: the range bins' names, metres."""
    return [f"{lo:g}-{hi:g}" for lo, hi in zip(bins_m[:-1], bins_m[1:])]


def class_table(table: dict[str, dict[str, dict]]) -> str:
    """:func:`compare_classes`' table as Markdown: one row per class and set, the height profile in percent, bottom to top;
    with summaries by range (:func:`class_summary`), the median points per crop in each range bin (crops in it),
    the count exponent and the median outline share after it."""
    by_range = any("n_points_by_range" in st for sets in table.values() for st in sets.values())
    head = ["class", "set", "crops", "median points", "median height, m", "median width, m", "median height / width",
            "median normalised height", "% of points per tenth of the height, bottom to top"]  # fmt: skip
    if by_range:
        head += [f"median points at {b} m (crops)" for b in _bin_names()] + ["count exponent", "median outline share"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for k, sets in table.items():
        for name, st in sets.items():
            profile = " ".join(f"{100 * v:.0f}" for v in st["height_shares"])
            cells = [k, name, str(st["crops"]), *(_fmt(st[key]) for key in ("n_points", "height_m", "width_m", "height_to_width",
                                                                           "median_normalised_height")), profile]  # fmt: skip
            if by_range:
                cells += [f"{_fmt(m)} ({c})" for m, c in zip(st["n_points_by_range"], st["crops_by_range"])]
                cells += [_fmt(st["count_exponent"]), _fmt(st["outline_share"])]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _class_rows(table: dict[str, dict[str, dict]]) -> list[dict]:
    """:func:`compare_classes`' table as CSV rows: class, set, the medians and one column per tenth of the height."""
    arrays = ("height_shares", "n_points_by_range", "crops_by_range")
    return [{"class": k, "set": name, **{key: v for key, v in st.items() if key not in arrays},
             **{f"share_{b / HEIGHT_BINS:g}_{(b + 1) / HEIGHT_BINS:g}": float(v) for b, v in enumerate(st["height_shares"])},
             **{f"{key}_{b}_m": v.item() for key in arrays[1:] if key in st for b, v in zip(_bin_names(), st[key])}}
            for k, sets in table.items() for name, st in sets.items()]  # fmt: skip


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


def _summary(stats: list[dict]) -> dict:
    spacing = np.concatenate([s["ring_spacings_deg"] for s in stats]) if stats else np.zeros(0)
    r = np.array([s["range_m"] for s in stats])
    n = np.array([s["n_points"] for s in stats])
    b, se, a = fit_count_exponent(r, n)
    return {
        "clouds": len(stats),
        "median_ring_spacing_deg": float(np.median(spacing)) if len(spacing) else float("nan"),
        "count_exponent": b, "count_exponent_se": se, "count_log_intercept": a,
        "median_points": float(np.median(n)), "median_range_m": float(np.median(r)),
        "range_m_p5_p95": (float(np.percentile(r, 5)), float(np.percentile(r, 95))),
        "median_nn_spacing_m": float(np.nanmedian([s["nn_spacing_m"] for s in stats])),
        "median_vertical_extent_m": float(np.median([s["vertical_extent_m"] for s in stats])),
        "median_across_sight_width_m": float(np.median([s["across_sight_width_m"] for s in stats])),
        "median_outline_share": float(np.nanmedian([s["outline_share"] for s in stats])),
        "_spacing": spacing, "_range": r, "_count": n, "_nn": np.array([s["nn_spacing_m"] for s in stats]),
    }  # fmt: skip


def compare_sets(
    generated: list[ObjectCloud], real: list[ObjectCloud], *, ring_gap_deg: float = RING_GAP_DEG
) -> tuple[list[dict], dict, dict]:
    """Statistics of both sets and the table rows.

    The count ratio at matched range is ``count / (real fit at that range)`` per generated cloud
    inside the real clouds' 5–95 % range, median over them.

    Returns
    -------
    rows : list of dict
        ``metric, generated, real, difference, target, met``.
    gen, real : dict
        :func:`_summary` of each set (arrays under keys starting with ``_``).
    """
    g = _summary([cloud_stats(c, ring_gap_deg=ring_gap_deg) for c in generated])
    r = _summary([cloud_stats(c, ring_gap_deg=ring_gap_deg) for c in real])
    lo, hi = r["range_m_p5_p95"]
    inside = (g["_range"] >= lo) & (g["_range"] <= hi)
    predicted = np.exp(r["count_log_intercept"]) * g["_range"][inside] ** r["count_exponent"]
    ratio = float(np.median(g["_count"][inside] / predicted)) if inside.any() else float("nan")
    g["count_ratio_at_matched_range"] = ratio
    g["count_ratio_n"] = int(inside.sum())
    # The exponent over the ranges both sets cover: a cloud nearer than any real one (an
    # extended object seen from a few metres, whose angular size saturates) would bend the fit.
    c_lo = max(g["_range"].min(), r["_range"].min())
    c_hi = min(g["_range"].max(), r["_range"].max())
    common = {}
    for name, st in (("g", g), ("r", r)):
        m = (st["_range"] >= c_lo) & (st["_range"] <= c_hi)
        common[name] = fit_count_exponent(st["_range"][m], st["_count"][m])[:2] + (int(m.sum()),)
    g["count_exponent_common"], r["count_exponent_common"] = common["g"][0], common["r"][0]
    ds = g["median_ring_spacing_deg"] - r["median_ring_spacing_deg"]
    db = common["g"][0] - common["r"][0]
    db_all = g["count_exponent"] - r["count_exponent"]
    rows = [
        {"metric": "clouds", "generated": g["clouds"], "real": r["clouds"], "difference": "", "target": "", "met": ""},
        {"metric": "median range, m", "generated": g["median_range_m"], "real": r["median_range_m"], "difference": g["median_range_m"] - r["median_range_m"], "target": "", "met": ""},
        {"metric": "median ring spacing, deg", "generated": g["median_ring_spacing_deg"], "real": r["median_ring_spacing_deg"], "difference": ds, "target": "abs(diff) <= 0.05", "met": abs(ds) <= 0.05},
        {"metric": f"count-vs-range exponent b (count ∝ r^b), common range {c_lo:.1f}-{c_hi:.1f} m (n={common['g'][2]}, {common['r'][2]})", "generated": common["g"][0], "real": common["r"][0], "difference": db, "target": "abs(diff) <= 0.2", "met": abs(db) <= 0.2},
        {"metric": "its standard error", "generated": common["g"][1], "real": common["r"][1], "difference": "", "target": "", "met": ""},
        {"metric": "exponent b over all clouds", "generated": g["count_exponent"], "real": r["count_exponent"], "difference": db_all, "target": "", "met": ""},
        {"metric": f"count / real fit at matched range (n={g['count_ratio_n']})", "generated": ratio, "real": 1.0, "difference": "", "target": f"1/{RATIO_TARGET:g} <= ratio <= {RATIO_TARGET:g}", "met": (1 / RATIO_TARGET <= ratio <= RATIO_TARGET) if math.isfinite(ratio) else ""},
        {"metric": "median points per cloud", "generated": g["median_points"], "real": r["median_points"], "difference": "", "target": "", "met": ""},
        {"metric": "median nearest-neighbour spacing, m", "generated": g["median_nn_spacing_m"], "real": r["median_nn_spacing_m"], "difference": g["median_nn_spacing_m"] - r["median_nn_spacing_m"], "target": "", "met": ""},
        {"metric": "median vertical extent, m", "generated": g["median_vertical_extent_m"], "real": r["median_vertical_extent_m"], "difference": g["median_vertical_extent_m"] - r["median_vertical_extent_m"], "target": "", "met": ""},
        {"metric": "median across-sight width, m", "generated": g["median_across_sight_width_m"], "real": r["median_across_sight_width_m"], "difference": g["median_across_sight_width_m"] - r["median_across_sight_width_m"], "target": "", "met": ""},
        {"metric": "median outline share (points ending a run of their ring)", "generated": g["median_outline_share"], "real": r["median_outline_share"], "difference": g["median_outline_share"] - r["median_outline_share"], "target": "", "met": ""},
    ]  # fmt: skip
    return rows, g, r


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "yes" if v else "**no**"
    if isinstance(v, (float, np.floating)):
        return f"{v:.3f}" if math.isfinite(v) else "n/a"
    return str(v)


def markdown_table(rows: list[dict]) -> str:
    """The rows as a Markdown table."""
    keys = ["metric", "generated", "real", "difference", "target", "met"]
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(_fmt(row[k]) for k in keys) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def _figure(g: dict, r: dict, labels: tuple[str, str]):
    """Ring spacing, count against range and spacing against range, generated beside real."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
    bins = np.arange(0.0, 4.01, 0.05)
    for s, name, colour in ((g, labels[0], "tab:blue"), (r, labels[1], "tab:orange")):
        ax[0].hist(s["_spacing"], bins=bins, alpha=0.6, density=True, label=name, color=colour)
        ax[1].loglog(s["_range"], s["_count"], ".", alpha=0.5, color=colour, label=f"{name}: b = {s['count_exponent']:.2f}")
        xs = np.geomspace(max(s["_range"].min(), 1e-3), s["_range"].max(), 20)
        ax[1].loglog(xs, np.exp(s["count_log_intercept"]) * xs ** s["count_exponent"], "-", color=colour)
        ax[2].loglog(s["_range"], s["_nn"], ".", alpha=0.5, color=colour, label=name)
    ax[0].set(xlabel="ring spacing, deg", ylabel="density", title="elevation ring spacing")
    ax[1].set(xlabel="range, m", ylabel="points", title="point count vs range (all clouds)")
    ax[2].set(xlabel="range, m", ylabel="median nearest-neighbour spacing, m", title="point spacing vs range")
    for a in ax:
        a.legend(fontsize=8)
    return fig


def _save(fig, folder: OwnedFolder, name: str) -> None:
    """Write ``fig`` as the PNG ``name`` in ``folder`` (:meth:`OwnedFolder.write_bytes`) and close it."""
    import matplotlib.pyplot as plt

    try:
        fig.tight_layout()
        folder.write_bytes(name, png_bytes(fig, dpi=110))
    finally:
        plt.close(fig)


def _profile_figure(table: dict[str, dict[str, dict]]):
    """Per class, the share of points in each tenth of the height, generated beside real."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(table), figsize=(3.2 * len(table), 3.8), squeeze=False)
    centres = (np.arange(HEIGHT_BINS) + 0.5) / HEIGHT_BINS
    for ax, (k, sets) in zip(axes[0], table.items(), strict=True):
        for (name, st), colour in zip(sets.items(), ("tab:blue", "tab:orange"), strict=True):
            ax.plot(st["height_shares"], centres, "o-", color=colour, label=f"{name} ({st['crops']})")
        ax.set(xlabel="share of points", ylabel="height above the bottom / height", title=k, ylim=(0, 1))
        ax.legend(fontsize=8)
    return fig


#: The files :func:`realism_report` writes in its folder (the figure unless ``figure=False``).
REPORT_FILES = ("realism.md", "realism.csv", "realism_classes.csv", "realism.png")


def realism_report(generated: str | os.PathLike, real: str | os.PathLike, out_dir: str | os.PathLike, *, ring_gap_deg: float = RING_GAP_DEG, min_points: int = 1, figure: bool = True,
                   ground_in_crops: bool = False, airborne: bool = False) -> tuple[list[dict], dict[str, dict[str, dict]]]:  # fmt: skip
    """Compare two sets of object clouds; write ``realism.md``, ``realism.csv``,
    ``realism_classes.csv`` and ``realism.png`` under ``out_dir``.

    Parameters
    ----------
    generated, real : path
        :func:`read_object_clouds`; ``ground_in_crops`` applies to ``generated``.
    airborne : bool
        The clouds are aerial crops (no sensor position): only the per-class comparison
        (:func:`compare_classes`), whose height profiles the figure then shows; without it, the
        ring, range and spacing rows (:func:`compare_sets`) come first.

    Returns
    -------
    rows : list of dict
        What ``realism.csv`` holds: :func:`compare_sets`' rows (but its first, the cloud counts,
        alone with ``airborne``), then :func:`compare_classes`'.
    table : dict
        :func:`compare_classes`' table, as ``realism_classes.csv`` holds it.

    Raises
    ------
    InvalidInputError
        A set is missing or empty.
    OutputError
        ``out_dir`` cannot be made or written.
    UnsafePathError
        A file of a name it writes is in ``out_dir`` and was not written by a run of ours, or
        was changed since (checked before any cloud is read; nothing is written).
    DatasetBusy
        Another live process holds ``out_dir``.
    """
    files = REPORT_FILES if figure else REPORT_FILES[:-1]
    with OwnedFolder(out_dir, files=REPORT_FILES, what="the realism report") as folder:
        folder.check_writable(files)  # every file before any work: a refusal writes nothing
        return _report_into(folder, generated, real, ring_gap_deg=ring_gap_deg, min_points=min_points, figure=figure,
                            ground_in_crops=ground_in_crops, airborne=airborne)  # fmt: skip


def _report_into(folder: OwnedFolder, generated: str | os.PathLike, real: str | os.PathLike, *, ring_gap_deg: float, min_points: int, figure: bool,
                 ground_in_crops: bool, airborne: bool) -> tuple[list[dict], dict[str, dict[str, dict]]]:  # fmt: skip
    """:func:`realism_report` once its folder is held."""
    gen_clouds = read_object_clouds(generated, min_points=min_points, ground_in_crops=ground_in_crops)
    real_clouds = read_object_clouds(real, min_points=min_points)
    if airborne:
        rows = [{"metric": "clouds", "generated": len(gen_clouds), "real": len(real_clouds), "difference": "", "target": "", "met": ""}]
    else:
        rows, g, r = compare_sets(gen_clouds, real_clouds, ring_gap_deg=ring_gap_deg)
    class_rows, table = compare_classes(gen_clouds, real_clouds, by_range=not airborne)
    rows += class_rows
    header = f"Generated: {generated} ({len(gen_clouds)} clouds); real: {real} ({len(real_clouds)} clouds)\n\n"
    folder.write_text("realism.md", header + markdown_table(rows) + "\n" + class_table(table))
    folder.write_csv("realism.csv", rows)
    folder.write_csv("realism_classes.csv", _class_rows(table))
    if figure:
        _save(_profile_figure(table) if airborne else _figure(g, r, ("generated", "real")), folder, "realism.png")
    return rows, table
