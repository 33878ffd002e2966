"""The oracle: exact object-space hidden surface removal, the ground truth of every other method.

Definition
----------
A point ``p`` is *visible* from a camera with centre ``e`` iff

(a) ``p`` lies inside the camera's view frustum (:meth:`Camera.in_frustum`), and
(b) no face ``f`` of the mesh, other than the face ``p`` was sampled on (``face_index[p]``,
    when given), meets the segment from ``p`` to ``e`` at a distance ``d`` from ``p`` with
    ``tolerance < d <= |e - p|``.

``tolerance`` defaults to :data:`~zbuf_occlude.visibility.registry.DEFAULT_SELF_HIT_TOLERANCE`
(1e-6 object units; meshes are normalised to a maximum extent of 1).  Faces are two-sided:
there is no back-face culling.  A face "meets" the segment when the closed segment meets the
closed triangle (a point on an edge or a vertex counts, so a ray through an edge shared by
two triangles is never let through); a segment parallel to a face's plane never meets it.
Condition (b) is decided in float64 by the kernel of :func:`segment_hits_triangles` (the
paper's Eq. 1-10), one (point, face) pair at a time and always with the same arithmetic, so
the two implementations below can differ only if one of them never tests a pair that
occludes.  "Exact" means: decided in float64 with inclusive bounds, each triangle's edge
planes moved out by 1e-12 of its coordinate scale so that a segment through an edge shared
by two faces cannot round to outside both (the paper's edge tests alone are not watertight).
The registered methods also apply the edge-on rule of :mod:`~zbuf_occlude.visibility.definition`
(a point whose own face is seen within 1e-4 degrees of edge-on is not visible), with one
float64 function shared by both, so they agree bit for bit there too.

Implementations
---------------
:func:`occluded_numpy`
    The paper's equations (Sryamkin, Msallam & Klestov 2023, §3.1 and §3.5, Eq. 1-10),
    vectorised over (point, face) pairs in bounded chunks, after a conservative
    image-plane cull of the pairs (``cull=False`` tests all N·F).  Numpy only.
:func:`occluded_embree`
    Intel Embree (float32 BVH, through ``embreex``) proposes the candidate occluder of each
    ray; every candidate is re-decided in float64 by the same kernel, so Embree's rounding
    can cost at most a missed candidate, never a false occluder.  How the float32 traps are
    handled is documented on the function.

Registered methods (:func:`~zbuf_occlude.visibility.registry.visible_mask`)
-----------------------------------------------------------------------------
``"oracle"``
    :func:`oracle_visible`, Embree.
``"oracle-numpy"``
    :func:`oracle_numpy_visible`, pure numpy (small meshes, or to check ``"oracle"``).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from ..cameras import Camera
from ..errors import BackendUnavailable, InvalidInputError
from ..mesh_cache import MeshCache
from .definition import hide_edge_on
from .registry import DEFAULT_SELF_HIT_TOLERANCE, check_face_index, check_points, log_ignored, register, visible_in_frustum

__all__ = [
    "TrianglePlanes",
    "triangle_planes",
    "mesh_planes",
    "segment_hits_triangles",
    "occluded_numpy",
    "occluded_embree",
    "oracle_visible",
    "oracle_numpy_visible",
    "DEFAULT_PAIRS_PER_CHUNK",
]

log = logging.getLogger(__name__)

#: (point, face) pairs tested at once by :func:`occluded_numpy`.  The kernel holds about
#: 20 float64/bool temporaries per pair at its peak (~150 bytes), so 2**20 pairs keep the
#: working set near 150 MB whatever N × F is.
DEFAULT_PAIRS_PER_CHUNK = 1 << 20

# -- Embree ray-casting constants (all relative to the radius of the mesh's bounding
#    sphere, so that they are scale-free; float32 has a relative precision of ~6e-8) ------
#: Rays are cast only across the mesh's bounding sphere widened by this margin (origins
#: near the mesh keep float32 coordinates small); the margin keeps faces on the sphere in.
_EMBREE_SPHERE_MARGIN = 1e-3
#: First step past a rejected hit before re-casting: a few float32 ulps at the sphere's
#: radius, enough to leave a face hit at a non-grazing angle in one re-cast.
_EMBREE_FIRST_STEP = 2.0**-20
#: Casts per ray before giving up on Embree and deciding that ray with the exact kernel.
#: The step doubles each time the same face is hit again, so 64 casts reach any distance.
_EMBREE_MAX_CASTS = 64
#: Points whose (distance to their face's boundary) × |cos(sightline, face normal)| is
#: below this get the faces around their own face tested exactly after the Embree pass
#: (see occluded_embree); 2 × 5e-6, some 50 times float32's noise at the sphere's radius.
_EMBREE_CREASE_BAND = 1e-5
#: Outward shift of each triangle's edge planes, relative to its coordinate scale: far above
#: float64 rounding (~1e-16) and far below any mesh feature, it makes shared edges watertight.
_EDGE_SLACK = 1e-12
#: Relative widening of the image-plane boxes that cull (point, face) pairs before the
#: exact test, so that float64 rounding (~1e-16) never drops a pair it would accept.
_CULL_SLACK = 1e-9
#: Faces reaching this close (relative to the scene's size) to the eye's image plane are
#: not projected for the cull but tested against every point.
_CULL_MIN_DEPTH = 1e-6
#: Up to this many rays that Embree could not settle are decided one by one against the
#: faces whose bounding boxes meet their segment; more go through the image-plane cull.
_FEW_FALLBACK_RAYS = 64
#: Meshes whose planes and Embree scenes stay cached (least recently used evicted).
_SCENE_CACHE_SIZE = 8


# =========================================================================================
# The float64 kernel: Eq. 1-10 of Sryamkin et al. 2023
# =========================================================================================
@dataclass(frozen=True)
class TrianglePlanes:
    """Per-triangle planes of the segment/triangle test, precomputed once per mesh.

    All fields share the leading shape ``(...)`` of the triangles they come from; index
    them together with :meth:`take`.

    Attributes
    ----------
    vertices : (..., 3, 3) float64
        ``A, B, C``, object frame.
    normal : (..., 3) float64
        ``n = (B - A) × (C - A)``, not normalised (Sryamkin et al. 2023, Eq. 1-2).
    offset : (...,) float64
        ``n · A``: the triangle's plane is ``{x : n · x = offset}`` (Eq. 3).
    edge_normals : (..., 3, 3) float64
        Row ``k`` is ``m_k = n × (V_{k+1} - V_k)`` for the edges AB, BC, CA: the normal of the
        plane through edge ``k`` perpendicular to the triangle, pointing to the inside.
    edge_offsets : (..., 3) float64
        ``m_k · V_k``.  A point ``X`` of the triangle's plane is inside the closed triangle iff
        ``m_k · X >= edge_offsets[k]`` for all three ``k`` (Eq. 7-10).
    """

    vertices: NDArray[np.float64]
    normal: NDArray[np.float64]
    offset: NDArray[np.float64]
    edge_normals: NDArray[np.float64]
    edge_offsets: NDArray[np.float64]

    @property
    def shape(self) -> tuple[int, ...]:
        """Leading shape ``(...)``: ``(F,)`` for the faces of a mesh."""
        return self.offset.shape

    def take(self, index: ArrayLike) -> TrianglePlanes:
        """The planes of the triangles ``index`` (any numpy index on the leading axes)."""
        return TrianglePlanes(
            self.vertices[index],
            self.normal[index],
            self.offset[index],
            self.edge_normals[index],
            self.edge_offsets[index],
        )


def _dot3(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    # Written out, not einsum/matmul (whose summation order and FMA use depend on shapes
    # and BLAS): a (point, face) pair must get the same bits whatever the arrays around it,
    # or the numpy and Embree oracles could disagree on the same pair.
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    # np.cross, spelled out for the same reason as _dot3.
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def triangle_planes(triangles: ArrayLike) -> TrianglePlanes:
    """Precompute the planes of the segment/triangle test (Sryamkin et al. 2023, Eq. 1-3, 7-10).

    Parameters
    ----------
    triangles : (..., 3, 3) float
        Vertices ``A, B, C`` of each triangle, object frame.

    Returns
    -------
    planes : TrianglePlanes
        Fields of leading shape ``(...)``.  Degenerate (zero-area) triangles get ``n = 0``
        and are never hit.

    Raises
    ------
    InvalidInputError
        If the shape is not ``(..., 3, 3)`` or a coordinate is NaN/inf.
    """
    tri = np.asarray(triangles, dtype=np.float64)
    if tri.ndim < 2 or tri.shape[-2:] != (3, 3):
        raise InvalidInputError(f"triangles must have shape (..., 3, 3), got {tri.shape}")
    if not np.all(np.isfinite(tri)):
        raise InvalidInputError("triangles contain NaN/inf coordinates")
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    normal = _cross(b - a, c - a)
    edge_normals = np.stack([_cross(normal, b - a), _cross(normal, c - b), _cross(normal, a - c)], axis=-2)
    edge_offsets = np.stack(
        [_dot3(edge_normals[..., 0, :], a), _dot3(edge_normals[..., 1, :], b), _dot3(edge_normals[..., 2, :], c)],
        axis=-1,
    )
    # Watertightness: move each edge plane outwards by _EDGE_SLACK times the triangle's
    # coordinate scale, so a segment through an edge shared by two faces, whose
    # intersection point rounds (~1e-16 relative) to just outside both, still hits one.
    scale = 1.0 + np.abs(tri).max(axis=(-2, -1))
    edge_offsets = edge_offsets - _EDGE_SLACK * scale[..., None] * np.sqrt(_dot3(edge_normals, edge_normals))
    return TrianglePlanes(tri, normal, _dot3(normal, a), edge_normals, edge_offsets)


def _segment_plane(
    p: NDArray[np.float64], seg: NDArray[np.float64], normal: NDArray[np.float64], offset: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Eq. 4-6: parameter ``t`` of ``X = p + t · seg`` on the plane, and ``0 <= t <= 1``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (offset - _dot3(normal, p)) / _dot3(normal, seg)
    # A segment parallel to the plane has n · seg == 0, so t is ±inf or NaN and fails both
    # comparisons: parallel means no hit, as in the paper.
    return t, (t >= 0.0) & (t <= 1.0)


def _inside_triangle(
    p: NDArray[np.float64],
    seg: NDArray[np.float64],
    t: NDArray[np.float64],
    edge_normals: NDArray[np.float64],
    edge_offsets: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Eq. 7-10: ``X = p + t · seg`` on the inner side of the three edge planes (inclusive)."""
    with np.errstate(invalid="ignore"):
        x = p + t[..., None] * seg
        inside = _dot3(x, edge_normals[..., 0, :]) >= edge_offsets[..., 0]
        inside &= _dot3(x, edge_normals[..., 1, :]) >= edge_offsets[..., 1]
        inside &= _dot3(x, edge_normals[..., 2, :]) >= edge_offsets[..., 2]
    return inside


