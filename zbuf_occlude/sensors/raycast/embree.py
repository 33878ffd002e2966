"""First hits of many rays from one origin on a triangle mesh: Embree (reference) and z-buffer (GPU).

Both return the hit face and the float64 ray parameter, decided exactly in float64 on the hit
face (Möller–Trumbore), so that the backends differ only in *which* face they pick.

* :func:`cast_embree`: Embree (embreex, through trimesh) finds the first face in float32;
  the distance is then recomputed in float64 on that face.
* :func:`cast_embree_beyond`: every hit along each ray, not only the first: Embree cast again
  from just beyond each hit on a surface that transmits (a leafy layer, a pane), up to
  ``max_hits`` per ray.  The z-buffer keeps one face per pixel, the nearest, so only Embree
  gives the hits behind it.
* :func:`~zbuf_occlude.sensors.raycast.zbuffer.cast_zbuffer` (its own module): the scene is rasterised from the ray origin with moderngl (one
  perspective view for rays inside a cone, else the six faces of a cube map) into face-id
  images; each ray's candidates are the faces seen in the ``(2r+1)²`` pixels around its
  projection, tested exactly on the GPU (``render/shaders/scan_candidates.comp``), as the z-buffer
  visibility method decides points (:mod:`zbuf_occlude.visibility.zbuffer`); the distance on
  the chosen face is recomputed in float64.  Rays whose window shows faces but none of them
  is hit (sub-pixel faces, cracks) are decided by Embree.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.mesh.cache import MeshCache

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = ["BACKENDS", "MAX_HITS", "cast_embree", "cast_embree_beyond", "face_normals", "ray_triangle_f64"]

log = logging.getLogger(__name__)

#: Ray-casting backends of :func:`zbuf_occlude.sensors.scan`.
BACKENDS = ("embree", "zbuffer")

#: Barycentric widening of the exact test: float64 rounding is ~1e-16 relative; a ray through a
#: shared edge must hit one of the two faces.
EDGE_EPSILON = 1e-10

#: Most hits :func:`cast_embree_beyond` finds along one ray by default: one per LAS return number
#: (:data:`~zbuf_occlude.sensors.beam.echoes.MAX_RETURNS`, 15) and one more.
MAX_HITS = 16

#: :func:`cast_embree_beyond` starts each further cast this share of the scene's bounding-box
#: diagonal beyond the last hit: Embree's float32 hit has a relative error of ~1e-7 of the
#: coordinates, so a step 100× that never finds the same surface point again (a shared edge, the
#: face just left), and stays far below any receiver's range resolution (2 mm in a 230 m scene).
BEYOND_HIT_SHARE = 1e-5

#: Bytes :func:`cast_embree_beyond` holds per ray still cast (origins, starts, directions,
#: faces, ranges and masks) and per hit kept (ray, face, range), for the memory check.
_BYTES_PER_ACTIVE_RAY = 160
_BYTES_PER_HIT = 24


def _unit_normals(mesh: trimesh.Trimesh) -> NDArray[np.float64]:
    """(F, 3) float64 unit normals of every face of ``mesh`` (:func:`face_normals`)."""
    tri = np.asarray(mesh.triangles, dtype=np.float64)
    normal = np.cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :])
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-300)
    normal.flags.writeable = False
    return normal


#: Unit face normals of the scenes in use, once per mesh (rebuilt after an edit): a scan gathers
#: rows instead of a cross product per hit (the same float64 operations per face, so the same bits).
_normals = MeshCache(_unit_normals, 4)


def face_normals(mesh: trimesh.Trimesh, face: NDArray[np.int64]) -> NDArray[np.float64]:
    """``face.shape + (3,)`` float64 unit normals of faces ``face`` (int, any shape) of ``mesh``.

    Right-hand winding, ``(b − a) × (c − a)`` normalised; a degenerate face gives the zero vector.
    The one normal of every scanner's hit faces (spinning, airborne, single and multi return);
    computed once per face of a mesh and gathered (a new array the caller may change).
    """
    return _normals(mesh)[face]


def ray_triangle_f64(
    origin: NDArray[np.float64], directions: NDArray[np.float64], triangles: NDArray[np.float64], *, edge_epsilon: float = EDGE_EPSILON
):
    """Möller–Trumbore ray–triangle test in float64, vectorised.

    Parameters
    ----------
    origin : (3,) float64
    directions : (..., 3) float64
        Ray directions (need not be unit; the parameter is in units of their length).
    triangles : (..., 3, 3) float64
        Broadcast against ``directions``.

    Returns
    -------
    t : (...) float64
        Ray parameter of the supporting plane's intersection (inf where parallel).
    inside : (...) bool
        The hit lies in the triangle (barycentrics widened by ``edge_epsilon``) and ``t > 0``.

    Source: T. Möller, B. Trumbore, "Fast, minimum storage ray-triangle intersection", JGT 1997.
    """
    a = triangles[..., 0, :] - origin
    e1 = triangles[..., 1, :] - triangles[..., 0, :]
    e2 = triangles[..., 2, :] - triangles[..., 0, :]
    p = _cross(directions, e2)
    det = np.einsum("...i,...i->...", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = -a
        u = np.einsum("...i,...i->...", s, p) * inv
        q = _cross(s, e1)
        v = np.einsum("...i,...i->...", directions, q) * inv
        t = np.einsum("...i,...i->...", e2, q) * inv
        ok = np.isfinite(t) & (det != 0.0)
        inside = ok & (u >= -edge_epsilon) & (v >= -edge_epsilon) & (u + v <= 1.0 + edge_epsilon) & (t > 0.0)
    return np.where(ok, t, np.inf), inside


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``np.cross(a, b)`` of (..., 3) float64 arrays: the same products and differences in the same
    order (so the same bits), without its generic axis handling (twice as fast on a scan's rays)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    np.multiply(a[..., 1], b[..., 2], out=out[..., 0])
    out[..., 0] -= a[..., 2] * b[..., 1]
    np.multiply(a[..., 2], b[..., 0], out=out[..., 1])
    out[..., 1] -= a[..., 0] * b[..., 2]
    np.multiply(a[..., 0], b[..., 1], out=out[..., 2])
    out[..., 2] -= a[..., 1] * b[..., 0]
    return out


def _face_edges(mesh: trimesh.Trimesh) -> NDArray[np.float64]:
    """(3, 3, F) float64: each face's first vertex ``a`` and edges ``b − a``, ``c − a``, then x, y, z,
    then the face (:func:`ray_triangle_f64`'s subtractions, so the same bits): a hit gathers one
    contiguous column per face instead of its triangle's strided rows."""
    tri = np.asarray(mesh.triangles, dtype=np.float64)
    edges = np.ascontiguousarray(np.stack([tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]]).transpose(0, 2, 1))
    edges.flags.writeable = False
    return edges


