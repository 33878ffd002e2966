"""An airborne laser scanner fitted to segmented aerial object crops: what the simulation can set, estimated from the user's own crops.

Input: object crops, each ``(N, 3) float64``, world frame, z up, metres, **no sensor position**
(airborne crops do not record one).  Every crop is split into its planar faces: points whose
local plane (:data:`PLANE_NEIGHBOURS` nearest neighbours) has a normal within
:data:`HORIZONTAL_DEG` of z are its *top*; points whose normal is within :data:`HORIZONTAL_DEG`
of horizontal are grouped by the azimuth of their outward normal (away from the crop's centre)
into *walls*.  Then, per crop:

``density_m2``
    Points per m² of the top, counted in a square grid of the top's x–y (cells about two point
    spacings wide): the mean count of the *interior* cells (a cell and its 8 neighbours all hold
    points) over the cell's area.  Cells fall at random offsets from the scan pattern, so the
    mean count is unbiased for a regular pattern as for a random one.
``incidence_deg`` (the scan angle at the crop)
    Pulses arriving at angle θ from the vertical, from the side ``u`` (unit horizontal vector
    towards the aircraft), put ``ρ_h = Φ cos θ`` points per m² on a horizontal face and
    ``Φ sin θ (m · u)`` on a vertical face of outward normal ``m`` (Φ: pulses per m² across the
    beam).  The walls' densities (same grid rule, in the wall's own coordinates) are fitted by
    least squares as ``ρ_m = m · b``; then ``tan θ = |b| / ρ_h``.  A crop whose walls face
    opposite ways with points on both (lit by strips on both sides, as in a survey block with
    side overlap) gives no single angle; it counts towards ``two_sided_fraction``.
``vertical_noise_m``
    σ of the top's points about their local planes: the smallest eigenvalue of the neighbours'
    covariance, ``× k / (k − 3)`` (the residual variance of a plane fitted to ``k`` points),
    median over interior points, corrected for the median of a χ² with ``k − 3`` degrees of
    freedom.  Curved tops make it an upper bound.  ``range_noise_m = σ_v / cos θ``.
``points_per_footprint_m2``
    Returns per m² of the crop's x–y convex hull: how many points an object of a given size
    gets, the figure the realism report compares per class.

Over the crops: ``max_scan_angle_deg``, half the swath: objects spread evenly across a strip
have ``tan θ`` uniform on ``[0, tan(S/2)]``, so ``tan(S/2) = 2 · median tan θ`` (crops with a
top but too little wall to tell count as 0: they lie near the nadir; the median, unlike the
largest angle, is not pulled up by one noisy crop); the mean top density, the median noise,
``two_sided_fraction``.
Uncertainties: the standard deviation over :data:`BOOTSTRAP` resamples of the crops (with
replacement, seed given).  Nothing depends on file names or class labels.  A crop of more than
:data:`MAX_CROP_POINTS` points is measured on a seeded random subsample of that many, its
densities scaled back by ``N / MAX_CROP_POINTS`` (:func:`crop_faces`): memory and time stay
bounded for crops of millions of points.

What cannot be told from crops: flying height, speed and pulse rate separately (only the
density they give), dropout (it only lowers the density).  :func:`fit_airborne` keeps those of
the base scanner and sets its pulse rate to give the measured density, its swath from
``max_scan_angle_deg`` (one-sided crops only) and its range noise.

The flight plan follows the same model: when the swath was measured and most crops are lit from
one side (``two_sided_fraction`` at most :data:`ONE_SIDED_SHARE`), the fitted scanner flies
:data:`FITTED_LINES` parallel lines with no side overlap (strips that abut, at the survey density
of one strip).  ``scan``, ``farm`` and ``experiment sim2real`` place an object near the plan
centre and shift the lines across track by a uniform draw over one strip
(:func:`~zbuf_occlude.sensors.scan.scan_airborne`), so the object lies in one strip, anywhere
across it: its scan angle is spread as the fit assumed, ``tan θ`` uniform on ``[0, tan(S/2)]``.
Crops mostly lit from both sides (strips with a large overlap) cannot tell the plan: the base's
is kept.

Sources: the flat-ground density law is Baltsavias (1999), Eq. 17 (:mod:`zbuf_occlude.sensors.patterns.airborne`);
the wall/top ratio is the projection of the same beam flux onto a vertical face.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.sampling import check_seed
from zbuf_occlude.sensors.patterns.airborne import AirborneScanner
from zbuf_occlude.sensors.fit.lidar import BOOTSTRAP, Estimate, check_bootstrap, check_fit_seed, estimates_markdown
from zbuf_occlude.sensors.kinds import capabilities

__all__ = [
    "AirborneFit", "CropFaces", "FITTED_LINES", "HORIZONTAL_DEG", "MAX_CROP_POINTS", "MIN_CROP_POINTS", "ONE_SIDED_SHARE",
    "PLANE_NEIGHBOURS",
    "crop_faces", "fit_airborne",
]  # fmt: skip

#: Neighbours of the local plane fit.
PLANE_NEIGHBOURS = 16
#: A face is a top (or a wall) when its normal is within this angle of z (of horizontal).
HORIZONTAL_DEG = 20.0
#: Fewest points a crop needs to take part in the fit.
MIN_CROP_POINTS = 40
#: Most points of a crop its faces are measured on: a larger crop is measured on a seeded random
#: subsample of this many (the local planes hold ``(n, PLANE_NEIGHBOURS, 3) float64``, 384 bytes a
#: point: 2 GB for a crop of 5·10⁶; 200,000 points tell a crop's density, angle and noise as well).
MAX_CROP_POINTS = 200_000
#: Parallel lines of a fitted plan: the line nearest an object and one either side, so that an
#: object anywhere within a strip's width of the plan centre lies in one strip (module docstring).
FITTED_LINES = 3
#: The fitted plan's strips abut when at most this share of the crops is lit from both sides.
ONE_SIDED_SHARE = 0.5
#: Fewest points of a wall for its density to count.
_MIN_WALL_POINTS = 15
#: Largest ratio of the smallest to the middle eigenvalue of a planar neighbourhood.
_PLANARITY = 0.1
#: Walls whose azimuths are closer than this are one wall, degrees.
_WALL_GAP_DEG = 25.0
#: A Delaunay triangle with an edge longer than this many median edges spans a gap: left out.
_LONG_EDGE = 4.0
#: Fewest inner triangles of a face for its density to count.
_MIN_TRIANGLES = 8


@dataclass(frozen=True)
class CropFaces:
    """The faces of one crop and what they give (module docstring).

    Attributes
    ----------
    n_points : int
        Points of the crop (all of them, also where a subsample was measured).
    top_density_m2 : float
        NaN when the crop has no top with enough interior cells.
    wall_normals : (W, 2) float64
        Outward unit normals of the walls with a density, x–y.
    wall_density_m2 : (W,) float64
    incidence_deg : float
        NaN when it cannot be told (no top, no wall, or walls lit from both sides).
    two_sided : bool
        Walls facing opposite ways both hold points.
    plane_variance_m2 : float
        Median residual variance of the top's points about their local planes (χ²-corrected); NaN without a top.
    footprint_m2 : float
        Area of the x–y convex hull.
    """

    n_points: int
    top_density_m2: float
    wall_normals: NDArray[np.float64]
    wall_density_m2: NDArray[np.float64]
    incidence_deg: float
    two_sided: bool
    plane_variance_m2: float
    footprint_m2: float


def _local_planes(points: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Per point: unit normal (sign arbitrary), the plane-fit residual variance, and the neighbour indices."""
    from scipy.spatial import cKDTree

    k = min(PLANE_NEIGHBOURS, len(points))
    _, idx = cKDTree(points).query(points, k=k)
    nb = points[idx]  # (n, k, 3): crop_faces caps n (MAX_CROP_POINTS)
    nb -= nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb) / k
    w, v = np.linalg.eigh(cov)  # ascending
    planar = w[:, 0] <= _PLANARITY * np.maximum(w[:, 1], 1e-300)
    variance = np.where(planar, w[:, 0] * k / max(k - 3, 1), np.nan)
    return v[:, :, 0], variance, idx


