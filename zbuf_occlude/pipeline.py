"""Occluded samples of one object from many poses: the unit of work of ``generate`` and the farm.

Per object (Sryamkin et al. 2023, §3.4 and §4.3): sample a dense cloud once, decide its
visibility from every pose, and draw ``samples_per_view`` fixed-size samples per pose from
the visible points (seeds and draws: :mod:`zbuf_occlude.geometry.samples`).  A pose that sees
fewer than ``n_points`` dense points is topped up with more visible points drawn on the faces
it sees (:func:`~zbuf_occlude.geometry.samples.top_up`), so its samples hold distinct points
unless its visible surface is truly too small.

A point-set input (a cloud of a PointNet HDF5, ``.npy`` or ``.ply`` point file) has no faces:
its dense cloud is its own points, its visibility per pose comes from the points alone (the
z-buffer test over surfel splats, :mod:`zbuf_occlude.visibility.point_splats`), nothing is
topped up and its samples' ``face_index`` is :data:`NO_FACE` (:func:`occlude_point_set`).

:func:`occlude` is the one-call version, ``zbuf_occlude.occlude(...)``.
"""

from __future__ import annotations

import functools
import logging
import os
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.defaults import (
    DEFAULT_DENSE_POINTS,
    DEFAULT_METHOD,
    DEFAULT_N_POINTS,
    DEFAULT_OCCLUDE_SAMPLES_PER_VIEW,
    DEFAULT_RESOLUTION,
    DEFAULT_SAMPLES_PER_VIEW,
    DEFAULT_SEED,
    DEFAULT_VIEWS,
)
from zbuf_occlude.errors import InvalidInputError, PaddedSamplesWarning
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS, Camera, camera_on_sphere, view_schedule
from zbuf_occlude.geometry.samples import (
    DENSE_STREAM,
    ObjectProvenance,
    OccludedCloud,
    TopUp,
    derive_rng,
    object_key,
    pool_take,
    pose_samples,
    top_up,
)
from zbuf_occlude.geometry.sampling import sample_surface, triangles_of
from zbuf_occlude.mesh.inputs.kinds import POINT_SET_METHOD  # the point-set input kind's method, re-exported
from zbuf_occlude.resources import check_memory, estimate_job_memory
from zbuf_occlude.visibility.registry import check_keywords, method_info, resolution_option, visible_mask

if TYPE_CHECKING:  # trimesh (and scipy) is imported by occlude(), which takes files and meshes
    import trimesh

__all__ = [
    "DenseCloud", "dense_cloud", "CameraSphere", "PoseDraws", "PoseResult", "occlude_poses", "occlude_object", "occlude", "occlude_point_set",
    "NO_FACE", "POINT_SET_METHOD",
]  # fmt: skip

log = logging.getLogger(__name__)

#: :func:`occlude` uses a given mesh as it is when its bounding box is already centred with
#: largest side 1 within this (object units): normalising again is not bit-exact, and the
#: samples must equal those ``generate`` writes from the same file.
NORMALISED_ATOL = 1e-9
#: ``face_index`` of a sample point that lies on no face: the points of a point-set input.
NO_FACE = -1


@dataclass
class DenseCloud:
    """The per-object dense cloud (sampled once, reused for every pose, paper §3.4).

    What :func:`dense_cloud` gives, and what :class:`zbuf_occlude.learn.RandomOcclusion` takes;
    ``DenseCloud(*sample_surface(mesh, count=8192, seed=0))`` makes one of any mesh
    (:func:`~zbuf_occlude.geometry.sampling.sample_surface`).

    Attributes
    ----------
    points : (M, 3) float64
        Points on the mesh's surface, in its frame (object units).
    face_index : (M,) int64
        Index into ``mesh.faces`` of the face each point lies on.
    """

    points: NDArray[np.float64]
    face_index: NDArray[np.int64]


def dense_cloud(
    mesh: trimesh.Trimesh, key: int, *, seed: int = 0, count: int | None = DEFAULT_DENSE_POINTS, density: float | None = None
) -> DenseCloud:
    """Sample the object's dense cloud with the generator of ``(seed, key)``.

    ``count`` points area-weighted, or ``density`` points per unit area (Algorithm 1).
    """
    rng = derive_rng(seed, key, DENSE_STREAM)
    if density is not None:
        points, face_index = sample_surface(mesh, density=density, seed=rng)
    else:
        points, face_index = sample_surface(mesh, count=count, seed=rng)
    return DenseCloud(points, face_index)


