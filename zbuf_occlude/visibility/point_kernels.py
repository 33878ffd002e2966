"""The numba kernels of point-only visibility: surfel splatting into a depth/id buffer, and the
per-point decision (:mod:`zbuf_occlude.visibility.point_splats` states the method and its sources).

Both work in the OpenCV camera frame (x right, y down, z = linear depth forward, object units) on
an image plane at z = 1: pixel ``(i, j)`` is the square ``[x0 + i·pix, x0 + (i+1)·pix) ×
[y0 + j·pix, y0 + (j+1)·pix)`` of normalised coordinates ``(x/z, y/z)``, sampled at its centre.
The GPU path (:mod:`zbuf_occlude.render.surfel_zbuffer`) fills the same buffers and decides with
the same formulas in float64, operation by operation (``render/shaders/point_splat.comp`` and
``point_decide.comp``): a change to :func:`splat_surfels` or :func:`decide` is a change to them too
(tests/render/test_surfel_zbuffer_agreement.py fails until both agree).
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Iterator

import numba
import numpy as np

__all__ = [
    "camera_frame", "decide", "decide_threaded", "splat_surfels", "splat_surfels_threaded", "threads_for", "threads_started",
    "NORMALS_GIVEN", "NORMALS_ORIENTED", "NORMALS_ESTIMATED",
]  # fmt: skip

#: A surfel seen closer than this to edge-on (|cos| between its normal and a pixel's ray) covers
#: nothing there: its footprint is a line of zero area (and the ray-plane depth is unbounded).
EDGE_ON_COS = 1e-6
EDGE_ON_COS2 = EDGE_ON_COS * EDGE_ON_COS
#: A winner's centre within this many spacings of a point's tangent plane lies in that plane
#: (float64 rounding of coplanar points is ~1e-16 of the object; a millionth of a spacing is
#: far above it and far below any real offset).
COPLANAR = 1e-6
#: The curvature allowance is this many times the tangent plane's height at the neighbour's
#: distance (the pixel's ray meets the plane up to half a pixel off the point, and the estimate
#: of the curvature from two normals is first order).
CURVATURE_SLACK = 1.0
#: A winner less than this many spacings in front of a point, along the camera's axis, is on the
#: point's own sheet whatever its tangent plane says: 0.25.  An estimated normal can be far off
#: (a wall or a part thinner than the neighbourhood that estimates it tilts the plane fit by tens
#: of degrees) and then a neighbour of the same sheet stands off that plane.  Chosen on the
#: tuning meshes without normals (+0.6 points of accuracy at 2,048 and 10,000 points; 0.15 and
#: 0.35 gave +0.4 and +0.6); it costs 0.2-0.4 points with exact normals, where walls thinner
#: than it show their far side (docs/results/point_visibility.md).
DEPTH_SLACK = 0.25

#: How the normals of :func:`decide` were found (its ``normals`` argument): given, of either sign.
NORMALS_GIVEN = 0
#: Given, and pointing out of a closed surface consistently (``oriented``).
NORMALS_ORIENTED = 1
#: Estimated from the points.  A winner's disk is then tilted by its normal's error (a disk of
#: radius r tilted by θ reaches r·sin θ toward the camera: 0.26 spacings at 15°), so a winner
#: whose *centre* lies less than :data:`DEPTH_SLACK` spacings in front of the point is on the
#: point's own sheet too, wherever its disk meets the pixel's ray.  Chosen on the tuning meshes
#: (+0.002 at 2,048 and 10,000 points; with given normals, whose disks are exact, it cost 0.001
#: to 0.003, so they keep the disk's depth alone; docs/results/point_visibility.md).
NORMALS_ESTIMATED = 2


@numba.njit(cache=True, nogil=True, inline="always")
def _cell(v, n):  # pragma: no cover - numba
    """``floor(v)`` as an int, ``v`` clamped to ``[-1, n]`` first (NaN: -1).  A pixel coordinate far
    off the image (the box of a disk that nearly reaches the camera plane, a point near it) stays
    off it; converting a float beyond int64 to an int is undefined.  Inside, the same ``floor``."""
    if not v >= -1.0:
        return -1
    if v >= n:
        return n
    return int(np.floor(v))


@numba.njit(cache=True, nogil=True)
def camera_frame(points, normals, rotation, translation):  # pragma: no cover - numba
    """Points and normals in the OpenCV camera frame: ``R p + t`` and ``R n``.

    Parameters
    ----------
    points, normals : (N, 3) float64
        World frame.
    rotation : (3, 3) float64
    translation : (3,) float64
        ``Camera.extrinsics`` split (world -> OpenCV camera).

    Returns
    -------
    cam, normal : (N, 3) float64
    """
    n = points.shape[0]
    cam = np.empty((n, 3))
    normal = np.empty((n, 3))
    for k in range(n):
        for r in range(3):
            cam[k, r] = rotation[r, 0] * points[k, 0] + rotation[r, 1] * points[k, 1] + rotation[r, 2] * points[k, 2] + translation[r]
            normal[k, r] = rotation[r, 0] * normals[k, 0] + rotation[r, 1] * normals[k, 1] + rotation[r, 2] * normals[k, 2]
    return cam, normal


#: Relative widening of a disk's bounding box (of its radius): rounding of the unit normal.
BOX_MARGIN = 1e-6


@numba.njit(cache=True, nogil=True)
def splat_surfels(cam, normal, radius, pix, x0, y0, width, height):  # pragma: no cover - numba
    """Rasterise oriented disks (surfels) into a z-buffer and a surfel-id buffer.

    Each surfel ``k`` is the disk of radius ``radius[k]`` centred on ``cam[k]`` in the plane of
    normal ``normal[k]``.  A pixel is covered when its central ray meets the plane at a point
    within the radius of the centre; the depth stored there is that ray-plane intersection's
    (exact perspective depth of the disk, as Botsch et al. 2005's per-pixel depth correction),
    and the nearest surfel wins.

    Parameters
    ----------
    cam : (N, 3) float64
        Surfel centres, OpenCV camera frame, object units.
    normal : (N, 3) float64
        Unit normals, same frame (either sign).
    radius : (N,) float64
        Disk radii, object units.
    pix, x0, y0 : float
        Pixel side and the image's top-left corner, normalised image coordinates (module docstring).
    width, height : int
        Image size, pixels.

    Returns
    -------
    depth : (height, width) float64
        Nearest covering depth, ``inf`` where no surfel covers the pixel.
    ids : (height, width) int32
        Index of that surfel, −1 where none.
    """
    depth = np.full((height, width), np.inf)
    ids = np.full((height, width), -1, np.int32)
    _splat_rows(cam, normal, radius, pix, x0, y0, width, height, 0, height, depth, ids)
    return depth, ids


@numba.njit(cache=True, nogil=True)
def _splat_rows(cam, normal, radius, pix, x0, y0, width, height, row0, row1, depth, ids):  # pragma: no cover - numba
    """:func:`splat_surfels` on the rows ``row0 <= j < row1`` of ``depth`` and ``ids``: every surfel
    in order, so that a band's pixels are what the whole image's would be."""
    for k in range(cam.shape[0]):
        qx, qy, qz = cam[k, 0], cam[k, 1], cam[k, 2]
        r = radius[k]
        if qz - r <= 0.0 or r <= 0.0:
            continue
        nx, ny, nz = normal[k, 0], normal[k, 1], normal[k, 2]
        # the disk lies inside the box q ± e, e_a = r sqrt(1 - n_a^2) (a little wider, for
        # rounding), whose projection (x/z, y/z) is extreme at corners
        ex = r * (np.sqrt(max(1.0 - nx * nx, 0.0)) + BOX_MARGIN)
        ey = r * (np.sqrt(max(1.0 - ny * ny, 0.0)) + BOX_MARGIN)
        ez = min(r * (np.sqrt(max(1.0 - nz * nz, 0.0)) + BOX_MARGIN), r)
        near, far = qz - ez, qz + ez
        j0 = max(_cell((min((qy - ey) / near, (qy - ey) / far) - y0) / pix, height), row0)
        j1 = min(_cell((max((qy + ey) / near, (qy + ey) / far) - y0) / pix, height), row1 - 1)
        if j0 > j1:
            continue
        i0 = max(_cell((min((qx - ex) / near, (qx - ex) / far) - x0) / pix, width), 0)
        i1 = min(_cell((max((qx + ex) / near, (qx + ex) / far) - x0) / pix, width), width - 1)
        nq = nx * qx + ny * qy + nz * qz
        r2 = r * r
        for j in range(j0, j1 + 1):
            y = y0 + (j + 0.5) * pix
            for i in range(i0, i1 + 1):
                x = x0 + (i + 0.5) * pix
                den = nx * x + ny * y + nz
                if den * den < EDGE_ON_COS2 * (x * x + y * y + 1.0):
                    continue
                # the ray (x, y, 1) meets the plane at t = nq / den; within the disk iff
                # |t (x, y, 1) - q|^2 <= r^2, here multiplied by den^2 to spare the division
                wx = nq * x - den * qx
                wy = nq * y - den * qy
                wz = nq - den * qz
                if wx * wx + wy * wy + wz * wz > r2 * den * den:
                    continue
                t = nq / den
                if t < depth[j, i]:
                    depth[j, i] = t
                    ids[j, i] = k


@numba.njit(cache=True, nogil=True, parallel=True)
def splat_surfels_threaded(cam, normal, radius, pix, x0, y0, width, height, bands):  # pragma: no cover - numba
    """:func:`splat_surfels` on numba's threads, in ``bands`` bands of rows (a few per thread, for
    the load's balance): the same buffers, bit for bit (each pixel sees the surfels in the same
    order)."""
    depth = np.full((height, width), np.inf)
    ids = np.full((height, width), -1, np.int32)
    bands = max(min(bands, height), 1)
    for b in numba.prange(bands):
        _splat_rows(cam, normal, radius, pix, x0, y0, width, height, b * height // bands, (b + 1) * height // bands, depth, ids)
    return depth, ids


@numba.njit(cache=True, nogil=True, inline="always")
def _curvature_allowance(p, q, cam, normal, radius, crease_cos, reach_factor):  # pragma: no cover - numba
    """How far ``q``'s tangent plane may stand off ``p``'s on one smooth sheet: for neighbours
    (``|p - q| <= reach_factor · (r_p + r_q)``) whose normals differ by less than the crease, the height of a
    tangent plane over a surface of curvature ``|n_p -/+ n_q| / |p - q|`` at distance ``|p - q|``,
    ``0.5 |n_p -/+ n_q| |p - q|``; else 0."""
    cos_pq = normal[p, 0] * normal[q, 0] + normal[p, 1] * normal[q, 1] + normal[p, 2] * normal[q, 2]
    if abs(cos_pq) < crease_cos:
        return 0.0
    dx, dy, dz = cam[p, 0] - cam[q, 0], cam[p, 1] - cam[q, 1], cam[p, 2] - cam[q, 2]
    d2 = dx * dx + dy * dy + dz * dz
    reach = reach_factor * (radius[p] + radius[q])
    if d2 > reach * reach:
        return 0.0
    s = 1.0 if cos_pq >= 0.0 else -1.0
    ex = normal[p, 0] - s * normal[q, 0]
    ey = normal[p, 1] - s * normal[q, 1]
    ez = normal[p, 2] - s * normal[q, 2]
    return CURVATURE_SLACK * 0.5 * np.sqrt((ex * ex + ey * ey + ez * ez) * d2)


#: Directions searched around a point that wins its own pixel (:func:`_in_a_gap`).
_GAP_DIRECTIONS = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1]])
#: How far they are searched, in the point's own splat radii.
GAP_REACH = 2.0


@numba.njit(cache=True, nogil=True)
def _in_a_gap(p, i, j, cam, normal, radius, spacing, depth, ids, pix, x0, y0, tolerance, crease_cos, oriented):  # pragma: no cover - numba
    """True when a point whose pixel its own sheet holds is seen through a gap of a surface in
    front: in each of 8 directions, within :data:`GAP_REACH` of its splat radius, the first pixel
    that its own sheet does not hold shows a surface in front of its tangent plane.  Random
    sampling leaves gaps wider than the splats (a few back points of a sampled sphere or cube
    show through them without this test)."""
    px, py, pz = cam[p, 0], cam[p, 1], cam[p, 2]
    height, width = depth.shape
    toward = -(normal[p, 0] * px + normal[p, 1] * py + normal[p, 2] * pz)
    side = 1.0 if toward >= 0.0 else -1.0
    p_faces = toward > 0.0
    allowance = tolerance * spacing[p]
    steps = GAP_REACH * radius[p] / pz / pix
    reach = width + height if steps >= width + height else int(np.ceil(steps))  # the image's end stops the search
    if reach < 1:
        return False
    for d in range(8):
        di, dj = _GAP_DIRECTIONS[d, 0], _GAP_DIRECTIONS[d, 1]
        blocked = False
        for step in range(1, reach + 1):
            ii, jj = i + di * step, j + dj * step
            if ii < 0 or jj < 0 or ii >= width or jj >= height or ids[jj, ii] < 0:
                break
            q = ids[jj, ii]
            if q == p:
                continue
            # the winner's centre, not the pixel's surface point: a neighbour's disk on a convex
            # sheet rises above p's tangent plane, its centre never does
            rise = side * ((cam[q, 0] - px) * normal[p, 0] + (cam[q, 1] - py) * normal[p, 1] + (cam[q, 2] - pz) * normal[p, 2])
            if oriented and not p_faces and normal[q, 0] * cam[q, 0] + normal[q, 1] * cam[q, 1] + normal[q, 2] * cam[q, 2] < 0.0:
                blocked = True
                break
            if rise > allowance + _curvature_allowance(p, q, cam, normal, radius, crease_cos, GAP_REACH + 1.0):
                blocked = True
                break
            if rise < -allowance:
                break
        if not blocked:
            return False
    return True


@numba.njit(cache=True, nogil=True)
def decide(cam, normal, radius, spacing, depth, ids, box, tolerance, crease_cos, normals, sided):  # pragma: no cover - numba
    """Per point: does the surfel that wins its pixel lie on the point's own surface?

    Point ``p`` is a candidate when nothing covers its pixel, when its own surfel wins, when the
    winner ``q``'s centre lies behind ``p``'s tangent plane as seen from the camera, or in it to
    :data:`COPLANAR` spacings (its disk only cuts that plane, as past a convex crease), or when the winner's surface point ``h``
    (where the pixel's ray meets its disk) lies within ``tolerance · spacing[p]`` of ``p``'s
    tangent plane, widened by :func:`_curvature_allowance`, or less than :data:`DEPTH_SLACK`
    spacings in front of ``p`` along the camera's axis (with estimated normals, ``h`` or ``q``'s
    centre, whichever stands less far in front: :data:`NORMALS_ESTIMATED`).  A candidate is visible unless it
    is seen through a gap of a surface in front (:func:`_in_a_gap`).  With oriented
    normals, a point facing away from the camera whose pixel a surfel facing it wins is hidden
    (the back of a closed surface).  A ``sided`` point facing away from the camera is hidden: it
    lies on the far side of a wall whose near side holds points too.  With exact normals of a convex shape, every point facing
    the camera is visible: no other point lies in front of its tangent plane.

    Parameters
    ----------
    cam, normal, radius, depth, ids
        As :func:`splat_surfels` (its output for these surfels).
    box : (pix, x0, y0) float
        The image plane :func:`splat_surfels` drew on: its pixel size and its corner.
    spacing : (N,) float64
        Local sampling spacing of each point, object units.
    tolerance : float
        Distance to the tangent plane, in spacings.
    crease_cos : float
        Normals closer than this (|cos|) are one smooth sheet.
    normals : int
        How the normals were found: :data:`NORMALS_GIVEN`, :data:`NORMALS_ORIENTED` (they point
        out of the surface consistently) or :data:`NORMALS_ESTIMATED`.
    sided : (N,) bool
        The point lies on one side of a thin wall, its normal pointing out of the wall
        (:func:`~zbuf_occlude.visibility.point_preparation.thin_wall_sides`).

    Returns
    -------
    visible : (N,) bool
        Before the frustum test (points behind the camera are False).
    """
    pix, x0, y0 = box
    visible = np.zeros(cam.shape[0], dtype=np.bool_)
    for p in range(cam.shape[0]):
        visible[p] = _decide_point(p, cam, normal, radius, spacing, depth, ids, pix, x0, y0, tolerance, crease_cos, normals, sided)
    return visible


@numba.njit(cache=True, nogil=True)
def _decide_point(
    p, cam, normal, radius, spacing, depth, ids, pix, x0, y0, tolerance, crease_cos, normals, sided
):  # pragma: no cover - numba
    """:func:`decide` for point ``p``."""
    oriented = normals == NORMALS_ORIENTED
    height, width = depth.shape
    px, py, pz = cam[p, 0], cam[p, 1], cam[p, 2]
    if pz <= 0.0:
        return False
    if sided[p] and normal[p, 0] * px + normal[p, 1] * py + normal[p, 2] * pz > 0.0:
        return False  # the far side of a thin wall
    i = _cell((px / pz - x0) / pix, width)
    j = _cell((py / pz - y0) / pix, height)
    if i < 0 or j < 0 or i >= width or j >= height:
        return False
    q = ids[j, i]
    if q < 0 or q == p:
        return not _in_a_gap(p, i, j, cam, normal, radius, spacing, depth, ids, pix, x0, y0, tolerance, crease_cos, oriented)
    if oriented:
        q_faces = normal[q, 0] * cam[q, 0] + normal[q, 1] * cam[q, 1] + normal[q, 2] * cam[q, 2] < 0.0
        p_faces = normal[p, 0] * px + normal[p, 1] * py + normal[p, 2] * pz < 0.0
        if q_faces and not p_faces:
            return False
    dx, dy, dz = px - cam[q, 0], py - cam[q, 1], pz - cam[q, 2]
    # the winner's centre behind p's tangent plane (seen from the camera), or in it: its disk
    # only passes through that plane, as past a convex crease, and hides nothing of p's sheet
    # (in it: within COPLANAR spacings, as coplanar surfels that tie for the pixel, and a centre
    # on a convex crease, which rounding puts on either side)
    toward = -(normal[p, 0] * px + normal[p, 1] * py + normal[p, 2] * pz)  # n_p · (eye - p)
    rise = -(dx * normal[p, 0] + dy * normal[p, 1] + dz * normal[p, 2])  # n_p · (q - p)
    if rise * toward < COPLANAR * spacing[p] * abs(toward):
        return not _in_a_gap(p, i, j, cam, normal, radius, spacing, depth, ids, pix, x0, y0, tolerance, crease_cos, oriented)
    x = x0 + (i + 0.5) * pix
    y = y0 + (j + 0.5) * pix
    t = depth[j, i]
    dist = abs((x * t - px) * normal[p, 0] + (y * t - py) * normal[p, 1] + (t - pz) * normal[p, 2])
    allowance = tolerance * spacing[p] + _curvature_allowance(p, q, cam, normal, radius, crease_cos, 1.0)
    # the winner's depth: where its disk meets the pixel's ray, or with estimated normals also its centre's
    front = pz - (max(t, cam[q, 2]) if normals == NORMALS_ESTIMATED else t)
    if dist <= allowance or front <= DEPTH_SLACK * spacing[p]:
        return not _in_a_gap(p, i, j, cam, normal, radius, spacing, depth, ids, pix, x0, y0, tolerance, crease_cos, oriented)
    return False


@numba.njit(cache=True, nogil=True, parallel=True)
def decide_threaded(cam, normal, radius, spacing, depth, ids, box, tolerance, crease_cos, normals, sided):  # pragma: no cover - numba
    """:func:`decide` on numba's threads (the same answer: each point is decided alone)."""
    pix, x0, y0 = box
    visible = np.zeros(cam.shape[0], dtype=np.bool_)
    for p in numba.prange(cam.shape[0]):
        visible[p] = _decide_point(p, cam, normal, radius, spacing, depth, ids, pix, x0, y0, tolerance, crease_cos, normals, sided)
    return visible


