"""Depth images of a pinhole camera, their back-projection to 3D, and down-sampling.

The field's occlusion recipes (ModelNet40-C, PCN, OcCo) render a depth image and lift its
pixels back to 3D; their clouds follow the pixel grid, not a uniform surface sampling.  This
module does the same headless and exactly: one ray per pixel centre, first hit by Embree
(:func:`zbuf_occlude.sensors.raycast.embree.cast_embree`, float64 distance on the hit face), so the
only error of a back-projected point is the float32 rounding of the stored depth.

Conventions (OpenCV, as Open3D's ``PinholeCameraIntrinsic`` and ModelNet40-C use them):

* ``K`` (3, 3): pixel ``(u, v)`` = (column, row), row 0 at the top, **pixel centres at integer
  coordinates**; a principal point at the image centre is ``cx = (W − 1)/2, cy = (H − 1)/2``,
  the convention of :attr:`zbuf_occlude.geometry.cameras.Camera.K` too.
* ``extrinsics`` (3, 4) ``[R | t]``: world → camera, camera looks down +z, y down.
* ``depth`` (H, W) float32: distance along the optical axis (camera z), object units; 0 = no hit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.geometry.samples import draw_sample
from zbuf_occlude.sensors.raycast.embree import cast_embree

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = [
    "PinholeView",
    "DepthImage",
    "render_depth_image",
    "back_project",
    "project",
    "downsample",
    "farthest_point_sample",
    "SAMPLINGS",
    "DOWNSAMPLERS",
]

#: How an occluded cloud is made: ``surface`` = uniform on the visible surface (the paper's);
#: ``depth`` = depth pixels lifted to 3D, then down-sampled (ModelNet40-C, PCN).
SAMPLINGS = ("surface", "depth")
#: Down-samplers of back-projected clouds (:func:`downsample`).
DOWNSAMPLERS = ("random", "fps")


@dataclass(frozen=True)
class PinholeView:
    """A pinhole camera in OpenCV conventions (module docstring).

    Parameters
    ----------
    K : (3, 3) float64
        Intrinsics, pixels; pixel centres at integer coordinates.
    extrinsics : (3, 4) float64
        World → camera ``[R | t]``; ``R`` a rotation.
    width, height : int
        Image size, pixels.

    Raises
    ------
    InvalidInputError
        Non-finite values, ``R`` not a rotation (to 1e-6), a non-positive focal length or size.
    """

    K: NDArray[np.float64]
    extrinsics: NDArray[np.float64]
    width: int
    height: int

    def __post_init__(self) -> None:
        K = np.asarray(self.K, dtype=np.float64).reshape(3, 3)
        rt = np.asarray(self.extrinsics, dtype=np.float64).reshape(3, 4)
        if not (np.isfinite(K).all() and np.isfinite(rt).all()):
            raise InvalidInputError("camera K and extrinsics must be finite")
        if K[0, 0] <= 0 or K[1, 1] <= 0 or int(self.width) < 1 or int(self.height) < 1:
            raise InvalidInputError(f"need positive focal lengths and image size, got K={K.tolist()}, {self.width}x{self.height}")
        R = rt[:, :3]
        if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
            raise InvalidInputError("extrinsics rotation is not a rotation matrix (orthonormal, det +1)")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "extrinsics", rt)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    @classmethod
    def from_camera(cls, camera: Camera) -> PinholeView:
        """The same camera as ``camera`` (:class:`~zbuf_occlude.geometry.cameras.Camera`): its ``K``, extrinsics and size."""
        return cls(camera.K, camera.extrinsics, camera.width, camera.height)

    @classmethod
    def from_pose(cls, K, camera_to_world, width: int, height: int) -> PinholeView:
        """From a (4, 4) or (3, 4) camera → world pose (OpenCV camera axes), as Open3D's ``pose``."""
        pose = np.asarray(camera_to_world, dtype=np.float64)[:3]
        R, c = pose[:, :3], pose[:, 3]
        return cls(K, np.column_stack([R.T, -R.T @ c]), width, height)

    @property
    def center(self) -> NDArray[np.float64]:
        """(3,) float64: camera centre, world frame (``−Rᵀ t``)."""
        return -self.extrinsics[:, :3].T @ self.extrinsics[:, 3]

    @property
    def camera_to_world(self) -> NDArray[np.float64]:
        """(4, 4) float64: camera (OpenCV) → world."""
        m = np.eye(4)
        m[:3, :3] = self.extrinsics[:, :3].T
        m[:3, 3] = self.center
        return m

    def pixel_rays(self) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Rays through every pixel centre, row-major (row 0 first), world frame.

        Returns
        -------
        directions : (H·W, 3) float64
            ``Rᵀ K⁻¹ (u, v, 1)``: camera-frame z component 1, so the ray parameter is the depth.
        pixels : (H·W, 2) int64
            ``(u, v)`` = (column, row).
        """
        v, u = np.mgrid[0 : self.height, 0 : self.width]
        pixels = np.stack([u.ravel(), v.ravel()], axis=1).astype(np.int64)
        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        cam = np.column_stack([(pixels[:, 0] - cx) / fx, (pixels[:, 1] - cy) / fy, np.ones(len(pixels))])
        return cam @ self.extrinsics[:, :3], pixels


@dataclass
class DepthImage:
    """One rendered view.

    Attributes
    ----------
    depth : (H, W) float32
        Distance along the optical axis, object units; 0 where no face is hit.
    face_index : (H, W) int64
        Row of ``mesh.faces`` hit at each pixel centre; −1 for none.
    view : PinholeView
    """

    depth: NDArray[np.float32]
    face_index: NDArray[np.int64]
    view: PinholeView


#: Most faces a ray passes through when back faces are culled (further ones count as no hit).
MAX_CULLED_LAYERS = 16
#: Relative step past a culled face before the ray is cast again (above float32 rounding).
CULL_STEP_RTOL = 1e-5


def _first_front_face(mesh: trimesh.Trimesh, origin, unit: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """First hit whose face points toward the ray origin (OpenGL's ``GL_CULL_FACE``, counter-clockwise front)."""
    face, t = cast_embree(mesh, origin, unit)
    normals = np.asarray(mesh.face_normals)
    todo = np.flatnonzero(face >= 0)
    for layer in range(MAX_CULLED_LAYERS + 1):
        back = todo[np.einsum("ij,ij->i", normals[face[todo]], unit[todo]) > 0]
        if len(back) == 0:
            break
        if layer == MAX_CULLED_LAYERS:
            face[back], t[back] = -1, np.inf
            break
        # restart each culled ray just past its back face: Embree works in float32, so the step
        # must exceed float32 rounding of the start (~6e-8 relative); faces closer than that
        # behind a culled face are skipped too
        t0 = t[back] * (1.0 + CULL_STEP_RTOL) + CULL_STEP_RTOL
        starts = origin + unit[back] * t0[:, None]
        f2, t2 = cast_embree(mesh, starts, unit[back])  # the same cached Embree scene, one origin per ray
        face[back], t[back] = f2, t0 + t2
        todo = back[f2 >= 0]
    return face, t


def render_depth_image(mesh: trimesh.Trimesh, view: PinholeView, *, cull_back_faces: bool = False) -> DepthImage:
    """Ray-cast a depth image: one ray per pixel centre, first hit (Embree, CPU, headless, fork-safe).

    The depth is computed in float64 on the hit face
    (:func:`~zbuf_occlude.sensors.raycast.embree.cast_embree`), then rounded to float32.  Embree
    picks the face in float32: a ray through a crack of the mesh within ~1e-5 of a face's
    edge may be counted as a hit on that face, and its depth is then that of the face's plane
    (about 1 pixel in 10⁴ on ModelNet meshes, off the surface by at most ~1e-5).

    Parameters
    ----------
    cull_back_faces : bool
        False (default): faces are two-sided.  True: faces whose normal (trimesh's, from the
        vertex order) points away from the camera are invisible, as in a rasteriser with
        ``GL_CULL_FACE`` (Open3D's ``Visualizer`` with ``mesh_show_back_face=False``, its
        default, which ModelNet40-C renders with); at most :data:`MAX_CULLED_LAYERS` culled
        faces per ray.

    Raises
    ------
    BackendUnavailable
        embreex is not installed.
    """
    directions, _ = view.pixel_rays()
    norm = np.linalg.norm(directions, axis=1)
    unit = directions / norm[:, None]
    if cull_back_faces:
        face, t = _first_front_face(mesh, view.center, unit)
    else:
        face, t = cast_embree(mesh, view.center, unit)
    depth = np.where(face >= 0, t / norm, 0.0)  # t is along the unit ray; z = t / |d| since d_z = 1
    shape = (view.height, view.width)
    return DepthImage(depth.reshape(shape).astype(np.float32), face.reshape(shape), view)


def back_project(
    depth: NDArray[np.floating], K: NDArray[np.floating], extrinsics: NDArray[np.floating]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Lift every pixel with ``depth > 0`` to 3D (Open3D's ``PointCloud.create_from_depth_image``).

    ``x = (u − cx) z / fx``, ``y = (v − cy) z / fy`` in the camera frame, then camera → world
    with the inverse of ``extrinsics``; pixels in row-major order, as Open3D returns them
    (Open3D ``geometry/PointCloudFactory.cpp``, ``CreatePointCloudFromFloatDepthImage``).

    Parameters
    ----------
    depth : (H, W) float
        Object units; 0 (or negative, NaN) = no hit.
    K : (3, 3) float
    extrinsics : (3, 4) or (4, 4) float
        World → camera.

    Returns
    -------
    points : (M, 3) float64
        World frame.
    camera_points : (M, 3) float64
        Camera frame (OpenCV).
    pixels : (M, 2) int64
        ``(u, v)`` of each point.
    """
    depth = np.asarray(depth, dtype=np.float64)
    K = np.asarray(K, dtype=np.float64)
    rt = np.asarray(extrinsics, dtype=np.float64)[:3]
    v, u = np.nonzero(np.nan_to_num(depth) > 0)
    z = depth[v, u]
    cam = np.column_stack([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z])
    R, t = rt[:, :3], rt[:, 3]
    return (cam - t) @ R, cam, np.column_stack([u, v]).astype(np.int64)


def project(
    points: NDArray[np.floating], K: NDArray[np.floating], extrinsics: NDArray[np.floating]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """World points → pixels: the inverse of :func:`back_project`.

    Returns
    -------
    uv : (N, 2) float64
        Pixel coordinates, pixel centres at integers.
    depth : (N,) float64
        Camera-frame z, object units.
    """
    rt = np.asarray(extrinsics, dtype=np.float64)[:3]
    cam = np.asarray(points, dtype=np.float64) @ rt[:, :3].T + rt[:, 3]
    K = np.asarray(K, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.column_stack([K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2], K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]])
    return uv, cam[:, 2]


def farthest_point_sample(points: NDArray[np.floating], n_points: int, rng: np.random.Generator) -> NDArray[np.int64]:
    """Indices of ``n_points`` of ``points`` by farthest-point sampling (a random first point).

    The greedy rule of PointNet++ (Qi et al. 2017, §3.2): each next point is the one farthest
    (Euclidean) from those chosen; O(n_points · N) time, O(N) memory.  Needs ``n_points <= N``.
    """
    pts = np.asarray(points, dtype=np.float64)
    chosen = np.empty(n_points, dtype=np.int64)
    chosen[0] = rng.integers(len(pts))
    dist = np.full(len(pts), np.inf)
    for i in range(1, n_points):
        dist = np.minimum(dist, ((pts - pts[chosen[i - 1]]) ** 2).sum(axis=1))
        chosen[i] = int(np.argmax(dist))
    return chosen


def downsample(points: NDArray[np.floating], n_points: int, rng: np.random.Generator, method: str = "random") -> NDArray[np.int64]:
    """Indices of ``n_points`` rows of a back-projected cloud.

    ``random``: uniformly at random without replacement (:func:`zbuf_occlude.geometry.samples.draw_sample`);
    ``fps``: :func:`farthest_point_sample`.  When fewer points exist, every point is taken
    once and the rest are repeats drawn at random (both methods).  Empty input → empty output.

    Raises
    ------
    InvalidInputError
        Unknown ``method`` or ``n_points < 1``.
    """
    if method not in DOWNSAMPLERS:
        raise InvalidInputError(f"unknown down-sampling {method!r}; use one of {DOWNSAMPLERS}")
    if n_points < 1:
        raise InvalidInputError(f"n_points must be >= 1, got {n_points}")
    n = len(points)
    if method == "fps" and n > n_points:
        return farthest_point_sample(points, n_points, rng)
    return draw_sample(np.arange(n, dtype=np.int64), n_points, rng)[0]
