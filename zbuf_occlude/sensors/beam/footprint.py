"""A laser beam's footprint sampled by sub-rays: equal-area cells of the divergence cone.

A pulse leaves the scanner as a cone of full angle ``divergence`` about its centre direction.
The cone's cross-section (the footprint disc, in angle) is cut into ``K`` cells of equal area,
and each cell is represented by one sub-ray; the sub-ray's weight is the share of the pulse's
energy that falls in its cell.

The cells, in units of the half-divergence (the disc of radius 1):

* a centre disc of radius ``sqrt(1/K)`` (area ``1/K``), its sub-ray on the beam axis;
* ``R`` rings around it; ring ``j`` holds ``n_j`` cells, ``c_j = 1 + n_1 + ... + n_j`` cells
  lie inside its outer radius ``sqrt(c_j / K)``, so every cell has area ``1/K``;
* ring ``j``'s sub-rays lie at its mean-area radius ``sqrt((c_{j-1} + c_j) / (2K))`` (the
  radius that halves the annulus), at azimuths ``(i + (j - 1) / 2) · 360° / n_j`` (consecutive
  rings staggered by half a cell).

``R`` is the fewest rings whose hexagonal layout (``n_j = 6j``: 1, 7, 19, 37, 61 ... rays)
holds ``K``, and the ``K - 1`` outer cells are shared among the rings in proportion to ``j``
(largest remainders), so that cells stay about as wide as they are long (of the ring counts
tried, this one keeps the sub-rays' nearest-neighbour cells within about ±30 % of ``1/K`` for
4 ≤ K ≤ 257).  ``K = 7`` is the centre and 6 rays at ``sqrt(4/7)`` of the half-angle, 60° apart,
starting along the beam's local ``u`` axis.  :meth:`Beam.footprint_directions
<zbuf_occlude.sensors.beam.fields.Beam.footprint_directions>` casts a beam's sub-rays with these offsets.

Offsets are polar, in the beam's local frame: column 0 is the angle off the beam axis, column 1
the azimuth about it from ``u`` towards ``v`` (both radians).  Polar, not Cartesian, so that
:func:`subray_directions` takes the same floating-point steps for every ``K`` (the tangent of
the angle off the axis, the cosine and sine of the azimuth).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.checks import count, real, text

__all__ = [
    "FOOTPRINT_RAYS",
    "MAX_DIVERGENCE_DEG",
    "MAX_SUBRAYS",
    "PROFILES",
    "footprint_offsets",
    "plane_subrays",
    "subray_directions",
]

#: The footprint a scanner is given when none is named (``scan --footprint``, ``farm
#: --sensor-footprint``, ``experiment sim2real --returns``, a fitted divergence): the centre ray
#: and a ring of 6, one per equal-area cell of the cone.  Measured on bush meshes seen by an
#: HDL-32E at 10–20 m (docs/results/returns.md): the shares of pulses with 1, 2 and 3 returns at
#: 7 sub-rays lie 1.5, 1.6 and 0.0 points from 61 sub-rays' (19 sub-rays: within their spread)
#: at 3.9× the cost of one ray (19: 9.8×); give ``footprint_rays`` 19 or more where the shares
#: of several returns matter more than the time.
FOOTPRINT_RAYS = 7

#: Most sub-rays per pulse: a scan casts ``pulses × K`` rays, so K multiplies the cost and the
#: memory of every scan; 1024 cells already make each cell ~3 % of the footprint's diameter.
MAX_SUBRAYS = 1024
#: Widest full-angle beam divergence, degrees: the edge of the cone 45° off its axis, already
#: thousands of times any scanner's (0.01–0.5°); a beam's ``divergence_deg`` above it is refused.
MAX_DIVERGENCE_DEG = 90.0

#: Beam profiles: "tophat" (uniform over the cone) and "gaussian" (TEM00, 1/e² diameter =
#: the divergence).
PROFILES = ("tophat", "gaussian")


def _ring_counts(n_subrays: int) -> list[int]:
    """Cells per ring, innermost first, for ``n_subrays`` cells in all (centre included)."""
    outer = n_subrays - 1
    if outer == 0:
        return []
    # the fewest rings whose hexagonal layout holds n_subrays: cells about as wide as long
    n_rings = 1
    while 1 + 3 * n_rings * (n_rings + 1) < n_subrays:
        n_rings += 1
    share = np.arange(1, n_rings + 1, dtype=np.float64)
    # one cell each, the rest in proportion to j
    ideal = 1.0 + (outer - n_rings) * share / share.sum()
    counts = np.floor(ideal).astype(np.int64)
    # largest remainders; ties go to the outer ring (it is the longest)
    left = outer - int(counts.sum())
    rank = np.lexsort((-np.arange(n_rings), -(ideal - counts)))
    counts[rank[:left]] += 1
    return [int(c) for c in counts]


def footprint_offsets(n_subrays: int, divergence_deg: float, *, profile: str = "tophat") -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The sub-rays of one pulse: angular offsets from its axis and their energy weights.

    Parameters
    ----------
    n_subrays : int
        K, from 1 to :data:`MAX_SUBRAYS`.  1: the centre ray alone, weight 1.
    divergence_deg : float
        Full-angle beam divergence, degrees in [0, 90]; > 0 when K > 1.
    profile : {"tophat", "gaussian"}
        Energy across the cone.  "tophat" (default): uniform, every cell ``1/K``: the profile
        today's 7-ray footprint and its detection threshold assume, and the one a data sheet's
        bare "divergence" figure implies when it names no profile.  "gaussian": a TEM00 beam
        whose 1/e² diameter is the divergence; each cell gets the energy of that Gaussian over
        it, renormalised over the cone (which holds ``1 - e⁻² ≈ 86 %`` of the beam), so the
        centre cell weighs most.  The cells stay the same; only the weights change.

    Returns
    -------
    offsets : (K, 2) float64
        Per sub-ray: angle off the beam axis, radians in ``[0, divergence/2)``; azimuth about
        the axis, radians from the local ``u`` axis towards ``v`` (:func:`subray_directions`).
        Row 0 is the centre ray ``(0, 0)``; rings follow, innermost first (module docstring).
    weights : (K,) float64
        Share of the pulse's energy in each sub-ray's cell, summing to 1 (to rounding).

    Raises
    ------
    InvalidInputError
        ``n_subrays`` not an integer from 1 to :data:`MAX_SUBRAYS`; ``divergence_deg`` not a
        finite number in [0, 90], or 0 with more than one sub-ray; an unknown ``profile``.
    """
    k = count(n_subrays, "n_subrays", low=1, high=MAX_SUBRAYS)
    divergence = real(divergence_deg, "divergence_deg", low=0.0, high=MAX_DIVERGENCE_DEG)
    text(profile, "profile", choices=PROFILES)
    if k > 1 and divergence == 0.0:
        raise InvalidInputError(f"n_subrays {k} needs divergence_deg > 0 (the sub-rays would all be the centre ray)")
    radius = [0.0]
    azimuth = [np.zeros(1)]
    bounds = [1]  # cells inside each ring's outer radius, centre first
    for j, n in enumerate(_ring_counts(k), start=1):
        inner, outer = bounds[-1], bounds[-1] + n
        bounds.append(outer)
        # for K = 7 these are the float steps radians(div) / 2 · sqrt(4/7) of the 7-ray layout
        mid = math.sqrt((inner + outer) / (2.0 * k))
        radius += [math.radians(divergence) / 2.0 * mid] * n
        azimuth.append(np.radians((np.arange(n) + 0.5 * (j - 1)) * (360.0 / n)))
    offsets = np.column_stack([np.array(radius), np.concatenate(azimuth)])
    if profile == "tophat":
        return offsets, np.full(k, 1.0 / k)
    # the energy of exp(-2ρ²) (ρ in half-divergences) within each ring's outer edge,
    # ρ² = c_j / K, is 1 - exp(-2ρ²); a ring's share is the difference, split among its cells
    cells = np.diff(bounds, prepend=0)
    inside = -np.expm1(-2.0 * np.array(bounds, dtype=np.float64) / k)
    weights = np.repeat(np.diff(inside, prepend=0.0) / cells, cells)
    # renormalised over the cone, which holds 1 - e⁻² of the beam
    return offsets, weights / weights.sum()


