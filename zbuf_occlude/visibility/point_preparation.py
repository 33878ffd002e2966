"""The view-independent part of point-only visibility, fast: one neighbour search gives each point
its spacing and the neighbourhoods of its normal, and numba kernels fit the planes and make the
robust choice of :func:`~zbuf_occlude.geometry.normals.robust_normals`.

:func:`~zbuf_occlude.geometry.normals.robust_normals` states the method in numpy and stays the
reference: :func:`surfel_geometry` gives the same normals (up to sign; the same neighbourhood is
chosen wherever two candidates' scores are not within rounding of each other, and a closed-form
3 x 3 eigensolver stands in for LAPACK's), which tests/visibility/test_point_preparation.py holds
on the shipped meshes: at 2,048 and 10,000 points the largest difference is 8e-7 degrees, the
median 1e-14.  The views decide near-ties between coplanar splats by rounding, so these
differences flip 534 of 771,072 point-views (0.07 %; 8 poses), as the GPU's float32 does.  The neighbours come from a uniform grid
(:mod:`zbuf_occlude.visibility.point_neighbours`: exactly ``cKDTree.query``'s, with 1.5-2x less
CPU on surface samples) searched in the points' Morton order; the work is split over threads
(the kernels release the GIL) from
:data:`~zbuf_occlude.visibility.point_neighbours.POINTS_PER_THREAD` points a thread.

Where the time went at 100,000 points (chair_0001, one process, load 10-12 on 2 cores): the numpy
path spent 37 % in two single-threaded k-d tree queries, 39 % in the plane fits (covariances and
``np.linalg.eigh`` over ``(n, 3, 3)`` stacks at three sizes) and the rest gathering
neighbourhoods and candidates; here about 60 % is the neighbour search, 20 % the plane fits,
10 % the choice and 4 % the Morton order.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.geometry.normals import (
    ROBUST_NORMAL_SCALES,
    ROBUST_PLANE_TOLERANCE,
    ROBUST_SHIFT_PENALTY,
    ROBUST_SPACING_NEIGHBOUR,
)
from zbuf_occlude.visibility.point_kernels import COPLANAR
from zbuf_occlude.visibility.point_neighbours import (
    grid_neighbours,
    run_in_threads,
    thread_count,
    tree_neighbours,
    uniform_grid,
)

__all__ = [
    "plane_fits", "robust_choice", "surfel_geometry", "thin_wall_sides",
    "THIN_WALL_NEIGHBOURS", "THIN_WALL_SPLIT", "THIN_WALL_LEAST_SHARE", "THIN_WALL_MOST_GAP",
]  # fmt: skip

#: Neighbours (the point included) in which :func:`thin_wall_sides` looks for a wall's two sheets.
THIN_WALL_NEIGHBOURS = 24
#: Least share of the neighbours' variance along the normal that the split into two sheets must
#: explain (Otsu's between-class variance over the total): 0.75 for offsets spread evenly, as on
#: one curved sheet; near 1 for two thin sheets.
THIN_WALL_SPLIT = 0.9
#: Least share of the neighbours each sheet must hold.
THIN_WALL_LEAST_SHARE = 0.25
#: Largest distance between the two sheets' mean offsets, in spacings: farther sheets are told
#: apart by depth (:data:`~zbuf_occlude.visibility.point_kernels.DEPTH_SLACK` is a quarter of one).
THIN_WALL_MOST_GAP = 1.0

#: Jacobi sweeps at most per 3 x 3 plane fit; it converges in 4-6 (quadratically).
_MAX_SWEEPS = 30
#: The closed form's eigenvector errs by about 1e-16 / gap (radians), the gap between the two
#: smallest eigenvalues as a share of the spread; below 1e-6 of it Jacobi's rotations take over.
_CLOSED_FORM_GAP = 1e-6


@numba.njit(cache=True, nogil=True, inline="always")
def _rotate(a, v, p, q):  # pragma: no cover - numba
    """One Jacobi rotation zeroing ``a[p, q]`` of the symmetric 3 x 3 ``a``, accumulated into
    ``v`` (Numerical Recipes, 3rd ed., 11.1).  False when ``a[p, q]`` is already negligible."""
    apq = a[p, q]
    if abs(apq) <= 1e-18 * np.sqrt(abs(a[p, p] * a[q, q])) or abs(apq) < 1e-300:
        a[p, q] = 0.0
        a[q, p] = 0.0
        return False
    theta = (a[q, q] - a[p, p]) / (2.0 * apq)
    if abs(theta) > 1e150:
        t = 1.0 / (2.0 * theta)
    else:
        t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
        if theta < 0.0:
            t = -t
    c = 1.0 / np.sqrt(t * t + 1.0)
    s = t * c
    a[p, p] -= t * apq
    a[q, q] += t * apq
    a[p, q] = 0.0
    a[q, p] = 0.0
    r = 3 - p - q
    arp, arq = a[r, p], a[r, q]
    a[r, p] = a[p, r] = c * arp - s * arq
    a[r, q] = a[q, r] = s * arp + c * arq
    for m in range(3):
        vp, vq = v[m, p], v[m, q]
        v[m, p] = c * vp - s * vq
        v[m, q] = s * vp + c * vq
    return True


@numba.njit(cache=True, nogil=True, inline="always")
def _largest_entry(a):  # pragma: no cover - numba
    """The largest magnitude among the symmetric 3 x 3 ``a``'s six distinct entries."""
    return max(abs(a[0, 0]), abs(a[1, 1]), abs(a[2, 2]), abs(a[0, 1]), abs(a[0, 2]), abs(a[1, 2]))