@dataclass(frozen=True)
class CameraSphere:
    """The cameras of an object's poses: on a sphere of ``radius`` around it, looking at its centre.

    Attributes
    ----------
    radius : float
        Camera distance from the centre, object units (the object's largest side is 1).
    resolution : int or (width, height)
        Image size, pixels (the z-buffer of image-space methods).
    """

    radius: float = DEFAULT_RADIUS
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION

    def camera(self, elevation_deg: float, azimuth_deg: float) -> Camera:
        """The camera of one pose (:func:`~zbuf_occlude.geometry.cameras.camera_on_sphere`).

        Raises
        ------
        CameraError
            A non-finite pose, an elevation outside [−90, 90], or a radius inside the object's
            bounding sphere or too far to decide visibility.
        """
        try:
            return _sphere_camera(elevation_deg, azimuth_deg, self.radius, self.resolution)
        except TypeError:  # an unhashable resolution (a list): made afresh
            return camera_on_sphere(elevation_deg, azimuth_deg, self.radius, resolution=self.resolution)


@dataclass(frozen=True)
class PoseDraws:
    """What each pose of an object draws: ``samples_per_view`` samples of ``n_points`` points from the dense points it
    sees, topped up where they are too few (:func:`occlude_poses`).

    Attributes
    ----------
    n_points : int
        Points per sample, at least 1.
    samples_per_view : int
        Samples drawn per pose, at least 0.
    topped_up : bool
        Top up the poses that see too few dense points (default; :func:`~zbuf_occlude.geometry.samples.top_up`);
        ``False`` draws from the visible dense points alone (padding with repeats when they are too few).

    Raises
    ------
    InvalidInputError
        ``n_points < 1`` or ``samples_per_view < 0``.
    """

    n_points: int = DEFAULT_N_POINTS
    samples_per_view: int = DEFAULT_SAMPLES_PER_VIEW
    topped_up: bool = True

    def __post_init__(self) -> None:
        _check_counts(self.n_points, self.samples_per_view)


@functools.lru_cache(maxsize=4096)
def _sphere_camera(elevation_deg: float, azimuth_deg: float, radius: float, resolution: int | tuple[int, int]) -> Camera:
    """:func:`camera_on_sphere`, made once per process for each pose: every object of a farm
    has the same poses, and a camera is immutable (it was 4 % of a farm worker's time)."""
    return camera_on_sphere(elevation_deg, azimuth_deg, radius, resolution=resolution)


@dataclass
class PoseResult:
    """What :func:`occlude_poses` gives for one pose.

    Attributes
    ----------
    pose_index : int
    visible : (M,) bool
        Which dense points the pose sees.
    topped_up : TopUp
        The pose's top-up points (``(T, 3) float64`` points, ``(T,) int64`` face indices; empty
        when it sees ``n_points`` dense points, or nothing).
    clouds : list of OccludedCloud
        Its samples (none when it sees nothing).
    """

    pose_index: int
    visible: NDArray[np.bool_]
    topped_up: TopUp
    clouds: list[OccludedCloud]

    @property
    def n_visible(self) -> int:
        """Distinct visible points the pose offers its samples: visible dense points plus top-up points."""
        return int(np.count_nonzero(self.visible)) + len(self.topped_up)


def _check_counts(n_points: int, samples_per_view: int) -> None:
    if n_points < 1 or samples_per_view < 0:
        raise InvalidInputError(f"need n_points >= 1 and samples_per_view >= 0, got {n_points}, {samples_per_view}")


def _pose_clouds(
    points: NDArray[np.float64],
    face_index: NDArray[np.int64],
    extra: TopUp,
    chosen: Sequence[NDArray[np.int64]],
    pose: tuple[float, float],
    n_visible_dense: int,
    cameras: CameraSphere,
    provenance: ObjectProvenance,
) -> list[OccludedCloud]:
    """One pose's samples: pool indices ``chosen`` (:func:`~zbuf_occlude.geometry.samples.pose_samples`) taken
    from the dense ``points``/``face_index`` and the pose's top-up ``extra``, with the pose and provenance."""
    el, az = pose
    return [
        OccludedCloud(
            points=pool_take(points, extra.points, c).astype(np.float32),
            face_index=pool_take(face_index, extra.face_index, c),
            elevation_deg=float(el),
            azimuth_deg=float(az),
            radius=float(cameras.radius),
            label=provenance.label,
            class_name=provenance.class_name,
            source=provenance.source,
            sample_index=sample_index,
            n_visible=n_visible_dense + len(extra),
            split=provenance.split,
            n_topped_up=len(extra),
        )
        for sample_index, c in enumerate(chosen)
    ]