def _finite(value: ArrayLike, name: str, shape: str, n_min: int) -> NDArray[np.float64]:
    """``value`` as a finite float64 array of ``shape`` ("(N, 3)") with at least ``n_min`` rows."""
    columns = int(shape[-2])
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.full((0, 0), np.nan)
    if a.ndim != 2 or a.shape[1] != columns or len(a) < n_min or not np.all(np.isfinite(a)):
        raise InvalidInputError(f"{name} must be a finite {shape} number array, got {type(value).__name__} of shape {np.shape(a)}")
    return a


def subray_directions(directions: ArrayLike, offsets: ArrayLike) -> NDArray[np.float64]:
    """(N, K, 3) float64: the K sub-rays of each beam, unit vectors in the frame of ``directions``.

    Parameters
    ----------
    directions : (N, 3) float
        Unit beam axes (any frame; the sub-rays come out in it).
    offsets : (K, 2) float
        Angle off the axis and azimuth about it, radians (:func:`footprint_offsets`).

    Returns
    -------
    (N, K, 3) float64
        Sub-ray ``k`` of beam ``n`` is ``normalise(d + tan(θ_k) (cos φ_k u + sin φ_k v))`` with
        ``u = normalise(d × h)``, ``v = d × u`` and ``h`` the z axis, or the x axis where
        ``|d_z| ≥ 0.9`` (:meth:`Beam.footprint_directions
        <zbuf_occlude.sensors.beam.fields.Beam.footprint_directions>` casts a beam's sub-rays with it).
        A sub-ray at angle 0 is ``d`` itself, unnormalised.

    Raises
    ------
    InvalidInputError
        ``directions`` not (N, 3) or ``offsets`` not (K, 2) with K ≥ 1, or not finite.
    """
    d = _finite(directions, "directions", "(N, 3)", 0)
    off = _finite(offsets, "offsets", "(K, 2)", 1)
    out = np.empty((len(d), len(off), 3))
    centre = off[:, 0] == 0.0
    for k in np.flatnonzero(centre):  # one strided copy each (a boolean mask's assignment is several times slower)
        out[:, k] = d
    ring = np.flatnonzero(~centre)
    if ring.size == 0:
        return out
    # One coordinate at a time, on contiguous (N,) and (R, N) arrays: the products, sums and
    # the norm's ((x² + y²) + z²) of np.cross and np.linalg.norm over (N, 3) rows, in their
    # order, so the same bits, without their (N, R, 3) temporaries.
    dx, dy, dz = (np.ascontiguousarray(d[:, i]) for i in range(3))
    u, v = _axes(dx, dy, dz)
    # math.tan, one value per offset (numpy's tan may differ in the last bit)
    tan = np.array([math.tan(theta) for theta in off[ring, 0]])[:, None]
    # a contiguous copy (numpy's cos and sin take other paths over strided views)
    phi = off[ring, 1]
    cos, sin = np.cos(phi)[:, None], np.sin(phi)[:, None]
    # (3, R, N): the beams along the contiguous inner axis, so each operation is one long loop;
    # dc + tan · (cos · uc + sin · vc) and its norm, in place in two buffers (fresh temporaries
    # of this size cost more in page faults than in arithmetic)
    rays = np.empty((3, len(ring), len(d)))
    tmp = np.empty((len(ring), len(d)))
    for ray, dc, uc, vc in zip(rays, (dx, dy, dz), u, v):
        np.multiply(cos, uc, out=ray)
        np.multiply(sin, vc, out=tmp)
        ray += tmp
        np.multiply(tan, ray, out=ray)
        np.add(dc, ray, out=ray)
    norm = np.multiply(rays[0], rays[0])
    for ray in rays[1:]:
        norm += np.multiply(ray, ray, out=tmp)
    rays /= np.sqrt(norm, out=norm)
    # one strided copy into the (N, K, 3) rows, through a slice where the ring's sub-rays follow each other
    contiguous = ring[-1] - ring[0] + 1 == len(ring)
    out[:, slice(ring[0], ring[-1] + 1) if contiguous else ring, :] = rays.transpose(2, 1, 0)
    return out


