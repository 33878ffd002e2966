"""The oracle: exact object-space hidden surface removal, the ground truth of every other method.

Definition
----------
A point ``p`` is *visible* from a camera with centre ``e`` iff

(a) ``p`` lies inside the camera's view frustum (:meth:`Camera.in_frustum`), and
(b) no face ``f`` of the mesh, other than the face ``p`` was sampled on (``face_index[p]``,
    when given), meets the segment from ``p`` to ``e`` at a distance ``d`` from ``p`` with
    ``tolerance < d <= |e - p|``.

``tolerance`` defaults to :data:`~zbuf_occlude.visibility.registry.DEFAULT_SELF_HIT_TOLERANCE`
(1e-6 object units; meshes are normalised to a maximum extent of 1).  Faces are two-sided:
there is no back-face culling.  A face "meets" the segment when the closed segment meets the
closed triangle (a point on an edge or a vertex counts, so a ray through an edge shared by
two triangles is never let through); a segment parallel to a face's plane never meets it.
Condition (b) is decided in float64 by the kernel of :func:`segment_hits_triangles` (the
paper's Eq. 1-10), one (point, face) pair at a time and always with the same arithmetic, so
the two implementations below can differ only if one of them never tests a pair that
occludes.  "Exact" means: decided in float64 with inclusive bounds, each triangle's edge
planes moved out by 1e-12 of its coordinate scale so that a segment through an edge shared
by two faces cannot round to outside both (the paper's edge tests alone are not watertight).
The registered methods also apply the edge-on rule of :mod:`~zbuf_occlude.visibility.definition`
(a point whose own face is seen within 1e-4 degrees of edge-on is not visible), with one
float64 function shared by both, so they agree bit for bit there too.

Implementations
---------------
The kernel, :mod:`.segment_triangle`, decides a (point, face) pair; two drivers choose the pairs:

:func:`occluded_numpy` (:mod:`.oracle_numpy`)
    The paper's equations (Sryamkin, Msallam & Klestov 2023, §3.1 and §3.5, Eq. 1-10),
    vectorised over (point, face) pairs in bounded chunks, after a conservative
    image-plane cull of the pairs (``cull=False`` tests all N·F).  Numpy only.
:func:`occluded_embree` (:mod:`.oracle_embree`)
    Intel Embree (float32 BVH, through ``embreex``) proposes the candidate occluder of each
    ray; every candidate is re-decided in float64 by the same kernel, so Embree's rounding
    can cost at most a missed candidate, never a false occluder.  How the float32 traps are
    handled is documented on the function.

Registered methods (:func:`~zbuf_occlude.visibility.registry.visible_mask`)
-----------------------------------------------------------------------------
``"oracle"``
    :func:`oracle_visible`, Embree.
``"oracle-numpy"``
    :func:`oracle_numpy_visible`, pure numpy (small meshes, or to check ``"oracle"``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude.defaults import DEFAULT_SELF_HIT_TOLERANCE
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.visibility.definition import hide_edge_on
from zbuf_occlude.visibility.oracle_embree import occluded_embree
from zbuf_occlude.visibility.oracle_numpy import occluded_numpy
from zbuf_occlude.visibility.registry import check_face_index, check_points, register, visible_in_frustum
from zbuf_occlude.visibility.segment_triangle import mesh_planes

__all__ = ["oracle_visible", "oracle_numpy_visible"]


def _visible(
    occluded_fn: Callable[..., NDArray[np.bool_]],
    occluders: Any,
    points: NDArray[np.floating],
    camera: Camera,
    face_index: NDArray[np.integer] | None,
    tolerance: float,
    mesh: trimesh.Trimesh,
) -> NDArray[np.bool_]:
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), len(mesh.faces))
    visible = visible_in_frustum(
        pts,
        camera,
        lambda idx: occluded_fn(occluders, pts[idx], camera.eye, face_index=None if fi is None else fi[idx], tolerance=tolerance),
    )
    # Rule (b) of visibility.definition: own face seen edge-on (issue 11).
    return hide_edge_on(visible, mesh_planes(mesh), pts, camera.eye, fi, tolerance)


@register("oracle", exact=True)
def oracle_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
) -> NDArray[np.bool_]:
    """Exact HSR, Embree-accelerated: ``camera.in_frustum(points) & ~occluded_embree(...)``.

    The ground-truth definition is in the module docstring (Sryamkin et al. 2023, Eq. 1-10).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The occluding surface, world frame; its Embree scene is cached across cameras.
    points : (N, 3) float
        Points on the surface, world frame.
    camera : Camera
        Pose and intrinsics.
    face_index : (N,) int, optional
        Face each point was sampled on; it never hides its own point.
    tolerance : float
        Occluders closer than this to the point are ignored (object units, default 1e-6).

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    BackendUnavailable
        If ``embreex`` is not installed (``pip install embreex``).
    InvalidInputError
        On bad ``points``, ``face_index`` or ``tolerance``.
    """
    return _visible(occluded_embree, mesh, points, camera, face_index, tolerance, mesh)


@register("oracle-numpy", exact=True)
def oracle_numpy_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
) -> NDArray[np.bool_]:
    """Exact HSR in pure numpy: ``camera.in_frustum(points) & ~occluded_numpy(...)``.

    O(N·F); meant for small meshes and for checking ``"oracle"``.  Parameters, returns and
    ignored options as :func:`oracle_visible`; raises :class:`InvalidInputError` on bad input.
    """
    return _visible(occluded_numpy, mesh_planes(mesh), points, camera, face_index, tolerance, mesh)