def _face_density(uv: NDArray[np.float64]) -> float:
    """Points per unit area of a planar face given in its own 2-D coordinates; NaN when it cannot be told.

    ``N`` points in the plane make about ``2N`` Delaunay triangles, of mean area ``1 / (2ρ)``
    whatever the pattern (exactly for a Poisson process, and for any lattice).  Triangles with a
    corner on the convex hull or an edge longer than :data:`_LONG_EDGE` median edges (across a
    gap between pieces of the face, or along its outline) are left out, so neither the face's
    outline nor its shape (a roof in pieces, an L) biases the mean.
    """
    from scipy.spatial import Delaunay, QhullError

    if len(uv) < 9:
        return math.nan
    try:
        tri = Delaunay(uv)
    except (QhullError, ValueError):
        return math.nan
    corners = uv[tri.simplices]  # (T, 3, 2)
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)  # (T, 3)
    on_hull = np.isin(tri.simplices, tri.convex_hull).any(axis=1)
    keep = ~on_hull & (edges.max(axis=1) <= _LONG_EDGE * np.median(edges))
    if keep.sum() < _MIN_TRIANGLES:
        return math.nan
    a, b, c = corners[keep, 0], corners[keep, 1], corners[keep, 2]
    area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    mean = float(area.mean())
    return 1.0 / (2.0 * mean) if mean > 0 else math.nan


