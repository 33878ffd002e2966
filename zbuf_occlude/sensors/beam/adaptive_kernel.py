"""The adaptive footprint's compiled loops: its test and plane echo in one pass a pulse, and the pulses' neighbours across lines.

:func:`uniform_plane_echoes` decides, pulse by pulse, whether a footprint is *uniform* (the rules
of :mod:`zbuf_occlude.sensors.beam.adaptive_cast`'s docstring: its centre face does not transmit, its neighbours lie
on that face's plane, every sub-ray meets the plane inside the face, one echo, within the range
limits) and gives a uniform hit's one echo on that plane, without ``(P, K)`` temporaries.  Each
sub-ray's range and incidence on the plane (:func:`plane_subray`) and the plane's echo
(:func:`plane_echo`) are the one implementation: :func:`~zbuf_occlude.sensors.beam.footprint.plane_subrays` and
:func:`~zbuf_occlude.sensors.beam.adaptive_cast.plane_echoes` loop over them for whole arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError

__all__ = [
    "UniformRules", "nearest_in_line", "plane_echo", "plane_echo_rows", "plane_subray", "plane_subray_rows", "subray_axes", "subray_trig",
    "uniform_plane_echoes",
]  # fmt: skip


def _subray_axes(dx, dy, dz):
    # footprint._axes for one axis d: u = normalise(d × h), v = d × u, h = z or, where |d_z| ≥ 0.9, x
    near_pole = abs(dz) >= 0.9
    hx = 1.0 if near_pole else 0.0
    hz = 0.0 if near_pole else 1.0
    hy = 0.0
    x, y, z = dy * hz - dz * hy, dz * hx - dx * hz, dx * hy - dy * hx
    norm = math.sqrt((x * x + y * y) + z * z)
    ux, uy, uz = x / norm, y / norm, z / norm
    return ux, uy, uz, dy * uz - dz * uy, dz * ux - dx * uz, dx * uy - dy * ux


def _plane_subray(t, nd, nu, nv, tan, cos_phi, sin_phi, root):
    # footprint.plane_subrays for one sub-ray: range and |cos| where it meets the plane the axis meets at t
    ndk = (nd + tan * (cos_phi * nu + sin_phi * nv)) / root
    return t * (nd / ndk), abs(ndk)


#: ``subray_axes(dx, dy, dz) -> (ux, uy, uz, vx, vy, vz)``: the axes a beam's sub-rays turn about (:func:`~zbuf_occlude.sensors.beam.footprint.subray_directions`).
subray_axes = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(_subray_axes)
#: ``plane_subray(t, n·d, n·u, n·v, tan θ, cos φ, sin φ, sqrt(1 + tan² θ)) -> (range, |cos|)`` of one sub-ray.
plane_subray = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(_plane_subray)


def _plane_echo(ranges, cosines, weights, min_range):
    # the one echo of K sub-ray hits on one plane: Σ E_k, Σ E_k t_k / Σ E_k, E_k = |cos_k| w_k / max(t_k, MIN_RANGE_M)²:
    # the range equation of echoes.hit_energy (Kashani et al. 2015, Eq. 4) with ρ = 1, as numba compiles it
    total, moment = 0.0, 0.0
    for k in range(len(ranges)):
        r = max(ranges[k], min_range)
        e = cosines[k] * weights[k] / r**2
        total += e
        moment += e * ranges[k]
    return moment / total, total


#: ``plane_echo(ranges (K,), cosines (K,), weights (K,), min_range) -> (range, energy)``: one pulse's echo on a plane, ρ = 1.
plane_echo = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(_plane_echo)


def subray_trig(offsets: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
    """``(tan θ, cos φ, sin φ, sqrt(1 + tan² θ))`` (K,) float64 of the sub-rays ``offsets (K, 2)`` (angle off the axis,
    azimuth; radians): what :func:`plane_subray` takes, as :func:`~zbuf_occlude.sensors.beam.footprint.plane_subrays` computed them."""
    tan = np.array([math.tan(theta) for theta in offsets[:, 0]])
    phi = np.ascontiguousarray(offsets[:, 1])
    return tan, np.cos(phi), np.sin(phi), np.sqrt(1.0 + tan * tan)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def plane_subray_rows(t, directions, normal, tan, cos_phi, sin_phi, root):
    """``(range, cos)`` (N, K): :func:`plane_subray` of every sub-ray of every beam (:func:`~zbuf_occlude.sensors.beam.footprint.plane_subrays`'s loop)."""
    n, n_sub = len(t), len(tan)
    ranges, cosines = np.empty((n, n_sub)), np.empty((n, n_sub))
    for i in range(n):
        dx, dy, dz = directions[i, 0], directions[i, 1], directions[i, 2]
        ux, uy, uz, vx, vy, vz = subray_axes(dx, dy, dz)
        nx, ny, nz = normal[i, 0], normal[i, 1], normal[i, 2]
        nd, nu, nv = nx * dx + ny * dy + nz * dz, nx * ux + ny * uy + nz * uz, nx * vx + ny * vy + nz * vz
        for k in range(n_sub):
            ranges[i, k], cosines[i, k] = plane_subray(t[i], nd, nu, nv, tan[k], cos_phi[k], sin_phi[k], root[k])
    return ranges, cosines


@numba.njit(cache=True, nogil=True, error_model="numpy")
def plane_echo_rows(ranges, cosines, weights, min_range):
    """``(range, energy)`` (P,): :func:`plane_echo` of every row (:func:`~zbuf_occlude.sensors.beam.adaptive_cast.plane_echoes`' loop)."""
    n = len(ranges)
    echo_range, energy = np.empty(n), np.empty(n)
    for p in range(n):
        echo_range[p], energy[p] = plane_echo(ranges[p], cosines[p], weights, min_range)
    return echo_range, energy


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _inside_cone(origin, direction, point, other_direction, hit, cos_max):
    """Whether a neighbouring pulse lies inside the cone of a pulse's sub-rays (half-angle ``arccos(cos_max)``):
    its hit ``point`` seen from the pulse's ``origin``, or where it hit nothing its direction."""
    if hit:
        vx, vy, vz = point[0] - origin[0], point[1] - origin[1], point[2] - origin[2]
        norm = math.sqrt(vx * vx + vy * vy + vz * vz)
        if norm == 0.0:
            return True
        return (vx * direction[0] + vy * direction[1] + vz * direction[2]) / norm > cos_max
    return direction[0] * other_direction[0] + direction[1] * other_direction[1] + direction[2] * other_direction[2] > cos_max


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _uniform_plane_echoes(origins, directions, face, t, neighbours, planes, face_object, transmits, tan, cos_phi, sin_phi, root,
                          weights, theta_max, resolution, low, high, margin, tolerance, min_range):  # fmt: skip
    n_pulses, n_sub = len(face), len(tan)
    one_origin = len(origins) == 1
    point = np.empty((n_pulses, 3))
    for p in range(n_pulses):
        o = 0 if one_origin else p
        s = t[p] if face[p] >= 0 else 0.0
        for i in range(3):
            point[p, i] = origins[o, i] + directions[p, i] * s
    uniform = np.zeros(n_pulses, np.bool_)
    on_plane = np.zeros(n_pulses, np.bool_)
    echo_range = np.full(n_pulses, np.nan)
    energy = np.full(n_pulses, np.nan)
    ranges, cosines, order = np.empty(n_sub), np.empty(n_sub), np.empty(n_sub)
    cos_max = math.cos(theta_max)
    for p in range(n_pulses):
        hit = face[p] >= 0
        f = face[p] if hit else 0
        ok = hit and not transmits[f]
        miss = not hit
        known_any = False
        enclosed = True
        obj = face_object[f]
        plane = planes[f]  # (4, 4): the face's plane, then its edge lines
        for j in range(neighbours.shape[1]):
            q = neighbours[p, j]
            if q < 0:
                continue
            known_any = True
            q_hit = face[q] >= 0
            if _inside_cone(origins[0 if one_origin else p], directions[p], point[q], directions[q], q_hit, cos_max):
                enclosed = False  # the footprint reaches past this neighbour: cast in full, whatever the others show
                break
            if ok:
                if not q_hit or face_object[face[q] if q_hit else 0] != obj:
                    ok = False
                else:
                    off = abs(plane[0, 0] * point[q, 0] + plane[0, 1] * point[q, 1] + plane[0, 2] * point[q, 2] + plane[0, 3])
                    ok = off <= tolerance
            if q_hit:
                miss = False
        if not known_any or not enclosed:
            continue
        if miss:
            uniform[p] = True
            continue
        if not ok:
            continue
        # the sub-rays on the centre face's plane: inside the face, one echo, within the range limits
        dx, dy, dz = directions[p, 0], directions[p, 1], directions[p, 2]
        ux, uy, uz, vx, vy, vz = subray_axes(dx, dy, dz)
        nx, ny, nz = plane[0, 0], plane[0, 1], plane[0, 2]
        nd, nu, nv = nx * dx + ny * dy + nz * dz, nx * ux + ny * uy + nz * uz, nx * vx + ny * vy + nz * vz
        tc = t[p]
        spread = 0.0
        finite = True
        for k in range(n_sub):
            ranges[k], cosines[k] = plane_subray(tc, nd, nu, nv, tan[k], cos_phi[k], sin_phi[k], root[k])
            if not math.isfinite(ranges[k]):
                finite = False
            spread = max(spread, abs(ranges[k] - tc))
        if not finite:
            continue  # a sub-ray along the plane, or never meeting it
        inside = np.inf
        for e in range(1, 4):
            inside = min(inside, plane[e, 0] * point[p, 0] + plane[e, 1] * point[p, 1] + plane[e, 2] * point[p, 2] + plane[e, 3])
        if not inside >= spread + tc * theta_max + margin:
            continue
        nearest, farthest = ranges.min(), ranges.max()
        if not (nearest >= max(low, 0.0) and farthest <= high):
            continue
        if not farthest - nearest < resolution:  # else every step between sorted ranges is below the resolution
            for k in range(n_sub):  # insertion sort in place: a few sub-rays, no allocation
                order[k] = ranges[k]
                j = k
                while j > 0 and order[j - 1] > order[j]:
                    order[j - 1], order[j] = order[j], order[j - 1]
                    j -= 1
            one_echo = True
            for k in range(1, n_sub):
                if not order[k] - order[k - 1] < resolution:
                    one_echo = False
            if not one_echo:
                continue
        uniform[p] = True
        on_plane[p] = True
        echo_range[p], energy[p] = plane_echo(ranges, cosines, weights, min_range)
    return uniform, on_plane, echo_range, energy


@numba.njit(cache=True, nogil=True, error_model="numpy")
def nearest_in_line(key, position, line, order, width, low, step, column, out):
    """Write into ``out[:, column]`` each pulse's nearest pulse by position on line ``line + step``: the loop of
    :func:`~zbuf_occlude.sensors.beam.adaptive_cast.grid_neighbours` over pulses sorted by ``key = line · width + (position − low)``
    (``order`` their rows), the first key at or after each target (``np.searchsorted``'s side left), ties to the
    lower position.  Along a line the targets rise with the positions, so the search walks on from the last one;
    it searches by halves where a line starts."""
    n = len(key)
    lo = 0
    for i in range(n):
        target = (line[i] + step) * width + (position[i] - low)
        if i == 0 or line[i] != line[i - 1]:
            lo, hi = 0, n
            while lo < hi:  # the first key >= target
                mid = (lo + hi) >> 1
                if key[mid] < target:
                    lo = mid + 1
                else:
                    hi = mid
        else:
            while lo < n and key[lo] < target:  # the targets of a line rise: the first key >= target lies ahead
                lo += 1
        left, right = min(max(lo - 1, 0), n - 1), min(lo, n - 1)
        ok_left, ok_right = line[left] == line[i] + step, line[right] == line[i] + step
        if ok_left and (not ok_right or abs(position[left] - position[i]) <= abs(position[right] - position[i])):
            out[order[i], column] = order[left]
        elif ok_right:
            out[order[i], column] = order[right]


@dataclass(frozen=True)
class UniformRules:
    """What :func:`uniform_plane_echoes` holds a footprint to.

    Attributes
    ----------
    range_resolution_m : float
        The receiver's range resolution, metres: a uniform footprint's ranges step less than it.
    range_limits_m : (float, float)
        The beam's range limits, metres: a uniform footprint's ranges lie within them.
    margin_m : float
        How far inside its face a uniform footprint stays beyond the cone's reach, metres.
    tolerance_m : float
        A neighbour's hit lies on the centre face's plane within this distance, metres.
    min_range_m : float
        Ranges below it count as it in the energy (``echoes.MIN_RANGE_M``).
    """

    range_resolution_m: float
    range_limits_m: tuple[float, float]
    margin_m: float
    tolerance_m: float
    min_range_m: float


def _check(origins, directions, face, t, neighbours, planes, face_object, transmits, offsets, weights) -> None:
    """Refuse what would make the compiled loop read outside its arrays."""
    n, n_faces = len(face), len(face_object)
    problems = [
        (origins.ndim != 2 or origins.shape[1] != 3 or len(origins) not in (1, n), f"origins {origins.shape} (1 or P rows of 3)"),
        (directions.shape != (n, 3), f"directions {directions.shape} (P, 3)"),
        (face.shape != (n,) or t.shape != (n,), f"face {face.shape} and t {t.shape} (P,)"),
        (neighbours.ndim != 2 or len(neighbours) != n, f"neighbours {neighbours.shape} (P, m)"),
        (planes.shape != (n_faces, 4, 4) or transmits.shape != (n_faces,), f"planes {planes.shape} (F, 4, 4), transmits {transmits.shape} (F,)"),
        (offsets.ndim != 2 or offsets.shape[1] != 2 or len(offsets) == 0 or weights.shape != (len(offsets),),
         f"offsets {offsets.shape} (K, 2), weights {weights.shape} (K,)"),
        (bool(n) and (face.min() < -1 or face.max() >= n_faces), f"face indices outside -1..{n_faces - 1}"),
        (bool(neighbours.size) and (neighbours.min() < -1 or neighbours.max() >= n), f"neighbour indices outside -1..{n - 1}"),
    ]  # fmt: skip
    bad = [text for wrong, text in problems if wrong]
    if bad:
        raise InvalidInputError(f"uniform_plane_echoes got {'; '.join(bad)}")


def uniform_plane_echoes(
    origins: NDArray[np.float64],
    directions: NDArray[np.float64],
    face: NDArray[np.int64],
    t: NDArray[np.float64],
    neighbours: NDArray[np.int64],
    planes: NDArray[np.float64],
    face_object: NDArray[np.int64],
    transmits: NDArray[np.bool_],
    offsets: NDArray[np.float64],
    weights: NDArray[np.float64],
    rules: UniformRules,
) -> tuple[NDArray[np.bool_], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """The uniform footprints, and the plane echo of those that hit (rules: :mod:`zbuf_occlude.sensors.beam.adaptive_cast`).

    Parameters
    ----------
    origins : (1, 3) or (P, 3) float64
        Where the pulses leave, world frame, metres.
    directions : (P, 3) float64
        Unit centre directions.
    face, t : (P,) int64, (P,) float64
        The centre rays' first hits: face (−1 for none) and range, metres.
    neighbours : (P, m) int64
        Rows of each pulse's neighbours, −1 for none.
    planes : (F, 4, 4) float64
        Each face's plane and edge lines (``adaptive_footprint._face_planes``).
    face_object : (F,) int64
        The object of each face.
    transmits : (F,) bool
        Faces a sub-ray goes on through.
    offsets : (K, 2) float64
        The footprint's sub-rays: angle off the axis and azimuth, radians.
    weights : (K,) float64
        Each sub-ray's share of the pulse's energy.
    rules : UniformRules
        The receiver's range resolution and limits, and the test's margins.

    Returns
    -------
    uniform : (P,) bool
        The pulses whose sub-rays need no cast.
    rows : (U,) int64
        The uniform pulses that hit, ascending.
    echo_range, energy : (U,) float64
        Their echo's range, metres, and energy for ρ = 1 (:func:`~zbuf_occlude.sensors.beam.adaptive_cast.plane_echoes`).

    Raises
    ------
    InvalidInputError
        Arrays of other shapes or lengths, or a face or neighbour index outside its array (the
        compiled loop does not check its indices).
    """
    origins = np.ascontiguousarray(np.atleast_2d(origins), dtype=np.float64)
    directions, face, t = (np.ascontiguousarray(directions, dtype=np.float64), np.ascontiguousarray(face, dtype=np.int64),
                           np.ascontiguousarray(t, dtype=np.float64))  # fmt: skip
    neighbours, planes = np.ascontiguousarray(neighbours, dtype=np.int64), np.ascontiguousarray(planes, dtype=np.float64)
    face_object, transmits = np.ascontiguousarray(face_object, dtype=np.int64), np.ascontiguousarray(transmits, dtype=np.bool_)
    off, weights = np.asarray(offsets, dtype=np.float64), np.ascontiguousarray(weights, dtype=np.float64)
    _check(origins, directions, face, t, neighbours, planes, face_object, transmits, off, weights)
    tan, cos_phi, sin_phi, root = subray_trig(off)
    low, high = (float(v) for v in rules.range_limits_m)
    uniform, plane, echo_range, energy = _uniform_plane_echoes(
        origins, directions, face, t, neighbours, planes, face_object, transmits, tan, cos_phi, sin_phi, root, weights,
        float(np.max(off[:, 0])), float(rules.range_resolution_m), low, high, float(rules.margin_m), float(rules.tolerance_m),
        float(rules.min_range_m),
    )  # fmt: skip
    rows = np.flatnonzero(plane)
    return uniform, rows, echo_range[rows], energy[rows]
