"""A CPU z-buffer pre-pass that settles most points of a view without casting a ray.

Used by ``embree-fast`` (:mod:`~zbuf_occlude.visibility.embree_fast`) before its rays: per
view, the mesh is rasterised in compiled code (numba) into a grid over the image plane of
the camera, and each point in the frustum is decided from its cell when that decision can be
*proven*; only the rest are cast as rays.  Nothing here is an approximation: a settled point
gets the oracle's answer (:mod:`~zbuf_occlude.visibility.definition`).

The buffer
----------
The grid covers the mesh's projection (normalised image coordinates ``x / z, y / z`` of the
OpenCV camera frame, clipped to the image), with about :data:`CELLS_PER_POINT` cells per
point.  Each face is rasterised *conservatively*: every cell its projected triangle may
touch (the separating-axis test of the triangle against the cell grown by
:data:`_CELL_GROWTH`) receives an upper bound of the face's ``1 / z`` over the cell, i.e. a
lower bound of its depth: ``1 / z`` is affine on the image plane, so the bound is its value
at the cell's corners, capped by the nearest vertex (a face's depth is a convex combination
of its vertices').  Per cell the buffer keeps the :data:`_KEEP` faces of largest bound (the
nearest), with their ids, the next bound, and a lower bound of ``1 / z`` of the nearest face
that covers the whole (grown) cell.

A point ``p`` of depth ``z_p`` in its cell is

* **hidden** if a face covers the cell in front of ``p`` by more than the tolerance (its
  sightline, at least ``z_p - z`` long there, meets the face inside), or if one of the kept
  faces in front of ``p`` (other than its own face) occludes it by the oracle's float64 pair
  test (:func:`~zbuf_occlude.visibility.segment_triangle.pair_occludes`, operation for
  operation), so the answer is the oracle's bit for bit;
* **visible** if every kept face in front of ``p`` was tested and none occludes it, and the
  next bound lies beyond ``p``: every other face lies beyond ``p`` wherever it covers the
  cell, so it cannot meet the segment from ``p`` to the eye; the edge-on rule is then
  applied as in :func:`~zbuf_occlude.visibility.definition.edge_on_own`;
* otherwise **undecided** (more than :data:`_KEEP` faces in front): the caller casts a ray.

The frustum test repeats :meth:`Camera.in_frustum`'s float64 arithmetic, so its answer is
the camera's.  Bounds are kept conservative against rounding: the plane of ``1 / z`` is
used only when its conditioning (``|n| |P| / |n · P|``) is below :data:`_MAX_PLANE_COND`,
with an absolute slack of :data:`_PLANE_SLACK` times its terms' magnitude; bounds are
rounded outwards to float32.  A view whose mesh reaches behind :data:`_MIN_DEPTH` of the
camera plane gets no buffer (every point undecided).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude.errors import BackendUnavailable
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.geometry.grouping import exact_face_groups
from zbuf_occlude.mesh.cache import MeshCache
from zbuf_occlude.visibility.definition import EDGE_ON_SIN
from zbuf_occlude.visibility.kernels import pair_occludes_one
from zbuf_occlude.visibility.segment_triangle import SCENE_CACHE_SIZE, mesh_planes, pack_planes

__all__ = [
    "CELLS_PER_POINT",
    "HIDDEN",
    "VISIBLE",
    "UNDECIDED",
    "ZBuffer",
    "build_zbuffer",
    "zbuffer_tasks",
    "classify",
    "cell_of",
    "group_by_face",
    "group_task",
]

#: Grid cells per point in the frustum (the resolution follows the point density): more
#: cells settle more points near face edges, fewer cost less to clear and rasterise.
CELLS_PER_POINT = 0.25
#: Bounds on the grid's cell count.
_MIN_CELLS, _MAX_CELLS = 64 * 64, 2048 * 2048  # (64 bytes a cell: 256 MiB at most)
#: Each cell is grown by this fraction of its side on every side when a face is
#: rasterised, so that a point whose cell index rounds across a cell border is still
#: covered (float64 rounding of image coordinates is ~1e-16 relative).
_CELL_GROWTH = 1e-3
#: The ``1 / z`` plane of a face is trusted below this conditioning; above it (a face seen
#: nearly edge-on) only the nearest vertex bounds the face's depth.
_MAX_PLANE_COND = 1e5
#: Absolute slack on ``1 / z``, relative to the magnitude of its terms (float64 rounding of
#: the camera-frame vertices, the plane and its evaluation are ~1e-15 of it).
_PLANE_SLACK = 1e-9
#: Bounds are scaled by these before being rounded to float32 (6e-8 relative), so that
#: they stay on their side.
_ROUND_DOWN = 1.0 - 1e-6
_ROUND_UP = 1.0 + 1e-6
#: A triangle is flat (seen edge-on: its projected area may be rounding) below this share of its
#: squared span, plus this share of its span times its largest cell coordinate.
_FLAT_AREA_REL, _FLAT_AREA_ABS = 1e-9, 1e-12
#: Rounding slack of an edge function, relative to its terms (float64: ~1e-16 of them).
_EDGE_SLACK = 1e-9
#: Columns bounds are moved outwards (touching) or inwards (inside) by this, in cells.
_COLUMN_SLACK = 1e-6
#: A point is beyond a face bound only with this relative margin (its own depth's rounding).
_DEPTH_MARGIN = 1e-12
#: No buffer when a vertex is this close (relative to the mesh's depth range) to the
#: camera plane or behind it: projected coordinates blow up there.
_MIN_DEPTH = 1e-6

#: Work of grouping one point by face (:func:`group_task`) in units of the raster's work, one
#: (face, row) pair: about 12 ns against 60 ns, measured in the one-shot call (sofa_0001, 100,000
#: points; the points' first touch in the view is a cache miss).  Only where the bands are cut
#: depends on it, not the buffer.
_GROUP_WORK = 0.2

#: Faces kept per cell (those of the smallest depth bounds), each tested exactly against a
#: point of the cell in front of it: more settle points where several faces meet, at 8
#: bytes a cell each.
_KEEP = 7
_COVER = 2 * _KEEP + 1  # the column of the covering faces' bound

#: Point status codes of :func:`classify`.
HIDDEN, VISIBLE, UNDECIDED = 0, 1, 2


def _to_camera_py(vertices, rt, used):
    """(V, 5) float64: ``x, y, z`` in the OpenCV camera frame (:meth:`Camera.project`'s
    arithmetic) and the normalised image coordinates ``x / z, y / z``; and the extent of the
    vertices ``used`` (all when empty), ``(min z, max |z|, min x/z, max x/z, min y/z, max y/z)``."""
    out = np.empty((len(vertices), 5))
    for i in range(len(vertices)):
        x, y, z = vertices[i, 0], vertices[i, 1], vertices[i, 2]
        for r in range(3):
            out[i, r] = x * rt[r, 0] + y * rt[r, 1] + z * rt[r, 2] + rt[r, 3]
        out[i, 3] = out[i, 0] / out[i, 2]
        out[i, 4] = out[i, 1] / out[i, 2]
    extent = np.empty(6)
    n = len(used) if len(used) else len(vertices)
    for k in range(n):
        i = used[k] if len(used) else k
        z, a, b = out[i, 2], out[i, 3], out[i, 4]
        if k == 0:
            extent[0], extent[1], extent[2], extent[3], extent[4], extent[5] = z, abs(z), a, a, b, b
        else:  # (min and max are exact: any order gives numpy's answer on finite values)
            extent[0], extent[1] = min(extent[0], z), max(extent[1], abs(z))
            extent[2], extent[3] = min(extent[2], a), max(extent[3], a)
            extent[4], extent[5] = min(extent[4], b), max(extent[5], b)
    return out, extent


def _face_rows_py(cam, faces, grid, gb):
    """(F, 2) int32: the first and last row of the grid each face may touch (its grown bounding
    box, clipped to the grid; empty when last < first), as :func:`_rasterise` reads them."""
    b0, inv_sb = grid[1], grid[3]
    grow = _CELL_GROWTH
    rows = np.empty((len(faces), 2), dtype=np.int32)
    for f in range(len(faces)):
        c0 = (cam[faces[f, 0], 4] - b0) * inv_sb
        c1 = (cam[faces[f, 1], 4] - b0) * inv_sb
        c2 = (cam[faces[f, 2], 4] - b0) * inv_sb
        rows[f, 0] = max(int(math.floor(min(c0, c1, c2) - grow)), 0)
        rows[f, 1] = min(int(math.floor(max(c0, c1, c2) + grow)), gb - 1)
    return rows


def _band_cuts_py(face_rows, gb, bands, reserve):
    """``bands + 1`` row cuts, ``0 .. gb``, giving each band about the same work: its (face, row)
    pairs to rasterise, plus one per row (clearing it); the last band gets ``reserve`` less (the
    thread that takes it runs another task first)."""
    work = np.ones(gb + 1, dtype=np.int64)
    work[gb] = 0
    for f in range(len(face_rows)):
        if face_rows[f, 0] <= face_rows[f, 1]:
            work[face_rows[f, 0]] += 1
            work[face_rows[f, 1] + 1] -= 1
    total = 0
    for j in range(gb):
        if j > 0:  # (a running sum of the differences: faces over row j, plus one)
            work[j] += work[j - 1] - 1
        total += work[j]
    share = (total + reserve) / bands
    cuts = np.empty(bands + 1, dtype=np.int64)
    cuts[0], k, acc = 0, 1, 0
    for j in range(gb):
        acc += work[j]
        while k < bands and acc >= share * k:
            cuts[k] = j + 1
            k += 1
    while k <= bands:
        cuts[k] = gb
        k += 1
    return cuts


def _insert_py(zbuf, ids, c, z, f):
    """Face ``f`` with bound ``z`` (of ``1 / depth``) into cell ``c``'s sorted bounds (:class:`ZBuffer`)."""
    if z > zbuf[c, _KEEP]:
        s = _KEEP
        while s > 0 and z > zbuf[c, s - 1]:
            zbuf[c, s] = zbuf[c, s - 1]
            if s < _KEEP:
                ids[c, _KEEP + 1 + s] = ids[c, _KEEP + s]
            s -= 1
        zbuf[c, s] = z
        if s < _KEEP:
            ids[c, _KEEP + 1 + s] = f


