"""Image-space hidden surface removal: the z-buffer methods.

``zbuffer`` (default)
    Rasterise depth and face index; for each point, the faces kept in a small pixel window
    around its projection are the only ones that can hide it, and each gets an exact
    segment–triangle test (compute shader).  Points whose own face is not the one the centre
    pixel shows (sub-pixel faces, rays through cracks of triangle soup) carry no evidence in the image
    and are decided exactly with Embree on the CPU (``resolve="embree"``, default), or kept
    visible (``resolve="none"``, GPU only).
``zbuffer-tolerance``
    The classic depth test: visible iff the point's linear depth is within a slope-scaled
    tolerance (object units) of the depth at its pixel, as in shadow mapping
    (Williams 1978; slope-scaled bias as in OpenGL's ``glPolygonOffset``).

Both keep the mesh on the GPU across calls: :func:`renderer_for` caches one renderer per
mesh (a few meshes, least recently used), and :class:`ResidentPoints` also keeps the points uploaded.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude.defaults import (  # noqa: F401 - DEFAULT_RESOLUTION etc. are re-exported from here
    DEFAULT_DEPTH_TOLERANCE,
    DEFAULT_GPU_TOLERANCE,
    DEFAULT_MAX_SLOPE,
    DEFAULT_RESOLUTION,
    DEFAULT_SLOPE_SCALE,
)
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.render.moderngl_backend import PointBuffer
from zbuf_occlude.render.renderer_cache import RENDERER_CACHE_SIZE, renderer_for  # noqa: F401 - re-exported
from zbuf_occlude.visibility.definition import TOLERANCE, hide_edge_on
from zbuf_occlude.visibility.registry import SessionBase, check_face_index, check_points, register
from zbuf_occlude.visibility.segment_triangle import mesh_planes

__all__ = ["ResidentPoints", "zbuffer_visible", "zbuffer_tolerance_visible"]


def _at_resolution(camera: Camera, resolution: int | tuple[int, int] | None) -> Camera:
    if resolution is None:
        return camera
    width, height = (resolution, resolution) if np.isscalar(resolution) else resolution
    if (width, height) == camera.resolution:
        return camera
    return dataclasses.replace(camera, width=int(width), height=int(height))


def _resolve_uncertain(
    mesh: trimesh.Trimesh,
    points: NDArray[np.float64],
    face_index: NDArray[np.int64] | None,
    camera: Camera,
    visible: NDArray[np.bool_],
    uncertain: NDArray[np.bool_],
    resolve: str,
    tolerance: float,
) -> NDArray[np.bool_]:
    if resolve not in ("embree", "none"):
        raise InvalidInputError(f"resolve must be 'embree' or 'none', got {resolve!r}")
    if resolve == "none" or not uncertain.any():
        return visible
    from zbuf_occlude.visibility.oracle_embree import occluded_embree  # deferred: only needed when points are uncertain

    idx = np.flatnonzero(uncertain)
    fi = None if face_index is None else face_index[idx]
    out = visible.copy()
    out[idx] = ~occluded_embree(mesh, points[idx], camera.eye, face_index=fi, tolerance=tolerance)
    return out


class ResidentPoints(SessionBase):
    """One mesh and one point set on the GPU, tested from many cameras.

    Holds the (cached, shared) renderer of the mesh and the points uploaded once; use it
    for many poses of one object (the render farm does).  ``visible_mask`` with the z-buffer
    methods builds a throw-away ResidentPoints per call (the mesh stays cached, the points are
    re-uploaded).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame.
    points : (N, 3) float
        Points on the surface, world frame.
    face_index : (N,) int, optional
        Face of each point (recommended: exact own-face exclusion and ``resolve``).

    Raises
    ------
    InvalidInputError
        Bad points or face index.
    BackendUnavailable
        No OpenGL 4.3 context.
    """

    def __init__(
        self,
        mesh: trimesh.Trimesh,
        points: NDArray[np.floating],
        face_index: NDArray[np.integer] | None = None,
    ):
        self.mesh = mesh
        self.points = check_points(points)
        self.face_index = check_face_index(face_index, len(self.points), len(mesh.faces))
        self.renderer = renderer_for(mesh)
        self._buffer: PointBuffer | None = self.renderer.upload_points(self.points, self.face_index)

    def visible(
        self,
        camera: Camera,
        *,
        resolution: int | tuple[int, int] | None = None,
        neighborhood: int = 1,
        tolerance: float = DEFAULT_GPU_TOLERANCE,
        resolve: str = "embree",
    ) -> NDArray[np.bool_]:
        """``zbuffer`` visibility of the points from ``camera``; see the module docstring.

        Parameters
        ----------
        camera : Camera
        resolution : int or (width, height), optional
            Overrides the camera's image size.
        neighborhood : int
            Candidate window radius r in pixels: (2r + 1)² pixels, 0 ≤ r ≤ 4.
        tolerance : float
            Object units: intersections closer than this to the point are its own surface
            (float32 on the GPU; 1e-5 of the object's size).
        resolve : {"embree", "none"}
            How points without evidence in the image are decided.

        Returns
        -------
        visible : (N,) bool
        """
        camera = _at_resolution(camera, resolution)
        visible, uncertain = self.renderer.visible(camera, self._buffer, rule="candidates", neighborhood=neighborhood, tolerance=tolerance)
        # The CPU decides with the one tolerance of every method (visibility.definition);
        # ``tolerance`` is the GPU's float32 band.
        visible = _resolve_uncertain(self.mesh, self.points, self.face_index, camera, visible, uncertain, resolve, TOLERANCE)
        # Rule (b) of the definition: points on a face seen edge-on are not visible.
        return hide_edge_on(visible, mesh_planes(self.mesh), self.points, camera.eye, self.face_index)

    def visible_tolerance(
        self,
        camera: Camera,
        *,
        resolution: int | tuple[int, int] | None = None,
        depth_tolerance: float = DEFAULT_DEPTH_TOLERANCE,
        slope_scale: float = DEFAULT_SLOPE_SCALE,
        max_slope: float = DEFAULT_MAX_SLOPE,
    ) -> NDArray[np.bool_]:
        """``zbuffer-tolerance`` visibility: a point is visible iff its linear depth is at
        most the depth at its pixel plus ``depth_tolerance + slope_scale · pixel_footprint ·
        min(tan θ, max_slope)`` (object units; θ from the point's face normal, so the slope
        term needs ``face_index``).

        Returns
        -------
        visible : (N,) bool
        """
        camera = _at_resolution(camera, resolution)
        visible, _ = self.renderer.visible(
            camera,
            self._buffer,
            rule="tolerance",
            depth_tolerance=depth_tolerance,
            slope_scale=slope_scale,
            max_slope=max_slope,
        )
        return visible

    def release(self) -> None:
        """Free the uploaded points (the mesh's renderer stays cached)."""
        if self._buffer is not None:
            with self.renderer.ctx:
                self._buffer.release()
            self._buffer = None


@register("zbuffer", takes_resolution=True, gpu=True, session=ResidentPoints)
def zbuffer_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.float64],
    camera: Camera,
    *,
    face_index: NDArray[np.int64] | None = None,
    resolution: int | tuple[int, int] | None = DEFAULT_RESOLUTION,
    neighborhood: int = 1,
    tolerance: float = DEFAULT_GPU_TOLERANCE,
    resolve: str = "embree",
) -> NDArray[np.bool_]:
    """Default image-space HSR: id-buffer candidates + exact tests; see :meth:`ResidentPoints.visible`."""
    with ResidentPoints(mesh, points, face_index) as scene:
        return scene.visible(camera, resolution=resolution, neighborhood=neighborhood, tolerance=tolerance, resolve=resolve)


@register("zbuffer-tolerance", takes_resolution=True, gpu=True)
def zbuffer_tolerance_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.float64],
    camera: Camera,
    *,
    face_index: NDArray[np.int64] | None = None,
    resolution: int | tuple[int, int] | None = DEFAULT_RESOLUTION,
    depth_tolerance: float = DEFAULT_DEPTH_TOLERANCE,
    slope_scale: float = DEFAULT_SLOPE_SCALE,
    max_slope: float = DEFAULT_MAX_SLOPE,
) -> NDArray[np.bool_]:
    """Depth-test image-space HSR with a slope-scaled tolerance; see :meth:`ResidentPoints.visible_tolerance`."""
    with ResidentPoints(mesh, points, face_index) as scene:
        return scene.visible_tolerance(
            camera, resolution=resolution, depth_tolerance=depth_tolerance, slope_scale=slope_scale, max_slope=max_slope
        )
