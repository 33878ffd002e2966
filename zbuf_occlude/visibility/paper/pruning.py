"""The exclusion rules of Sryamkin et al. 2023, §3.6: which faces a point need not be tested against.

A face whose key exceeds a point's camera distance is not tested for that point
(:func:`~.face_scan.occluded_by_faces` with ``face_key``/``limit``).  Used by
``paper-pruned`` (:mod:`.object_space`) and the occupancy grid (:mod:`.occupancy`).
"""

from __future__ import annotations

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.visibility.paper.face_scan import face_count
from zbuf_occlude.visibility.segment_triangle import TrianglePlanes

__all__ = ["PRUNE_RULES", "plane_distance", "min_sample_distance", "face_keys", "camera_distance", "parse_prune"]

#: Pruning rules of :func:`face_keys`: ``"plane"`` is §3.6's first suggestion, ``"samples"``
#: its second; ``paper-pruned`` applies both.
PRUNE_RULES = ("plane", "samples")


def plane_distance(planes: TrianglePlanes, eye: ArrayLike) -> NDArray[np.float64]:
    """Distance from ``eye`` to each face's plane: §3.6's first exclusion rule.

    Every point of face ``f`` is at least ``plane_distance[f]`` from the camera, so a face
    whose plane is farther than the tested point cannot hide it: the rule is exact.

    Parameters
    ----------
    planes : TrianglePlanes
        F faces.
    eye : (3,) float
        Camera centre, object frame.

    Returns
    -------
    distance : (F,) float64
        Object units; ``+inf`` for degenerate faces (zero normal), which never hide anything.
    """
    e = np.asarray(eye, dtype=np.float64)
    norm = np.sqrt(np.einsum("ij,ij->i", planes.normal, planes.normal))
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.abs(planes.normal @ e - planes.offset) / norm
    return np.where(norm > 0.0, d, np.inf)


def min_sample_distance(
    triangles: NDArray[np.float64],
    eye: ArrayLike,
    points: NDArray[np.float64] | None = None,
    face_index: NDArray[np.int64] | None = None,
) -> NDArray[np.float64]:
    """Smallest camera distance of the points known on each face: §3.6's second rule.

    The points of face ``f`` are its three corners and the sampled points with
    ``face_index == f``.  The corners are included so that every face has a key (a face
    that drew no sample would otherwise never be excluded) and because, for a face small
    against its camera distance, the nearest point is a corner.  The rule is a heuristic:
    a face seen nearly face-on can come closer to the camera than all its known points
    (the plane rule bounds that case), so it can exclude a true occluder; the agreement
    with the oracle in docs/results measures how often.

    Parameters
    ----------
    triangles : (F, 3, 3) float64
    eye : (3,) float
    points : (N, 3) float64, optional
    face_index : (N,) int64, optional
        Both or neither.

    Returns
    -------
    distance : (F,) float64
        Object units.
    """
    e = np.asarray(eye, dtype=np.float64)
    corners = triangles - e
    d = np.sqrt(np.einsum("fkj,fkj->fk", corners, corners)).min(axis=1)
    if points is not None and face_index is not None and len(points):
        diff = points - e
        np.minimum.at(d, face_index, np.sqrt(np.einsum("ij,ij->i", diff, diff)))
    return d


def face_keys(
    mesh: trimesh.Trimesh,
    planes: TrianglePlanes,
    eye: NDArray[np.float64],
    rules: tuple[str, ...],
    points: NDArray[np.float64] | None,
    face_index: NDArray[np.int64] | None,
) -> NDArray[np.float64]:
    """(F,) float64: the exclusion key of each face under ``rules`` (max of the rules' keys).

    A face is excluded for a point whose camera distance is below the key: see
    :func:`plane_distance` (``"plane"``) and :func:`min_sample_distance` (``"samples"``).

    Raises
    ------
    InvalidInputError
        On an empty or unknown rule.
    """
    if not rules or any(r not in PRUNE_RULES for r in rules):
        raise InvalidInputError(f"prune rules must be a non-empty subset of {PRUNE_RULES}, got {rules!r}")
    key = np.full(face_count(planes), -np.inf)
    if "plane" in rules:
        key = np.maximum(key, plane_distance(planes, eye))
    if "samples" in rules:
        key = np.maximum(key, min_sample_distance(np.asarray(mesh.triangles), eye, points, face_index))
    return key


def camera_distance(points: NDArray[np.float64], eye: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N,) float64: distance of each point from ``eye``, object units."""
    diff = eye - points
    return np.sqrt(np.einsum("ij,ij->i", diff, diff))


def parse_prune(prune: str | tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """Rules from ``"plane,samples"`` or a sequence; :class:`InvalidInputError` if empty or unknown."""
    rules = tuple(r.strip() for r in prune.split(",")) if isinstance(prune, str) else tuple(prune)
    if not rules or any(r not in PRUNE_RULES for r in rules):
        raise InvalidInputError(f"prune must name rules among {PRUNE_RULES} (e.g. 'plane,samples'), got {prune!r}")
    return rules
