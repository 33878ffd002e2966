"""moderngl renderer: one mesh uploaded once, rendered and tested from many poses.

Rasterisation writes one RG32F target per pose (linear depth, face index) with a 32-bit
float depth buffer.  Visibility runs in compute shaders over the uploaded points and reads
the target as a texture, so only one bit per point comes back to the CPU.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import moderngl
import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude.defaults import DEFAULT_GPU_TOLERANCE, DEFAULT_MAX_SLOPE
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.mesh.load import MAX_ABS_COORDINATE
from zbuf_occlude.render import bindings
from zbuf_occlude.render.compute import dispatch, read_through, set_uniforms
from zbuf_occlude.render.context import check_image_size, shared_context
from zbuf_occlude.render.shaders import load_shader

__all__ = ["DepthRender", "PointBuffer", "ModernGLRenderer", "MAX_FACES"]

log = logging.getLogger(__name__)

#: Face indices travel as float32 in the render target: exact below 2^24.
MAX_FACES = 2**24


@dataclass(frozen=True)
class DepthRender:
    """A rendered pose.

    Attributes
    ----------
    depth : (H, W) float32
        Linear depth along the optical axis, object units; 0 where nothing was drawn.
        Row 0 is the top of the image (OpenCV convention, as ``Camera.K``).
    face_index : (H, W) int64
        Row of ``mesh.faces`` seen at each pixel centre; −1 for background.
    camera : Camera
    """

    depth: NDArray[np.float32]
    face_index: NDArray[np.int64]
    camera: Camera

    @property
    def mask(self) -> NDArray[np.bool_]:
        """(H, W) bool: pixels covered by the mesh."""
        return self.face_index >= 0


def canonical_faces(triangles: NDArray[np.floating]) -> NDArray[np.int64]:
    """For each face, the lowest index of the faces with exactly the same three vertex
    positions (any order); ModelNet meshes duplicate many faces.

    Parameters
    ----------
    triangles : (F, 3, 3) float
        World frame; compared after rounding to float32, the precision the GPU sees.

    Returns
    -------
    canonical : (F,) int64
        ``canonical[f] <= f``, equal for faces of one group.
    """
    tri = np.ascontiguousarray(triangles, dtype=np.float32)
    vertex = tri.view(np.dtype((np.void, 12))).reshape(len(tri), 3)  # a vertex as 12 raw bytes
    key = np.ascontiguousarray(np.sort(vertex, axis=1)).view(np.dtype((np.void, 36))).ravel()
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    return first[inverse.ravel()].astype(np.int64)


class PointBuffer:
    """Points uploaded to the GPU once, for tests from many poses.

    Made by :meth:`ModernGLRenderer.upload_points`; release with :meth:`release`.
    """

    def __init__(
        self,
        ctx: moderngl.Context,
        points: NDArray[np.float64],
        face_index: NDArray[np.int64] | None,
        canonical: NDArray[np.int64],
    ):
        self.n_points = len(points)
        padded = np.zeros((max(self.n_points, 1), 4), dtype=np.float32)
        padded[: self.n_points, :3] = points
        faces = np.full(max(self.n_points, 1), -1, dtype=np.int32)
        if face_index is not None:
            faces[: self.n_points] = canonical[face_index]  # the id the image holds for that face
        self.has_face_index = face_index is not None
        self.points = ctx.buffer(padded.tobytes())
        self.faces = ctx.buffer(faces.tobytes())
        # visible bits, then uncertain bits (see shaders/common.glsl)
        self.visible_bits = ctx.buffer(reserve=2 * 4 * max(math.ceil(self.n_points / 32), 1))
        #: What the CPU reads: ``visible_bits`` copied on the GPU (:func:`~zbuf_occlude.render.compute.read_through`).
        self.bits_read = ctx.buffer(reserve=self.visible_bits.size)

    def release(self) -> None:
        for buf in (self.points, self.faces, self.visible_bits, self.bits_read):
            buf.release()


class ModernGLRenderer:
    """Headless OpenGL renderer of one mesh (moderngl, EGL or OSMesa).

    The mesh is uploaded once (vertex/index buffers for rasterisation, a triangle storage
    buffer for the exact tests); render targets are cached per resolution.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame (normally from :func:`zbuf_occlude.load_mesh`).
    context : moderngl.Context, optional
        Default: the process's shared context (:func:`zbuf_occlude.render.context.shared_context`).

    Raises
    ------
    InvalidInputError
        Empty mesh, more than 2^24 faces, NaN/inf vertices or coordinates beyond
        float32 (:data:`~zbuf_occlude.mesh.load.MAX_ABS_COORDINATE`); a camera larger than the GL's maximum
        image size (:func:`~zbuf_occlude.render.context.max_image_size`) when rendering.
    BackendUnavailable
        No OpenGL 4.3 context can be created.
    """

    def __init__(self, mesh: trimesh.Trimesh, *, context: moderngl.Context | None = None):
        faces = np.asarray(mesh.faces)
        if len(faces) == 0:
            raise InvalidInputError("cannot render a mesh with no faces")
        if len(faces) >= MAX_FACES:
            raise InvalidInputError(f"mesh has {len(faces)} faces; the renderer supports fewer than {MAX_FACES}")
        vertices = np.asarray(mesh.vertices)
        if not (np.isfinite(vertices).all() and np.abs(vertices).max(initial=0.0) <= MAX_ABS_COORDINATE):
            # float32 on the GPU: NaN, inf or |x| > 3.4e38 would be drawn as garbage, silently.
            raise InvalidInputError(f"cannot render a mesh with NaN, inf or beyond-float32 (> {MAX_ABS_COORDINATE:.3g}) vertex coordinates")
        self.n_faces = len(faces)
        self.ctx = context or shared_context()
        triangles = np.asarray(mesh.triangles)
        #: (F,) int64: each face's group of identical faces, named by its lowest index.
        self.canonical = canonical_faces(triangles)
        drawn = np.flatnonzero(self.canonical == np.arange(self.n_faces))
        with self.ctx:
            self._vbo = self.ctx.buffer(np.asarray(mesh.vertices, dtype=np.float32).tobytes())
            # Draw one face per group: duplicates add raster work and, since either copy may
            # win the depth test, would hide the point's own face from the candidate window.
            self._ibo = self.ctx.buffer(faces[drawn].astype(np.uint32).tobytes())
            self._draw_faces = self.ctx.buffer(drawn.astype(np.int32).tobytes())
            self._triangles = self.ctx.buffer(triangles.astype(np.float32).tobytes())
            self._program = self.ctx.program(vertex_shader=load_shader("mesh.vert"), fragment_shader=load_shader("mesh.frag"))
            self._vao = self.ctx.vertex_array(self._program, [(self._vbo, "3f", "in_position")], index_buffer=self._ibo)
            self._compute: dict[tuple[str, int], moderngl.ComputeShader] = {}
        self._targets: dict[tuple[int, int], tuple[moderngl.Framebuffer, moderngl.Texture, moderngl.Texture]] = {}
        self._released = False

    # -- rasterisation -------------------------------------------------------------
    def _target(self, size: tuple[int, int]):
        if size not in self._targets:
            # moderngl would fail with "framebuffer is not complete" beyond the GL's limits.
            check_image_size(size, ctx=self.ctx)
            color = self.ctx.texture(size, 2, dtype="f4")
            color.filter = (moderngl.NEAREST, moderngl.NEAREST)
            depth = self.ctx.depth_texture(size)
            self._targets[size] = (self.ctx.framebuffer([color], depth), color, depth)
        return self._targets[size]

    def _draw(self, camera: Camera) -> moderngl.Texture:
        fbo, color, _ = self._target(camera.resolution)
        fbo.use()
        fbo.clear(0.0, -1.0, 0.0, 0.0, depth=1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)  # meshes are triangle soup: two-sided
        self._program["view_matrix"].write(camera.view_matrix.T.astype(np.float32).tobytes())
        self._program["projection_matrix"].write(camera.projection_matrix.T.astype(np.float32).tobytes())
        self._draw_faces.bind_to_storage_buffer(bindings.DRAW_FACES)
        self._vao.render(moderngl.TRIANGLES)
        return color

    def _shader(self, rule: str, neighborhood: int) -> moderngl.ComputeShader:
        key = (rule, neighborhood if rule in ("candidates", "scan") else 0)
        if key not in self._compute:
            if rule == "candidates":
                source = load_shader("visibility_candidates.comp", (("NEIGHBORHOOD", neighborhood),))
            elif rule == "scan":
                source = load_shader("scan_candidates.comp", (("NEIGHBORHOOD", neighborhood),))
            else:
                source = load_shader("visibility_tolerance.comp")
            self._compute[key] = self.ctx.compute_shader(source)
        return self._compute[key]

    def render(self, camera: Camera) -> DepthRender:
        """Rasterise one pose and read back linear depth and face index.

        Returns
        -------
        DepthRender
            ``depth (H, W) float32`` and ``face_index (H, W) int64``, row 0 at the top.
        """
        with self.ctx:
            color = self._draw(camera)
            raw = np.frombuffer(color.read(), dtype=np.float32).reshape(camera.height, camera.width, 2)
        raw = raw[::-1]  # OpenGL rows start at the bottom
        return DepthRender(depth=raw[..., 0].copy(), face_index=raw[..., 1].astype(np.int64), camera=camera)

    # -- visibility ------------------------------------------------------------------
    def upload_points(self, points: NDArray[np.floating], face_index: NDArray[np.integer] | None = None) -> PointBuffer:
        """Upload ``points (N, 3)`` (world frame) and their optional ``face_index (N,)``."""
        with self.ctx:
            return PointBuffer(self.ctx, np.asarray(points, dtype=np.float64), face_index, self.canonical)

    def visible(
        self,
        camera: Camera,
        points: PointBuffer,
        *,
        rule: str = "candidates",
        neighborhood: int = 1,
        tolerance: float = DEFAULT_GPU_TOLERANCE,
        edge_epsilon: float = 1e-5,
        depth_tolerance: float = 0.0,
        slope_scale: float = 0.0,
        max_slope: float = DEFAULT_MAX_SLOPE,
    ) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """Render ``camera`` and decide each uploaded point's visibility on the GPU.

        Parameters
        ----------
        camera : Camera
        points : PointBuffer
            From :meth:`upload_points`.
        rule : {"candidates", "tolerance"}
            ``"candidates"``: exact segment tests against the faces seen in the
            ``(2·neighborhood + 1)²`` pixels around the point's projection (``tolerance``
            and ``edge_epsilon`` apply).  ``"tolerance"``: the point's linear depth must
            not exceed the nearest pixel's by more than ``depth_tolerance + slope_scale ·
            pixel_footprint · min(tan θ, max_slope)`` object units.
        neighborhood : int
            Pixel radius r of the candidate window, 0 ≤ r ≤ 4.
        tolerance : float
            Object units: an intersection closer than this to the point is its own surface.
            Default 1e-5: float32 rounding of points and vertices is ~3e-8 per coordinate,
            magnified up to ~100× at grazing incidence.
        edge_epsilon : float
            Barycentric widening of each triangle so segments cannot slip through shared
            edges (float32).
        depth_tolerance, slope_scale, max_slope : float
            The ``"tolerance"`` rule's constants (object units, pixels, dimensionless).

        Returns
        -------
        visible : (N,) bool
        uncertain : (N,) bool
            ``"candidates"`` rule only: points called visible although the centre pixel
            does not show their own face (sub-pixel faces, rays through cracks).  The image holds
            no evidence for them; :mod:`zbuf_occlude.visibility.zbuffer` decides them exactly.
            Always False without a face index.
        """
        if not 0 <= neighborhood <= 4:
            raise InvalidInputError(f"neighborhood must be in [0, 4] pixels, got {neighborhood}")
        if rule not in ("candidates", "tolerance"):
            raise InvalidInputError(f"unknown z-buffer rule {rule!r}; use 'candidates' or 'tolerance'")
        n = points.n_points
        if n == 0:
            return np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)
        uniforms = {
            "view_projection": (camera.projection_matrix @ camera.view_matrix).T.astype(np.float32).tobytes(),
            "eye": tuple(float(v) for v in camera.eye),
            "depth_row": tuple(float(v) for v in -camera.view_matrix[2]),
            "resolution": camera.resolution,
            "n_points": n,
            "tolerance": float(tolerance),
            "edge_epsilon": float(edge_epsilon),
            "depth_tolerance": float(depth_tolerance),
            "slope_scale": float(slope_scale),
            "max_slope": float(max_slope),
            "focal_px": float(camera.focal_px),
        }
        with self.ctx:
            shader = self._shader(rule, int(neighborhood))
            color = self._draw(camera)
            self.ctx.memory_barrier()
            set_uniforms(shader, uniforms)
            color.use(location=bindings.DEPTH_AND_FACE_UNIT)
            points.points.bind_to_storage_buffer(bindings.VISIBILITY_POINTS)
            points.faces.bind_to_storage_buffer(bindings.VISIBILITY_POINT_FACES)
            self._triangles.bind_to_storage_buffer(bindings.VISIBILITY_TRIANGLES)
            points.visible_bits.bind_to_storage_buffer(bindings.VISIBILITY_BITS)
            points.visible_bits.clear()
            dispatch(shader, n, "point_offset")
            self.ctx.memory_barrier()
            words = np.frombuffer(
                read_through(self.ctx, points.visible_bits, points.bits_read, points.bits_read.size), dtype=np.uint32
            ).reshape(2, -1)
        bits = np.unpackbits(words.view(np.uint8), axis=1, count=n, bitorder="little").view(bool)
        return bits[0], bits[1]

    def first_hits(
        self,
        camera: Camera,
        origin: NDArray[np.floating],
        directions: NDArray[np.floating],
        *,
        neighborhood: int,
        znear: float,
        edge_epsilon: float,
    ) -> NDArray[np.int64]:
        """The face each ray from ``origin`` hits first among the faces rasterised around it.

        ``camera`` (eye at ``origin``) is rasterised into face ids; each ray tests the faces
        of the ``(2 neighborhood + 1)²`` pixels around its projection in float32 with
        barycentrics widened by ``edge_epsilon`` (``shaders/scan_candidates.comp``).

        Parameters
        ----------
        camera : Camera
            Eye at ``origin``; the rays lie in its view.
        origin : (3,) float
            World frame.
        directions : (R, 3) float
            Unit directions, world frame.
        neighborhood : int
            Window radius, pixels.
        znear : float
            Nothing nearer than this is hit, object units.
        edge_epsilon : float
            Barycentric widening of the float32 test.

        Returns
        -------
        face : (R,) int64
            Face index (the lowest of its group of identical faces); −1 no face seen in the
            window, −2 faces seen, none hit.
        """
        n = len(directions)
        uniforms = {
            "view_projection": (camera.projection_matrix @ camera.view_matrix).T.astype(np.float32).tobytes(),
            "origin": tuple(float(v) for v in origin), "resolution": camera.resolution, "n_rays": n,
            "znear": float(znear), "edge_epsilon": float(edge_epsilon),
        }  # fmt: skip
        rays = np.zeros((n, 4), dtype=np.float32)
        rays[:, :3] = directions
        with self.ctx:
            shader = self._shader("scan", int(neighborhood))
            color = self._draw(camera)  # RG32F (linear depth, face id) of this view
            self.ctx.memory_barrier()
            ray_buf = self.ctx.buffer(rays.tobytes())
            out_buf = self.ctx.buffer(reserve=4 * max(n, 1))
            set_uniforms(shader, uniforms)
            color.use(location=bindings.DEPTH_AND_FACE_UNIT)
            ray_buf.bind_to_storage_buffer(bindings.SCAN_RAYS)
            out_buf.bind_to_storage_buffer(bindings.SCAN_HITS)
            self._triangles.bind_to_storage_buffer(bindings.SCAN_TRIANGLES)
            dispatch(shader, n, "ray_offset")
            self.ctx.memory_barrier()
            face = np.frombuffer(out_buf.read(4 * n), dtype=np.int32).astype(np.int64)
            ray_buf.release()
            out_buf.release()
        return face

    # -- lifetime ------------------------------------------------------------------------
    def release(self) -> None:
        """Free every GL object of this renderer (the context stays)."""
        if self._released:
            return
        self._released = True
        with self.ctx:
            for fbo, color, depth in self._targets.values():
                fbo.release()
                color.release()
                depth.release()
            for obj in (self._vao, self._program, self._vbo, self._ibo, self._draw_faces, self._triangles, *self._compute.values()):
                obj.release()

    def __enter__(self) -> ModernGLRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.release()