def plane_subrays(range_m: ArrayLike, directions: ArrayLike, normal: ArrayLike, offsets: ArrayLike) -> tuple[NDArray[np.float64], ...]:
    """``(range, cos)`` (N, K) float64: where the K sub-rays of each beam meet the plane its axis meets.

    Sub-ray ``k`` of :func:`subray_directions`, ``d_k = (d + tan θ_k (cos φ_k u + sin φ_k v)) /
    sqrt(1 + tan² θ_k)`` (``u ⊥ v ⊥ d`` unit), meets the plane of unit normal ``n`` that the axis
    ``d`` meets at range ``t`` at range ``t (n · d) / (n · d_k)``, at incidence ``|n · d_k|``; a
    sub-ray parallel to the plane gives inf or nan, one meeting it behind the origin a negative
    range.  Computed from ``n · d``, ``n · u`` and ``n · v``, without the sub-rays themselves
    (:func:`~zbuf_occlude.sensors.beam.adaptive_kernel.plane_subray`, compiled).

    Parameters
    ----------
    range_m : (N,) float
        Range of each axis's hit on its plane, metres.
    directions : (N, 3) float
        Unit beam axes.
    normal : (N, 3) float
        Unit normal of each plane (either side).
    offsets : (K, 2) float
        Angle off the axis and azimuth about it, radians (:func:`footprint_offsets`).

    Raises
    ------
    InvalidInputError
        ``directions`` or ``normal`` not finite (N, 3), ``offsets`` not finite (K, 2).
    """
    d = _finite(directions, "directions", "(N, 3)", 0)
    n = _finite(normal, "normal", "(N, 3)", 0)
    off = _finite(offsets, "offsets", "(K, 2)", 1)
    t = np.asarray(range_m, dtype=np.float64)
    if t.shape != (len(d),) or len(n) != len(d):
        raise InvalidInputError(f"range_m, directions and normal need one row per beam, got {t.shape}, {d.shape}, {n.shape}")
    from zbuf_occlude.sensors.beam.adaptive_kernel import plane_subray_rows, subray_trig  # numba: imported when used

    return plane_subray_rows(t, np.ascontiguousarray(d), np.ascontiguousarray(n), *subray_trig(off))


