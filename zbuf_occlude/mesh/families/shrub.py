"""Shrubs: a blob of leaf clusters about as wide as 1-1.6 times its height, from the ground up.

Six to ten clusters of foliage.  :func:`unit_shrub` is the shrub of height about 1 that the earlier sim-to-real runs
use (``docs/results/sensor_fit/procedural_meshes.py``): its clusters are ``trimesh.creation.icosphere`` shells
(:func:`~zbuf_occlude.mesh.families.parts.leaf_cluster`: jittered, 30 % of their faces removed), which a beam through a
gap crosses to the shell behind.  :func:`make` draws the same clusters at a real height as balls of leaves
(:func:`~zbuf_occlude.mesh.families.parts.leaf_ball`), a turbid medium that a beam may cross whole: a real bush's scan
lines break where beams pass through it, and a shell's do not.

Ranges
------
* ``height_m`` 0.5-3.0 m: typical shrubs and hedges (woody plants below tree size); the real bushes
  of the sim-to-real fit half are about as wide as tall (width/height 0.97-1.48, 10th-90th percentile).
* ``aspect`` (horizontal extent over height) 1.0-1.6.
* ``leaf_area_density`` 1.25 m²/m³ in each cluster's ball (:data:`LEAF_AREA_DENSITY`): no published figure; the
  density at which HDL-32E crops of these shrubs (the ``hdl32e`` preset, 5-25 m away, 12 objects × 4 crops) break
  their scan lines as LiDARNet's fit-half bush crops do (``realism``'s outline share 0.26 against the real 0.265; the
  shells' 0.07; 1.5 gave 0.25, 2.0 0.20, 2.5 0.16).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.mesh.families.parts import assemble, leaf_ball, leaf_cluster

if TYPE_CHECKING:
    import trimesh  # imported where used: a parser that lists the families loads no trimesh

__all__ = ["CLASS_NAME", "LEAF_AREA_DENSITY", "NAME", "OPEN_PARTS", "RANGES", "make", "parts", "unit_parts", "unit_shrub"]

NAME = "shrub"
CLASS_NAME = "bush"
#: Drawn parameters and their ranges (module docstring for the sources).
RANGES = {"height_m": (0.5, 3.0), "aspect": (1.0, 1.6)}
#: The foliage is open: leaves.
OPEN_PARTS = frozenset({"foliage"})
#: One-sided leaf area per volume of a cluster's ball, m²/m³ (:func:`~zbuf_occlude.mesh.families.parts.leaf_ball`;
#: module docstring).
LEAF_AREA_DENSITY = 1.25


def _unit_clusters(rng: np.random.Generator) -> tuple[trimesh.Trimesh, list[tuple[np.ndarray, float]], dict[str, Any]]:
    """The unit shrub's open clusters as one mesh on z = 0, the clusters' balls (centre, radius) in its frame, and what
    was drawn."""
    import trimesh

    aspect = rng.uniform(1.0, 1.6)  # horizontal extent over height
    parts, balls = [], []
    clusters = int(rng.integers(6, 11))
    for _ in range(clusters):
        r = rng.uniform(0.25, 0.4)
        centre = np.array([*rng.uniform(-1, 1, 2) * (0.5 * aspect - r), rng.uniform(r, 1 - r)])
        parts.append(leaf_cluster(rng, centre, r))
        balls.append((centre, float(r)))
    m = trimesh.util.concatenate(parts)
    lift = -m.bounds[0, 2]
    m.apply_translation([0.0, 0.0, lift])
    return m, [(c + [0.0, 0.0, lift], r) for c, r in balls], {"aspect": float(aspect), "clusters": clusters}


def unit_parts(rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """A blob of foliage standing on z = 0, of height about 1 (open leaf clusters), and what was drawn."""
    m, _, params = _unit_clusters(rng)
    return m, params


def unit_shrub(rng: np.random.Generator) -> trimesh.Trimesh:
    """The shrub of :func:`unit_parts` (height about 1, on z = 0)."""
    return unit_parts(rng)[0]


def parts(rng: np.random.Generator) -> tuple[dict[str, list[trimesh.Trimesh]], dict[str, Any]]:
    """A shrub in real size: the unit shrub's clusters scaled to a drawn height, each a :func:`leaf_ball` of
    :data:`LEAF_AREA_DENSITY`, the whole scaled again to exactly that height (metres, z up, the lowest leaf on z = 0).

    Returns
    -------
    parts : dict
        ``"foliage"``: one open mesh of leaves.
    params : dict
        ``height_m``, ``aspect``, ``clusters``, ``leaf_area_density``.
    """
    import trimesh

    unit, balls, params = _unit_clusters(rng)
    height = float(rng.uniform(*RANGES["height_m"]))
    k = height / unit.extents[2]
    m = trimesh.util.concatenate([leaf_ball(rng, c * k, r * k, LEAF_AREA_DENSITY) for c, r in balls])
    m.apply_translation([0.0, 0.0, -m.bounds[0, 2]])
    m.apply_scale(height / m.extents[2])  # the leaves reach about as high as the balls: now exactly the drawn height
    return {"foliage": [m]}, {"height_m": height, **params, "leaf_area_density": LEAF_AREA_DENSITY}


def make(rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """One shrub (:func:`parts`) as one mesh, and its parameters."""
    pieces, params = parts(rng)
    return assemble(pieces), params