@numba.njit(cache=True, nogil=True)
def _jacobi_smallest(a, v, out):  # pragma: no cover - numba
    """Writes into ``out`` the unit eigenvector of the smallest eigenvalue of the symmetric 3 x 3
    ``a`` (overwritten: scaled by the power of two that brings its largest entry into [0.5, 1), which
    is exact and keeps every product of two entries from overflowing or underflowing, then its
    eigenvalues end on the diagonal) by cyclic Jacobi rotations; returns that eigenvalue's share of
    the trace (0 when the trace is not positive)."""
    big = _largest_entry(a)
    if big > 0.0:
        factor = math.ldexp(1.0, -math.frexp(big)[1])
        for m in range(3):
            for j in range(3):
                a[m, j] *= factor
    for m in range(3):
        for j in range(3):
            v[m, j] = 1.0 if m == j else 0.0
    for _ in range(_MAX_SWEEPS):
        turned = _rotate(a, v, 0, 1)
        turned = _rotate(a, v, 0, 2) or turned
        turned = _rotate(a, v, 1, 2) or turned
        if not turned:
            break
    low = 0
    for m in range(1, 3):
        if a[m, m] < a[low, low]:
            low = m
    for m in range(3):
        out[m] = v[m, low]
    total = a[0, 0] + a[1, 1] + a[2, 2]
    return a[low, low] / total if total > 0.0 else 0.0


@numba.njit(cache=True, nogil=True)
def _smallest_eigenvector(a, v, out):  # pragma: no cover - numba
    """:func:`_jacobi_smallest` in closed form where the smallest eigenvalue stands apart: the
    eigenvalues from the cubic's trigonometric solution (Smith 1961), the eigenvector as the
    largest cross product of two rows of ``a - λ0 I``; closer than :data:`_CLOSED_FORM_GAP` of
    the spread to the middle one (the vector is ill-conditioned there), Jacobi's rotations."""
    big = _largest_entry(a)
    if big == 0.0:  # all points at one place: LAPACK's answer for the zero matrix
        out[0], out[1], out[2] = 1.0, 0.0, 0.0
        return 0.0
    a00, a11, a22 = a[0, 0] / big, a[1, 1] / big, a[2, 2] / big
    a01, a02, a12 = a[0, 1] / big, a[0, 2] / big, a[1, 2] / big
    q = (a00 + a11 + a22) / 3.0
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)
    if p2 == 0.0:
        return _jacobi_smallest(a, v, out)
    p = np.sqrt(p2 / 6.0)
    det = b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02) + a02 * (a01 * a12 - b11 * a02)
    r = min(max(det / (2.0 * p * p * p), -1.0), 1.0)
    phi = np.arccos(r) / 3.0
    high = q + 2.0 * p * np.cos(phi)
    low = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    middle = 3.0 * q - high - low
    if middle - low < _CLOSED_FORM_GAP * (high - low):
        return _jacobi_smallest(a, v, out)
    r00, r11, r22 = a00 - low, a11 - low, a22 - low
    # the rows (r00, a01, a02), (a01, r11, a12), (a02, a12, r22) and their pairwise cross products
    x0, y0, z0 = a01 * a12 - a02 * r11, a02 * a01 - r00 * a12, r00 * r11 - a01 * a01
    x1, y1, z1 = a01 * r22 - a02 * a12, a02 * a02 - r00 * r22, r00 * a12 - a01 * a02
    x2, y2, z2 = r11 * r22 - a12 * a12, a12 * a02 - a01 * r22, a01 * a12 - r11 * a02
    n0, n1, n2 = x0 * x0 + y0 * y0 + z0 * z0, x1 * x1 + y1 * y1 + z1 * z1, x2 * x2 + y2 * y2 + z2 * z2
    if n0 >= n1 and n0 >= n2:
        scale = 1.0 / np.sqrt(n0)
        out[0], out[1], out[2] = x0 * scale, y0 * scale, z0 * scale
    elif n1 >= n2:
        scale = 1.0 / np.sqrt(n1)
        out[0], out[1], out[2] = x1 * scale, y1 * scale, z1 * scale
    else:
        scale = 1.0 / np.sqrt(n2)
        out[0], out[1], out[2] = x2 * scale, y2 * scale, z2 * scale
    # The eigenvalue again, as the Rayleigh quotient of the unit vector: the trigonometric solution
    # errs by about 1e-16 / gap of the spread (1.7e-11 of the trace at a gap of 1e-6), the quotient
    # by the square of the vector's error; a covariance has no negative eigenvalue (rounding aside).
    x, y, z = out[0], out[1], out[2]
    low = a00 * x * x + a11 * y * y + a22 * z * z + 2.0 * (a01 * x * y + a02 * x * z + a12 * y * z)
    total = 3.0 * q
    return max(low, 0.0) / total if total > 0.0 else 0.0


