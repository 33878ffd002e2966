"""The paper's segment/triangle test (Sryamkin, Msallam & Klestov 2023, §3.1, §3.5, Eq. 1-10), in float64.

The one kernel behind every exact decision of :mod:`zbuf_occlude.visibility`: the oracles
(:mod:`.oracle_numpy`, :mod:`.oracle_embree`), the paper's object-space methods
(:mod:`.face_scan`) and the z-buffer's CPU resolve all test a (point, face) pair with the
functions below, always with the same arithmetic, so two methods can differ only in *which*
pairs they test, never in how a pair is decided.

* :class:`TrianglePlanes`, :func:`triangle_planes`, :func:`mesh_planes`: per-face planes
  (Eq. 1-3 and the edge planes of Eq. 7-10), computed once per mesh;
* :func:`segment_plane` (Eq. 4-6) and :func:`inside_triangle` (Eq. 7-10): the two halves of
  the test, on broadcast arrays;
* :func:`segment_hits_triangles`: the whole test, public and broadcasting;
* :func:`pair_occludes`: the oracle's condition (b) for (point, face) pairs (see
  :mod:`.oracle`).

Edge planes are moved out by 1e-12 of each triangle's coordinate scale so that a segment
through an edge shared by two faces cannot round to outside both (the paper's edge tests
alone are not watertight).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.cache import MeshCache

__all__ = [
    "PACKED_COLUMNS",
    "pack_planes",
    "TrianglePlanes",
    "triangle_planes",
    "mesh_planes",
    "segment_plane",
    "inside_triangle",
    "segment_hits_triangles",
    "pair_occludes",
    "near_own_surface",
    "boundary_times_cos",
    "dot3",
    "cross",
    "check_eye",
    "check_tolerance",
    "SCENE_CACHE_SIZE",
]

#: Outward shift of each triangle's edge planes, relative to its coordinate scale: far above
#: float64 rounding (~1e-16) and far below any mesh feature, it makes shared edges watertight.
_EDGE_SLACK = 1e-12
#: Meshes whose planes (and Embree scenes, :mod:`.oracle_embree`) stay cached (least
#: recently used evicted).
SCENE_CACHE_SIZE = 8


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


def dot3(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    # Written out, not einsum/matmul (whose summation order and FMA use depend on shapes
    # and BLAS): a (point, face) pair must get the same bits whatever the arrays around it,
    # or the numpy and Embree oracles could disagree on the same pair.
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    # np.cross, spelled out for the same reason as dot3.
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
    normal = cross(b - a, c - a)
    edge_normals = np.stack([cross(normal, b - a), cross(normal, c - b), cross(normal, a - c)], axis=-2)
    edge_offsets = np.stack(
        [dot3(edge_normals[..., 0, :], a), dot3(edge_normals[..., 1, :], b), dot3(edge_normals[..., 2, :], c)],
        axis=-1,
    )
    # Watertightness: move each edge plane outwards by _EDGE_SLACK times the triangle's
    # coordinate scale, so a segment through an edge shared by two faces, whose
    # intersection point rounds (~1e-16 relative) to just outside both, still hits one.
    scale = 1.0 + np.abs(tri).max(axis=(-2, -1))
    edge_offsets = edge_offsets - _EDGE_SLACK * scale[..., None] * np.sqrt(dot3(edge_normals, edge_normals))
    return TrianglePlanes(tri, normal, dot3(normal, a), edge_normals, edge_offsets)


def segment_plane(
    p: NDArray[np.float64], seg: NDArray[np.float64], normal: NDArray[np.float64], offset: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Eq. 4-6: parameter ``t`` of ``X = p + t · seg`` on the plane, and ``0 <= t <= 1``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (offset - dot3(normal, p)) / dot3(normal, seg)
    # A segment parallel to the plane has n · seg == 0, so t is ±inf or NaN and fails both
    # comparisons: parallel means no hit, as in the paper.
    return t, (t >= 0.0) & (t <= 1.0)


def inside_triangle(
    p: NDArray[np.float64],
    seg: NDArray[np.float64],
    t: NDArray[np.float64],
    edge_normals: NDArray[np.float64],
    edge_offsets: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Eq. 7-10: ``X = p + t · seg`` on the inner side of the three edge planes (inclusive)."""
    with np.errstate(invalid="ignore"):
        x = p + t[..., None] * seg
        inside = dot3(x, edge_normals[..., 0, :]) >= edge_offsets[..., 0]
        inside &= dot3(x, edge_normals[..., 1, :]) >= edge_offsets[..., 1]
        inside &= dot3(x, edge_normals[..., 2, :]) >= edge_offsets[..., 2]
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
    t, on_segment = segment_plane(p, seg, planes.normal, planes.offset)
    hit = on_segment & inside_triangle(p, seg, t, planes.edge_normals, planes.edge_offsets)
    distance = np.where(hit, t * np.sqrt(dot3(seg, seg)), np.inf)
    return hit, distance


