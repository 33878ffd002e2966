"""Peer HSR methods from other tools, registered for the comparison.

``"naive-zbuffer"``
    The plain depth test with no tolerance, as ``mesh_to_sdf``'s ``Scan.is_visible`` does:
    a point is visible iff its depth is not behind the depth buffer at its pixel.
    :func:`naive_zbuffer_visible`.
``"open3d-hpr"``
    Katz, Tal & Basri, "Direct visibility of point sets", SIGGRAPH 2007, through Open3D's
    ``PointCloud.hidden_point_removal``, with the radius rule of Open3D's own example.
    :func:`open3d_hpr_visible`.
``"open3d-raycast"``
    Open3D's ``RaycastingScene.test_occlusions`` (Embree inside, float32): a second
    exact-by-construction oracle, independent of ours, to cross-check it.
    :func:`open3d_raycast_visible`.

The Open3D methods need the ``open3d`` extra (``pip install '.[open3d]'`` from a checkout) (Open3D's wheel also needs
the system's ``libusb-1.0``) and raise :class:`~zbuf_occlude.errors.BackendUnavailable`
without it.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude._version import install_hint
from zbuf_occlude.defaults import DEFAULT_RESOLUTION
from zbuf_occlude.errors import BackendUnavailable
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.visibility.registry import check_face_index, check_points, register, visible_in_frustum
from zbuf_occlude.visibility.zbuffer import ResidentPoints

__all__ = [
    "HPR_RADIUS_FACTOR",
    "RAYCAST_START_OFFSET",
    "naive_zbuffer_visible",
    "open3d_hpr_visible",
    "open3d_raycast_visible",
    "import_open3d",
]

log = logging.getLogger(__name__)

#: Katz et al.'s spherical-flipping radius as a multiple of the cloud's bounding-box
#: diagonal: Open3D's example (``hidden_point_removal`` tutorial) uses ``diameter * 100``.
HPR_RADIUS_FACTOR = 100.0
#: ``open3d-raycast``: rays start this far from the point towards the camera (object
#: units), to step off the point's own surface.  Embree works in float32, whose spacing
#: near a camera 4 units away is ~5e-7; 1e-4 of the object's size is well clear of it and
#: still far below any gap between two surfaces of a ModelNet model.
RAYCAST_START_OFFSET = 1e-4


@register("naive-zbuffer", takes_resolution=True, gpu=True)
def naive_zbuffer_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.float64],
    camera: Camera,
    *,
    face_index: NDArray[np.int64] | None = None,
    resolution: int | tuple[int, int] | None = DEFAULT_RESOLUTION,
) -> NDArray[np.bool_]:
    """Plain z-buffer depth test, zero tolerance (the rule of ``mesh_to_sdf``'s ``Scan.is_visible``).

    :meth:`zbuf_occlude.visibility.zbuffer.ResidentPoints.visible_tolerance` with
    ``depth_tolerance=0`` and ``slope_scale=0``: visible iff the point's linear depth is at
    most the rendered depth at its pixel.  Points on surfaces seen at a slant lose to their
    own face's rasterised depth about half the time (the "shadow acne" of shadow maps),
    which is what the tolerance of ``zbuffer-tolerance`` and the exact tests of
    ``zbuffer`` remove.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame.
    points : (N, 3) float64
        World frame.
    camera : Camera
    face_index : (N,) int64, optional
        Unused by the rule; accepted for the common signature.
    resolution : int or (width, height), optional
        Image size, pixels (default 1024).

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    BackendUnavailable
        No OpenGL 4.3 context.
    """
    with ResidentPoints(mesh, points, face_index) as scene:
        return scene.visible_tolerance(camera, resolution=resolution, depth_tolerance=0.0, slope_scale=0.0)


def import_open3d() -> Any:
    """The ``open3d`` module; :class:`BackendUnavailable` with the install hint when missing."""
    try:
        import open3d
    except ImportError as exc:  # also OSError-like failures of its shared libraries
        raise BackendUnavailable(
            f"the open3d-* visibility methods need Open3D: {install_hint('open3d')} "
            f"(and the system library libusb-1.0, e.g. apt-get install libusb-1.0-0): {exc}"
        ) from None
    return open3d


@register("open3d-hpr", extra="open3d")
def open3d_hpr_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    hpr_radius_factor: float = HPR_RADIUS_FACTOR,
) -> NDArray[np.bool_]:
    """Hidden point removal of Katz et al. 2007 (Open3D ``hidden_point_removal``).

    Works on the points alone (the mesh is not used): spherical flipping about the camera
    with radius ``hpr_radius_factor`` × the diagonal of the points' bounding box, then the
    convex hull; points on the hull are visible.  Combined with the camera frustum.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Unused (the method sees only points); kept for the common signature.
    points : (N, 3) float
    camera : Camera
    face_index : (N,) int, optional
        Unused.
    hpr_radius_factor : float
        Radius / bounding-box diagonal (default 100, Open3D's example).

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    BackendUnavailable
        Open3D not installed.
    """
    o3d = import_open3d()
    pts = check_points(points)
    visible = np.zeros(len(pts), dtype=bool)
    # Katz et al.'s hull needs at least 4 points in general position.
    if len(pts) < 4:
        return camera.in_frustum(pts)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    diameter = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    _, kept = cloud.hidden_point_removal(np.asarray(camera.eye, dtype=np.float64), diameter * float(hpr_radius_factor))
    visible[np.asarray(kept, dtype=np.int64)] = True
    return visible & camera.in_frustum(pts)


@register("open3d-raycast", extra="open3d")
def open3d_raycast_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    raycast_start_offset: float = RAYCAST_START_OFFSET,
) -> NDArray[np.bool_]:
    """Exact-by-construction HSR with Open3D's ``RaycastingScene.test_occlusions``.

    One ray per point, from ``raycast_start_offset`` object units off the point towards
    the camera, to the camera; occluded iff Embree (float32, inside Open3D) reports any
    hit.  Unlike ``"oracle"`` no hit is re-decided in float64 and the own face is not
    excluded by index, so differences from the oracle measure float32 and the start
    offset, i.e. how much a careful oracle matters.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame.
    points : (N, 3) float
    camera : Camera
    face_index : (N,) int, optional
        Checked, not used.
    raycast_start_offset : float
        Object units (default 1e-4, see :data:`RAYCAST_START_OFFSET`).

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    BackendUnavailable
        Open3D not installed.
    """
    o3d = import_open3d()
    pts = check_points(points)
    check_face_index(face_index, len(pts), len(mesh.faces))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
    )

    def occluded(idx: NDArray[np.int64]) -> NDArray[np.bool_]:
        seg = camera.eye - pts[idx]
        length = np.linalg.norm(seg, axis=1, keepdims=True)
        origin = pts[idx] + float(raycast_start_offset) * seg / length
        # Direction e - origin un-normalised: t in [0, 1] spans exactly origin → camera.
        rays = np.hstack([origin, camera.eye - origin]).astype(np.float32)
        return scene.test_occlusions(o3d.core.Tensor(rays), tnear=0.0, tfar=1.0).numpy().astype(bool)

    return visible_in_frustum(pts, camera, occluded)
