"""The paper's own object-space hidden surface removal (HSR) family.

Sryamkin, Msallam & Klestov, "A method to create real-like point clouds for 3D object
classification", Front. Robot. AI 9 (2023), §3.3, §3.5 and §3.6.  Every method decides
occlusion with the paper's segment/triangle test (Eq. 1-10), in float64, with the planes
of :func:`zbuf_occlude.visibility.oracle.triangle_planes`; what differs is *which*
segments are tested against *which* faces.

Registered methods (:func:`~zbuf_occlude.visibility.registry.visible_mask`)
-----------------------------------------------------------------------------
``"paper-vertex"`` (§3.3, Fig. 3-4)
    Test the mesh's vertices; delete every face with an occluded vertex; a sampled point
    is visible iff its face survived.  :func:`paper_vertex_visible`.
``"paper-exact"`` (§3.5)
    Test every sampled point against every face, stopping at the first occluder.  Same
    definition as the oracle, so the same answer.  :func:`paper_exact_visible`.
``"paper-pruned"``, ``"paper-pruned-plane"`` (§3.6, first and second suggestions)
    As ``paper-exact``, but a face that is farther from the camera than the tested point
    is excluded.  :func:`paper_pruned_visible`.
``"og"``, ``"og16"``, ``"og32"``, ``"og64"``, ``"og128"`` (§3.6, third suggestion)
    Occupancy grid: one test per occupied cell; every point takes its cell's answer.
    :func:`og_visible` (the reading of the paper implemented is documented there).

Every method returns ``camera.in_frustum(points) & ~occluded``, like the oracle.

Two backends run the same arithmetic (:func:`occluded_by_faces`):

``"numba"``
    A compiled loop, parallel over points, that visits faces one by one and stops at the
    first occluder, as the paper describes.  It is a line-by-line transcription of the
    float64 kernel of :func:`~zbuf_occlude.visibility.oracle.segment_hits_triangles`
    (same operations in the same order, no fused multiply-add), so it decides every
    (point, face) pair bit for bit as the numpy kernel does; ``tests/test_object_space.py``
    checks this.  Needs ``pip install 'zbuf-occlude[fast]'`` (numba).
``"numpy"``
    The oracle's own kernel functions on blocks of (point, face) pairs, a block of faces
    at a time, dropping a point as soon as a block occludes it.  No dependency; memory
    stays below ``pairs_per_chunk`` pairs (~150 bytes each) whatever N × F is.

``"auto"`` (default) takes numba when it imports.  Either backend needs O(N + F) memory
besides its pair blocks, so 1M points × 200k faces run in bounded memory (slowly: O(N·F)
is what §3.6 sets out to reduce).
"""

from __future__ import annotations

import functools
import importlib.util
import logging
import math
from typing import Any

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from ..cameras import Camera
from ..errors import BackendUnavailable, InvalidInputError
from .oracle import (
    DEFAULT_PAIRS_PER_CHUNK,
    TrianglePlanes,
    _inside_triangle,
    _segment_plane,
    mesh_planes,
)
from .registry import (
    DEFAULT_SELF_HIT_TOLERANCE,
    check_face_index,
    check_points,
    log_ignored,
    register,
    visible_in_frustum,
)

__all__ = [
    "BACKENDS",
    "DEFAULT_GRID",
    "DEFAULT_OG_REPRESENTATIVE",
    "OG_GRIDS",
    "PRUNE_RULES",
    "occluded_by_faces",
    "plane_distance",
    "min_sample_distance",
    "face_keys",
    "surviving_faces",
    "occupancy_grid",
    "paper_vertex_visible",
    "paper_exact_visible",
    "paper_pruned_visible",
    "og_visible",
    "numba_available",
]

log = logging.getLogger(__name__)

#: Accepted values of every ``backend`` argument of this module.
BACKENDS = ("auto", "numba", "numpy")
#: Cells per axis of ``"og"`` when ``grid`` is not given: the paper's OG_32 (§3.6, Table 1B).
DEFAULT_GRID = 32
#: Grid sizes registered as their own method names (``"og16"`` ... ``"og128"``); the paper
#: reports OG_32 and OG_64, 16 and 128 bracket them for the agreement-vs-grid sweep.
OG_GRIDS = (16, 32, 64, 128)
#: How ``"og"`` represents a cell: ``"centre"`` or ``"point"`` (see :func:`og_visible`).
DEFAULT_OG_REPRESENTATIVE = "point"
#: Pruning rules of :func:`face_keys`: ``"plane"`` is §3.6's first suggestion, ``"samples"``
#: its second; ``paper-pruned`` applies both.
PRUNE_RULES = ("plane", "samples")
#: Points per block of the numpy backend; with ``pairs_per_chunk`` pairs a block meets
#: ``pairs_per_chunk // 256`` faces at a time, small enough that a hidden point stops
#: being tested soon after its first occluder, large enough to amortise numpy's overhead.
_NUMPY_POINTS_PER_BLOCK = 256
#: Columns of the packed per-face rows the numba kernel reads: normal (3), offset (1),
#: edge normals (9), edge offsets (3), so that one face is two cache lines.
_PACKED_COLUMNS = 16


