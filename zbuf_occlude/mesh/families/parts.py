"""The parts the families are built of: ``trimesh.creation`` primitives placed in metres, z up.

Every part is a :class:`trimesh.Trimesh` in the object frame (z up, metres, the ground at z = 0).
Closed parts (:func:`rod`, :func:`frustum`, :func:`plate`) are watertight on their own; the open
ones say so (:func:`open_tube`, :func:`leaf_cluster`).  :func:`assemble` concatenates a family's
named parts in order, without merging vertices, so each part keeps its own closure.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    import trimesh  # imported where used: a parser that lists the families loads no trimesh

__all__ = ["assemble", "capsule", "ellipsoid", "frustum", "leaf_cluster", "open_tube", "plate", "rod", "LEAF_GAP"]

#: Share of a leaf cluster's faces removed, so that a beam through an outer gap returns from the
#: foliage behind it, as in a real crown (the shrub recipe of the sim-to-real runs).
LEAF_GAP = 0.3
#: Radial jitter of a leaf cluster's vertices: each is scaled by a factor drawn in this range.
LEAF_JITTER = (0.85, 1.15)
#: Icosphere subdivisions of a leaf cluster (320 faces before the gaps).
LEAF_SUBDIVISIONS = 2
#: Sections around a rod or a column: enough for a round silhouette at scanner resolutions.
ROUND_SECTIONS = 16


def rod(start: ArrayLike, end: ArrayLike, radius: float, *, sections: int = ROUND_SECTIONS) -> trimesh.Trimesh:
    """A closed cylinder of ``radius`` metres from ``start`` (3,) to ``end`` (3,) (``trimesh.creation.cylinder``)."""
    import trimesh

    segment = np.array([start, end], dtype=np.float64)
    return trimesh.creation.cylinder(radius=radius, segment=segment, sections=sections)


def capsule(start: ArrayLike, end: ArrayLike, radius: float, *, count: int = 8) -> trimesh.Trimesh:
    """A closed capsule (a cylinder with hemispherical ends) of ``radius`` metres whose end centres are
    ``start`` (3,) and ``end`` (3,) (``trimesh.creation.capsule``, ``count`` segments around and along):
    a limb whose joints stay round when it bends."""
    import trimesh

    start, end = np.asarray(start, dtype=np.float64), np.asarray(end, dtype=np.float64)
    length = float(np.linalg.norm(end - start))
    m = trimesh.creation.capsule(height=length, radius=radius, count=[count, count])
    transform = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], (end - start) / length) if length > 0 else np.eye(4)
    transform[:3, 3] = 0.5 * (start + end)
    return m.apply_transform(transform)


def ellipsoid(centre: ArrayLike, semi_axes: ArrayLike) -> trimesh.Trimesh:
    """A closed ellipsoid of ``semi_axes`` (3,) metres along x, y, z at ``centre`` (3,): an icosphere
    (``trimesh.creation.icosphere``, 2 subdivisions) scaled per axis."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    return trimesh.Trimesh(s.vertices * np.asarray(semi_axes, dtype=np.float64) + centre, s.faces, process=False)


def frustum(height: float, r_bottom: float, r_top: float, *, sections: int = ROUND_SECTIONS) -> trimesh.Trimesh:
    """A closed tapered column standing on z = 0: radius ``r_bottom`` at the ground, ``r_top`` at ``height`` (metres).

    A ``trimesh.creation.cylinder`` whose rings are scaled linearly with height.
    """
    import trimesh

    m = trimesh.creation.cylinder(radius=1.0, height=height, sections=sections)
    v = np.array(m.vertices)
    t = (v[:, 2] + 0.5 * height) / height  # 0 at the bottom, 1 at the top
    v[:, :2] *= (r_bottom + (r_top - r_bottom) * t)[:, None]
    v[:, 2] += 0.5 * height
    return trimesh.Trimesh(v, m.faces, process=False)


def plate(extents: ArrayLike, centre: ArrayLike, *, yaw_deg: float = 0.0, roll_deg: float = 0.0) -> trimesh.Trimesh:
    """A closed box of ``extents`` (3,) metres centred at ``centre`` (3,), turned ``roll_deg`` about y then ``yaw_deg`` about z."""
    import trimesh

    rotate = trimesh.transformations.rotation_matrix
    transform = (trimesh.transformations.translation_matrix(centre) @ rotate(np.radians(yaw_deg), [0, 0, 1])
                 @ rotate(np.radians(roll_deg), [0, 1, 0]))  # fmt: skip
    return trimesh.creation.box(extents=np.asarray(extents, dtype=np.float64), transform=transform)


def open_tube(start: ArrayLike, end: ArrayLike, radius: float, *, sections: int = 6) -> trimesh.Trimesh:
    """A thin tube from ``start`` to ``end`` with its ends deliberately open (no caps): a wire cut
    where the object's crop ends, whose cut faces a scanner never sees.  Not watertight."""
    import trimesh

    start, end = np.asarray(start, dtype=np.float64), np.asarray(end, dtype=np.float64)
    axis = (end - start) / np.linalg.norm(end - start)
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    w = np.cross(axis, u)
    a = np.linspace(0.0, 2 * np.pi, sections, endpoint=False)
    ring = radius * (np.cos(a)[:, None] * u + np.sin(a)[:, None] * w)
    verts = np.vstack([ring + start, ring + end])
    j = np.arange(sections)
    k = (j + 1) % sections
    faces = np.vstack([np.stack([j, k, k + sections], axis=1), np.stack([j, k + sections, j + sections], axis=1)])
    return trimesh.Trimesh(verts, faces, process=False)


def leaf_cluster(rng: np.random.Generator, centre: ArrayLike, radius: float) -> trimesh.Trimesh:
    """A clump of foliage: an icosphere of ``radius`` metres at ``centre`` (3,), each vertex moved
    radially by a factor in :data:`LEAF_JITTER`, and :data:`LEAF_GAP` of its faces removed (open).

    Draws from ``rng``: one factor per vertex, then one number per face.
    """
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=LEAF_SUBDIVISIONS, radius=radius)
    v = s.vertices * rng.uniform(*LEAF_JITTER, (len(s.vertices), 1)) + centre
    keep = rng.random(len(s.faces)) >= LEAF_GAP
    return trimesh.Trimesh(v, s.faces[keep], process=False)


def assemble(parts: Mapping[str, Sequence[trimesh.Trimesh]]) -> trimesh.Trimesh:
    """The named parts as one mesh, in order (``trimesh.util.concatenate``; vertices not merged)."""
    import trimesh

    return trimesh.util.concatenate([m for group in parts.values() for m in group])
