"""Normals of a cloud estimated from the points alone: the plane of each point's ``k`` nearest
neighbours (principal component analysis, Hoppe et al. 1992; Open3D's ``estimate_normals`` with
``KNNSearch``), turned toward the sensor as a real scan's are (:func:`estimate_normals`), or, where
sharp edges matter more than speed, the flattest of several neighbourhoods near each point
(:func:`robust_normals`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "NORMAL_NEIGHBOURS", "ROBUST_NORMAL_SCALES", "ROBUST_PLANE_TOLERANCE", "ROBUST_SHIFT_PENALTY", "ROBUST_SPACING_NEIGHBOUR",
    "estimate_normals", "covariance_normals", "robust_normals",
]  # fmt: skip

#: Neighbours whose plane gives a normal: PointNet++'s and Open3D's usual count for ~2k-point clouds.
NORMAL_NEIGHBOURS = 16
#: Neighbourhood sizes (the point included) :func:`robust_normals` compares: 9, 24 and 48.  Chosen
#: with point-only visibility without normals against the exact oracle on the tuning meshes (16
#: unshipped ModelNet meshes and 6 made in code, 16 poses; docs/results/point_visibility.md), never
#: on the meshes the results page reports: mean accuracy 0.859 -> 0.882 at 2,048 points, 0.905 ->
#: 0.924 at 10,000 and 0.970 -> 0.971 at 100,000 against the earlier (6, 9, 14).  A part thinner
#: than the spacing (a plate, a table top) puts both its faces in a small neighbourhood, whose
#: flattest plane then tilts through them; 48 neighbours span enough of the part to lie along it
#: (a 1 cm plate at 2,048 points: normals more than 20 degrees off 27 % -> 4 %).  (9, 16, 32)
#: gives 0.877 / 0.917 at 1.5x the preparation's time, (12, 24, 48, 72) 0.884 / 0.926.
ROBUST_NORMAL_SCALES = (9, 24, 48)
#: A neighbourhood counts for a point only if its plane passes within this many spacings (the
#: distance to the 4th neighbour) of the point: 0.05 (with the scales above, 0.1 gives 0.882 /
#: 0.924 on the tuning meshes at 2,048 / 10,000 points, 0.05 0.884 / 0.927, 0.025 0.884 / 0.927,
#: 0.2 0.878 / 0.920).
ROBUST_PLANE_TOLERANCE = 0.05
#: The spacing of :func:`robust_normals` is the distance to this neighbour (the point not counted).
ROBUST_SPACING_NEIGHBOUR = 4
#: Surface variation added per spacing a neighbourhood's centre lies from the point: 0.005.  On a
#: curved surface a shifted neighbourhood is as flat as the point's own but tilted by the
#: curvature; this keeps the own one there (a sampled sphere: 0.970 -> 0.981 accuracy at 10,000
#: points) and shifts next to edges (+0.3 points on the tuning meshes).
ROBUST_SHIFT_PENALTY = 0.005


def estimate_normals(
    points: NDArray[np.floating], eye: NDArray[np.floating], *, k: int = NORMAL_NEIGHBOURS, neighbours: NDArray[np.integer] | None = None
) -> NDArray[np.float32]:
    """Unit normals of ``points``, each facing ``eye``.

    Parameters
    ----------
    points : (n, 3) float
        One cloud, object frame.
    eye : (3,) float
        The sensor's position, same frame: each normal is flipped to face it (a point the
        sensor saw lies on a surface facing it).
    k : int
        Neighbours per point (the point itself included); fewer points than ``k``: all of them.
    neighbours : (n, k) int, optional
        Each point's neighbours when the caller has them (``cKDTree.query``); else found here.

    Returns
    -------
    (n, 3) float32
        The eigenvector of the smallest eigenvalue of each neighbourhood's covariance, unit length,
        with ``dot(normal, eye - point) >= 0``.
    """
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=np.float64)
    k = int(min(k, len(p)))
    if k < 3:
        normal = np.zeros_like(p)
        normal[:, 2] = 1.0
        return normal.astype(np.float32)
    idx = cKDTree(p).query(p, k=k)[1] if neighbours is None else np.asarray(neighbours)
    normal, _ = covariance_normals(p, idx)
    flip = np.einsum("ni,ni->n", normal, np.asarray(eye, dtype=np.float64) - p) < 0
    normal[flip] *= -1.0
    return normal.astype(np.float32)


def covariance_normals(points: NDArray[np.float64], neighbours: NDArray[np.integer]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The covariance (PCA) normal of each neighbourhood and its surface variation.

    Parameters
    ----------
    points : (n, 3) float64
    neighbours : (n, k) int
        Indices into ``points`` of each neighbourhood.

    Returns
    -------
    normals : (n, 3) float64
        Unit eigenvector of the smallest eigenvalue, of arbitrary sign.
    variation : (n,) float64
        ``λ0 / (λ0 + λ1 + λ2)``, 0 on a plane, 1/3 for an isotropic blob (Pauly et al. 2002).
    """
    return _plane_fit(points[neighbours])


