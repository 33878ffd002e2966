"""The view-independent part of point-only visibility, fast: one neighbour search gives each point
its spacing and the neighbourhoods of its normal, and numba kernels fit the planes and make the
robust choice of :func:`~zbuf_occlude.geometry.normals.robust_normals`.

:func:`~zbuf_occlude.geometry.normals.robust_normals` states the method in numpy and stays the
reference: :func:`surfel_geometry` gives the same normals (up to sign; the same neighbourhood is
chosen wherever two candidates' scores are not within rounding of each other, and a closed-form
3 x 3 eigensolver stands in for LAPACK's), which tests/visibility/test_point_preparation.py holds
on the shipped meshes.  The neighbours come from a uniform grid (:func:`nearest_neighbours`:
exactly ``cKDTree.query``'s, 1.5-2x faster on surface samples) searched in the points' Morton
order; the work is split over threads (the kernels release the GIL) from
:data:`_POINTS_PER_THREAD` points a thread.

Where the time went at 100,000 points (chair_0001, one process, load 10-12 on 2 cores): the numpy
path spent 37 % in two single-threaded k-d tree queries, 39 % in the plane fits (covariances and
``np.linalg.eigh`` over ``(n, 3, 3)`` stacks at three sizes) and the rest gathering
neighbourhoods and candidates; here about 60 % is the neighbour search, 20 % the plane fits,
10 % the choice and 4 % the Morton order.
"""

from __future__ import annotations

import math
import os

import numba
import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.geometry.normals import (
    ROBUST_NORMAL_SCALES,
    ROBUST_PLANE_TOLERANCE,
    ROBUST_SHIFT_PENALTY,
    ROBUST_SPACING_NEIGHBOUR,
)

__all__ = ["plane_fits", "robust_choice", "surfel_geometry"]

#: Jacobi sweeps at most per 3 x 3 plane fit; it converges in 4-6 (quadratically).
_MAX_SWEEPS = 30
#: The closed form's eigenvector errs by about 1e-16 / gap (radians), the gap between the two
#: smallest eigenvalues as a share of the spread; below 1e-6 of it Jacobi's rotations take over.
_CLOSED_FORM_GAP = 1e-6
#: Points per grid cell :func:`nearest_neighbours` aims at: 14 neighbours then lie within the
#: cell's ring of 26 on a surface (4 and 12 were slower on the shipped meshes at 10,000 and
#: 100,000 points).
_POINTS_PER_CELL = 8.0
#: A cell holding more points than this (duplicates, a dense knot): the k-d tree instead.
_MAX_CELL_POINTS = 2_048
#: Points per thread at least: 2,048 to 100,000 points prepared no faster on 2 threads than on one
#: at load 12 on 2 cores (starting the threads costs more than it saves while the cores are busy).
_POINTS_PER_THREAD = 50_000


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


