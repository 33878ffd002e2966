"""``embree-fast``: a CPU z-buffer pre-pass, then float32 rays with float64 re-checks of near-ties.

The CPU path of ``auto`` (:mod:`~zbuf_occlude.visibility.auto`).  Per view, the mesh is first
rasterised on the CPU into a conservative depth/face buffer (:mod:`.cpu_zbuffer`, compiled
with numba, on the thread pool), which settles most points with a proof: hidden by a face
the oracle's own float64 pair test confirms, or visible because every other face lies
beyond the point in its cell.  Those points get the oracle's answer bit for bit.  The rest
(near silhouettes and where many faces meet; a few percent to a few tens of percent,
depending on the point density) are split into chunks cast on a thread pool (``embreex``
releases the GIL inside ``run``, and numpy does for the per-chunk arithmetic), each chunk in
two Embree ``OCCLUDED`` queries from the point towards the camera, clipped to the mesh's
bounding sphere:

1. from ``start`` to the sphere: a hit is an occluder farther than ``start`` from the point
   (float32: only a hit grazing an unshared edge can be false);
2. for the points pass 1 left visible, the band from ``band_lo`` to ``start``: a hit there
   may be the point's own surface (float32 rounding at grazing angles, a crease at its
   face's edge) or a true occluder close to it, a *near-tie*, and the point is decided by
   the exact oracle (:func:`~zbuf_occlude.visibility.oracle.occluded_embree`, float64).

With ``face_index``, ``start`` and ``band_lo`` grow as the point's face turns edge-on
(float32 puts the own plane up to ``ulp / cos`` away), so pass 1 never meets the own face.
Rule (b) of :mod:`~zbuf_occlude.visibility.definition` (edge-on faces) is then applied
exactly.  What float32 can still get wrong: an occluder closer than ``band_lo`` (a few
float32 ulps of the scene's size over ``cos``) that is not the own face, and edge grazes
in pass 1, for the points cast as rays; measured agreement with the oracle is in
``docs/results/speed.md`` (``benchmarks/bench_visibility_accuracy.py``).

Per-mesh state (the Embree BVH here, the pre-pass's face data and the oracle's planes) is
cached per mesh object (:class:`~zbuf_occlude.mesh.cache.MeshCache`), so a one-shot
:func:`embree_fast_visible` call on a mesh already seen builds nothing but the view's
buffer; it does not sort the points either (the kept :class:`FastScene` does, once).
"""

from __future__ import annotations

import itertools
import logging
import os
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numba
import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.geometry.grouping import morton_order
from zbuf_occlude.mesh.cache import MeshCache
from zbuf_occlude.visibility import cpu_zbuffer
from zbuf_occlude.visibility.definition import EDGE_ON_SIN, TOLERANCE, edge_on_any, edge_on_own
from zbuf_occlude.visibility.kernels import pair_occludes_one
from zbuf_occlude.visibility.oracle_embree import occluded_embree
from zbuf_occlude.visibility.oracle_embree import scene_for as oracle_scene
from zbuf_occlude.visibility.registry import SessionBase, check_face_index, check_points, register
from zbuf_occlude.visibility.segment_triangle import mesh_planes

__all__ = ["FastScene", "embree_fast_visible", "DEFAULT_THREADS", "set_default_threads"]

log = logging.getLogger(__name__)

#: Threads per view (default: the CPUs this process may run on; :func:`set_default_threads` changes it).
DEFAULT_THREADS = max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))
#: Pass 1 starts this far from the point (relative to the bounding sphere's radius), over
#: ``cos`` of the point's face (capped by ``_MAX_START``); without face_index, ``cos = 1``.
_START = 1e-4
_MAX_START = 2e-2
#: Pass 2 starts this far from the point (relative, over ``cos``): float32 rounding of the
#: point and the own face (a few ulps of the radius) stays below it.
_BAND_LO = 2e-6
#: Rays per chunk of the thread pool (one chunk per thread below that).
_CHUNK = 65536
#: Slices of points per thread in the pre-pass's classification: taken in turn by the threads, so
#: that a slow slice (many faces in front of its points, a thread the system runs late) leaves the
#: other threads the rest instead of being waited for; each slice costs a call.
_SLICES_PER_THREAD = 4
#: Depth slack of the frustum test, relative to the depth: float32 points within it of the near or
#: far plane are settled by the float64 frustum test of the oracle (``FRUSTUM_BORDER``).
_DEPTH_REL_MARGIN = 1e-5
#: Smallest ``|cos|`` of a sightline and its face used in divisions (an edge-on face gives 0).
_MIN_COS = 1e-30
#: Frustum border, pixels: a constant plus a share of the image size, above float32's projection
#: error (~1e-3 px at 1024²); points within it of an image edge get the float64 frustum test.
_BORDER_PX, _BORDER_PER_PX = 1e-3, 1e-5
#: Faces within this much more than the edge-on sine (float32 cosines) are re-checked in float64.
_EDGE_ON_SLACK = 1e-3


