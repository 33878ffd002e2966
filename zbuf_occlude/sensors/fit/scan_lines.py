"""The scan lines of a spinning LiDAR's crop of an object: its rings (:func:`ring_labels`, :func:`ring_spacings_deg`),
each ring's runs of points along the azimuth (:func:`scan_line_runs`, :func:`break_depths_m`) and their ends, the
outline (:func:`outline_mask`, :func:`outline_share`).  Points in a frame centred on the sensor, z up, metres.

Within each ring, the points sorted by azimuth split into runs where the azimuth gap to the next point exceeds
:data:`OUTLINE_GAP_FACTOR` times the ring's azimuth step; the two ends of each run (one point for a run of one) are
the outline.  Its share of the points is the share whose neighbouring footprint along the scan line falls off the
object: where a beam's footprint straddles the object's edge (mixed pixels), which a multi-ray footprint model adds
and a real receiver may drop.  :mod:`zbuf_occlude.experiments.realism` compares crops by it, and ``fit-sensor
--meshes`` fits the receiver's partial echoes to it (:mod:`~zbuf_occlude.sensors.fit.partial_echo_meshes`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError

__all__ = [
    "RING_GAP_DEG", "OUTLINE_GAP_FACTOR", "SAME_AZIMUTH_DEG", "sensor_points", "ring_labels", "ring_spacings_deg", "outline_mask",
    "scan_line_runs", "break_depths_m", "outline_share",
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


def sensor_points(points_m, what: str = "points_m") -> NDArray[np.float64]:
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
    p = sensor_points(points_m)
    elev = _elevations_deg(p)
    order = np.argsort(elev, kind="stable")
    labels = np.empty(len(p), dtype=np.int64)
    labels[order] = np.concatenate([[0], np.cumsum(np.diff(elev[order]) > ring_gap_deg)]) if len(p) else []
    return labels


def ring_spacings_deg(points_m: NDArray[np.floating], *, ring_gap_deg: float = RING_GAP_DEG) -> NDArray[np.float64]:
    """(R − 1,) float64: elevation differences of consecutive rings (:func:`ring_labels`), each ring
    at its points' median elevation, degrees (module docstring)."""
    p = sensor_points(points_m)
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
    p = sensor_points(points_m)
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
    for r, (ring, breaks) in enumerate(_ring_runs(sensor_points(points_m), ring_gap_deg, azimuth_step_deg, gap_factor)):
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
    p = sensor_points(points_m)
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