def occlude_poses(
    mesh: trimesh.Trimesh,
    poses: Sequence[tuple[float, float]],
    *,
    key: int,
    draws: PoseDraws = PoseDraws(),
    seed: int = DEFAULT_SEED,
    dense: DenseCloud | None = None,
    method: str = DEFAULT_METHOD,
    cameras: CameraSphere = CameraSphere(),
    provenance: ObjectProvenance = ObjectProvenance(),
    **method_options,
) -> Iterator[PoseResult]:
    """Yield a :class:`PoseResult` for each pose of one object: mask, top-up points and samples.

    A pose that sees ``0 < V < n_points`` dense points (``draws.n_points``) is topped up: candidates drawn on the
    faces holding its visible dense points are tested with ``method`` from the same camera, in
    a session of their own (:func:`~zbuf_occlude.geometry.samples.top_up`, seeded by ``(seed,
    key, TOPUP_STREAM, pose_index, round)``), and the visible ones join the pose's pool.  Poses
    that see ``n_points`` or more are not touched: their samples are the same bytes either way.
    ``open3d-hpr``, which decides from the point set alone, judges the candidates among
    themselves.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Normalised (max extent 1), world frame.
    poses : sequence of (elevation_deg, azimuth_deg)
    key : int
        The object's seed key (:func:`object_key` of a stable name).
    draws : PoseDraws
        Points per sample, samples drawn per pose, and whether a pose that sees too few dense points is topped up.
    dense : DenseCloud, optional
        Default: :func:`dense_cloud` ``(mesh, key, seed=seed)``.
    method : str
        Visibility method; image-space methods keep the points on the GPU across poses.
    cameras : CameraSphere
        The poses' camera distance (object units) and image size (pixels).
    provenance : ObjectProvenance
        The object's ``label``, ``class_name``, ``source`` and ``split``, copied into every cloud
        (:class:`OccludedCloud`).
    **method_options
        The visibility method's keywords.

    Raises
    ------
    InsufficientMemoryError
        (an InvalidInputError) The object's job would not fit in the memory available
        (:func:`zbuf_occlude.resources.check_memory`), checked before any allocation.
    CameraError
        A pose or ``cameras`` gives no valid camera (:meth:`CameraSphere.camera`).
    """
    n_points, samples_per_view = draws.n_points, draws.samples_per_view
    check_keywords(method, method_options)  # a misspelt option must not run with the default
    # Refuse before allocating what cannot fit (the OOM killer gives no message).
    check_memory(
        estimate_job_memory(
            points=int(n_points), samples_per_view=int(samples_per_view),
            dense_points=len(dense.points) if dense is not None else DEFAULT_DENSE_POINTS,
            resolution=cameras.resolution, faces=len(mesh.faces),
        )
    )  # fmt: skip
    dense = dense or dense_cloud(mesh, key, seed=seed)
    n_dense = len(dense.points)
    session = method_info(method).session
    scene = session(mesh, dense.points, dense.face_index) if session is not None else None
    one_shot_options = {**resolution_option(method, cameras.resolution), **method_options}
    triangles: NDArray[np.float64] | None = None  # the mesh's corners, once, for the first pose topped up

    def candidates_visible(camera: Camera, points: NDArray[np.float64], face_index: NDArray[np.int64]) -> NDArray[np.bool_]:
        # the method of the dense points: its own session over the candidates (mesh-side state is cached per mesh)
        if session is None:
            return visible_mask(mesh, points, camera, method, face_index=face_index, **one_shot_options)
        candidates = session(mesh, points, face_index)
        try:
            return candidates.visible(camera, **method_options)
        finally:
            candidates.release()

    try:
        for pose_index, (el, az) in enumerate(poses):
            camera = cameras.camera(el, az)
            if scene is not None:
                visible = scene.visible(camera, **method_options)
            else:
                visible = visible_mask(mesh, dense.points, camera, method, face_index=dense.face_index, **one_shot_options)
            visible_index = np.flatnonzero(visible)
            if len(visible_index) == 0 and samples_per_view:
                log.warning("%s: nothing visible from el=%g az=%g; no sample", provenance.source or "mesh", el, az)
            extra = TopUp()
            if draws.topped_up and 0 < len(visible_index) < n_points:
                triangles = triangles_of(mesh) if triangles is None else triangles
                seen_faces = np.unique(dense.face_index[visible_index])
                on_seen = int(np.count_nonzero(np.isin(dense.face_index, seen_faces)))
                extra = top_up(
                    triangles, seen_faces, n_points - len(visible_index),
                    lambda p, f, camera=camera: candidates_visible(camera, p, f),
                    seed=seed, key=key, pose_index=pose_index, n_points=n_points,
                    visible_fraction=len(visible_index) / on_seen,
                )  # fmt: skip
            chosen = pose_samples(
                visible_index, n_points, seed=seed, key=key, pose_index=pose_index,
                sample_indices=range(samples_per_view), n_dense=n_dense, n_topped_up=len(extra),
            )  # fmt: skip
            clouds = _pose_clouds(dense.points, dense.face_index, extra, chosen, (el, az), len(visible_index), cameras, provenance)
            yield PoseResult(pose_index, visible, extra, clouds)
    finally:
        if scene is not None:
            scene.release()