def _plane_fit(neighbourhoods: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`covariance_normals` of the ``(n, k, 3)`` points of each neighbourhood, gathered."""
    nb = neighbourhoods - neighbourhoods.mean(axis=1, keepdims=True)
    values, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    total = values.sum(axis=1)
    variation = np.where(total > 0, values[:, 0] / np.where(total > 0, total, 1.0), 0.0)
    return vectors[:, :, 0], variation  # eigh sorts eigenvalues ascending


def robust_normals(
    points: NDArray[np.floating],
    *,
    scales: tuple[int, ...] = ROBUST_NORMAL_SCALES,
    plane_tolerance: float = ROBUST_PLANE_TOLERANCE,
    shift_penalty: float = ROBUST_SHIFT_PENALTY,
) -> NDArray[np.float64]:
    """Normals that stay true next to sharp edges, of arbitrary sign.

    A point's own neighbourhood straddles an edge it lies near, and its covariance normal bends
    halfway between the faces.  Here each point takes, among the neighbourhoods of sizes
    ``scales`` centred on itself and on its nearest neighbours, the flattest (least surface
    variation, Pauly et al. 2002, plus ``shift_penalty`` per spacing between the centre and the
    point) whose plane passes within ``plane_tolerance`` spacings of it:
    one that lies on its own face (the neighbourhood shifting of robust normal estimation near
    sharp features, e.g. Wang et al. 2013, done with plain PCA).

    Parameters
    ----------
    points : (n, 3) float
        Object frame.
    scales : tuple of int
        Neighbourhood sizes, the centre included (:data:`ROBUST_NORMAL_SCALES`); the candidate
        centres are the point's ``scales[1]`` nearest points.
    plane_tolerance : float
        In spacings (the distance to the 4th neighbour).
    shift_penalty : float
        Surface variation per spacing of shift (:data:`ROBUST_SHIFT_PENALTY`).

    Returns
    -------
    (n, 3) float64
        Unit normals.  Fewer than 3 points: ``+z``.
    """
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=np.float64)
    n = len(p)
    sizes = sorted({min(int(k), n) for k in scales if min(int(k), n) >= 3})
    if not sizes:
        return np.tile([0.0, 0.0, 1.0], (n, 1))
    distance, idx = cKDTree(p).query(p, k=max(sizes))
    distance, idx = distance.reshape(n, -1), idx.reshape(n, -1)
    spacing = distance[:, min(ROBUST_SPACING_NEIGHBOUR, distance.shape[1] - 1)]
    centres = idx[:, : min(scales[1] if len(scales) > 1 else sizes[0], idx.shape[1])]
    rows = np.arange(n)
    best = np.full(n, np.inf)
    normal = np.zeros_like(p)
    gathered = p[idx]  # the largest neighbourhood: its first k rows are the neighbourhood of size k
    offset = p[:, None, :] - gathered[:, : centres.shape[1]]
    shift = shift_penalty * np.linalg.norm(offset, axis=2) / np.maximum(spacing, 1e-300)[:, None]
    middle = sizes[len(sizes) // 2]
    for k in sizes:
        candidate, variation = _plane_fit(gathered[:, :k])
        if k == middle:
            own = candidate
        off = np.abs(np.einsum("nkj,nkj->nk", offset, candidate[centres]))
        score = np.where(off <= plane_tolerance * spacing[:, None], variation[centres] + shift, np.inf)
        j = score.argmin(axis=1)
        take = score[rows, j] < best
        best[take] = score[rows, j][take]
        normal[take] = candidate[centres[rows, j]][take]
    # no neighbourhood passed near the point (an isolated spike): its own at the middle scale
    lost = ~np.isfinite(best)
    if lost.any():
        normal[lost] = own[lost]
    return normal