class _Intrinsics(NamedTuple):
    """The camera as _prepare reads it (float32): focal length and image size in pixels, depth
    range, and the frustum border (pixels) within which the float64 test decides."""

    focal_px: np.float32
    width: np.float32
    height: np.float32
    znear: np.float32
    zfar: np.float32
    border_px: np.float32


class _RaySettings(NamedTuple):
    """The rays' set-up (float32): the bounding sphere's radius, pass 1's start (relative, and its
    cap), pass 2's start (relative), and the cosine below which a face may be seen edge-on."""

    radius: np.float32
    start_rel: np.float32
    max_start: np.float32
    band_rel: np.float32
    edge_cos: np.float32


# Bits of a point's status from _prepare (numba reads these module ints as constants).
#: The point is in the camera's frustum.
IN_FRUSTUM = 1
#: Its ray would start beyond the bounding sphere: decided by the exact test, not by Embree.
EXACT_NEEDED = 2
#: Within the frustum's float32 margin: re-checked by the float64 frustum test.
FRUSTUM_BORDER = 4
#: Its face may be seen edge-on (definition rule b): re-checked in float64.
MAYBE_EDGE_ON = 8
#: Closer to its face's boundary than pass 2's start: a neighbouring face may hide it (crease).
CREASE = 16


class _Scene:
    def __init__(self, mesh: trimesh.Trimesh):
        try:
            import embreex  # noqa: F401
        except ImportError as exc:
            raise BackendUnavailable(f"'embree-fast' needs Embree: pip install embreex ({exc})") from None
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        used = vertices[np.asarray(mesh.faces)].reshape(-1, 3)
        self.centre = (used.min(axis=0) + used.max(axis=0)) / 2.0
        self.radius = float(np.sqrt(((used - self.centre) ** 2).sum(axis=1)).max()) * (1.0 + 1e-3)
        # The oracle's scene (its crease and near-tie re-checks need it anyway) holds the BVH the
        # rays need: float32 vertices around the same centre, one face per group of identical
        # faces (a ray grazing m stacked copies would test all m; a mesh of 300,000 copies took
        # minutes).  Built once, it serves both.
        self._oracle = oracle_scene(mesh)
        self.scene = self._oracle.scene
        self.n_faces_in_bvh = len(self._oracle.listed)
        planes = mesh_planes(mesh)
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = planes.normal / np.sqrt((planes.normal**2).sum(axis=1))[:, None]
            # Edge planes scaled to unit normals: (F, 3, 4) = (m_k / |m_k|, offset_k / |m_k|).
            scale = 1.0 / np.sqrt((planes.edge_normals**2).sum(axis=2))
            edge = np.concatenate([planes.edge_normals * scale[..., None], (planes.edge_offsets * scale)[..., None]], axis=2)
        self.unit_normals = np.nan_to_num(unit).astype(np.float32)
        self.edge_planes = np.nan_to_num(edge)  # degenerate faces: distance 0 (always a crease)
        #: The face normals of the edge-on rule (float64, :func:`mesh_planes`'s).
        self.normals = planes.normal

    def oracle(self, mesh: trimesh.Trimesh):
        """The oracle's scene of ``mesh`` (this scene's mesh), which also holds this scene's BVH."""
        return self._oracle


_scenes: MeshCache[_Scene] = MeshCache(_Scene, 8)