def _walls(normals: NDArray[np.float64]) -> list[NDArray[np.int64]]:
    """Indices of each wall: near-vertical points grouped by the azimuth of their outward normal."""
    azimuth = np.degrees(np.arctan2(normals[:, 1], normals[:, 0])) % 360.0
    order = np.argsort(azimuth)
    a = azimuth[order]
    if len(a) == 0:
        return []
    gaps = np.diff(np.concatenate([a, [a[0] + 360.0]]))
    cuts = np.flatnonzero(gaps > _WALL_GAP_DEG)
    if len(cuts) == 0:  # one band all round: a cylinder, no planar wall
        return []
    groups = []
    start = (cuts[-1] + 1) % len(a)
    for cut in cuts:  # each group runs from just after the previous cut to this cut (cyclically)
        stop = cut + 1
        members = order[start:stop] if start < stop else np.concatenate([order[start:], order[:stop]])
        groups.append(members)
        start = stop % len(a)
    return [g for g in groups if len(g) >= _MIN_WALL_POINTS]


def _checked_crop(points, where: str = "") -> NDArray[np.float64]:
    """``points`` as ``(N, 3) float64``, or InvalidInputError (``where`` names the crop)."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or not np.all(np.isfinite(p)):
        raise InvalidInputError(f"{where}expected finite (N, 3) points, got shape {p.shape}")
    return p


def crop_faces(points: NDArray[np.floating], *, max_points: int = MAX_CROP_POINTS, seed: int = 0) -> CropFaces:
    """Split one crop into its top and walls and measure them (module docstring).

    A crop of more than ``max_points`` points is measured on a random subsample of ``max_points``
    of them (drawn without replacement, seeded): a uniform thinning keeps the faces, their
    normals and the noise about them, and scales every density by ``max_points / N``, which is
    undone.  The footprint is the hull of every point.  Memory and time so stay bounded whatever
    the crop's size (the local planes alone take 384 bytes a point).

    Parameters
    ----------
    points : (N, 3) float
        World frame, z up, metres.
    max_points : int
        Most points measured (:data:`MAX_CROP_POINTS`), at least :data:`MIN_CROP_POINTS`.
    seed : int
        Seeds the subsample; the same seed gives the same figures.

    Raises
    ------
    InvalidInputError
        Not finite ``(N, 3)`` points, fewer than :data:`MIN_CROP_POINTS`, or ``max_points`` below it; a seed
        :func:`~zbuf_occlude.geometry.sampling.check_seed` refuses.
    """
    seed = check_seed(seed)
    p = _checked_crop(points)
    if len(p) < MIN_CROP_POINTS:
        raise InvalidInputError(f"a crop needs at least {MIN_CROP_POINTS} points, got {len(p)}")
    if int(max_points) < MIN_CROP_POINTS:
        raise InvalidInputError(f"max_points must be at least MIN_CROP_POINTS = {MIN_CROP_POINTS}, got {max_points!r}")
    n_points = len(p)
    # centred: in projected coordinates (eastings and northings of 10^5 to 10^7 m, as aerial crops
    # come) Qhull's Delaunay triangulation loses the centimetres that the faces' densities rest on
    p = p - p.mean(axis=0)
    footprint = _hull_area(p[:, :2])
    thinning = 1.0
    if n_points > int(max_points):
        keep = np.sort(np.random.default_rng(seed).choice(n_points, size=int(max_points), replace=False))
        p = p[keep]
        thinning = n_points / len(p)  # each density of the subsample is this much below the crop's
    normal, variance, idx = _local_planes(p)
    planar = np.isfinite(variance)
    top = planar & (np.abs(normal[:, 2]) >= math.cos(math.radians(HORIZONTAL_DEG)))
    top_density = _face_density(p[top, :2]) * thinning
    # the top's noise from points whose neighbours are all top points (not across an edge)
    inner_top = top & top[idx].all(axis=1)
    dof = max(idx.shape[1] - 3, 1)
    chi2_median = (1.0 - 2.0 / (9.0 * dof)) ** 3  # Wilson–Hilferty: the median of χ²_d / d
    plane_variance = float(np.median(variance[inner_top]) / chi2_median) if inner_top.sum() >= 10 else math.nan

    # the walls' planes from the other points alone, so that no neighbourhood reaches over the top's edge
    rest = p[~top]
    normals, densities = [], []
    if len(rest) >= _MIN_WALL_POINTS:
        rest_normal, _, _ = _local_planes(rest)  # sparse, noisy walls: the normal's direction, planar or not
        wall = np.abs(rest_normal[:, 2]) <= math.sin(math.radians(HORIZONTAL_DEG))
        m = rest_normal[wall][:, :2]
        m /= np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-300)
        wall_points = rest[wall]
        m[np.einsum("ij,ij->i", m, wall_points[:, :2] - p[:, :2].mean(axis=0)) < 0] *= -1.0  # outward
        for group in _walls(m):
            mean = m[group].mean(axis=0)
            mean /= max(float(np.linalg.norm(mean)), 1e-300)
            along = np.array([-mean[1], mean[0]])
            density = _face_density(np.column_stack([wall_points[group, :2] @ along, wall_points[group, 2]])) * thinning
            if np.isfinite(density):
                normals.append(mean)
                densities.append(density)
    wall_normals = np.array(normals, dtype=np.float64).reshape(-1, 2)
    wall_density = np.array(densities, dtype=np.float64)
    two_sided = bool(len(wall_normals) > 1 and (wall_normals @ wall_normals.T).min() < -0.5)
    incidence = math.nan
    if len(wall_normals) and np.isfinite(top_density) and top_density > 0 and not two_sided:
        b, *_ = np.linalg.lstsq(wall_normals, wall_density, rcond=None)
        incidence = math.degrees(math.atan2(float(np.linalg.norm(b)), top_density))
    return CropFaces(
        n_points=n_points, top_density_m2=top_density, wall_normals=wall_normals, wall_density_m2=wall_density,
        incidence_deg=incidence, two_sided=two_sided, plane_variance_m2=plane_variance, footprint_m2=footprint,
    )  # fmt: skip


def _hull_area(xy: NDArray[np.float64]) -> float:
    from scipy.spatial import ConvexHull, QhullError

    try:
        return float(ConvexHull(xy).volume)  # the area of a 2-D hull
    except (QhullError, ValueError):
        return 0.0


def _aggregate(faces: Sequence[CropFaces]) -> dict[str, float]:
    """The fit's figures over some crops (module docstring)."""
    density = np.array([f.top_density_m2 for f in faces])
    incidence = np.array([f.incidence_deg for f in faces])
    variance = np.array([f.plane_variance_m2 for f in faces])
    footprint = np.array([f.n_points / f.footprint_m2 if f.footprint_m2 > 0 else np.nan for f in faces])
    one_sided = incidence[np.isfinite(incidence)]
    # crops with a top but no wall to tell by lie near the nadir: counted as angle 0 (censored low)
    censored = np.array([not f.two_sided and math.isnan(f.incidence_deg) and math.isfinite(f.top_density_m2) for f in faces])
    tangents = np.concatenate([np.tan(np.radians(one_sided)), np.zeros(int(censored.sum()))])
    vertical = math.sqrt(float(np.nanmedian(variance))) if np.isfinite(variance).any() else math.nan
    median_incidence = float(np.median(one_sided)) if len(one_sided) else math.nan
    return {
        "density_m2": float(np.nanmean(density)) if np.isfinite(density).any() else math.nan,
        "max_scan_angle_deg": math.degrees(math.atan(2.0 * float(np.median(tangents)))) if len(one_sided) else math.nan,
        "median_incidence_deg": median_incidence,
        "vertical_noise_m": vertical,
        "range_noise_m": vertical / math.cos(math.radians(median_incidence)) if np.isfinite(median_incidence) else vertical,
        "two_sided_fraction": float(np.mean([f.two_sided for f in faces])),
        "points_per_footprint_m2": float(np.nanmedian(footprint)) if np.isfinite(footprint).any() else math.nan,
    }


