"""First hits of many rays from one origin on a triangle mesh: Embree (reference) and z-buffer (GPU).

Both return the hit face and the float64 ray parameter, decided exactly in float64 on the hit
face (Möller–Trumbore), so that the backends differ only in *which* face they pick.

* :func:`cast_embree`: Embree (embreex, through trimesh) finds the first face in float32;
  the distance is then recomputed in float64 on that face.
* :func:`cast_zbuffer`: the scene is rasterised from the ray origin with moderngl (one
  perspective view for rays inside a cone, else the six faces of a cube map) into face-id
  images; each ray's candidates are the faces seen in the ``(2r+1)²`` pixels around its
  projection, tested exactly on the GPU (``render/shaders/scan_candidates.comp``), as the z-buffer
  visibility method decides points (:mod:`zbuf_occlude.visibility.zbuffer`); the distance on
  the chosen face is recomputed in float64.  Rays whose window shows faces but none of them
  is hit (sub-pixel faces, cracks) are decided by Embree.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.mesh.cache import MeshCache

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = ["ray_triangle_f64", "cast_embree", "cast_zbuffer", "face_normals", "BACKENDS"]

log = logging.getLogger(__name__)

#: Ray-casting backends of :func:`zbuf_occlude.sensors.scan`.
BACKENDS = ("embree", "zbuffer")

#: Barycentric widening of the exact test: float64 rounding is ~1e-16 relative; a ray through a
#: shared edge must hit one of the two faces.
EDGE_EPSILON = 1e-10


def face_normals(mesh: trimesh.Trimesh, face: NDArray[np.int64]) -> NDArray[np.float64]:
    """``face.shape + (3,)`` float64 unit normals of faces ``face`` (int, any shape) of ``mesh``.

    Right-hand winding, ``(b − a) × (c − a)`` normalised; a degenerate face gives the zero vector.
    The one normal of every scanner's hit faces (spinning, airborne, single and multi return).
    """
    tri = np.asarray(mesh.triangles, dtype=np.float64)[face]
    normal = np.cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :])
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-300)
    return normal


def ray_triangle_f64(origin: NDArray[np.float64], directions: NDArray[np.float64], triangles: NDArray[np.float64], *, edge_epsilon: float = EDGE_EPSILON):
    """Möller–Trumbore ray–triangle test in float64, vectorised.

    Parameters
    ----------
    origin : (3,) float64
    directions : (..., 3) float64
        Ray directions (need not be unit; the parameter is in units of their length).
    triangles : (..., 3, 3) float64
        Broadcast against ``directions``.

    Returns
    -------
    t : (...) float64
        Ray parameter of the supporting plane's intersection (inf where parallel).
    inside : (...) bool
        The hit lies in the triangle (barycentrics widened by ``edge_epsilon``) and ``t > 0``.

    Source: T. Möller, B. Trumbore, "Fast, minimum storage ray-triangle intersection", JGT 1997.
    """
    a = triangles[..., 0, :] - origin
    e1 = triangles[..., 1, :] - triangles[..., 0, :]
    e2 = triangles[..., 2, :] - triangles[..., 0, :]
    p = np.cross(directions, e2)
    det = np.einsum("...i,...i->...", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = -a
        u = np.einsum("...i,...i->...", s, p) * inv
        q = np.cross(s, e1)
        v = np.einsum("...i,...i->...", directions, q) * inv
        t = np.einsum("...i,...i->...", e2, q) * inv
        ok = np.isfinite(t) & (det != 0.0)
        inside = ok & (u >= -edge_epsilon) & (v >= -edge_epsilon) & (u + v <= 1.0 + edge_epsilon) & (t > 0.0)
    return np.where(ok, t, np.inf), inside


def _exact_distance(mesh: trimesh.Trimesh, origin, directions, face):
    """float64 ray parameter on the given (hit) faces; the plane's if rounding put the hit just outside."""
    t = np.full(len(face), np.inf)
    hit = face >= 0
    if hit.any():
        tri = np.asarray(mesh.triangles, dtype=np.float64)[face[hit]]
        origin = np.asarray(origin, dtype=np.float64)
        t[hit], _ = ray_triangle_f64(origin[hit] if origin.ndim == 2 else origin, directions[hit], tri)
    return t


def _build_intersector(mesh: trimesh.Trimesh):
    try:
        from trimesh.ray.ray_pyembree import RayMeshIntersector
    except ImportError as exc:  # embreex missing
        raise BackendUnavailable(f"the 'embree' scan backend needs embreex: pip install embreex ({exc})") from None
    return RayMeshIntersector(mesh)


#: Embree BVHs of the scenes in use, rebuilt after a mesh edit (:class:`~zbuf_occlude.mesh.cache.MeshCache`).
_intersector = MeshCache(_build_intersector, 4)


def cast_embree(mesh: trimesh.Trimesh, origin: NDArray[np.float64], directions: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """First hit of each ray ``origin + t · directions[i]``, Embree.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame.
    origin : (3,) or (N, 3) float64
        One origin for every ray, or one per ray (an airborne scanner's moving aircraft).
    directions : (N, 3) float64
        Unit vectors.

    Returns
    -------
    face : (N,) int64
        Row of ``mesh.faces`` hit first, −1 for none.
    t : (N,) float64
        Distance to the hit along the ray (float64 on the hit face), inf for none.

    Raises
    ------
    BackendUnavailable
        embreex is not installed.
    """
    directions = np.asarray(directions, dtype=np.float64)
    if len(directions) == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    origins = np.broadcast_to(np.asarray(origin, dtype=np.float64), directions.shape)
    face = np.asarray(_intersector(mesh).intersects_first(origins, directions), dtype=np.int64)
    return face, _exact_distance(mesh, np.asarray(origin, np.float64), directions, face)


# -- z-buffer (GPU) ----------------------------------------------------------------------------
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

    The views are rasterised and each ray's candidates tested on the GPU
    (``render/shaders/scan_candidates.comp``, float32); the distance on the chosen face is then
    recomputed in float64, and a ray goes to Embree when its window showed faces but none was
    hit, or when the float64 test puts the chosen face's hit outside it by more than
    :data:`RECHECK_EPSILON`.

    Parameters
    ----------
    mesh, origin, directions
        As :func:`cast_embree`.
    resolution : int
        Pixels per side of each view (cube-map face: 90° field of view).
    neighborhood : int
        Candidate window radius r, pixels (window ``(2r+1)²``), 0 ≤ r ≤ 4.
    znear, zfar : float
        Clip planes, metres; nothing nearer than ``znear`` is hit.

    Returns
    -------
    face, t
        As :func:`cast_embree`; ``face`` is the lowest index of a group of identical faces.
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
