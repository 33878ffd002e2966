"""Pedestrians: a body of capsules, an ellipsoid head and an elliptic torso, standing or walking, with or
without a coat, a backpack or a shoulder bag.

The street meshes hold six people, one of them in a T-pose; a classifier trained on them sees
few builds and gaits.  The body's joints stand where the segment lengths of Drillis & Contini put
them, as fractions of the stature ``H`` (D. A. Winter, *Biomechanics and Motor Control of Human
Movement*, 4th ed., Wiley 2009, Fig. 4.1): shoulder joint 0.818 H, hip joint 0.530 H, knee
0.285 H, ankle 0.039 H, chin 0.870 H; shoulder breadth 0.259 H, hip breadth 0.191 H; upper arm
0.186 H, forearm 0.146 H, hand 0.108 H; foot 0.152 H long and 0.055 H wide.  The person walks
along +x; a walking leg swings as ``hip = stride sin(2 pi phase)`` with the knee bending while the
leg swings forward (up to 2.4 times the stride), the arms swing against the legs.  Seen from the
front, each leg runs straight from its hip joint to an ankle half the step width from the midline:
walkers place their feet far closer together than their hips.

Ranges
------
* ``height_m`` 1.5-1.95 m: adult stature, about the 3rd percentile of women to the 97th of men
  across countries (NCD Risk Factor Collaboration, eLife 5:e13410, 2016), as
  :data:`zbuf_occlude.mesh.sizes.CLASS_SIZES_M`.
* ``build`` 0.85-1.25: girth (breadths, depths, limb radii) against the proportions above; the
  5th-95th percentile spread of chest and hip breadth in ANSUR II (Gordon et al., US Army
  NSRDEC TR-15/007, 2014) is about ±15 % around the mean (typical).
* ``depth_ratio`` 0.12-0.16: torso depth / stature (ANSUR II chest depth, typical).
* ``stride_deg`` 0-25 degrees: hip flexion amplitude; 0 stands, about 20-25 walks at a normal pace
  (hip 30 degrees flexion to 10 extension, knee up to 60 degrees in swing: J. Perry and
  J. M. Burnfield, *Gait Analysis*, 2nd ed., 2010).
* ``phase`` 0-1: the moment of the gait cycle.
* ``step_width_m``, the distance across the walk between the ankles' centres: walking, 0.08-0.16 of the
  leg length (the metabolic optimum 0.12 of it lies near the width walkers prefer: J. M. Donelan,
  R. Kram and A. D. Kuo, Proc. R. Soc. B 268:1985-1992, 2001); standing, 0.09-0.24 m (the natural
  stance's 16.5 +- 3.8 cm, mean +- 2 SD: Bio-Medical Materials and Engineering, "Feet distance and
  static postural balance").
* ``arm_swing_deg`` 0-30 and ``elbow_deg`` 0-45 degrees: arm swing and elbow flexion of walking
  adults (typical).
* ``coat`` 0/1: a coat or skirt to ``hem_ratio`` 0.25-0.45 of the stature on 25 % of people.
* ``clothing_m`` 0.005-0.04 m: the thickness of what the upper body wears, over the torso, the arms
  and the neck (a shirt to a padded jacket), and ``hair_m`` 0-0.06 m on each side of the head (hair,
  a cap or a hood): typical values, set so that the family's HDL-32E crops at 3-8 m are as broad
  across the line of sight at the chest as the first half of the LiDARNet v2 pedestrians (median
  0.46 m against 0.44 m, 0.3-0.6 m below the top; 0.38 m bare).  Their heads stay narrower (0.17 m
  against 0.22 m over the top 0.2 m).  The legs are bare.
* ``carry`` 0/1/2: nothing, a backpack (0.28-0.35 wide, 0.35-0.50 tall, 0.12-0.25 m deep: typical
  day packs), or a shoulder bag at the hip (0.25-0.40 x 0.08-0.15 x 0.20-0.30 m), on 25 % each.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.mesh.families.parts import capsule, ellipsoid, frustum, plate

if TYPE_CHECKING:
    import trimesh  # imported where used: a parser that lists the families loads no trimesh

__all__ = ["CLASS_NAME", "NAME", "OPEN_PARTS", "PROPORTIONS", "RANGES", "parts"]

NAME = "pedestrian"
CLASS_NAME = "pedestrian"
#: Drawn parameters and their ranges (module docstring for the sources).
RANGES = {"height_m": (1.5, 1.95), "build": (0.85, 1.25), "depth_ratio": (0.12, 0.16), "stride_deg": (0.0, 25.0),
          "phase": (0.0, 1.0), "arm_swing_deg": (0.0, 30.0), "elbow_deg": (0.0, 45.0), "coat": (0, 1),
          "hem_ratio": (0.25, 0.45), "carry": (0, 2), "step_width_m": (0.06, 0.24), "clothing_m": (0.005, 0.04),
          "hair_m": (0.0, 0.06)}  # fmt: skip
#: Joint heights, breadths and segment lengths as fractions of the stature (Winter 2009, Fig. 4.1).
PROPORTIONS = {"shoulder_z": 0.818, "hip_z": 0.530, "knee_z": 0.285, "ankle_z": 0.039, "chin_z": 0.870,
               "shoulder_breadth": 0.259, "hip_breadth": 0.191, "upper_arm": 0.186, "forearm": 0.146, "hand": 0.108,
               "foot_length": 0.152, "foot_width": 0.055}  # fmt: skip
#: Limb radii as fractions of the stature at a build of 1 (typical girths).
RADII = {"upper_arm": 0.027, "forearm": 0.021, "thigh": 0.045, "shank": 0.030, "neck": 0.033}
#: Share of people walking rather than standing still (a stride below 3 degrees).
STANDING_SHARE = 0.3
#: A walker's step width as fractions of the leg length (the hip joint's height; Donelan et al. 2001), and a
#: standing person's in metres: together within ``RANGES["step_width_m"]`` at every drawn stature.
WALKING_STEP_WIDTH, STANDING_STEP_WIDTH_M = (0.08, 0.16), (0.09, 0.24)
#: Share with a coat or skirt; share with a backpack, and with a shoulder bag.
COAT_SHARE, BACKPACK_SHARE, BAG_SHARE = 0.25, 0.25, 0.25
#: Every part is closed.
OPEN_PARTS: frozenset[str] = frozenset()


def _direction(angle_deg: float) -> np.ndarray:
    """A unit vector in the x-z plane ``angle_deg`` forward (+x) of straight down."""
    a = np.radians(angle_deg)
    return np.array([np.sin(a), 0.0, -np.cos(a)])


def _draw(rng: np.random.Generator) -> dict[str, Any]:
    p: dict[str, Any] = {k: float(rng.uniform(*RANGES[k])) for k in ("height_m", "build", "depth_ratio", "phase", "hem_ratio")}
    walking = rng.random() >= STANDING_SHARE
    p["stride_deg"] = float(rng.uniform(10.0, RANGES["stride_deg"][1]) if walking else rng.uniform(0.0, 3.0))
    p["arm_swing_deg"] = float(rng.uniform(0.3, 1.2) * p["stride_deg"]) if walking else float(rng.uniform(0.0, 5.0))
    leg_length = PROPORTIONS["hip_z"] * p["height_m"]
    p["step_width_m"] = float(rng.uniform(*WALKING_STEP_WIDTH) * leg_length if walking else rng.uniform(*STANDING_STEP_WIDTH_M))
    p["elbow_deg"] = float(rng.uniform(*RANGES["elbow_deg"]))
    p["coat"] = int(rng.random() < COAT_SHARE)
    u = rng.random()
    p["carry"] = 1 if u < BACKPACK_SHARE else 2 if u < BACKPACK_SHARE + BAG_SHARE else 0
    p["carried_m"] = [float(v) for v in (rng.uniform((0.28, 0.35, 0.12), (0.35, 0.50, 0.25)) if p["carry"] == 1
                                         else rng.uniform((0.25, 0.20, 0.08), (0.40, 0.30, 0.15)))]  # fmt: skip
    p["clothing_m"], p["hair_m"] = (float(rng.uniform(*RANGES[k])) for k in ("clothing_m", "hair_m"))
    return p


def parts(rng: np.random.Generator) -> tuple[dict[str, list[trimesh.Trimesh]], dict[str, Any]]:
    """One pedestrian in real size (metres, z up, the lower foot on z = 0, walking along +x).

    Returns
    -------
    parts : dict
        ``"head"``, ``"neck"``, ``"torso"`` (closed ellipsoid, capsule, elliptic frustum), ``"arm"`` and
        ``"leg"`` (closed capsules, two segments each), ``"foot"`` (closed boxes), ``"coat"`` (a closed
        frustum or none) and ``"carried"`` (a closed box or none).
    params : dict
        The drawn ``RANGES`` keys, and ``carried_m`` (width, height, depth of what is carried).
    """
    p = _draw(rng)
    h, b, f = p["height_m"], p["build"], PROPORTIONS
    half_depth = 0.5 * p["depth_ratio"] * h * b
    r = {k: v * h * b for k, v in RADII.items()}
    cloth = p["clothing_m"]
    hip_y, shoulder_y = 0.055 * h * b, 0.5 * f["shoulder_breadth"] * h * b - r["upper_arm"]
    sin_phase, cos_phase = np.sin(2 * np.pi * p["phase"]), np.cos(2 * np.pi * p["phase"])
    swing = p["stride_deg"] * sin_phase

    legs, feet = [], []
    for side, hip_angle in ((1.0, swing), (-1.0, -swing)):
        forward = cos_phase * side > 0  # this leg's hip angle is growing: it swings forward
        knee_flex = 2.4 * p["stride_deg"] * abs(cos_phase) if forward else 0.0
        hip = np.array([0.0, side * hip_y, f["hip_z"] * h])
        knee = hip + (f["hip_z"] - f["knee_z"]) * h * _direction(hip_angle)
        ankle = knee + (f["knee_z"] - f["ankle_z"]) * h * _direction(hip_angle - knee_flex)
        # seen from the front the leg is straight, from the hip joint to an ankle half a step width out
        across = side * 0.5 * p["step_width_m"] - hip[1]
        knee[1] += across * (f["hip_z"] - f["knee_z"]) / (f["hip_z"] - f["ankle_z"])
        ankle[1] += across
        legs += [capsule(hip, knee, r["thigh"]), capsule(knee, ankle, r["shank"])]
        foot_h = f["ankle_z"] * h
        feet.append(plate((f["foot_length"] * h, f["foot_width"] * h * b, foot_h),
                          ankle + [0.25 * f["foot_length"] * h, 0.0, -0.5 * foot_h]))  # fmt: skip
    arms = []
    for side, arm_angle in ((1.0, -p["arm_swing_deg"] * sin_phase), (-1.0, p["arm_swing_deg"] * sin_phase)):
        shoulder = np.array([0.0, side * (shoulder_y + cloth), f["shoulder_z"] * h - r["upper_arm"]])
        elbow = shoulder + f["upper_arm"] * h * _direction(arm_angle)
        wrist = elbow + (f["forearm"] + 0.5 * f["hand"]) * h * _direction(arm_angle + p["elbow_deg"])
        arms += [capsule(shoulder, elbow, r["upper_arm"] + cloth), capsule(elbow, wrist, r["forearm"] + cloth)]

    torso_bottom = f["hip_z"] * h - r["thigh"]
    torso_top = f["shoulder_z"] * h + 0.5 * r["neck"]
    half_hips, half_chest = 0.5 * f["hip_breadth"] * h * b, shoulder_y - 0.5 * r["upper_arm"]
    torso = frustum(torso_top - torso_bottom, half_hips + cloth, half_chest + cloth)
    # elliptic: as deep as drawn, as broad as the body, both in their clothes
    torso.vertices[:, 0] *= (half_depth + cloth) / (max(half_hips, half_chest) + cloth)
    torso.apply_translation([0.0, 0.0, torso_bottom])
    chin = f["chin_z"] * h
    head_half_height = 0.5 * (1.0 - f["chin_z"]) * h
    hair = p["hair_m"]
    head = ellipsoid([0.01 * h, 0.0, chin + head_half_height], [0.056 * h + hair, 0.044 * h + hair, head_half_height])
    neck = capsule([0.0, 0.0, f["shoulder_z"] * h], [0.0, 0.0, chin + 0.3 * head_half_height], r["neck"] + cloth)

    coat, carried = [], []
    if p["coat"]:
        hem = p["hem_ratio"] * h
        skirt = frustum(torso_bottom + 0.15 * h - hem, 1.3 * half_hips, 1.05 * half_hips)
        skirt.vertices[:, 0] *= 1.1 * half_depth / half_hips
        coat.append(skirt.apply_translation([0.0, 0.0, hem]))
    width, height, depth = p["carried_m"]
    if p["carry"] == 1:  # on the back, below the shoulders
        carried.append(plate((depth, width, height), [-(half_depth + cloth + 0.5 * depth), 0.0, f["shoulder_z"] * h - 0.6 * height]))
    elif p["carry"] == 2:  # hanging at the hip on the right side, outside the arm
        carried.append(plate((width, depth, height), [0.0, -(shoulder_y + r["upper_arm"] + 2 * cloth + 0.5 * depth), f["hip_z"] * h]))

    pieces = {"head": [head], "neck": [neck], "torso": [torso], "arm": arms, "leg": legs, "foot": feet, "coat": coat,
              "carried": carried}  # fmt: skip
    ground = min(float(m.vertices[:, 2].min()) for group in pieces.values() for m in group)
    for group in pieces.values():
        for m in group:
            m.apply_translation([0.0, 0.0, -ground])
    return pieces, p