#: :func:`_face_edges` of the scenes in use, once per mesh (rebuilt after an edit).
_edges = MeshCache(_face_edges, 4)


def _ray_parameter(mesh: trimesh.Trimesh, origin, directions, face) -> NDArray[np.float64]:
    """(M,) float64: the ``t`` of :func:`ray_triangle_f64` of rays ``origin`` ((3,) or (M, 3)) +
    t · ``directions`` (M, 3) on faces ``face`` (M,) of ``mesh``, without the barycentric test a
    known hit face does not need.

    The same operations, so the same bits: ``np.cross``'s products and differences, and the dot
    products summed as ``(x + z) + y``, the order in which ``np.einsum("...i,...i->...")`` adds
    the three products of contiguous (M, 3) rows; one coordinate at a time on contiguous (M,)
    arrays instead of (M, 3) rows gathered from (M, 3, 3) triangles.  The numerator
    ``e2 · ((o − a) × e1)`` depends on the face and the origin alone: from one origin, with
    no more faces than hits, it is computed once per face and gathered.
    """
    edges = _edges(mesh)
    o = np.asarray(origin, dtype=np.float64)
    if o.ndim == 1 and edges.shape[2] <= len(face):
        numerator = _plane_numerator(edges, o)[face]
        (e1x, e1y, e1z), (e2x, e2y, e2z) = np.take(edges[1:], face, axis=2)
    else:
        mine = np.take(edges, face, axis=2)
        numerator = _plane_numerator(mine, o)
        (e1x, e1y, e1z), (e2x, e2y, e2z) = mine[1:]
    dx, dy, dz = directions[:, 0], directions[:, 1], directions[:, 2]
    # det = e1 · (d × e2) = (e1x (dy e2z − dz e2y) + e1z (dx e2y − dy e2x)) + e1y (dz e2x − dx e2z), in
    # place in three buffers (the same operations: a product's factors swapped give the same bits)
    det, part, tmp = np.multiply(dy, e2z), np.multiply(dx, e2y), np.multiply(dz, e2y)
    det -= tmp
    det *= e1x
    part -= np.multiply(dy, e2x, out=tmp)
    part *= e1z
    det += part
    np.multiply(dz, e2x, out=part)
    part -= np.multiply(dx, e2z, out=tmp)
    part *= e1y
    det += part
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = np.multiply(numerator, np.divide(1.0, det, out=part), out=numerator)  # numerator: a new array of its own
    # det 0 (a degenerate face, a ray in the face's plane) makes t ±inf or nan: no range
    np.copyto(t, np.inf, where=~np.isfinite(t))
    return t