def segment_hits_triangles(
    p: ArrayLike, e: ArrayLike, triangles: ArrayLike | TrianglePlanes
) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    """Does the closed segment ``[p, e]`` meet the closed triangle?  Float64, broadcasting.

    The paper's exact test (Sryamkin, Msallam & Klestov 2023, §3.1, §3.5): the plane of the
    triangle (Eq. 1-3), the intersection ``X = p + t (e - p)`` of the line through ``p`` and
    ``e`` with it (Eq. 4-6; a line parallel to the plane never hits), and the inside test
    against the three planes through the edges perpendicular to the triangle (Eq. 7-10).
    Bounds are inclusive: ``X`` on an edge or a vertex is a hit, so a segment through an
    edge shared by two triangles hits both of them when the arithmetic is exact (and at
    least one, barring rounding of ~1e-16 relative, when it is not).  Triangles are
    two-sided.

    Parameters
    ----------
    p : (..., 3) float
        Segment start (the sampled point), object frame.
    e : (..., 3) float
        Segment end (the camera centre), broadcastable against ``p``, e.g. ``(3,)``.
    triangles : (..., 3, 3) float or TrianglePlanes
        Triangles ``A, B, C``, broadcastable against ``p``; pass
        :func:`triangle_planes` output to test many segments against the same triangles.

    Returns
    -------
    hit : (...) bool
        The segment meets the triangle, ``0 <= t <= 1``.
    distance : (...) float64
        ``|X - p| = t |e - p|``, object units, where ``hit``; ``+inf`` elsewhere.  Callers
        apply their own tolerance (the oracle counts a hit as an occluder iff
        ``distance > tolerance``).

    Raises
    ------
    InvalidInputError
        On shapes that are not ``(..., 3)`` / ``(..., 3, 3)`` or NaN/inf triangles.
    """
    planes = triangles if isinstance(triangles, TrianglePlanes) else triangle_planes(triangles)
    p = np.asarray(p, dtype=np.float64)
    e = np.asarray(e, dtype=np.float64)
    if p.shape[-1:] != (3,) or e.shape[-1:] != (3,):
        raise InvalidInputError(f"p and e must have shape (..., 3), got {p.shape} and {e.shape}")
    seg = e - p
    t, on_segment = _segment_plane(p, seg, planes.normal, planes.offset)
    hit = on_segment & _inside_triangle(p, seg, t, planes.edge_normals, planes.edge_offsets)
    distance = np.where(hit, t * np.sqrt(_dot3(seg, seg)), np.inf)
    return hit, distance


