"""The float64 segment–triangle occlusion test for one (point, face) pair: the kernel of every CPU method.

Face ``f`` occludes point ``p`` seen from ``e`` when the segment from ``p`` to ``e`` crosses the
closed triangle beyond the self-hit tolerance (Sryamkin et al. 2023, §3.5, Eq. 4–10;
:mod:`zbuf_occlude.visibility.definition`):

* Eq. 4–6: ``t = (offset − n·p) / (n·(e − p))``, the crossing of the face's plane; a segment
  parallel to it gives ``inf`` or ``nan``, which fails the comparisons (no exception);
* the crossing counts when ``0 ≤ t ≤ 1`` and ``t·|e − p| > tolerance``;
* Eq. 7–10: ``X = p + t (e − p)`` lies on the inner side (``≥``) of the face's three edge planes.

One implementation, compiled with numba and inlined into the loops of the CPU z-buffer
(:mod:`.cpu_zbuffer`), Embree's crease re-check (:mod:`.embree_fast`) and the paper's face scan
(:mod:`.paper.face_scan`).  :func:`zbuf_occlude.visibility.segment_triangle.pair_occludes` is its
vectorised numpy form (operation for operation; a hypothesis test holds them equal), and
``render/shaders/exact_pair64.glsl`` its GLSL twin for the GPU (the same operations, in ``precise``
float64; a test runs both on random pairs).

The planes of a face are packed in one row of 16 float64 so that the loops read one contiguous
row per face (:func:`~zbuf_occlude.visibility.segment_triangle.pack_planes`).
"""

from __future__ import annotations

import numba

__all__ = ["pair_occludes_one"]


def _pair_occludes_one(px, py, pz, sx, sy, sz, seg_len, row, tolerance):
    # p = (px, py, pz), s = e - p, seg_len = |s|, row = one packed face: keep every operation
    # and its order, the numpy form and the GLSL twin compute the same ones.
    t = (row[3] - (row[0] * px + row[1] * py + row[2] * pz)) / (row[0] * sx + row[1] * sy + row[2] * sz)
    if not (t >= 0.0 and t <= 1.0 and t * seg_len > tolerance):
        return False
    x, y, z = px + t * sx, py + t * sy, pz + t * sz
    for e in range(3):
        if not (x * row[4 + 3 * e] + y * row[5 + 3 * e] + z * row[6 + 3 * e] >= row[13 + e]):
            return False
    return True


#: ``pair_occludes_one(px, py, pz, sx, sy, sz, seg_len, row, tolerance) -> bool``: face ``row``
#: (a :func:`~zbuf_occlude.visibility.segment_triangle.pack_planes` row) occludes the point ``p`` from the eye ``p + s``; numba-compiled,
#: inlined into the numba loops that call it (``error_model="numpy"``: a zero division gives
#: ``inf``/``nan`` as in numpy).
pair_occludes_one = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(_pair_occludes_one)