def set_default_threads(threads: int) -> None:
    """Threads per view of the sessions and calls made after this (those given no ``threads``),
    e.g. 1 to time a view's stages in one thread.  The masks do not depend on it (each point is
    decided alone).

    Raises
    ------
    InvalidInputError
        ``threads < 1``.
    """
    global DEFAULT_THREADS
    if int(threads) < 1:
        raise InvalidInputError(f"threads must be >= 1, got {threads!r}")
    DEFAULT_THREADS = int(threads)


_pool: ThreadPoolExecutor | None = None


def _forget_pool() -> None:
    # A forked child (a DataLoader worker) inherits the pool object but none of its threads:
    # a task submitted to it would wait forever.  The child makes its own on first use.
    global _pool
    _pool = None


os.register_at_fork(after_in_child=_forget_pool)


def _executor(threads: int) -> ThreadPoolExecutor:
    global _pool
    if _pool is None or _pool._max_workers != threads:  # noqa: SLF001 - resize on demand
        _pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="embree-fast")
    return _pool


def _prepare_py(p, pp, normals, boundary, eye, frame, cam, rays):
    """Per point of a chunk: frustum status and the two rays (see :class:`FastScene`).

    Returns ``status`` (uint8 bits :data:`IN_FRUSTUM`, :data:`EXACT_NEEDED`, :data:`FRUSTUM_BORDER`,
    :data:`MAYBE_EDGE_ON`, :data:`CREASE`), pass-1 origins and lengths, pass-2 origins and lengths
    (0: no ray), unit directions (float32, mesh-centred frame).
    """
    n = len(p)
    status = np.zeros(n, dtype=np.uint8)
    org1 = np.empty((n, 3), dtype=np.float32)
    org2 = np.empty((n, 3), dtype=np.float32)
    dirs = np.empty((n, 3), dtype=np.float32)
    len1 = np.zeros(n, dtype=np.float32)
    len2 = np.zeros(n, dtype=np.float32)
    f, width, height, znear, zfar, margin = cam.focal_px, cam.width, cam.height, cam.znear, cam.zfar, cam.border_px
    radius, start_rel, max_start, band_rel, edge_cos = rays.radius, rays.start_rel, rays.max_start, rays.band_rel, rays.edge_cos
    has_normals = len(normals) == n and n > 0
    for i in range(n):
        x, y, z = p[i, 0], p[i, 1], p[i, 2]
        org1[i, 0], org1[i, 1], org1[i, 2] = x, y, z
        dirs[i, 0], dirs[i, 1], dirs[i, 2] = 1.0, 0.0, 0.0
        depth = frame[2, 0] * x + frame[2, 1] * y + frame[2, 2] * z + frame[2, 3]
        dm = _DEPTH_REL_MARGIN * abs(depth)
        if depth < znear - dm or depth > zfar + dm:
            continue
        u = (frame[0, 0] * x + frame[0, 1] * y + frame[0, 2] * z + frame[0, 3]) * f / depth + 0.5 * width
        v = (frame[1, 0] * x + frame[1, 1] * y + frame[1, 2] * z + frame[1, 3]) * f / depth + 0.5 * height
        if u < -margin or u >= width + margin or v < -margin or v >= height + margin:
            continue
        st = IN_FRUSTUM
        if depth < znear + dm or depth > zfar - dm or u < margin or u >= width - margin or v < margin or v >= height - margin:
            st |= FRUSTUM_BORDER
        dx, dy, dz = eye[0] - x, eye[1] - y, eye[2] - z
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        dx, dy, dz = dx / length, dy / length, dz / length
        dirs[i, 0], dirs[i, 1], dirs[i, 2] = dx, dy, dz
        cos = 1.0
        if has_normals:
            cos = abs(normals[i, 0] * dx + normals[i, 1] * dy + normals[i, 2] * dz)
            if cos < edge_cos:
                st |= MAYBE_EDGE_ON
        start = min(start_rel * radius / max(cos, _MIN_COS), max_start * radius)
        band = band_rel * radius / max(cos, _MIN_COS)
        if has_normals and boundary[i] < band:
            st |= CREASE
        b = x * dx + y * dy + z * dz
        disc = b * b - (pp[i] - radius * radius)
        far = min(-b + np.sqrt(max(disc, 0.0)), length)
        if start < far:
            org1[i, 0], org1[i, 1], org1[i, 2] = x + dx * start, y + dy * start, z + dz * start
            len1[i] = far - start
            if band < start:
                org2[i, 0], org2[i, 1], org2[i, 2] = x + dx * band, y + dy * band, z + dz * band
                len2[i] = start - band
        elif band < far:
            st |= EXACT_NEEDED
        status[i] = st
    return status, org1, len1, org2, len2, dirs