def occlude_point_set(
    points: NDArray[np.floating],
    poses: Sequence[tuple[float, float]],
    *,
    key: int,
    normals: NDArray[np.floating] | None = None,
    n_points: int = DEFAULT_N_POINTS,
    samples_per_view: int = DEFAULT_SAMPLES_PER_VIEW,
    seed: int = DEFAULT_SEED,
    cameras: CameraSphere = CameraSphere(),
    provenance: ObjectProvenance = ObjectProvenance(),
) -> Iterator[PoseResult]:
    """Yield a :class:`PoseResult` for each pose of one point-set object, as :func:`occlude_poses` does for a mesh.

    The object's dense cloud is ``points`` itself (nothing is sampled).  Its surfels are made
    once (:func:`~zbuf_occlude.visibility.point_splats.point_surfels`, with ``normals`` where
    given, else normals estimated from the points) and tested from the camera of every pose
    (:meth:`~zbuf_occlude.visibility.point_splats.PointSurfels.visible`); the samples are drawn
    from the visible points as a mesh's are (:func:`~zbuf_occlude.geometry.samples.pose_samples`,
    the same seeds), so a compact data set redraws them.  A point set has no faces: nothing is
    topped up (a pose that sees fewer than ``n_points`` gives samples padded with repeats) and
    every sample's ``face_index`` is :data:`NO_FACE`.

    Parameters
    ----------
    points : (M, 3) float
        The object's points, normalised as a mesh is (largest side 1), world frame.
    poses : sequence of (elevation_deg, azimuth_deg)
    key : int
        The object's seed key (:func:`object_key` of a stable name).
    normals : (M, 3) float, optional
        The points' normals (any sign; their length is ignored).
    n_points, samples_per_view : int
        Points per sample and samples drawn per pose.
    seed : int
    cameras : CameraSphere
        The poses' camera distance (object units) and image size (pixels; the splat image is
        sized from the splats, not from it).
    provenance : ObjectProvenance
        The object's ``label``, ``class_name``, ``source`` and ``split``, copied into every cloud.

    Raises
    ------
    InvalidInputError
        ``n_points < 1``, ``samples_per_view < 0``, or bad points or normals (shape, NaN/inf,
        zero normals).
    InsufficientMemoryError
        The object's job would not fit in the memory available, checked before any allocation.
    CameraError
        A pose or ``cameras`` gives no valid camera (:meth:`CameraSphere.camera`).
    """
    from zbuf_occlude.visibility.point_splats import point_surfels

    _check_counts(n_points, samples_per_view)
    check_memory(
        estimate_job_memory(
            points=int(n_points), samples_per_view=int(samples_per_view), dense_points=len(points), resolution=cameras.resolution
        )
    )
    surfels = point_surfels(points, normals)
    n_dense = len(surfels.points)
    no_face = np.full(n_dense, NO_FACE, dtype=np.int64)
    for pose_index, (el, az) in enumerate(poses):
        camera = cameras.camera(el, az)
        visible = surfels.visible(camera)
        visible_index = np.flatnonzero(visible)
        if len(visible_index) == 0 and samples_per_view:
            log.warning("%s: nothing visible from el=%g az=%g; no sample", provenance.source or "point set", el, az)
        chosen = pose_samples(
            visible_index, n_points, seed=seed, key=key, pose_index=pose_index, sample_indices=range(samples_per_view),
            n_dense=n_dense,
        )  # fmt: skip
        clouds = _pose_clouds(surfels.points, no_face, TopUp(), chosen, (el, az), len(visible_index), cameras, provenance)
        yield PoseResult(pose_index, visible, TopUp(), clouds)


