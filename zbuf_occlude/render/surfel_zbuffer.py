"""The surfel z-buffer of point-only visibility, filled by an OpenGL compute shader.

:func:`zbuf_occlude.visibility.point_kernels.splat_surfels` (numba, float64) and
:meth:`SurfelZBuffer.splat` (GLSL, float64) fill the same two buffers over the same image:
normalised coordinates ``(x/z, y/z)`` of the OpenCV camera frame, pixel ``(i, j)`` sampled at
``(x0 + (i + ½)·pix, y0 + (j + ½)·pix)``; a surfel (a disk of radius ``r`` centred on ``q`` in
the plane of normal ``n``) covers a pixel where the pixel's central ray meets that plane within
``r`` of ``q``, at depth ``t`` (the intersection's z); the nearest surfel wins, and of surfels
at the same ``t`` the lowest id.

How the GPU fills it (``shaders/point_splat.comp``):

* one invocation per surfel and slice of its rows (:data:`SLICES` slices, so that a surfel's box
  is shared among several invocations); each computes the surfel's pixel box with the kernel's
  formulas, a millionth of ``r`` wider than the disk, and tests the pixels of its rows;
* the coverage test and ``t`` use the kernel's operations, in its order, ``precise`` (no fused or
  reordered operation); the quotient gets one correction from its exact residual, so that a
  division an ulp off the correctly rounded quotient gives the same ``t``;
* the nearest surfel is chosen without a depth test, by atomics on three storage buffers in three
  dispatches over the same pixels: the least high word of ``t``'s bits at each pixel, then the
  least low word among the surfels with that high word, then the least id among those with both.
  So each pixel holds the least ``t`` and, of surfels at exactly that ``t``, the lowest id: the
  kernel's rule (it draws surfels in id order and keeps a depth only if less), whatever order the
  GPU runs the invocations in; a fourth pass, one invocation per pixel, turns the keys back into
  the depth buffer (float64, ``inf`` where no surfel won);
* the buffers are cleared and read back through copies made on the GPU (from a buffer of set
  bits; into a staging buffer, as :func:`~zbuf_occlude.render.compute.read_through` does), so the
  CPU never maps a buffer the shader uses;
* an image whose depth buffer (8 bytes a pixel) would exceed the GL's largest storage block
  (``GL_MAX_SHADER_STORAGE_BLOCK_SIZE``, at least 16 MiB by the specification: 2,097,152 pixels)
  is filled in tiles: bands of whole rows, or parts of one row where a row is longer.

:meth:`SurfelZBuffer.visible` then decides each point on the GPU (``shaders/point_decide.comp``,
:func:`zbuf_occlude.visibility.point_kernels.decide`'s arithmetic, its quotients and square roots
corrected to correct rounding, ``shaders/splat64.glsl``) and reads back the mask alone; an image
of several tiles is left to the CPU's decision (:meth:`SurfelZBuffer.fits_one_tile`).

The buffers are the kernel's, bit for bit, where the GL's float64 addition and multiplication
round to nearest as IEEE 754 says and its division is within an ulp of that: Mesa llvmpipe's
and NVIDIA's are (tests/render/test_surfel_zbuffer*.py on llvmpipe; ``benchmarks/agreement_point_splats.py``
on an NVIDIA H200).

Compute shaders, not the rasteriser: an earlier version drew the same test as point sprites and
quads, with a fragment shader; on an NVIDIA H200 a view at 10,000 points then waited 5.3 ms for
its fragments, where the compute passes and the decision now take about 1 ms
(docs/results/point_visibility.md, "The GPU path").
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from typing import NamedTuple

import moderngl
import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.render import bindings
from zbuf_occlude.render.compute import dispatch, read_through, set_uniforms
from zbuf_occlude.render.context import shared_context
from zbuf_occlude.render.shaders import load_shader

__all__ = ["SLICES", "DecisionRule", "SurfelZBuffer", "shared_surfel_zbuffer", "tiles"]

#: Invocations per surfel: each tests every ``SLICES``-th row of the surfel's pixel box.
SLICES = 8
#: The shader's stages (module docstring).
_DEFINES = (("SPLAT_STAGE_HIGH", 0), ("SPLAT_STAGE_LOW", 1), ("SPLAT_STAGE_ID", 2), ("SPLAT_SLICES", SLICES))
_STAGES = tuple(value for name, value in _DEFINES if name.startswith("SPLAT_STAGE_"))
#: Share of a disk's radius added to each side of its box: far above the rounding of a unit normal
#: and of the disk test (~1e-16), far below a pixel; the kernel's
#: :data:`~zbuf_occlude.visibility.point_kernels.BOX_MARGIN` (the render layer cannot import it;
#: tests/render/test_surfel_zbuffer_agreement.py holds the two together).
_BOX_MARGIN = 1e-6
#: Bytes: the buffers grow in steps of this (they are kept across views).
_BUFFER_STEP = 1 << 20


class SurfelZBuffer:
    """Fills a depth and an id buffer of surfels with an OpenGL compute shader (module docstring).

    Compiles its shaders once; keeps its buffers, grown to the largest tile filled.  Release them
    with :meth:`release` (or use it as a context manager).

    Parameters
    ----------
    context : moderngl.Context, optional
        Default: the process's shared context (:func:`~zbuf_occlude.render.context.shared_context`).

    Attributes
    ----------
    max_tile_bytes : int
        Bytes: the largest storage buffer a shader may bind (``GL_MAX_SHADER_STORAGE_BLOCK_SIZE``);
        an image of more than an eighth of this many pixels (its depth buffer holds 8 bytes a
        pixel) is filled in tiles (module docstring).  May be lowered (e.g. to fill a small image
        in several tiles).

    Raises
    ------
    BackendUnavailable
        No OpenGL 4.3 context can be created, or the shader is missing (a broken install).
    """

    def __init__(self, *, context: moderngl.Context | None = None):
        self.ctx = context or shared_context()
        with self.ctx:
            self._shader = self.ctx.compute_shader(load_shader("point_splat.comp", _DEFINES))
            self._resolve = self.ctx.compute_shader(load_shader("point_splat.comp", (*_DEFINES, ("SPLAT_RESOLVE", 1))))
            self._decide = self.ctx.compute_shader(load_shader("point_decide.comp"))
        self.max_tile_bytes = int(self.ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE", 1 << 24))
        self._buffers: dict[str, moderngl.Buffer] = {}
        self._host = np.empty((0, 7))  # the surfels as uploaded, (N, 7) float64
        self._released = False

    def splat(
        self,
        cam: NDArray[np.floating],
        normal: NDArray[np.floating],
        radius: NDArray[np.floating],
        pix: float,
        x0: float,
        y0: float,
        width: int,
        height: int,
        *,
        edge_on_cos: float,
    ) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
        """Rasterise oriented disks (surfels) into a z-buffer and a surfel-id buffer on the GPU.

        Same arguments and buffers as :func:`zbuf_occlude.visibility.point_kernels.splat_surfels`,
        computed with the same float64 operations: the same buffers, bit for bit, where the GL
        rounds float64 as IEEE 754 says (module docstring).

        Parameters
        ----------
        cam : (N, 3) float
            Surfel centres, OpenCV camera frame, object units.
        normal : (N, 3) float
            Unit normals, same frame (either sign).
        radius : (N,) float
            Disk radii, object units; surfels with ``r <= 0`` or ``z - r <= 0`` are not drawn.
        pix, x0, y0 : float
            Pixel side and the image's top-left corner, normalised image coordinates.
        width, height : int
            Image size, pixels.
        edge_on_cos : float
            A pixel whose ray meets the disk's plane at ``|cos| <`` this is not covered
            (:data:`~zbuf_occlude.visibility.point_kernels.EDGE_ON_COS`).

        Returns
        -------
        depth : (height, width) float64
            ``t`` of the nearest covering surfel, object units; ``inf`` where none.
        ids : (height, width) int32
            Index of that surfel (the lowest of those at the same ``t``), −1 where none.
        """
        n = self._upload(cam, normal, radius)
        depth = np.empty((height, width))
        ids = np.empty((height, width), dtype=np.int32)
        if n == 0 or width * height == 0:
            depth.fill(np.inf)
            ids.fill(-1)
            return depth, ids
        uniforms = _splat_uniforms(n, (pix, x0, y0, width, height), edge_on_cos)
        with self.ctx:
            for i0, j0, w, h in tiles(width, height, self._tile_pixels):
                words = self._fill_tile(n, (i0, j0), (w, h), uniforms)
                if w == width:  # whole rows: read straight into the buffers
                    self._read_tile(words, depth[j0 : j0 + h], ids[j0 : j0 + h])
                else:
                    tile_depth, tile_ids = np.empty((h, w)), np.empty((h, w), dtype=np.int32)
                    self._read_tile(words, tile_depth, tile_ids)
                    depth[j0 : j0 + h, i0 : i0 + w], ids[j0 : j0 + h, i0 : i0 + w] = tile_depth, tile_ids
        return depth, ids

    def fits_one_tile(self, width: int, height: int) -> bool:
        """Whether a ``width`` × ``height`` image is filled in one tile, as :meth:`visible` needs."""
        return width * height <= self._tile_pixels

    @property
    def _tile_pixels(self) -> int:
        """Pixels of the largest tile: its depth buffer (8 bytes a pixel) fits :attr:`max_tile_bytes`."""
        return max(self.max_tile_bytes // 8, 1)

    def visible(
        self,
        cam: NDArray[np.floating],
        normal: NDArray[np.floating],
        radius: NDArray[np.floating],
        spacing: NDArray[np.floating],
        sided: NDArray[np.bool_],
        image: tuple[float, float, float, int, int],
        *,
        edge_on_cos: float,
        rule: DecisionRule,
    ) -> NDArray[np.bool_]:
        """Splat the surfels (:meth:`splat`) and decide each point on the GPU: the mask of
        :func:`zbuf_occlude.visibility.point_kernels.decide` over :meth:`splat`'s buffers, bit
        for bit, where the GL rounds float64 as IEEE 754 says (module docstring); only the mask
        comes back.

        Parameters
        ----------
        cam, normal, radius
            As :meth:`splat`: the points as surfels, OpenCV camera frame.
        spacing : (N,) float
            Local sampling spacing of each point, object units.
        sided : (N,) bool
            The point lies on one side of a thin wall (``decide``'s ``sided``).
        image : (pix, x0, y0, width, height)
            The image, as :meth:`splat` takes it; :meth:`fits_one_tile` must hold for it.
        edge_on_cos : float
            As :meth:`splat`.
        rule : DecisionRule
            ``decide``'s settings and constants.

        Returns
        -------
        visible : (N,) bool
            As ``decide``'s: before the frustum test.

        Raises
        ------
        ValueError
            The image needs more than one tile.
        """
        pix, x0, y0, width, height = image
        if not self.fits_one_tile(width, height):
            raise ValueError(f"a {width} x {height} image is filled in several tiles: decide on the CPU")
        n = self._upload(cam, normal, radius)
        if n == 0 or width * height == 0:
            return np.zeros(n, dtype=np.bool_)
        points = np.stack([np.asarray(spacing, dtype=np.float64).reshape(-1), np.asarray(sided, dtype=np.float64).reshape(-1)], axis=1)
        uniforms = _splat_uniforms(n, image, edge_on_cos)
        with self.ctx:
            self._fill_tile(n, (0, 0), (width, height), uniforms)
            source = self._buffer("points", points.nbytes)
            source.write(points)
            source.bind_to_storage_buffer(bindings.DECIDE_POINTS, size=points.nbytes)
            size = n * np.dtype(np.uint32).itemsize  # one word a point
            result = self._buffer("visible", size)
            result.bind_to_storage_buffer(bindings.DECIDE_VISIBLE, size=size)
            set_uniforms(self._decide, {**uniforms, "n_points": n, **rule.uniforms()})
            dispatch(self._decide, n, "offset")
            self.ctx.memory_barrier()
            words = read_through(self.ctx, result, self._buffer("staging", size), size)
        return np.frombuffer(words, dtype=np.uint32) != 0

    def _upload(self, cam, normal, radius) -> int:
        """Write the surfels (7 float64 each) to the GPU and bind them; their number."""
        if self._released:
            raise RuntimeError("this SurfelZBuffer was released")
        cam = np.asarray(cam, dtype=np.float64).reshape(-1, 3)
        normal = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
        radius = np.asarray(radius, dtype=np.float64).reshape(-1, 1)
        if len(self._host) < len(cam):  # kept: fresh arrays of this size cost more than the copy
            self._host = np.empty((len(cam), 7))
        surfels = np.concatenate([cam, normal, radius], axis=1, out=self._host[: len(cam)])
        if len(cam):
            with self.ctx:
                source = self._buffer("surfels", surfels.nbytes)
                source.write(surfels)
                source.bind_to_storage_buffer(bindings.SPLAT_SURFELS, size=surfels.nbytes)
        return len(cam)

    def _fill_tile(self, n: int, offset: tuple[int, int], size: tuple[int, int], uniforms: dict) -> int:
        """The three stages and the resolve pass over the ``size`` (columns, rows) tile whose
        first pixel is ``offset``: the winners' ids and depths in their buffers, bound.  Returns
        the bytes of a buffer of one uint a pixel."""
        pixels = size[0] * size[1]
        words = 4 * pixels  # bytes of a buffer of one uint a pixel
        blank = self._buffer("blank", words, fill=b"\xff")
        keys = [self._buffer(name, words) for name in ("key_high", "key_low", "winner")]
        for buffer in keys:
            self.ctx.copy_buffer(buffer, blank, words)  # no key, no winner (read as int32: id −1)
        keys[0].bind_to_storage_buffer(bindings.SPLAT_KEY_HIGH, size=words)
        keys[1].bind_to_storage_buffer(bindings.SPLAT_KEY_LOW, size=words)
        keys[2].bind_to_storage_buffer(bindings.SPLAT_WINNER, size=words)
        resolved = self._buffer("depth", 2 * words)
        resolved.bind_to_storage_buffer(bindings.SPLAT_DEPTH, size=2 * words)
        tile = {**uniforms, "tile_offset": offset, "tile_size": size}
        set_uniforms(self._shader, tile)
        for stage in _STAGES:
            self._shader["stage"].value = stage
            dispatch(self._shader, n, "offset", slices=SLICES)
            self.ctx.memory_barrier()  # the next stage sees this one's minima
        set_uniforms(self._resolve, tile)
        dispatch(self._resolve, pixels, "offset")
        self.ctx.memory_barrier()
        return words

    def _read_tile(self, words: int, depth: NDArray[np.float64], ids: NDArray[np.int32]) -> None:
        """The tile just filled, read into ``depth`` and ``ids`` (C-contiguous, its shape)."""
        staging = self._buffer("staging", 3 * words)
        self.ctx.copy_buffer(staging, self._buffers["depth"], 2 * words)
        self.ctx.copy_buffer(staging, self._buffers["winner"], words, write_offset=2 * words)
        staging.read_into(depth, size=2 * words)
        staging.read_into(ids, size=words, offset=2 * words)

    def _buffer(self, name: str, size: int, *, fill: bytes | None = None) -> moderngl.Buffer:
        """The kept buffer ``name``, at least ``size`` bytes (grown in steps of
        :data:`_BUFFER_STEP`); ``fill``: a byte every byte of it holds."""
        buffer = self._buffers.get(name)
        if buffer is None or buffer.size < size:
            if buffer is not None:
                buffer.release()
            grown = -(-max(size, 4) // _BUFFER_STEP) * _BUFFER_STEP
            buffer = self.ctx.buffer(fill * grown) if fill is not None else self.ctx.buffer(reserve=grown)
            self._buffers[name] = buffer
        return buffer

    def release(self) -> None:
        """Free this object's GL objects (the context stays)."""
        if self._released:
            return
        self._released = True
        with self.ctx:
            for buffer in self._buffers.values():
                buffer.release()
            self._buffers.clear()
            self._shader.release()
            self._resolve.release()
            self._decide.release()

    def __enter__(self) -> SurfelZBuffer:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


class DecisionRule(NamedTuple):
    """The settings and constants of :func:`zbuf_occlude.visibility.point_kernels.decide`, as
    :meth:`SurfelZBuffer.visible` hands them to the GPU (the render layer cannot import them)."""

    tolerance: float  #: distance to the tangent plane, spacings
    crease_cos: float  #: normals closer than this (|cos|) are one smooth sheet
    oriented: bool  #: the normals point out of the surface consistently (NORMALS_ORIENTED)
    estimated: bool  #: the normals were estimated (NORMALS_ESTIMATED)
    coplanar: float  #: point_kernels.COPLANAR
    depth_slack: float  #: point_kernels.DEPTH_SLACK
    curvature_slack: float  #: point_kernels.CURVATURE_SLACK
    gap_reach: float  #: point_kernels.GAP_REACH

    def uniforms(self) -> dict:
        """The decision shader's uniforms."""
        return {
            "tolerance": float(self.tolerance), "crease_cos": float(self.crease_cos),
            "oriented": int(bool(self.oriented)), "estimated": int(bool(self.estimated)),
            "coplanar": float(self.coplanar), "depth_slack": float(self.depth_slack),
            "half_slack": float(self.curvature_slack) * 0.5, "gap_reach": float(self.gap_reach),
        }  # fmt: skip


def _splat_uniforms(n: int, image: tuple, edge_on_cos: float) -> dict:
    pix, x0, y0, width, height = image
    return {
        "n_surfels": n, "size": (int(width), int(height)), "pix": float(pix), "x0": float(x0), "y0": float(y0),
        "edge_on_cos2": float(edge_on_cos) * float(edge_on_cos), "box_margin": _BOX_MARGIN,
    }  # fmt: skip


def tiles(width: int, height: int, max_pixels: int) -> Iterator[tuple[int, int, int, int]]:
    """``(i0, j0, w, h)`` of the tiles of at most ``max_pixels`` pixels that cover a ``width`` ×
    ``height`` image, row by row: bands of whole rows, or parts of one row where a row is longer."""
    if width <= max_pixels:
        rows = min(height, max_pixels // width)
        for j0 in range(0, height, rows):
            yield 0, j0, width, min(rows, height - j0)
    else:
        for j0 in range(height):
            for i0 in range(0, width, max_pixels):
                yield i0, j0, min(max_pixels, width - i0), 1


_shared: dict[int, SurfelZBuffer] = {}
_shared_lock = threading.Lock()


def shared_surfel_zbuffer() -> SurfelZBuffer:
    """The process's :class:`SurfelZBuffer` over the shared context (made on first use).

    Per process, as :func:`~zbuf_occlude.render.context.shared_context`: a forked worker makes
    its own and never touches its parent's.  Its GL objects live as long as the context.

    Raises
    ------
    BackendUnavailable
        No OpenGL 4.3 context can be created.
    """
    ctx = shared_context()
    key = os.getpid()
    with _shared_lock:
        zbuffer = _shared.get(key)
        if zbuffer is None or zbuffer.ctx is not ctx:
            for stale in [k for k in _shared if k != key]:
                del _shared[stale]  # inherited across fork: unusable, never released here
            if zbuffer is not None:
                zbuffer.release()
            zbuffer = _shared[key] = SurfelZBuffer(context=ctx)
        return zbuffer
