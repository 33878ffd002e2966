"""Normals of a sampled cloud, estimated from the points alone and turned toward the sensor, as a
real scan's are: the plane of each point's ``k`` nearest neighbours (principal component analysis,
Hoppe et al. 1992; Open3D's ``estimate_normals`` with ``KNNSearch``)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["NORMAL_NEIGHBOURS", "estimate_normals"]

#: Neighbours whose plane gives a normal: PointNet++'s and Open3D's usual count for ~2k-point clouds.
NORMAL_NEIGHBOURS = 16


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
    nb = p[idx] - p[idx].mean(axis=1, keepdims=True)
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    normal = vectors[:, :, 0]  # eigh sorts eigenvalues ascending
    flip = np.einsum("ni,ni->n", normal, np.asarray(eye, dtype=np.float64) - p) < 0
    normal[flip] *= -1.0
    return normal.astype(np.float32)
