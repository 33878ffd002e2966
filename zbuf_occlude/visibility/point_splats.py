"""Visibility of a bare point cloud: the z-buffer test over surfel splats.

Most point-cloud data sets (PointNet's ``modelnet40_ply_hdf5_2048``, ShapeNetPart) hold points and
no mesh.  This module decides which of those points a camera sees from the points alone (and their
normals, where given), with the z-buffer test the mesh methods use:

1. **Surfels.**  Each point becomes a disk in its tangent plane (Pfister et al. 2000, *Surfels*;
   Zwicker et al. 2001, *Surface splatting*).  The radius follows the local sampling density, the
   distance to the k-th nearest neighbour (:data:`~zbuf_occlude.defaults.DEFAULT_POINT_NEIGHBOURS`),
   so sparse and dense parts of a cloud are both closed.  The normal is the given one, or the
   flattest covariance normal among neighbourhoods near the point
   (:func:`~zbuf_occlude.geometry.normals.robust_normals`).
2. **Splatting.**  The disks are rasterised into a depth buffer and an id buffer; each pixel holds
   the depth where its central ray meets the nearest disk (per-pixel ray-plane depth as in Botsch
   et al. 2005), :func:`~zbuf_occlude.visibility.point_kernels.splat_surfels`.  The pixel size is
   chosen from the splats (three pixels across the median radius), not set by the user.
3. **The test.**  A point is visible when the surface point that wins its pixel lies on the
   point's own sheet: within a tolerance of its tangent plane, measured along the normal, so
   that grazing views do not magnify it, plus the curvature between the two when they are
   neighbours on one smooth sheet, or less than a quarter spacing in front of the point along
   the camera's axis (:data:`~zbuf_occlude.visibility.point_kernels.DEPTH_SLACK`; where the
   normals were estimated, the winner's centre counts too, since an estimated normal tilts the
   winner's disk toward the camera); a winner whose centre lies behind that plane (past a convex
   crease) does not hide the point, and a point seen through a gap of a surface in front is
   hidden (:func:`~zbuf_occlude.visibility.point_kernels.decide`).
4. **Thin walls.**  Where a wall is thinner than the sampling (a sign's plate, a car's sheet
   metal), its two faces lie within the depth tolerance of each other, so depth cannot tell the
   near face from the far one.  But a point's neighbourhood then holds both faces as two
   sheets: the preparation finds them and turns each point's normal out of its wall
   (:func:`~zbuf_occlude.visibility.point_preparation.thin_wall_sides`), and a view hides the
   points of a wall's side that faces away.  Normals given as oriented keep their own sides.
5. **The hull test.**  Up to :data:`~zbuf_occlude.defaults.HULL_VETO_MAX_POINTS` points, where a splat is coarse
   and a point behind a small part or a gap between splats wins its own pixel, the points a view keeps go to the
   hull test of hidden point removal (HPR, Katz et al. 2007), which may hide them only
   (:func:`~zbuf_occlude.visibility.point_hull.hull_veto`).

Compared with HPR alone (Open3D's ``hidden_point_removal``) it needs no radius from the user; with
screen-space operators (Pintus et al. 2011) and variable-density visibility
(Biasutti et al. 2019) it shares the idea of sizing the test from the local density.
docs/results/point_visibility.md measures it and HPR against the exact mesh oracle.

What points alone cannot tell: a wall sampled on one face only, or whose two faces are too far
apart to share a neighbourhood yet nearer than the depth tolerance, shows its far face unless
the normals are oriented (``oriented=True``: a closed, consistently wound surface); and points
within about one spacing of an occluding edge are decided by the splat's reach, not by the
surface, which does not show.

What float64 cannot hold is refused before any work, in one line naming the value: coordinates
beyond :data:`MAX_SPLAT_COORDINATE` (squared distances between them would overflow), a
``splat_scale`` beyond :data:`MAX_SPLAT_SCALE`, normals that cannot be made unit
(:func:`~zbuf_occlude.io.point_sets.unit_normals`), and a cloud whose preparation would need more
memory than is available (:data:`BYTES_PER_SURFEL`, :data:`BYTES_PER_ESTIMATED_NORMAL` and
:data:`BYTES_PER_THREAD` for each thread of its neighbour search; :func:`~zbuf_occlude.resources.check_memory`),
and so is a view (:meth:`PointSurfels.visible`) whose arrays would (:data:`BYTES_PER_VIEW_POINT`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.defaults import (
    DEFAULT_CREASE_COS,
    DEFAULT_POINT_NEIGHBOURS,
    DEFAULT_SPLAT_SCALE,
    DEFAULT_SPLAT_TOLERANCE,
    HULL_RADIUS_FACTOR_PER_POINT,
    HULL_VETO_MAX_POINTS,
    MAX_SPLAT_PIXELS,
)
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.arguments import check_camera, check_count, check_flag, check_nonnegative, check_points
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.geometry.placement import warn_camera_placement
from zbuf_occlude.io.point_sets import unit_normals
from zbuf_occlude.resources import check_memory
from zbuf_occlude.visibility.point_hull import BYTES_PER_HULL_POINT, hull_veto
from zbuf_occlude.visibility.registry import register
from zbuf_occlude.visibility.splat_image import splat_image

__all__ = [
    "PointSurfels", "point_surfels", "visible_mask_points", "BYTES_PER_SURFEL", "BYTES_PER_ESTIMATED_NORMAL",
    "MAX_SPLAT_COORDINATE", "MAX_SPLAT_SCALE", "BYTES_PER_THREAD", "BYTES_PER_VIEW_POINT",
]  # fmt: skip

#: Bytes per point of :func:`point_surfels` with normals given (not oriented), at its peak.  It
#: holds the float64 points (24), the Morton order and the points in it (32), the uniform grid's
#: cells (:func:`~zbuf_occlude.visibility.point_preparation.nearest_neighbours`: at most 4 cells a
#: point, 40 B, in numba's allocator), the distances and indices of the
#: :data:`~zbuf_occlude.visibility.point_preparation.THIN_WALL_NEIGHBOURS` nearest neighbours
#: that the thin walls' sides are found in (384), the spacing and the radius (16), the unit
#: normals in both orders (48) and the sides: 540 B at the peak by tracemalloc at 200,000 and
#: 800,000 points on a sphere, plus the grid's 40 (which tracemalloc does not see); rounded up.
BYTES_PER_SURFEL = 584
#: Bytes per point the normals' estimate adds when none are given
#: (:func:`~zbuf_occlude.visibility.point_preparation.surfel_geometry`): the 48 nearest
#: neighbours' distances and indices instead of 24 (+384), the plane fits of three sizes (72 +
#: 24), less what the given normals took.  464 B more than with normals, measured as above
#: (tracemalloc's peak 1,004-1,005 B a point); rounded up.
BYTES_PER_ESTIMATED_NORMAL = 472
#: Address space each thread of the neighbour search maps (from 2 threads, one per core and
#: :data:`~zbuf_occlude.visibility.point_neighbours.POINTS_PER_THREAD` points): its stack (8 MiB,
#: ``ulimit -s``) and the glibc malloc arena its first allocation reserves (64 MiB on 64-bit), which
#: a limit on the address space (``ulimit -v``) counts although little of it is touched.
BYTES_PER_THREAD = 72 << 20
#: Bytes per point of one view (:meth:`PointSurfels.visible`) at its peak, beside the prepared
#: cloud: the points, normals, radii, spacings and sides gathered in Morton order once (65, kept), the
#: camera-frame points and normals (48), the frustum test, the splat image's per-point
#: temporaries and the masks: 150 B a point by tracemalloc on the first view at 200,000 and
#: 800,000 points on a sphere (86 on later views), plus the camera frame's 48 that numba
#: allocates (which tracemalloc does not see); rounded up.
BYTES_PER_VIEW_POINT = 208
#: Bytes per pixel of a view's splat image: its float64 depth and int64 ids.
_BYTES_PER_SPLAT_PIXEL = 16
#: Largest |coordinate| of a cloud, object units: 1e100.  The preparation sums squares of
#: coordinate differences (the k-d tree's distances; a plane fit's covariance over 14
#: neighbours, at most 14 · 3 · (2e100 · MAX_SPLAT_SCALE)² ≈ 2e207) and the splat test squares
#: radii over depths; all stay finite in float64 (1.8e308) below this.  A point at 1e200 makes
#: squared distances inf, and the neighbour search returns no neighbours.  No object or scene
#: in any unit comes near it (the observable universe is 1e27 m across).
MAX_SPLAT_COORDINATE = 1e100
#: Largest ``splat_scale``: splats 1,000 spacings in radius (the spacing being the distance to
#: the k-th neighbour) already cover the image of a cloud of a million points from any view; a
#: larger one changes nothing but the size of the numbers (``1e308`` overflows the image's area).
MAX_SPLAT_SCALE = 1_000.0


@dataclass(frozen=True)
class PointSurfels:
    """A point cloud prepared for visibility from many cameras (the view-independent part).

    Attributes
    ----------
    points : (N, 3) float64
        World frame.
    normals : (N, 3) float64
        Unit normals, world frame; given, or estimated (then of arbitrary sign), turned out of
        the wall where :attr:`sided`.
    spacing : (N,) float64
        Distance to the k-th nearest neighbour, object units.
    radius : (N,) float64
        Splat radius, object units (``splat_scale · spacing``).
    oriented : bool
        The normals point out of the surface consistently (given so by the caller).
    sided : (N,) bool
        The point lies on one side of a wall thinner than the sampling, its normal pointing out
        of the wall (:func:`~zbuf_occlude.visibility.point_preparation.thin_wall_sides`); found
        unless ``oriented``.  Facing away from a camera, such a point is hidden by the wall's
        near side.  All False where not given.
    estimated : bool
        The normals were estimated from the points (:func:`point_surfels` without normals): a
        winner's disk may be tilted by its normal's error, and a view takes the winner's centre
        as its depth too (:data:`~zbuf_occlude.visibility.point_kernels.NORMALS_ESTIMATED`).
        Not with ``oriented``.  Default False.
    """

    points: NDArray[np.float64]
    normals: NDArray[np.float64]
    spacing: NDArray[np.float64]
    radius: NDArray[np.float64]
    oriented: bool
    sided: NDArray[np.bool_] = field(default=None, repr=False)  # type: ignore[assignment]
    #: (N,) int64: the Morton order of the points (:func:`~zbuf_occlude.geometry.grouping.morton_order`),
    #: in which each view is splatted and decided: neighbours in space are neighbours in memory
    #: (about 2x faster at 100,000 points than the order given).
    order: NDArray[np.int64] = field(default=None, repr=False)  # type: ignore[assignment]
    estimated: bool = False

    def __post_init__(self) -> None:
        for name in ("oriented", "estimated"):
            check_flag(getattr(self, name), name)
        if self.oriented and self.estimated:
            raise InvalidInputError("oriented and estimated exclude each other: estimated normals have no consistent sign")
        if self.sided is None:
            object.__setattr__(self, "sided", np.zeros(len(self.points), dtype=np.bool_))
        elif np.shape(self.sided) != (len(self.points),):
            raise InvalidInputError(f"sided must hold one bool per point ({len(self.points)}), got shape {np.shape(self.sided)}")
        else:
            object.__setattr__(self, "sided", np.asarray(self.sided, dtype=np.bool_))
        if self.order is None:
            from zbuf_occlude.geometry.grouping import morton_order

            order = morton_order(self.points) if len(self.points) else np.zeros(0, dtype=np.int64)
            object.__setattr__(self, "order", order)

    @property
    def _normals(self) -> int:
        """How the normals were found, as :func:`~zbuf_occlude.visibility.point_kernels.decide` takes it."""
        from zbuf_occlude.visibility import point_kernels as kernels

        if self.estimated:
            return kernels.NORMALS_ESTIMATED
        return kernels.NORMALS_ORIENTED if self.oriented else kernels.NORMALS_GIVEN

    @functools.cached_property
    def _in_order(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """``points``, ``normals``, ``radius``, ``spacing``, ``sided`` in :attr:`order`: gathered once, not per view."""
        order = self.order
        return self.points[order], self.normals[order], self.radius[order], self.spacing[order], self.sided[order]

    def visible(
        self, camera: Camera, *, tolerance: float = DEFAULT_SPLAT_TOLERANCE, backend: str = "cpu", hull_test: bool | None = None
    ) -> NDArray[np.bool_]:
        """(N,) bool: the points ``camera`` sees (module docstring), inside its frustum.

        Parameters
        ----------
        camera : Camera
        tolerance : float
            Distance from a point's tangent plane, in spacings, within which the surface that
            wins its pixel counts as its own (:data:`~zbuf_occlude.defaults.DEFAULT_SPLAT_TOLERANCE`).
        backend : {"cpu", "gpu"}
            Who splats and decides: ``"cpu"`` (numba, float64) or ``"gpu"`` (OpenGL compute
            shaders, float64, :mod:`zbuf_occlude.render.surfel_zbuffer`; the CPU decides where
            the image needs several of its tiles).  Both compute the same arithmetic and break
            ties the same way (least depth, then lowest id): the masks are equal on 100 % of
            point-views of the shipped meshes (8 meshes x 16 poses at 2,048 to 100,000 points,
            Mesa llvmpipe and an NVIDIA H200).  From
            :data:`~zbuf_occlude.visibility.point_kernels.THREADED_MIN_POINTS` points the CPU
            kernels run on numba's threads where allowed
            (:func:`~zbuf_occlude.visibility.point_kernels.threads_for`), with the same masks.
            Either way the hull test (module docstring, step 5) runs on the CPU.
        hull_test : bool, optional
            Hand what the splats keep to the hull test (module docstring, step 5): None (the default)
            where the cloud holds at most :data:`~zbuf_occlude.defaults.HULL_VETO_MAX_POINTS` points,
            where it pays; True or False always or never.  It makes a view 2-4 times as long at 2,048 and
            10,000 points (docs/results/point_visibility.md).

        Raises
        ------
        InvalidInputError
            ``tolerance`` negative or not finite; an unknown ``backend``.
        ArgumentTypeError
            ``camera`` not a :class:`Camera`, ``tolerance`` not a number, ``hull_test`` not None, True or False.
        InsufficientMemoryError
            The view's arrays (:data:`BYTES_PER_VIEW_POINT` a point, ``BYTES_PER_HULL_POINT`` more for the hull test, and its splat image) would need
            more memory than is available (naming the points), checked before any is allocated.
        BackendUnavailable
            ``backend="gpu"`` and no OpenGL 4.3 context can be created.
        """
        from zbuf_occlude.visibility import point_kernels as kernels

        check_camera(camera)
        tol = check_nonnegative(tolerance, "tolerance")
        zbuffer = _gpu_zbuffer(backend)
        n = len(self.points)
        hull = n <= HULL_VETO_MAX_POINTS if hull_test is None else check_flag(hull_test, "hull_test")
        check_memory(
            n * (BYTES_PER_VIEW_POINT + (BYTES_PER_HULL_POINT if hull else 0)) + MAX_SPLAT_PIXELS * _BYTES_PER_SPLAT_PIXEL,
            f"a view of the splats of {n:,} points",
            hint="give fewer points (a random subset), or run where more memory is available",
        )
        in_frustum = camera.in_frustum(self.points)
        if n == 0 or not in_frustum.any():
            return in_frustum
        extrinsics = camera.extrinsics
        order = self.order
        points, normals, radius, spacing, sided = self._in_order
        cam, normal = kernels.camera_frame(points, normals, np.ascontiguousarray(extrinsics[:, :3]), extrinsics[:, 3].copy())
        image = splat_image(cam, radius, in_frustum[order], camera)
        box = (image.pix, image.x0, image.y0)
        if zbuffer is not None and zbuffer.fits_one_tile(image.width, image.height):
            rule = _decision_rule(tol, self._normals)
            decided = zbuffer.visible(
                cam, normal, radius, spacing, sided, (*box, image.width, image.height), edge_on_cos=kernels.EDGE_ON_COS, rule=rule
            )
        else:
            with kernels.threads_for(n) as threads:
                if zbuffer is not None:
                    depth, ids = zbuffer.splat(cam, normal, radius, *box, image.width, image.height, edge_on_cos=kernels.EDGE_ON_COS)
                elif threads > 1:
                    bands = kernels.BANDS_PER_THREAD * threads
                    depth, ids = kernels.splat_surfels_threaded(cam, normal, radius, *box, image.width, image.height, bands)
                else:
                    depth, ids = kernels.splat_surfels(cam, normal, radius, *box, image.width, image.height)
                decide = kernels.decide_threaded if threads > 1 else kernels.decide
                decided = decide(cam, normal, radius, spacing, depth, ids, box, tol, DEFAULT_CREASE_COS, self._normals, sided)
        visible = np.empty_like(decided)
        visible[order] = decided
        visible &= in_frustum
        if hull:
            visible = hull_veto(self.points, visible, camera.eye, HULL_RADIUS_FACTOR_PER_POINT * n)
        return visible


def _gpu_zbuffer(backend: object):
    """The GPU's surfel z-buffer for ``backend="gpu"``, None for ``"cpu"``."""
    if isinstance(backend, str) and backend == "cpu":
        return None
    if isinstance(backend, str) and backend == "gpu":
        from zbuf_occlude.render.surfel_zbuffer import shared_surfel_zbuffer

        return shared_surfel_zbuffer()
    raise InvalidInputError(f"backend must be 'cpu' or 'gpu', got {backend!r}")