# =========================================================================================
# The kernel: Eq. 1-10, one face at a time (numba) or in pair blocks (numpy)
# =========================================================================================
def numba_available() -> bool:
    """True when numba can be imported (the ``"numba"`` backend)."""
    return importlib.util.find_spec("numba") is not None


# ``prange`` is ``range`` until numba is imported by _numba_kernel(), which rebinds it to
# numba.prange before compiling, so that this module imports without numba.
prange = range


def _occluded_loop(points, eye, packed, own_face, end, tolerance, out):  # pragma: no cover - compiled
    # Transcription of oracle._segment_plane + oracle._inside_triangle for one pair at a
    # time: keep every operation and its order, or the two backends could disagree.
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
            if j == own:
                continue
            row = packed[j]
            # Eq. 4-6: t = (n·A - n·p) / (n·(e - p)); a parallel segment gives inf/nan
            # and fails the comparisons below (error_model="numpy": no exception).
            t = (row[3] - (row[0] * px + row[1] * py + row[2] * pz)) / (row[0] * sx + row[1] * sy + row[2] * sz)
            if not (t >= 0.0 and t <= 1.0):
                continue
            if not (t * seg_len > tolerance):
                continue
            # Eq. 7-10: X = p + t (e - p) on the inner side of the three edge planes.
            x0 = px + t * sx
            x1 = py + t * sy
            x2 = pz + t * sz
            if (
                x0 * row[4] + x1 * row[5] + x2 * row[6] >= row[13]
                and x0 * row[7] + x1 * row[8] + x2 * row[9] >= row[14]
                and x0 * row[10] + x1 * row[11] + x2 * row[12] >= row[15]
            ):
                out[k] = True
                break


@functools.cache
def _numba_kernel() -> Any:
    try:
        import numba
    except ImportError as exc:
        raise BackendUnavailable(
            f"backend='numba' needs numba: pip install 'zbuf-occlude[fast]' ({exc}); or use backend='numpy'"
        ) from None
    globals()["prange"] = numba.prange
    # cache=True keeps the compiled kernel in __pycache__ (compiling takes seconds);
    # error_model="numpy" makes x / 0 give inf/nan like numpy instead of raising.
    return numba.njit(parallel=True, cache=True, error_model="numpy", nogil=True)(_occluded_loop)


def _resolve_backend(backend: str) -> str:
    if backend not in BACKENDS:
        raise InvalidInputError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "auto":
        return "numba" if numba_available() else "numpy"
    return backend


def _n_faces(planes: TrianglePlanes) -> int:
    return int(planes.offset.shape[0])