def pair_occludes(
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
    t, ok = segment_plane(p, seg, planes.normal[face_ids], planes.offset[face_ids])
    ok &= t * seg_len > tolerance
    if own_face is not None:
        ok &= face_ids != own_face
    # Gather the edge planes only for pairs that cross the plane on the counted part.
    f = face_ids[ok]
    ok[ok] = inside_triangle(p[ok], seg[ok], t[ok], planes.edge_normals[f], planes.edge_offsets[f])
    return ok


def near_own_surface(
    p: NDArray[np.float64],
    seg: NDArray[np.float64],
    seg_len: NDArray[np.float64],
    planes: TrianglePlanes,
    tolerance: float,
) -> NDArray[np.bool_]:
    """(K,) bool: the line through ``p`` along ``seg`` meets the closed face at ``|d| <= tolerance``."""
    t, _ = segment_plane(p, seg, planes.normal, planes.offset)
    with np.errstate(invalid="ignore"):
        near = np.abs(t * seg_len) <= tolerance
    near[near] = inside_triangle(p[near], seg[near], t[near], planes.edge_normals[near], planes.edge_offsets[near])
    return near


def boundary_times_cos(planes: TrianglePlanes, p: NDArray[np.float64], direction: NDArray[np.float64]) -> NDArray[np.float64]:
    """(K,) ``b · |cos θ|``: ``b`` the distance from ``p[k]`` (on triangle k) to the triangle's
    edge lines, ``θ`` the angle between ``direction[k]`` (unit) and the triangle's normal."""
    with np.errstate(divide="ignore", invalid="ignore"):
        edge_dist = (dot3(p[:, None, :], planes.edge_normals) - planes.edge_offsets) / np.sqrt(
            dot3(planes.edge_normals, planes.edge_normals)
        )
        cos = np.abs(dot3(direction, planes.normal)) / np.sqrt(dot3(planes.normal, planes.normal))
    # Degenerate faces give NaN: keep those points in (NaN fails every "> band" test).
    return np.nan_to_num(np.abs(edge_dist).min(axis=1) * cos, nan=0.0)


#: float64 values per face in :func:`pack_planes`'s rows.
PACKED_COLUMNS = 16


def pack_planes(planes: TrianglePlanes) -> NDArray[np.float64]:
    """``(F, 16) float64``, C-contiguous: one row per face, ``normal (3)``, ``offset``, three ``edge normals (3 × 3)``,
    three ``edge offsets``: what :func:`zbuf_occlude.visibility.kernels.pair_occludes_one` reads."""
    n = int(planes.offset.shape[0])
    packed = np.empty((n, PACKED_COLUMNS))
    packed[:, 0:3] = planes.normal
    packed[:, 3] = planes.offset
    packed[:, 4:13] = planes.edge_normals.reshape(n, 9)
    packed[:, 13:16] = planes.edge_offsets
    return packed


def check_eye(eye: ArrayLike) -> NDArray[np.float64]:
    e = np.asarray(eye, dtype=np.float64)
    if e.shape != (3,) or not np.all(np.isfinite(e)):
        raise InvalidInputError(f"eye must be a finite (3,) vector, got {e!r}")
    return e


def check_tolerance(tolerance: float) -> float:
    try:
        tol = float(tolerance)
    except (TypeError, ValueError):
        tol = math.nan
    if not (math.isfinite(tol) and tol >= 0.0):
        raise InvalidInputError(f"tolerance must be finite and >= 0, got {tolerance!r}")
    return tol


#: Face planes of the meshes in use (:func:`mesh_planes`).
_planes_cache: MeshCache[TrianglePlanes] = MeshCache(lambda mesh: triangle_planes(mesh.triangles), SCENE_CACHE_SIZE)


def mesh_planes(mesh: trimesh.Trimesh) -> TrianglePlanes:
    """The :func:`triangle_planes` of ``mesh``, cached per mesh object (rebuilt after edits).

    Shared by the oracles and the paper's object-space methods, so that many cameras of
    one mesh compute the planes once.
    """
    return _planes_cache(mesh)