def _clear_rows_py(zbuf, ids, row_lo, row_hi, ga):
    """Empty cells of rows ``row_lo:row_hi``: no face, bounds beyond everything (``1 / depth = 0``)."""
    for c in range(row_lo * ga, row_hi * ga):
        for s in range(_KEEP + 1):
            zbuf[c, s] = 0.0
        for s in range(_KEEP):
            ids[c, _KEEP + 1 + s] = -1
        zbuf[c, _COVER] = 0.0


def _inverse_depth_plane_py(cam, i0, i1, i2, a0, b0, sa, sb, grow, amax, bmax):
    """The face's ``1 / z`` as a plane over the grid, ``1/z = g0 + g_a * column + g_b * row``:
    ``(trusted, g_max, g_a, g_b, g_min)`` with ``g_max`` and ``g_min`` the plane at a cell's corner
    plus and minus its reach over the grown cell and the rounding slack (``trusted``: the plane is
    well conditioned, :data:`_MAX_PLANE_COND`; else only the vertices bound the depth)."""
    pmax = max(
        abs(cam[i0, 0]) + abs(cam[i0, 1]) + abs(cam[i0, 2]),
        abs(cam[i1, 0]) + abs(cam[i1, 1]) + abs(cam[i1, 2]),
        abs(cam[i2, 0]) + abs(cam[i2, 1]) + abs(cam[i2, 2]),
    )
    # 1/z = g0 + g_a * ca + g_b * cb on the face's plane n . X = d (camera frame).
    e1x, e1y, e1z = cam[i1, 0] - cam[i0, 0], cam[i1, 1] - cam[i0, 1], cam[i1, 2] - cam[i0, 2]
    e2x, e2y, e2z = cam[i2, 0] - cam[i0, 0], cam[i2, 1] - cam[i0, 1], cam[i2, 2] - cam[i0, 2]
    nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    d = nx * cam[i0, 0] + ny * cam[i0, 1] + nz * cam[i0, 2]
    nn = abs(nx) + abs(ny) + abs(nz)
    trusted = abs(d) * _MAX_PLANE_COND > nn * pmax and nn > 0.0
    g_max = g_a = g_b = g_min = 0.0
    if trusted:
        g_a, g_b = nx * sa / d, ny * sb / d
        # the plane at the cell's centre, plus its half-extents and the rounding slack
        # (|nx a| + |ny b| + |nz| over the grid, over |d|: the terms' magnitude)
        g_min = (nx * a0 + ny * b0 + nz) / d + 0.5 * (g_a + g_b)
        reach = (abs(g_a) + abs(g_b)) * (0.5 + grow) + _PLANE_SLACK * (abs(nx) * amax + abs(ny) * bmax + abs(nz)) / abs(d)
        g_max = g_min + reach
        g_min -= reach  # (the smallest 1/z over the cell: the largest depth)
    return trusted, g_max, g_a, g_b, g_min