def _pack(planes: TrianglePlanes) -> NDArray[np.float64]:
    packed = np.empty((_n_faces(planes), _PACKED_COLUMNS))
    packed[:, 0:3] = planes.normal
    packed[:, 3] = planes.offset
    packed[:, 4:13] = planes.edge_normals.reshape(-1, 9)
    packed[:, 13:16] = planes.edge_offsets
    return packed


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
    if n_points == 0 or _n_faces(planes) == 0:
        return occluded
    seg = eye - points
    # Written-out dot product, as the oracle's kernel computes it (einsum may round differently).
    seg_len = np.sqrt(seg[:, 0] * seg[:, 0] + seg[:, 1] * seg[:, 1] + seg[:, 2] * seg[:, 2])
    # Points with similar face ranges share blocks, so a block's faces are few.
    order = np.argsort(end, kind="stable")
    point_block = min(_NUMPY_POINTS_PER_BLOCK, max(1, pairs_per_chunk))
    face_block = max(1, pairs_per_chunk // point_block)
    face_pos = np.arange(_n_faces(planes), dtype=np.int64)
    for start in range(0, n_points, point_block):
        active = order[start : start + point_block]
        stop = int(end[active].max())
        for f0 in range(0, stop, face_block):
            active = active[end[active] > f0]
            if len(active) == 0:
                break
            fb = slice(f0, min(f0 + face_block, stop))
            p, s, ln = points[active][:, None, :], seg[active][:, None, :], seg_len[active][:, None]
            t, ok = _segment_plane(p, s, planes.normal[None, fb], planes.offset[None, fb])
            ok &= t * ln > tolerance
            ok &= face_pos[None, fb] < end[active][:, None]
            if own_face is not None:
                ok &= face_pos[None, fb] != own_face[active][:, None]
            i, j = np.nonzero(ok)
            inside = _inside_triangle(p[i, 0], s[i, 0], t[i, j], planes.edge_normals[fb][j], planes.edge_offsets[fb][j])
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
        Planes of the F faces, from :func:`~zbuf_occlude.visibility.oracle.triangle_planes`.
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
    e = np.asarray(eye, dtype=np.float64)
    if e.shape != (3,) or not np.all(np.isfinite(e)):
        raise InvalidInputError(f"eye must be a finite (3,) vector, got {eye!r}")
    tol = float(tolerance)
    if not (math.isfinite(tol) and tol >= 0.0):
        raise InvalidInputError(f"tolerance must be finite and >= 0, got {tolerance!r}")
    if int(pairs_per_chunk) < 1:
        raise InvalidInputError(f"pairs_per_chunk must be >= 1, got {pairs_per_chunk!r}")
    n_faces = _n_faces(planes)
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
            _pack(ordered),
            own if own is not None else np.zeros(0, dtype=np.int64),
            end,
            tol,
            out,
        )
        return out
    return _occluded_numpy_blocks(ordered, pts, e, own, end, tol, int(pairs_per_chunk))


# =========================================================================================
# Face keys for §3.6's exclusion rules
# =========================================================================================
def plane_distance(planes: TrianglePlanes, eye: ArrayLike) -> NDArray[np.float64]:
    """Distance from ``eye`` to each face's plane: §3.6's first exclusion rule.

    Every point of face ``f`` is at least ``plane_distance[f]`` from the camera, so a face
    whose plane is farther than the tested point cannot hide it: the rule is exact.

    Parameters
    ----------
    planes : TrianglePlanes
        F faces.
    eye : (3,) float
        Camera centre, object frame.

    Returns
    -------
    distance : (F,) float64
        Object units; ``+inf`` for degenerate faces (zero normal), which never hide anything.
    """
    e = np.asarray(eye, dtype=np.float64)
    norm = np.sqrt(np.einsum("ij,ij->i", planes.normal, planes.normal))
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.abs(planes.normal @ e - planes.offset) / norm
    return np.where(norm > 0.0, d, np.inf)


def min_sample_distance(
    triangles: NDArray[np.float64],
    eye: ArrayLike,
    points: NDArray[np.float64] | None = None,
    face_index: NDArray[np.int64] | None = None,
) -> NDArray[np.float64]:
    """Smallest camera distance of the points known on each face: §3.6's second rule.

    The points of face ``f`` are its three corners and the sampled points with
    ``face_index == f``.  The corners are included so that every face has a key (a face
    that drew no sample would otherwise never be excluded) and because, for a face small
    against its camera distance, the nearest point is a corner.  The rule is a heuristic:
    a face seen nearly face-on can come closer to the camera than all its known points
    (the plane rule bounds that case), so it can exclude a true occluder; the agreement
    with the oracle in docs/results measures how often.

    Parameters
    ----------
    triangles : (F, 3, 3) float64
    eye : (3,) float
    points : (N, 3) float64, optional
    face_index : (N,) int64, optional
        Both or neither.

    Returns
    -------
    distance : (F,) float64
        Object units.
    """
    e = np.asarray(eye, dtype=np.float64)
    corners = triangles - e
    d = np.sqrt(np.einsum("fkj,fkj->fk", corners, corners)).min(axis=1)
    if points is not None and face_index is not None and len(points):
        diff = points - e
        np.minimum.at(d, face_index, np.sqrt(np.einsum("ij,ij->i", diff, diff)))
    return d