def _pair_occludes(
    p: NDArray[np.float64],
    seg: NDArray[np.float64],
    seg_len: NDArray[np.float64],
    planes: TrianglePlanes,
    face_ids: NDArray[np.int64],
    own_face: NDArray[np.int64] | None,
    tolerance: float,
) -> NDArray[np.bool_]:
    """(K,) bool: face ``face_ids[k]`` occludes point ``k`` (definition (b) of the module).

    ``p``, ``seg = eye - p`` and ``seg_len`` are per pair; ``planes`` are all faces' planes.
    Every exact decision of this module goes through here, so a (point, face) pair gets
    the same bits whichever method asked.
    """
    t, ok = _segment_plane(p, seg, planes.normal[face_ids], planes.offset[face_ids])
    ok &= t * seg_len > tolerance
    if own_face is not None:
        ok &= face_ids != own_face
    # Gather the edge planes only for pairs that cross the plane on the counted part.
    f = face_ids[ok]
    ok[ok] = _inside_triangle(p[ok], seg[ok], t[ok], planes.edge_normals[f], planes.edge_offsets[f])
    return ok


def _near_own_surface(
    p: NDArray[np.float64],
    seg: NDArray[np.float64],
    seg_len: NDArray[np.float64],
    planes: TrianglePlanes,
    tolerance: float,
) -> NDArray[np.bool_]:
    """(K,) bool: the line through ``p`` along ``seg`` meets the closed face at ``|d| <= tolerance``."""
    t, _ = _segment_plane(p, seg, planes.normal, planes.offset)
    with np.errstate(invalid="ignore"):
        near = np.abs(t * seg_len) <= tolerance
    near[near] = _inside_triangle(p[near], seg[near], t[near], planes.edge_normals[near], planes.edge_offsets[near])
    return near


