"""GPU side of ``zbuffer-exact``: faces binned into screen tiles, every point decided exactly.

Per view, three compute passes (``shaders/exact_bin.comp``, ``shaders/exact_points.comp``):

1. *count*: each distinct face adds 1 to every tile (``tile × tile`` pixels) its projected
   bounding box overlaps, grown by ``margin`` pixels; faces reaching behind the near plane
   go to a global list instead;
2. the CPU reads the counts (one int per tile) and writes the list starts (a prefix sum);
   *fill* writes the face ids;
3. *points*: each point tests every face of its tile (and the global list): float32 with an
   error bound, float64 for pairs inside the bound (the oracle's arithmetic).  Two bits per
   point come back: visible, and "cpu" (a float64 result within 1e-12 of a boundary, or a
   point on the frustum's border), which the caller decides on the CPU.

:meth:`ExactMesh.visible` runs them in turn, one method each (``_count_pass``, ``_prefix_sum``,
``_fill_pass``, ``_points_pass``, then ``_read_back``); every pass binds the buffers its shader
declares, by the names of :mod:`zbuf_occlude.render.bindings`.

A face that meets the segment from a point to the camera contains the point's projection,
so it is in the point's tile: the candidate set is complete by construction, however thin
the face (no pixel centre needs to sample it).
"""

from __future__ import annotations

import math
import time

import moderngl
import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.geometry.grouping import exact_face_groups, morton_order
from zbuf_occlude.render import bindings
from zbuf_occlude.render.compute import dispatch, read_through, set_uniforms
from zbuf_occlude.render.context import is_software_renderer
from zbuf_occlude.render.shaders import load_shader

__all__ = ["ExactMesh", "ExactPoints", "DEFAULT_TILE", "BIN_MARGIN_PX"]

#: Tile side in pixels: a point tests the faces binned into its tile.
DEFAULT_TILE = 8
#: Growth of each face's projected box, pixels (float32 projection error is ~1e-3 px at 1024²).
BIN_MARGIN_PX = 0.01
#: Points this close to the image border (pixels, plus 1e-5 of the image size) are left to the CPU.
FRUSTUM_MARGIN_PX = 1e-3
#: Invocations per face in the bin passes on a GPU, each taking every BIN_SLICES-th tile of the
#: face's box: a face covering thousands of tiles (a box side seen close) would otherwise be one
#: thread's serial loop, while small faces cost the extra invocations almost nothing.  On a
#: software rasteriser every invocation costs CPU time, so there each face is one invocation
#: (32 slices made the bin passes of a 27k-face mesh 10x slower on llvmpipe).
BIN_SLICES = 32
_EPS32 = 2.0**-24


class ExactPoints:
    """Points uploaded for :class:`ExactMesh` (float32 and float64 copies, own-face ids),
    stored in :func:`morton_order`; the shader writes each point's bits at its index in the
    caller's order (``index``), so that results need no permutation on the CPU."""

    def __init__(self, ctx: moderngl.Context, points: NDArray[np.float64], own: NDArray[np.int64] | None):
        order = morton_order(points)
        points = points[order]
        own = None if own is None else own[order]
        self.n_points = len(points)
        n = max(self.n_points, 1)
        p32 = np.zeros((n, 4), dtype=np.float32)
        p32[: self.n_points, :3] = points
        p64 = np.zeros((n, 3), dtype=np.float64)
        p64[: self.n_points] = points
        faces = np.full(n, -1, dtype=np.int32)
        if own is not None:
            faces[: self.n_points] = own
        self.coord_max = float(np.abs(points).max(initial=0.0))
        self.points32 = ctx.buffer(p32.tobytes())
        self.points64 = ctx.buffer(p64.tobytes())
        self.faces = ctx.buffer(faces.tobytes())
        index = np.zeros(n, dtype=np.uint32)
        index[: self.n_points] = order
        self.index = ctx.buffer(index.tobytes())
        self.bits = ctx.buffer(reserve=2 * 4 * max(math.ceil(self.n_points / 32), 1))
        #: What the CPU reads: ``bits`` copied here on the GPU (:func:`~zbuf_occlude.render.compute.read_through`).
        self.bits_read = ctx.buffer(reserve=self.bits.size)

    def release(self) -> None:
        for buf in (self.points32, self.points64, self.faces, self.index, self.bits, self.bits_read):
            buf.release()