def face_keys(
    mesh: trimesh.Trimesh,
    planes: TrianglePlanes,
    eye: NDArray[np.float64],
    rules: tuple[str, ...],
    points: NDArray[np.float64] | None,
    face_index: NDArray[np.int64] | None,
) -> NDArray[np.float64]:
    """(F,) float64: the exclusion key of each face under ``rules`` (max of the rules' keys).

    A face is excluded for a point whose camera distance is below the key: see
    :func:`plane_distance` (``"plane"``) and :func:`min_sample_distance` (``"samples"``).

    Raises
    ------
    InvalidInputError
        On an empty or unknown rule.
    """
    if not rules or any(r not in PRUNE_RULES for r in rules):
        raise InvalidInputError(f"prune rules must be a non-empty subset of {PRUNE_RULES}, got {rules!r}")
    key = np.full(_n_faces(planes), -np.inf)
    if "plane" in rules:
        key = np.maximum(key, plane_distance(planes, eye))
    if "samples" in rules:
        key = np.maximum(key, min_sample_distance(np.asarray(mesh.triangles), eye, points, face_index))
    return key


def _camera_distance(points: NDArray[np.float64], eye: NDArray[np.float64]) -> NDArray[np.float64]:
    diff = eye - points
    return np.sqrt(np.einsum("ij,ij->i", diff, diff))


def _parse_rules(prune: str | tuple[str, ...] | list[str]) -> tuple[str, ...]:
    rules = tuple(r.strip() for r in prune.split(",")) if isinstance(prune, str) else tuple(prune)
    if not rules or any(r not in PRUNE_RULES for r in rules):
        raise InvalidInputError(f"prune must name rules among {PRUNE_RULES} (e.g. 'plane,samples'), got {prune!r}")
    return rules


# =========================================================================================
# §3.5: exact
# =========================================================================================
@register("paper-exact")
def paper_exact_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    face_order: str = "mesh",
    backend: str = "auto",
    pairs_per_chunk: int = DEFAULT_PAIRS_PER_CHUNK,
    **_ignored: Any,
) -> NDArray[np.bool_]:
    """The paper's exact HSR: every sampled point against every face (Sryamkin et al. 2023, §3.5).

    Sample first, then for each point test the segment to the camera against the faces,
    one by one, with Eq. 1-10, stopping at the first occluder.  The definition is the
    oracle's (:mod:`zbuf_occlude.visibility.oracle`), so the answer equals
    ``"oracle-numpy"`` bit for bit and ``"oracle"`` up to Embree's documented float32
    residue; only the cost differs: O(N·F) pair tests, fewer for hidden points.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The occluders, world frame.
    points : (N, 3) float
        Points on the surface, world frame.
    camera : Camera
        Pose and intrinsics; points outside the frustum are not visible.
    face_index : (N,) int, optional
        Face each point was sampled on; it never hides its own point.
    tolerance : float
        Hits within this distance of the point are its own surface (object units, 1e-6).
    face_order : {"mesh", "near-first"}
        Order in which faces are visited: the file's (the paper's loop), or by increasing
        camera distance of their nearest corner (an ablation: it separates the gain of
        §3.6's exclusion from that of meeting occluders sooner).  Never changes the answer.
    backend : {"auto", "numba", "numpy"}
        See the module docstring.
    pairs_per_chunk : int
        numpy backend: most (point, face) pairs held at once.
    **_ignored
        Options of other methods, accepted and ignored.

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    InvalidInputError
        Bad input or an unknown ``face_order``/``backend``.
    BackendUnavailable
        ``backend="numba"`` without numba.
    """
    log_ignored("paper-exact", _ignored)
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), len(mesh.faces))
    planes = mesh_planes(mesh)
    if face_order == "mesh":
        order = None
    elif face_order == "near-first":
        order = np.argsort(min_sample_distance(np.asarray(mesh.triangles), camera.eye), kind="stable")
    else:
        raise InvalidInputError(f"face_order must be 'mesh' or 'near-first', got {face_order!r}")

    def decide(idx: NDArray[np.int64]) -> NDArray[np.bool_]:
        return occluded_by_faces(
            planes,
            pts[idx],
            camera.eye,
            face_index=None if fi is None else fi[idx],
            tolerance=tolerance,
            order=order,
            backend=backend,
            pairs_per_chunk=pairs_per_chunk,
        )

    return visible_in_frustum(pts, camera, decide)