def _decision_rule(tolerance: float, normals: int):
    """:func:`~zbuf_occlude.visibility.point_kernels.decide`'s settings and constants, for the GPU."""
    from zbuf_occlude.render.surfel_zbuffer import DecisionRule
    from zbuf_occlude.visibility import point_kernels as kernels

    return DecisionRule(
        tolerance, DEFAULT_CREASE_COS, normals == kernels.NORMALS_ORIENTED, normals == kernels.NORMALS_ESTIMATED,
        kernels.COPLANAR, kernels.DEPTH_SLACK, kernels.CURVATURE_SLACK, kernels.GAP_REACH,
    )  # fmt: skip


def _check_coordinates(points: NDArray[np.float64]) -> None:
    """Refuse a cloud with a coordinate beyond :data:`MAX_SPLAT_COORDINATE`, naming its row and value."""
    beyond = (np.abs(points) > MAX_SPLAT_COORDINATE).any(axis=1)
    if beyond.any():
        count, row = int(np.count_nonzero(beyond)), int(np.argmax(beyond))
        raise InvalidInputError(
            f"points: {count:,} {'row has' if count == 1 else 'rows have'} a coordinate beyond ±{MAX_SPLAT_COORDINATE:g}, first "
            f"row {row} {points[row].tolist()}; squared distances between points would overflow float64: scale the cloud"
        )


