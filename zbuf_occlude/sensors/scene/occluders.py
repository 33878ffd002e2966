"""Occluders that a crop's scene stands between the sensor and its object: thin upright panels that hide one side
of it (:func:`side_occluders`), as a street's parked cars and walls do.  :func:`~zbuf_occlude.sensors.crops.object_crop`
adds them where its placement leaves a share of the object's angular width visible."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.scene.objects import SceneObject

__all__ = ["SIDE_OCCLUDER_RANGE", "side_occluders"]

#: A side occluder stands at this share of the distance to the object's nearest vertex.
SIDE_OCCLUDER_RANGE = 0.5
#: It hides this share of the object's angular width more than asked, on the outer side, and stands
#: this many metres taller than the sensor and the object's top: every ray to the hidden side ends on it.
_SIDE_OCCLUDER_MARGIN = 0.05
_SIDE_OCCLUDER_RISE_M = 0.5
_SIDE_OCCLUDER_DEPTH_M = 0.05
#: Widest azimuth one flat panel covers, degrees; a wider hidden sector takes several side by side.
_SIDE_PANEL_DEG = 60.0


def side_occluders(world_vertices: NDArray[np.floating], sensor_m, visible: float, side: float) -> list[SceneObject]:
    """Thin upright panels between the sensor and an object that hide one side of it.

    The object's vertices span azimuths ``[φ_lo, φ_hi]`` seen from the sensor; the panels cover
    ``[φ_hi − (1 − visible)·Δφ, φ_hi]`` (``side`` > 0) or ``[φ_lo, φ_lo + (1 − visible)·Δφ]``
    (``side`` < 0), widened on the outer side by :data:`_SIDE_OCCLUDER_MARGIN`, each at most
    :data:`_SIDE_PANEL_DEG` wide, facing the sensor at :data:`SIDE_OCCLUDER_RANGE` of the
    horizontal distance to the nearest vertex, from the ground to 0.5 m above both the sensor
    and the object's top, so that each ray from the sensor to the hidden side ends on one.  A
    partial view as a street's parked cars and walls make it: the edge is vertical, and the
    object keeps its shape and size.

    Parameters
    ----------
    world_vertices : (V, 3) float
        The object's vertices, world frame (metres, z up, ground at its lowest vertex or below).
    sensor_m : (3,) float
        The sensor's centre, world frame.
    visible : float
        The share of the angular width left visible, in (0, 1).
    side : float
        > 0 hides the counter-clockwise side, < 0 the clockwise one.

    Returns
    -------
    list of SceneObject
        Box primitives (``box_m``: depth along the line of sight, width, height; metres); none
        where the object spans 170° of azimuth or more (the sensor inside its outline or
        against it): nothing stands between them.

    Raises
    ------
    InvalidInputError
        ``visible`` outside (0, 1).
    """
    if not 0.0 < visible < 1.0:
        raise InvalidInputError(f"the visible share of a side-occluded object must be in (0, 1), got {visible!r}")
    v = np.asarray(world_vertices, dtype=np.float64) - np.asarray(sensor_m, dtype=np.float64)
    centre = math.atan2(float(np.mean(v[:, 1])), float(np.mean(v[:, 0])))
    phi = (np.arctan2(v[:, 1], v[:, 0]) - centre + math.pi) % (2 * math.pi) - math.pi
    lo, hi = float(phi.min()), float(phi.max())
    near = float(np.hypot(v[:, 0], v[:, 1]).min())
    if not (hi - lo < math.radians(170.0) and near > 0):
        return []
    hidden, margin = (1.0 - visible) * (hi - lo), _SIDE_OCCLUDER_MARGIN * (hi - lo) + math.radians(0.5)
    a, b = (hi - hidden, hi + margin) if side > 0 else (lo - margin, lo + hidden)
    r = SIDE_OCCLUDER_RANGE * near
    height = max(float(np.max(v[:, 2])), 0.0) + float(sensor_m[2]) + _SIDE_OCCLUDER_RISE_M
    n = math.ceil((b - a) / math.radians(_SIDE_PANEL_DEG))
    out = []
    overlap = math.radians(0.5)  # neighbours overlap, so that no ray passes between them; the visible edge stays where asked
    for k in range(n):  # side by side, each facing the sensor
        a_k = a + (b - a) * k / n - (overlap if k > 0 else 0.0)
        b_k = a + (b - a) * (k + 1) / n + (overlap if k < n - 1 else 0.0)
        mid = centre + (a_k + b_k) / 2
        width = 2.0 * r * math.tan((b_k - a_k) / 2)
        reach = r + _SIDE_OCCLUDER_DEPTH_M / 2
        x, y = float(sensor_m[0]) + reach * math.cos(mid), float(sensor_m[1]) + reach * math.sin(mid)
        out.append(SceneObject({"box_m": [_SIDE_OCCLUDER_DEPTH_M, width, height]}, "occluder", (x, y), math.degrees(mid)))
    return out