_METHODS = {
    "density_m2": ("mean over crops of the top's interior-cell density", "1/m²"),
    "max_scan_angle_deg": ("atan(2 · median tan θ) over one-sided crops, wall-less ones as 0", "deg"),
    "median_incidence_deg": ("median one-sided incidence", "deg"),
    "vertical_noise_m": ("σ about local planes of the tops (χ²-corrected median)", "m"),
    "range_noise_m": ("vertical noise / cos(median incidence)", "m"),
    "two_sided_fraction": ("crops with walls lit from opposite sides", ""),
    "points_per_footprint_m2": ("median returns per m² of x–y convex hull", "1/m²"),
}
#: The estimates the fitted scanner takes.
_SET_IN_SENSOR = ("density_m2", "max_scan_angle_deg", "range_noise_m")
#: Why an estimate can be NaN, for the table (:func:`~zbuf_occlude.sensors.fit.lidar.estimates_markdown`).
_WHY_NOT_MEASURED = {
    "density_m2": "no crop has a top large enough to count its points",
    "max_scan_angle_deg": "no crop tells the scan angle",
    "median_incidence_deg": "no crop tells the scan angle",
    "vertical_noise_m": "no crop has a top large enough to fit planes to",
    "range_noise_m": "no crop has a top large enough to fit planes to",
    "points_per_footprint_m2": "no crop has a footprint of nonzero area",
}