def _edge_constraints_py(ca, cb, grow, ga, gb, con_i, con_j, con_0, con_in):
    """The triangle's edge functions as per-cell constraints linear in the column and the row.

    Edge functions E_k(c) = (c_{k+1} - c_k) x (c - c_k), signed so that inside is >= 0; a cell
    may touch the triangle iff max over the grown cell of each E_k >= 0 (the separating axes of
    a triangle and a box: the box's axes, the bounding box loop, and the edges' normals).  Writes
    per constraint ``1 / coefficient of the column`` (``con_i``), the row's coefficient
    (``con_j``), the constant of "may touch" (``con_0``) and of "the grown cell is inside"
    (``con_in``); returns ``(count, flat)``, ``flat`` when the triangle is seen edge-on.
    """
    area = (ca[1] - ca[0]) * (cb[2] - cb[0]) - (ca[2] - ca[0]) * (cb[1] - cb[0])
    span = max(max(ca[0], ca[1], ca[2]) - min(ca[0], ca[1], ca[2]), max(cb[0], cb[1], cb[2]) - min(cb[0], cb[1], cb[2]))
    cmax = max(abs(ca[0]), abs(ca[1]), abs(ca[2]), abs(cb[0]), abs(cb[1]), abs(cb[2])) + 1.0
    flat = abs(area) <= _FLAT_AREA_REL * span * span + _FLAT_AREA_ABS * span * cmax  # (or its sign is rounding)
    sign = 1.0 if area >= 0.0 else -1.0
    n_con = 0
    for m in range(2 if flat else 3):
        if flat:
            # Seen edge-on, the triangle is a segment: the band |E_k| <= w around its
            # longest edge's line that holds the third vertex.
            best, k = -1.0, 0
            for q in range(3):
                ln = abs(ca[(q + 1) % 3] - ca[q]) + abs(cb[(q + 1) % 3] - cb[q])
                if ln > best:
                    best, k = ln, q
            k1, k2 = (k + 1) % 3, (k + 2) % 3
            sgn = 1.0 if m == 0 else -1.0
            da, db = ca[k1] - ca[k], cb[k1] - cb[k]
            w = abs((cb[k2] - cb[k]) * da - (ca[k2] - ca[k]) * db)
        else:
            k, sgn, w = m, sign, 0.0
            da, db = ca[(k + 1) % 3] - ca[k], cb[(k + 1) % 3] - cb[k]
        # E at the cell centre (i + 0.5, j + 0.5), plus the half-extents and rounding slack
        ci = -sgn * db
        con_j[n_con] = sgn * da
        centre = sgn * (-cb[k] * da + (ca[k] - 0.5) * db + 0.5 * da)
        reach = (abs(da) + abs(db)) * (0.5 + grow) + _EDGE_SLACK * (abs(da) + abs(db)) * (abs(ca[k]) + abs(cb[k]) + ga + gb)
        con_0[n_con] = centre + w + reach
        con_in[n_con] = -1.0 if flat else centre - reach
        if ci == 0.0:
            con_i[n_con] = 0.0
        else:
            con_i[n_con] = 1.0 / ci
        n_con += 1
    return n_con, flat


