"""A spinning LiDAR fitted to real object scans: what the simulation can set, estimated from the user's own scans.

Input: segmented object scans, each ``(N, 3) float64`` with the sensor at the origin, z up, metres
(:attr:`zbuf_occlude.real_scans.records.RealScan.points_sensor_m`).  Every return is given a ring,
the beam of the base sensor nearest in elevation, and an azimuth; then, over all scans:

``elevation_offset_deg``
    Median of (return elevation − its beam's elevation): a mount tilt, or a beam table that is
    not the sensor's.  Reported; the fitted sensor keeps the base table (the data sheet's).
``ring_spacing_deg``
    Median spacing of consecutive occupied rings (median elevation per ring) within a scan;
    the realism statistic (:mod:`zbuf_occlude.experiments.realism`) on the same scans.
``azimuth_step_deg`` → ``firing_rate_hz``
    Consecutive returns of one ring are ``k`` azimuth steps apart (``k ≥ 1``; ``k > 1`` where
    returns are lost).  A first guess ``s₀`` (the 20th percentile of the azimuth differences:
    losses only make differences longer) gives ``k = max(1, round(d / s₀))``, and the step is
    the median of ``d / k``; ``firing_rate_hz = 360 · rotation_hz / step``.
``dropout``
    Missing firings inside a ring's run over the object: ``Σ (k − 1) / Σ k`` over gaps of at
    most :data:`MAX_DROPOUT_GAP` steps (longer gaps are the object's shape or occlusion, not
    lost returns).  Its dependence on range (the scan's centroid range) is a least-squares line
    ``p = a + b·R`` over the scans: ``b`` is the sensor's ``dropout_range_per_m``, and its
    ``dropout`` (the rate at range 0, ``dropout_at_0m``) is ``a = p̄ − b·R̄``, with ``p̄`` the
    pooled rate and ``R̄`` the scans' range weighted by their firings, so that the simulated
    law loses the pooled share of the scans' firings (clipped at 0).
``range_noise_m``
    Second differences of range along a ring, ``r[i-1] − 2 r[i] + r[i+1]`` over returns one
    azimuth step apart: on a surface that is locally linear in azimuth they hold only the
    noise, with variance ``6 σ²``; σ = ``1.4826 · MAD / √6`` (difference-based variance
    estimation, Gasser, Sroka & Jennen-Steinmetz 1986, "Residual variance and residual pattern
    in nonlinear regression", Biometrika 73(3)).  Edges and curvature make it an upper bound.
``count_exponent``
    ``b`` of ``count ∝ range^b`` (least squares in log–log over the scans), the law the
    realism report compares; it follows from the others and is reported, not set.
``ground_fraction``
    Returns in the bottom 0.15 m of a scan whose local plane is horizontal (normal within 25°
    of z): the ground that the segmentation left under the object.  Reported; the simulated
    crops hold no ground.

Uncertainties: the standard deviation over :data:`BOOTSTRAP` resamples of the scans (with
replacement, seed given).  Nothing depends on file names or class labels.

Where the crops stand and how tall their objects are is the scene's, not the sensor's, and is
fitted per class of the user's scans (:func:`crop_placement_json`): the sensor's horizontal
distance to each scan's centroid (:func:`fit_crop_distances`), each scan's height
(:func:`fit_crop_heights`: its top above the ground) and how high above the ground its lowest return lies
(:func:`fit_crop_bottoms`, with the ground from :func:`fit_sensor_height`) and how wide it shows
across the line of sight (:func:`fit_crop_widths`), as percentile intervals to draw uniformly, and
its outline over the height (:func:`fit_crop_width_profile`).  A mesh is made as wide as that by a
horizontal stretch fitted to its own simulated crops (:func:`fit_width_scale`), and given that
outline by a warp (:func:`fit_width_profile`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.lidar import Lidar

__all__ = [
    "BOOTSTRAP", "DISTANCE_QUANTILES", "MAX_DROPOUT_GAP", "MIN_PLACEMENT_SCANS", "PLANE_NEIGHBOURS", "Estimate", "LidarFit",
    "SENSOR_HEIGHT_QUANTILE", "WIDTH_BAND_M", "WIDTH_PROFILE_BINS", "WIDTH_SAMPLES", "across_sight_width", "crop_placement_json",
    "fit_crop_bottoms", "fit_crop_distances", "fit_crop_heights", "fit_crop_width_profile", "fit_crop_widths", "fit_lidar",
    "fit_object_shape", "fit_sensor_height", "fit_visible_across_sight", "fit_width_profile", "fit_width_scale", "lidar_to_json",
    "width_profile",
]  # fmt: skip

#: Non-empty scans a class needs for its crops' distances and heights (:func:`crop_placement_json`).
MIN_PLACEMENT_SCANS = 3
#: Percentiles of the real scans' distances that bound the fitted crop distances (:func:`fit_crop_distances`).
DISTANCE_QUANTILES = (10.0, 90.0)
#: Percentile of the scans' lowest-return depths below the sensor taken as the ground's (:func:`fit_sensor_height`).
SENSOR_HEIGHT_QUANTILE = 75.0
#: Bootstrap resamples of the scans for every uncertainty.
BOOTSTRAP = 200
#: Longest gap inside a ring, in azimuth steps, counted as lost returns (module docstring).
MAX_DROPOUT_GAP = 4
#: Neighbours of the local plane fit (ground returns).
PLANE_NEIGHBOURS = 24
#: Fewest returns a scan needs to take part in the fit.
MIN_RETURNS = 20
#: Height of the horizontal bands in which :func:`across_sight_width` measures a scan, metres
#: (about one HDL-32E ring beyond 7 m).
WIDTH_BAND_M = 0.15
#: Simulated crops of a mesh that :func:`fit_width_scale` and :func:`fit_width_profile` measure.
WIDTH_SAMPLES = 16
#: Bins of relative height of :func:`width_profile`.
WIDTH_PROFILE_BINS = 8
_GROUND_SLICE_M = 0.15
_MIN_HEIGHT_M = 0.05  # a fitted object height is at least this (a scan whose top lies at or below the fitted ground)
_PLANARITY = 0.3
_WIDTH_STREAM = 0x57D7  # fit_width_scale's crops
_PROFILE_STREAM = 0x9F0F  # fit_width_profile's crops
_WIDTH_GROWTHS = 6  # fit_width_scale widens a mesh that shows no width up to 4**6 times
_GROUND_NORMAL_COS = math.cos(math.radians(25.0))


@dataclass(frozen=True)
class Estimate:
    """One fitted quantity: ``value ± std`` (bootstrap over scans), from ``n`` returns or scans."""

    value: float
    std: float
    n: int
    method: str
    unit: str = ""
    set_in_sensor: bool = False


@dataclass(frozen=True)
class LidarFit:
    """The fitted sensor and the estimates behind it.

    Attributes
    ----------
    sensor : Lidar
        ``base`` with ``firing_rate_hz``, ``range_noise_m``, ``dropout`` and ``dropout_range_per_m`` set from the scans.
    base : Lidar
    estimates : dict of str to Estimate
    n_scans : int
        Scans used (those with at least :data:`MIN_RETURNS` returns).
    """

    sensor: Lidar
    base: Lidar
    estimates: dict[str, Estimate]
    n_scans: int

    def to_json(self) -> dict:
        """The sensor as :func:`~zbuf_occlude.sensors.presets.sensor_from_name` reads it, plus a ``fit`` block."""
        spec = lidar_to_json(self.sensor)
        spec["fit"] = {"base": self.base.name, "n_scans": self.n_scans,
                       "estimates": {k: vars(e) for k, e in self.estimates.items()}}  # fmt: skip
        return spec

    def markdown(self) -> str:
        """A table of the estimates: quantity, value ± std, unit, n, set in the sensor, method."""
        lines = ["| quantity | value ± std | unit | n | sets the sensor | how |", "|---|---|---|---|---|---|"]
        for name, e in self.estimates.items():
            lines.append(f"| {name} | {e.value:.4g} ± {e.std:.2g} | {e.unit} | {e.n} | {'yes' if e.set_in_sensor else 'no'} | {e.method} |")
        return "\n".join(lines) + "\n"


def lidar_to_json(sensor: Lidar) -> dict:
    """A Lidar's constructor fields as JSON-ready values, with ``"kind": "lidar"``."""
    spec = {"kind": "lidar"}
    for f in fields(sensor):
        if f.init:
            v = getattr(sensor, f.name)
            spec[f.name] = list(v) if isinstance(v, tuple) else v
    return spec