def _check_normals(normals: object, n: int) -> NDArray[np.float64]:
    nrm = check_points(normals, name="normals")
    if len(nrm) != n:
        raise InvalidInputError(f"normals must have one row per point ({n}), got {len(nrm)}")
    return unit_normals(nrm, what="normals")


def point_surfels(
    points: NDArray[np.floating],
    normals: NDArray[np.floating] | None = None,
    *,
    oriented: bool = False,
    neighbours: int = DEFAULT_POINT_NEIGHBOURS,
    splat_scale: float = DEFAULT_SPLAT_SCALE,
) -> PointSurfels:
    """Prepare a point cloud for :meth:`PointSurfels.visible` from many cameras.

    Parameters
    ----------
    points : (N, 3) float
        World frame, object units.
    normals : (N, 3) float, optional
        Surface normals (any finite length but zero, 5e-324 to 1.8e308).  Without them each point's normal is estimated
        from its neighbours, robustly next to sharp edges (the normals of
        :func:`~zbuf_occlude.geometry.normals.robust_normals`, computed by
        :func:`~zbuf_occlude.visibility.point_preparation.surfel_geometry`, which also finds the
        spacing and the sides of thin walls in the same neighbour search).  Given or estimated,
        a thin wall's points get normals turned out of the wall (:attr:`PointSurfels.sided`).
    oriented : bool
        ``normals`` point out of a closed surface consistently (a watertight mesh wound
        consistently); then a point facing away whose pixel is won by a surface facing the camera
        is hidden, which decides walls thinner than the tolerance, and no sides are looked for.
        False (default): normals of either sign.  Needs ``normals``.
    neighbours : int
        The k of the spacing, the distance to the k-th nearest neighbour (default 4).
    splat_scale : float
        Splat radius in spacings (default 1.0).

    Returns
    -------
    PointSurfels

    Raises
    ------
    InvalidInputError
        Bad shapes, NaN/inf, a coordinate beyond :data:`MAX_SPLAT_COORDINATE`, normals that are
        zero or cannot be made unit, ``oriented`` without normals, a count below 1 or a scale
        negative or beyond :data:`MAX_SPLAT_SCALE` (each naming the value).
    ArgumentTypeError
        An argument of the wrong kind: text or a bool where a number goes, a float where
        ``neighbours`` goes, anything but a bool for ``oriented``.
    InsufficientMemoryError
        The preparation (:data:`BYTES_PER_SURFEL` a point, and :data:`BYTES_PER_ESTIMATED_NORMAL`
        without normals, and :data:`BYTES_PER_THREAD` a thread) would need more memory than is
        available (naming the points), checked before any of it is allocated.
    """
    pts = check_points(points)
    k = check_count(neighbours, "neighbours")
    scale = check_nonnegative(splat_scale, "splat_scale", MAX_SPLAT_SCALE)
    check_flag(oriented, "oriented")
    if oriented and normals is None:
        raise InvalidInputError("oriented=True needs normals: estimated normals have no consistent sign")
    _check_coordinates(pts)
    n = len(pts)
    nrm = None if normals is None else _check_normals(normals, n)
    from zbuf_occlude.visibility.point_neighbours import thread_count

    threads = thread_count(n, -1)  # surfel_geometry's, each mapping its stack and malloc arena
    check_memory(
        n * (BYTES_PER_SURFEL + (BYTES_PER_ESTIMATED_NORMAL if nrm is None else 0)) + (threads * BYTES_PER_THREAD if threads > 1 else 0),
        f"preparing the splats of {n:,} points",
        hint="give fewer points" + ("" if nrm is not None else ", or normals (their estimate takes most of it)"),
    )
    estimated = nrm is None
    if n < 2:
        spacing = np.zeros(n)
        if nrm is None:
            nrm = np.tile([0.0, 0.0, 1.0], (n, 1))
        return PointSurfels(pts, nrm, spacing, spacing.copy(), bool(oriented), estimated=estimated)
    from zbuf_occlude.visibility.point_preparation import surfel_geometry

    spacing, nrm, sided, order = surfel_geometry(pts, k, nrm, sides=not oriented)  # oriented: the caller's sides stand
    return PointSurfels(pts, nrm, spacing, scale * spacing, bool(oriented), sided=sided, order=order, estimated=estimated)