class ExactMesh:
    """One mesh on the GPU for ``zbuffer-exact``.

    Parameters
    ----------
    ctx : moderngl.Context
        Needs OpenGL 4.3 with float64 in shaders (GLSL 4.00).
    triangles : (F, 3, 3) float64
        World frame.
    planes : (F, 16) float64
        Per face: normal (3), offset, edge normals (3 × 3), edge offsets (3), as the oracle's
        ``TrianglePlanes`` (the GPU re-decides ties with them).
    """

    def __init__(self, ctx: moderngl.Context, triangles: NDArray[np.float64], planes: NDArray[np.float64]):
        tri = np.asarray(triangles, dtype=np.float64)
        if len(tri) == 0:
            raise InvalidInputError("cannot test visibility against a mesh with no faces")
        self.ctx = ctx
        self.n_faces = len(tri)
        #: (F,) the representative of each face's group of bit-identical faces.
        self.group = exact_face_groups(tri)
        binned = np.flatnonzero(self.group == np.arange(self.n_faces)).astype(np.int32)
        self.n_bin_faces = len(binned)
        self.coord_max = float(np.abs(tri).max())
        with ctx:
            self._triangles = ctx.buffer(tri.astype(np.float32).tobytes())
            self._planes = ctx.buffer(np.ascontiguousarray(planes, dtype=np.float64).tobytes())
            self._bin_faces = ctx.buffer(binned.tobytes())
            self._global = ctx.buffer(reserve=4 * (self.n_bin_faces + 1))
            self._global_read = ctx.buffer(reserve=4)
            self._params = ctx.buffer(reserve=8 * 8)
            self._count = self._count_read = self._starts = self._list = None
            self._n_tiles = -1
            self._list_capacity = 0
            self._bin_count = ctx.compute_shader(load_shader("exact_bin.comp", (("BIN_FILL", 0),)))
            self._bin_fill = ctx.compute_shader(load_shader("exact_bin.comp", (("BIN_FILL", 1),)))
            self._points = ctx.compute_shader(load_shader("exact_points.comp"))
        #: Invocations per face in the bin passes (:data:`BIN_SLICES`; 1 on a software rasteriser).
        self.bin_slices = 1 if is_software_renderer(str(ctx.info["GL_RENDERER"])) else BIN_SLICES
        self.last_stats: dict[str, int] = {}
        #: When true, :meth:`visible` waits for the GPU after each stage and records
        #: :attr:`last_timings` (for benchmarks: the waits cost time themselves).
        self.profile = False
        #: Seconds per stage of the last :meth:`visible` call when :attr:`profile` is set.
        self.last_timings: dict[str, float] = {}

    def upload_points(self, points: NDArray[np.float64], face_index: NDArray[np.int64] | None) -> ExactPoints:
        """Upload ``points (N, 3)`` world frame and their optional own faces."""
        own = None if face_index is None else self.group[face_index]
        with self.ctx:
            return ExactPoints(self.ctx, np.asarray(points, dtype=np.float64), own)

    def _tile_buffers(self, n_tiles: int) -> None:
        if n_tiles != self._n_tiles:
            for buf in (self._count, self._count_read, self._starts):
                if buf is not None:
                    buf.release()
            self._count = self.ctx.buffer(reserve=4 * (n_tiles + 1))
            self._count_read = self.ctx.buffer(reserve=4 * (n_tiles + 1))
            self._starts = self.ctx.buffer(reserve=4 * (n_tiles + 1))
            self._n_tiles = n_tiles

    def _stamp(self, stamps: list[tuple[str, float]], stage: str) -> None:
        if self.profile:
            self.ctx.finish()
            stamps.append((stage, time.perf_counter()))

    def visible(
        self,
        camera: Camera,
        points: ExactPoints,
        *,
        tolerance: float,
        edge_sin: float,
        tile: int = DEFAULT_TILE,
    ) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """Decide every uploaded point from ``camera``: the passes of the module docstring in turn.

        Returns
        -------
        visible : (N,) bool
            The GPU's decision (meaningless where ``cpu``).
        cpu : (N,) bool
            Points the GPU leaves to the CPU (float64 near-ties, frustum border).

        Raises
        ------
        InvalidInputError
            ``tile`` < 1, or more than 2^31 (tile, face) entries (a larger tile is needed).
        """
        if int(tile) < 1:
            raise InvalidInputError(f"tile must be >= 1 pixel, got {tile!r}")
        n = points.n_points
        if n == 0:
            return np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)
        width, height = camera.resolution
        tiles = (math.ceil(width / tile), math.ceil(height / tile))
        n_tiles = tiles[0] * tiles[1]
        uniforms = self._uniforms(camera, points, tolerance=tolerance, edge_sin=edge_sin, tile=int(tile), tiles=tiles)
        params = np.array([*camera.eye, tolerance, edge_sin], dtype=np.float64)
        stamps = [("", time.perf_counter())]
        with self.ctx:
            self._count_pass(uniforms, n_tiles)
            self._stamp(stamps, "bin count")
            counts = self._prefix_sum(n_tiles, tile)
            self._stamp(stamps, "prefix sum")
            self._fill_pass(uniforms)
            self._stamp(stamps, "bin fill")
            self._points_pass(points, uniforms, params)
            self._stamp(stamps, "points")
            words, n_global = self._read_back(points)
            self._stamp(stamps, "read back")
        self.last_stats = {
            "tiles": n_tiles,
            "entries": int(counts.sum()),
            "global_faces": n_global,
            "max_per_tile": int(counts.max(initial=0)),
        }
        visible, cpu = _unpack(words, n)
        self._stamp(stamps, "unpack")
        self.last_timings = {stage: t - stamps[k][1] for k, (stage, t) in enumerate(stamps[1:])}
        return visible, cpu

    def _uniforms(
        self, camera: Camera, points: ExactPoints, *, tolerance: float, edge_sin: float, tile: int, tiles: tuple[int, int]
    ) -> dict:
        """The uniforms of the three shaders (each takes the ones it declares)."""
        width, height = camera.resolution
        eye = np.asarray(camera.eye, dtype=np.float64)
        scale = max(self.coord_max, points.coord_max)
        return {
            "view_projection": (camera.projection_matrix @ camera.view_matrix).T.astype(np.float32).tobytes(),
            "resolution": (width, height),
            "tile": tile,
            "tiles": tiles,
            "n_bin_faces": self.n_bin_faces,
            "near_w": float(0.5 * camera.znear),
            "margin": float(BIN_MARGIN_PX + 1e-5 * max(width, height)),
            "depth_row": tuple(float(v) for v in -camera.view_matrix[2]),
            "n_points": points.n_points,
            "eye": tuple(float(v) for v in eye),
            "tolerance": float(tolerance),
            "edge_sin": float(edge_sin),
            "coord_err": float(8.0 * _EPS32 * scale),
            "dir_err": float(8.0 * _EPS32 * (scale + float(np.abs(eye).max()))),
            "depth_range": (float(camera.znear), float(camera.zfar)),
            "frustum_margin": float(FRUSTUM_MARGIN_PX + 1e-5 * max(width, height)),
        }

    def _count_pass(self, uniforms: dict, n_tiles: int) -> None:
        """Pass 1: count the faces of each tile; faces reaching behind the near plane go to the global list."""
        self._tile_buffers(n_tiles)
        self._count.clear()
        self._global.write(np.zeros(1, dtype=np.uint32).tobytes())
        self._triangles.bind_to_storage_buffer(bindings.EXACT_TRIANGLES)
        self._count.bind_to_storage_buffer(bindings.EXACT_TILE_COUNT)
        self._global.bind_to_storage_buffer(bindings.EXACT_GLOBAL_FACES)
        self._bin_faces.bind_to_storage_buffer(bindings.EXACT_BIN_FACES)
        set_uniforms(self._bin_count, uniforms)
        dispatch(self._bin_count, self.n_bin_faces, "face_offset", slices=self.bin_slices)
        self.ctx.memory_barrier()

    def _prefix_sum(self, n_tiles: int, tile: int) -> NDArray[np.int64]:
        """Pass 2 (CPU): read the counts, write each tile's list start and the fill pass's write
        cursors, grow the list buffer when needed; returns the ``(n_tiles,) int64`` counts."""
        counts = np.frombuffer(read_through(self.ctx, self._count, self._count_read, 4 * n_tiles), dtype=np.uint32).astype(np.int64)
        starts = np.zeros(n_tiles + 1, dtype=np.int64)
        np.cumsum(counts, out=starts[1:])
        total = int(starts[-1])
        if total > 2**31:
            raise InvalidInputError(f"{total} (tile, face) entries: use a larger tile than {tile} px")
        if total > self._list_capacity:
            if self._list is not None:
                self._list.release()
            self._list_capacity = max(int(total * 1.5), 1024)
            self._list = self.ctx.buffer(reserve=8 * self._list_capacity)
        self._starts.write(starts.astype(np.uint32).tobytes())
        self._count.write(starts.astype(np.uint32).tobytes())  # write cursors
        return counts

    def _fill_pass(self, uniforms: dict) -> None:
        """Pass 2 (GPU): write each binned face into the lists of the tiles it overlaps."""
        self._triangles.bind_to_storage_buffer(bindings.EXACT_TRIANGLES)
        self._count.bind_to_storage_buffer(bindings.EXACT_TILE_COUNT)
        self._list.bind_to_storage_buffer(bindings.EXACT_TILE_FACES)
        self._global.bind_to_storage_buffer(bindings.EXACT_GLOBAL_FACES)
        self._bin_faces.bind_to_storage_buffer(bindings.EXACT_BIN_FACES)
        set_uniforms(self._bin_fill, uniforms)
        dispatch(self._bin_fill, self.n_bin_faces, "face_offset", slices=self.bin_slices)
        self.ctx.memory_barrier()

    def _points_pass(self, points: ExactPoints, uniforms: dict, params: NDArray[np.float64]) -> None:
        """Pass 3: each point against the global list and its tile's list; ``params`` (5,) float64:
        eye xyz (world frame), tolerance (object units), edge-on sine."""
        self._params.write(params.tobytes())
        points.points32.bind_to_storage_buffer(bindings.EXACT_POINTS)
        points.faces.bind_to_storage_buffer(bindings.EXACT_POINT_FACES)
        self._triangles.bind_to_storage_buffer(bindings.EXACT_TRIANGLES)
        points.bits.bind_to_storage_buffer(bindings.EXACT_BITS)
        self._planes.bind_to_storage_buffer(bindings.EXACT_PLANES)
        points.points64.bind_to_storage_buffer(bindings.EXACT_POINTS64)
        self._starts.bind_to_storage_buffer(bindings.EXACT_TILE_START)
        self._list.bind_to_storage_buffer(bindings.EXACT_TILE_FACES)
        self._global.bind_to_storage_buffer(bindings.EXACT_GLOBAL_FACES)
        self._params.bind_to_storage_buffer(bindings.EXACT_PARAMS)
        points.index.bind_to_storage_buffer(bindings.EXACT_POINT_INDEX)
        points.bits.clear()
        set_uniforms(self._points, uniforms)
        dispatch(self._points, points.n_points, "point_offset")
        self.ctx.memory_barrier()

    def _read_back(self, points: ExactPoints) -> tuple[NDArray[np.uint32], int]:
        """The points pass's words ``(2, ceil(N / 32)) uint32`` (visible, cpu) and the global list's length."""
        words = np.frombuffer(read_through(self.ctx, points.bits, points.bits_read, points.bits.size), dtype=np.uint32).reshape(2, -1)
        n_global = int(np.frombuffer(read_through(self.ctx, self._global, self._global_read, 4), dtype=np.uint32)[0])
        return words, n_global

    def release(self) -> None:
        """Free the GL objects of this mesh."""
        with self.ctx:
            for obj in (
                self._triangles,
                self._planes,
                self._bin_faces,
                self._global,
                self._global_read,
                self._params,
                self._count,
                self._count_read,
                self._starts,
                self._list,
                self._bin_count,
                self._bin_fill,
                self._points,
            ):
                if obj is not None:
                    obj.release()


def _unpack(words: NDArray[np.uint32], n: int) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """``visible, cpu`` ``(n,) bool`` from the points pass's words, already in the caller's order
    (the shader wrote each bit at :attr:`ExactPoints.index`)."""
    visible = np.unpackbits(words[0].view(np.uint8), count=n, bitorder="little").view(bool)
    cpu = np.zeros(n, dtype=bool)
    if words[1].any():  # most views leave no point to the CPU
        cpu = np.unpackbits(words[1].view(np.uint8), count=n, bitorder="little").view(bool)
    return visible, cpu