@dataclass(frozen=True)
class AirborneFit:
    """The fitted airborne scanner and the estimates behind it.

    Attributes
    ----------
    sensor : AirborneScanner
        ``base`` with ``pulse_rate_hz`` set to give the measured density over its flight plan
        (``survey_density_m2``), ``swath_deg`` twice ``max_scan_angle_deg`` (when one-sided crops
        measured it, capped below 180°) and then, where most crops are one-sided, a plan of
        :data:`FITTED_LINES` abutting lines on ``base``'s first heading (module docstring), and its
        beam's ``range_noise_m``; the rest as in ``base`` (every other beam field its data sheet's).
    base : AirborneScanner
    estimates : dict of str to Estimate
    n_crops : int
        Crops used (those with at least :data:`MIN_CROP_POINTS` points).
    """

    sensor: AirborneScanner
    base: AirborneScanner
    estimates: dict[str, Estimate]
    n_crops: int

    def to_json(self) -> dict:
        """A sensor file that ``scan``, ``farm --sensor`` and ``experiment sim2real --sensor`` take: the
        scanner's fields with ``"kind": "airborne"`` and, under ``"fit"``, the estimates (metadata); an estimate
        nothing measured (the scan angle when no crop tells one) is ``null`` (:meth:`Estimate.to_json`)."""
        from zbuf_occlude.sensors.kinds import sensor_to_json

        spec = sensor_to_json(self.sensor)
        spec["fit"] = {
            "base": self.base.name, "n_crops": self.n_crops,
            "estimates": {k: e.to_json() for k, e in self.estimates.items()},
        }  # fmt: skip
        return spec

    def markdown(self) -> str:
        """The estimates as a table (value ± the bootstrap's std, or why it was not measured) and, below it, the fitted
        scanner in one paragraph."""
        s, base = self.sensor, self.base
        return estimates_markdown(self.estimates, _WHY_NOT_MEASURED) + (
            f"\nThe fitted scanner {s.name}: {s.survey_density_m2:.1f} points/m² on flat open ground (pulse rate "
            f"{s.pulse_rate_hz:,.0f} Hz), swath {s.swath_deg:.1f}° ({s.swath_width_m:,.0f} m wide at {s.altitude_m:g} m), "
            f"range noise {s.beam.range_noise_m:.3f} m.  Its altitude, speed, line rate and scan pattern are {base.name}'s: crops "
            f"cannot tell them apart, only the density they give.  {self.plan_sentence()}\n"
        )

    def plan_sentence(self) -> str:
        """What the fitted flight plan is and where it comes from, in one sentence."""
        s, base = self.sensor, self.base
        if _abutting(self.estimates["max_scan_angle_deg"].value, self.estimates["two_sided_fraction"].value):
            return (f"It flies {s.n_lines} parallel lines whose strips abut ({s.flight_line_spacing_m:,.0f} m apart), so that "
                    f"a scanned object lies in one strip, anywhere across it: scan angles 0° to {s.swath_deg / 2:.1f}°, as "
                    "in the crops.")  # fmt: skip
        if self.estimates["two_sided_fraction"].value > ONE_SIDED_SHARE:
            return (f"Most crops are lit from both sides (overlapping strips), which does not tell the flight plan: it is "
                    f"{base.name}'s ({s.n_lines} lines, side overlap {s.side_overlap:g}).")  # fmt: skip
        return f"No crop told a scan angle: the swath and the flight plan are {base.name}'s ({s.n_lines} lines, side overlap {s.side_overlap:g})."