def _setup_py(points, order, face_index, centre, unit_normals, edge_planes):
    """Sorted points (float64), float32 copies relative to ``centre``, their squared norms,
    and with ``face_index`` their faces' unit normals and distances to the faces' edges."""
    n = len(order)
    sorted_points = np.empty((n, 3), dtype=np.float64)
    p32 = np.empty((n, 3), dtype=np.float32)
    pp = np.empty(n, dtype=np.float32)
    has_faces = len(face_index) == len(points) and n > 0
    m = n if has_faces else 0
    n32 = np.empty((m, 3), dtype=np.float32)
    boundary = np.empty(m, dtype=np.float32)
    for i in range(n):
        k = order[i]
        x, y, z = points[k, 0], points[k, 1], points[k, 2]
        sorted_points[i, 0], sorted_points[i, 1], sorted_points[i, 2] = x, y, z
        a, b, c = np.float32(x - centre[0]), np.float32(y - centre[1]), np.float32(z - centre[2])
        p32[i, 0], p32[i, 1], p32[i, 2] = a, b, c
        pp[i] = a * a + b * b + c * c
        if has_faces:
            f = face_index[k]
            n32[i, 0], n32[i, 1], n32[i, 2] = unit_normals[f, 0], unit_normals[f, 1], unit_normals[f, 2]
            best = np.inf
            for e in range(3):
                d = abs(edge_planes[f, e, 0] * x + edge_planes[f, e, 1] * y + edge_planes[f, e, 2] * z - edge_planes[f, e, 3])
                best = min(best, d)
            boundary[i] = best
    return sorted_points, p32, pp, n32, boundary


def _crease_py(idx, points, face_index, eye, planes, corner_vertex, vertex_start, vertex_faces, tolerance):
    """(K,) bool: point ``idx[k]`` is hidden by a face sharing a vertex with its own face
    (``planes``: packed rows, :func:`~zbuf_occlude.visibility.segment_triangle.pack_planes`);
    the oracle's pair test (:func:`~zbuf_occlude.visibility.kernels.pair_occludes_one`), stopping at the first hit."""
    out = np.zeros(len(idx), dtype=np.bool_)
    for j in range(len(idx)):
        k = idx[j]
        own = face_index[k]
        px, py, pz = points[k, 0], points[k, 1], points[k, 2]
        sx, sy, sz = eye[0] - px, eye[1] - py, eye[2] - pz
        seg_len = np.sqrt(sx * sx + sy * sy + sz * sz)
        for c in range(3):
            v = corner_vertex[own, c]
            for q in range(vertex_start[v], vertex_start[v + 1]):
                g = vertex_faces[q]
                if g != own and pair_occludes_one(px, py, pz, sx, sy, sz, seg_len, planes[g], tolerance):
                    out[j] = True
                    break
            if out[j]:
                break
    return out


_prepare = numba.njit(cache=True, nogil=True)(_prepare_py)
_setup = numba.njit(cache=True, nogil=True)(_setup_py)
_crease = numba.njit(cache=True, nogil=True, error_model="numpy")(_crease_py)


class _Runner:
    """``run(fn, args_list)`` for :mod:`.cpu_zbuffer`: ``fn(*args)`` for each argument tuple,
    pulled in turn by the calling thread and ``threads - 1`` threads of the pool (the compiled
    kernels release the GIL), so that a late thread only takes fewer; ``bands`` is how many
    tuples to make (``per_thread`` per thread)."""

    def __init__(self, threads: int, per_thread: int = 1):
        self.threads = threads
        self.bands = threads * per_thread if threads > 1 else 1

    def __call__(self, fn, args_list) -> list:
        return _run_shared(self.threads, fn, args_list)


