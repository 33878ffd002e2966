"""The hull test of hidden point removal as a second opinion on a view of splats.

Hidden point removal (HPR; Katz, Tal & Basri, "Direct visibility of point sets", SIGGRAPH 2007,
Sec. 3) flips a cloud about the viewpoint ``C`` through a sphere of radius ``R`` ("spherical
flipping", their Eq. 1: ``p̂ = p + 2 (R − ‖p‖) p / ‖p‖`` with ``p`` relative to ``C``) and calls
visible the points whose images lie on the convex hull of the flipped cloud and ``C``.  Their
``R = 10^γ · max ‖p‖`` trades false hidden points (small ``R``, concave parts) against false
visible ones (large ``R``).

Splats (:mod:`zbuf_occlude.visibility.point_splats`) fail the other way: at a few thousand points a
splat's disk is coarse, and a point behind a small occluder, or behind the gap between two splats,
is called visible.  So a view of splats asks the hull about the points it calls visible only
(:func:`hull_veto`): a point the splats see and whose image lies inside the flipped hull of the
points the splats see is hidden.  The hull is that of the splats' visible points alone (the hidden
ones cannot veto), which is also 2-3 times cheaper than the whole cloud's.  Where the hull would hide
most of what the splats see, it is HPR that fails (a sheet through the eye, :data:`MAX_VETOED_SHARE`),
and the veto is not taken.  Measured on the tuning meshes of docs/results/point_visibility.md (no
normals, 16 poses): accuracy 0.889 → 0.898 at 2,048 points, 0.930 → 0.934 at 10,000; at 100,000
points it gains 0.001 for three views' time (:data:`~zbuf_occlude.defaults.HULL_VETO_MAX_POINTS`).

The convex hull is scipy's (Qhull, Barber et al. 1996).  Points coplanar with a hull facet (a
duplicate of a hull vertex, within Qhull's precision) count as on the hull.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["BYTES_PER_HULL_POINT", "MAX_VETOED_SHARE", "flipped", "on_flipped_hull", "hull_veto"]

#: Bytes per point of :func:`on_flipped_hull` at its peak: the images (24) and Qhull's facets and
#: vertices, 490 B a point by the peak resident memory of a hull of 20,064 points of a hemisphere
#: (80 % of them on the hull); rounded up.
BYTES_PER_HULL_POINT = 512

#: Largest share of a view's visible points the veto hides; past it the veto is not taken.  A sheet through
#: the eye (a sign's plate seen exactly edge-on) flips into a flat hull whose inside holds the sheet's own
#: points, so HPR hides most of them (0.87 of what the splats kept of a sign at 2,048 points); splat leaks
#: are a rim band and small parts (at most 0.40 of what the splats kept in any view of the tuning meshes at
#: 2,048 and 10,000 points).
MAX_VETOED_SHARE = 0.5
#: Fewest points a 3-D hull is taken of: 4 in general position, the viewpoint one of them.
_MIN_HULL_POINTS = 4


def flipped(points: NDArray[np.float64], eye: NDArray[np.float64], radius_factor: float) -> NDArray[np.float64]:
    """Katz et al.'s spherical flipping (Eq. 1) of ``points (N, 3) float64`` about ``eye (3,)``, in
    the frame centred on ``eye`` with the farthest point's distance as its unit (so that the hull sees
    the same numbers at any scale): each point moved along its ray to ``2R − ‖p‖`` from the eye, with
    ``R = radius_factor``.  Points at the eye stay at it."""
    p = points - eye
    largest = float(np.abs(p).max(initial=0.0))
    if not largest > 0.0:
        return np.zeros_like(p)
    p = p / largest  # squares of 1e-160 or 1e200 would under- or overflow
    d = np.sqrt(np.einsum("ij,ij->i", p, p))
    farthest = float(d.max())
    p, d = p / farthest, d / farthest
    scale = np.divide(2.0 * radius_factor - d, d, out=np.zeros_like(d), where=d > 0.0)
    return p * scale[:, None]


def on_flipped_hull(points: NDArray[np.float64], eye: NDArray[np.float64], radius_factor: float) -> NDArray[np.bool_]:
    """(N,) bool: HPR's visible points (Katz et al. 2007, Sec. 3), the points of ``points (N, 3)
    float64`` whose images under :func:`flipped` lie on the convex hull of the images and the eye
    (a vertex, or coplanar with a facet).  All True where no hull can be taken (fewer than
    :data:`_MIN_HULL_POINTS` with the eye, or all in one plane with it): HPR has nothing to say."""
    from scipy.spatial import ConvexHull, QhullError

    n = len(points)
    if n + 1 < _MIN_HULL_POINTS:
        return np.ones(n, dtype=np.bool_)
    images = np.vstack([flipped(points, eye, radius_factor), np.zeros((1, 3))])
    try:
        hull = ConvexHull(images, qhull_options="Qc")
    except (QhullError, ValueError):  # flat or degenerate with the eye: no hull to be inside
        return np.ones(n, dtype=np.bool_)
    on = np.zeros(n + 1, dtype=np.bool_)
    on[hull.vertices] = True
    if len(hull.coplanar):
        on[hull.coplanar[:, 0]] = True
    return on[:n]


def hull_veto(points: NDArray[np.float64], visible: NDArray[np.bool_], eye: NDArray[np.float64], radius_factor: float) -> NDArray[np.bool_]:
    """``visible`` less the points inside the flipped hull of the visible points (module docstring).

    Parameters
    ----------
    points : (N, 3) float64
        World frame.
    visible : (N,) bool
        A view's visible points (the splat test's).
    eye : (3,) float64
        The camera's centre, world frame.
    radius_factor : float
        Katz et al.'s ``10^γ``: the flipping radius over the farthest visible point's distance.

    Returns
    -------
    (N,) bool
        A subset of ``visible``; ``visible`` itself where the hull would hide more than
        :data:`MAX_VETOED_SHARE` of it.
    """
    rows = np.flatnonzero(visible)
    on = on_flipped_hull(points[rows], np.asarray(eye, dtype=np.float64), radius_factor)
    if np.count_nonzero(~on) > MAX_VETOED_SHARE * len(rows):  # a sheet through the eye: the hull cannot judge
        return np.array(visible, dtype=np.bool_)
    kept = np.zeros(len(points), dtype=np.bool_)
    kept[rows] = on
    return kept