@numba.njit(cache=True, nogil=True)
def _jacobi_smallest(a, v, out):  # pragma: no cover - numba
    """Writes into ``out`` the unit eigenvector of the smallest eigenvalue of the symmetric 3 x 3
    ``a`` (overwritten: its eigenvalues end on the diagonal) by cyclic Jacobi rotations; returns
    that eigenvalue's share of the trace (0 when the trace is not positive)."""
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
    big = max(abs(a[0, 0]), abs(a[1, 1]), abs(a[2, 2]), abs(a[0, 1]), abs(a[0, 2]), abs(a[1, 2]))
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
    total = 3.0 * q
    return low / total if total > 0.0 else 0.0


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
            mx = my = mz = 0.0
            for m in range(k):
                j = neighbours[i, m]
                mx += points[j, 0]
                my += points[j, 1]
                mz += points[j, 2]
            mx /= k
            my /= k
            mz /= k
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
def robust_choice(points, neighbours, spacing, normals, variation, centres, middle, tolerance, penalty, first, last, out):  # pragma: no cover - numba
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
    first, last : int
        The points chosen for: ``first`` to ``last - 1``.
    out : (n, 3) float64
        Written: the normals.
    """
    count = normals.shape[0]
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


def surfel_geometry(
    points: NDArray[np.float64], neighbours: int, *, estimate_normals: bool, workers: int = -1
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None, NDArray[np.int64]]:
    """Each point's spacing and, when asked, its robust normal, from one neighbour search.

    The points are searched and fitted in their Morton order
    (:func:`~zbuf_occlude.geometry.grouping.morton_order`), neighbours in space being neighbours
    in memory, and the results put back in the order given.

    Parameters
    ----------
    points : (n, 3) float64
        At least 2 points, finite (checked by the caller).
    neighbours : int
        The k of the spacing (the distance to the k-th nearest neighbour, itself not counted).
    estimate_normals : bool
        Also the normals of :func:`~zbuf_occlude.geometry.normals.robust_normals` at its defaults.
    workers : int
        Threads (-1: every core the process may use, from :data:`_POINTS_PER_THREAD` points a
        thread).

    Returns
    -------
    spacing : (n,) float64
    normals : (n, 3) float64 or None
        Unit, of arbitrary sign; None unless ``estimate_normals``.
    order : (n,) int64
        The Morton order of ``points`` (:attr:`~zbuf_occlude.visibility.point_splats.PointSurfels.order`).
    """
    from zbuf_occlude.geometry.grouping import morton_order

    n = len(points)
    order = morton_order(points)
    ordered = np.ascontiguousarray(points[order])
    k = min(neighbours, n - 1) + 1
    sizes = sorted({min(int(s), n) for s in ROBUST_NORMAL_SCALES if min(int(s), n) >= 3}) if estimate_normals else []
    query = max([k, *sizes])
    grid = _grid(ordered)
    if grid is None:
        distance, idx = _tree_neighbours(ordered, query, workers)
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

    threads = _threads(n, workers)
    _in_threads(neighbourhoods, n, threads)
    spacing = np.empty(n)
    spacing[order] = distance[:, k - 1]
    if not estimate_normals:
        return spacing, None, order
    normals = np.empty((n, 3))
    if not sizes:
        normals[:] = (0.0, 0.0, 1.0)
        return spacing, normals, order
    scales = ROBUST_NORMAL_SCALES
    centres = min(scales[1] if len(scales) > 1 else sizes[0], sizes[-1])
    own_spacing = np.ascontiguousarray(distance[:, min(ROBUST_SPACING_NEIGHBOUR, sizes[-1] - 1)])
    chosen = np.empty((n, 3))

    def choose(first: int, last: int) -> None:
        robust_choice(ordered, idx, own_spacing, fits, variation, centres, len(sizes) // 2, ROBUST_PLANE_TOLERANCE,
                      ROBUST_SHIFT_PENALTY, first, last, chosen)  # fmt: skip

    _in_threads(choose, n, threads)
    normals[order] = chosen
    return spacing, normals, order


def _threads(n: int, workers: int) -> int:
    """Threads for ``n`` points: ``workers``, or with -1 every core, at least
    :data:`_POINTS_PER_THREAD` points each."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(min(cores, n // _POINTS_PER_THREAD), 1) if workers == -1 else max(int(workers), 1)


def _in_threads(work, n: int, threads: int) -> None:
    """``work(first, last)`` over ``range(n)`` split in ``threads`` parts, each in its own thread
    (the numba kernels release the GIL)."""
    bounds = np.linspace(0, n, threads + 1).astype(np.int64)
    if threads == 1:
        work(0, n)
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(work, bounds[:-1], bounds[1:]))


@numba.njit(cache=True, nogil=True)
def grid_cells(points, lo, h, dims):  # pragma: no cover - numba
    """The points bucketed into a uniform grid of cell side ``h`` from ``lo``, ``dims`` cells a
    side: ``(start, members)``, the points of cell ``c`` being ``members[start[c]:start[c + 1]]``
    (ascending; cell ``c = (cx·dims[1] + cy)·dims[2] + cz``)."""
    n = points.shape[0]
    cells = dims[0] * dims[1] * dims[2]
    cell = np.empty(n, np.int64)
    start = np.zeros(cells + 1, np.int64)
    for i in range(n):
        c = 0
        for d in range(3):
            q = int((points[i, d] - lo[d]) / h)
            c = c * dims[d] + min(max(q, 0), dims[d] - 1)
        cell[i] = c
        start[c + 1] += 1
    for c in range(cells):
        start[c + 1] += start[c]
    cursor = start[:-1].copy()
    members = np.empty(n, np.int64)
    for i in range(n):
        members[cursor[cell[i]]] = i
        cursor[cell[i]] += 1
    return start, members


