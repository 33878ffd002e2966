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
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.geometry.arguments import described
from zbuf_occlude.geometry.sampling import check_seed
from zbuf_occlude.sensors.kinds import capabilities
from zbuf_occlude.sensors.patterns.spinning import Lidar

__all__ = [
    "BOOTSTRAP", "check_bootstrap", "check_fit_seed", "Estimate", "MAX_BOOTSTRAP", "estimates_markdown", "fit_lidar", "LidarFit", "MAX_DROPOUT_GAP", "MIN_RETURNS", "PLANE_NEIGHBOURS", "RING_SHARE",
]  # fmt: skip
#: How a refusal of scans no spinning sensor made ends: what to fit instead, in the library and on the command line.
_NOT_SPINNING = ("these are not scans in a spinning sensor's frame (airborne crops or world coordinates?); fit an airborne "
                 "scanner to airborne crops instead (fit_airborne; fit-sensor --sensor dales-q1560 or riegl-q1560)")  # fmt: skip
#: Bootstrap resamples of the scans for every uncertainty.
BOOTSTRAP = 200
#: Most bootstrap resamples a fit takes (``fit-sensor --bootstrap`` too): each is a pass over the scans or pulses, and a
#: standard deviation over 10,000 resamples is already within 1 % of its limit, ``1/√(2(B − 1))``.
MAX_BOOTSTRAP = 10_000
#: Longest gap inside a ring, in azimuth steps, counted as lost returns (module docstring).
MAX_DROPOUT_GAP = 4
#: Neighbours of the local plane fit (ground returns).
PLANE_NEIGHBOURS = 24
#: Fewest returns a scan needs to take part in the fit.
MIN_RETURNS = 20
#: Least share of the returns within an eighth of a beam spacing of a beam (:func:`_check_rings`).
RING_SHARE = 0.6
#: Degrees beyond half the widest beam gap at which a return lies outside every beam.
_OUTSIDE_BEAMS_DEG = 0.5
_GROUND_SLICE_M = 0.15
_PLANARITY = 0.3
_GROUND_NORMAL_COS = math.cos(math.radians(25.0))


def check_bootstrap(bootstrap: object, *, name: str = "bootstrap") -> int:
    """``bootstrap`` as the number of resamples of a fit: an integer from 2 to :data:`MAX_BOOTSTRAP`.

    Raises
    ------
    ArgumentTypeError
        Not an integer (a bool, a float, text), naming ``name``.
    InvalidInputError
        Below 2 (a spread needs two resamples) or above :data:`MAX_BOOTSTRAP`.
    """
    if isinstance(bootstrap, (bool, np.bool_)) or not isinstance(bootstrap, (int, np.integer)):
        raise ArgumentTypeError(f"{name} must be an integer, got {described(bootstrap)}")
    if bootstrap < 2:
        raise InvalidInputError(
            f"{name} must be >= 2 (a spread needs two resamples), got {int(bootstrap) if bootstrap > -1000 else 'fewer'}"
        )
    if bootstrap > MAX_BOOTSTRAP:
        raise InvalidInputError(f"{name} must be at most {MAX_BOOTSTRAP:,} (MAX_BOOTSTRAP), got {_typed(bootstrap)}")
    return int(bootstrap)


def _typed(number: int) -> str:
    """A whole number the caller gave (an argument, never a file's value) for a message; a huge one by its size."""
    return str(int(number)) if abs(int(number)).bit_length() <= 64 else "a whole number of over 19 digits"


def check_fit_seed(seed: object, *, name: str = "seed") -> int:
    """``seed`` of a fit's bootstrap: :func:`~zbuf_occlude.geometry.sampling.check_seed`'s rule, and an integer, which
    the fit records beside its figures (not None or a Generator).

    Raises
    ------
    InvalidInputError
        What :func:`~zbuf_occlude.geometry.sampling.check_seed` refuses (negative, above ``MAX_SEED``, not a number).
    ArgumentTypeError
        None or a numpy Generator.
    """
    checked = check_seed(seed, name=name)
    if not isinstance(checked, int):
        raise ArgumentTypeError(f"{name} must be a non-negative integer (a fit records its seed), got {described(seed)}")
    return checked


@dataclass(frozen=True)
class Estimate:
    """One fitted quantity: ``value ± std`` (bootstrap over scans), from ``n`` returns or scans.

    ``value`` (or ``std``) is NaN where the scans do not tell it (nothing to measure it on, or
    too few resamples that measured it): :meth:`to_json` writes ``null`` for it and
    :func:`estimates_markdown` says it was not measured.
    """

    value: float
    std: float
    n: int
    method: str
    unit: str = ""
    set_in_sensor: bool = False

    def to_json(self) -> dict:
        """The fields as a strict-JSON object: ``value`` and ``std`` are ``None`` (``null``) where not measured (NaN or infinite)."""
        out = dict(vars(self))
        for key in ("value", "std"):
            out[key] = float(out[key]) if math.isfinite(out[key]) else None
        return out


