"""A camera placed where the CLI would never put it: a warning from the Python functions.

The CLI normalises every object (centred, largest side 1) and puts its cameras on a sphere
outside it (:func:`~zbuf_occlude.geometry.cameras.camera_on_sphere` refuses one inside the
bounding sphere).  A Python caller passes an object and a camera of its own: a cloud in its
file's units (millimetres) with the default radius-4 camera, or a camera inside the mesh, sees
almost nothing, which is a right answer to a wrong question.  :func:`warn_camera_placement`
says so once per call, naming the camera's distance and the object's extent.
"""

from __future__ import annotations

import math
import sys
import warnings
from types import CodeType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import CameraPlacementWarning
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS, Camera

__all__ = ["placement_problem", "warn_camera_placement"]

#: Pixels: an object that would fill fewer than this across the camera's image is too small.
MIN_OBJECT_PIXELS = 1.0
#: The public functions that have called :func:`warn_camera_placement` (their code objects): one
#: called by another (``visible_mask`` with ``method="point-splat"`` calls
#: ``visible_mask_points``) leaves the warning to the outer one.
_CHECKERS: set[CodeType] = set()


def _bounds(obj: Any) -> NDArray[np.float64] | None:
    """``(2, 3)`` lower and upper corners of the object's axis-aligned bounding box, or None for
    no points: ``obj`` is ``(N, 3)`` points or a mesh (its ``bounds``, else its ``vertices``)."""
    if isinstance(obj, np.ndarray):
        points = obj
    elif getattr(obj, "bounds", None) is not None:
        return np.asarray(obj.bounds, dtype=np.float64).reshape(2, 3)
    else:
        points = np.asarray(obj.vertices, dtype=np.float64)
    points = points.reshape(-1, 3)
    if len(points) == 0:
        return None
    # column by column: a reduction over axis 0 of an (N, 3) array steps 3 values at a time
    return np.array([[points[:, k].min() for k in range(3)], [points[:, k].max() for k in range(3)]], dtype=np.float64)


def placement_problem(camera: Camera, obj: Any) -> str | None:
    """What is wrong with ``camera``'s place for the object ``obj``, in one sentence, or None.

    Two things: the camera's eye inside the object's axis-aligned bounding box (which the CLI's
    cameras never are: they stay outside the bounding sphere), or the object so small or so far
    that its bounding sphere would span fewer than :data:`MIN_OBJECT_PIXELS` pixels of the
    image.  An object of no extent (one point, or none) has nothing to say.

    Parameters
    ----------
    camera : Camera
    obj : (N, 3) float array or mesh
        Points, or a mesh (``trimesh.Trimesh``: its cached ``bounds``), world frame.
    """
    bounds = _bounds(obj)
    if bounds is None:
        return None
    (x0, y0, z0), (x1, y1, z1) = bounds.tolist()
    extent = max(x1 - x0, y1 - y0, z1 - z0)
    if not (extent > 0.0 and math.isfinite(extent)):
        return None
    ex, ey, ez = (float(v) for v in camera.eye)
    distance = math.dist((ex, ey, ez), (0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * (z0 + z1)))
    if x0 <= ex <= x1 and y0 <= ey <= y1 and z0 <= ez <= z1:
        problem, place = "the camera is inside the object's bounding box, where the CLI never puts one", "outside it"
    else:
        radius = 0.5 * math.dist((x0, y0, z0), (x1, y1, z1))
        focal_px = 0.5 * camera.height / math.tan(math.radians(0.5 * camera.yfov_deg))
        across_px = 2.0 * radius * focal_px / distance
        if across_px >= MIN_OBJECT_PIXELS:
            return None
        problem, place = f"the object would span {across_px:.2g} pixels of the camera's image, too few to see", "closer"
    return (
        f"{problem}: the camera is {distance:.3g} object units from the centre of the object's bounding box, whose "
        f"largest side is {extent:.3g}; scale the object to a largest side of 1 (zo.normalize_mesh; points: "
        f"(points - centre) / {extent:.3g}), or place the camera {place} (zo.camera_on_sphere's default radius is "
        f"{DEFAULT_RADIUS:g} x the largest side)"
    )


def warn_camera_placement(camera: Camera, obj: Any) -> None:
    """Warn (:class:`~zbuf_occlude.errors.CameraPlacementWarning`) where :func:`placement_problem`
    finds one, pointing at the caller of the public function that calls this; once per call: not
    when that function was itself called by another public function that calls this."""
    caller = sys._getframe(1)
    _CHECKERS.add(caller.f_code)
    frame = caller.f_back
    while frame is not None:
        if frame.f_code in _CHECKERS:
            return
        frame = frame.f_back
    problem = placement_problem(camera, obj)
    if problem is not None:
        warnings.warn(problem, CameraPlacementWarning, stacklevel=3)
