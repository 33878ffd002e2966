"""Which points a face hides, visiting faces one by one: the loop of the paper's object-space methods.

Sryamkin, Msallam & Klestov 2023, §3.5 (every point against every face, Eq. 1-10, stop at
the first occluder) and §3.6 (exclude faces farther than the point): :func:`occluded_by_faces`
runs that loop for :mod:`.object_space`, :mod:`.vertex` and :mod:`.occupancy`, deciding each
pair with the kernel of :mod:`.segment_triangle`.

Two backends run the same arithmetic (:func:`occluded_by_faces`):

``"numba"``
    A compiled loop, parallel over points, that visits faces one by one and stops at the
    first occluder, as the paper describes.  It is a line-by-line transcription of the
    float64 kernel of :func:`~zbuf_occlude.visibility.segment_triangle.segment_hits_triangles`
    (same operations in the same order, no fused multiply-add), so it decides every
    (point, face) pair bit for bit as the numpy kernel does; ``tests/visibility/paper/test_object_space.py``
    checks this.  Needs numba (a core dependency).
``"numpy"``
    The kernel functions of :mod:`.segment_triangle` on blocks of (point, face) pairs, a block of faces
    at a time, dropping a point as soon as a block occludes it.  No dependency; memory
    stays below ``pairs_per_chunk`` pairs (~150 bytes each) whatever N × F is.

``"auto"`` (default) takes numba when it imports.  Either backend needs O(N + F) memory
besides its pair blocks, so 1M points × 200k faces run in bounded memory (slowly: O(N·F)
is what §3.6 sets out to reduce).
"""

from __future__ import annotations

import functools
import importlib.util
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude._version import install_hint
from zbuf_occlude.defaults import DEFAULT_SELF_HIT_TOLERANCE
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.visibility.oracle_numpy import DEFAULT_PAIRS_PER_CHUNK
from zbuf_occlude.visibility.registry import check_face_index, check_points
from zbuf_occlude.visibility.segment_triangle import (
    TrianglePlanes,
    check_eye,
    check_tolerance,
    inside_triangle,
    pack_planes,
    segment_plane,
)

__all__ = ["BACKENDS", "occluded_by_faces", "numba_available", "face_count"]

#: Accepted values of every ``backend`` argument of this module.
BACKENDS = ("auto", "numba", "numpy")
#: Points per block of the numpy backend; with ``pairs_per_chunk`` pairs a block meets
#: ``pairs_per_chunk // 256`` faces at a time, small enough that a hidden point stops
#: being tested soon after its first occluder, large enough to amortise numpy's overhead.
_NUMPY_POINTS_PER_BLOCK = 256


def numba_available() -> bool:
    """True when numba can be imported (the ``"numba"`` backend)."""
    return importlib.util.find_spec("numba") is not None


# ``prange`` is ``range`` until numba is imported by _numba_kernel(), which rebinds it to
# numba.prange before compiling, so that this module imports without numba.
prange = range
pair_occludes_one = None  # bound by _numba_kernel() to visibility.kernels.pair_occludes_one


def _occluded_loop(points, eye, packed, own_face, end, tolerance, out):  # pragma: no cover - compiled
    # The pair test is the one kernel of every CPU method (visibility/kernels.py), inlined here.
    use_own = own_face.shape[0] > 0
    for k in prange(points.shape[0]):
        px = points[k, 0]
        py = points[k, 1]
        pz = points[k, 2]
        sx = eye[0] - px
        sy = eye[1] - py
        sz = eye[2] - pz
        seg_len = math.sqrt(sx * sx + sy * sy + sz * sz)
        own = own_face[k] if use_own else -1
        for j in range(end[k]):
            if j != own and pair_occludes_one(px, py, pz, sx, sy, sz, seg_len, packed[j], tolerance):
                out[k] = True
                break