def fit_airborne(crops: Sequence[NDArray[np.floating]], base: AirborneScanner, *, seed: int = 0, bootstrap: int = BOOTSTRAP,
                 max_crop_points: int = MAX_CROP_POINTS) -> AirborneFit:  # fmt: skip
    """Fit an airborne scanner to segmented aerial object crops (module docstring).

    Parameters
    ----------
    crops : sequence of (N, 3) float
        World frame, z up, metres; no sensor position needed.
    base : AirborneScanner
        Supplies what crops cannot tell: flying height, speed, line rate, pattern, flight plan.
    seed : int
        Seeds the bootstrap and the subsample of each crop above ``max_crop_points``.
    bootstrap : int
        Resamples of the crops, at least 2.
    max_crop_points : int
        A crop of more points is measured on a seeded random subsample of this many
        (:data:`MAX_CROP_POINTS`, :func:`crop_faces`), so that memory stays bounded.

    Returns
    -------
    AirborneFit

    Raises
    ------
    InvalidInputError
        ``base`` is not an airborne scanner; a crop that is not finite ``(N, 3)`` points (naming its index), fewer than 2 usable crops, no
        crop with a measurable top (the density cannot be told), ``bootstrap`` outside 2 to
        :data:`~zbuf_occlude.sensors.fit.lidar.MAX_BOOTSTRAP`, a negative or too large ``seed``, ``max_crop_points`` below
        :data:`MIN_CROP_POINTS`.
    ArgumentTypeError
        ``seed`` or ``bootstrap`` not an integer.
    """
    kind = capabilities(base)
    if not (kind.flies and kind.fits):
        raise InvalidInputError(f"fit_airborne fits an airborne scanner, got {type(base).__name__}")
    seed, bootstrap = check_fit_seed(seed), check_bootstrap(bootstrap)
    faces = []
    for i, crop in enumerate(crops):
        p = _checked_crop(crop, f"crop {i}: ")
        if len(p) >= MIN_CROP_POINTS:
            faces.append(crop_faces(p, max_points=max_crop_points, seed=seed))
    if len(faces) < 2:
        raise InvalidInputError(f"an airborne fit needs at least 2 crops of {MIN_CROP_POINTS}+ points, got {len(faces)}")
    if not any(np.isfinite(f.top_density_m2) for f in faces):
        raise InvalidInputError(
            "no crop has a horizontal top large enough to measure the point density: are these airborne crops, z up, in metres?"
        )
    best = _aggregate(faces)
    rng = np.random.default_rng(seed)
    boots = [_aggregate([faces[j] for j in rng.integers(len(faces), size=len(faces))]) for _ in range(int(bootstrap))]
    estimates = {}
    for key, value in best.items():
        spread = np.array([b[key] for b in boots], dtype=np.float64)
        std = float(np.nanstd(spread)) if np.isfinite(spread).sum() >= 2 else math.nan
        method, unit = _METHODS[key]
        estimates[key] = Estimate(value, std, len(faces), method, unit, key in _SET_IN_SENSOR and math.isfinite(value))
    return AirborneFit(sensor=_fitted_scanner(base, best), base=base, estimates=estimates, n_crops=len(faces))