def occlude_object(
    mesh: trimesh.Trimesh, poses: Sequence[tuple[float, float]], *, key: int, **options
) -> Iterator[tuple[int, NDArray[np.bool_], list[OccludedCloud]]]:
    """Yield ``(pose_index, visible (M,) bool, clouds)`` for each pose of one object.

    :func:`occlude_poses` (same keywords, same samples) without the top-up points: a pose that
    sees fewer than ``n_points`` dense points is topped up with visible points on the faces it
    sees; with ``samples_per_view=0`` no sample draws from them, so nothing is topped up.

    Raises
    ------
    InvalidInputError, InsufficientMemoryError
        As :func:`occlude_poses`.
    """
    draws = options.pop("draws", PoseDraws())
    if draws.samples_per_view == 0:  # the masks alone: no sample would draw from the top-up points
        draws = replace(draws, topped_up=False)
    for result in occlude_poses(mesh, poses, key=key, draws=draws, **options):
        yield result.pose_index, result.visible, result.clouds


def _is_normalised(mesh: trimesh.Trimesh) -> bool:
    lo, hi = mesh.bounds
    return bool(np.all(np.abs(lo + hi) <= 2 * NORMALISED_ATOL) and abs(float(np.max(hi - lo)) - 1.0) <= NORMALISED_ATOL)


