"""The one definition of visibility that every method decides (issue 11, item 3).

A point ``p`` is **visible** from a camera with centre ``e`` iff

(a) ``p`` is in the camera's frustum (:meth:`Camera.in_frustum`, float64);
(b) the point's own face is *not* seen within :data:`EDGE_ON_DEGREES` of edge-on, i.e.
    ``|n · (e - p)| >= sin(EDGE_ON_DEGREES) · |n| · |e - p|`` for its face normal ``n``
    (a face seen edge-on has zero projected area: nothing on it shows in an image).  The
    own face is ``face_index[p]`` when given; without it, *every* face whose plane lies
    within the tolerance of ``p`` and whose closed triangle contains ``p``'s orthogonal
    projection counts as an own face, and any one of them seen edge-on hides ``p``
    (for points sampled inside a face this is the same face; the two differ only on
    edges, a set of measure zero);
(c) no face other than the own face meets the segment from ``p`` to ``e`` at a distance
    ``d`` with ``tolerance < d <= |e - p|`` (:data:`TOLERANCE` = 1e-6 object units for
    every method; the oracle module states the float64 arithmetic).

Every method (the oracles, ``zbuffer-exact``, ``embree-fast``, ``auto``) implements this
definition; the two oracles decide (b) with the functions below and (c) with one float64
kernel, so they agree bit for bit.  The GPU path decides (b) and (c) in float32 with
error bounds and re-decides every pair inside the bounds in float64 with the same formulas
(written out in ``render/shaders/exact_pair64.glsl``).

The tolerance of (c) is decided only for cameras within
:data:`~zbuf_occlude.defaults.MAX_CAMERA_RADIUS` (≈ 1.1e6 object units) of the object:
farther, float64's rounding of ``e - p`` comes within 2**12 of it, and
:func:`~zbuf_occlude.geometry.cameras.camera_on_sphere` refuses such a radius (the derivation is
beside the constant).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.defaults import DEFAULT_SELF_HIT_TOLERANCE

__all__ = ["TOLERANCE", "EDGE_ON_DEGREES", "EDGE_ON_SIN", "edge_on_own", "edge_on_any"]

#: The one self-hit tolerance of every method, object units (meshes normalised to extent 1).
TOLERANCE = DEFAULT_SELF_HIT_TOLERANCE
#: A point whose own face is seen within this angle of edge-on is not visible, degrees.
#: Small enough that no real face is hit by chance (a 1280-face icosphere from the equator
#: has faces at 0.004° from edge-on), large enough to decide faces seen *exactly* edge-on
#: (a shelf at elevation 0, where float64 leaves |cos| ~ 1e-17 of rounding noise) the
#: same way in every method.
EDGE_ON_DEGREES = 1e-4
#: ``sin(EDGE_ON_DEGREES)``: the bound on ``|cos(normal, sightline)|`` (float64).
EDGE_ON_SIN = math.sin(math.radians(EDGE_ON_DEGREES))


def _dot3(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    # Same summation order as the oracle's kernel and the GLSL float64 replica.
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def edge_on_own(normal: NDArray[np.float64], points: NDArray[np.float64], eye: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(N,) bool: the face of normal ``normal[k]`` is seen from ``eye`` within
    :data:`EDGE_ON_DEGREES` of edge-on at ``points[k]`` (rule (b)).

    Parameters
    ----------
    normal : (N, 3) float64
        Unnormalised face normals (``TrianglePlanes.normal`` rows), object frame.
    points : (N, 3) float64
    eye : (3,) float64

    Notes
    -----
    Evaluated as ``|n · s| < EDGE_ON_SIN · sqrt(n · n) · sqrt(s · s)`` with ``s = eye - p``,
    in this order, so the GPU's float64 replica gives the same bits.  Degenerate faces
    (``n = 0``) are never edge-on.
    """
    seg = eye - points
    seg_len = np.sqrt(_dot3(seg, seg))
    return np.abs(_dot3(normal, seg)) < EDGE_ON_SIN * np.sqrt(_dot3(normal, normal)) * seg_len