def _row_span_py(j, lo_a, hi_a, flat, n_con, con_i, con_j, con_0, con_in):
    """Columns of row ``j`` the face may touch, ``first..last``, and those whose grown cell lies
    inside it, ``first_in..last_in`` (empty when ``last < first``)."""
    first, last = lo_a, hi_a
    first_in, last_in = lo_a, hi_a if not flat else lo_a - 1
    for m in range(n_con):
        cst = con_j[m] * j + con_0[m]
        cin = con_j[m] * j + con_in[m]
        # (bounds compared as floats first: a near-zero coefficient gives huge ones)
        if con_i[m] > 0.0:
            x = -cst * con_i[m] - _COLUMN_SLACK
            if x > first:
                first = int(math.ceil(min(x, hi_a + 1.0)))
            x = -cin * con_i[m] + _COLUMN_SLACK
            if x > first_in:
                first_in = int(math.ceil(min(x, hi_a + 1.0)))
        elif con_i[m] < 0.0:
            x = -cst * con_i[m] + _COLUMN_SLACK
            if x < last:
                last = int(math.floor(max(x, lo_a - 1.0)))
            x = -cin * con_i[m] - _COLUMN_SLACK
            if x < last_in:
                last_in = int(math.floor(max(x, lo_a - 1.0)))
        else:
            if cst < 0.0:
                last = first - 1
            if cin < 0.0:
                last_in = first_in - 1
    return first, last, first_in, last_in


def _rasterise_py(cam, faces, face_ids, grid, ga, gb, row_lo, row_hi, zbuf, ids, face_rows):
    """Conservative rasterisation (module docstring) of every face (``faces[f]``, stored as
    ``face_ids[f]``) into rows
    ``row_lo:row_hi`` of the buffer (:class:`ZBuffer`'s layout: ``zbuf`` and ``ids`` are two
    views of one record per cell); ``grid = (a0, b0, inv_sa, inv_sb)``; ``face_rows``:
    :func:`_face_rows`'s, so that a band skips the faces outside it for two integer reads."""
    a0, b0, inv_sa, inv_sb = grid[0], grid[1], grid[2], grid[3]
    sa, sb = 1.0 / inv_sa, 1.0 / inv_sb
    grow = _CELL_GROWTH
    _clear_rows(zbuf, ids, row_lo, row_hi, ga)
    amax = max(abs(a0), abs(a0 + sa * ga))
    bmax = max(abs(b0), abs(b0 + sb * gb))
    ca = np.empty(3)  # the face's vertices in cell units: column, row
    cb = np.empty(3)
    con_i = np.empty(3)  # per constraint: 1 / coefficient of the column i, of the row j, constant
    con_j = np.empty(3)
    con_0 = np.empty(3)
    con_in = np.empty(3)  # the constant of "the grown cell is inside the edge"
    for f in range(len(faces)):
        # The rows of the grid (not of this band) decide the one-cell case below, so that
        # the buffer does not depend on where the bands are cut.
        grid_lo_b, grid_hi_b = face_rows[f, 0], face_rows[f, 1]
        lo_b, hi_b = max(grid_lo_b, row_lo), min(grid_hi_b, row_hi - 1)
        if lo_b > hi_b:
            continue
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        for k in range(3):
            v = faces[f, k]
            ca[k] = (cam[v, 3] - a0) * inv_sa
            cb[k] = (cam[v, 4] - b0) * inv_sb
        lo_a = max(int(math.floor(min(ca[0], ca[1], ca[2]) - grow)), 0)
        hi_a = min(int(math.floor(max(ca[0], ca[1], ca[2]) + grow)), ga - 1)
        if lo_a > hi_a:
            continue
        zmin = min(cam[i0, 2], cam[i1, 2], cam[i2, 2])
        if lo_a == hi_a and grid_lo_b == grid_hi_b:
            # Inside one cell, grown bounding box and all: it touches that cell only (and
            # covers none), and its nearest vertex bounds its depth.
            _insert(zbuf, ids, lo_b * ga + lo_a, np.float32(_ROUND_UP / zmin), face_ids[f])
            continue
        trusted, g_max, g_a, g_b, g_min = _inverse_depth_plane(cam, i0, i1, i2, a0, b0, sa, sb, grow, amax, bmax)
        inv_cap = 1.0 / zmin
        inv_floor = 1.0 / max(cam[i0, 2], cam[i1, 2], cam[i2, 2])
        n_con, flat = _edge_constraints(ca, cb, grow, ga, gb, con_i, con_j, con_0, con_in)
        for j in range(lo_b, hi_b + 1):
            first, last, first_in, last_in = _row_span(j, lo_a, hi_a, flat, n_con, con_i, con_j, con_0, con_in)
            row = j * ga
            base = g_max + g_b * j
            base_in = g_min + g_b * j
            for i in range(first, last + 1):
                if i >= first_in and i <= last_in:
                    # the grown cell lies inside the triangle: an upper bound of its depth there
                    low = inv_floor
                    if trusted:
                        low = max(low, base_in + g_a * i)
                    zc = np.float32(_ROUND_DOWN * low)
                    if zc > zbuf[row + i, _COVER]:
                        zbuf[row + i, _COVER] = zc
                inv = inv_cap
                if trusted:
                    hi = base + g_a * i
                    if hi <= 0.0:
                        continue  # the plane is behind the camera over the whole cell
                    inv = min(inv, hi)
                _insert(zbuf, ids, row + i, np.float32(_ROUND_UP * inv), face_ids[f])


