"""The surfel z-buffer of point-only visibility, rasterised by OpenGL as point sprites.

:func:`zbuf_occlude.visibility.point_kernels.splat_surfels` (numba, float64) and
:meth:`PointSpriteRenderer.splat` (GLSL, float64) fill the same two buffers over the same image:
normalised coordinates ``(x/z, y/z)`` of the OpenCV camera frame, pixel ``(i, j)`` sampled at
``(x0 + (i + ½)·pix, y0 + (j + ½)·pix)``; a surfel (a disk of radius ``r`` centred on ``q`` in
the plane of normal ``n``) covers a pixel where the pixel's central ray meets that plane within
``r`` of ``q``, at depth ``t`` (the intersection's z); the nearest surfel wins, and of surfels
at the same ``t`` the lowest id.

How the GPU draws it (``shaders/point_splat.vert``, ``shaders/point_splat.frag``):

* the image rectangle is mapped orthographically onto clip space (it is already in normalised
  coordinates); each surfel's pixel box is the projection of the box that holds its disk
  (``q ± r sqrt(1 − n_a²)`` per axis ``a``, a millionth of ``r`` wider), clamped to the image,
  computed here in float64 as the kernel computes its own: every pixel the disk test can pass;
* one GL point per surfel, centred on its box, ``gl_PointSize`` = the box's longer side + 2 pixels;
* the fragment shader reads the surfel in float64 and computes the pixel's ray, the edge-on and
  the disk tests and ``t`` with the kernel's operations, in its order, ``precise`` (no fused or
  reordered operation); the quotient gets one correction from its exact residual, so that a
  division an ulp off the correctly rounded quotient gives the same ``t``;
* the nearest surfel is chosen without a depth test, by image atomics in three stages over the
  same fragments: the least high word of ``t``'s bits at each pixel, then the least low word
  among the fragments with that high word, then the least id among those with both.  So each
  pixel holds the least ``t`` and, of surfels at exactly that ``t``, the lowest id: the kernel's
  rule (it draws surfels in id order and keeps a depth only if less), whatever order the GPU
  runs the fragments in;
* **the quad pass**: a surfel whose sprite would exceed the GL's largest point size
  (``GL_POINT_SIZE_RANGE``: 255 pixels on Mesa llvmpipe), or whose box centre falls outside the
  tile (GL drops a point whose centre is clipped, however large its sprite), is drawn as an
  instanced quad over its box by the same fragment shader;
* an image larger than the GL's maximum image size (:func:`~zbuf_occlude.render.context.max_image_size`)
  is drawn in tiles.

The buffers are the kernel's, bit for bit, where the GL's float64 addition and multiplication
round to nearest as IEEE 754 says and its division is within an ulp of that (Mesa llvmpipe's are:
tests/render/test_point_sprites*.py; no other GL measured yet).  Each stage runs the fragment
shader over every fragment, in float64: on llvmpipe a view takes about 7 times as long as one
float32 depth-tested pass over the same surfels (which decides near-ties either way).
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
from zbuf_occlude.render.context import max_image_size, shared_context
from zbuf_occlude.render.shaders import load_shader

__all__ = ["PointSpriteRenderer", "shared_point_sprites"]

#: One surfel as the vertex shader reads it (20 bytes): its id and its pixel box.  The fragment
#: shader reads the surfel itself from a storage buffer: 7 float64 (centre, normal, radius).
_SURFEL = np.dtype([("id", "<i4"), ("box", "<i4", 4)])
_SURFEL_FORMAT = "1i 4i"
_SURFEL_ATTRIBUTES = ("in_id", "in_box")
#: The fragment shader's stages (module docstring); its bindings are :mod:`~zbuf_occlude.render.bindings`' SPLAT_ names.
_DEFINES = (("SPLAT_STAGE_HIGH", 0), ("SPLAT_STAGE_LOW", 1), ("SPLAT_STAGE_ID", 2))
#: The image unit of each of a target's images, in :attr:`_Target.images`' order.
_IMAGE_UNITS = (bindings.SPLAT_KEY_HIGH, bindings.SPLAT_KEY_LOW, bindings.SPLAT_WINNER)
_STAGES = tuple(value for name, value in _DEFINES if name.startswith("SPLAT_STAGE_"))
#: Share of a disk's radius added to each side of its box (:class:`_Boxes`): far above the
#: rounding of a unit normal and of the disk test (~1e-16), far below a pixel; the kernel's
#: :data:`~zbuf_occlude.visibility.point_kernels.BOX_MARGIN` (the render layer cannot import it;
#: tests/render/test_point_sprites_agreement.py holds the two together).
_BOX_MARGIN = 1e-6
#: Pixels kept between a sprite's centre and the tile's border, where GL would clip the point.
_SPRITE_MARGIN_PX = 1.0
#: Pixels: the render target's sides grow in steps of this (it is kept across views).
_TARGET_STEP = 256
#: The images' clear value: no key, no winner (read as int32: id −1).
_NONE = np.uint32(0xFFFFFFFF)


class _Target(NamedTuple):
    size: tuple[int, int]
    images: tuple[moderngl.Texture, ...]
    draw: moderngl.Framebuffer
    read: moderngl.Framebuffer


class PointSpriteRenderer:
    """Rasterises surfels into a depth and an id buffer with OpenGL (module docstring).

    Compiles its two programs (sprites, quads) once; keeps one render target, grown to the
    largest tile drawn; every per-view buffer is released before :meth:`splat` returns.  Release
    the rest with :meth:`release` (or use it as a context manager).

    Parameters
    ----------
    context : moderngl.Context, optional
        Default: the process's shared context (:func:`~zbuf_occlude.render.context.shared_context`).

    Attributes
    ----------
    max_point_size : float
        Pixels: the GL's largest point size (upper end of ``GL_POINT_SIZE_RANGE``); larger
        sprites go to the quad pass.  May be lowered (e.g. to send every surfel there).
    max_tile : int
        Pixels: the largest tile side (:func:`~zbuf_occlude.render.context.max_image_size`).
        May be lowered (e.g. to draw a small image in several tiles).

    Raises
    ------
    BackendUnavailable
        No OpenGL 4.3 context can be created, or the shaders are missing (a broken install).
    """

    def __init__(self, *, context: moderngl.Context | None = None):
        self.ctx = context or shared_context()
        with self.ctx:
            self._programs = {
                quads: self.ctx.program(
                    vertex_shader=load_shader("point_splat.vert", (("SPLAT_QUADS", 1),) if quads else ()),
                    fragment_shader=load_shader("point_splat.frag", _DEFINES),
                )
                for quads in (False, True)
            }
        self.max_point_size = float(self.ctx.info["GL_POINT_SIZE_RANGE"][1])
        self.max_tile = max_image_size(self.ctx)
        self._target: _Target | None = None
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
        if self._released:
            raise RuntimeError("this PointSpriteRenderer was released")
        cam = np.asarray(cam, dtype=np.float64).reshape(-1, 3)
        radius = np.asarray(radius, dtype=np.float64).reshape(-1)
        depth = np.full((height, width), np.inf)
        ids = np.full((height, width), -1, dtype=np.int32)
        normal = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
        boxes = _Boxes(cam, normal, radius, pix, x0, y0, width, height)
        if not boxes.drawn.any():
            return depth, ids
        records = np.empty(len(cam), dtype=_SURFEL)
        records["id"] = np.arange(len(cam), dtype=np.int32)
        records["box"] = boxes.box
        surfels64 = np.concatenate([cam, normal, radius[:, None]], axis=1)
        uniforms = {
            "pix": float(pix), "x0": float(x0), "y0": float(y0),
            "edge_on_cos2": float(edge_on_cos) * float(edge_on_cos),
        }  # fmt: skip
        with self.ctx:
            surfel_buffer = self.ctx.buffer(np.ascontiguousarray(surfels64).tobytes())
            try:
                surfel_buffer.bind_to_storage_buffer(bindings.SPLAT_SURFELS)
                for i0, j0, w, h in _tiles(width, height, self.max_tile):
                    sprites, quads = boxes.split(i0, j0, w, h, self.max_point_size)
                    tile_ids, tile_t = self._draw_tile(records[sprites], records[quads], (i0, j0), (w, h), uniforms)
                    ids[j0 : j0 + h, i0 : i0 + w] = tile_ids
                    depth[j0 : j0 + h, i0 : i0 + w] = np.where(tile_ids >= 0, tile_t, np.inf)
            finally:
                surfel_buffer.release()
        return depth, ids

    def _draw_tile(self, sprites, quads, offset, size, uniforms) -> tuple[NDArray[np.int32], NDArray[np.float64]]:
        """Draw the sprites and the quads, each stage in turn, into a ``size`` tile whose first
        pixel is ``offset``; read back the winners' ids (−1 none) and their ``t``, rows of
        increasing ``j``."""
        target = self._target_of(size)
        viewport = (0, 0, *size)
        width, height = size
        for texture in target.images:
            texture.write(np.full((height, width), _NONE).tobytes(), viewport=viewport)
        for unit, texture in zip(_IMAGE_UNITS, target.images):
            texture.bind_to_image(unit, read=True, write=True)
        target.draw.use()
        self.ctx.viewport = viewport
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        self.ctx.enable(moderngl.PROGRAM_POINT_SIZE)
        tile_uniforms = {**uniforms, "tile_offset": offset, "tile_size": tuple(float(v) for v in size)}
        draws = [(as_quads, records) for as_quads, records in ((False, sprites), (True, quads)) if len(records)]
        buffers = [self.ctx.buffer(records.tobytes()) for _, records in draws]
        try:
            for stage in _STAGES:
                for (as_quads, records), buffer in zip(draws, buffers):
                    self._draw(as_quads, records, buffer, {**tile_uniforms, "stage": stage})
                self.ctx.memory_barrier()  # the next stage (and the read-back) sees this one's minima
        finally:
            for buffer in buffers:
                buffer.release()
        self.ctx.disable(moderngl.PROGRAM_POINT_SIZE)

        def read(attachment: int) -> NDArray[np.uint32]:
            data = target.read.read(viewport=viewport, components=1, attachment=attachment, dtype="u4")
            return np.frombuffer(data, dtype=np.uint32).reshape(height, width)

        high, low, winner = (read(k) for k in range(3))
        key = (high.astype(np.uint64) << np.uint64(32)) | low
        # key64 in the shader, undone: the sign bit set held a positive t, every bit flipped a negative one
        negative = (key >> np.uint64(63)) == 0
        bits = np.where(negative, ~key, key ^ np.uint64(1 << 63))
        return winner.view(np.int32), bits.view(np.float64)

    def _draw(self, quads: bool, records: NDArray[np.void], buffer: moderngl.Buffer, uniforms: dict) -> None:
        program = self._programs[quads]
        for name, value in uniforms.items():
            if name in program:  # the compiler drops unused uniforms
                program[name].value = value
        fmt = _SURFEL_FORMAT + ("/i" if quads else "")
        vao = self.ctx.vertex_array(program, [(buffer, fmt, *_SURFEL_ATTRIBUTES)])
        try:
            if quads:
                vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=len(records))
            else:
                vao.render(moderngl.POINTS, vertices=len(records))
        finally:
            vao.release()

    def _target_of(self, size: tuple[int, int]) -> _Target:
        """The images (key's high and low words, winner: R32UI) at least ``size``, with a
        framebuffer without attachments to draw into and one over the images to read them: kept
        and grown in steps of :data:`_TARGET_STEP` pixels, since each view's image has its own size."""
        have = self._target.size if self._target is not None else (0, 0)
        if size[0] > have[0] or size[1] > have[1]:
            self._release_target()
            step = _TARGET_STEP
            grown = tuple(min(max(old, -(-need // step) * step), self.max_tile) for old, need in zip(have, size))
            images = tuple(self.ctx.texture(grown, 1, dtype="u4") for _ in range(3))
            self._target = _Target(grown, images, self.ctx.empty_framebuffer(grown), self.ctx.framebuffer(list(images)))
        return self._target

    def _release_target(self) -> None:
        if self._target is not None:
            for obj in (self._target.draw, self._target.read, *self._target.images):
                obj.release()
            self._target = None

    def release(self) -> None:
        """Free this renderer's GL objects (the context stays)."""
        if self._released:
            return
        self._released = True
        with self.ctx:
            self._release_target()
            for program in self._programs.values():
                program.release()

    def __enter__(self) -> PointSpriteRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


class _Boxes:
    """Each surfel's pixel box (float64, clamped to the image), and its sprite: the projection of
    the box ``q ± e`` that holds the disk, ``e_a = r (sqrt(1 - n_a²) + margin)`` for a unit normal
    (``e_z`` at most ``r``; extreme at its corners), which holds every pixel the kernel's disk
    test can pass; the fragment shader tests no pixel outside it."""

    def __init__(self, cam, normal, radius, pix, x0, y0, width, height):
        z = cam[:, 2]
        ok = (radius > 0.0) & (z - radius > 0.0)
        e = radius[:, None] * (np.sqrt(np.maximum(1.0 - normal * normal, 0.0)) + _BOX_MARGIN)
        e[:, 2] = np.minimum(e[:, 2], radius)
        near = np.where(ok, z - e[:, 2], 1.0)
        far = np.where(ok, z + e[:, 2], 1.0)
        lo_x, hi_x = cam[:, 0] - e[:, 0], cam[:, 0] + e[:, 0]
        lo_y, hi_y = cam[:, 1] - e[:, 1], cam[:, 1] + e[:, 1]
        with np.errstate(invalid="ignore", over="ignore"):
            box = np.stack([
                np.floor((np.minimum(lo_x / near, lo_x / far) - x0) / pix),
                np.floor((np.minimum(lo_y / near, lo_y / far) - y0) / pix),
                np.floor((np.maximum(hi_x / near, hi_x / far) - x0) / pix),
                np.floor((np.maximum(hi_y / near, hi_y / far) - y0) / pix),
            ], axis=1)  # fmt: skip
        self.drawn = ok & (box[:, 2] >= 0) & (box[:, 0] <= width - 1) & (box[:, 3] >= 0) & (box[:, 1] <= height - 1)
        #: (N, 4) int64 (i0, j0, i1, j1), clamped to the image; meaningful where ``drawn``
        self.box = np.where(self.drawn[:, None], np.clip(box, 0, [width - 1, height - 1] * 2), 0).astype(np.int64)

    def split(self, i0: int, j0: int, w: int, h: int, max_size: float) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Ids of the surfels drawn in the tile ``[i0, i0 + w) × [j0, j0 + h)``, ascending: as
        sprites, and as quads (larger than ``max_size`` pixels, or centred outside the tile)."""
        b = self.box
        touch = self.drawn & (b[:, 2] >= i0) & (b[:, 0] <= i0 + w - 1) & (b[:, 3] >= j0) & (b[:, 1] <= j0 + h - 1)
        side = np.maximum(b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]) + 1
        centre_x, centre_y = 0.5 * (b[:, 0] + b[:, 2] + 1), 0.5 * (b[:, 1] + b[:, 3] + 1)
        margin = _SPRITE_MARGIN_PX
        inside = (
            (centre_x >= i0 + margin) & (centre_x <= i0 + w - margin)
            & (centre_y >= j0 + margin) & (centre_y <= j0 + h - margin)
        )  # fmt: skip
        sprite = touch & inside & (side + 2 <= max_size)
        return np.flatnonzero(sprite), np.flatnonzero(touch & ~sprite)


def _tiles(width: int, height: int, limit: int) -> Iterator[tuple[int, int, int, int]]:
    """``(i0, j0, w, h)`` of the tiles, at most ``limit`` pixels a side, that cover the image."""
    for j0 in range(0, height, limit):
        for i0 in range(0, width, limit):
            yield i0, j0, min(limit, width - i0), min(limit, height - j0)


_shared: dict[int, PointSpriteRenderer] = {}
_shared_lock = threading.Lock()


def shared_point_sprites() -> PointSpriteRenderer:
    """The process's :class:`PointSpriteRenderer` over the shared context (made on first use).

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
        renderer = _shared.get(key)
        if renderer is None or renderer.ctx is not ctx:
            for stale in [k for k in _shared if k != key]:
                del _shared[stale]  # inherited across fork: unusable, never released here
            if renderer is not None:
                renderer.release()
            renderer = _shared[key] = PointSpriteRenderer(context=ctx)
        return renderer