@functools.cache
def _numba_kernel() -> Any:
    try:
        import numba
    except ImportError as exc:
        raise BackendUnavailable(f"backend='numba' needs numba: {install_hint('fast')} ({exc}); or use backend='numpy'") from None
    from zbuf_occlude.visibility.kernels import pair_occludes_one

    globals()["prange"] = numba.prange
    globals()["pair_occludes_one"] = pair_occludes_one
    # cache=True keeps the compiled kernel in __pycache__ (compiling takes seconds);
    # error_model="numpy" makes x / 0 give inf/nan like numpy instead of raising.
    return numba.njit(parallel=True, cache=True, error_model="numpy", nogil=True)(_occluded_loop)


def _resolve_backend(backend: str) -> str:
    if backend not in BACKENDS:
        raise InvalidInputError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "auto":
        return "numba" if numba_available() else "numpy"
    return backend


def face_count(planes: TrianglePlanes) -> int:
    return int(planes.offset.shape[0])


def _occluded_numpy_blocks(
    planes: TrianglePlanes,
    points: NDArray[np.float64],
    eye: NDArray[np.float64],
    own_face: NDArray[np.int64] | None,
    end: NDArray[np.int64],
    tolerance: float,
    pairs_per_chunk: int,
) -> NDArray[np.bool_]:
    """numpy backend: ``planes`` in visiting order, point ``k`` meets faces ``[0, end[k])``.

    ``own_face`` holds visiting positions, not mesh face ids.
    """
    n_points = len(points)
    occluded = np.zeros(n_points, dtype=bool)
    if n_points == 0 or face_count(planes) == 0:
        return occluded
    seg = eye - points
    # Written-out dot product, as the oracle's kernel computes it (einsum may round differently).
    seg_len = np.sqrt(seg[:, 0] * seg[:, 0] + seg[:, 1] * seg[:, 1] + seg[:, 2] * seg[:, 2])
    # Points with similar face ranges share blocks, so a block's faces are few.
    order = np.argsort(end, kind="stable")
    point_block = min(_NUMPY_POINTS_PER_BLOCK, max(1, pairs_per_chunk))
    face_block = max(1, pairs_per_chunk // point_block)
    face_pos = np.arange(face_count(planes), dtype=np.int64)
    for start in range(0, n_points, point_block):
        active = order[start : start + point_block]
        stop = int(end[active].max())
        for f0 in range(0, stop, face_block):
            active = active[end[active] > f0]
            if len(active) == 0:
                break
            fb = slice(f0, min(f0 + face_block, stop))
            p, s, ln = points[active][:, None, :], seg[active][:, None, :], seg_len[active][:, None]
            t, ok = segment_plane(p, s, planes.normal[None, fb], planes.offset[None, fb])
            ok &= t * ln > tolerance
            ok &= face_pos[None, fb] < end[active][:, None]
            if own_face is not None:
                ok &= face_pos[None, fb] != own_face[active][:, None]
            i, j = np.nonzero(ok)
            inside = inside_triangle(p[i, 0], s[i, 0], t[i, j], planes.edge_normals[fb][j], planes.edge_offsets[fb][j])
            hidden = np.zeros(len(active), dtype=bool)
            hidden[i[inside]] = True
            occluded[active[hidden]] = True
            active = active[~hidden]
    return occluded


def occluded_by_faces(
    planes: TrianglePlanes,
    points: ArrayLike,
    eye: ArrayLike,
    *,
    face_index: ArrayLike | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    face_key: ArrayLike | None = None,
    limit: ArrayLike | None = None,
    order: ArrayLike | None = None,
    backend: str = "auto",
    pairs_per_chunk: int = DEFAULT_PAIRS_PER_CHUNK,
) -> NDArray[np.bool_]:
    """Which points a face hides from ``eye``, with optional exclusion of faces per point.

    Sryamkin et al. 2023, §3.5 (every point against every face, Eq. 1-10, stop at the first
    occluder) and §3.6 (exclude faces farther than the point).  Point ``k`` is occluded iff
    some face ``f`` with ``f != face_index[k]`` and, when ``face_key`` is given,
    ``face_key[f] <= limit[k]``, meets the segment from the point to ``eye`` at a distance
    ``d`` from the point with ``tolerance < d``: the oracle's condition (b) restricted to
    the faces not excluded.

    Parameters
    ----------
    planes : TrianglePlanes
        Planes of the F faces, from :func:`~zbuf_occlude.visibility.segment_triangle.triangle_planes`.
    points : (N, 3) float
        Segment starts, object frame.
    eye : (3,) float
        Camera centre, object frame.
    face_index : (N,) int, optional
        Face each point lies on; it never hides its own point.
    tolerance : float
        Hits within this distance of the point are ignored (object units, default 1e-6).
    face_key, limit : (F,) and (N,) float, optional
        Exclusion: face ``f`` is not tested for point ``k`` when ``face_key[f] > limit[k]``.
        Faces are then visited in increasing ``face_key`` order, so that the faces a point
        meets are a prefix and the exclusion costs nothing per excluded face.
    order : (F,) int, optional
        Visiting order of the faces when ``face_key`` is not given (default: mesh order).
        Only the time changes with the order, never the answer.
    backend : {"auto", "numba", "numpy"}
        See the module docstring.
    pairs_per_chunk : int
        numpy backend: most (point, face) pairs held at once.

    Returns
    -------
    occluded : (N,) bool
        The camera frustum is not considered.

    Raises
    ------
    InvalidInputError
        On bad shapes, NaN, a negative tolerance, ``face_key`` without ``limit`` or an
        unknown backend.
    BackendUnavailable
        ``backend="numba"`` without numba installed.
    """
    pts = check_points(points)
    e = check_eye(eye)
    tol = check_tolerance(tolerance)
    if int(pairs_per_chunk) < 1:
        raise InvalidInputError(f"pairs_per_chunk must be >= 1, got {pairs_per_chunk!r}")
    n_faces = face_count(planes)
    fi = check_face_index(face_index, len(pts), n_faces)
    if (face_key is None) != (limit is None):
        raise InvalidInputError("face_key and limit must be given together")
    if face_key is not None:
        key = np.asarray(face_key, dtype=np.float64)
        lim = np.asarray(limit, dtype=np.float64)
        if key.shape != (n_faces,) or lim.shape != (len(pts),):
            raise InvalidInputError(f"face_key must be ({n_faces},) and limit ({len(pts)},), got {key.shape}, {lim.shape}")
        visit = np.argsort(key, kind="stable")
        end = np.searchsorted(key[visit], lim, side="right").astype(np.int64)
    else:
        visit = np.arange(n_faces, dtype=np.int64) if order is None else np.asarray(order, dtype=np.int64)
        if visit.shape != (n_faces,) or not np.array_equal(np.sort(visit), np.arange(n_faces)):
            raise InvalidInputError(f"order must be a permutation of range({n_faces})")
        end = np.full(len(pts), n_faces, dtype=np.int64)
    if len(pts) == 0 or n_faces == 0:
        return np.zeros(len(pts), dtype=bool)
    # Own faces as visiting positions, so the kernel compares positions, not ids.
    own = None
    if fi is not None:
        position = np.empty(n_faces, dtype=np.int64)
        position[visit] = np.arange(n_faces, dtype=np.int64)
        own = position[fi]
    ordered = planes.take(visit)
    if _resolve_backend(backend) == "numba":
        kernel = _numba_kernel()
        out = np.zeros(len(pts), dtype=bool)
        kernel(
            pts,
            e,
            pack_planes(ordered),
            own if own is not None else np.zeros(0, dtype=np.int64),
            end,
            tol,
            out,
        )
        return out
    return _occluded_numpy_blocks(ordered, pts, e, own, end, tol, int(pairs_per_chunk))