def _classify_py(points, face_index, lo, hi, rt, intr, eye, grid, ga, gb, zbuf, ids, planes, tolerance, edge_on_sin, status):
    """:data:`HIDDEN` (or outside the frustum), :data:`VISIBLE` or :data:`UNDECIDED` for
    points ``lo:hi`` into ``status``; ``intr = (f, width, height, znear, zfar)``; ``ga == 0``:
    no buffer."""
    f, width, height, znear, zfar = intr[0], intr[1], intr[2], intr[3], intr[4]
    a0, b0, inv_sa, inv_sb = grid[0], grid[1], grid[2], grid[3]
    has_faces = len(face_index) > 0
    margin = 1.0 - _DEPTH_MARGIN
    for k in range(lo, hi):
        px, py, pz = points[k, 0], points[k, 1], points[k, 2]
        x = px * rt[0, 0] + py * rt[0, 1] + pz * rt[0, 2] + rt[0, 3]
        y = px * rt[1, 0] + py * rt[1, 1] + pz * rt[1, 2] + rt[1, 3]
        z = px * rt[2, 0] + py * rt[2, 1] + pz * rt[2, 2] + rt[2, 3]
        a, b = x / z, y / z
        u = a * f + width / 2.0
        v = b * f + height / 2.0
        if not (z >= znear and z <= zfar and u >= 0 and u < width and v >= 0 and v < height):
            status[k] = HIDDEN
            continue
        status[k] = UNDECIDED
        if ga == 0:
            continue
        ca = (a - a0) * inv_sa
        cb = (b - b0) * inv_sb
        if not (ca >= 0.0 and ca < ga and cb >= 0.0 and cb < gb):
            continue
        c = int(cb) * ga + int(ca)
        own = face_index[k] if has_faces else -1
        beyond = (1.0 / z) * margin  # a face whose 1 / depth bound is below this is beyond p
        cover = zbuf[c, _COVER]
        if cover > 0.0 and z - 1.0 / cover > tolerance + z * _DEPTH_MARGIN:
            # A face covers the whole cell in front of the point, by more than the
            # tolerance along the sightline (which is at least as long as the depth).
            status[k] = HIDDEN
            continue
        state = VISIBLE
        sx, sy, sz = eye[0] - px, eye[1] - py, eye[2] - pz
        seg_len = np.sqrt(sx * sx + sy * sy + sz * sz)
        for s in range(_KEEP + 1):
            if zbuf[c, s] < beyond:  # this face and all after it lie beyond the point
                break
            if s == _KEEP:
                state = UNDECIDED
                break
            g = ids[c, _KEEP + 1 + s]
            if g != own and pair_occludes_one(px, py, pz, sx, sy, sz, seg_len, planes[g], tolerance):
                state = HIDDEN
                break
        if state == VISIBLE and has_faces:  # rule (b), as definition.edge_on_own
            n0, n1, n2 = planes[own, 0], planes[own, 1], planes[own, 2]
            if abs(n0 * sx + n1 * sy + n2 * sz) < edge_on_sin * np.sqrt(n0 * n0 + n1 * n1 + n2 * n2) * seg_len:
                state = HIDDEN
        status[k] = state


