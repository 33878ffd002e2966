"""Hedges: a segment of a row of shrubs grown together, longer than it is thick, from the ground up.

A hedge is a line of closely set shrubs grown into one mass.  A street scan's segmentation cuts a run
into pieces a few metres long, so a segment, not the whole run, is one object.  Its foliage is
:func:`~zbuf_occlude.mesh.families.parts.leaf_cluster` icospheres (open: 30 % of each cluster's faces
removed, so that a beam through an outer gap returns from the foliage behind it) filling the segment's
envelope, as :mod:`~zbuf_occlude.mesh.families.shrub` fills a shrub's; a shrub is as long as it is broad,
a hedge :data:`RANGES` ``length_ratio`` times as long as it is tall.

Ranges
------
* ``height_m`` 0.5-2.5 m: from front-garden hedges kept below 1 m to rural hedgerows, whose favourable
  condition is an average height of at least 1.5 m (Defra, *Hedgerow Survey Handbook*, 2nd ed.,
  2007); a hedge over 2 m is a "high hedge" (Anti-social Behaviour Act 2003, Part 8, s. 66).
* ``thickness_ratio`` (the thickness across the run over the height) 0.5-1.0: clipped hedges are kept
  thinner than tall, and a hedgerow in favourable condition is at least 1.5 m wide for its 1.5 m of
  height (the same handbook).
* ``length_ratio`` (the segment's length over its height) 1.2-2.0: the piece of a run that one object of a
  street scan's segmentation holds (a run is cut where it meets other objects or the crop's bounds, not
  where a plant ends).  No published figure: a segment longer than it is tall, and no longer than a
  parked car, the object a segmentation most often cuts a roadside run against.
* ``cluster_ratio`` (a leaf cluster's radius over the smaller of the thickness and the height)
  0.25-0.4, as the shrub's clusters are to its height.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.mesh.families.parts import assemble, leaf_cluster

if TYPE_CHECKING:
    import trimesh  # imported where used: a parser that lists the families loads no trimesh

__all__ = ["CLASS_NAME", "NAME", "OPEN_PARTS", "RANGES", "make", "parts"]

NAME = "hedge"
CLASS_NAME = "bush"
#: Drawn parameters and their ranges (module docstring for the sources).
RANGES = {"height_m": (0.5, 2.5), "thickness_ratio": (0.5, 1.0), "length_ratio": (1.2, 2.0), "cluster_ratio": (0.25, 0.4)}
#: The foliage is open: its clusters have gaps.
OPEN_PARTS = frozenset({"foliage"})
#: Leaf clusters' summed volume over the envelope's (before they overlap), and the fewest and most clusters.
FILL, CLUSTERS = 0.8, (8, 150)


def parts(rng: np.random.Generator) -> tuple[dict[str, list[trimesh.Trimesh]], dict[str, Any]]:
    """One hedge segment in real size (metres, z up, on z = 0; the run along x, centred on the origin).

    Returns
    -------
    parts : dict
        ``"foliage"``: the open leaf clusters, their centres drawn uniformly in the envelope (``length_m``
        along x, ``thickness_m`` across, ``height_m`` up) inset by a cluster's radius, four of them at its
        bottom, top and two ends.
    params : dict
        The drawn ``RANGES`` keys, ``length_m``, ``thickness_m``, ``cluster_m`` and ``clusters``.
    """
    draw = {k: float(rng.uniform(*RANGES[k])) for k in RANGES}
    size = draw["height_m"] * np.array([draw["length_ratio"], draw["thickness_ratio"], 1.0])
    r = draw["cluster_ratio"] * min(size[1], size[2])
    count = int(np.clip(round(FILL * np.prod(size) / (4.0 / 3.0 * np.pi * r**3)), *CLUSTERS))
    half = 0.5 * size - r
    centres = rng.uniform(-half, half, (count, 3))
    for k, (axis, side) in enumerate(((2, -1), (2, 1), (0, -1), (0, 1))):  # the bottom, the top and the two ends reached
        centres[k, axis] = side * half[axis]
    centres[:, 2] += 0.5 * size[2]
    clusters = [leaf_cluster(rng, c, r) for c in centres]
    bottom = min(float(m.bounds[0, 2]) for m in clusters)  # the lowest leaf (of a face kept) stands on the ground
    for m in clusters:
        m.apply_translation([0.0, 0.0, -bottom])
    return {"foliage": clusters}, {
        **draw,
        "length_m": float(size[0]),
        "thickness_m": float(size[1]),
        "cluster_m": float(r),
        "clusters": count,
    }


def make(rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """One hedge segment (:func:`parts`) as one mesh, and its parameters."""
    pieces, params = parts(rng)
    return assemble(pieces), params