def _plane_numerator(edges: NDArray[np.float64], origin: NDArray[np.float64]) -> NDArray[np.float64]:
    """``e2 · (s × e1)`` with ``s = −(a − origin)``, per column of ``edges`` (3, 3, n) (:func:`_face_edges`);
    ``origin`` (3,) or (n, 3)."""
    (ax, ay, az), (e1x, e1y, e1z), (e2x, e2y, e2z) = edges
    sx, sy, sz = -(ax - origin[..., 0]), -(ay - origin[..., 1]), -(az - origin[..., 2])
    return (e2x * (sy * e1z - sz * e1y) + e2z * (sx * e1y - sy * e1x)) + e2y * (sz * e1x - sx * e1z)


def _exact_distance(mesh: trimesh.Trimesh, origin, directions, face):
    """float64 ray parameter on the given (hit) faces; the plane's if rounding put the hit just outside."""
    hit = face >= 0
    if not hit.any():
        return np.full(len(face), np.inf)
    # every ray, a miss on face 0 and then dropped: cheaper than gathering the hits' rows (a
    # scan's rays mostly hit), and each hit's t the same bits
    t = _ray_parameter(mesh, origin, directions, np.where(hit, face, 0))
    np.copyto(t, np.inf, where=~hit)
    return t


def _build_intersector(mesh: trimesh.Trimesh):
    try:
        from trimesh.ray.ray_pyembree import RayMeshIntersector
    except ImportError as exc:  # embreex missing
        raise BackendUnavailable(f"the 'embree' scan backend needs embreex: pip install embreex ({exc})") from None
    return RayMeshIntersector(mesh)


#: Embree BVHs of the scenes in use, rebuilt after a mesh edit (:class:`~zbuf_occlude.mesh.cache.MeshCache`).
_intersector = MeshCache(_build_intersector, 4)


