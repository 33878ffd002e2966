"""``zbuffer-exact``: the visibility definition decided on the GPU, with a complete candidate set.

Every face is binned (compute shader) into the screen tiles its projected bounding box
overlaps; each point tests every face of its tile, so no occluder can be missed however
thin it is (a face narrower than a pixel, a sliver, a silhouette fold).  Each pair is
decided in float32 with an error bound and, inside the bound, in float64 with the oracle's
formulas; the own face is ``face_index`` when given and is recovered on the GPU otherwise
(rule (b) of :mod:`~zbuf_occlude.visibility.definition`).  Only float64 near-ties (within
1e-12 relative of a boundary) and points on the frustum's border are decided on the CPU,
by the Embree oracle; :attr:`ExactScene.last_cpu_fraction` says how many there were.
See :mod:`zbuf_occlude.render.exact_backend` for the passes.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.mesh.cache import MeshCache
from zbuf_occlude.render.context import shared_context
from zbuf_occlude.render.exact_backend import DEFAULT_TILE, ExactMesh, ExactPoints
from zbuf_occlude.visibility.definition import EDGE_ON_SIN, TOLERANCE
from zbuf_occlude.visibility.oracle import oracle_visible
from zbuf_occlude.visibility.registry import SessionBase, check_face_index, check_points, register
from zbuf_occlude.visibility.segment_triangle import mesh_planes

__all__ = ["ExactScene", "exact_mesh_for", "zbuffer_exact_visible", "DEFAULT_RESOLUTION"]

log = logging.getLogger(__name__)

#: Default image size for the tile grid, pixels (tiles of ``DEFAULT_TILE`` pixels).
DEFAULT_RESOLUTION = 1024


def _build(mesh: trimesh.Trimesh) -> ExactMesh:
    pl = mesh_planes(mesh)
    planes = np.concatenate([pl.normal, pl.offset[:, None], pl.edge_normals.reshape(-1, 9), pl.edge_offsets], axis=1)
    return ExactMesh(shared_context(), np.asarray(mesh.triangles), planes)


_meshes: MeshCache[ExactMesh] = MeshCache(_build, 4, release=ExactMesh.release)


def exact_mesh_for(mesh: trimesh.Trimesh) -> ExactMesh:
    """The cached :class:`~zbuf_occlude.render.exact_backend.ExactMesh` of ``mesh``."""
    return _meshes(mesh)


def _at_resolution(camera: Camera, resolution) -> Camera:
    if resolution is None:
        return camera
    width, height = (resolution, resolution) if np.isscalar(resolution) else resolution
    if (int(width), int(height)) == camera.resolution:
        return camera
    return dataclasses.replace(camera, width=int(width), height=int(height))


class ExactScene(SessionBase):
    """One mesh and one point set on the GPU for ``zbuffer-exact``, tested from many cameras.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame.
    points : (N, 3) float
        World frame.
    face_index : (N,) int, optional
        Own face of each point; recovered on the GPU when absent (same result).

    Raises
    ------
    InvalidInputError
        Bad points or face index.
    BackendUnavailable
        No OpenGL 4.3 context.
    """

    def __init__(self, mesh: trimesh.Trimesh, points: NDArray[np.floating], face_index: NDArray[np.integer] | None = None):
        self.mesh = mesh
        self.points = check_points(points)
        self.face_index = check_face_index(face_index, len(self.points), len(mesh.faces))
        self.gpu = exact_mesh_for(mesh)
        self._buffer: ExactPoints | None = self.gpu.upload_points(self.points, self.face_index)
        #: Fraction of the points the last call decided on the CPU.
        self.last_cpu_fraction = 0.0

    def visible(
        self,
        camera: Camera,
        *,
        resolution: int | tuple[int, int] | None = None,
        tile: int = DEFAULT_TILE,
        tolerance: float = TOLERANCE,
    ) -> NDArray[np.bool_]:
        """Visibility of the points from ``camera`` (:mod:`~zbuf_occlude.visibility.definition`).

        Parameters
        ----------
        camera : Camera
        resolution : int or (width, height), optional
            Overrides the camera's image size (the tile grid; the result does not depend on it).
        tile : int
            Tile side, pixels.
        tolerance : float
            Object units (default: the one tolerance of every method, 1e-6).

        Returns
        -------
        visible : (N,) bool
        """
        camera = _at_resolution(camera, resolution)
        visible, cpu = self.gpu.visible(camera, self._buffer, tolerance=tolerance, edge_sin=EDGE_ON_SIN, tile=tile)
        idx = np.flatnonzero(cpu)
        self.last_cpu_fraction = len(idx) / max(len(self.points), 1)
        if len(idx):
            fi = None if self.face_index is None else self.face_index[idx]
            visible[idx] = oracle_visible(self.mesh, self.points[idx], camera, face_index=fi, tolerance=tolerance)
        return visible

    def release(self) -> None:
        """Free the uploaded points (the mesh stays cached)."""
        if self._buffer is not None:
            with self.gpu.ctx:
                self._buffer.release()
            self._buffer = None


@register("zbuffer-exact", takes_resolution=True, gpu=True, exact=True, session=ExactScene)
def zbuffer_exact_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.float64],
    camera: Camera,
    *,
    face_index: NDArray[np.int64] | None = None,
    resolution: int | tuple[int, int] | None = DEFAULT_RESOLUTION,
    tile: int = DEFAULT_TILE,
    tolerance: float = TOLERANCE,
) -> NDArray[np.bool_]:
    """Exact GPU HSR with a complete candidate set; see :class:`ExactScene`."""
    with ExactScene(mesh, points, face_index) as scene:
        return scene.visible(camera, resolution=resolution, tile=tile, tolerance=tolerance)