@dataclass
class _ScanStats:
    """Per-scan sufficient statistics, so the bootstrap only re-aggregates."""

    count: int
    range_m: float
    elevation_residual_deg: NDArray[np.float64]
    ring_spacings_deg: NDArray[np.float64]
    azimuth_diffs_deg: NDArray[np.float64]
    noise_residuals_m: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    ground: int = 0


def _checked_scan(i: int, cloud) -> NDArray[np.float64]:
    """Scan ``i`` as ``(N, 3) float64``, or InvalidInputError naming it."""
    p = np.asarray(cloud, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or not np.all(np.isfinite(p)):
        raise InvalidInputError(f"scan {i}: expected finite (N, 3) points, got shape {p.shape}")
    return p


def _plane_normals(points: NDArray[np.float64], k: int) -> NDArray[np.float64]:
    """Per point: the normal of the PCA plane of its ``k`` nearest neighbours in beam direction
    (NaN where they lie on one ring's line and span no plane)."""
    from scipy.spatial import cKDTree

    k = min(k, len(points))
    beam = points / np.linalg.norm(points, axis=1, keepdims=True)
    _, idx = cKDTree(beam).query(beam, k=k)
    nb = points[idx]  # (N, k, 3)
    _, sv, vt = np.linalg.svd(nb - nb.mean(axis=1, keepdims=True), full_matrices=False)
    normal = vt[:, 2, :].copy()
    normal[sv[:, 1] <= _PLANARITY * sv[:, 0]] = np.nan
    return normal


def _scan_stats(points: NDArray[np.float64], beams_deg: NDArray[np.float64]) -> _ScanStats:
    r = np.linalg.norm(points, axis=1)
    elev = np.degrees(np.arcsin(np.clip(points[:, 2] / r, -1.0, 1.0)))
    azim = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
    order = np.argsort(beams_deg)
    sorted_beams = beams_deg[order]
    pos = np.clip(np.searchsorted(sorted_beams, elev), 1, len(sorted_beams) - 1)
    nearer = np.where(np.abs(elev - sorted_beams[pos - 1]) <= np.abs(elev - sorted_beams[pos]), pos - 1, pos)
    ring = order[nearer]
    diffs, ring_elev, second = [], [], []
    for b in np.unique(ring):
        sel = ring == b
        o = np.argsort(azim[sel])
        a, rr = azim[sel][o], r[sel][o]
        if len(a) >= 3:
            d = np.diff(a)
            unit = d <= 1.5 * np.percentile(d, 20)  # one azimuth step apart
            both = unit[:-1] & unit[1:]
            second.append((rr[:-2] - 2 * rr[1:-1] + rr[2:])[both])
        if len(a) >= 2:
            # unwrap a run that crosses ±180°: the largest gap is the object's outside
            d = np.diff(np.concatenate([a, a[:1] + 360.0]))
            d = np.delete(d, np.argmax(d))
            diffs.append(d[d > 1e-6])
        ring_elev.append(float(np.median(elev[sel])))
    ring_elev = np.sort(ring_elev)
    normal = _plane_normals(points, PLANE_NEIGHBOURS) if len(points) >= PLANE_NEIGHBOURS else None
    ground = 0
    if normal is not None:
        low = points[:, 2] < points[:, 2].min() + _GROUND_SLICE_M
        ground = int(np.count_nonzero(low & (np.nan_to_num(np.abs(normal[:, 2])) > _GROUND_NORMAL_COS)))
    return _ScanStats(
        count=len(points), range_m=float(np.linalg.norm(points.mean(axis=0))),
        elevation_residual_deg=elev - beams_deg[ring], ring_spacings_deg=np.diff(ring_elev),
        azimuth_diffs_deg=np.concatenate(diffs) if diffs else np.zeros(0), noise_residuals_m=np.concatenate(second) if second else np.zeros(0), ground=ground,
    )  # fmt: skip


def _azimuth_step(d: NDArray[np.float64]) -> float:
    if len(d) == 0:
        return math.nan
    s0 = float(np.percentile(d, 20))
    k = np.maximum(1, np.round(d / s0))
    return float(np.median(d / k))


def _firings(d: NDArray[np.float64], step: float) -> tuple[float, float]:
    """(lost, fired): firings missing in gaps of at most MAX_DROPOUT_GAP steps, and all firings there."""
    if len(d) == 0 or not math.isfinite(step):
        return 0.0, 0.0
    k = np.maximum(1, np.round(d / step))
    k = k[k <= MAX_DROPOUT_GAP]
    return float((k - 1).sum()), float(k.sum())


def _robust_sigma(resid: NDArray[np.float64]) -> float:
    if len(resid) == 0:
        return math.nan
    return float(1.4826 * np.median(np.abs(resid - np.median(resid))) / math.sqrt(6.0))


def _line(x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[float, float]:
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 2 or np.ptp(x[ok]) == 0:
        return math.nan, math.nan
    b, a = np.polyfit(x[ok], y[ok], 1)
    return float(a), float(b)


def _aggregate(stats: Sequence[_ScanStats]) -> dict[str, float]:
    d = np.concatenate([s.azimuth_diffs_deg for s in stats])
    step = _azimuth_step(d)
    firings = np.array([_firings(s.azimuth_diffs_deg, step) for s in stats]).reshape(-1, 2)
    with np.errstate(invalid="ignore", divide="ignore"):
        per_scan_dropout = firings[:, 0] / firings[:, 1]
    ranges = np.array([s.range_m for s in stats])
    counts = np.array([s.count for s in stats], dtype=np.float64)
    _, slope = _line(ranges, per_scan_dropout)
    lost, fired = firings[:, 0], firings[:, 1]
    pooled = float(lost.sum() / fired.sum()) if fired.sum() else math.nan  # the pooled rate: these sums, not a second pass
    mean_range = float((fired * ranges).sum() / fired.sum()) if fired.sum() else math.nan
    at_0m = pooled - (slope if math.isfinite(slope) else 0.0) * mean_range
    _, exponent = _line(np.log(ranges), np.log(counts))
    spacings = np.concatenate([s.ring_spacings_deg for s in stats])
    return {
        "elevation_offset_deg": float(np.median(np.concatenate([s.elevation_residual_deg for s in stats]))),
        "ring_spacing_deg": float(np.median(spacings)) if len(spacings) else math.nan,
        "azimuth_step_deg": step,
        "dropout": pooled,
        "dropout_at_0m": at_0m,
        "dropout_range_per_m": slope,
        "range_noise_m": _robust_sigma(np.concatenate([s.noise_residuals_m for s in stats])),
        "count_exponent": exponent,
        "ground_fraction": float(sum(s.ground for s in stats) / counts.sum()),
    }


_METHODS = {
    "elevation_offset_deg": ("deg", "median of return elevation minus its nearest beam's"),
    "ring_spacing_deg": ("deg", "median spacing of occupied rings within a scan"),
    "azimuth_step_deg": ("deg", "median of azimuth gap / steps in the gap, within rings"),
    "firing_rate_hz": ("Hz", "360 · rotation_hz / azimuth step"),
    "dropout": ("", f"missing firings in gaps of at most {MAX_DROPOUT_GAP} steps, pooled"),
    "dropout_at_0m": ("", "pooled dropout − slope · firing-weighted mean range (the sensor's dropout)"),
    "dropout_range_per_m": ("1/m", "slope of per-scan dropout against centroid range"),
    "range_noise_m": ("m", "1.4826·MAD/√6 of second differences of range along rings"),
    "count_exponent": ("", "b of count ∝ range^b, least squares in log–log"),
    "ground_fraction": ("", f"returns in the bottom {_GROUND_SLICE_M} m on a horizontal local plane"),
}
_SETS_SENSOR = ("firing_rate_hz", "dropout_at_0m", "dropout_range_per_m", "range_noise_m")


def fit_lidar(clouds: Sequence[NDArray[np.floating]], base: Lidar, *, seed: int = 0, bootstrap: int = BOOTSTRAP) -> LidarFit:
    """Fit ``base``'s firing rate, range noise and range-dependent dropout to real object scans (module docstring).

    Parameters
    ----------
    clouds : sequence of (N_i, 3) float
        One segmented object per scan; sensor at the origin, z up, metres.
    base : Lidar
        The sensor model (its beam table and spin rate are kept).
    seed : int
        Seeds the bootstrap.
    bootstrap : int
        Resamples for the uncertainties (>= 2).

    Returns
    -------
    LidarFit

    Raises
    ------
    InvalidInputError
        ``base`` is not a :class:`Lidar`, fewer than 3 scans have :data:`MIN_RETURNS` returns, a
        scan is not (N, 3) finite or is centred on its object (not in the sensor frame), or
        nothing could be estimated.
    """
    if not isinstance(base, Lidar):
        raise InvalidInputError(f"fit_lidar fits a spinning LiDAR, got {type(base).__name__}")
    if int(bootstrap) < 2:
        raise InvalidInputError(f"bootstrap must be >= 2, got {bootstrap!r}")
    beams = np.asarray(base.elevations_deg, dtype=np.float64)
    stats = []
    for i, c in enumerate(clouds):
        p = _checked_scan(i, c)
        p = p[np.linalg.norm(p, axis=1) > 0]
        if len(p) >= MIN_RETURNS:
            if np.linalg.norm(p.mean(axis=0)) < 0.5 * np.linalg.norm(np.ptp(p, axis=0)):
                raise InvalidInputError(f"scan {i}: the sensor is inside the object's extent; are the points centred "
                                        "on the object rather than in the sensor's frame (sensor at the origin)?")  # fmt: skip
            stats.append(_scan_stats(p, beams))
    if len(stats) < 3:
        raise InvalidInputError(f"fit_lidar needs at least 3 scans of {MIN_RETURNS}+ returns, got {len(stats)}")
    point = _aggregate(stats)
    rng = np.random.default_rng(seed)
    boots = [_aggregate([stats[j] for j in rng.integers(len(stats), size=len(stats))]) for _ in range(int(bootstrap))]
    step = point["azimuth_step_deg"]
    if not (math.isfinite(step) and step > 0 and math.isfinite(point["range_noise_m"]) and math.isfinite(point["dropout"])):
        raise InvalidInputError("fit_lidar: the scans gave no azimuth step, range noise or dropout (too few returns per ring?)")
    point["firing_rate_hz"] = 360.0 * base.rotation_hz / step
    for b in boots:
        b["firing_rate_hz"] = 360.0 * base.rotation_hz / b["azimuth_step_deg"]
    n_returns = int(sum(s.count for s in stats))
    estimates = {}
    for name, (unit, method) in _METHODS.items():
        spread = np.array([b[name] for b in boots], dtype=np.float64)
        spread = spread[np.isfinite(spread)]
        n = len(stats) if name in ("dropout_range_per_m", "count_exponent") else n_returns
        estimates[name] = Estimate(value=float(point[name]), std=float(np.std(spread, ddof=1)) if len(spread) > 1 else math.nan,
                                   n=n, method=method, unit=unit, set_in_sensor=name in _SETS_SENSOR)  # fmt: skip
    sensor = replace(
        base, name=f"{base.name}-fitted", firing_rate_hz=point["firing_rate_hz"], range_noise_m=point["range_noise_m"],
        dropout=min(max(point["dropout_at_0m"], 0.0), 0.95),
        dropout_range_per_m=point["dropout_range_per_m"] if math.isfinite(point["dropout_range_per_m"]) else 0.0, source=f"{base.source}; fitted to {len(stats)} real scans".lstrip("; "),
    )  # fmt: skip
    return LidarFit(sensor=sensor, base=base, estimates=estimates, n_scans=len(stats))


def _per_scan(clouds: Sequence[NDArray[np.floating]], measure, what: str) -> NDArray[np.float64]:
    values = []
    for i, c in enumerate(clouds):
        p = _checked_scan(i, c)
        if len(p):
            values.append(float(measure(p)))
    if len(values) < MIN_PLACEMENT_SCANS:
        raise InvalidInputError(f"{what} needs at least {MIN_PLACEMENT_SCANS} non-empty scans, got {len(values)}")
    return np.asarray(values)


def _percentiles_per_scan(clouds: Sequence[NDArray[np.floating]], quantiles: tuple[float, float], measure, what: str) -> tuple[float, float]:
    lo_q, hi_q = (float(q) for q in quantiles)
    if not 0.0 <= lo_q <= hi_q <= 100.0:
        raise InvalidInputError(f"quantiles must satisfy 0 <= lo <= hi <= 100, got {quantiles!r}")
    lo, hi = np.percentile(_per_scan(clouds, measure, what), [lo_q, hi_q])
    return float(lo), float(hi)


def fit_crop_distances(clouds: Sequence[NDArray[np.floating]], quantiles: tuple[float, float] = DISTANCE_QUANTILES) -> tuple[float, float]:
    """The interval of sensor-to-object distances of real object scans, for the crops' placement.

    The distance of a scan is the horizontal distance (xy) from the sensor to the centroid of its
    returns; the interval is their ``quantiles`` percentiles, to be drawn uniformly as
    :class:`~zbuf_occlude.sensors.crops.CropDistributions` ``distance_m``.  The centroid of the
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
    :class:`~zbuf_occlude.sensors.crops.CropDistributions` ``hidden_below_m`` (metres, >= 0).  A
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


def _across_sight(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(N,)`` each return's coordinate along the horizontal direction perpendicular to the line
    of sight from the sensor (the origin) to the scan's centroid; along x for a centroid straight above."""
    sight = p[:, :2].mean(axis=0)
    norm = float(np.hypot(*sight))
    return p[:, :2] @ (np.array([-sight[1], sight[0]]) / norm if norm > 0 else np.array([1.0, 0.0]))


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


def fit_width_scale(mesh, sensor, distributions, width_m: tuple[float, float], *, n_samples: int = WIDTH_SAMPLES,
                    seed: int = 0, name: str = "the mesh") -> tuple[float, float]:  # fmt: skip
    """The horizontal stretch that makes a mesh's crops as wide as real scans, for :class:`~zbuf_occlude.sensors.crops.CropDistributions` ``width_scale``.

    ``n_samples`` crops of ``mesh`` drawn from ``distributions`` are measured with
    :func:`across_sight_width`, first at the mesh's own proportions (its ``width_scale``
    ignored; a mesh that shows no width, a post thinner than the sensor's azimuth step, is
    widened 4x at a time until it does), then once more at the stretch ``s`` that this first
    median asks for; ``s`` is corrected by the second median (a thin post's width does not
    grow in proportion at first: one return per ring has no width).  The
    interval ``width_m · s / w̄``, with ``w̄`` the middle of ``width_m``, then gives crops whose
    median width is about ``w̄`` and whose spread is ``width_m``'s, and that keep the height and
    placement they would have had.  The stretch changes how the object looks, not only how
    large it is: fit it where the real objects are thicker or thinner than the mesh (trunks
    scanned as posts, shrubs as slim trees), not where the real scans are narrow because they
    show part of an object (a car squeezed to a partial view's width is a tall narrow lump), and
    compare the crops with the real scans (:mod:`zbuf_occlude.experiments.realism`).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A normalised, z-up mesh (:func:`zbuf_occlude.load_mesh`).
    sensor : Lidar
    distributions : CropDistributions
    width_m : (lo, hi)
        Metres, 0 <= lo <= hi, hi > 0 (:func:`fit_crop_widths`).
    n_samples, seed : int
        Crops measured per round (>= 1) and their seed (placements and sensor noise).
    name : str
        The mesh as errors name it (its file).

    Returns
    -------
    (lo, hi) : tuple of float
        Stretch factors, > 0.

    Raises
    ------
    InvalidInputError
        A bad ``width_m`` or ``n_samples``, a sensor that is not a :class:`Lidar`, or no crop of
        the mesh with a band of two returns (naming ``name``).
    """
    lo, hi = _check_width_fit(width_m, n_samples, sensor)

    def median_width(scale: float) -> float:
        return _median_crop_width(mesh, sensor, replace(distributions, width_scale=scale), int(n_samples), seed)

    middle, scale = (lo + hi) / 2, 1.0
    w = median_width(scale)
    for _ in range(_WIDTH_GROWTHS):  # a mesh too thin to show a width: widen it until it shows one
        if w > 0:
            break
        scale *= 4.0
        w = median_width(scale)
    if not w > 0:
        raise InvalidInputError(f"{name}: no crop of {n_samples} shows it two returns wide in a band, even {scale:g}x as wide")
    scale *= middle / w
    w = median_width(scale)
    if w > 0:  # the correction
        scale *= middle / w
    return max(lo, 1e-3 * hi) * scale / middle, hi * scale / middle


def fit_visible_across_sight(mesh, sensor, distributions, width_m: tuple[float, float], *, n_samples: int = WIDTH_SAMPLES,
                             seed: int = 0, name: str = "the mesh") -> tuple[float, float]:  # fmt: skip
    """The share of a mesh's width to leave visible so that its crops are as wide as real scans, for :class:`~zbuf_occlude.sensors.crops.CropDistributions` ``visible_across_sight``.

    ``n_samples`` crops of ``mesh`` drawn from ``distributions`` with nothing hidden are
    measured with :func:`across_sight_width` (median ``w``); where ``w`` is wider than the
    middle ``w̄`` of ``width_m``, the share ``v = w̄ / w`` is measured once more under a side
    occluder (:func:`~zbuf_occlude.sensors.crops.side_occluders`) and corrected by that median.
    The interval ``width_m · v / w̄`` then gives crops whose median width is about ``w̄`` where
    the mesh shows wider, and whole crops where the real scans are wider than the mesh's (the
    share is capped at 1 when drawn).  Fit it where real scans are narrow because they show
    part of an object (a parked car's one end), where :func:`fit_width_scale` would squeeze it.

    Parameters and errors as :func:`fit_width_scale`.

    Returns
    -------
    (lo, hi) : tuple of float
        Shares > 0 (values of 1 or more: nothing hidden).
    """
    lo, hi = _check_width_fit(width_m, n_samples, sensor)
    dist = replace(distributions, visible_across_sight=None)
    w = _median_crop_width(mesh, sensor, dist, int(n_samples), seed)
    if not w > 0:  # narrower than the sensor resolves: every real width is wider
        return 1.0, 1.0
    middle = (lo + hi) / 2
    share = middle / w
    if share < 1.0:  # the correction: a side occluder's edge does not cut the band widths in proportion
        hidden = _median_crop_width(mesh, sensor, replace(dist, visible_across_sight=(share, share)), int(n_samples), seed)
        if hidden > 0:
            share *= middle / hidden
    return max(lo, 1e-3 * hi) * share / middle, hi * share / middle


def _check_width_fit(width_m, n_samples, sensor) -> tuple[float, float]:
    """``width_m`` as ``(lo, hi)`` metres, with ``n_samples`` >= 1 and a spinning LiDAR (the width fits' arguments)."""
    try:
        lo, hi = (float(v) for v in width_m)
    except (TypeError, ValueError):
        lo, hi = math.nan, math.nan
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi and hi > 0):
        raise InvalidInputError(f"width_m must be an interval 0 <= lo <= hi, hi > 0 metres, got {width_m!r}")
    if int(n_samples) < 1:
        raise InvalidInputError(f"n_samples must be >= 1, got {n_samples}")
    if not isinstance(sensor, Lidar):
        raise InvalidInputError(f"widths are measured across a spinning LiDAR's line of sight; {getattr(sensor, 'name', sensor)!r} is not one")
    return lo, hi


def _median_crop_width(mesh, sensor, distributions, n: int, seed: int) -> float:
    """The median :func:`across_sight_width` of a width fit's ``n`` crops (metres)."""
    crops = _fit_crops(mesh, sensor, distributions, n, seed, _WIDTH_STREAM)
    return float(np.median([_across_sight_width(crop.scan.points.astype(np.float64)) for crop in crops]))


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
    if int(n_bins) < 2:
        raise InvalidInputError(f"n_bins must be >= 2, got {n_bins!r}")
    rows = [row for i, c in enumerate(clouds) if len(p := _checked_scan(i, c)) and np.any(np.isfinite(row := _width_profile(p, int(n_bins))))]
    if len(rows) < MIN_PLACEMENT_SCANS:
        raise InvalidInputError(f"fit_crop_width_profile needs at least {MIN_PLACEMENT_SCANS} scans that show a width, got {len(rows)}")
    return _nan_median_or_one(np.array(rows))


def _nan_median_or_one(rows: NDArray[np.float64]) -> tuple[float, ...]:
    filled = np.isfinite(rows).any(axis=0)
    median = np.full(rows.shape[1], 1.0)
    median[filled] = np.nanmedian(rows[:, filled], axis=0)
    return tuple(float(v) for v in median)


def fit_width_profile(mesh, sensor, distributions, profile: Sequence[float], *, n_samples: int = WIDTH_SAMPLES, seed: int = 0,
                      name: str = "the mesh") -> tuple[float, ...]:  # fmt: skip
    """The warp over the height that gives a mesh's crops a class's outline, for :class:`~zbuf_occlude.sensors.crops.CropDistributions` ``width_profile``.

    ``n_samples`` crops of ``mesh`` drawn from ``distributions`` (its ``width_scale`` and
    ``width_profile`` as given) are measured with :func:`width_profile`; the stretch of each bin
    is the target ``profile`` over their median, clipped to [1/8, 8] (1 where either is
    unknown).  Those bins are of the crops' relative height, which starts above the mesh's
    bottom where the placement hides it; they are mapped to the mesh's own relative height by
    the crops' median lowest and highest return, then the crops are measured once more under
    the warp and each bin corrected once.  Both profiles are over the scan's median width, which
    the warp moves too, so the crops get the outline's shape up to a common factor (a person's
    knees at 0.5 and shoulders at 1.2 may come out 0.57 and 1.36); fit ``width_scale`` again
    under the warp (:func:`fit_width_scale`) for the widths in metres.  A mesh made to look
    like the user's scans, not a sensor setting: its parts move (a T-posed person's arms are
    pulled in; a sign's plate is made as narrow as its post; a tree's trunk as wide as its
    crown).

    Parameters
    ----------
    mesh : trimesh.Trimesh or dict
        A normalised, z-up mesh (:func:`zbuf_occlude.load_mesh`), or a primitive spec
        (:mod:`zbuf_occlude.sensors.scene`).
    sensor : Lidar
    distributions : CropDistributions
    profile : sequence of float
        The class's outline, ``K >= 2`` values > 0 (:func:`fit_crop_width_profile`).
    n_samples, seed : int
        Crops measured per round (>= 1) and their seed.
    name : str
        The mesh as errors name it.

    Returns
    -------
    tuple of K float
        Stretch factors in [1/8, 8] at the centres of ``K`` equal bins of the mesh's relative height.

    Raises
    ------
    InvalidInputError
        A bad ``profile`` or ``n_samples``, a sensor that is not a :class:`Lidar`, or no crop of
        the mesh that shows a width (naming ``name``).
    """
    from zbuf_occlude.sensors.scene import SceneObject, check_width_profile

    target = np.asarray(check_width_profile(profile))
    if int(n_samples) < 1:
        raise InvalidInputError(f"n_samples must be >= 1, got {n_samples}")
    if not isinstance(sensor, Lidar):
        raise InvalidInputError(f"widths are measured across a spinning LiDAR's line of sight; {getattr(sensor, 'name', sensor)!r} is not one")
    k = len(target)
    z_lo, z_hi = (float(v) for v in np.asarray(SceneObject(mesh).build()[0].bounds, dtype=np.float64)[:, 2])  # a primitive's too
    centres = (np.arange(k) + 0.5) / k

    def measure(dist) -> tuple[NDArray[np.float64], float, float]:
        """The crops' median profile, and their median lowest and highest return in the mesh's relative height."""
        rows, spans = [], []
        for crop in _fit_crops(mesh, sensor, dist, int(n_samples), seed, _PROFILE_STREAM):
            row = _width_profile(crop.scan.points.astype(np.float64), k)
            if np.any(np.isfinite(row)):
                rows.append(row)
                spans.append((crop.local_points[:, 2].min(), crop.local_points[:, 2].max()))
        if not rows:
            raise InvalidInputError(f"{name}: no crop of {n_samples} shows a width to fit its outline to")
        lo, hi = (np.median(np.array(spans), axis=0) - z_lo) / max(z_hi - z_lo, 1e-12)
        return np.array(_nan_median_or_one(np.array(rows))), float(lo), float(hi)

    def stretch(measured, lo, hi) -> NDArray[np.float64]:
        """Target over measured per crop bin, at the mesh's bin centres."""
        ratio = np.clip(target / measured, 1 / 8, 8)
        return np.interp(centres, lo + centres * (hi - lo), ratio)

    first = stretch(*measure(distributions))
    dist = replace(distributions, width_profile=tuple(float(v) for v in first))
    factors = np.clip(first * stretch(*measure(dist)), 1 / 8, 8)  # the correction
    return tuple(float(v) for v in factors)


def fit_object_shape(mesh, sensor, distributions, width_m: tuple[float, float] | None = None, profile: Sequence[float] | None = None, *,
                     occlude: bool = False, seed: int = 0, name: str = "the mesh") -> dict:  # fmt: skip
    """What makes a mesh's crops as wide as real scans and gives them a real outline, as :class:`~zbuf_occlude.sensors.crops.CropDistributions` keywords.

    With ``width_m`` only: ``{"width_scale": (lo, hi)}`` (:func:`fit_width_scale`), or with
    ``occlude`` ``{"visible_across_sight": (lo, hi)}`` (:func:`fit_visible_across_sight`: a
    partial view instead of a thinner object).  With ``profile`` only: ``{"width_profile": (K
    factors)}`` (:func:`fit_width_profile`).  With both, the warp is fitted at the width stretch
    (or at the mesh's own width, with ``occlude``), then the width again under the warp.
    Neither: ``{}``.  Parameters and errors as those functions.
    """
    fit_width = fit_visible_across_sight if occlude else fit_width_scale
    key = "visible_across_sight" if occlude else "width_scale"
    out: dict = {}
    if width_m is not None and not occlude:
        out[key] = fit_width(mesh, sensor, distributions, width_m, seed=seed, name=name)
    if profile is not None:
        at = replace(distributions, width_scale=out.get("width_scale", distributions.width_scale))
        out["width_profile"] = fit_width_profile(mesh, sensor, at, profile, seed=seed, name=name)
    if width_m is not None and (occlude or profile is not None):
        out[key] = fit_width(mesh, sensor, replace(distributions, width_profile=out.get("width_profile", distributions.width_profile)),
                             width_m, seed=seed, name=name)  # fmt: skip
    return out


def _fit_crops(mesh, sensor, distributions, n: int, seed: int, stream: int):
    """The ``n`` crops a fit measures, crop ``k`` drawn from ``derive_rng(seed, stream, k)`` (a generator)."""
    from zbuf_occlude.geometry.samples import derive_rng
    from zbuf_occlude.sensors.crops import draw_placement, object_crop  # scans: trimesh and embree, imported when a fit measures

    for k in range(n):
        rng = derive_rng(seed, stream, k)
        yield object_crop(mesh, sensor, draw_placement(distributions, rng), seed=int(rng.integers(2**63)))


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