def _first_faces(mesh: trimesh.Trimesh, origin: NDArray[np.float64], directions: NDArray[np.float64]) -> NDArray[np.int64]:
    """(N,) int64: the row of ``mesh.faces`` each ray ``origin + t · directions`` hits first, −1 for none.

    ``origin`` (3,) or (N, 3), ``directions`` (N, 3) float64.  trimesh's
    ``RayMeshIntersector.intersects_first``, bit for bit: the same float32 rays reach the same
    Embree scene (the origins rounded to float32, moved and scaled into the scene's frame in
    float64, rounded again; the directions rounded to float32 and divided by their norm as
    ``trimesh.util.unitize`` does, then rounded again), without its copies of every ray: one
    origin is moved once and broadcast.  Where trimesh's wrapper is not the one this mirrors
    (another trimesh version), its own call.
    """
    from trimesh.util import TOL_ZERO

    intersector = _intersector(mesh)
    wrap = intersector._scene
    scene, shift, scale = (getattr(wrap, name, None) for name in ("scene", "origin", "scale"))
    if scene is None or shift is None or scale is None:
        return np.asarray(intersector.intersects_first(np.broadcast_to(origin, directions.shape), directions), dtype=np.int64)
    # _EmbreeWrap.run's origins: float32, then float64 into the scene's frame, then float32
    moved = ((np.asarray(origin, dtype=np.float32).astype(np.float64) - shift) * scale).astype(np.float32)
    # unitize's norm (the same np.dot of the float32 squares with ones, in float64) and reciprocal
    d32 = directions.astype(np.float32)
    norm = np.sqrt(np.dot(d32 * d32, _ONES_3))
    np.reciprocal(norm, out=norm, where=norm > TOL_ZERO)
    # the float64 product rounded to float32 on the way out (unitize's float64 result, then run's astype)
    unit = np.multiply(d32, norm[:, None], out=np.empty_like(d32), casting="same_kind")
    return np.asarray(scene.run(np.broadcast_to(moved, directions.shape), unit), dtype=np.int64)


#: The ones ``trimesh.util.unitize`` sums a row's squares with (its ``[1.0] * 3``, as float64).
_ONES_3 = np.ones(3)