def _abutting(max_scan_angle_deg: float, two_sided_fraction: float) -> bool:
    """Whether the fitted plan is :data:`FITTED_LINES` abutting strips: a swath was measured and most crops are one-sided."""
    return math.isfinite(max_scan_angle_deg) and max_scan_angle_deg > 0 and two_sided_fraction <= ONE_SIDED_SHARE


def _fitted_scanner(base: AirborneScanner, best: dict[str, float]) -> AirborneScanner:
    changes: dict = {"name": f"{base.name}-fitted"}
    if math.isfinite(best["max_scan_angle_deg"]) and best["max_scan_angle_deg"] > 0:
        changes["swath_deg"] = min(2.0 * best["max_scan_angle_deg"], 170.0)
    if _abutting(best["max_scan_angle_deg"], best["two_sided_fraction"]):
        changes.update(n_lines=FITTED_LINES, side_overlap=0.0, headings_deg=base.headings_deg[:1])
    if math.isfinite(best["range_noise_m"]):  # the base's beam (its data sheet) with the noise measured
        changes["beam"] = base.beam.with_(range_noise_m=best["range_noise_m"])
    scanner = base.with_(**changes)
    if math.isfinite(best["density_m2"]) and best["density_m2"] > 0:
        # survey_density_m2 is proportional to the pulse rate; dropout lowers what is measured
        scale = best["density_m2"] / (scanner.survey_density_m2 * (1.0 - scanner.beam.dropout))
        scanner = scanner.with_(pulse_rate_hz=scanner.pulse_rate_hz * scale)
    return scanner