def _face_order_py(face_index, n_faces, perm):
    """Counting sort of the points by face (stable, ``O(N + F)``): the permutation, into ``perm``."""
    start = np.zeros(n_faces + 1, dtype=np.int64)
    for k in range(len(face_index)):
        start[face_index[k] + 1] += 1
    for f in range(n_faces):
        start[f + 1] += start[f]
    for k in range(len(face_index)):
        f = face_index[k]
        perm[start[f]] = k
        start[f] += 1


def _gather_py(points, face_index, perm, lo, hi, out, faces):
    """``out[j] = points[perm[j]]``, ``faces[j] = face_index[perm[j]]`` for ``j`` in ``lo:hi``."""
    for j in range(lo, hi):
        k = perm[j]
        out[j, 0], out[j, 1], out[j, 2] = points[k, 0], points[k, 1], points[k, 2]
        faces[j] = face_index[k]


_face_order = numba.njit(cache=True, nogil=True)(_face_order_py)
_gather = numba.njit(cache=True, nogil=True)(_gather_py)


def _group_py(points, face_index, n_faces, perm, out, faces):
    """:func:`_face_order` into ``perm``, then the whole :func:`_gather`, in one call (one task)."""
    _face_order(face_index, n_faces, perm)
    _gather(points, face_index, perm, 0, len(perm), out, faces)


_group = numba.njit(cache=True, nogil=True)(_group_py)
_insert = numba.njit(cache=True, nogil=True, inline="always")(_insert_py)
_to_camera = numba.njit(cache=True, nogil=True, error_model="numpy")(_to_camera_py)
_face_rows = numba.njit(cache=True, nogil=True, error_model="numpy")(_face_rows_py)
_band_cuts = numba.njit(cache=True, nogil=True, error_model="numpy")(_band_cuts_py)
_clear_rows = numba.njit(cache=True, nogil=True, inline="always")(_clear_rows_py)
_inverse_depth_plane = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(_inverse_depth_plane_py)
_edge_constraints = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(_edge_constraints_py)
_row_span = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(_row_span_py)
_rasterise = numba.njit(cache=True, nogil=True, error_model="numpy")(_rasterise_py)
_classify = numba.njit(cache=True, nogil=True, error_model="numpy")(_classify_py)


class _MeshData:
    """What the pre-pass needs of a mesh, computed once per mesh (:class:`MeshCache`):
    vertices, faces and the float64 planes of the oracle's pair test packed one row per
    face (``normal (3), offset, edge_normals (3 × 3), edge_offsets (3)``: 128 bytes, two
    cache lines, for a random access)."""

    def __init__(self, mesh: trimesh.Trimesh):
        self.vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
        # Rasterised: one face per group of identical faces (a stack of m copies would fill every
        # cell it covers m times; a copy of a point's own face never occludes it, within the tolerance).
        self.raster_ids = _listed_faces(mesh) if len(self.faces) else np.zeros(0, dtype=np.int64)
        self.raster_faces = np.ascontiguousarray(self.faces[self.raster_ids])
        #: The vertices the view's extent is taken over: those of a face when the file lists many
        #: more than the faces use (a point cloud with a few faces), else all (empty).
        self.used = np.unique(self.faces) if len(self.vertices) > 3 * len(self.faces) else np.zeros(0, dtype=np.int64)
        self.planes = pack_planes(mesh_planes(mesh))


def _listed_faces(mesh: trimesh.Trimesh) -> NDArray[np.int64]:
    """(K,) int64, ascending: the lowest index of each group of faces with bit-identical vertices
    (:func:`~zbuf_occlude.geometry.grouping.exact_face_groups`).  Taken from the oracle's Embree
    scene of the mesh where Embree is installed (``embree-fast``, the pre-pass's caller, builds
    it anyway): grouping the faces is a sort of the whole mesh, once is enough."""
    try:
        from zbuf_occlude.visibility.oracle_embree import scene_for

        return scene_for(mesh).listed
    except BackendUnavailable:
        return np.flatnonzero(exact_face_groups(mesh.triangles) == np.arange(len(mesh.faces)))


_mesh_data: MeshCache[_MeshData] = MeshCache(_MeshData, SCENE_CACHE_SIZE)


