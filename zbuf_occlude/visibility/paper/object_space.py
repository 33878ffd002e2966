"""The paper's own object-space hidden surface removal (HSR) family.

Sryamkin, Msallam & Klestov, "A method to create real-like point clouds for 3D object
classification", Front. Robot. AI 9 (2023), §3.3, §3.5 and §3.6.  Every method decides
occlusion with the paper's segment/triangle test (Eq. 1-10), in float64, with the planes
of :func:`zbuf_occlude.visibility.segment_triangle.triangle_planes`; what differs is *which*
segments are tested against *which* faces.

Registered methods (:func:`~zbuf_occlude.visibility.registry.visible_mask`)
-----------------------------------------------------------------------------
``"paper-vertex"`` (§3.3, Fig. 3-4)
    Test the mesh's vertices; delete every face with an occluded vertex; a sampled point
    is visible iff its face survived.  :func:`paper_vertex_visible`.
``"paper-exact"`` (§3.5)
    Test every sampled point against every face, stopping at the first occluder.  Same
    definition as the oracle, so the same answer.  :func:`paper_exact_visible`.
``"paper-pruned"``, ``"paper-pruned-plane"`` (§3.6, first and second suggestions)
    As ``paper-exact``, but a face that is farther from the camera than the tested point
    is excluded.  :func:`paper_pruned_visible`.
``"og"``, ``"og16"``, ``"og32"``, ``"og64"``, ``"og128"`` (§3.6, third suggestion)
    Occupancy grid: one test per occupied cell; every point takes its cell's answer.
    :func:`og_visible` (the reading of the paper implemented is documented there).

Every method returns ``camera.in_frustum(points) & ~occluded``, like the oracle.

The loop over faces that every method runs, with its numba and numpy backends, is
:func:`~.face_scan.occluded_by_faces` (:mod:`.face_scan`); §3.6's exclusion keys are in
:mod:`.pruning`, the vertex method in :mod:`.vertex` and the occupancy grid in
:mod:`.occupancy`.  This module holds ``paper-exact`` and ``paper-pruned`` and re-exports
the rest, so ``zbuf_occlude.visibility.paper.object_space`` keeps every name it had.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude.defaults import DEFAULT_SELF_HIT_TOLERANCE
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.visibility.oracle_numpy import DEFAULT_PAIRS_PER_CHUNK
from zbuf_occlude.visibility.paper.face_scan import occluded_by_faces
from zbuf_occlude.visibility.paper.pruning import PRUNE_RULES, camera_distance, face_keys, min_sample_distance, parse_prune
from zbuf_occlude.visibility.registry import check_face_index, check_points, register, signature_without, visible_in_frustum
from zbuf_occlude.visibility.segment_triangle import mesh_planes

__all__ = ["paper_exact_visible", "paper_pruned_visible"]


# =========================================================================================
# §3.5: exact
# =========================================================================================
@register("paper-exact", exact=True)
def paper_exact_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    face_order: str = "mesh",
    backend: str = "auto",
    pairs_per_chunk: int = DEFAULT_PAIRS_PER_CHUNK,
) -> NDArray[np.bool_]:
    """The paper's exact HSR: every sampled point against every face (Sryamkin et al. 2023, §3.5).

    Sample first, then for each point test the segment to the camera against the faces,
    one by one, with Eq. 1-10, stopping at the first occluder.  The definition is the
    oracle's (:mod:`zbuf_occlude.visibility.oracle`), so the answer equals
    ``"oracle-numpy"`` bit for bit and ``"oracle"`` up to Embree's documented float32
    residue; only the cost differs: O(N·F) pair tests, fewer for hidden points.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The occluders, world frame.
    points : (N, 3) float
        Points on the surface, world frame.
    camera : Camera
        Pose and intrinsics; points outside the frustum are not visible.
    face_index : (N,) int, optional
        Face each point was sampled on; it never hides its own point.
    tolerance : float
        Hits within this distance of the point are its own surface (object units, 1e-6).
    face_order : {"mesh", "near-first"}
        Order in which faces are visited: the file's (the paper's loop), or by increasing
        camera distance of their nearest corner (an ablation: it separates the gain of
        §3.6's exclusion from that of meeting occluders sooner).  Never changes the answer.
    backend : {"auto", "numba", "numpy"}
        See the module docstring.
    pairs_per_chunk : int
        numpy backend: most (point, face) pairs held at once.

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    InvalidInputError
        Bad input or an unknown ``face_order``/``backend``.
    BackendUnavailable
        ``backend="numba"`` without numba.
    """
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), len(mesh.faces))
    planes = mesh_planes(mesh)
    if face_order == "mesh":
        order = None
    elif face_order == "near-first":
        order = np.argsort(min_sample_distance(np.asarray(mesh.triangles), camera.eye), kind="stable")
    else:
        raise InvalidInputError(f"face_order must be 'mesh' or 'near-first', got {face_order!r}")

    def decide(idx: NDArray[np.int64]) -> NDArray[np.bool_]:
        return occluded_by_faces(
            planes,
            pts[idx],
            camera.eye,
            face_index=None if fi is None else fi[idx],
            tolerance=tolerance,
            order=order,
            backend=backend,
            pairs_per_chunk=pairs_per_chunk,
        )

    return visible_in_frustum(pts, camera, decide)


# =========================================================================================
# §3.6, first and second suggestions: exclude faces farther than the point
# =========================================================================================
@register("paper-pruned")
def paper_pruned_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    prune: str | tuple[str, ...] = PRUNE_RULES,
    backend: str = "auto",
    pairs_per_chunk: int = DEFAULT_PAIRS_PER_CHUNK,
) -> NDArray[np.bool_]:
    """``paper-exact`` with faces farther from the camera than the point excluded (§3.6).

    Sryamkin et al. 2023, §3.6, first and second suggestions.  For a point at camera
    distance ``d``, face ``f`` is not tested when its key exceeds ``d``, the key being the
    largest of the rules in ``prune``:

    ``"plane"`` (first suggestion)
        The distance from the camera to the face's plane (:func:`plane_distance`): every
        point of the face is at least that far, so the rule is exact.
    ``"samples"`` (second suggestion)
        The smallest camera distance of the points sampled inside the face, corners
        included (:func:`min_sample_distance`): a heuristic that may exclude an occluder
        seen nearly face-on.

    The faces are visited nearest key first, so the faces a point meets are a prefix
    and excluded faces cost nothing (see :func:`occluded_by_faces`).  With
    ``prune="plane"`` (method ``"paper-pruned-plane"``) the answer equals ``paper-exact``'s.

    Parameters
    ----------
    mesh, points, camera, face_index, tolerance, backend, pairs_per_chunk
        As :func:`paper_exact_visible`.
    prune : str or tuple of str
        Rules among ``("plane", "samples")``, e.g. ``"plane,samples"`` (default: both).

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    InvalidInputError
        Bad input or unknown rules.
    BackendUnavailable
        ``backend="numba"`` without numba.
    """
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), len(mesh.faces))
    rules = parse_prune(prune)
    planes = mesh_planes(mesh)
    eye = np.asarray(camera.eye, dtype=np.float64)
    key = face_keys(mesh, planes, eye, rules, pts if fi is not None else None, fi)

    def decide(idx: NDArray[np.int64]) -> NDArray[np.bool_]:
        return occluded_by_faces(
            planes,
            pts[idx],
            eye,
            face_index=None if fi is None else fi[idx],
            tolerance=tolerance,
            face_key=key,
            limit=camera_distance(pts[idx], eye),
            backend=backend,
            pairs_per_chunk=pairs_per_chunk,
        )

    return visible_in_frustum(pts, camera, decide)


@register("paper-pruned-plane", exact=True)
def paper_pruned_plane_visible(mesh: trimesh.Trimesh, points: NDArray[np.floating], camera: Camera, **options: Any) -> NDArray[np.bool_]:
    """``paper-pruned`` with the first suggestion of §3.6 only (exact): see :func:`paper_pruned_visible`."""
    options["prune"] = ("plane",)
    return paper_pruned_visible(mesh, points, camera, **options)


paper_pruned_plane_visible.__signature__ = signature_without(paper_pruned_visible, "prune")