def cast_embree(
    mesh: trimesh.Trimesh, origin: NDArray[np.float64], directions: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """First hit of each ray ``origin + t · directions[i]``, Embree.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame.
    origin : (3,) or (N, 3) float64
        One origin for every ray, or one per ray (an airborne scanner's moving aircraft).
    directions : (N, 3) float64
        Unit vectors.

    Returns
    -------
    face : (N,) int64
        Row of ``mesh.faces`` hit first, −1 for none.
    t : (N,) float64
        Distance to the hit along the ray (float64 on the hit face), inf for none.

    Raises
    ------
    BackendUnavailable
        embreex is not installed.
    """
    directions = np.asarray(directions, dtype=np.float64)
    if len(directions) == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    face = _first_faces(mesh, origin, directions)
    return face, _exact_distance(mesh, np.asarray(origin, np.float64), directions, face)


def cast_embree_beyond(
    mesh: trimesh.Trimesh,
    origin: NDArray[np.float64],
    directions: NDArray[np.float64],
    face: NDArray[np.int64],
    t: NDArray[np.float64],
    face_transmits: NDArray[np.bool_],
    *,
    max_hits: int = MAX_HITS,
    step_m: float | None = None,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Every hit along each ray ``origin + t · directions[i]``, through the faces that transmit.

    Starting from each ray's first hit ``(face, t)`` (:func:`cast_embree` or
    :func:`cast_zbuffer`), a ray whose last hit lies on a face with ``face_transmits`` is cast
    again (Embree) from ``step_m`` beyond that hit, and so on until it hits a face that does not
    transmit, leaves the scene, or has ``max_hits`` hits.  Rays whose first hit does not
    transmit are not cast again, so a scene without transmitting faces costs nothing more.  A
    further hit must lie more than ``step_m / 2`` beyond the last one (else it is the surface
    point just left, found again through float32 rounding, and the ray steps on); two surfaces
    less than ``step_m`` apart along a ray give one hit.  Ranges are float64 on the hit face
    from the ray's own origin, as :func:`cast_embree` gives them.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame, metres.
    origin : (3,) or (N, 3) float64
        One origin for every ray, or one per ray.
    directions : (N, 3) float64
        Unit vectors.
    face : (N,) int64
        Each ray's first hit (row of ``mesh.faces``), −1 for none.
    t : (N,) float64
        Its range, metres (inf for none).
    face_transmits : (F,) bool
        Per row of ``mesh.faces``: a ray goes on through it.
    max_hits : int
        Most hits per ray, ≥ 1 (default :data:`MAX_HITS`).
    step_m : float, optional
        How far beyond a hit the next cast starts, metres, > 0; default
        :data:`BEYOND_HIT_SHARE` of the mesh's bounding-box diagonal.

    Returns
    -------
    ray : (H,) int64
        Row of ``directions`` of each hit; sorted, each ray's hits in range order.
    face : (H,) int64
        Row of ``mesh.faces`` hit (≥ 0).
    t : (H,) float64
        Range of the hit along its ray, metres; increasing within a ray.  The first hits are
        the given ones, bit for bit.

    Raises
    ------
    InvalidInputError
        ``face_transmits`` not one bool per face, ``max_hits`` below 1, ``step_m`` not > 0.
    InsufficientMemoryError
        The rays cast again and the hits kept would not fit in memory
        (:func:`zbuf_occlude.resources.check_memory`), before they are allocated.
    BackendUnavailable
        embreex is not installed (only when a ray is cast again).
    """
    from zbuf_occlude.resources import check_memory

    directions = np.asarray(directions, dtype=np.float64)
    face = np.asarray(face, dtype=np.int64)
    t = np.asarray(t, dtype=np.float64)
    transmits = np.asarray(face_transmits)
    if transmits.dtype != np.bool_ or transmits.shape != (len(mesh.faces),):
        raise InvalidInputError(
            f"face_transmits must be ({len(mesh.faces)},) bool, one per face, got shape {transmits.shape} dtype {transmits.dtype}"
        )
    if int(max_hits) != max_hits or max_hits < 1:
        raise InvalidInputError(f"max_hits must be a whole number >= 1, got {max_hits!r}")
    if step_m is None:
        step_m = (
            BEYOND_HIT_SHARE * float(np.linalg.norm(np.ptp(np.asarray(mesh.vertices, np.float64), axis=0))) if len(mesh.vertices) else 1.0
        )
    if not (np.isfinite(step_m) and step_m > 0):
        raise InvalidInputError(f"step_m must be a finite number of metres > 0, got {step_m!r}")
    first = np.flatnonzero(face >= 0)
    rays, faces, ranges = [first], [face[first]], [t[first]]
    active = first[transmits[face[first]]] if max_hits > 1 else first[:0]
    if len(active):
        check_memory(len(active) * (_BYTES_PER_ACTIVE_RAY + (max_hits - 1) * _BYTES_PER_HIT), option=f"{len(active):,} transmitting rays x max_hits {max_hits}",
                     hint="give fewer rays, fewer max_hits or fewer surfaces a transmittance")  # fmt: skip
    origins = np.broadcast_to(np.asarray(origin, dtype=np.float64), directions.shape)
    last, n_hits = t[active], np.ones(len(active), np.int64)
    # a ray that keeps finding the surface point it left steps on; bounded so that it ends
    for _ in range(2 * int(max_hits)):
        if not len(active):
            break
        o, d = origins[active], directions[active]
        start = o + (last + step_m)[:, None] * d
        f = _first_faces(mesh, start, d)
        got = f >= 0
        r = np.full(len(active), np.inf)
        if got.any():
            r[got] = _ray_parameter(mesh, o[got], d[got], f[got])
        new = got & np.isfinite(r) & (r > last + 0.5 * step_m)
        again = got & ~new
        rays.append(active[new])
        faces.append(f[new])
        ranges.append(r[new])
        n_hits += new
        go_on = again | (new & transmits[np.maximum(f, 0)] & (n_hits < max_hits))
        last = np.where(new, r, last + step_m)[go_on]
        active, n_hits = active[go_on], n_hits[go_on]
    ray = np.concatenate(rays)
    order = np.argsort(ray, kind="stable")  # each ray's hits were found in range order
    return ray[order], np.concatenate(faces)[order], np.concatenate(ranges)[order]
