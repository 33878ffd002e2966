"""Street lights: a tapered steel column, one or two arms rising outward, a luminaire head on each.

Arms point along +x (and -x for a double-armed column).  Every part is closed.  The arms make the
object as wide as real ones: aerial crops of real street lights and utility poles measure a median
of about 4 m across for 11 m height.

Ranges
------
* ``height_m`` 4-12 m: the nominal heights of lighting columns in EN 40-1 (lighting columns,
  definitions and terms) and the usual mounting heights of road lighting (typical: 4-6 m on
  residential streets, 8-12 m on main roads).
* ``outreach_m`` 0.5-3.0 m: the bracket projections of EN 40 columns (typical).
* ``rise_deg`` 0-15 degrees: typical upcast of an arm.
* ``base_diameter_m`` 0.14-0.25 m, ``top_diameter_m`` 0.06-0.10 m: typical tapered steel columns.
* ``head_length_m`` 0.4-0.8 m, ``head_width_m`` 0.2-0.35 m, ``head_depth_m`` 0.08-0.15 m: typical
  road luminaires (cobra head, LED).
* two arms on 30 % of columns (typical of a median).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.mesh.families.parts import assemble, frustum, plate, rod

if TYPE_CHECKING:
    import trimesh  # imported where used: a parser that lists the families loads no trimesh

__all__ = ["CLASS_NAME", "NAME", "OPEN_PARTS", "RANGES", "make", "parts"]

NAME = "street_light"
CLASS_NAME = "pole"
#: Drawn parameters and their ranges (module docstring for the sources).
RANGES = {"height_m": (4.0, 12.0), "outreach_m": (0.5, 3.0), "rise_deg": (0.0, 15.0), "base_diameter_m": (0.14, 0.25),
          "top_diameter_m": (0.06, 0.10), "head_length_m": (0.4, 0.8), "head_width_m": (0.2, 0.35),
          "head_depth_m": (0.08, 0.15), "arm_radius_m": (0.03, 0.05), "arms": (1, 2)}  # fmt: skip
#: Share of columns with two opposite arms.
DOUBLE_ARM_SHARE = 0.3
#: Distance below the column top where an arm leaves it, metres.
ARM_DROP_M = 0.25
#: Every part is closed.
OPEN_PARTS: frozenset[str] = frozenset()


def parts(rng: np.random.Generator) -> tuple[dict[str, list[trimesh.Trimesh]], dict[str, Any]]:
    """One street light in real size (metres, z up, on z = 0; arms along x).

    Returns
    -------
    parts : dict
        ``"column"`` (closed frustum), ``"arm"`` (closed cylinders), ``"head"`` (closed boxes).
    params : dict
        The drawn ``RANGES`` keys.
    """
    keys = ("height_m", "outreach_m", "rise_deg", "base_diameter_m", "top_diameter_m", "head_length_m",
            "head_width_m", "head_depth_m", "arm_radius_m")  # fmt: skip
    p: dict[str, Any] = {k: float(rng.uniform(*RANGES[k])) for k in keys}
    p["arms"] = 2 if rng.random() < DOUBLE_ARM_SHARE else 1
    column = frustum(p["height_m"], 0.5 * p["base_diameter_m"], 0.5 * p["top_diameter_m"])
    arms, heads = [], []
    for side in (1.0, -1.0)[: p["arms"]]:
        start = np.array([0.0, 0.0, p["height_m"] - ARM_DROP_M])
        end = start + [side * p["outreach_m"], 0.0, p["outreach_m"] * np.tan(np.radians(p["rise_deg"]))]
        arms.append(rod(start, end, p["arm_radius_m"], sections=12))
        length, depth = p["head_length_m"], p["head_depth_m"]
        centre = end + [side * (0.5 * length - p["arm_radius_m"]), 0.0, -0.5 * depth]  # the head hangs from the arm's end
        heads.append(plate((length, p["head_width_m"], depth), centre))
    return {"column": [column], "arm": arms, "head": heads}, p


def make(rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """One street light (:func:`parts`) as one mesh, and its parameters."""
    pieces, params = parts(rng)
    return assemble(pieces), params