@numba.njit(cache=True, nogil=True, inline="always")
def _neighbourhood_mean(points, neighbours, i, k):  # pragma: no cover - numba
    """The mean of point ``i``'s first ``k`` neighbours."""
    mx = my = mz = 0.0
    for m in range(k):
        j = neighbours[i, m]
        mx += points[j, 0]
        my += points[j, 1]
        mz += points[j, 2]
    return mx / k, my / k, mz / k


@numba.njit(cache=True, nogil=True)
def plane_fits(points, neighbours, sizes, first, last, normals, variation):  # pragma: no cover - numba
    """The covariance (PCA) normal and surface variation of each point's first ``sizes[s]``
    neighbours, for each size: what :func:`~zbuf_occlude.geometry.normals.covariance_normals`
    gives, without gathering the neighbourhoods.

    Parameters
    ----------
    points : (n, 3) float64
    neighbours : (n, K) int64
        Each point's neighbours, nearest first (itself first), ``K >= max(sizes)``.
    sizes : (S,) int64
        Neighbourhood sizes, ascending, each at least 3.
    first, last : int
        The points fitted: ``first`` to ``last - 1`` (a thread's share).
    normals : (S, n, 3) float64
        Written: unit, of arbitrary sign.
    variation : (S, n) float64
        Written: ``λ0 / (λ0 + λ1 + λ2)`` (Pauly et al. 2002).
    """
    count = sizes.shape[0]
    a = np.empty((3, 3))
    v = np.empty((3, 3))
    for i in range(first, last):
        for s in range(count):
            k = sizes[s]
            mx, my, mz = _neighbourhood_mean(points, neighbours, i, k)
            xx = xy = xz = yy = yz = zz = 0.0
            for m in range(k):
                j = neighbours[i, m]
                dx = points[j, 0] - mx
                dy = points[j, 1] - my
                dz = points[j, 2] - mz
                xx += dx * dx
                xy += dx * dy
                xz += dx * dz
                yy += dy * dy
                yz += dy * dz
                zz += dz * dz
            a[0, 0], a[1, 1], a[2, 2] = xx, yy, zz
            a[0, 1] = a[1, 0] = xy
            a[0, 2] = a[2, 0] = xz
            a[1, 2] = a[2, 1] = yz
            variation[s, i] = _smallest_eigenvector(a, v, normals[s, i])


