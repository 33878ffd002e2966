"""Bare trunks: a tapered, bent stem with a root flare, bark-scale noise and a few branch stubs.

The stem is a grid of rings (:data:`RINGS` rings of :data:`SECTORS` vertices; the faces built as
trimesh's cylinder builds them) closed at the top by a fan, and, in real size, at the ground;
branch stubs are ``trimesh.creation.cylinder`` parts.  :func:`unit_trunk` is the stem of height 1
that the sim-to-real runs use (``docs/results/sensor_fit/procedural_meshes.py``);
:func:`make` draws it, then its real height.

Ranges
------
* ``height_m`` 2.0-6.0 m: typical bare stems and snags below a crown; the real trunks of the
  sim-to-real fit half measure 2.4-3.8 m tall (10th-90th percentile).
* ``base_radius_ratio`` 0.02-0.09 of the height (a base diameter of 0.08-1.1 m over the heights
  drawn): the real trunks' width/height ratio 0.04-0.15 and a tail of thick trunks.
* one to three branch stubs in 75 % of trunks, 30-65 degrees from the vertical, in the top quarter.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.mesh.families.parts import assemble

if TYPE_CHECKING:
    import trimesh  # imported where used: a parser that lists the families loads no trimesh

__all__ = ["CLASS_NAME", "NAME", "OPEN_PARTS", "RANGES", "RINGS", "SECTORS", "make", "parts", "unit_parts", "unit_trunk"]

NAME = "trunk"
#: The class folder a trunk is written to: real scans label bare trunks as poles.
CLASS_NAME = "pole"
#: Drawn parameters and their ranges (module docstring for the sources).
RANGES = {"height_m": (2.0, 6.0), "base_radius_ratio": (0.02, 0.09)}
#: No open part: the stem is closed at the top and at the ground, the stubs are closed cylinders.
OPEN_PARTS: frozenset[str] = frozenset()
#: Rings up the stem and vertices per ring.
RINGS, SECTORS = 24, 18


def unit_parts(rng: np.random.Generator) -> tuple[list[trimesh.Trimesh], dict[str, Any]]:
    """A stem of height 1 standing on z = 0, open at the ground, and its branch stubs.

    Returns
    -------
    parts : list of trimesh.Trimesh
        The stem (``RINGS * SECTORS + 1`` vertices: the rings bottom to top, then the top
        vertex), then 0 to 3 stubs.
    params : dict
        What was drawn (ratios of the height).
    """
    import trimesh

    n_z, n_a = RINGS, SECTORS
    z = np.linspace(0.0, 1.0, n_z)
    a = np.linspace(0.0, 2 * np.pi, n_a, endpoint=False)
    r0 = rng.uniform(0.02, 0.09)
    flare, taper, ellipse = rng.uniform(0.2, 0.8), rng.uniform(0.6, 0.9), rng.uniform(0.75, 1.0)
    bend = rng.uniform(-0.06, 0.06, 2)

    def axis(t):  # the stem's centre (x, y) and its radius without the flare at height t
        return bend[0] * t**2, bend[1] * t**2, r0 * (1 - (1 - taper) * t)

    cx, cy, r = axis(z[:, None])
    radius = r * (1 + flare * np.exp(-z[:, None] / 0.06))
    noise = 1 + 0.04 * rng.standard_normal((n_z, n_a))
    x = (radius * noise * np.cos(a)[None]) + cx
    y = (radius * noise * ellipse * np.sin(a)[None]) + cy
    verts = np.stack([x, y, np.broadcast_to(z[:, None], x.shape)], axis=-1).reshape(-1, 3)
    faces = []
    for i in range(n_z - 1):
        for j in range(n_a):
            p, q = i * n_a + j, i * n_a + (j + 1) % n_a
            faces += [(p, q, q + n_a), (p, q + n_a, p + n_a)]
    top = len(verts)
    verts = np.vstack([verts, [[*axis(1.0)[:2], 1.0]]])
    faces += [((n_z - 1) * n_a + j, (n_z - 1) * n_a + (j + 1) % n_a, top) for j in range(n_a)]
    parts = [trimesh.Trimesh(verts, np.asarray(faces), process=False)]
    branches = int(rng.choice([0, 1, 2, 3], p=[0.25, 0.3, 0.3, 0.15]))
    for _ in range(branches):
        h = rng.uniform(0.75, 0.97)
        tilt, heading = np.radians(rng.uniform(30.0, 65.0)), rng.uniform(0.0, 2 * np.pi)
        length = rng.uniform(0.08, 0.3)
        *centre, r_here = axis(h)
        start = np.array([*centre, h])
        end = start + length * np.array([np.sin(tilt) * np.cos(heading), np.sin(tilt) * np.sin(heading), np.cos(tilt)])
        parts.append(trimesh.creation.cylinder(radius=r_here * rng.uniform(0.35, 0.7), segment=[start, end], sections=10))
    params = {"base_radius_ratio": float(r0), "flare": float(flare), "taper": float(taper), "ellipse": float(ellipse),
              "bend": [float(b) for b in bend], "branches": branches}  # fmt: skip
    return parts, params


def unit_trunk(rng: np.random.Generator) -> trimesh.Trimesh:
    """The stem of :func:`unit_parts` and its stubs as one mesh: height 1, standing on z = 0, open at the ground."""
    import trimesh

    return trimesh.util.concatenate(unit_parts(rng)[0])


def _closed_at_the_ground(stem: trimesh.Trimesh) -> trimesh.Trimesh:
    """``stem`` with a fan over its bottom ring (facing down), to the centre of that ring on z = 0."""
    import trimesh

    centre = len(stem.vertices)
    j = np.arange(SECTORS)
    fan = np.stack([np.full(SECTORS, centre), (j + 1) % SECTORS, j], axis=1)
    verts = np.vstack([stem.vertices, [[0.0, 0.0, 0.0]]])  # the stem's axis starts at the origin (no bend at t = 0)
    return trimesh.Trimesh(verts, np.vstack([stem.faces, fan]), process=False)


def parts(rng: np.random.Generator) -> tuple[dict[str, list[trimesh.Trimesh]], dict[str, Any]]:
    """A trunk in real size: the unit stem (:func:`unit_parts`), closed at the ground, scaled to a drawn height.

    Returns
    -------
    parts : dict
        ``"stem"``: one closed mesh; ``"branch"``: 0 to 3 closed stubs.  Metres, z up, on z = 0.
    params : dict
        ``height_m`` (the stem's; a stub may reach a little higher) and the unit stem's draws.
    """
    unit, params = unit_parts(rng)
    height = float(rng.uniform(*RANGES["height_m"]))
    pieces = [_closed_at_the_ground(unit[0]), *unit[1:]]
    for m in pieces:
        m.apply_scale(height)
    return {"stem": pieces[:1], "branch": pieces[1:]}, {"height_m": height, **params}


def make(rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """One trunk (:func:`parts`) as one mesh, and its parameters."""
    pieces, params = parts(rng)
    return assemble(pieces), params
