"""First hits of many rays from one origin by z-buffer (GPU): the scene rasterised into face-id images.

The scene is rasterised from the ray origin with moderngl (one perspective view for rays inside a
cone, else the six faces of a cube map) into face-id images; each ray's candidates are the faces
seen in the ``(2r+1)²`` pixels around its projection, tested exactly on the GPU
(``render/shaders/scan_candidates.comp``), as the z-buffer visibility method decides points
(:mod:`zbuf_occlude.visibility.zbuffer`); the distance on the chosen face is recomputed in float64
(:func:`~zbuf_occlude.sensors.raycast.embree.ray_triangle_f64`), so that it differs from :func:`~zbuf_occlude.sensors.raycast.embree.cast_embree` only in
*which* face it picks.  Rays whose window shows faces but none of them is hit (sub-pixel faces,
cracks) are decided by Embree.
"""

from __future__ import annotations

from dataclasses import dataclass

import logging
import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.cache import MeshCache
from zbuf_occlude.sensors.raycast.embree import cast_embree, ray_triangle_f64

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = ["GPU_EDGE_EPSILON", "RECHECK_EPSILON", "cast_zbuffer", "ZBufferView"]

log = logging.getLogger(__name__)


_CUBE = [  # (forward, up) of the six cube-map views
    ((1, 0, 0), (0, 0, 1)), ((-1, 0, 0), (0, 0, 1)), ((0, 1, 0), (0, 0, 1)),
    ((0, -1, 0), (0, 0, 1)), ((0, 0, 1), (1, 0, 0)), ((0, 0, -1), (1, 0, 0)),
]  # fmt: skip


def _views(origin, directions, resolution, znear, zfar):
    """Cameras covering every ray, and each ray's view index."""
    from zbuf_occlude.geometry.cameras import Camera

    mean = directions.mean(axis=0)
    norm = np.linalg.norm(mean)
    if norm > 0.5:
        axis = mean / norm
        cos_max = float((directions @ axis).min())
        if cos_max > math.cos(math.radians(60.0)):
            # One view: a square frustum around the mean direction that holds every ray.
            up = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
            cam = Camera(origin, origin + axis, up, 90.0, 2, 2, znear, zfar)
            local = directions @ cam._basis.T  # x right, y up, -z forward
            half = np.degrees(np.arctan(np.abs(local[:, :2] / -local[:, 2:3]).max()))
            cam = Camera(origin, origin + axis, up, min(2.0 * half * 1.02 + 0.1, 150.0), resolution, resolution, znear, zfar)
            return [cam], np.zeros(len(directions), np.int64)
    cams = [Camera(origin, origin + np.array(f, float), np.array(u, float), 90.0, resolution, resolution, znear, zfar) for f, u in _CUBE]
    axis = np.argmax(np.abs(directions), axis=1)
    sign = np.take_along_axis(directions, axis[:, None], axis=1)[:, 0] < 0
    return cams, (2 * axis + sign).astype(np.int64)


#: Barycentric widening of the float32 candidate test on the GPU (a ray through an edge shared by
#: two faces must hit one); the chosen face is re-checked in float64 with :data:`RECHECK_EPSILON`.
GPU_EDGE_EPSILON = 1e-5
#: A GPU hit whose float64 barycentrics fall outside the face by more than this goes to Embree.
RECHECK_EPSILON = 1e-6


def _build_renderer(mesh: trimesh.Trimesh):
    from zbuf_occlude.render.moderngl_backend import ModernGLRenderer

    return ModernGLRenderer(mesh)


def _release_renderer(renderer) -> None:
    renderer.release()


#: GL renderers of the scenes in use (mesh uploaded once for many scans).
_renderers = MeshCache(_build_renderer, 2, release=_release_renderer)


@dataclass(frozen=True)
class ZBufferView:
    """How the z-buffer backend renders a scan (:func:`cast_zbuffer`): ``resolution`` pixels a side of each view, and the
    ``neighborhood`` radius of the window of candidate faces around each ray's pixel (checked where they are used)."""

    resolution: int = 2048
    neighborhood: int = 1


def cast_zbuffer(
    mesh: trimesh.Trimesh,
    origin: NDArray[np.float64],
    directions: NDArray[np.float64],
    *,
    resolution: int = 2048,
    neighborhood: int = 1,
    znear: float = 0.05,
    zfar: float = 500.0,
) -> tuple[NDArray[np.int64], NDArray[np.float64], int]:
    """First hit of each ray from one origin, from rasterised face-id images (module docstring).

    Only the first: each pixel keeps the nearest face, so nothing behind it can be read back.
    The hits behind a surface that transmits come from :func:`~zbuf_occlude.sensors.raycast.embree.cast_embree_beyond` (Embree), and
    :func:`~zbuf_occlude.sensors.scan.scan` refuses a transmittance above 0 with this backend.

    The views are rasterised and each ray's candidates tested on the GPU
    (``render/shaders/scan_candidates.comp``, float32); the distance on the chosen face is then
    recomputed in float64, and a ray goes to Embree when its window showed faces but none was
    hit, or when the float64 test puts the chosen face's hit outside it by more than
    :data:`RECHECK_EPSILON`.

    Parameters
    ----------
    mesh, origin, directions
        As :func:`~zbuf_occlude.sensors.raycast.embree.cast_embree`.
    resolution : int
        Pixels per side of each view (cube-map face: 90° field of view).
    neighborhood : int
        Candidate window radius r, pixels (window ``(2r+1)²``), 0 ≤ r ≤ 4.
    znear, zfar : float
        Clip planes, metres; nothing nearer than ``znear`` is hit.

    Returns
    -------
    face, t
        As :func:`~zbuf_occlude.sensors.raycast.embree.cast_embree`; ``face`` is the lowest index of a group of identical faces.
    n_fallback : int
        Rays decided by Embree.

    Raises
    ------
    BackendUnavailable
        No OpenGL 4.3 context.
    InvalidInputError
        ``neighborhood`` outside [0, 4].
    """
    if not 0 <= int(neighborhood) <= 4:
        raise InvalidInputError(f"neighborhood must be in [0, 4] pixels, got {neighborhood}")
    origin = np.asarray(origin, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    n = len(directions)
    face = np.full(n, -1, np.int64)
    t_hit = np.full(n, np.inf)
    if n == 0:
        return face, t_hit, 0
    renderer = _renderers(mesh)
    cams, view = _views(origin, directions, int(resolution), float(znear), float(zfar))
    for k, cam in enumerate(cams):
        rays = np.flatnonzero(view == k)
        if len(rays):
            face[rays] = renderer.first_hits(
                cam, origin, directions[rays], neighborhood=int(neighborhood), znear=float(znear), edge_epsilon=GPU_EDGE_EPSILON
            )
    fallback = face == -2
    got = np.flatnonzero(face >= 0)
    tri = np.asarray(mesh.triangles, dtype=np.float64)[face[got]]
    t, inside = ray_triangle_f64(origin, directions[got], tri, edge_epsilon=RECHECK_EPSILON)
    t_hit[got] = t
    fallback[got[~inside]] = True
    n_fallback = int(fallback.sum())
    if n_fallback:
        f, t = cast_embree(mesh, origin, directions[fallback])
        face[fallback], t_hit[fallback] = f, t
        log.debug("zbuffer scan: %d of %d rays decided by Embree", n_fallback, n)
    face[face < 0] = -1
    return face, t_hit, n_fallback
