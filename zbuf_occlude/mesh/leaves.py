"""Square leaves: the discrete foliage of a crown or a shrub, as triangles.

:func:`leaf_quads` builds leaves at given centres facing given normals; :func:`spherical_normals` draws
their normals from the *spherical* leaf angle distribution (uniform on the sphere), whose mean
projection ``G = 0.5`` makes a volume of leaves the turbid medium of canopy radiative transfer: a ray
passes a depth ``L`` of foliage of leaf area density ``LAD`` (one-sided leaf area per volume, m²/m³)
with probability ``exp(−G · LAD · L)`` (J. Ross 1981, *The radiation regime and architecture of plant
stands*; T. Nilson 1971, Agric. Meteorol. 8, 25–38).  The procedural families
(:func:`~zbuf_occlude.mesh.families.parts.leaf_ball`) and the crowns a scene grows
(:func:`~zbuf_occlude.sensors.scene.foliage.add_foliage`) are made of them.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["leaf_quads", "spherical_normals"]


def spherical_normals(n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """``n`` unit normals ``(n, 3) float64`` uniform on the sphere (normalised Gaussian draws, ``3n`` from ``rng``)."""
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return normals


def leaf_quads(centres: NDArray, normals: NDArray, side_m: float, rng: np.random.Generator) -> tuple[NDArray, NDArray]:
    """Square leaves: ``centres (N, 3)`` and unit ``normals (N, 3)`` float64, side ``side_m`` metres, each turned
    by a uniform angle about its normal.

    Returns
    -------
    vertices : (4N, 3) float64
        Four corners a leaf, in order around it.
    faces : (2N, 3) int64
        Two triangles a leaf, wound counter-clockwise seen from its normal.
    """
    n = len(centres)
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(normals, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(normals, u)
    turn = rng.uniform(0.0, 2.0 * math.pi, (n, 1))
    a, b = np.cos(turn) * u + np.sin(turn) * v, -np.sin(turn) * u + np.cos(turn) * v
    h = side_m / 2.0
    corners = np.stack([centres - h * a - h * b, centres + h * a - h * b, centres + h * a + h * b, centres - h * a + h * b], axis=1)
    base = 4 * np.arange(n, dtype=np.int64)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]]).reshape(2, n, 3).transpose(1, 0, 2).reshape(-1, 3)
    return corners.reshape(-1, 3), faces