@numba.njit(cache=True, nogil=True)
def grid_neighbours(points, queries, k, lo, h, dims, start, members, distance, index):  # pragma: no cover - numba
    """The ``k`` nearest of ``points`` to each of ``queries`` (rows of ``points``), nearest first,
    into ``distance`` and ``index`` (``(len(queries), k)``): the grid's cells ring by ring around
    the query's, until the k-th distance found is within the searched block (exact: a point
    outside it lies farther than the block's nearest face)."""
    best = np.empty(k)
    at = np.empty(k, np.int64)
    margin = 1e-9 * h  # a point bucketed by rounding just outside its cell
    for row in range(queries.shape[0]):
        i = queries[row]
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        cx = min(max(int((x - lo[0]) / h), 0), dims[0] - 1)
        cy = min(max(int((y - lo[1]) / h), 0), dims[1] - 1)
        cz = min(max(int((z - lo[2]) / h), 0), dims[2] - 1)
        found = 0
        r = 0
        while True:
            for ax in range(max(cx - r, 0), min(cx + r, dims[0] - 1) + 1):
                edge_x = ax == cx - r or ax == cx + r
                for ay in range(max(cy - r, 0), min(cy + r, dims[1] - 1) + 1):
                    edge = edge_x or ay == cy - r or ay == cy + r
                    step = 1 if edge else 2 * r
                    az = cz - r
                    while az <= cz + r:
                        if 0 <= az < dims[2]:
                            c = (ax * dims[1] + ay) * dims[2] + az
                            for m in range(start[c], start[c + 1]):
                                j = members[m]
                                dx, dy, dz = points[j, 0] - x, points[j, 1] - y, points[j, 2] - z
                                d2 = dx * dx + dy * dy + dz * dz
                                if found == k and d2 >= best[k - 1]:
                                    continue
                                slot = found if found < k else k - 1
                                while slot > 0 and best[slot - 1] > d2:
                                    best[slot] = best[slot - 1]
                                    at[slot] = at[slot - 1]
                                    slot -= 1
                                best[slot] = d2
                                at[slot] = j
                                if found < k:
                                    found += 1
                        az += step
            # the searched block's nearest face; a side at the grid's edge has nothing beyond it
            reach = np.inf
            whole = True
            for d, cd, coordinate in ((0, cx, x), (1, cy, y), (2, cz, z)):
                if cd - r > 0:
                    reach = min(reach, coordinate - (lo[d] + (cd - r) * h))
                    whole = False
                if cd + r < dims[d] - 1:
                    reach = min(reach, lo[d] + (cd + r + 1) * h - coordinate)
                    whole = False
            reach -= margin
            if whole or (found == k and reach > 0.0 and best[k - 1] <= reach * reach):
                break
            r += 1
        for m in range(k):
            distance[row, m] = np.sqrt(best[m])
            index[row, m] = at[m]


def nearest_neighbours(points: NDArray[np.float64], k: int, *, workers: int = -1) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``cKDTree(points).query(points, k)`` for a cloud, from a uniform grid (:func:`_grid`): (n, k)
    distances and indices, nearest first (the point itself among them), on ``workers`` threads."""
    grid = _grid(points)
    if grid is None:
        return _tree_neighbours(points, k, workers)
    n = len(points)
    distance, index = np.empty((n, k)), np.empty((n, k), np.int64)
    rows = np.arange(n, dtype=np.int64)

    def search(first: int, last: int) -> None:
        grid_neighbours(points, rows[first:last], k, *grid, distance[first:last], index[first:last])

    _in_threads(search, n, _threads(n, workers))
    return distance, index


def _grid(points: NDArray[np.float64]) -> tuple | None:
    """``(lo, side, dims, start, members)`` of :func:`grid_neighbours`: cells of about
    :data:`_POINTS_PER_CELL` points (a surface's density measured on a first grid), at most
    4 per point; None where a cell would hold more than :data:`_MAX_CELL_POINTS` (duplicates, a
    dense knot) or the points all coincide: then the k-d tree."""
    n = len(points)
    lo = points.min(axis=0)
    extent = points.max(axis=0) - lo
    span = float(extent.max())
    if span == 0.0 or not np.isfinite(span):
        return None
    side = span / math.ceil(n ** (1 / 3))
    start, _ = grid_cells(points, lo, side, _dims(extent, side))
    per_cell = n / max(np.count_nonzero(np.diff(start)), 1)
    side *= math.sqrt(_POINTS_PER_CELL / per_cell)  # a surface's points per cell grow as its side squared
    while np.prod(_dims(extent, side).astype(np.float64)) > 4.0 * n + 64:
        side *= 1.25
    dims = _dims(extent, side)
    start, members = grid_cells(points, lo, side, dims)
    if np.diff(start).max() > _MAX_CELL_POINTS:
        return None
    return lo, side, dims, start, members


def _dims(extent: NDArray[np.float64], side: float) -> NDArray[np.int64]:
    return (np.floor(extent / side) + 1).astype(np.int64)


def _tree_neighbours(points: NDArray[np.float64], k: int, workers: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    from scipy.spatial import cKDTree

    distance, index = cKDTree(points).query(points, k=k, workers=workers)
    return distance.reshape(len(points), -1), index.reshape(len(points), -1).astype(np.int64, copy=False)
