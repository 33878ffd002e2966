"""Trees: a tapered trunk under a crown of leaf clusters.

The trunk is a closed :func:`~zbuf_occlude.mesh.families.parts.frustum` that reaches into the
crown; the crown is an ellipsoid filled with :func:`~zbuf_occlude.mesh.families.parts.leaf_cluster`
icospheres (open: 30 % of each cluster's faces removed), with one cluster at its top and four at its
widest, so that the tree's height and crown diameter are those drawn (within a cluster's jitter).

Ranges
------
Typical of the street trees in McPherson, van Doorn & Peper (2016), *Urban tree database and
allometric equations*, USDA Forest Service Gen. Tech. Rep. PSW-GTR-253 (measured street trees of
16 US reference cities, heights and crown diameters against trunk diameter):

* ``height_m`` 4-20 m;
* ``crown_ratio`` (crown diameter over height) 0.4-0.8, so a crown diameter of 1.6-16 m;
* ``crown_base_ratio`` (clear stem under the crown over height) 0.25-0.45 (street trees are
  pruned clear of walkers and traffic);
* ``dbh_ratio`` (trunk diameter at breast height over height) 0.015-0.04: 0.06-0.8 m.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.mesh.families.parts import assemble, frustum, leaf_cluster

if TYPE_CHECKING:
    import trimesh  # imported where used: a parser that lists the families loads no trimesh

__all__ = ["CLASS_NAME", "NAME", "OPEN_PARTS", "RANGES", "make", "parts"]

NAME = "tree"
CLASS_NAME = "tree"
#: Drawn parameters and their ranges (module docstring for the sources).
RANGES = {"height_m": (4.0, 20.0), "crown_ratio": (0.4, 0.8), "crown_base_ratio": (0.25, 0.45),
          "dbh_ratio": (0.015, 0.04), "clusters": (12, 24), "cluster_ratio": (0.18, 0.3)}  # fmt: skip
#: The crown is open: its clusters have gaps.
OPEN_PARTS = frozenset({"crown"})
#: The crown's depth-wise semi-axis over its width-wise one: crowns are a little elliptic from above.
CROWN_ELLIPTICITY = (0.85, 1.0)
#: Trunk radius at the ground and at its top over half the DBH (a flare below breast height, a taper above).
TRUNK_TAPER = (1.1, 0.5)


def parts(rng: np.random.Generator) -> tuple[dict[str, list[trimesh.Trimesh]], dict[str, Any]]:
    """One tree in real size (metres, z up, on z = 0).

    Returns
    -------
    parts : dict
        ``"trunk"``: one closed frustum; ``"crown"``: the open leaf clusters.
    params : dict
        The drawn ``RANGES`` keys, and ``crown_diameter_m``, ``crown_base_m``, ``dbh_m``.
    """
    draw = {k: float(rng.uniform(*RANGES[k])) for k in ("height_m", "crown_ratio", "crown_base_ratio", "dbh_ratio", "cluster_ratio")}
    lo, hi = RANGES["clusters"]
    clusters = int(rng.integers(lo, hi + 1))
    height = draw["height_m"]
    diameter, base, dbh = height * draw["crown_ratio"], height * draw["crown_base_ratio"], height * draw["dbh_ratio"]
    depth = height - base
    semi = np.array([0.5 * diameter, 0.5 * diameter * rng.uniform(*CROWN_ELLIPTICITY), 0.5 * depth])
    centre = np.array([0.0, 0.0, base + 0.5 * depth])
    r = draw["cluster_ratio"] * min(diameter, depth)
    inner = np.maximum(semi - r, 0.0)  # cluster centres inside the ellipsoid shrunk by a cluster's radius
    anchors = [(0, 0, 1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)]  # the top, and the crown's widest
    crown = [leaf_cluster(rng, centre + inner * a, r) for a in anchors]
    for _ in range(clusters - len(anchors)):
        direction = rng.standard_normal(3)
        direction /= np.linalg.norm(direction)
        crown.append(leaf_cluster(rng, centre + inner * direction * rng.uniform() ** (1 / 3), r))
    trunk_top = base + 0.5 * depth  # into the crown, as a real stem runs on into its branches
    trunk = frustum(trunk_top, 0.5 * dbh * TRUNK_TAPER[0], 0.5 * dbh * TRUNK_TAPER[1])
    params = {**draw, "clusters": clusters, "crown_diameter_m": diameter, "crown_base_m": base, "dbh_m": dbh}
    return {"trunk": [trunk], "crown": crown}, params


def make(rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """One tree (:func:`parts`) as one mesh, and its parameters."""
    pieces, params = parts(rng)
    return assemble(pieces), params