def _boundary_times_cos(
    planes: TrianglePlanes, p: NDArray[np.float64], direction: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(K,) ``b · |cos θ|``: ``b`` the distance from ``p[k]`` (on triangle k) to the triangle's
    edge lines, ``θ`` the angle between ``direction[k]`` (unit) and the triangle's normal."""
    with np.errstate(divide="ignore", invalid="ignore"):
        edge_dist = (_dot3(p[:, None, :], planes.edge_normals) - planes.edge_offsets) / np.sqrt(
            _dot3(planes.edge_normals, planes.edge_normals)
        )
        cos = np.abs(_dot3(direction, planes.normal)) / np.sqrt(_dot3(planes.normal, planes.normal))
    # Degenerate faces give NaN: keep those points in (NaN fails every "> band" test).
    return np.nan_to_num(np.abs(edge_dist).min(axis=1) * cos, nan=0.0)


def _cull_frame(
    planes: TrianglePlanes, points: NDArray[np.float64], eye: NDArray[np.float64]
) -> tuple[NDArray[np.float64], float]:
    """Rows: an orthonormal camera frame ``(a, b, w)`` at ``eye``, ``w`` towards the mesh; and a length scale."""
    w = planes.vertices.reshape(-1, 3).mean(axis=0) - eye
    norm = float(np.sqrt(_dot3(w, w)))
    w = w / norm if norm > 0.0 else np.array([0.0, 0.0, 1.0])
    a = np.cross(w, np.eye(3)[int(np.argmin(np.abs(w)))])
    a /= np.sqrt(_dot3(a, a))
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


def _occluded_core(
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
    seg_len = np.sqrt(_dot3(seg, seg))
    # Still to decide: no face can lie farther than tolerance from p on a segment of length
    # <= tolerance, and a point found hidden needs no further face.
    todo = seg_len > tolerance
    if cull:
        pairs = _candidate_pairs(planes, points, eye, todo, chunk_size)
    else:
        pairs = _all_pairs(n_faces, todo, chunk_size)
    for k, j in pairs:
        hit = _pair_occludes(
            points[k], seg[k], seg_len[k], planes, j, None if face_index is None else face_index[k], tolerance
        )
        hidden = k[hit]
        occluded[hidden] = True
        todo[hidden] = False
    return occluded


def _all_pairs(
    n_faces: int, todo: NDArray[np.bool_], chunk_size: int
) -> Iterator[tuple[NDArray[np.int64], NDArray[np.int64]]]:
    """Every ``(point, face)`` pair, in blocks of about ``chunk_size`` (no cull)."""
    face_block = min(n_faces, chunk_size)
    point_block = max(1, chunk_size // face_block)
    for p0 in range(0, len(todo), point_block):
        for f0 in range(0, n_faces, face_block):
            k = np.arange(p0, min(p0 + point_block, len(todo)))
            k = k[todo[k]]
            j = np.arange(f0, min(f0 + face_block, n_faces))
            yield np.repeat(k, len(j)), np.tile(j, len(k))


def _check_eye(eye: ArrayLike) -> NDArray[np.float64]:
    e = np.asarray(eye, dtype=np.float64)
    if e.shape != (3,) or not np.all(np.isfinite(e)):
        raise InvalidInputError(f"eye must be a finite (3,) vector, got {e!r}")
    return e


def _check_tolerance(tolerance: float) -> float:
    try:
        tol = float(tolerance)
    except (TypeError, ValueError):
        tol = math.nan
    if not (math.isfinite(tol) and tol >= 0.0):
        raise InvalidInputError(f"tolerance must be finite and >= 0, got {tolerance!r}")
    return tol


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
    return _occluded_core(
        planes, pts, _check_eye(eye), fi, _check_tolerance(tolerance), int(chunk_size), cull=bool(cull)
    )


# =========================================================================================
# Embree
# =========================================================================================
class _EmbreeScene:
    """An Embree BVH of one mesh plus its float64 planes (for re-deciding Embree's hits)."""

    def __init__(
        self, vertices: NDArray[np.float64], faces: NDArray[np.int64], planes: TrianglePlanes | None = None
    ) -> None:
        try:
            from embreex import rtcore_scene
            from embreex.mesh_construction import TriangleMesh
        except ImportError as exc:
            raise BackendUnavailable(
                f"the 'oracle' visibility method needs Embree: pip install embreex ({exc}); "
                "or use method='oracle-numpy'"
            ) from None
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        self.n_faces = len(faces)
        self.planes = triangle_planes(vertices[faces]) if planes is None else planes
        used = vertices[faces].reshape(-1, 3)
        # Float32 is most precise near 0, so the BVH is built around the bounding-box centre.
        self.centre = (used.min(axis=0) + used.max(axis=0)) / 2.0 if len(used) else np.zeros(3)
        self.radius = float(np.sqrt(_dot3(used - self.centre, used - self.centre)).max()) if len(used) else 0.0
        # Faces around each vertex (CSR), vertices merged by position: ModelNet files often
        # repeat a vertex per face, and adjacency has to follow geometry, not indices.
        _, corner_vertex = np.unique(used, axis=0, return_inverse=True)
        corner_vertex = corner_vertex.reshape(-1)  # numpy 2.0.0 returned it 2-D
        self.corner_vertex = corner_vertex.reshape(-1, 3)
        order = np.argsort(corner_vertex, kind="stable")
        self.vertex_faces = order // 3
        self.vertex_start = np.searchsorted(corner_vertex[order], np.arange(corner_vertex.max(initial=-1) + 2))
        # Per-face bounding boxes, for deciding a few fallback rays without a full cull.
        self.face_lo = self.planes.vertices.min(axis=-2)
        self.face_hi = self.planes.vertices.max(axis=-2)
        self.scene = None
        if self.n_faces:
            # Robust mode: watertight ray/triangle tests (no leaks through shared edges).
            self.scene = rtcore_scene.EmbreeScene(robust=True)
            TriangleMesh(
                scene=self.scene,
                vertices=np.ascontiguousarray(vertices - self.centre, dtype=np.float32),
                indices=np.ascontiguousarray(faces, dtype=np.int32),
            )

    def faces_around(self, face: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Pairs ``(k, g)``: face ``g`` shares a vertex position with ``face[k]`` (itself included)."""
        corners = self.corner_vertex[face].ravel()
        start = self.vertex_start[corners]
        count = self.vertex_start[corners + 1] - start
        k = np.repeat(np.repeat(np.arange(len(face)), 3), count)
        offset = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
        return k, self.vertex_faces[np.repeat(start, count) + offset]

    def first_hits(
        self, origins: NDArray[np.float64], directions: NDArray[np.float64], lengths: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """(K,) face hit first (-1 for none) and its float32 ray parameter, as float64."""
        out = self.scene.run(
            np.ascontiguousarray(origins - self.centre, dtype=np.float32),
            np.ascontiguousarray(directions, dtype=np.float32),
            dists=np.ascontiguousarray(lengths, dtype=np.float32),
            output=True,
        )
        return out["primID"].astype(np.int64), out["tfar"].astype(np.float64)


#: Face planes of the meshes in use (:func:`mesh_planes`).
_planes_cache: MeshCache[TrianglePlanes] = MeshCache(lambda mesh: triangle_planes(mesh.triangles), _SCENE_CACHE_SIZE)
# _EmbreeScene is looked up at build time (tests count the builds by patching it).
_scenes: MeshCache[_EmbreeScene] = MeshCache(
    lambda mesh: _EmbreeScene(mesh.vertices, mesh.faces, planes=mesh_planes(mesh)), _SCENE_CACHE_SIZE
)


def mesh_planes(mesh: trimesh.Trimesh) -> TrianglePlanes:
    """The :func:`triangle_planes` of ``mesh``, cached per mesh object (rebuilt after edits).

    Shared by the oracles and the paper's object-space methods, so that many cameras of
    one mesh compute the planes once.
    """
    return _planes_cache(mesh)


def _scene_for(mesh: trimesh.Trimesh) -> _EmbreeScene:
    """The cached Embree scene of ``mesh`` (:class:`~zbuf_occlude.mesh_cache.MeshCache`)."""
    return _scenes(mesh)


def _embree_scene(mesh: trimesh.Trimesh | ArrayLike) -> _EmbreeScene:
    if isinstance(mesh, trimesh.Trimesh):
        return _scene_for(mesh)
    tri = np.asarray(mesh, dtype=np.float64)
    if tri.ndim != 3 or tri.shape[1:] != (3, 3):
        raise InvalidInputError(f"expected a trimesh.Trimesh or (F, 3, 3) triangles, got shape {tri.shape}")
    if not np.all(np.isfinite(tri)):
        raise InvalidInputError("triangles contain NaN/inf coordinates")
    return _EmbreeScene(tri.reshape(-1, 3), np.arange(3 * len(tri), dtype=np.int64).reshape(-1, 3))


def occluded_embree(
    mesh: trimesh.Trimesh | ArrayLike,
    points: ArrayLike,
    eye: ArrayLike,
    *,
    face_index: ArrayLike | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    stats: dict[str, int] | None = None,
) -> NDArray[np.bool_]:
    """Condition (b) of the module definition, with Embree proposing the occluders.

    Same result as :func:`occluded_numpy` (Sryamkin et al. 2023, Eq. 1-10), at BVH speed.
    One ray per point is cast *from the camera* towards the point, over the part of the
    segment inside the mesh's bounding sphere and ending ``tolerance`` short of the point;
    Embree (float32) returns the first face on it.  The float32 traps, and how each is
    closed:

    * **False hits** (Embree reports a face the exact segment misses, e.g. at an edge) and
      **near misses**: every hit is re-decided in float64 by the exact kernel for that
      (point, face) pair; Embree never decides alone that a point is hidden.
    * **Self-hits**: a hit on the point's own face (``face_index``) or within ``tolerance``
      of the point (own surface, coplanar duplicate faces; at grazing angles float32 can
      place these well before the point) is rejected and the ray is re-cast from just past
      it, the step doubling while the same face comes back, rather than the point being
      declared visible.
    * **Shared edges**: a face rejected because the exact segment misses it (the ray grazes
      one of its edges) may hide a neighbour that the exact segment does hit.  Skipping past
      it could lose that neighbour, so such rays, and any ray still undecided after
      ``_EMBREE_MAX_CASTS`` casts, are decided by :func:`occluded_numpy` against all faces.
    * **Creases at the point's own face**: seen at a grazing angle, the segment can cross a
      face adjacent to the point's own face within float32 noise of their shared edge, and
      Embree's ray passes on the own face's side, reporting nothing.  With ``face_index``,
      the points where that is geometrically possible (see ``_EMBREE_CREASE_BAND``) get the
      faces sharing a vertex position with their own face decided exactly.

    What remains possible is a float32 *miss* of a face the exact segment meets within
    ~1e-7 of an unshared edge, or, without ``face_index``, at a crease as above.  Measured
    against :func:`occluded_numpy` on the 27 ModelNet meshes of the test data (20 000
    points × 10 views each, half of the views without ``face_index``): 1 miss in 5.4
    million (point, view) pairs, at a crease without ``face_index``; before the crease
    pass there were 3, all at creases.

    Parameters
    ----------
    mesh : trimesh.Trimesh or (F, 3, 3) float
        The occluders, object frame.  For a ``Trimesh`` the Embree scene is built once and
        cached (while the mesh lives and its vertices and faces are unchanged), so many
        cameras of one mesh share it; for raw triangles it is rebuilt on every call.
    points : (N, 3) float
        The points to test, object frame.
    eye : (3,) float
        Camera centre, object frame.
    face_index : (N,) int, optional
        Face each point lies on (index into ``mesh.faces`` / ``triangles``).
    tolerance : float
        As in :func:`occluded_numpy` (object units, default 1e-6).
    stats : dict, optional
        If given, filled with counters: ``rays``, ``casts``, ``accepted``,
        ``rejected_self`` (own face / within tolerance, re-cast), ``rejected_miss``
        (float32 hit the exact test refutes), ``crease`` (points found hidden by the crease
        pass) and ``exact_fallback`` (rays decided by :func:`occluded_numpy`).

    Returns
    -------
    occluded : (N,) bool

    Raises
    ------
    BackendUnavailable
        If ``embreex`` is not installed (``pip install embreex``).
    InvalidInputError
        On bad shapes, NaN/inf, ``face_index`` out of range or a negative tolerance.
    """
    scene = _embree_scene(mesh)
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), scene.n_faces)
    e = _check_eye(eye)
    tol = _check_tolerance(tolerance)
    counters = dict.fromkeys(
        ("rays", "casts", "accepted", "rejected_self", "rejected_miss", "crease", "exact_fallback"), 0
    )
    occluded = np.zeros(len(pts), dtype=bool)
    if scene.n_faces == 0 or len(pts) == 0:
        if stats is not None:
            stats.update(counters)
        return occluded

    seg = e - pts
    seg_len = np.sqrt(_dot3(seg, seg))
    with np.errstate(divide="ignore", invalid="ignore"):
        direction = -seg / seg_len[:, None]  # unit, camera → point
    # Ray parameter s = distance from the camera.  Occluders lie at s in [0, L - tol) and
    # inside the bounding sphere: clip the cast to that, which keeps float32 coordinates
    # small (origins near the mesh, not at the camera) and the cast short.
    margin = _EMBREE_SPHERE_MARGIN * scene.radius
    to_centre = e - scene.centre
    b = _dot3(direction, to_centre)
    disc = b * b - (_dot3(to_centre, to_centre) - (scene.radius + margin) ** 2)
    root = np.sqrt(np.maximum(disc, 0.0))
    s_lo = np.maximum(-b - root, 0.0)
    s_hi = np.minimum(seg_len - tol, -b + root)
    live = np.flatnonzero((seg_len > tol) & (disc > 0.0) & (s_hi > s_lo))
    counters["rays"] = len(live)

    first_step = _EMBREE_FIRST_STEP * scene.radius
    crease_band = _EMBREE_CREASE_BAND * scene.radius
    step = np.full(len(pts), first_step)
    last_face = np.full(len(pts), -1, dtype=np.int64)
    fallback = np.zeros(len(pts), dtype=bool)
    for _ in range(_EMBREE_MAX_CASTS):
        if len(live) == 0:
            break
        counters["casts"] += len(live)
        face, t_hit = scene.first_hits(e + s_lo[live, None] * direction[live], direction[live], s_hi[live] - s_lo[live])
        hit = face >= 0
        live, face, t_hit = live[hit], face[hit], t_hit[hit]  # rays that hit nothing are done
        if len(live) == 0:
            break
        own = fi[live] if fi is not None else None
        accept = _pair_occludes(pts[live], seg[live], seg_len[live], scene.planes, face, own, tol)
        occluded[live[accept]] = True
        counters["accepted"] += int(accept.sum())
        live, face, t_hit = live[~accept], face[~accept], t_hit[~accept]
        # Why was each hit rejected?  Own face, or the exact line meets the closed face
        # within tolerance of the point (either side): the point's own surface, step past
        # it.  Otherwise the exact segment misses the face: float32 grazed an edge, and a
        # neighbour across that edge may be the true occluder, hidden in the step we would
        # skip; decide those rays exactly.
        own_surface = _near_own_surface(pts[live], seg[live], seg_len[live], scene.planes.take(face), tol)
        if fi is not None:
            own_surface |= face == fi[live]
        fallback[live[~own_surface]] = True
        counters["rejected_miss"] += int((~own_surface).sum())
        counters["rejected_self"] += int(own_surface.sum())
        live, face, t_hit = live[own_surface], face[own_surface], t_hit[own_surface]
        again = face == last_face[live]
        step[live] = np.where(again, 2.0 * step[live], first_step)
        last_face[live] = face
        s_lo[live] += t_hit + step[live]
        live = live[s_hi[live] > s_lo[live]]
    else:
        fallback[live] = True

    if fi is not None:
        # Creases at the point's own face: the segment can cross a face adjacent to it
        # within float32 noise eps of their shared boundary, where Embree's ray passes on
        # the own face's side and reports nothing.  The crossing X is then within eps of the
        # own face's plane and boundary, so with d = |X - p|, c = |cos(segment, own normal)|
        # and b = distance from p to its face's boundary: d c <= eps and b <= d + eps, hence
        # b c <= 2 eps.  Those points get the faces around their own face decided exactly.
        idx = np.flatnonzero(~occluded & ~fallback)
        idx = idx[_boundary_times_cos(scene.planes.take(fi[idx]), pts[idx], direction[idx]) <= crease_band]
        k, g = scene.faces_around(fi[idx])
        for c0 in range(0, len(k), DEFAULT_PAIRS_PER_CHUNK):
            kc, gc = idx[k[c0 : c0 + DEFAULT_PAIRS_PER_CHUNK]], g[c0 : c0 + DEFAULT_PAIRS_PER_CHUNK]
            crease = _pair_occludes(pts[kc], seg[kc], seg_len[kc], scene.planes, gc, fi[kc], tol)
            counters["crease"] += int(np.count_nonzero(crease & ~occluded[kc]))
            occluded[kc[crease]] = True

    if fallback.any():
        idx = np.flatnonzero(fallback)
        counters["exact_fallback"] = len(idx)
        if len(idx) <= _FEW_FALLBACK_RAYS:
            # A few rays: faces whose bounding box meets the segment's are the only
            # candidates; cheaper than the image-plane cull, which projects every face.
            for k in idx:
                lo, hi = np.minimum(pts[k], e) - tol, np.maximum(pts[k], e) + tol
                g = np.flatnonzero(np.all((scene.face_lo <= hi) & (scene.face_hi >= lo), axis=1))
                kk = np.full(len(g), k)
                hit = _pair_occludes(pts[kk], seg[kk], seg_len[kk], scene.planes, g, None if fi is None else fi[kk], tol)
                occluded[k] = bool(hit.any())
        else:
            occluded[idx] = _occluded_core(
                scene.planes, pts[idx], e, fi[idx] if fi is not None else None, tol, DEFAULT_PAIRS_PER_CHUNK
            )
    log.debug("occluded_embree: %s", counters)
    if stats is not None:
        stats.update(counters)
    return occluded


# =========================================================================================
# Registered HSR methods
# =========================================================================================
def _visible(
    occluded_fn: Callable[..., NDArray[np.bool_]],
    occluders: Any,
    points: NDArray[np.floating],
    camera: Camera,
    face_index: NDArray[np.integer] | None,
    n_faces: int,
    tolerance: float,
    planes: TrianglePlanes,
) -> NDArray[np.bool_]:
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), n_faces)
    visible = visible_in_frustum(
        pts,
        camera,
        lambda idx: occluded_fn(
            occluders, pts[idx], camera.eye, face_index=None if fi is None else fi[idx], tolerance=tolerance
        ),
    )
    # Rule (b) of visibility.definition: own face seen edge-on (issue 11).
    return hide_edge_on(visible, planes, pts, camera.eye, fi, tolerance)


@register("oracle")
def oracle_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    **_ignored: Any,
) -> NDArray[np.bool_]:
    """Exact HSR, Embree-accelerated: ``camera.in_frustum(points) & ~occluded_embree(...)``.

    The ground-truth definition is in the module docstring (Sryamkin et al. 2023, Eq. 1-10).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The occluding surface, world frame; its Embree scene is cached across cameras.
    points : (N, 3) float
        Points on the surface, world frame.
    camera : Camera
        Pose and intrinsics.
    face_index : (N,) int, optional
        Face each point was sampled on; it never hides its own point.
    tolerance : float
        Occluders closer than this to the point are ignored (object units, default 1e-6).
    **_ignored
        Options of other methods (``resolution``, ...), accepted and ignored so that one
        option set can be passed to several methods.

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    BackendUnavailable
        If ``embreex`` is not installed (``pip install embreex``).
    InvalidInputError
        On bad ``points``, ``face_index`` or ``tolerance``.
    """
    log_ignored("oracle", _ignored)
    return _visible(occluded_embree, mesh, points, camera, face_index, len(mesh.faces), tolerance, mesh_planes(mesh))


@register("oracle-numpy")
def oracle_numpy_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    **_ignored: Any,
) -> NDArray[np.bool_]:
    """Exact HSR in pure numpy: ``camera.in_frustum(points) & ~occluded_numpy(...)``.

    O(N·F); meant for small meshes and for checking ``"oracle"``.  Parameters, returns and
    ignored options as :func:`oracle_visible`; raises :class:`InvalidInputError` on bad input.
    """
    log_ignored("oracle-numpy", _ignored)
    return _visible(occluded_numpy, mesh_planes(mesh), points, camera, face_index, len(mesh.faces), tolerance, mesh_planes(mesh))
