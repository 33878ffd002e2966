"""The Embree oracle: Intel Embree proposes each ray's occluder, Eq. 1-10 decides it.

:func:`occluded_embree` gives the same answer as :func:`~.oracle_numpy.occluded_numpy` (the
oracle's condition (b), :mod:`.oracle`) at BVH speed: Embree (float32, through ``embreex``)
proposes the candidate occluder of each ray, and every candidate is re-decided in float64 by
the kernel of :mod:`.segment_triangle`, so Embree's rounding can cost at most a missed
candidate, never a false occluder.  How the float32 traps are handled is documented on the
function.  The driver lives in its own module, as trimesh keeps ``ray/ray_pyembree.py``.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numba
import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.defaults import DEFAULT_SELF_HIT_TOLERANCE
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.geometry.grouping import exact_face_groups
from zbuf_occlude.mesh.cache import MeshCache
from zbuf_occlude.visibility.kernels import pair_occludes_one
from zbuf_occlude.visibility.oracle_numpy import DEFAULT_PAIRS_PER_CHUNK, occluded_unchecked
from zbuf_occlude.visibility.registry import check_face_index, check_points
from zbuf_occlude.visibility.segment_triangle import (
    SCENE_CACHE_SIZE,
    TrianglePlanes,
    boundary_times_cos,
    check_eye,
    check_tolerance,
    dot3,
    mesh_planes,
    near_own_surface,
    pack_planes,
    pair_occludes,
    triangle_planes,
)

__all__ = ["occluded_embree", "position_ranks"]

log = logging.getLogger(__name__)

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
#: Up to this many rays that Embree could not settle are decided one by one against the
#: faces whose bounding boxes meet their segment; more go through the image-plane cull.
_FEW_FALLBACK_RAYS = 64


class _EmbreeScene:
    """An Embree BVH of one mesh plus its float64 planes (for re-deciding Embree's hits)."""

    def __init__(self, vertices: NDArray[np.float64], faces: NDArray[np.int64], planes: TrianglePlanes | None = None) -> None:
        try:
            from embreex import rtcore_scene
            from embreex.mesh_construction import TriangleMesh
        except ImportError as exc:
            raise BackendUnavailable(
                f"the 'oracle' visibility method needs Embree: pip install embreex ({exc}); or use method='oracle-numpy'"
            ) from None
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        self.n_faces = len(faces)
        self.planes = triangle_planes(vertices[faces]) if planes is None else planes
        self.packed_planes = pack_planes(self.planes)  # rows of kernels.pair_occludes_one (crease re-checks)
        # Faces with bit-identical vertices (same order) give bit-identical tests, so one face
        # per group stands for all: the BVH, the adjacency and the exact fallback hold only
        # these.  A mesh of m copies of one face (ModelNet repeats faces; a hostile file can
        # hold 1e6 copies) then costs each ray O(1) tests there instead of O(m).
        group = exact_face_groups(self.planes.vertices) if len(faces) else np.zeros(0, dtype=np.int64)
        #: (K,) int64: the faces listed, one per group of identical faces (the lowest index).
        self.listed = np.flatnonzero(group == np.arange(len(faces)))
        #: (F,) int64: each face's group as a position in :attr:`listed`.
        self.listed_pos = np.searchsorted(self.listed, group)
        #: The planes of the :attr:`listed` faces.
        self.listed_planes = self.planes.take(self.listed)
        used = vertices[faces].reshape(-1, 3)
        # Float32 is most precise near 0, so the BVH is built around the bounding-box centre.
        self.centre = (used.min(axis=0) + used.max(axis=0)) / 2.0 if len(used) else np.zeros(3)
        self.radius = float(np.sqrt(dot3(used - self.centre, used - self.centre)).max()) if len(used) else 0.0
        # Faces around each vertex (CSR), vertices merged by position: ModelNet files often
        # repeat a vertex per face, and adjacency has to follow geometry, not indices.
        corner_vertex = position_ranks(used)
        self.corner_vertex = corner_vertex.reshape(-1, 3)
        listed_corners = self.corner_vertex[self.listed].reshape(-1)
        order = np.argsort(listed_corners, kind="stable")
        #: (K,) the listed faces around each vertex (CSR, rows ``vertex_start[v]:vertex_start[v + 1]``).
        self.vertex_faces = self.listed[order // 3]
        self.vertex_start = np.searchsorted(listed_corners[order], np.arange(corner_vertex.max(initial=-1) + 2))
        # Bounding boxes of the listed faces, for deciding a few fallback rays without a full cull.
        self.face_lo = self.listed_planes.vertices.min(axis=-2)
        self.face_hi = self.listed_planes.vertices.max(axis=-2)
        self.scene = None
        if self.n_faces:
            # Robust mode: watertight ray/triangle tests (no leaks through shared edges).
            self.scene = rtcore_scene.EmbreeScene(robust=True)
            TriangleMesh(
                scene=self.scene,
                vertices=np.ascontiguousarray(vertices - self.centre, dtype=np.float32),
                indices=np.ascontiguousarray(faces[self.listed], dtype=np.int32),
            )

    def faces_around(self, face: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Pairs ``(k, g)``: listed face ``g`` shares a vertex position with ``face[k]`` (its own
        group's listed face included); one face per group of identical faces."""
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
        prim = out["primID"].astype(np.int64)
        return np.where(prim >= 0, self.listed[np.maximum(prim, 0)], -1), out["tfar"].astype(np.float64)


def _ordered_bits(values: NDArray[np.float64]) -> NDArray[np.uint64]:
    """Unsigned integers in the order of the float64 ``values`` (finite; -0.0 and 0.0 one key)."""
    bits = (np.ascontiguousarray(values, dtype=np.float64) + 0.0).view(np.uint64)  # + 0.0: -0.0 becomes 0.0
    return np.where(bits >> np.uint64(63), ~bits, bits | np.uint64(1 << 63))


def position_ranks(positions: NDArray[np.float64]) -> NDArray[np.int64]:
    """(N,) int64: each row's rank among the distinct rows of the finite ``positions`` (N, 3),
    sorted lexicographically by value: ``np.unique(positions, axis=0, return_inverse=True)[1]``,
    by one ``np.lexsort`` of integer keys instead of a sort of structured rows (5x faster)."""
    keys = _ordered_bits(positions)
    order = np.lexsort((keys[:, 2], keys[:, 1], keys[:, 0]))
    keys = keys[order]
    new = np.ones(len(keys), dtype=bool)
    new[1:] = (keys[1:] != keys[:-1]).any(axis=1)
    ranks = np.empty(len(keys), dtype=np.int64)
    ranks[order] = np.cumsum(new) - 1
    return ranks


def _occluded_few_py(idx, pts, seg, seg_len, eye, face_lo, face_hi, listed, packed, own, tolerance, occluded):
    """``occluded[k]`` for ``k`` in ``idx``: a listed face whose bounding box meets the segment's
    box (grown by ``tolerance``) occludes point ``k`` by the exact pair test (``own``: the
    points' faces, never their occluders; empty: none)."""
    has_own = len(own) > 0
    for j in range(len(idx)):
        k = idx[j]
        lo0, hi0 = min(pts[k, 0], eye[0]) - tolerance, max(pts[k, 0], eye[0]) + tolerance
        lo1, hi1 = min(pts[k, 1], eye[1]) - tolerance, max(pts[k, 1], eye[1]) + tolerance
        lo2, hi2 = min(pts[k, 2], eye[2]) - tolerance, max(pts[k, 2], eye[2]) + tolerance
        hit = False
        for q in range(len(listed)):
            if not (
                face_lo[q, 0] <= hi0
                and face_lo[q, 1] <= hi1
                and face_lo[q, 2] <= hi2
                and face_hi[q, 0] >= lo0
                and face_hi[q, 1] >= lo1
                and face_hi[q, 2] >= lo2
            ):
                continue
            g = listed[q]
            if has_own and g == own[k]:
                continue
            if pair_occludes_one(pts[k, 0], pts[k, 1], pts[k, 2], seg[k, 0], seg[k, 1], seg[k, 2], seg_len[k], packed[g], tolerance):
                hit = True
                break
        occluded[k] = hit


_occluded_few = numba.njit(cache=True, nogil=True, error_model="numpy")(_occluded_few_py)


# _EmbreeScene is looked up at build time (tests count the builds by patching it).
_scenes: MeshCache[_EmbreeScene] = MeshCache(
    lambda mesh: _EmbreeScene(mesh.vertices, mesh.faces, planes=mesh_planes(mesh)), SCENE_CACHE_SIZE
)


def scene_for(mesh: trimesh.Trimesh) -> _EmbreeScene:
    """The cached Embree scene of ``mesh`` (:class:`~zbuf_occlude.mesh.cache.MeshCache`)."""
    return _scenes(mesh)


def _embree_scene(mesh: trimesh.Trimesh | ArrayLike) -> _EmbreeScene:
    if isinstance(mesh, trimesh.Trimesh):
        return scene_for(mesh)
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
    e = check_eye(eye)
    tol = check_tolerance(tolerance)
    counters = dict.fromkeys(("rays", "casts", "accepted", "rejected_self", "rejected_miss", "crease", "exact_fallback"), 0)
    occluded = np.zeros(len(pts), dtype=bool)
    if scene.n_faces and len(pts):
        rays = _sightlines(pts, e, fi, tol)
        fallback = _cast(scene, rays, occluded, counters)
        if fi is not None:
            _crease_pass(scene, rays, occluded, fallback, counters)
        if fallback.any():
            _decide_exactly(scene, rays, np.flatnonzero(fallback), occluded, counters)
        log.debug("occluded_embree: %s", counters)
    if stats is not None:
        stats.update(counters)
    return occluded


class _Sightlines(NamedTuple):
    """The segments of one :func:`occluded_embree` call, from each point to the eye (float64)."""

    pts: NDArray[np.float64]  # (N, 3) the points, object frame
    eye: NDArray[np.float64]  # (3,) the camera centre
    seg: NDArray[np.float64]  # (N, 3) eye - point
    seg_len: NDArray[np.float64]  # (N,) |seg|
    direction: NDArray[np.float64]  # (N, 3) unit, camera → point
    face_index: NDArray[np.int64] | None  # (N,) each point's face, or None
    tolerance: float


def _sightlines(pts: NDArray[np.float64], eye: NDArray[np.float64], fi: NDArray[np.int64] | None, tol: float) -> _Sightlines:
    seg = eye - pts
    seg_len = np.sqrt(dot3(seg, seg))
    with np.errstate(divide="ignore", invalid="ignore"):
        direction = -seg / seg_len[:, None]  # unit, camera → point
    return _Sightlines(pts, eye, seg, seg_len, direction, fi, tol)


def _clip_to_sphere(scene: _EmbreeScene, rays: _Sightlines) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """``(s_lo, s_hi, live)``: each ray's cast, as distances from the camera, and the rays with one to cast.

    Occluders lie at ``s`` in ``[0, L - tol)`` and inside the bounding sphere: the cast is
    clipped to that, which keeps float32 coordinates small (origins near the mesh, not at the
    camera) and the cast short."""
    margin = _EMBREE_SPHERE_MARGIN * scene.radius
    to_centre = rays.eye - scene.centre
    b = dot3(rays.direction, to_centre)
    # r² - (squared distance from the centre to the line), from the perpendicular vector: the
    # textbook b² - (|c|² - r²) cancels two terms of size R² and loses the sphere entirely
    # for a far camera (R = 1e7: eps · R² ≈ 0.02, the size of r² itself).
    perp = to_centre - b[:, None] * rays.direction
    disc = (scene.radius + margin) ** 2 - dot3(perp, perp)
    root = np.sqrt(np.maximum(disc, 0.0))
    s_lo = np.maximum(-b - root, 0.0)
    s_hi = np.minimum(rays.seg_len - rays.tolerance, -b + root)
    live = np.flatnonzero((rays.seg_len > rays.tolerance) & (disc > 0.0) & (s_hi > s_lo))
    return s_lo, s_hi, live


def _cast(scene: _EmbreeScene, rays: _Sightlines, occluded: NDArray[np.bool_], counters: dict[str, int]) -> NDArray[np.bool_]:
    """Cast every ray with Embree, re-deciding each hit exactly, into ``occluded``; return the
    (N,) rays left for the exact fallback (an edge grazed, or ``_EMBREE_MAX_CASTS`` spent)."""
    pts, seg, seg_len, fi, tol = rays.pts, rays.seg, rays.seg_len, rays.face_index, rays.tolerance
    s_lo, s_hi, live = _clip_to_sphere(scene, rays)
    counters["rays"] = len(live)
    first_step = _EMBREE_FIRST_STEP * scene.radius
    step = np.full(len(pts), first_step)
    last_face = np.full(len(pts), -1, dtype=np.int64)
    fallback = np.zeros(len(pts), dtype=bool)
    for _ in range(_EMBREE_MAX_CASTS):
        if len(live) == 0:
            break
        counters["casts"] += len(live)
        face, t_hit = scene.first_hits(rays.eye + s_lo[live, None] * rays.direction[live], rays.direction[live], s_hi[live] - s_lo[live])
        hit = face >= 0
        live, face, t_hit = live[hit], face[hit], t_hit[hit]  # rays that hit nothing are done
        if len(live) == 0:
            break
        own = fi[live] if fi is not None else None
        accept = pair_occludes(pts[live], seg[live], seg_len[live], scene.planes, face, own, tol)
        occluded[live[accept]] = True
        counters["accepted"] += int(accept.sum())
        live, face, t_hit = live[~accept], face[~accept], t_hit[~accept]
        if len(live) == 0:  # (the common end: every hit accepted)
            break
        # Why was each hit rejected?  Own face, or the exact line meets the closed face
        # within tolerance of the point (either side): the point's own surface, step past
        # it.  Otherwise the exact segment misses the face: float32 grazed an edge, and a
        # neighbour across that edge may be the true occluder, hidden in the step we would
        # skip; decide those rays exactly.
        own_surface = near_own_surface(pts[live], seg[live], seg_len[live], scene.planes.take(face), tol)
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
    return fallback


def _crease_pass(scene: _EmbreeScene, rays: _Sightlines, occluded: NDArray[np.bool_], fallback: NDArray[np.bool_],
                 counters: dict[str, int]) -> None:  # fmt: skip
    """Creases at the point's own face (needs ``face_index``), into ``occluded``.

    The segment can cross a face adjacent to the own face within float32 noise eps of their
    shared boundary, where Embree's ray passes on the own face's side and reports nothing.
    The crossing X is then within eps of the own face's plane and boundary, so with
    d = |X - p|, c = |cos(segment, own normal)| and b = distance from p to its face's
    boundary: d c <= eps and b <= d + eps, hence b c <= 2 eps.  Those points get the faces
    around their own face decided exactly."""
    pts, seg, seg_len, fi, tol = rays.pts, rays.seg, rays.seg_len, rays.face_index, rays.tolerance
    idx = np.flatnonzero(~occluded & ~fallback)
    if len(idx) == 0:
        return
    idx = idx[boundary_times_cos(scene.planes.take(fi[idx]), pts[idx], rays.direction[idx]) <= _EMBREE_CREASE_BAND * scene.radius]
    k, g = scene.faces_around(fi[idx])
    for c0 in range(0, len(k), DEFAULT_PAIRS_PER_CHUNK):
        kc, gc = idx[k[c0 : c0 + DEFAULT_PAIRS_PER_CHUNK]], g[c0 : c0 + DEFAULT_PAIRS_PER_CHUNK]
        crease = pair_occludes(pts[kc], seg[kc], seg_len[kc], scene.planes, gc, fi[kc], tol)
        counters["crease"] += int(np.count_nonzero(crease & ~occluded[kc]))
        occluded[kc[crease]] = True


def _decide_exactly(scene: _EmbreeScene, rays: _Sightlines, idx: NDArray[np.int64], occluded: NDArray[np.bool_],
                    counters: dict[str, int]) -> None:  # fmt: skip
    """The rays ``idx`` Embree could not settle, decided against every face, into ``occluded``."""
    fi = rays.face_index
    counters["exact_fallback"] = len(idx)
    if len(idx) <= _FEW_FALLBACK_RAYS:
        # A few rays: faces whose bounding box meets the segment's are the only
        # candidates; cheaper than the image-plane cull, which projects every face.
        _occluded_few(
            idx, rays.pts, rays.seg, rays.seg_len, rays.eye, scene.face_lo, scene.face_hi, scene.listed, scene.packed_planes,
            fi if fi is not None else np.zeros(0, dtype=np.int64), rays.tolerance, occluded,
        )  # fmt: skip
    else:
        occluded[idx] = occluded_unchecked(
            scene.listed_planes, rays.pts[idx], rays.eye, scene.listed_pos[fi[idx]] if fi is not None else None, rays.tolerance,
            DEFAULT_PAIRS_PER_CHUNK,
        )  # fmt: skip