# =========================================================================================
# §3.6, first and second suggestions: exclude faces farther than the point
# =========================================================================================
@register("paper-pruned")
def paper_pruned_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    prune: str | tuple[str, ...] = PRUNE_RULES,
    backend: str = "auto",
    pairs_per_chunk: int = DEFAULT_PAIRS_PER_CHUNK,
    **_ignored: Any,
) -> NDArray[np.bool_]:
    """``paper-exact`` with faces farther from the camera than the point excluded (§3.6).

    Sryamkin et al. 2023, §3.6, first and second suggestions.  For a point at camera
    distance ``d``, face ``f`` is not tested when its key exceeds ``d``, the key being the
    largest of the rules in ``prune``:

    ``"plane"`` (first suggestion)
        The distance from the camera to the face's plane (:func:`plane_distance`): every
        point of the face is at least that far, so the rule is exact.
    ``"samples"`` (second suggestion)
        The smallest camera distance of the points sampled inside the face, corners
        included (:func:`min_sample_distance`): a heuristic that may exclude an occluder
        seen nearly face-on.

    The faces are visited nearest key first, so the faces a point meets are a prefix
    and excluded faces cost nothing (see :func:`occluded_by_faces`).  With
    ``prune="plane"`` (method ``"paper-pruned-plane"``) the answer equals ``paper-exact``'s.

    Parameters
    ----------
    mesh, points, camera, face_index, tolerance, backend, pairs_per_chunk
        As :func:`paper_exact_visible`.
    prune : str or tuple of str
        Rules among ``("plane", "samples")``, e.g. ``"plane,samples"`` (default: both).
    **_ignored
        Options of other methods, accepted and ignored.

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    InvalidInputError
        Bad input or unknown rules.
    BackendUnavailable
        ``backend="numba"`` without numba.
    """
    log_ignored("paper-pruned", _ignored)
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), len(mesh.faces))
    rules = _parse_rules(prune)
    planes = mesh_planes(mesh)
    eye = np.asarray(camera.eye, dtype=np.float64)
    key = face_keys(mesh, planes, eye, rules, pts if fi is not None else None, fi)

    def decide(idx: NDArray[np.int64]) -> NDArray[np.bool_]:
        return occluded_by_faces(
            planes,
            pts[idx],
            eye,
            face_index=None if fi is None else fi[idx],
            tolerance=tolerance,
            face_key=key,
            limit=_camera_distance(pts[idx], eye),
            backend=backend,
            pairs_per_chunk=pairs_per_chunk,
        )

    return visible_in_frustum(pts, camera, decide)


@register("paper-pruned-plane")
def paper_pruned_plane_visible(
    mesh: trimesh.Trimesh, points: NDArray[np.floating], camera: Camera, **options: Any
) -> NDArray[np.bool_]:
    """``paper-pruned`` with the first suggestion of §3.6 only (exact): see :func:`paper_pruned_visible`."""
    options["prune"] = ("plane",)
    return paper_pruned_visible(mesh, points, camera, **options)


# =========================================================================================
# §3.3: vertices
# =========================================================================================
def _subdivide(mesh: trimesh.Trimesh, max_edge: float) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """Fig. 4: split faces until no edge is longer than ``max_edge``; (vertices, faces, parent)."""
    if not (math.isfinite(max_edge) and max_edge > 0.0):
        raise InvalidInputError(f"max_edge must be finite and > 0 object units, got {max_edge!r}")
    longest = float(np.max(mesh.edges_unique_length)) if len(mesh.faces) else 0.0
    # Each pass halves every edge longer than max_edge, so log2(longest / max_edge) passes
    # are enough; one more absorbs rounding.
    passes = max(1, math.ceil(math.log2(max(longest / max_edge, 1.0))) + 1)
    vertices, faces, parent = trimesh.remesh.subdivide_to_size(
        mesh.vertices, mesh.faces, max_edge, max_iter=passes, return_index=True
    )
    return np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64), np.asarray(parent, dtype=np.int64)


