"""Each point's k nearest neighbours in its own cloud, exact and fast: a uniform grid searched in
numba ring by ring (:func:`nearest_neighbours`, the distances and neighbours of
``scipy.spatial.cKDTree.query``, 1.5-2x less CPU on surface samples), and the threads that share
such work (the kernels release the GIL).  Used by the preparation of point-only visibility
(:mod:`zbuf_occlude.visibility.point_preparation`)."""

from __future__ import annotations

import math
import os

import numba
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "POINTS_PER_THREAD",
    "grid_cells",
    "grid_neighbours",
    "nearest_neighbours",
    "run_in_threads",
    "thread_count",
    "tree_neighbours",
    "uniform_grid",
]

#: Points per grid cell :func:`nearest_neighbours` aims at: 14 neighbours then lie within the
#: cell's ring of 26 on a surface (4 and 12 were slower on the shipped meshes at 10,000 and
#: 100,000 points).
_POINTS_PER_CELL = 8.0
#: A cell holding more points than this (duplicates, a dense knot): the k-d tree instead.
_MAX_CELL_POINTS = 2_048
#: Points per thread at least: 2,048 to 100,000 points prepared no faster on 2 threads than on one
#: at load 12 on 2 cores (starting the threads costs more than it saves while the cores are busy).
POINTS_PER_THREAD = 50_000


def thread_count(n: int, workers: int) -> int:
    """Threads for ``n`` points: ``workers``, or with -1 every core, at least
    :data:`POINTS_PER_THREAD` points each."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(min(cores, n // POINTS_PER_THREAD), 1) if workers == -1 else max(int(workers), 1)


def run_in_threads(work, n: int, threads: int) -> None:
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


@numba.njit(cache=True, nogil=True, inline="always")
def _gap(v, low, h, margin):  # pragma: no cover - numba
    """Distance from ``v`` to the interval ``[low, low + h]`` less ``margin``, at least 0."""
    return max(low - v, v - (low + h), margin) - margin


@numba.njit(cache=True, nogil=True, inline="always")
def _box_gap2(x, y, z, lo, h, ax, ay, az, margin):  # pragma: no cover - numba
    """Squared distance from ``(x, y, z)`` to cell ``(ax, ay, az)`` less ``margin`` a side (a point
    bucketed by rounding just outside its cell): no point of the cell lies nearer."""
    gx = _gap(x, lo[0] + ax * h, h, margin)
    gy = _gap(y, lo[1] + ay * h, h, margin)
    gz = _gap(z, lo[2] + az * h, h, margin)
    return gx * gx + gy * gy + gz * gz


@numba.njit(cache=True, nogil=True)
def grid_neighbours(points, queries, k, lo, h, dims, start, members, distance, index):  # pragma: no cover - numba
    """The ``k`` nearest of ``points`` to each of ``queries`` (rows of ``points``), nearest first,
    into ``distance`` and ``index`` (``(len(queries), k)``): the grid's cells ring by ring around
    the query's, until the k-th distance found is within the searched block (exact: a point
    outside it lies farther than the block's nearest face), skipping a cell once k points nearer
    than its box are found (15-20 % less CPU at 100,000 points).  The previous query's k neighbours, k
    distinct points, bound the k-th distance of the next one (``bound``): a cell or a point farther is
    skipped from the start, which gives the same neighbours, in the same order, with fewer points
    tried (queries in Morton order lie close together)."""
    best = np.empty(k)
    at = np.empty(k, np.int64)
    margin = 1e-9 * h  # a point bucketed by rounding just outside its cell
    for row in range(queries.shape[0]):
        i = queries[row]
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        bound = np.inf  # no k-th distance beyond the previous query's k neighbours, seen from here
        if row > 0:
            bound = 0.0
            for m in range(k):
                j = at[m]
                dx, dy, dz = points[j, 0] - x, points[j, 1] - y, points[j, 2] - z
                bound = max(bound, dx * dx + dy * dy + dz * dz)
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
                        # a cell no nearer than the bound (the k-th distance once k are found) holds nothing to keep
                        if 0 <= az < dims[2] and _box_gap2(x, y, z, lo, h, ax, ay, az, margin) <= (bound if found < k else best[k - 1]):
                            c = (ax * dims[1] + ay) * dims[2] + az
                            for m in range(start[c], start[c + 1]):
                                j = members[m]
                                dx, dy, dz = points[j, 0] - x, points[j, 1] - y, points[j, 2] - z
                                d2 = dx * dx + dy * dy + dz * dz
                                if d2 > bound or (found == k and d2 >= best[k - 1]):
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
    """``cKDTree(points).query(points, k)`` for a cloud, from a uniform grid (:func:`uniform_grid`): (n, k)
    distances and indices, nearest first (the point itself among them), on ``workers`` threads."""
    grid = uniform_grid(points)
    if grid is None:
        return tree_neighbours(points, k, workers)
    n = len(points)
    distance, index = np.empty((n, k)), np.empty((n, k), np.int64)
    rows = np.arange(n, dtype=np.int64)

    def search(first: int, last: int) -> None:
        grid_neighbours(points, rows[first:last], k, *grid, distance[first:last], index[first:last])

    run_in_threads(search, n, thread_count(n, workers))
    return distance, index


def uniform_grid(points: NDArray[np.float64]) -> tuple | None:
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
    if not side > 0.0:
        return None
    start, _ = grid_cells(points, lo, side, _dims(extent, side))
    per_cell = n / max(np.count_nonzero(np.diff(start)), 1)
    side *= math.sqrt(_POINTS_PER_CELL / per_cell)  # a surface's points per cell grow as its side squared
    while np.prod(_dims(extent, side).astype(np.float64)) > 4.0 * n + 64:
        side *= 1.25
    if not (side > 0.0 and math.isfinite(side)):  # a span near the smallest float64: no grid
        return None
    dims = _dims(extent, side)
    start, members = grid_cells(points, lo, side, dims)
    if np.diff(start).max() > _MAX_CELL_POINTS:
        return None
    return lo, side, dims, start, members


def _dims(extent: NDArray[np.float64], side: float) -> NDArray[np.int64]:
    return (np.floor(extent / side) + 1).astype(np.int64)


def tree_neighbours(points: NDArray[np.float64], k: int, workers: int) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    from scipy.spatial import cKDTree

    distance, index = cKDTree(points).query(points, k=k, workers=workers)
    return distance.reshape(len(points), -1), index.reshape(len(points), -1).astype(np.int64, copy=False)
