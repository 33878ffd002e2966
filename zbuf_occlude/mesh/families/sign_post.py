"""Sign posts: a steel post carrying one to three plates stacked above each other.

Plates face -y and hang in front of the post; shapes: rectangle, square, disc, octagon (a stop
sign) and diamond (a warning sign).  Every part is closed (plates are thin boxes or prisms).

Ranges
------
* ``bottom_m`` 1.5-2.5 m, the height of the lowest plate's bottom edge: MUTCD (FHWA, Manual on
  Uniform Traffic Control Devices) Section 2A.18 asks at least 5 ft (1.5 m) in rural districts and
  7 ft (2.1 m) where there is parking or pedestrian activity.
* ``plate`` widths 0.45-0.9 m (18-36 in): the conventional-road sizes of MUTCD Table 2B-1
  (e.g. a stop sign 30 in, a speed limit sign 24 x 30 in); heights 0.6-1.4 times the width for
  rectangles; 3-5 mm thick (typical aluminium sign blanks, drawn as 4 mm).
* ``plates`` 1-3 per post, 0.03-0.15 m apart (typical).
* ``post_width_m`` 0.05-0.076 m (2-3 in): typical square steel tube and round pipe posts.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.mesh.families.parts import assemble, frustum, plate

if TYPE_CHECKING:
    import trimesh  # imported where used: a parser that lists the families loads no trimesh

__all__ = ["CLASS_NAME", "NAME", "OPEN_PARTS", "PLATE_SHAPES", "RANGES", "make", "parts"]

NAME = "sign_post"
CLASS_NAME = "pole"
#: Drawn parameters and their ranges (module docstring for the sources); per plate: width, gap.
RANGES = {"bottom_m": (1.5, 2.5), "plates": (1, 3), "plate_width_m": (0.45, 0.9), "plate_gap_m": (0.03, 0.15),
          "post_width_m": (0.05, 0.076), "post_above_m": (0.0, 0.1)}  # fmt: skip
#: Plate shapes, drawn with equal chance.
PLATE_SHAPES = ("rectangle", "square", "disc", "octagon", "diamond")
#: Plate thickness, metres (typical aluminium sign blanks are 2-3 mm; 4 mm keeps the box well formed).
PLATE_THICKNESS_M = 0.004
#: Share of round pipe posts (the others square tubes).
ROUND_POST_SHARE = 0.5
#: A rectangle's height over its width (typical of MUTCD regulatory and guide plates).
RECTANGLE_ASPECT = (0.6, 1.4)
#: Every part is closed.
OPEN_PARTS: frozenset[str] = frozenset()


def _plate(shape: str, width: float, height: float, centre: np.ndarray) -> trimesh.Trimesh:
    """A plate of ``shape``, ``width`` x ``height`` metres in the x-z plane, centred at ``centre``."""
    import trimesh

    if shape in ("rectangle", "square"):
        return plate((width, PLATE_THICKNESS_M, height), centre)
    if shape == "diamond":  # a square turned 45 degrees, as wide as ``width`` across its corners
        side = width / np.sqrt(2.0)
        return plate((side, PLATE_THICKNESS_M, side), centre, roll_deg=45.0)
    sections = 32 if shape == "disc" else 8
    # an octagon's width is across its flats (a 30 in stop sign), its radius to the corners
    radius = 0.5 * width if shape == "disc" else 0.5 * width / np.cos(np.pi / 8)
    prism = trimesh.creation.cylinder(radius=radius, height=PLATE_THICKNESS_M, sections=sections)
    turn = trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])  # its axis from z to y: the plate faces y
    if shape == "octagon":  # a flat top, as a stop sign stands
        turn = turn @ trimesh.transformations.rotation_matrix(np.pi / 8, [0, 0, 1])
    prism.apply_transform(trimesh.transformations.translation_matrix(centre) @ turn)
    return prism


def parts(rng: np.random.Generator) -> tuple[dict[str, list[trimesh.Trimesh]], dict[str, Any]]:
    """One sign post in real size (metres, z up, on z = 0; plates face -y).

    Returns
    -------
    parts : dict
        ``"post"`` (a closed square tube or round pipe), ``"plate"`` (closed, one per plate).
    params : dict
        ``bottom_m``, ``post_width_m``, ``post_above_m``, ``round_post``, and ``plates``: a list of
        ``{"shape", "width_m", "height_m", "gap_m"}`` bottom to top.
    """
    bottom = float(rng.uniform(*RANGES["bottom_m"]))
    post_w = float(rng.uniform(*RANGES["post_width_m"]))
    round_post = bool(rng.random() < ROUND_POST_SHARE)
    n = int(rng.integers(RANGES["plates"][0], RANGES["plates"][1] + 1))
    plates, drawn, z = [], [], bottom
    for _ in range(n):
        shape = PLATE_SHAPES[int(rng.integers(len(PLATE_SHAPES)))]
        width = float(rng.uniform(*RANGES["plate_width_m"]))
        height = width * float(rng.uniform(*RECTANGLE_ASPECT)) if shape == "rectangle" else width
        gap = float(rng.uniform(*RANGES["plate_gap_m"]))
        centre = np.array([0.0, -(0.5 * post_w + 0.5 * PLATE_THICKNESS_M), z + 0.5 * height])
        plates.append(_plate(shape, width, height, centre))
        drawn.append({"shape": shape, "width_m": width, "height_m": height, "gap_m": gap})
        z += height + gap
    top = z - drawn[-1]["gap_m"]  # the top plate's top edge
    above = float(rng.uniform(*RANGES["post_above_m"]))
    if round_post:
        post = frustum(top + above, 0.5 * post_w, 0.5 * post_w)
    else:
        post = plate((post_w, post_w, top + above), (0.0, 0.0, 0.5 * (top + above)))
    params = {"bottom_m": bottom, "post_width_m": post_w, "post_above_m": above, "round_post": round_post, "plates": drawn}
    return {"post": [post], "plate": plates}, params


def make(rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """One sign post (:func:`parts`) as one mesh, and its parameters."""
    pieces, params = parts(rng)
    return assemble(pieces), params