@numba.njit(cache=True, nogil=True)
def robust_choice(
    points, neighbours, spacing, normals, variation, centres, middle, tolerance, penalty, rows, out
):  # pragma: no cover - numba
    """Each point's normal: among the candidates of every size centred on its first ``centres``
    neighbours, the least ``variation`` plus ``penalty`` per spacing of shift whose plane passes
    within ``tolerance`` spacings of the point; the first such in size then neighbour order on a
    tie; none: its own at size index ``middle``.  The loop of
    :func:`~zbuf_occlude.geometry.normals.robust_normals`, point by point.

    Parameters
    ----------
    points : (n, 3) float64
    neighbours : (n, K) int64
    spacing : (n,) float64
    normals, variation : (S, n, 3), (S, n) float64
        :func:`plane_fits`.
    centres, middle : int
    tolerance, penalty : float
    rows : (first, last) int
        The points chosen for: ``first`` to ``last - 1``.
    out : (n, 3) float64
        Written: the normals.
    """
    count = normals.shape[0]
    first, last = rows
    for i in range(first, last):
        limit = tolerance * spacing[i]
        scale = max(spacing[i], 1e-300)
        best = np.inf
        bs = -1
        bc = -1
        for s in range(count):
            low = np.inf
            at = -1
            for m in range(centres):
                c = neighbours[i, m]
                ox = points[i, 0] - points[c, 0]
                oy = points[i, 1] - points[c, 1]
                oz = points[i, 2] - points[c, 2]
                off = abs(ox * normals[s, c, 0] + oy * normals[s, c, 1] + oz * normals[s, c, 2])
                if off <= limit:
                    score = variation[s, c] + penalty * np.sqrt(ox * ox + oy * oy + oz * oz) / scale
                    if score < low:
                        low = score
                        at = c
            if low < best:
                best = low
                bs = s
                bc = at
        if bs < 0:
            bs = middle
            bc = i
        for d in range(3):
            out[i, d] = normals[bs, bc, d]


@numba.njit(cache=True, nogil=True)
def thin_wall_sides(points, neighbours, size, spacing, rows, normals, sided):  # pragma: no cover - numba
    """Finds the points that lie on one side of a wall thinner than the sampling, and turns their
    normals out of the wall.

    Where a wall is thinner than the spacing, a point's neighbourhood holds both of its faces:
    along the point's normal, its neighbours' offsets from their mean fall into two sheets.  The
    split of the sorted offsets that explains the most of their variance (Otsu 1979, the
    between-class variance) is taken; it is a wall when that split explains at least
    :data:`THIN_WALL_SPLIT` of the variance, each sheet holds at least
    :data:`THIN_WALL_LEAST_SHARE` of the neighbours and the sheets' means lie more than
    :data:`~zbuf_occlude.visibility.point_kernels.COPLANAR` and at most
    :data:`THIN_WALL_MOST_GAP` spacings apart.  The point's outward normal then points away
    from the other sheet, so a view can tell the wall's near face from its far one, which
    depth cannot (the faces lie within the depth slack).

    Parameters
    ----------
    points : (n, 3) float64
    neighbours : (n, K) int64
        Each point's neighbours, nearest first (itself first), ``K >= size``.
    size : int
        Neighbours looked at (:data:`THIN_WALL_NEIGHBOURS`), at least 4.
    spacing : (n,) float64
        Each point's spacing, object units.
    rows : (first, last) int
        The points looked at: ``first`` to ``last - 1``.
    normals : (n, 3) float64
        Unit normals of either sign; a wall's point's is turned to point out of the wall.
    sided : (n,) bool
        Written: the point lies on one side of a thin wall, its normal points out of it.
    """
    first, last = rows
    offsets = np.empty(size)
    for i in range(first, last):
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        mx, my, mz = _neighbourhood_mean(points, neighbours, i, size)
        total = 0.0
        for m in range(size):  # the offsets, kept sorted (insertion: a few dozen values)
            j = neighbours[i, m]
            value = (points[j, 0] - mx) * nx + (points[j, 1] - my) * ny + (points[j, 2] - mz) * nz
            total += value
            at = m
            while at > 0 and offsets[at - 1] > value:
                offsets[at] = offsets[at - 1]
                at -= 1
            offsets[at] = value
        own = (points[i, 0] - mx) * nx + (points[i, 1] - my) * ny + (points[i, 2] - mz) * nz
        mean = total / size
        variance = 0.0
        for m in range(size):
            variance += (offsets[m] - mean) ** 2
        variance /= size
        best, at, gap = -1.0, 0, 0.0
        below = 0.0
        for m in range(1, size):
            below += offsets[m - 1]
            mu0 = below / m
            mu1 = (total - below) / (size - m)
            w0 = m / size
            between = w0 * (1.0 - w0) * (mu1 - mu0) ** 2
            if between > best:
                best, at, gap = between, m, mu1 - mu0
        share = at / size
        sided[i] = (
            variance > 0.0
            and best >= THIN_WALL_SPLIT * variance
            and THIN_WALL_LEAST_SHARE <= share <= 1.0 - THIN_WALL_LEAST_SHARE
            and COPLANAR * spacing[i] < gap <= THIN_WALL_MOST_GAP * spacing[i]
        )
        if sided[i] and own <= 0.5 * (offsets[at - 1] + offsets[at]):  # on the lower sheet
            normals[i, 0], normals[i, 1], normals[i, 2] = -nx, -ny, -nz