def visible_mask_points(
    points: NDArray[np.floating],
    camera: Camera,
    *,
    normals: NDArray[np.floating] | None = None,
    oriented: bool = False,
    neighbours: int = DEFAULT_POINT_NEIGHBOURS,
    splat_scale: float = DEFAULT_SPLAT_SCALE,
    tolerance: float = DEFAULT_SPLAT_TOLERANCE,
    backend: str = "cpu",
    hull_test: bool | None = None,
) -> NDArray[np.bool_]:
    """Which points of a bare point cloud the camera sees: HSR without a mesh.

    The z-buffer test over surfel splats (module docstring; the defaults and their measured
    effect: :mod:`zbuf_occlude.defaults`).  For many cameras, prepare once with
    :func:`point_surfels` and call :meth:`PointSurfels.visible` per camera: the same answer
    without repeating the neighbour search.

    Parameters
    ----------
    points : (N, 3) float
        World frame, object units.
    camera : Camera
        Points outside its frustum are not visible.
    normals : (N, 3) float, optional
        Surface normals; estimated from the points when absent.
    oriented, neighbours, splat_scale
        See :func:`point_surfels`.
    tolerance, backend, hull_test
        See :meth:`PointSurfels.visible`.

    Returns
    -------
    visible : (N,) bool
        Empty for no points; a single point is visible iff it is in the frustum.

    Raises
    ------
    InvalidInputError
        Bad points or normals (shape, NaN/inf, beyond float64's reach: :func:`point_surfels`),
        bad option values (named).
    ArgumentTypeError
        An argument of the wrong kind (named): ``camera`` not a :class:`Camera`, text where
        points or a number go.
    InsufficientMemoryError
        As :func:`point_surfels`.
    BackendUnavailable
        ``backend="gpu"`` and no OpenGL 4.3 context can be created.
    """
    check_camera(camera)
    surfels = point_surfels(points, normals, oriented=oriented, neighbours=neighbours, splat_scale=splat_scale)
    warn_camera_placement(camera, surfels.points)
    return surfels.visible(camera, tolerance=tolerance, backend=backend, hull_test=hull_test)


@register("point-splat")
def point_splat_visible(
    mesh,
    points: NDArray[np.floating],
    camera: Camera,
    *,
    face_index: NDArray[np.integer] | None = None,
    tolerance: float = DEFAULT_SPLAT_TOLERANCE,
) -> NDArray[np.bool_]:
    """:func:`visible_mask_points` as a registered method: the points alone, no normals (the
    mesh and ``face_index`` are not used), so that every tool that compares methods with the
    oracle measures it too.

    Returns
    -------
    visible : (N,) bool
    """
    return visible_mask_points(points, camera, tolerance=tolerance)