def _locate_in_children(
    triangles: NDArray[np.float64],
    parent: NDArray[np.int64],
    points: NDArray[np.float64],
    face_index: NDArray[np.int64],
    pairs_per_chunk: int,
) -> NDArray[np.int64]:
    """(N,) int64: the sub-face (child of ``face_index[k]``) that contains point ``k``.

    Each point is compared with every child of its face: the child whose smallest
    barycentric coordinate is largest contains it (ties on shared edges go to either).
    """
    children = np.argsort(parent, kind="stable")
    first = np.searchsorted(parent[children], np.arange(parent.max() + 1 if len(parent) else 0))
    count = np.bincount(parent, minlength=len(first))
    best = np.empty(len(points), dtype=np.int64)
    n_per_point = count[face_index]
    block = max(1, pairs_per_chunk // max(1, int(n_per_point.max(initial=1))))
    for s in range(0, len(points), block):
        sl = slice(s, s + block)
        reps = n_per_point[sl]
        owner = np.repeat(np.arange(len(reps)), reps)
        offset = np.arange(len(owner)) - np.repeat(np.cumsum(reps) - reps, reps)
        child = children[first[face_index[sl]][owner] + offset]
        tri = triangles[child]
        bary = trimesh.triangles.points_to_barycentric(tri, points[sl][owner])
        score = bary.min(axis=1)
        # Best child per point: sort by (owner, -score) and take each owner's first.
        pick = np.lexsort((-score, owner))
        firsts = pick[np.r_[0, np.flatnonzero(np.diff(owner[pick])) + 1]]
        best[sl] = child[firsts]
    return best


def surviving_faces(
    mesh: trimesh.Trimesh,
    camera: Camera,
    *,
    max_edge: float | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    backend: str = "auto",
    pairs_per_chunk: int = DEFAULT_PAIRS_PER_CHUNK,
) -> tuple[trimesh.Trimesh, NDArray[np.bool_], NDArray[np.int64]]:
    """The paper's vertex-based HSR: faces with no occluded vertex (Sryamkin et al. 2023, §3.3).

    Each vertex's segment to the camera is tested against every face (Eq. 1-10, stop at
    the first occluder; faces through the vertex meet it at distance 0 <= ``tolerance``
    and do not count); every face with at least one occluded vertex is deleted.  Vertices
    with the same coordinates (ModelNet's triangle soup repeats them) are tested once.
    With ``max_edge``, faces are first split until no edge is longer (Fig. 4), which
    shrinks the faces that one occluded corner deletes whole.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame.
    camera : Camera
    max_edge : float, optional
        Longest edge after subdivision, object units; ``None`` (default) keeps the faces.
    tolerance, backend, pairs_per_chunk
        As :func:`occluded_by_faces`.

    Returns
    -------
    tested : trimesh.Trimesh
        The mesh whose faces were tested (``mesh`` itself without ``max_edge``).
    survived : (F',) bool
        Per face of ``tested``: no vertex occluded.  Sample these faces to get the paper's
        §3.3 output cloud.
    parent : (F',) int64
        Index into ``mesh.faces`` of each face of ``tested``.

    Raises
    ------
    InvalidInputError
        Bad ``max_edge``/``tolerance``/``backend``.
    BackendUnavailable
        ``backend="numba"`` without numba.
    """
    if max_edge is None:
        tested, parent = mesh, np.arange(len(mesh.faces), dtype=np.int64)
    else:
        vertices, faces, parent = _subdivide(mesh, float(max_edge))
        tested = trimesh.Trimesh(vertices, faces, process=False)
    vertices = np.asarray(tested.vertices, dtype=np.float64)
    faces = np.asarray(tested.faces, dtype=np.int64)
    used, corner_of = np.unique(faces.ravel(), return_inverse=True)
    unique_xyz, xyz_of = np.unique(vertices[used], axis=0, return_inverse=True)
    occluded_xyz = occluded_by_faces(
        mesh_planes(tested),
        unique_xyz,
        camera.eye,
        tolerance=tolerance,
        backend=backend,
        pairs_per_chunk=pairs_per_chunk,
    )
    corner_occluded = occluded_xyz[xyz_of.ravel()][corner_of.ravel()].reshape(faces.shape)
    return tested, ~corner_occluded.any(axis=1), parent


@register("paper-vertex")
def paper_vertex_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    max_edge: float | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    backend: str = "auto",
    pairs_per_chunk: int = DEFAULT_PAIRS_PER_CHUNK,
    **_ignored: Any,
) -> NDArray[np.bool_]:
    """Vertex-based HSR (Sryamkin et al. 2023, §3.3): a point is visible iff its face survived.

    :func:`surviving_faces` decides the faces; the paper then samples the surviving faces.
    To compare with the other methods on the same points, a sampled point counts as
    visible iff it is in the frustum and the face it lies on (after subdivision, the
    sub-face that contains it) survived.

    Parameters
    ----------
    mesh, points, camera, tolerance, backend, pairs_per_chunk
        As :func:`paper_exact_visible`.
    face_index : (N,) int, optional
        Face of each point; found with trimesh's closest-point query when missing (slower).
    max_edge : float, optional
        Subdivide faces first (Fig. 4), object units; ``None`` (default) does not.
    **_ignored
        Options of other methods, accepted and ignored.

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    InvalidInputError, BackendUnavailable
        As :func:`surviving_faces`.
    """
    log_ignored("paper-vertex", _ignored)
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), len(mesh.faces))
    if fi is None:
        log.debug("paper-vertex: no face_index, locating points with a closest-point query")
        _, _, fi = trimesh.proximity.closest_point(mesh, pts)
        fi = np.asarray(fi, dtype=np.int64)
    tested, survived, parent = surviving_faces(
        mesh, camera, max_edge=max_edge, tolerance=tolerance, backend=backend, pairs_per_chunk=pairs_per_chunk
    )
    if max_edge is not None:
        fi = _locate_in_children(np.asarray(tested.triangles), parent, pts, fi, pairs_per_chunk)
    return camera.in_frustum(pts) & survived[fi]