def _axes(dx: NDArray[np.float64], dy: NDArray[np.float64], dz: NDArray[np.float64]) -> tuple[tuple[NDArray[np.float64], ...], ...]:
    """The unit axes across beam axes ``d`` (components ``dx``, ``dy``, ``dz``) that sub-rays turn about,
    one coordinate at a time, ``((ux, uy, uz), (vx, vy, vz))``: ``u = normalise(d × h)``, ``v = d × u``,
    ``h`` the z axis or, where ``|d_z| ≥ 0.9``, the x axis."""
    near_pole = np.abs(dz) >= 0.9
    # helper h: z, or x near the poles; u = d × h (the products by h's zeros kept, for their signs)
    hx, hz = near_pole.astype(np.float64), (~near_pole).astype(np.float64)
    hy = np.zeros(len(dx))
    u = _unit(dy * hz - dz * hy, dz * hx - dx * hz, dx * hy - dy * hx)
    v = (dy * u[2] - dz * u[1], dz * u[0] - dx * u[2], dx * u[1] - dy * u[0])
    return u, v


def _unit(x: NDArray[np.float64], y: NDArray[np.float64], z: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
    """The vectors of components ``x``, ``y``, ``z`` (arrays of one shape) over their norm,
    ``sqrt((x² + y²) + z²)``: np.linalg.norm's sum over a last axis of 3, so the same bits."""
    norm = np.sqrt((x * x + y * y) + z * z)
    return x / norm, y / norm, z / norm
