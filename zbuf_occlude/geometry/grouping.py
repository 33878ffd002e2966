"""Orders and groups that every visibility method shares: identical faces, and a Morton order of points.

Pure numpy: the GPU method (:mod:`zbuf_occlude.render.exact_backend`) and the CPU methods
(Embree, the CPU z-buffer) use the same groups and the same order, without one importing the other.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["exact_face_groups", "morton_order"]


def exact_face_groups(triangles: NDArray[np.float64]) -> NDArray[np.int64]:
    """(F,) int64: for each face, the lowest index of the faces with bit-identical float64
    vertices in the same order (their float64 tests give the same bits, so one is tested)."""
    tri = np.ascontiguousarray(triangles, dtype=np.float64).reshape(len(triangles), 9)
    key = tri.view(np.dtype((np.void, 72))).ravel()
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    return first[inverse.ravel()].astype(np.int64)


def morton_order(points: NDArray[np.float64], bits: int = 10) -> NDArray[np.int64]:
    """(N,) permutation sorting ``points`` along a Z-order (Morton) curve of their bounding box
    (``bits`` <= 10 per axis: 30-bit codes).

    Neighbours in space project to neighbouring pixels from any camera, so in this order the
    invocations of one SIMD batch test the same tile's faces (divergence costs the batch the
    longest list of its lanes).
    """
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = points.min(axis=0), points.max(axis=0)
    q = ((points - lo) / np.maximum(hi - lo, 1e-30) * ((1 << bits) - 1)).astype(np.uint32)
    code = np.zeros(len(points), dtype=np.uint32)
    for axis in range(3):  # spread 10 bits to every third bit ("part1by2"), then interleave
        x = q[:, axis]
        x = (x | (x << 16)) & np.uint32(0x030000FF)
        x = (x | (x << 8)) & np.uint32(0x0300F00F)
        x = (x | (x << 4)) & np.uint32(0x030C30C3)
        x = (x | (x << 2)) & np.uint32(0x09249249)
        code |= x << np.uint32(axis)
    return np.argsort(code)  # equal codes: any order of theirs is as coherent