def _own_and_edge_on(planes, points, eye, faces, tolerance) -> NDArray[np.bool_]:
    n = planes.normal[faces]
    nn = np.sqrt(_dot3(n, n))
    near = np.abs(_dot3(n, points) - planes.offset[faces]) <= tolerance * nn
    en, eo = planes.edge_normals[faces], planes.edge_offsets[faces]
    near &= _dot3(points, en[:, 0]) >= eo[:, 0]
    near &= _dot3(points, en[:, 1]) >= eo[:, 1]
    near &= _dot3(points, en[:, 2]) >= eo[:, 2]
    return near & edge_on_own(n, points, eye)


def edge_on_any(
    planes,
    points: NDArray[np.float64],
    eye: NDArray[np.float64],
    tolerance: float = TOLERANCE,
    order: NDArray[np.int64] | None = None,
) -> NDArray[np.bool_]:
    """(N,) bool: rule (b) without ``face_index``: some face containing the point (plane
    within ``tolerance``, closed triangle containing its projection) is seen edge-on.

    Parameters
    ----------
    planes : TrianglePlanes
        Of all faces (``oracle.mesh_planes(mesh)``).
    points : (N, 3) float64
    eye : (3,) float64
    tolerance : float
        Object units.
    order : (N,) int, optional
        ``argsort(points[:, 0])`` if the caller has it (many views of one point set).

    Notes
    -----
    ``n · (e - x)`` is the same for every ``x`` of a face's plane, so only faces with
    ``|n · (e - A)| < EDGE_ON_SIN · |n| · max_k |e - V_k|`` (plus the tolerance) can be
    edge-on anywhere on them; each is paired with the points in its bounding box (a sweep
    over the points sorted by x) and the pairs are decided with the float64 rule.
    """
    out = np.zeros(len(points), dtype=bool)
    if len(points) == 0 or planes.shape[0] == 0:
        return out
    n = planes.normal
    nn = np.sqrt(_dot3(n, n))
    far = np.sqrt(_dot3(planes.vertices - eye, planes.vertices - eye)).max(axis=1)
    s = np.abs(planes.offset - _dot3(n, eye))
    cand = np.flatnonzero((nn > 0) & (s <= (EDGE_ON_SIN * far + 2.0 * tolerance) * nn * (1 + 1e-9)))
    if len(cand) == 0:
        return out
    lo = planes.vertices[cand].min(axis=1) - 2.0 * tolerance
    hi = planes.vertices[cand].max(axis=1) + 2.0 * tolerance
    if order is None:
        order = np.argsort(points[:, 0], kind="stable")
    xs = points[order, 0]
    first = np.searchsorted(xs, lo[:, 0], side="left")
    count = np.searchsorted(xs, hi[:, 0], side="right") - first
    total = int(count.sum())
    if total == 0:
        return out
    k = np.repeat(np.arange(len(cand)), count)
    idx = order[np.repeat(first - (np.cumsum(count) - count), count) + np.arange(total)]
    keep = np.all((points[idx] >= lo[k]) & (points[idx] <= hi[k]), axis=1)
    idx, k = idx[keep], k[keep]
    hit = _own_and_edge_on(planes, points[idx], eye, cand[k], tolerance)
    out[idx[hit]] = True
    return out


def edge_on(
    planes,
    points: NDArray[np.float64],
    eye: NDArray[np.float64],
    face_index: NDArray[np.int64] | None,
    tolerance: float = TOLERANCE,
) -> NDArray[np.bool_]:
    """(N,) bool: rule (b), with ``face_index`` (:func:`edge_on_own`) or without (:func:`edge_on_any`)."""
    if face_index is None:
        return edge_on_any(planes, points, eye, tolerance)
    return edge_on_own(planes.normal[face_index], points, eye)


def hide_edge_on(
    visible: NDArray[np.bool_],
    planes,
    points: NDArray[np.float64],
    eye: NDArray[np.float64],
    face_index: NDArray[np.int64] | None,
    tolerance: float = TOLERANCE,
) -> NDArray[np.bool_]:
    """``visible`` with rule (b) applied to its True entries (in place; returned)."""
    idx = np.flatnonzero(visible)
    if len(idx):
        fi = None if face_index is None else face_index[idx]
        visible[idx[edge_on(planes, points[idx], np.asarray(eye, dtype=np.float64), fi, tolerance)]] = False
    return visible