#: Points from which one view runs on numba's threads (:func:`threads_for`): 50,000, where a view
#: takes tens of milliseconds and starting the threads is negligible.  Smaller clouds (PointNet's
#: 2,048, a data loader's items) stay on one thread: their callers run one process per core.
THREADED_MIN_POINTS = 50_000
#: Bands of rows per thread in :func:`splat_surfels_threaded` (objects fill the middle rows).
BANDS_PER_THREAD = 2
_threads = threading.Lock()
_threads_pid: list[int] = []  # the process that first ran a threaded kernel


@contextlib.contextmanager
def threads_for(n: int) -> Iterator[int]:
    """The number of numba threads a view of ``n`` points may use (1: the serial kernels).

    More than 1 only for ``n >= THREADED_MIN_POINTS`` when ``numba.get_num_threads()`` (set by
    ``NUMBA_NUM_THREADS`` or ``numba.set_num_threads``) is above 1, no other Python thread is in
    a threaded view (numba's workqueue layer refuses concurrent calls), and this is not a forked
    child of a process that ran them (GNU OpenMP is not safe across ``fork``)."""
    count = numba.get_num_threads() if n >= THREADED_MIN_POINTS else 1
    if count <= 1 or (_threads_pid and _threads_pid[0] != os.getpid()) or not _threads.acquire(blocking=False):
        yield 1
        return
    try:
        threads_started()
        yield count
    finally:
        _threads.release()


def threads_started() -> None:
    """Note that this process started numba's threads (ran or compiled a threaded kernel): a
    process forked from it keeps to the serial kernels (:func:`threads_for`)."""
    if not _threads_pid:
        _threads_pid.append(os.getpid())
