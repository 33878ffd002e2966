"""Shrubs: a blob of leaf clusters about as wide as 1-1.6 times its height, from the ground up.

Six to ten ``trimesh.creation.icosphere`` clusters (:func:`~zbuf_occlude.mesh.families.parts.leaf_cluster`:
jittered, 30 % of their faces removed, so that a beam through an outer gap returns from the foliage
behind it).  :func:`unit_shrub` is the shrub of height about 1 that the sim-to-real runs use
(``docs/results/sensor_fit/procedural_meshes.py``); :func:`make` draws it, then its real height.

Ranges
------
* ``height_m`` 0.5-3.0 m: typical shrubs and hedges (woody plants below tree size); the real bushes
  of the sim-to-real fit half are about as wide as tall (width/height 0.97-1.48, 10th-90th percentile).
* ``aspect`` (horizontal extent over height) 1.0-1.6.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.mesh.families.parts import assemble, leaf_cluster

if TYPE_CHECKING:
    import trimesh  # imported where used: a parser that lists the families loads no trimesh

__all__ = ["CLASS_NAME", "NAME", "OPEN_PARTS", "RANGES", "make", "parts", "unit_parts", "unit_shrub"]

NAME = "shrub"
CLASS_NAME = "bush"
#: Drawn parameters and their ranges (module docstring for the sources).
RANGES = {"height_m": (0.5, 3.0), "aspect": (1.0, 1.6)}
#: The foliage is open: its clusters have gaps.
OPEN_PARTS = frozenset({"foliage"})


def unit_parts(rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """A blob of foliage standing on z = 0, of height about 1, and what was drawn."""
    import trimesh

    aspect = rng.uniform(1.0, 1.6)  # horizontal extent over height
    parts = []
    clusters = int(rng.integers(6, 11))
    for _ in range(clusters):
        r = rng.uniform(0.25, 0.4)
        centre = np.array([*rng.uniform(-1, 1, 2) * (0.5 * aspect - r), rng.uniform(r, 1 - r)])
        parts.append(leaf_cluster(rng, centre, r))
    m = trimesh.util.concatenate(parts)
    m.apply_translation([0.0, 0.0, -m.bounds[0, 2]])
    return m, {"aspect": float(aspect), "clusters": clusters}


def unit_shrub(rng: np.random.Generator) -> trimesh.Trimesh:
    """The shrub of :func:`unit_parts` (height about 1, on z = 0)."""
    return unit_parts(rng)[0]


def parts(rng: np.random.Generator) -> tuple[dict[str, list[trimesh.Trimesh]], dict[str, Any]]:
    """A shrub in real size: the unit shrub scaled to a drawn height (metres, z up, on z = 0).

    Returns
    -------
    parts : dict
        ``"foliage"``: one open mesh.
    params : dict
        ``height_m``, ``aspect``, ``clusters``.
    """
    m, params = unit_parts(rng)
    height = float(rng.uniform(*RANGES["height_m"]))
    m.apply_scale(height / m.extents[2])
    return {"foliage": [m]}, {"height_m": height, **params}


def make(rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """One shrub (:func:`parts`) as one mesh, and its parameters."""
    pieces, params = parts(rng)
    return assemble(pieces), params