class ZBuffer:
    """One view's buffer (module docstring).

    Attributes
    ----------
    grid : (4,) float64
        ``(a0, b0, 1 / cell_a, 1 / cell_b)``: origin and inverse cell size on the normalised
        image plane (``x / z``, ``y / z``, OpenCV camera frame).
    shape : (int, int)
        Cells ``(along a, along b)``; ``(0, 0)`` when the view has no buffer.
    zbuf : (C, 2 K + 2) float32
        One record per cell (64 bytes), ``K =`` :data:`_KEEP`: columns ``0..K``, upper
        bounds of ``1 / depth`` (1 / object units), sorted, the ``K`` largest (nearest) and
        the next (0: none); columns ``K+1..2K`` (read through :attr:`ids`) the faces of the
        ``K`` largest; column ``2K+1``, the largest lower bound of ``1 / depth`` of a face
        covering the whole cell (0: none).
    ids : (C, 2 K + 2) int32
        The same memory as ``zbuf``; columns ``K+1..2K`` are faces (-1: none).
    camera : Camera or None
        The camera it was built for, and ``extrinsics``, its ``(3, 4)`` float64 world → OpenCV
        matrix, computed once for the view's steps.
    mesh_data : object or None
        What the pre-pass keeps of the mesh it was built for (read by :func:`classify`).
    """

    def __init__(self, grid, shape, zbuf, camera=None, extrinsics=None, mesh_data=None):
        self.grid, self.shape, self.zbuf = grid, shape, zbuf
        self.ids = zbuf.view(np.int32)
        self.camera, self.extrinsics, self.mesh_data = camera, extrinsics, mesh_data

    def view_extrinsics(self, camera: Camera) -> NDArray[np.float64]:
        """``camera.extrinsics`` (C-contiguous), kept from the build when it is the same camera."""
        if camera is self.camera and self.extrinsics is not None:
            return self.extrinsics
        return np.ascontiguousarray(camera.extrinsics)


def build_zbuffer(mesh: trimesh.Trimesh, camera: Camera, n_points: int, *, cells_per_point: float = CELLS_PER_POINT, run=None) -> ZBuffer:
    """Rasterise ``mesh`` for ``camera`` on a grid of about ``cells_per_point × n_points``
    cells over the mesh's projection (module docstring).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame.
    camera : Camera
    n_points : int
        Points to be classified (sets the resolution).
    cells_per_point : float
    run : callable, optional
        ``run(fn, list_of_args)`` calling ``fn(*args)`` for each (a thread pool's map); the
        rows are split in ``run.bands`` bands.  Default: one band, in this thread.

    Returns
    -------
    ZBuffer
        ``shape == (0, 0)`` when the mesh reaches behind the camera plane (or is empty,
        or outside the image).
    """
    bands = max(1, getattr(run, "bands", 1)) if run is not None else 1
    zb, tasks = zbuffer_tasks(mesh, camera, n_points, cells_per_point=cells_per_point, bands=bands)
    if run is None:
        for fn, args in tasks:
            fn(*args)
    elif tasks:
        run(_rasterise, [args for _, args in tasks])
    return zb


def zbuffer_tasks(
    mesh: trimesh.Trimesh, camera: Camera, n_points: int, *, cells_per_point: float = CELLS_PER_POINT, bands: int = 1, grouping: int = 0
) -> tuple[ZBuffer, list]:
    """:func:`build_zbuffer` in two steps: the view's buffer, not yet filled, and the calls that
    fill it, one per band of rows, to be run in any order or at once (a caller's thread pool
    may run other work beside them).

    The bands are cut to take about the same time (from the faces' rows), except that with
    ``grouping`` (the points of a :func:`group_task` run first by one of the threads, beside the
    other bands) the last band is lighter by the grouping's share of work.

    Returns
    -------
    zb : ZBuffer
        Filled once every task has run (the buffer does not depend on the bands).
    tasks : list of (callable, tuple)
        ``fn(*args)`` for each; empty when the view has no buffer.
    """
    data = _mesh_data(mesh)
    rt = np.ascontiguousarray(camera.extrinsics)
    empty = ZBuffer(np.zeros(4), (0, 0), np.zeros((0, _COVER + 1), np.float32), camera, rt, data)
    if len(data.faces) == 0 or n_points == 0:
        return empty, []
    cam, extent = _to_camera(data.vertices, rt, data.used)
    z_min, z_abs_max, a_min, a_max, b_min, b_max = (float(x) for x in extent)
    if z_min <= _MIN_DEPTH * max(z_abs_max, 1e-300):
        return empty, []
    half_a, half_b = camera.width / (2.0 * camera.focal_px), camera.height / (2.0 * camera.focal_px)
    a0, a1 = max(a_min, -half_a), min(a_max, half_a)
    b0, b1 = max(b_min, -half_b), min(b_max, half_b)
    if not (a1 > a0 and b1 > b0):
        return empty, []
    cells = min(max(cells_per_point * n_points, _MIN_CELLS), _MAX_CELLS)
    side = math.sqrt((a1 - a0) * (b1 - b0) / cells)
    ga = max(1, int(math.ceil((a1 - a0) / side)))
    gb = max(1, int(math.ceil((b1 - b0) / side)))
    grid = np.array([a0, b0, ga / (a1 - a0), gb / (b1 - b0)])
    zbuf = np.empty((ga * gb, _COVER + 1), dtype=np.float32)
    zb = ZBuffer(grid, (ga, gb), zbuf, camera, rt, data)
    face_rows = _face_rows(cam, data.raster_faces, grid, gb)
    cuts = _band_cuts(face_rows, gb, max(1, int(bands)), _GROUP_WORK * grouping).tolist()
    return zb, [
        (_rasterise, (cam, data.raster_faces, data.raster_ids, grid, ga, gb, lo, hi, zbuf, zb.ids, face_rows))
        for lo, hi in zip(cuts[:-1], cuts[1:])
        if hi > lo
    ]


