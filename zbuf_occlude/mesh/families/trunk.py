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
* the first limbs of a crown in :data:`LIMBED_SHARE` of trunks: a scanner that sees a street tree's trunk
  to its top beam often sees the crown's lowest limbs too, as street trees are pruned to a clearance of
  7-8 ft (2.1-2.4 m) over sidewalks (Vermillion, SD, Code of Ordinances § 90.79; City of Clive, IA, tree
  trimming rules; City of Folsom, CA, tree pruning for safety and clearance).  Two to four limbs leave the
  stem together at 0.55-0.85 of its height (2.1-2.4 m of stems 2.6-3.9 m tall, the real trunks' heights
  above), 20-40 degrees from the vertical, and end at the stem's top.  :data:`LIMBED_SHARE` is not a
  published figure: it is about the share of the sim-to-real fit half's real trunks that widen in the
  top third of their height (docs/results/families.md, "Trunks with their first limbs").
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.mesh.families.parts import assemble

if TYPE_CHECKING:
    import trimesh  # imported where used: a parser that lists the families loads no trimesh

__all__ = ["CLASS_NAME", "LIMBED_SHARE", "LIMB_START", "NAME", "OPEN_PARTS", "RANGES", "RINGS", "SECTORS", "make", "parts",
           "unit_parts", "unit_trunk"]  # fmt: skip

NAME = "trunk"
#: The class folder a trunk is written to: real scans label bare trunks as poles.
CLASS_NAME = "pole"
#: Drawn parameters and their ranges (module docstring for the sources).
RANGES = {"height_m": (2.0, 6.0), "base_radius_ratio": (0.02, 0.09)}
#: No open part: the stem is closed at the top and at the ground, the stubs are closed cylinders.
OPEN_PARTS: frozenset[str] = frozenset()
#: Rings up the stem and vertices per ring.
RINGS, SECTORS = 24, 18
#: Share of trunks drawn with the first limbs of their crown (module docstring).
LIMBED_SHARE = 0.3
#: Where the limbs leave the stem, as a share of its height (module docstring).
LIMB_START = (0.55, 0.85)
#: The limbs' angle from the vertical, degrees, and their number.
LIMB_TILT_DEG, LIMB_COUNT = (20.0, 40.0), (2, 4)


def _stem_axis(params: dict[str, Any], t: float | np.ndarray) -> tuple:
    """The unit stem's centre (x, y) and its radius without the flare at height ``t`` (0 to 1), from the draws of :func:`unit_parts`."""
    bend, r0, taper = params["bend"], params["base_radius_ratio"], params["taper"]
    return bend[0] * t**2, bend[1] * t**2, r0 * (1 - (1 - taper) * t)


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
    drawn = {"base_radius_ratio": float(r0), "taper": float(taper), "bend": [float(b) for b in bend]}

    def axis(t):
        return _stem_axis(drawn, t)

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


def _unit_limbs(rng: np.random.Generator, params: dict[str, Any]) -> tuple[list[trimesh.Trimesh], dict[str, Any]]:
    """The first limbs of a crown on the unit stem of ``params`` (:func:`unit_parts`' draws), in
    :data:`LIMBED_SHARE` of the draws: closed cylinders from one height of :data:`LIMB_START` on the stem's
    axis to the stem's top height, spread around it; none otherwise.

    Returns
    -------
    limbs : list of trimesh.Trimesh
        0 or 2 to 4 closed cylinders (height 1 is the stem's).
    params : dict
        ``limbs`` (their number) and, with limbs, ``limb_start`` (the share of the height they leave the stem at).
    """
    import trimesh

    if rng.random() >= LIMBED_SHARE:
        return [], {"limbs": 0}
    n = int(rng.integers(LIMB_COUNT[0], LIMB_COUNT[1] + 1))
    start = float(rng.uniform(*LIMB_START))
    *centre, r_here = _stem_axis(params, start)
    tilt = np.radians(rng.uniform(*LIMB_TILT_DEG, n))
    heading = rng.uniform(0.0, 2 * np.pi) + 2 * np.pi * np.arange(n) / n + rng.uniform(-0.3, 0.3, n)
    radius = r_here * rng.uniform(0.45, 0.7, n)
    origin = np.array([*centre, start])
    limbs = []
    for k in range(n):
        reach = (1.0 - start) * np.tan(tilt[k])
        end = origin + np.array([reach * np.cos(heading[k]), reach * np.sin(heading[k]), 1.0 - start])
        end[2] -= radius[k]  # the end cap's rim rises up to a radius above its centre
        limbs.append(trimesh.creation.cylinder(radius=float(radius[k]), segment=[origin, end], sections=10))
    return limbs, {"limbs": n, "limb_start": start}


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
        ``"stem"``: one closed mesh; ``"branch"``: 0 to 3 closed stubs; ``"limb"``: 0 or 2 to 4 closed limbs
        (:func:`_unit_limbs`).  Metres, z up, on z = 0.
    params : dict
        ``height_m`` (the stem's; a stub may reach a little higher, a limb does not), the unit stem's draws and
        the limbs' (``limbs``, and ``limb_start`` where there are limbs).
    """
    unit, params = unit_parts(rng)
    height = float(rng.uniform(*RANGES["height_m"]))
    limbs, limb_params = _unit_limbs(rng, params)  # drawn after the height: the stem and its stubs are those of the draws before
    pieces = [_closed_at_the_ground(unit[0]), *unit[1:], *limbs]
    for m in pieces:
        m.apply_scale(height)
    n_stubs = len(unit) - 1
    named = {"stem": pieces[:1], "branch": pieces[1 : 1 + n_stubs], "limb": pieces[1 + n_stubs :]}
    return named, {"height_m": height, **params, **limb_params}


def make(rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """One trunk (:func:`parts`) as one mesh, and its parameters."""
    pieces, params = parts(rng)
    return assemble(pieces), params
