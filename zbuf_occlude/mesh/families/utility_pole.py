"""Utility poles: a tapered wood pole, one to three crossarms, pin insulators and short wire spans.

Crossarms run along x, the line (the wires) along y.  The wires are deliberately short and open
(:func:`~zbuf_occlude.mesh.families.parts.open_tube`: thin tubes without caps, cut where a crop of
the pole would end); every other part is closed.  Crossarms and wires make the pole as wide as
real ones: aerial crops of real utility poles measure a median of about 4 m across for 11 m height.

Ranges
------
* ``height_m`` 8-14 m above ground: ANSI O5.1 wood poles of the common distribution lengths
  (30-50 ft) set about 10 % + 0.6 m deep (typical practice).
* ``top_diameter_m`` 0.15-0.22 m: ANSI O5.1 minimum top circumferences of classes 5 to 1
  (19-27 in); ``ground_diameter_m`` 0.24-0.38 m (typical for those classes at the ground line).
* ``crossarm_length_m`` 2.44-3.05 m (8 and 10 ft) and a section of 92 x 117 mm (3-5/8 x 4-5/8 in):
  USDA RUS Bulletin 1728H-701, wood crossarms; ``crossarms`` 1-3, 0.6-1.2 m apart (typical).
* ``insulators`` 2-4 per crossarm, 0.12-0.25 m tall (typical pin and post insulators of 15-35 kV lines).
* ``wire_span_m`` 1-3 m each side of the pole, in 75 % of poles (else none), wires 6-15 mm in radius
  (typical conductors with ice-free clearance; kept short so the object stays one pole).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.mesh.families.parts import assemble, frustum, open_tube, plate, rod

if TYPE_CHECKING:
    import trimesh  # imported where used: a parser that lists the families loads no trimesh

__all__ = ["CLASS_NAME", "NAME", "OPEN_PARTS", "RANGES", "make", "parts"]

NAME = "utility_pole"
CLASS_NAME = "pole"
#: Drawn parameters and their ranges (module docstring for the sources).
RANGES = {"height_m": (8.0, 14.0), "top_diameter_m": (0.15, 0.22), "ground_diameter_m": (0.24, 0.38),
          "crossarm_length_m": (2.44, 3.05), "crossarms": (1, 3), "crossarm_spacing_m": (0.6, 1.2),
          "insulators": (2, 4), "insulator_height_m": (0.12, 0.25), "wire_span_m": (0.0, 3.0),
          "wire_radius_m": (0.006, 0.015)}  # fmt: skip
#: Wood crossarm section, metres (3-5/8 x 4-5/8 in, RUS Bulletin 1728H-701): width (along y) x depth (z).
CROSSARM_SECTION_M = (0.092, 0.117)
#: Share of poles drawn with wires.
WIRE_SHARE = 0.75
#: A wired pole's span each side, metres (``wire_span_m`` is 0 on a pole without wires).
WIRED_SPAN_M = (1.0, 3.0)
#: Radius of a pin insulator's body, metres (typical porcelain and polymer pins, 0.1-0.15 m across).
INSULATOR_RADIUS_M = 0.06
#: Distance of the outer insulators from a crossarm's ends, metres (typical).
END_CLEARANCE_M = 0.1
#: Distance of the top crossarm's centre below the pole top, metres (typical).
TOP_ARM_DROP_M = (0.2, 0.4)
#: The wires are open tubes; everything else is closed.
OPEN_PARTS = frozenset({"wire"})


def parts(rng: np.random.Generator) -> tuple[dict[str, list[trimesh.Trimesh]], dict[str, Any]]:
    """One utility pole in real size (metres, z up, on z = 0; crossarms along x, wires along y).

    Returns
    -------
    parts : dict
        ``"pole"`` (closed frustum), ``"crossarm"`` (closed boxes), ``"insulator"`` (closed
        cylinders), ``"wire"`` (open tubes; none in a quarter of poles).
    params : dict
        The drawn ``RANGES`` keys.
    """
    u = lambda key: float(rng.uniform(*RANGES[key]))  # noqa: E731
    height, top_d, ground_d = u("height_m"), u("top_diameter_m"), u("ground_diameter_m")
    length, spacing = u("crossarm_length_m"), u("crossarm_spacing_m")
    crossarms = int(rng.integers(RANGES["crossarms"][0], RANGES["crossarms"][1] + 1))
    insulators = int(rng.integers(RANGES["insulators"][0], RANGES["insulators"][1] + 1))
    insulator_h = u("insulator_height_m")
    wired = bool(rng.random() < WIRE_SHARE)
    span = float(rng.uniform(*WIRED_SPAN_M)) if wired else 0.0
    wire_r = u("wire_radius_m")
    width, depth = CROSSARM_SECTION_M
    arms, pins, wires = [], [], []
    first = height - rng.uniform(*TOP_ARM_DROP_M)
    xs = np.linspace(-0.5 * length + END_CLEARANCE_M, 0.5 * length - END_CLEARANCE_M, insulators)
    for k in range(crossarms):
        z = first - k * spacing
        arms.append(plate((length, width, depth), (0.0, 0.0, z)))
        for x in xs:
            base = np.array([x, 0.0, z + 0.5 * depth])
            pins.append(rod(base, base + [0.0, 0.0, insulator_h], radius=INSULATOR_RADIUS_M, sections=12))
            if wired:
                tip = base + [0.0, 0.0, insulator_h]
                wires.append(open_tube(tip - [0.0, span, 0.0], tip + [0.0, span, 0.0], wire_r))
    pole = frustum(height, 0.5 * ground_d, 0.5 * top_d)
    params = {"height_m": height, "top_diameter_m": top_d, "ground_diameter_m": ground_d, "crossarm_length_m": length,
              "crossarms": crossarms, "crossarm_spacing_m": spacing, "insulators": insulators,
              "insulator_height_m": insulator_h, "wire_span_m": span, "wire_radius_m": wire_r}  # fmt: skip
    return {"pole": [pole], "crossarm": arms, "insulator": pins, "wire": wires}, params


def make(rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """One utility pole (:func:`parts`) as one mesh, and its parameters."""
    pieces, params = parts(rng)
    return assemble(pieces), params
