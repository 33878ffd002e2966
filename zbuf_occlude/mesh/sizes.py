"""Real sizes of street objects, metres: what a mesh is scaled to before a LiDAR scans it.

Mesh files come in centimetres, inches, metres or no unit at all, and the paper's
normalisation (max extent 1) throws the size away.  A LiDAR scan depends on it (ring spacing
and point count grow with size over range), so the sensor path scales every object to a real
size drawn per sample, uniformly from its class's range in :data:`CLASS_SIZES_M`.  One
dimension is drawn (a car's *length*, a pole's *height*); the mesh keeps its proportions.

Sources of the default ranges (all overridable with :func:`parse_sizes`):

* **car, length 3.6–5.2 m**: small city cars to large saloons and SUVs (European segments A
  to E/J); the mean KITTI car is 3.9 m long, the VoxelNet anchor (Zhou & Tuzel, CVPR 2018,
  §3.1: l = 3.9, w = 1.6, h = 1.56 m).
* **pedestrian, height 1.5–1.95 m**: adult stature, about the 3rd percentile of women to the
  97th of men across countries (NCD Risk Factor Collaboration, "A century of trends in adult
  human height", eLife 5:e13410, 2016); VoxelNet's pedestrian anchor is 1.73 m.
* **pole, height 2.5–9 m**: sign posts (about 2.5–3.5 m to the top of the sign) to street
  lighting columns (EN 40-1 nominal heights 3–10 m; 4–8 m on residential streets) and
  utility poles' lower spans.
* **bush, height 0.4–2.5 m**: low vegetation, shrubs and hedges (taller is a tree).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from zbuf_occlude.errors import InvalidInputError

__all__ = ["SizeRange", "CLASS_SIZES_M", "DIMENSIONS", "parse_sizes", "dimension_extent", "size_interval"]

#: What a size range measures: ``length`` = the larger horizontal side, ``height`` = z, ``max`` = the largest side.
DIMENSIONS = ("length", "height", "max")


@dataclass(frozen=True)
class SizeRange:
    """A class's real size: ``dimension`` drawn uniformly in ``[lo_m, hi_m]`` metres."""

    dimension: str
    lo_m: float
    hi_m: float

    def __post_init__(self) -> None:
        if self.dimension not in DIMENSIONS:
            raise InvalidInputError(f"size dimension must be one of {DIMENSIONS}, got {self.dimension!r}")
        if not (np.isfinite(self.lo_m) and np.isfinite(self.hi_m) and 0 < self.lo_m <= self.hi_m):
            raise InvalidInputError(f"size range needs 0 < lo <= hi metres, got {self.lo_m}–{self.hi_m}")


#: Default real sizes per class (module docstring for the sources).
CLASS_SIZES_M: dict[str, SizeRange] = {
    "car": SizeRange("length", 3.6, 5.2),
    "pedestrian": SizeRange("height", 1.5, 1.95),
    "pole": SizeRange("height", 2.5, 9.0),
    "bush": SizeRange("height", 0.4, 2.5),
}


def parse_sizes(text: str | None, base: Mapping[str, SizeRange] = CLASS_SIZES_M) -> dict[str, SizeRange]:
    """``CLASS=DIMENSION:LO-HI,...`` (e.g. ``car=length:3.5-5,tree=height:4-20``) over ``base``.

    Raises
    ------
    InvalidInputError
        An item that is not ``CLASS=DIMENSION:LO-HI`` with numbers, naming it.
    """
    out = dict(base)
    for item in (text or "").split(","):
        if not item.strip():
            continue
        try:
            name, spec = item.split("=", 1)
            dimension, span = spec.split(":", 1)
            lo, hi = (float(v) for v in span.split("-", 1))
        except ValueError:
            raise InvalidInputError(f"size {item.strip()!r}: expected CLASS=DIMENSION:LO-HI, e.g. car=length:3.6-5.2") from None
        out[name.strip()] = SizeRange(dimension.strip(), lo, hi)
    return out


def dimension_extent(extents: ArrayLike, dimension: str) -> float:
    """The side of a z-up bounding box ``extents (3,)`` that ``dimension`` measures."""
    e = np.asarray(extents, dtype=np.float64).reshape(3)
    if dimension == "length":
        return float(max(e[0], e[1]))
    if dimension == "height":
        return float(e[2])
    if dimension == "max":
        return float(e.max())
    raise InvalidInputError(f"size dimension must be one of {DIMENSIONS}, got {dimension!r}")


def size_interval(extents: ArrayLike, size: SizeRange) -> tuple[float, float]:
    """The interval of the *largest* side (metres) that puts ``size.dimension`` uniformly in its range.

    Parameters
    ----------
    extents : (3,) float
        The z-up mesh's bounding box, any unit (a normalised mesh: max 1).

    Returns
    -------
    (lo, hi) : metres
        For :class:`zbuf_occlude.sensors.placement.CropDistributions` ``size_m``.

    Raises
    ------
    InvalidInputError
        The measured side has zero length.
    """
    e = np.asarray(extents, dtype=np.float64).reshape(3)
    side = dimension_extent(e, size.dimension)
    if not side > 0:
        raise InvalidInputError(f"the mesh has no {size.dimension} (extents {e.tolist()})")
    ratio = float(e.max()) / side
    return size.lo_m * ratio, size.hi_m * ratio