def occlude(
    mesh_or_path: trimesh.Trimesh | str | os.PathLike,
    views: str | Sequence[tuple[float, float]] = DEFAULT_VIEWS,
    n_points: int = DEFAULT_N_POINTS,
    samples_per_view: int = DEFAULT_OCCLUDE_SAMPLES_PER_VIEW,
    seed: int = DEFAULT_SEED,
    method: str = DEFAULT_METHOD,
    *,
    dense_points: int = DEFAULT_DENSE_POINTS,
    resolution: int = DEFAULT_RESOLUTION,
    radius: float = DEFAULT_RADIUS,
    name: str | None = None,
) -> list[OccludedCloud]:
    """Occluded point clouds of one mesh from many poses: the one-call version of ``generate``.

    Samples a dense cloud of ``dense_points`` on the surface (Sryamkin et al. 2023,
    Algorithms 1–2), decides which points a camera on a sphere of ``radius`` sees from each
    pose (``method``, :func:`~zbuf_occlude.visibility.visible_mask`), and draws
    ``samples_per_view`` samples of ``n_points`` visible points per pose, without
    replacement (paper §3.4, §4.3).  The same pipeline as ``zbuf-occlude generate``
    (:func:`occlude_object`): for a mesh file and the same options, the clouds equal the
    samples ``generate`` writes for it, bit for bit.

    Parameters
    ----------
    mesh_or_path : trimesh.Trimesh, str or PathLike
        A mesh file (OFF, OBJ, PLY, STL, GLB; loaded and normalised by
        :func:`~zbuf_occlude.load_mesh`) or a mesh.  A mesh whose bounding box is centred with
        largest side 1 (as :func:`~zbuf_occlude.load_mesh` returns) is used as it is; any other
        is normalised first (a copy, :func:`~zbuf_occlude.normalize_mesh`).
    views : str or sequence of (elevation_deg, azimuth_deg)
        A schedule name of :func:`~zbuf_occlude.view_schedule` (``"grid25"``, ``"paper100"``,
        ``"fibonacci:N"``, ``"EL:AZ,..."``) or the poses themselves, degrees.
    n_points : int
        Points per cloud (PointNet's 2048).
    samples_per_view : int
        Clouds drawn per pose.
    seed : int
        Non-negative; with ``name`` it fixes every random draw.
    method : str
        Visibility method (``zbuf-occlude info`` lists them; ``"auto"`` picks per machine).
    dense_points : int
        Points sampled on the whole surface before hidden-surface removal.
    resolution : int
        Z-buffer image size, pixels (image-space methods).
    radius : float
        Camera distance from the centre, object units (the object's largest side is 1).
    name : str, optional
        The object's name, which keys its random draws (:func:`object_key`).  Default: the
        file's stem for a path (as ``generate FILE`` names it), ``""`` for a mesh.  To get the
        samples ``generate ROOT`` wrote, pass the path relative to ``ROOT`` without the suffix,
        e.g. ``"chair/train/chair_0001"``.

    Returns
    -------
    clouds : list of OccludedCloud
        Pose-major, then sample index; a pose that sees nothing gives none.  Each has
        ``points (n_points, 3) float32`` in the normalised mesh's frame (object units, on
        the mesh's faces), ``face_index (n_points,) int64`` into the mesh's faces,
        ``elevation_deg``, ``azimuth_deg`` (degrees), ``radius``, ``sample_index``,
        ``n_visible``, the distinct visible points its pose offered, and ``n_topped_up``, how
        many of them were drawn on the faces the pose sees because it saw fewer than
        ``n_points`` dense points (:func:`occlude_poses`).  Only when even then ``n_visible <
        n_points`` (a tiny visible surface) does the cloud hold every visible point once plus
        repeats (``cloud.padded``), and a :class:`PaddedSamplesWarning` says how many clouds are.

    Raises
    ------
    MeshLoadError
        The file is missing, unreadable or not a usable mesh.
    InvalidInputError
        Not a path or a ``trimesh.Trimesh``, a bad view schedule, ``n_points < 1``,
        ``samples_per_view < 0``, a negative seed, an unknown method, or a job too large for
        the memory available.
    CameraError
        ``radius`` puts the camera inside the object's bounding sphere.
    BackendUnavailable
        The method needs an OpenGL context or a library that is missing.

    Examples
    --------
    >>> clouds = occlude("data/samples/chair/train/chair_0001.off", views="grid25", n_points=1024)
    >>> clouds[0].points.shape, clouds[0].elevation_deg, clouds[0].azimuth_deg
    ((1024, 3), -80.0, 0.0)
    """
    import trimesh

    from zbuf_occlude.mesh.load import load_mesh, normalize_mesh

    if isinstance(mesh_or_path, trimesh.Trimesh):
        mesh = mesh_or_path if _is_normalised(mesh_or_path) else normalize_mesh(mesh_or_path)
        default_name, source = "", ""
    elif not isinstance(mesh_or_path, (str, os.PathLike)):  # a point cloud, a Scene, an array...
        raise InvalidInputError(
            f"occlude needs a mesh file or a trimesh.Trimesh (faces occlude), got {type(mesh_or_path).__name__}; "
            "a trimesh.Scene: scene.to_mesh(); a point cloud has no faces to hide anything"
        )
    else:
        mesh = load_mesh(mesh_or_path)
        default_name, source = Path(mesh_or_path).stem, str(mesh_or_path)
    poses = view_schedule(views) if isinstance(views, str) else [(float(el), float(az)) for el, az in views]
    key = object_key(default_name if name is None else name)
    if dense_points is None or int(dense_points) < 1:
        raise InvalidInputError(f"dense_points must be an integer >= 1, got {dense_points!r}")
    dense = dense_cloud(mesh, key, seed=seed, count=int(dense_points))
    clouds = [
        c
        for _, _, pose_clouds in occlude_object(
            mesh,
            poses,
            key=key,
            draws=PoseDraws(n_points, samples_per_view),
            seed=seed,
            dense=dense,
            method=method,
            cameras=CameraSphere(radius, resolution),
            provenance=ObjectProvenance(source=source),
        )
        for c in pose_clouds
    ]
    n_padded = sum(c.padded for c in clouds)
    if n_padded:
        warnings.warn(
            f"{n_padded} of {len(clouds)} clouds hold repeated points: fewer than n_points={n_points} points were "
            f"visible from their poses, top-up included (each cloud's n_visible says how many; lower n_points)",
            PaddedSamplesWarning, stacklevel=2,
        )  # fmt: skip
    return clouds
