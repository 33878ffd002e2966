"""The paper's vertex-based hidden surface removal (Sryamkin et al. 2023, §3.3, Fig. 3-4).

Test the mesh's vertices; delete every face with an occluded vertex; a sampled point is
visible iff its face survived.  Registered as ``"paper-vertex"``.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude.defaults import DEFAULT_SELF_HIT_TOLERANCE
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.visibility.oracle_numpy import DEFAULT_PAIRS_PER_CHUNK
from zbuf_occlude.visibility.paper.face_scan import occluded_by_faces
from zbuf_occlude.visibility.registry import check_face_index, check_points, register
from zbuf_occlude.visibility.segment_triangle import mesh_planes

__all__ = ["surviving_faces", "paper_vertex_visible"]

log = logging.getLogger(__name__)


def _subdivide(mesh: trimesh.Trimesh, max_edge: float) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """Fig. 4: split faces until no edge is longer than ``max_edge``; (vertices, faces, parent)."""
    if not (math.isfinite(max_edge) and max_edge > 0.0):
        raise InvalidInputError(f"max_edge must be finite and > 0 object units, got {max_edge!r}")
    longest = float(np.max(mesh.edges_unique_length)) if len(mesh.faces) else 0.0
    # Each pass halves every edge longer than max_edge, so log2(longest / max_edge) passes
    # are enough; one more absorbs rounding.
    passes = max(1, math.ceil(math.log2(max(longest / max_edge, 1.0))) + 1)
    vertices, faces, parent = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge, max_iter=passes, return_index=True)
    return np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64), np.asarray(parent, dtype=np.int64)


def _locate_in_children(
    triangles: NDArray[np.float64],
    parent: NDArray[np.int64],
    points: NDArray[np.float64],
    face_index: NDArray[np.int64],
    pairs_per_chunk: int,
) -> NDArray[np.int64]:
    """(N,) int64: the sub-face (child of ``face_index[k]``) that contains point ``k``.

    Each point is compared with every child of its face: the child whose smallest
    barycentric coordinate is largest contains it (ties on shared edges go to either).
    """
    children = np.argsort(parent, kind="stable")
    first = np.searchsorted(parent[children], np.arange(parent.max() + 1 if len(parent) else 0))
    count = np.bincount(parent, minlength=len(first))
    best = np.empty(len(points), dtype=np.int64)
    n_per_point = count[face_index]
    block = max(1, pairs_per_chunk // max(1, int(n_per_point.max(initial=1))))
    for s in range(0, len(points), block):
        sl = slice(s, s + block)
        reps = n_per_point[sl]
        owner = np.repeat(np.arange(len(reps)), reps)
        offset = np.arange(len(owner)) - np.repeat(np.cumsum(reps) - reps, reps)
        child = children[first[face_index[sl]][owner] + offset]
        tri = triangles[child]
        bary = trimesh.triangles.points_to_barycentric(tri, points[sl][owner])
        score = bary.min(axis=1)
        # Best child per point: sort by (owner, -score) and take each owner's first.
        pick = np.lexsort((-score, owner))
        firsts = pick[np.r_[0, np.flatnonzero(np.diff(owner[pick])) + 1]]
        best[sl] = child[firsts]
    return best


def surviving_faces(
    mesh: trimesh.Trimesh,
    camera: Camera,
    *,
    max_edge: float | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    backend: str = "auto",
    pairs_per_chunk: int = DEFAULT_PAIRS_PER_CHUNK,
) -> tuple[trimesh.Trimesh, NDArray[np.bool_], NDArray[np.int64]]:
    """The paper's vertex-based HSR: faces with no occluded vertex (Sryamkin et al. 2023, §3.3).

    Each vertex's segment to the camera is tested against every face (Eq. 1-10, stop at
    the first occluder; faces through the vertex meet it at distance 0 <= ``tolerance``
    and do not count); every face with at least one occluded vertex is deleted.  Vertices
    with the same coordinates (ModelNet's triangle soup repeats them) are tested once.
    With ``max_edge``, faces are first split until no edge is longer (Fig. 4), which
    shrinks the faces that one occluded corner deletes whole.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame.
    camera : Camera
    max_edge : float, optional
        Longest edge after subdivision, object units; ``None`` (default) keeps the faces.
    tolerance, backend, pairs_per_chunk
        As :func:`occluded_by_faces`.

    Returns
    -------
    tested : trimesh.Trimesh
        The mesh whose faces were tested (``mesh`` itself without ``max_edge``).
    survived : (F',) bool
        Per face of ``tested``: no vertex occluded.  Sample these faces to get the paper's
        §3.3 output cloud.
    parent : (F',) int64
        Index into ``mesh.faces`` of each face of ``tested``.

    Raises
    ------
    InvalidInputError
        Bad ``max_edge``/``tolerance``/``backend``.
    BackendUnavailable
        ``backend="numba"`` without numba.
    """
    if max_edge is None:
        tested, parent = mesh, np.arange(len(mesh.faces), dtype=np.int64)
    else:
        vertices, faces, parent = _subdivide(mesh, float(max_edge))
        tested = trimesh.Trimesh(vertices, faces, process=False)
    vertices = np.asarray(tested.vertices, dtype=np.float64)
    faces = np.asarray(tested.faces, dtype=np.int64)
    used, corner_of = np.unique(faces.ravel(), return_inverse=True)
    unique_xyz, xyz_of = np.unique(vertices[used], axis=0, return_inverse=True)
    occluded_xyz = occluded_by_faces(
        mesh_planes(tested),
        unique_xyz,
        camera.eye,
        tolerance=tolerance,
        backend=backend,
        pairs_per_chunk=pairs_per_chunk,
    )
    corner_occluded = occluded_xyz[xyz_of.ravel()][corner_of.ravel()].reshape(faces.shape)
    return tested, ~corner_occluded.any(axis=1), parent


@register("paper-vertex")
def paper_vertex_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    max_edge: float | None = None,
    tolerance: float = DEFAULT_SELF_HIT_TOLERANCE,
    backend: str = "auto",
    pairs_per_chunk: int = DEFAULT_PAIRS_PER_CHUNK,
) -> NDArray[np.bool_]:
    """Vertex-based HSR (Sryamkin et al. 2023, §3.3): a point is visible iff its face survived.

    :func:`surviving_faces` decides the faces; the paper then samples the surviving faces.
    To compare with the other methods on the same points, a sampled point counts as
    visible iff it is in the frustum and the face it lies on (after subdivision, the
    sub-face that contains it) survived.

    Parameters
    ----------
    mesh, points, camera, tolerance, backend, pairs_per_chunk
        As :func:`paper_exact_visible`.
    face_index : (N,) int, optional
        Face of each point; found with trimesh's closest-point query when missing (slower).
    max_edge : float, optional
        Subdivide faces first (Fig. 4), object units; ``None`` (default) does not.

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    InvalidInputError, BackendUnavailable
        As :func:`surviving_faces`.
    """
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), len(mesh.faces))
    if fi is None:
        log.debug("paper-vertex: no face_index, locating points with a closest-point query")
        _, _, fi = trimesh.proximity.closest_point(mesh, pts)
        fi = np.asarray(fi, dtype=np.int64)
    tested, survived, parent = surviving_faces(
        mesh, camera, max_edge=max_edge, tolerance=tolerance, backend=backend, pairs_per_chunk=pairs_per_chunk
    )
    if max_edge is not None:
        fi = _locate_in_children(np.asarray(tested.triangles), parent, pts, fi, pairs_per_chunk)
    return camera.in_frustum(pts) & survived[fi]