def surfel_geometry(
    points: NDArray[np.float64],
    neighbours: int,
    normals: NDArray[np.float64] | None = None,
    *,
    sides: bool = True,
    workers: int = -1,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_], NDArray[np.int64]]:
    """Each point's spacing, its normal (the one given, or the robust estimate) and the side of a
    thin wall it lies on, from one neighbour search.

    The points are searched and fitted in their Morton order
    (:func:`~zbuf_occlude.geometry.grouping.morton_order`), neighbours in space being neighbours
    in memory, and the results put back in the order given.

    Parameters
    ----------
    points : (n, 3) float64
        At least 2 points, finite (checked by the caller).
    neighbours : int
        The k of the spacing (the distance to the k-th nearest neighbour, itself not counted).
    normals : (n, 3) float64, optional
        Unit normals of either sign (checked by the caller).  None: each point's is estimated,
        the normals of :func:`~zbuf_occlude.geometry.normals.robust_normals` at its defaults.
    sides : bool
        Look for thin walls' sides (False: ``sided`` is all False and the normals are as given or
        estimated, as for normals oriented by the caller).
    workers : int
        Threads (-1: every core the process may use, from :data:`~zbuf_occlude.visibility.point_neighbours.POINTS_PER_THREAD` points a
        thread).

    Returns
    -------
    spacing : (n,) float64
    normals : (n, 3) float64
        Unit; of either sign, but turned out of the wall where ``sided``.
    sided : (n,) bool
        The point lies on one side of a wall thinner than the sampling (:func:`thin_wall_sides`).
    order : (n,) int64
        The Morton order of ``points`` (:attr:`~zbuf_occlude.visibility.point_splats.PointSurfels.order`).
    """
    from zbuf_occlude.geometry.grouping import morton_order

    n = len(points)
    order = morton_order(points)
    ordered = np.ascontiguousarray(points[order])
    k = min(neighbours, n - 1) + 1
    sizes = sorted({min(int(s), n) for s in ROBUST_NORMAL_SCALES if min(int(s), n) >= 3}) if normals is None else []
    wall = min(THIN_WALL_NEIGHBOURS, n) if sides else 0
    query = max([k, wall, *sizes])
    grid = uniform_grid(ordered)
    if grid is None:
        distance, idx = tree_neighbours(ordered, query, workers)
    else:
        distance, idx = np.empty((n, query)), np.empty((n, query), np.int64)
    fits, variation = np.empty((len(sizes), n, 3)), np.empty((len(sizes), n))
    rows = np.arange(n, dtype=np.int64)
    size_array = np.asarray(sizes, dtype=np.int64)

    def neighbourhoods(first: int, last: int) -> None:  # a point's fits need only its own neighbours
        if grid is not None:
            grid_neighbours(ordered, rows[first:last], query, *grid, distance[first:last], idx[first:last])
        if sizes:
            plane_fits(ordered, idx, size_array, first, last, fits, variation)

    threads = thread_count(n, workers)
    run_in_threads(neighbourhoods, n, threads)
    spacing = np.ascontiguousarray(distance[:, k - 1])
    if normals is not None:
        chosen = np.array(normals[order], dtype=np.float64)
    elif sizes:
        chosen = np.empty((n, 3))
    else:
        chosen = np.tile([0.0, 0.0, 1.0], (n, 1))
    scales = ROBUST_NORMAL_SCALES
    centres = min(scales[1] if len(scales) > 1 else sizes[0], sizes[-1]) if sizes else 0
    own_spacing = np.ascontiguousarray(distance[:, min(ROBUST_SPACING_NEIGHBOUR, sizes[-1] - 1)]) if sizes else spacing
    sided = np.zeros(n, dtype=np.bool_)

    def choose(first: int, last: int) -> None:  # a point's side needs only its own normal
        if sizes:
            robust_choice(ordered, idx, own_spacing, fits, variation, centres, len(sizes) // 2, ROBUST_PLANE_TOLERANCE,
                          ROBUST_SHIFT_PENALTY, (first, last), chosen)  # fmt: skip
        if wall >= 4:
            thin_wall_sides(ordered, idx, wall, spacing, (first, last), chosen, sided)

    if sizes or wall >= 4:
        run_in_threads(choose, n, threads)
    out_spacing, out_normals, out_sided = np.empty(n), np.empty((n, 3)), np.empty(n, dtype=np.bool_)
    out_spacing[order], out_normals[order], out_sided[order] = spacing, chosen, sided
    return out_spacing, out_normals, out_sided, order