@dataclass(frozen=True)
class LidarFit:
    """The fitted sensor and the estimates behind it.

    Attributes
    ----------
    sensor : Lidar
        ``base`` with ``firing_rate_hz`` and its beam's ``range_noise_m``, ``dropout`` and ``dropout_range_per_m`` set from
        the scans; every other beam field is the base's (its data sheet).
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
        """The sensor as :func:`~zbuf_occlude.sensors.kinds.sensor_from_name` reads it, plus a ``fit`` block."""
        from zbuf_occlude.sensors.kinds import sensor_to_json

        spec = sensor_to_json(self.sensor)
        spec["fit"] = {"base": self.base.name, "n_scans": self.n_scans,
                       "estimates": {k: e.to_json() for k, e in self.estimates.items()}}  # fmt: skip
        return spec

    def markdown(self) -> str:
        """A table of the estimates (:func:`estimates_markdown`)."""
        return estimates_markdown(self.estimates)


def estimates_markdown(estimates: Mapping[str, Estimate], why_not_measured: Mapping[str, str] | None = None) -> str:
    """A Markdown table of fitted quantities: quantity, value ± std (the bootstrap's), unit, n, whether it sets the sensor, how.

    Parameters
    ----------
    estimates : mapping of str to Estimate
    why_not_measured : mapping of str to str, optional
        Per quantity, why the scans cannot tell it: a value that is NaN reads "not measured (<why>)",
        or just "not measured" where no reason is given.  A measured value whose spread is NaN (too
        few resamples measured it) reads "<value> (spread not measured)".
    """
    why_not_measured = why_not_measured or {}
    lines = ["| quantity | value ± std | unit | n | sets the sensor | how |", "|---|---|---|---|---|---|"]
    for name, e in estimates.items():
        if not math.isfinite(e.value):
            why = why_not_measured.get(name)
            value = f"not measured ({why})" if why else "not measured"
        elif not math.isfinite(e.std):
            value = f"{e.value:.4g} (spread not measured)"
        else:
            value = f"{e.value:.4g} ± {e.std:.2g}"
        lines.append(f"| {name} | {value} | {e.unit} | {e.n} | {'yes' if e.set_in_sensor else 'no'} | {e.method} |")
    return "\n".join(lines) + "\n"


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


def _check_rings(stats: Sequence[_ScanStats], base: Lidar) -> None:
    """Refuse scans that no spinning sensor at the origin could have made (airborne crops, a world frame).

    A spinning sensor's returns lie on its beams' cones: once each scan's median offset (a mount
    tilt) is taken out, nearly all lie within an eighth of the beam spacing of a beam, where
    elevations unrelated to the beams put a quarter (told from scans over three rings or more,
    when at least 3 are), and nearly none lie above or below every beam.  Scans whose objects lie
    beyond the sensor's range cannot be its scans either.
    """
    ranges = np.array([st.range_m for st in stats])
    if np.median(ranges) > base.beam.max_range_m:
        raise InvalidInputError(
            f"fit_lidar: the scans' objects lie a median {np.median(ranges):,.0f} m from the origin, beyond {base.name}'s "
            f"{base.beam.max_range_m:g} m range: {_NOT_SPINNING}"
        )
    beams = np.sort(np.asarray(base.elevations_deg, dtype=np.float64))
    spacing = float(np.median(np.diff(beams))) if len(beams) > 1 else math.inf
    # each scan's residuals about its own median (a mount tilt taken out)
    centred = [np.abs(st.elevation_residual_deg - np.median(st.elevation_residual_deg)) for st in stats]
    widest = float(np.max(np.diff(beams))) if len(beams) > 1 else 0.0
    outside = float(np.mean(np.concatenate(centred) > widest / 2.0 + _OUTSIDE_BEAMS_DEG))
    if outside > 1.0 - RING_SHARE:
        raise InvalidInputError(
            f"fit_lidar: no sensor origin consistent with {base.name}'s rings: {outside:.0%} of the returns lie outside its "
            f"beams' elevations ({beams[0]:g}° to {beams[-1]:g}°) seen from the origin; {_NOT_SPINNING}"
        )
    # only scans over three rings or more tell: a short object far away may lie within one beam spacing
    telling = [c for st, c in zip(stats, centred, strict=True) if st.ring_spacings_deg.sum() >= 2.0 * spacing]
    if len(telling) < 3:
        return
    share = float(np.mean(np.concatenate(telling) <= spacing / 8.0))
    if share < RING_SHARE:
        raise InvalidInputError(
            f"fit_lidar: no sensor origin consistent with {base.name}'s rings: {share:.0%} of the returns lie within an eighth "
            f"of a beam spacing of a beam (a spinning scan puts nearly all there, unrelated elevations a quarter); {_NOT_SPINNING}"
        )


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
        nothing could be estimated; ``bootstrap`` outside 2 to :data:`MAX_BOOTSTRAP`, a negative or too large ``seed``.
    ArgumentTypeError
        ``seed`` or ``bootstrap`` not an integer.
    """
    if not capabilities(base).spins:
        raise InvalidInputError(f"fit_lidar fits a spinning LiDAR, got {type(base).__name__}")
    seed, bootstrap = check_fit_seed(seed), check_bootstrap(bootstrap)
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
    _check_rings(stats, base)
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
    # the base's beam (its data sheet) with only what the scans measured changed
    beam = base.beam.with_(range_noise_m=point["range_noise_m"], dropout=min(max(point["dropout_at_0m"], 0.0), 0.95),
                           dropout_range_per_m=point["dropout_range_per_m"] if math.isfinite(point["dropout_range_per_m"]) else 0.0)  # fmt: skip
    sensor = replace(base, name=f"{base.name}-fitted", firing_rate_hz=point["firing_rate_hz"], beam=beam,
                     source=f"{base.source}; fitted to {len(stats)} real scans".lstrip("; "))  # fmt: skip
    return LidarFit(sensor=sensor, base=base, estimates=estimates, n_scans=len(stats))
