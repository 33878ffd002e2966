"""The numpy oracle: every (point, face) pair the image-plane cull keeps, decided by Eq. 1-10.

:func:`occluded_numpy` decides condition (b) of the oracle's definition (:mod:`.oracle`) in
pure numpy, exact in float64, through the kernel of :mod:`.segment_triangle`
(Sryamkin, Msallam & Klestov 2023, §3.1 and §3.5, Eq. 1-10).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.defaults import DEFAULT_SELF_HIT_TOLERANCE
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.visibility.registry import check_face_index, check_points
from zbuf_occlude.visibility.segment_triangle import (
    TrianglePlanes,
    check_eye,
    check_tolerance,
    dot3,
    pair_occludes,
    triangle_planes,
)

__all__ = ["occluded_numpy", "occluded_unchecked", "DEFAULT_PAIRS_PER_CHUNK"]

#: (point, face) pairs tested at once by :func:`occluded_numpy`.  The kernel holds about
#: 20 float64/bool temporaries per pair at its peak (~150 bytes), so 2**20 pairs keep the
#: working set near 150 MB whatever N × F is.
DEFAULT_PAIRS_PER_CHUNK = 1 << 20
#: Relative widening of the image-plane boxes that cull (point, face) pairs before the
#: exact test, so that float64 rounding (~1e-16) never drops a pair it would accept.
_CULL_SLACK = 1e-9
#: Faces reaching this close (relative to the scene's size) to the eye's image plane are
#: not projected for the cull but tested against every point.
_CULL_MIN_DEPTH = 1e-6


def _cull_frame(planes: TrianglePlanes, points: NDArray[np.float64], eye: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """Rows: an orthonormal camera frame ``(a, b, w)`` at ``eye``, ``w`` towards the mesh; and a length scale."""
    w = planes.vertices.reshape(-1, 3).mean(axis=0) - eye
    norm = float(np.sqrt(dot3(w, w)))
    w = w / norm if norm > 0.0 else np.array([0.0, 0.0, 1.0])
    a = np.cross(w, np.eye(3)[int(np.argmin(np.abs(w)))])
    a /= np.sqrt(dot3(a, a))
    scale = max(float(np.abs(planes.vertices - eye).max()), float(np.abs(points - eye).max(initial=0.0)))
    return np.stack([a, np.cross(w, a), w]), scale


def _candidate_pairs(
    planes: TrianglePlanes,
    points: NDArray[np.float64],
    eye: NDArray[np.float64],
    todo: NDArray[np.bool_],
    chunk_size: int,
) -> Iterator[tuple[NDArray[np.int64], NDArray[np.int64]]]:
    """Yield ``(point, face)`` index pairs, at most ``max(chunk_size, N)`` at a time, that may occlude.

    A conservative cull in the image plane of ``eye``, so that the exact test sees a few
    faces per sightline instead of all F.  If face ``f`` meets the segment from ``p`` to
    the eye at ``X``, then ``X`` and ``p`` lie on one ray from the eye: in a camera frame
    ``(a, b, w)`` both project to the same ``(x / z, y / z)``, which therefore lies in the
    2D bounding box of ``f``'s projected vertices, and ``X``'s depth ``z`` is at most ``p``'s.
    Boxes are widened by :data:`_CULL_SLACK` so float64 rounding never drops such a pair.
    Projection needs ``z > 0``: faces reaching within :data:`_CULL_MIN_DEPTH` of the eye's
    plane are paired with every point; points that close to it (or behind the eye) cannot
    be hidden by the other faces, whose depths all exceed theirs.  ``todo`` is read at
    each yield, so points found hidden meanwhile are skipped.
    """
    frame, scale = _cull_frame(planes, points, eye)
    min_depth, slack = _CULL_MIN_DEPTH * scale, _CULL_SLACK * scale
    vert = (planes.vertices - eye) @ frame.T  # (F, 3, 3): x, y, z per vertex
    pt = (points - eye) @ frame.T  # (N, 3)
    face_depth = vert[..., 2].min(axis=-1)
    near_faces = np.flatnonzero(face_depth <= min_depth)
    far_faces = np.flatnonzero(face_depth > min_depth)
    far_points = np.flatnonzero(pt[:, 2] > min_depth)

    if len(near_faces):
        # Faces reaching the eye's plane (rare: the eye is normally far outside the mesh):
        # all pairs, in blocks.
        point_block = max(1, chunk_size // len(near_faces))
        for p0 in range(0, len(points), point_block):
            k = np.arange(p0, min(p0 + point_block, len(points)))
            k = k[todo[k]]
            yield np.repeat(k, len(near_faces)), np.tile(near_faces, len(k))

    if len(far_faces) == 0 or len(far_points) == 0:
        return
    with np.errstate(divide="ignore", invalid="ignore"):
        fx = vert[far_faces, :, 0] / vert[far_faces, :, 2]
        fy = vert[far_faces, :, 1] / vert[far_faces, :, 2]
        px = pt[far_points, 0] / pt[far_points, 2]
        py = pt[far_points, 1] / pt[far_points, 2]
    x_lo, x_hi = fx.min(axis=1), fx.max(axis=1)
    y_lo, y_hi = fy.min(axis=1), fy.max(axis=1)
    x_lo -= _CULL_SLACK * (1.0 + np.abs(x_lo))
    x_hi += _CULL_SLACK * (1.0 + np.abs(x_hi))
    y_lo -= _CULL_SLACK * (1.0 + np.abs(y_lo))
    y_hi += _CULL_SLACK * (1.0 + np.abs(y_hi))
    # Sweep in x: the points in a face's x-range are one slice of the points sorted by x.
    order = np.argsort(px, kind="stable")
    px_sorted = px[order]
    first = np.searchsorted(px_sorted, x_lo, side="left")
    count = np.searchsorted(px_sorted, x_hi, side="right") - first
    ends = np.cumsum(count)
    f0 = 0
    while f0 < len(far_faces):
        # As many faces as fit in chunk_size pairs (at least one).
        f1 = max(f0 + 1, int(np.searchsorted(ends, ends[f0] - count[f0] + chunk_size, side="right")))
        c = count[f0:f1]
        face = np.repeat(np.arange(f0, f1), c)
        local = order[np.repeat(first[f0:f1] - (np.cumsum(c) - c), c) + np.arange(int(c.sum()))]
        keep = (py[local] >= y_lo[face]) & (py[local] <= y_hi[face])
        keep &= face_depth[far_faces[face]] <= pt[far_points[local], 2] + slack
        k = far_points[local[keep]]
        j = far_faces[face[keep]]
        keep = todo[k]
        yield k[keep], j[keep]
        f0 = f1


def occluded_unchecked(
    planes: TrianglePlanes,
    points: NDArray[np.float64],
    eye: NDArray[np.float64],
    face_index: NDArray[np.int64] | None,
    tolerance: float,
    chunk_size: int,
    cull: bool = True,
) -> NDArray[np.bool_]:
    """Validated-input body of :func:`occluded_numpy`."""
    n_points, n_faces = len(points), planes.shape[0]
    occluded = np.zeros(n_points, dtype=bool)
    if n_points == 0 or n_faces == 0:
        return occluded
    seg = eye - points
    seg_len = np.sqrt(dot3(seg, seg))
    # Still to decide: no face can lie farther than tolerance from p on a segment of length
    # <= tolerance, and a point found hidden needs no further face.
    todo = seg_len > tolerance
    if cull:
        pairs = _candidate_pairs(planes, points, eye, todo, chunk_size)
    else:
        pairs = _all_pairs(n_faces, todo, chunk_size)
    for k, j in pairs:
        hit = pair_occludes(points[k], seg[k], seg_len[k], planes, j, None if face_index is None else face_index[k], tolerance)
        hidden = k[hit]
        occluded[hidden] = True
        todo[hidden] = False
    return occluded


def _all_pairs(n_faces: int, todo: NDArray[np.bool_], chunk_size: int) -> Iterator[tuple[NDArray[np.int64], NDArray[np.int64]]]:
    """Every ``(point, face)`` pair, in blocks of about ``chunk_size`` (no cull)."""
    face_block = min(n_faces, chunk_size)
    point_block = max(1, chunk_size // face_block)
    for p0 in range(0, len(todo), point_block):
        for f0 in range(0, n_faces, face_block):
            k = np.arange(p0, min(p0 + point_block, len(todo)))
            k = k[todo[k]]
            j = np.arange(f0, min(f0 + face_block, n_faces))
            yield np.repeat(k, len(j)), np.tile(j, len(k))


def occluded_numpy(
    triangles: ArrayLike | TrianglePlanes,
    points: ArrayLike,
    eye: ArrayLike,
    *,
    face_index: ArrayLike | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    chunk_size: int = DEFAULT_PAIRS_PER_CHUNK,
    cull: bool = True,
) -> NDArray[np.bool_]:
    """Which points are hidden from ``eye`` by a face: condition (b) of the module definition.

    Pure numpy, exact in float64: (point, face) pairs are tested with Eq. 1-10 of
    Sryamkin, Msallam & Klestov 2023 (§3.1, §3.5), vectorised over pairs, through the
    kernel of :func:`segment_hits_triangles`.  With ``cull`` (default) the pairs are first
    culled conservatively in the eye's image plane (a pair survives iff the point's
    projection lies in the face's projected bounding box and the face is not entirely
    deeper than the point), which drops no pair the exact test would accept and leaves a
    few faces per point; without it all N·F pairs are tested.  Pairs go through in blocks
    of at most ``chunk_size`` (a single face's block may reach N), and a point leaves the
    remaining blocks as soon as one occluder is found.

    Parameters
    ----------
    triangles : (F, 3, 3) float or TrianglePlanes
        The occluding faces, object frame.
    points : (N, 3) float
        The points to test, object frame.
    eye : (3,) float
        Camera centre, object frame.
    face_index : (N,) int, optional
        Face each point lies on; that face never hides its own point.
    tolerance : float
        Hits at a distance ``<= tolerance`` from the point are ignored (object units,
        default :data:`DEFAULT_SELF_HIT_TOLERANCE` = 1e-6).
    chunk_size : int
        Pairs per block (default :data:`DEFAULT_PAIRS_PER_CHUNK`); temporaries take about
        150 bytes per pair.
    cull : bool
        Cull pairs in the image plane first (same result, much faster); ``False`` is the
        brute-force reference.

    Returns
    -------
    occluded : (N,) bool
        True where some face meets the segment from the point to ``eye`` at a distance
        ``d`` with ``tolerance < d <= |eye - point|``.  The frustum is not considered.

    Raises
    ------
    InvalidInputError
        On bad shapes, NaN/inf, ``face_index`` out of range, a negative tolerance or a
        non-positive ``chunk_size``.
    """
    planes = triangles if isinstance(triangles, TrianglePlanes) else triangle_planes(triangles)
    if len(planes.shape) != 1:
        raise InvalidInputError(f"triangles must have shape (F, 3, 3), got leading shape {planes.shape}")
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), planes.shape[0])
    if int(chunk_size) < 1:
        raise InvalidInputError(f"chunk_size must be >= 1, got {chunk_size!r}")
    return occluded_unchecked(planes, pts, check_eye(eye), fi, check_tolerance(tolerance), int(chunk_size), cull=bool(cull))
