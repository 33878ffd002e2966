"""The surfel z-buffer of point-only visibility, rasterised by OpenGL as point sprites.

:func:`zbuf_occlude.visibility.point_kernels.splat_surfels` (numba, float64) and
:meth:`PointSpriteRenderer.splat` (GLSL, float32) fill the same two buffers over the same image:
normalised coordinates ``(x/z, y/z)`` of the OpenCV camera frame, pixel ``(i, j)`` sampled at
``(x0 + (i + ½)·pix, y0 + (j + ½)·pix)``; a surfel (a disk of radius ``r`` centred on ``q`` in
the plane of normal ``n``) covers a pixel where the pixel's central ray meets that plane within
``r`` of ``q``, at depth ``t`` (the intersection's z); the nearest surfel wins.

How the GPU draws it (``shaders/point_splat.vert``, ``shaders/point_splat.frag``):

* the image rectangle is mapped orthographically onto clip space (it is already in normalised
  coordinates); each surfel's pixel box is the kernel's (half side ``rho = r / (z − r)`` around
  its centre's projection, clamped to the image), computed here in float64, and the fragment
  shader covers no pixel outside it, so that both fill exactly the same pixels;
* one GL point per surfel, centred on its box, ``gl_PointSize`` = the box's longer side + 2 pixels;
* the fragment shader computes the pixel's ray, the ray-plane ``t``, discards pixels outside the
  disk or seen closer than ``edge_on_cos`` to edge-on, and writes ``t`` mapped linearly onto
  ``[0, 1)`` as ``gl_FragDepth`` (depth test LESS; moderngl's depth buffer holds 24 bits), the id
  into an R32I attachment and ``t`` itself into an R32F one.  It works from the pixel's offset
  to the surfel's projected centre, so that float32 keeps ~1e-7 of the disk's radius, not of its
  depth (the shader's comment);
* **the quad pass**: a surfel whose sprite would exceed the GL's largest point size
  (``GL_POINT_SIZE_RANGE``: 255 pixels on Mesa llvmpipe), or whose box centre falls outside the
  tile (GL drops a point whose centre is clipped, however large its sprite), is drawn as an
  instanced quad over its box, after the sprites, by the same fragment shader;
* an image larger than the GL's maximum image size (:func:`~zbuf_occlude.render.context.max_image_size`)
  is drawn in tiles.

Where the two differ: the GPU computes in float32 and its depth buffer holds 24 bits over the
view's depth range, so where two surfels' depths at a pixel differ by less than about 1e-7 of
their depth, or a pixel centre lies within float32 rounding of a disk's rim, either may win.
Exact ties go to the surfel drawn first: the lower id within a pass (as the kernel), the sprite
before the quad.  A surfel whose sphere all but touches the camera's plane (centre projected
beyond 2^30 pixels) is drawn with its centre clipped there.
"""

from __future__ import annotations

import os
import threading
from typing import Iterator

import moderngl
import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.render.context import max_image_size, shared_context
from zbuf_occlude.render.shaders import load_shader

__all__ = ["PointSpriteRenderer", "shared_point_sprites"]