# =========================================================================================
# §3.6, third suggestion: occupancy grid
# =========================================================================================
def occupancy_grid(
    points: NDArray[np.floating], grid: int
) -> tuple[NDArray[np.float64], NDArray[np.int64], float]:
    """Occupied cells of an ``grid``³ occupancy grid of the points (Sryamkin et al. 2023, §3.6).

    The grid spans the cube that bounds the points: centred on their bounding box, side
    equal to its largest extent (so cells are cubes, as in VoxNet's input), split into
    ``grid`` cells per axis.  Points on the upper faces of the cube go to the last cell.

    Parameters
    ----------
    points : (N, 3) float
    grid : int
        Cells per axis, >= 1.

    Returns
    -------
    centres : (M,) x 3 float64
        Centres of the M occupied cells, object frame.
    cell_of : (N,) int64
        Index into ``centres`` of the cell of each point.
    cell_size : float
        Side of a cell, object units.

    Raises
    ------
    InvalidInputError
        On ``grid < 1`` or bad points.
    """
    pts = check_points(points)
    if isinstance(grid, bool) or int(grid) != grid or int(grid) < 1:
        raise InvalidInputError(f"grid must be an integer >= 1 (cells per axis), got {grid!r}")
    grid = int(grid)
    if len(pts) == 0:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64), 0.0
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    side = float((hi - lo).max())
    if side == 0.0:  # all points coincide: one cell of any size holds them
        side = 1.0
    corner = (lo + hi) / 2.0 - side / 2.0
    cell_size = side / grid
    ijk = np.clip(np.floor((pts - corner) / cell_size).astype(np.int64), 0, grid - 1)
    linear = (ijk[:, 0] * grid + ijk[:, 1]) * grid + ijk[:, 2]
    occupied, cell_of = np.unique(linear, return_inverse=True)
    cells = np.stack([occupied // (grid * grid), (occupied // grid) % grid, occupied % grid], axis=1)
    return corner + (cells + 0.5) * cell_size, cell_of.astype(np.int64), cell_size


@register("og")
def og_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    grid: int = DEFAULT_GRID,
    representative: str = DEFAULT_OG_REPRESENTATIVE,
    prune: str | tuple[str, ...] = PRUNE_RULES,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    backend: str = "auto",
    pairs_per_chunk: int = DEFAULT_PAIRS_PER_CHUNK,
    **_ignored: Any,
) -> NDArray[np.bool_]:
    """Occupancy-grid HSR, one test per occupied cell (Sryamkin et al. 2023, §3.6, third suggestion).

    The paper says only that the sampled points are turned into an N×N×N occupancy grid
    and that occlusion is decided for the occupied cells instead of the points, each point
    taking its cell's answer (OG_32, OG_64 in Table 1B).  The reading implemented here:

    1. Grid: :func:`occupancy_grid` of the sampled points (cubic cells over the points'
       bounding cube).
    2. One segment per occupied cell, from the cell's representative to the camera,
       tested against the faces with the paper's Eq. 1-10 and the same exclusion as
       ``paper-pruned`` (``prune``: faces whose key exceeds the representative's camera
       distance are not tested).
    3. A point is visible iff it is in the frustum and its cell's segment is not occluded.

    The representative (``representative``):

    ``"point"`` (default)
        The sampled point nearest the cell centre, tested exactly as ``paper-exact``
        tests a point (its own face excluded, ``tolerance``).  It lies on the surface, so
        the cell's answer is right for it and wrong only for cell-mates that differ from
        it: cells that straddle a silhouette or an occlusion boundary, or hold two
        surfaces (thin walls).  That error is confined to boundary cells and shrinks as
        ``grid`` grows (measured: ~98 % agreement at OG_32, ~99.5 % at OG_64, ~99.9 % at
        OG_128 on ModelNet bathtub/sofa, 10k points; lower on thin chairs).
    ``"centre"``
        The cell centre, with hits closer to it than half the cell diagonal ignored (the
        cell's own surface; with a 1e-6 tolerance the surface passing in front of the
        centre inside the cell would hide it).  The literal "segment from the cell
        centre" reading, kept for comparison: a centre behind a slanted surface meets it
        at ``h / cos θ`` > ``h``, so ~7 % of points come out falsely hidden *whatever the
        grid size* on the same meshes; it does not converge, which is why it is not the
        default.

    Either way the cost is one test per occupied cell (at most N³, whatever the number of
    points), which is where Table 1B's saving comes from.

    Parameters
    ----------
    mesh, points, camera, face_index, tolerance, backend, pairs_per_chunk
        As :func:`paper_pruned_visible` (``face_index`` feeds the ``"samples"`` rule and
        the own-face exclusion of the ``"point"`` representative).
    grid : int
        Cells per axis (default 32, the paper's OG_32).  Methods ``"og16"`` ...
        ``"og128"`` fix it.
    representative : {"point", "centre"}
        See above (default :data:`DEFAULT_OG_REPRESENTATIVE`).
    prune : str or tuple of str
        Exclusion rules, as in :func:`paper_pruned_visible` (default: both).
    **_ignored
        Options of other methods, accepted and ignored.

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    InvalidInputError
        Bad input, ``grid < 1``, an unknown representative or unknown rules.
    BackendUnavailable
        ``backend="numba"`` without numba.
    """
    log_ignored("og", _ignored)
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), len(mesh.faces))
    rules = _parse_rules(prune)
    centres, cell_of, cell_size = occupancy_grid(pts, grid)
    visible = camera.in_frustum(pts)
    if len(pts) == 0:
        return visible
    planes = mesh_planes(mesh)
    eye = np.asarray(camera.eye, dtype=np.float64)
    key = face_keys(mesh, planes, eye, rules, pts if fi is not None else None, fi)
    # Only cells holding an in-frustum point need a test.
    needed = np.unique(cell_of[visible])
    occluded_cell = np.zeros(len(centres), dtype=bool)
    if representative == "centre":
        half_diagonal = cell_size * math.sqrt(3.0) / 2.0
        occluded_cell[needed] = occluded_by_faces(
            planes,
            centres[needed],
            eye,
            tolerance=half_diagonal,
            face_key=key,
            limit=_camera_distance(centres[needed], eye) - half_diagonal,
            backend=backend,
            pairs_per_chunk=pairs_per_chunk,
        )
    elif representative == "point":
        rep = _point_nearest_centre(pts, centres, cell_of)[needed]
        occluded_cell[needed] = occluded_by_faces(
            planes,
            pts[rep],
            eye,
            face_index=None if fi is None else fi[rep],
            tolerance=tolerance,
            face_key=key,
            limit=_camera_distance(pts[rep], eye),
            backend=backend,
            pairs_per_chunk=pairs_per_chunk,
        )
    else:
        raise InvalidInputError(f"representative must be 'centre' or 'point', got {representative!r}")
    return visible & ~occluded_cell[cell_of]


def _point_nearest_centre(
    points: NDArray[np.float64], centres: NDArray[np.float64], cell_of: NDArray[np.int64]
) -> NDArray[np.int64]:
    """(M,) int64: per occupied cell, the index of its sampled point nearest its centre."""
    diff = points - centres[cell_of]
    order = np.lexsort((np.einsum("ij,ij->i", diff, diff), cell_of))
    first = np.r_[0, np.flatnonzero(np.diff(cell_of[order])) + 1]
    return order[first]


def _og_fixed(size: int) -> Any:
    def og_fixed(mesh: trimesh.Trimesh, points: NDArray[np.floating], camera: Camera, **options: Any) -> NDArray[np.bool_]:
        options["grid"] = size  # the name fixes the grid; a shared "grid" option is for "og"
        return og_visible(mesh, points, camera, **options)

    og_fixed.__name__ = og_fixed.__qualname__ = f"og{size}_visible"
    og_fixed.__doc__ = f"``og`` with ``grid={size}`` (Sryamkin et al. 2023, §3.6); see :func:`og_visible`."
    return og_fixed


for _size in OG_GRIDS:
    register(f"og{_size}")(_og_fixed(_size))
del _size