def _run_shared(threads: int, fn, args_list) -> list:
    """``[fn(*args) for args in args_list]``, computed by the calling thread and up to
    ``threads - 1`` threads of the pool, each taking the next undone tuple."""
    return _run_tasks(threads, [(fn, args) for args in args_list])


def _run_tasks(threads: int, tasks: list) -> list:
    """``[fn(*args) for fn, args in tasks]``, computed by the calling thread and up to
    ``threads - 1`` threads of the pool, each taking the next undone task (in list order)."""
    n = len(tasks)
    if threads <= 1 or n <= 1:
        return [fn(*args) for fn, args in tasks]
    out = [None] * n
    taken = itertools.count()

    def drain() -> None:
        while (k := next(taken)) < n:  # (next() on a count is atomic under the GIL)
            fn, args = tasks[k]
            out[k] = fn(*args)

    pool = _executor(threads - 1)
    helpers = [pool.submit(drain) for _ in range(min(threads, n) - 1)]
    try:
        drain()
    finally:
        for h in helpers:
            h.result()
    return out


class FastScene(SessionBase):
    """One mesh and one point set for ``embree-fast``, tested from many cameras.

    Per view, the CPU z-buffer pre-pass (:mod:`.cpu_zbuffer`) settles most points exactly;
    the rest are cast as rays (module docstring).  What depends on the mesh alone (Embree
    BVH, face planes) is cached per mesh, so a first view costs no more than a one-shot
    :func:`embree_fast_visible` call; with ``sort=True`` (the session that
    :class:`~zbuf_occlude.visibility.session.VisibilitySession` keeps) the points are also put in Morton
    order once, which makes later views faster (neighbouring points read neighbouring cells
    and cast coherent rays).

    Parameters
    ----------
    mesh : trimesh.Trimesh
    points : (N, 3) float
        World frame.
    face_index : (N,) int, optional
    threads : int, optional
        Default :data:`DEFAULT_THREADS`.
    sort : bool
        Keep the points in Morton order (worth it for several views).
    prepass : bool, optional
        Use the CPU z-buffer pre-pass (default: yes).

    Raises
    ------
    BackendUnavailable
        Without ``embreex``.
    InvalidInputError
        Bad points or face index.
    """

    def __init__(
        self, mesh: trimesh.Trimesh, points, face_index=None, *, threads: int | None = None, sort: bool = True, prepass: bool | None = None
    ):
        self.mesh = mesh
        points = check_points(points)
        face_index = check_face_index(face_index, len(points), len(mesh.faces))
        self.threads = int(threads or DEFAULT_THREADS)
        self._scene = _scenes(mesh)
        self._run = _Runner(self.threads)
        self._slices = _Runner(self.threads, _SLICES_PER_THREAD)
        self._prepass = True if prepass is None else bool(prepass)
        # Rays in Z-order (Morton) of their points traverse the same BVH nodes, and the
        # pre-pass reads the buffer in order: worth a sort for many views, or when every
        # point is cast.  For one view, points grouped by face (a counting sort) give the
        # pre-pass and the rays most of that locality for the price of one gather.
        self._perm = None
        if (sort or not self._prepass) and len(points):
            self._perm = morton_order(points)
            points = np.ascontiguousarray(points[self._perm])
            face_index = None if face_index is None else face_index[self._perm]
        # The grouping is left to the first view, which runs it beside the buffer's raster bands.
        self._grouping = None
        if face_index is not None and len(points) and self._perm is None:
            self._perm, points, face_index, self._grouping = cpu_zbuffer.group_task(points, face_index, len(mesh.faces))
        self._points, self._face_index = points, face_index
        self._x_order: NDArray[np.int64] | None = None
        #: Fraction of the points the last call re-decided in float64 (near-ties).
        self.last_cpu_fraction = 0.0
        #: Fraction of the points the last call cast as rays (the pre-pass settled the rest).
        self.last_ray_fraction = 0.0

    def _group_now(self) -> None:
        if self._grouping is not None:
            fn, args = self._grouping
            fn(*args)
            self._grouping = None

    @property
    def points(self) -> NDArray[np.float64]:
        """(N, 3) float64: the points in the scene's order (see ``_perm``; grouped by face on the first view)."""
        self._group_now()
        return self._points

    @property
    def face_index(self) -> NDArray[np.int64] | None:
        """(N,) int64 or None: the points' faces, in the order of :attr:`points`."""
        self._group_now()
        return self._face_index

    def _chunk(self, rays: NDArray[np.int64], view: tuple) -> tuple[NDArray, NDArray, NDArray]:
        """(in frustum and not occluded by pass 1, near-tie, status) for points ``rays``;
        ``view = (camera, eye_c, frame, intrinsics, ray settings)`` (:meth:`_cast`)."""
        camera, eye_c, frame, cam, settings = view
        sc = self._scene
        fi = self.face_index if self.face_index is not None else np.zeros(0, dtype=np.int64)
        sorted_points, p32, pp, normals, bound = _setup(self.points, rays, fi, sc.centre, sc.unit_normals, sc.edge_planes)
        status, org1, len1, org2, len2, dirs = _prepare(p32, pp, normals, bound, eye_c, frame, cam, settings)
        border = np.flatnonzero(status & FRUSTUM_BORDER)
        if len(border):  # within a hair of the frustum's border: Camera.in_frustum decides
            inside = camera.in_frustum(sorted_points[border])
            status[border[~inside]] = 0
        hit = np.asarray(sc.scene.run(org1, dirs, dists=len1, query="OCCLUDED")) >= 0  # -1: nothing hit
        inside = (status & IN_FRUSTUM).astype(bool)
        visible = inside & ~hit
        tie = inside & ((status & EXACT_NEEDED) != 0)  # start beyond the sphere's exit: exact
        idx = np.flatnonzero(visible & (len2 > 0))
        if len(idx):
            near = np.asarray(sc.scene.run(org2[idx], dirs[idx], dists=len2[idx], query="OCCLUDED")) >= 0
            tie[idx[near]] = True
        return visible, tie, status

    def _view(self, camera: Camera, rt: NDArray[np.float64]) -> tuple:
        """``(camera, eye_c, frame, intrinsics, ray settings)`` of :meth:`_chunk` (float32, mesh-centred);
        ``rt``: ``camera.extrinsics`` (world → OpenCV camera frame)."""
        sc = self._scene
        eye_c = (np.asarray(camera.eye, dtype=np.float64) - sc.centre).astype(np.float32)
        frame = np.empty((3, 4), dtype=np.float32)
        frame[:, :3] = rt[:, :3]
        frame[:, 3] = rt[:, :3] @ sc.centre + rt[:, 3]
        cam = _Intrinsics(
            *np.array(
                [
                    camera.focal_px,
                    camera.width,
                    camera.height,
                    camera.znear,
                    camera.zfar,
                    _BORDER_PX + _BORDER_PER_PX * max(camera.width, camera.height),
                ],
                dtype=np.float32,
            )
        )
        settings = _RaySettings(*np.array([sc.radius, _START, _MAX_START, _BAND_LO, EDGE_ON_SIN + _EDGE_ON_SLACK], dtype=np.float32))
        return camera, eye_c, frame, cam, settings

    def _cast(self, rays: NDArray[np.int64], camera: Camera, tolerance: float, visible: NDArray[np.bool_], rt: NDArray[np.float64]) -> None:
        """Decide points ``rays`` (in a coherent order) with Embree and float64 re-checks
        (module docstring) into ``visible``; ``rt``: ``camera.extrinsics``."""
        view = self._view(camera, rt)
        m = len(rays)
        step = min(_CHUNK, -(-m // self.threads))  # at least one chunk per thread
        parts = _run_shared(self.threads, self._chunk, [(rays[lo : lo + step], view) for lo in range(0, m, step)])
        vis = np.concatenate([v for v, _, _ in parts])
        tie = np.concatenate([t for _, t, _ in parts])
        status = np.concatenate([st for _, _, st in parts])
        at = np.flatnonzero(vis & ~tie & ((status & CREASE) != 0))
        crease = rays[at]
        eye = np.asarray(camera.eye, dtype=np.float64)
        if len(crease):
            # Within pass 2's start of its face's boundary, the point may be hidden by a
            # neighbouring face closer than that start: test the faces around its own
            # face exactly (as the oracle's crease pass does).
            scene = self._scene.oracle(self.mesh)
            hidden = _crease(
                crease,
                self.points,
                self.face_index,
                eye,
                scene.packed_planes,
                scene.corner_vertex,
                scene.vertex_start,
                scene.vertex_faces,
                float(tolerance),
            )
            vis[at[hidden]] = False
        idx = rays[tie]
        self.last_cpu_fraction = len(idx) / max(len(self.points), 1)
        if len(idx):
            fi_t = None if self.face_index is None else self.face_index[idx]
            vis[tie] = ~occluded_embree(self.mesh, self.points[idx], eye, face_index=fi_t, tolerance=tolerance)
        if self.face_index is not None:
            edge = np.flatnonzero(vis & ((status & MAYBE_EDGE_ON) != 0))
            pts = self.points[rays[edge]]
            vis[edge[edge_on_own(self._scene.normals[self.face_index[rays[edge]]], pts, camera.eye)]] = False
        visible[rays] = vis

    def _prepass_view(self, camera: Camera, tolerance: float) -> tuple[NDArray[np.bool_], NDArray[np.int64], NDArray[np.float64]]:
        """The pre-pass (:mod:`.cpu_zbuffer`): ``(visible, rays, extrinsics)``, the points it settled
        visible, those left to the rays, and ``camera.extrinsics``.  The first view also groups the
        points by face, on the pool beside the buffer's raster bands."""
        n = len(self._points)
        grouping = [] if self._grouping is None else [self._grouping]
        zb, tasks = cpu_zbuffer.zbuffer_tasks(self.mesh, camera, n, bands=self._run.bands, grouping=n if grouping else 0)
        _run_tasks(self.threads, grouping + tasks)  # (the grouping first: its thread then takes the lighter last band)
        self._grouping = None
        status = cpu_zbuffer.classify(self.mesh, self.points, self.face_index, camera, zb, tolerance, run=self._slices)
        visible = status == cpu_zbuffer.VISIBLE
        rays = np.flatnonzero(status == cpu_zbuffer.UNDECIDED)
        if self._perm is None and len(rays):
            # rays in the order of their cells (rows of the image plane): coherent enough
            rays = rays[np.argsort(cpu_zbuffer.cell_of(self.points[rays], camera, zb), kind="stable")]
        return visible, rays, zb.view_extrinsics(camera)

    def visible(self, camera: Camera, *, tolerance: float = TOLERANCE) -> NDArray[np.bool_]:
        """Visibility of the points from ``camera`` (see the module docstring).

        Returns
        -------
        visible : (N,) bool
            In the order of the points given to the constructor.
        """
        n = len(self._points)
        if self._prepass:
            visible, rays, rt = self._prepass_view(camera, tolerance)
        else:
            visible, rays, rt = np.zeros(n, dtype=bool), np.arange(n), camera.extrinsics
        self.last_ray_fraction = len(rays) / max(n, 1)
        self.last_cpu_fraction = 0.0
        if len(rays):
            self._cast(rays, camera, float(tolerance), visible, rt)
        if self.face_index is None:  # rule (b) without face_index, for every point
            if self._x_order is None:
                self._x_order = np.argsort(self.points[:, 0], kind="stable")
            visible &= ~edge_on_any(mesh_planes(self.mesh), self.points, camera.eye, tolerance, order=self._x_order)
        if self._perm is None:
            return visible
        out = np.empty(n, dtype=bool)
        out[self._perm] = visible
        return out


@register("embree-fast", session=FastScene)
def embree_fast_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.float64],
    camera: Camera,
    *,
    face_index: NDArray[np.int64] | None = None,
    tolerance: float = TOLERANCE,
    threads: int | None = None,
) -> NDArray[np.bool_]:
    """Multi-threaded float32 Embree with float64 re-checks of near-ties; see :class:`FastScene`."""
    # One view: no Morton sort of the points (the pre-pass settles most of them unsorted).
    return FastScene(mesh, points, face_index, threads=threads, sort=False).visible(camera, tolerance=tolerance)
