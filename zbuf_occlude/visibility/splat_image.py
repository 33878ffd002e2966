"""The image a view of splats is rasterised into (:func:`splat_image`), sized from the splats: the part of the
frustum that holds points, a few pixels across the median splat.  Made once per view by
:meth:`~zbuf_occlude.visibility.point_splats.PointSurfels.visible`; either rasteriser fills it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.defaults import MAX_SPLAT_PIXELS, SPLAT_PIXELS_PER_RADIUS
from zbuf_occlude.geometry.cameras import Camera

__all__ = ["SplatImage", "splat_image"]


@dataclass(frozen=True)
class SplatImage:
    """The image a view's splats are rasterised into: normalised coordinates ``(x/z, y/z)`` of
    the OpenCV camera frame, pixel ``(i, j)`` covering ``[x0 + i·pix, x0 + (i+1)·pix) ×
    [y0 + j·pix, y0 + (j+1)·pix)``."""

    pix: float
    x0: float
    y0: float
    width: int
    height: int


#: Largest pad of a splat image, in half-widths of the frustum (:func:`splat_image`): 1e6.
_MAX_PAD = 1e6


def splat_image(cam: NDArray[np.float64], radius: NDArray[np.float64], in_frustum: NDArray[np.bool_], camera: Camera) -> SplatImage:
    """The splat image of one view: the part of the frustum that holds points, with
    :data:`~zbuf_occlude.defaults.SPLAT_PIXELS_PER_RADIUS` pixels across the median splat radius
    (coarser if that exceeds :data:`~zbuf_occlude.defaults.MAX_SPLAT_PIXELS`).

    Parameters
    ----------
    cam : (N, 3) float64
        Points, OpenCV camera frame.
    radius : (N,) float64
        Splat radii, object units.
    in_frustum : (N,) bool
        ``camera.in_frustum`` of the points; at least one True.
    camera : Camera
    """
    inside = cam[in_frustum] if not in_frustum.all() else cam  # one gather, not one per column
    z = inside[:, 2]
    r = radius[in_frustum] if inside is not cam else radius
    x, y = inside[:, 0] / z, inside[:, 1] / z
    # a splat reaching the camera plane would cover everything: its angular size is capped
    rho = r / np.maximum(z - r, 0.5 * z)
    half_h = math.tan(math.radians(camera.yfov_deg) / 2.0)
    half_w = half_h * camera.width / camera.height
    x_lo, x_hi, y_lo, y_hi = float(x.min()), float(x.max()), float(y.min()), float(y.max())
    # a disk off the axis projects wider than rho, by up to a factor 1 + |x/z| (the kernel's box);
    # past _MAX_PAD frustums the pad only makes the numbers overflow (a splat at the camera plane)
    pad = min(float(rho.max()) * (1.0 + max(-x_lo, x_hi, -y_lo, y_hi)), _MAX_PAD * max(half_w, half_h))
    x0 = max(x_lo, -half_w) - pad
    x1 = min(x_hi, half_w) + pad
    y0 = max(y_lo, -half_h) - pad
    y1 = min(y_hi, half_h) + pad
    extent_x, extent_y = max(x1 - x0, 1e-12), max(y1 - y0, 1e-12)
    positive = rho[rho > 0]
    pix = float(np.median(positive)) / SPLAT_PIXELS_PER_RADIUS if len(positive) else max(extent_x, extent_y)
    pix = min(pix, max(extent_x, extent_y))  # one pixel covers the image at most
    if extent_x * extent_y / (pix * pix) > MAX_SPLAT_PIXELS:
        pix = math.sqrt(extent_x * extent_y / MAX_SPLAT_PIXELS)
    return SplatImage(pix, x0, y0, math.ceil(extent_x / pix) + 1, math.ceil(extent_y / pix) + 1)