#: One surfel as the vertex shader reads it (64 bytes): centre and radius, unit normal, id, the
#: centre's projection in pixels of the image (whole part and fraction), its pixel box.
_SURFEL = np.dtype([
    ("centre_radius", "<f4", 4), ("normal", "<f4", 3), ("id", "<i4"),
    ("centre_pixel", "<i4", 2), ("centre_fraction", "<f4", 2), ("box", "<i4", 4),
])  # fmt: skip
_SURFEL_FORMAT = "4f 3f 1i 2i 2f 4i"
_SURFEL_ATTRIBUTES = ("in_centre_radius", "in_normal", "in_id", "in_centre_pixel", "in_centre_fraction", "in_box")
#: Pixels: the whole part of a centre's projection is clipped to this (int32 in the shader); only
#: a surfel whose sphere all but touches the camera's plane projects that far.
_MAX_CENTRE_PIXEL = 2**30
#: Pixels kept between a sprite's centre and the tile's border, where GL would clip the point.
_SPRITE_MARGIN_PX = 1.0
#: Pixels: the render target's sides grow in steps of this (it is kept across views).
_TARGET_STEP = 256
#: Share of the 24-bit depth range left above the farthest surfel: rounding of ``t`` in float32
#: cannot reach the cleared depth 1.0, where LESS would drop it.
_DEPTH_HEADROOM = 2.0**-10


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
                    fragment_shader=load_shader("point_splat.frag"),
                )
                for quads in (False, True)
            }
        self.max_point_size = float(self.ctx.info["GL_POINT_SIZE_RANGE"][1])
        self.max_tile = max_image_size(self.ctx)
        self._target: tuple[tuple[int, int], moderngl.Framebuffer, tuple[moderngl.Texture, ...]] | None = None
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
        computed in float32 (module docstring: where the two may differ).

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
            The float32 ``t`` of the nearest covering surfel, object units; ``inf`` where none.
        ids : (height, width) int32
            Index of that surfel, −1 where none.
        """
        if self._released:
            raise RuntimeError("this PointSpriteRenderer was released")
        cam = np.asarray(cam, dtype=np.float64).reshape(-1, 3)
        radius = np.asarray(radius, dtype=np.float64).reshape(-1)
        depth = np.full((height, width), np.inf)
        ids = np.full((height, width), -1, dtype=np.int32)
        boxes = _Boxes(cam, radius, pix, x0, y0, width, height)
        if not boxes.drawn.any():
            return depth, ids
        records = _records(cam, normal, radius, boxes)
        near, far = boxes.depth_range()
        uniforms = {
            "pix": float(pix), "edge_on_cos": float(edge_on_cos),
            "depth_near": near, "depth_scale": (1.0 - _DEPTH_HEADROOM) / (far - near),
        }  # fmt: skip
        with self.ctx:
            for i0, j0, w, h in _tiles(width, height, self.max_tile):
                sprites, quads = boxes.split(i0, j0, w, h, self.max_point_size)
                tile_ids, tile_t = self._draw_tile(records[sprites], records[quads], (i0, j0), (w, h), uniforms)
                ids[j0 : j0 + h, i0 : i0 + w] = tile_ids - 1
                depth[j0 : j0 + h, i0 : i0 + w] = np.where(tile_ids > 0, tile_t, np.inf)
        return depth, ids

    def _draw_tile(self, sprites, quads, offset, size, uniforms) -> tuple[NDArray[np.int32], NDArray[np.float32]]:
        """Draw the sprites, then the quads, into a ``size`` tile whose first pixel is ``offset``;
        read back the ids (+1, 0 none) and ``t``, rows of increasing ``j``."""
        fbo = self._target_of(size)
        viewport = (0, 0, *size)
        fbo.use()
        self.ctx.viewport = viewport
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0, viewport=viewport)  # zero bits: id 0 ("none") in the R32I target
        self.ctx.enable(moderngl.DEPTH_TEST | moderngl.PROGRAM_POINT_SIZE)
        self.ctx.disable(moderngl.BLEND)
        self.ctx.depth_func = "<"
        for quads, records in ((False, sprites), (True, quads)):
            if len(records) == 0:
                continue
            program = self._programs[quads]
            for name, value in {**uniforms, "tile_offset": offset, "tile_size": tuple(float(v) for v in size)}.items():
                if name in program:  # the compiler drops unused uniforms
                    program[name].value = value
            buffer = self.ctx.buffer(records.tobytes())
            fmt = _SURFEL_FORMAT + ("/i" if quads else "")
            vao = self.ctx.vertex_array(program, [(buffer, fmt, *_SURFEL_ATTRIBUTES)])
            try:
                if quads:
                    vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=len(records))
                else:
                    vao.render(moderngl.POINTS, vertices=len(records))
            finally:
                vao.release()
                buffer.release()
        self.ctx.disable(moderngl.PROGRAM_POINT_SIZE)
        width, height = size
        tile_ids = np.frombuffer(fbo.read(viewport=viewport, components=1, attachment=0, dtype="i4"), dtype=np.int32)
        tile_t = np.frombuffer(fbo.read(viewport=viewport, components=1, attachment=1, dtype="f4"), dtype=np.float32)
        return tile_ids.reshape(height, width), tile_t.reshape(height, width)

    def _target_of(self, size: tuple[int, int]) -> moderngl.Framebuffer:
        """A framebuffer (ids R32I, ``t`` R32F, depth) at least ``size``: kept and grown in steps of
        :data:`_TARGET_STEP` pixels, since each view's image has its own size."""
        have = self._target[0] if self._target is not None else (0, 0)
        if size[0] > have[0] or size[1] > have[1]:
            self._release_target()
            step = _TARGET_STEP
            grown = tuple(min(max(old, -(-need // step) * step), self.max_tile) for old, need in zip(have, size))
            textures = (
                self.ctx.texture(grown, 1, dtype="i4"),
                self.ctx.texture(grown, 1, dtype="f4"),
                self.ctx.depth_texture(grown),
            )
            self._target = (grown, self.ctx.framebuffer(list(textures[:2]), textures[2]), textures)
        return self._target[1]

    def _release_target(self) -> None:
        if self._target is not None:
            _, fbo, textures = self._target
            fbo.release()
            for texture in textures:
                texture.release()
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
    """Each surfel's pixel box, by the formulas of the kernel (float64, clamped to the image), and
    its sprite.  The kernel bounds a disk by the projection of the cube ``q ± r`` around it (extreme
    at its corners); the GPU covers the same pixels, so the two fill the same buffers."""

    def __init__(self, cam, radius, pix, x0, y0, width, height):
        z = cam[:, 2]
        ok = (radius > 0.0) & (z - radius > 0.0)
        safe_z = np.where(ok, z, 1.0)
        near = np.where(ok, z - radius, 1.0)
        far = np.where(ok, z + radius, 1.0)
        #: the centre's projection, pixels of the whole image (continuous: pixel i spans [i, i+1))
        self.centre_x = (cam[:, 0] / safe_z - x0) / pix
        self.centre_y = (cam[:, 1] / safe_z - y0) / pix
        lo_x, hi_x = cam[:, 0] - radius, cam[:, 0] + radius
        lo_y, hi_y = cam[:, 1] - radius, cam[:, 1] + radius
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
        self._near = z - radius
        self._far = z + radius

    def depth_range(self) -> tuple[float, float]:
        """``(near, far)``, object units: the depths any drawn surfel can cover."""
        near = float(self._near[self.drawn].min())
        far = float(self._far[self.drawn].max())
        return near, max(far, near * (1.0 + 1e-6))

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


def _records(cam, normal, radius, boxes: _Boxes) -> NDArray[np.void]:
    records = np.empty(len(cam), dtype=_SURFEL)
    records["centre_radius"][:, :3] = cam
    records["centre_radius"][:, 3] = radius
    records["normal"] = normal
    records["id"] = np.arange(len(cam), dtype=np.int32)
    centre = np.stack([boxes.centre_x, boxes.centre_y], axis=1)
    whole = np.clip(np.floor(centre), -_MAX_CENTRE_PIXEL, _MAX_CENTRE_PIXEL)
    records["centre_pixel"] = whole
    records["centre_fraction"] = centre - whole
    records["box"] = boxes.box
    return records


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