def classify(
    mesh: trimesh.Trimesh,
    points: NDArray[np.float64],
    face_index: NDArray[np.int64] | None,
    camera: Camera,
    zb: ZBuffer,
    tolerance: float,
    *,
    run=None,
) -> NDArray[np.uint8]:
    """Status of each point (:data:`HIDDEN`, :data:`VISIBLE`, :data:`UNDECIDED`).

    Parameters
    ----------
    mesh : trimesh.Trimesh
    points : (N, 3) float64, C-contiguous
        World frame.
    face_index : (N,) int64 or None
    camera : Camera
    zb : ZBuffer
        :func:`build_zbuffer`'s for this camera.
    tolerance : float
        The definition's self-hit tolerance, object units.
    run : callable, optional
        As in :func:`build_zbuffer` (the points are split in slices).

    Returns
    -------
    status : (N,) uint8
        ``HIDDEN`` also for points outside the frustum (:meth:`Camera.in_frustum`'s answer).
    """
    data = zb.mesh_data if zb.mesh_data is not None else _mesh_data(mesh)
    n = len(points)
    status = np.empty(n, dtype=np.uint8)
    fi = face_index if face_index is not None else np.zeros(0, dtype=np.int64)
    intr = np.array([camera.focal_px, camera.width, camera.height, camera.znear, camera.zfar])
    args = (
        zb.view_extrinsics(camera),
        intr,
        np.asarray(camera.eye, dtype=np.float64),
        zb.grid,
        zb.shape[0],
        zb.shape[1],
        zb.zbuf,
        zb.ids,
        data.planes,
        float(tolerance),
        EDGE_ON_SIN,
        status,
    )
    if run is None:
        _classify(points, fi, 0, n, *args)
    else:
        parts = max(1, getattr(run, "bands", 1))
        cuts = [n * k // parts for k in range(parts + 1)]
        run(_classify, [(points, fi, cuts[k], cuts[k + 1], *args) for k in range(parts)])
    return status


def cell_of(points: NDArray[np.float64], camera: Camera, zb: ZBuffer) -> NDArray[np.int64]:
    """(N,) int64: the cell of each point, row by row (for ordering rays coherently; points
    outside the grid get some value)."""
    rt = zb.view_extrinsics(camera)
    cam = points[:, 0:1] * rt[:, 0] + points[:, 1:2] * rt[:, 1] + points[:, 2:3] * rt[:, 2] + rt[:, 3]
    ga, gb = max(zb.shape[0], 1), max(zb.shape[1], 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ca = np.nan_to_num((cam[:, 0] / cam[:, 2] - zb.grid[0]) * zb.grid[2])
        cb = np.nan_to_num((cam[:, 1] / cam[:, 2] - zb.grid[1]) * zb.grid[3])
    return np.clip(cb, 0, gb - 1).astype(np.int64) * ga + np.clip(ca, 0, ga - 1).astype(np.int64)


def group_by_face(points: NDArray[np.float64], face_index: NDArray[np.int64], n_faces: int, *, run=None):
    """The points grouped by face (a stable counting sort, ``O(N + F)``): the pre-pass then
    reads each face's planes and cells together, as for a sorted point set, for the price of
    one gather.

    Parameters
    ----------
    points : (N, 3) float64, C-contiguous
    face_index : (N,) int64
    n_faces : int
    run : callable, optional
        As in :func:`build_zbuffer` (the gather is split in slices).

    Returns
    -------
    perm : (N,) int64
        ``points[perm]`` is the grouped order.
    points : (N, 3) float64
        ``points[perm]``.
    face_index : (N,) int64
        ``face_index[perm]``.
    """
    face_index = np.ascontiguousarray(face_index, dtype=np.int64)
    perm = np.empty(len(face_index), dtype=np.int64)
    _face_order(face_index, int(n_faces), perm)
    out, faces = np.empty_like(points), np.empty_like(face_index)
    n = len(perm)
    parts = max(1, getattr(run, "bands", 1)) if run is not None else 1
    cuts = [n * k // parts for k in range(parts + 1)]
    args = [(points, face_index, perm, cuts[k], cuts[k + 1], out, faces) for k in range(parts)]
    if run is None:
        _gather(*args[0])
    else:
        run(_gather, args)
    return perm, out, faces


def group_task(points: NDArray[np.float64], face_index: NDArray[np.int64], n_faces: int):
    """:func:`group_by_face` as one call to be run later (beside other work, e.g. on a thread
    pool next to :func:`zbuffer_tasks`'s): the arrays it will fill, and the call.

    Returns
    -------
    perm, points, face_index : arrays
        As :func:`group_by_face`'s, filled once the task has run.
    task : (callable, tuple)
        ``fn(*args)``.
    """
    face_index = np.ascontiguousarray(face_index, dtype=np.int64)
    perm, out, faces = np.empty(len(face_index), dtype=np.int64), np.empty_like(points), np.empty_like(face_index)
    return perm, out, faces, (_group, (points, face_index, int(n_faces), perm, out, faces))
