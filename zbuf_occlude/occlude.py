"""Occluded samples of one object from many poses: the unit of work of ``generate`` and the farm.

Per object (Sryamkin et al. 2023, §3.4 and §4.3): sample a dense cloud once, decide its
visibility from every pose, and draw ``samples_per_view`` fixed-size samples per pose from
the visible points.  Every random draw has its own generator derived from
``(seed, object_key, pose_index, sample_index)`` with :class:`numpy.random.SeedSequence`,
so results are identical whatever the order, the worker count or the sharding.

:func:`occlude` is the one-call version, ``zbuf_occlude.occlude(...)``: the package attribute
``occlude`` is that function, so take this module's other names with ``from
zbuf_occlude.occlude import ...`` (or ``importlib.import_module("zbuf_occlude.occlude")``).
"""

from __future__ import annotations

import hashlib
import logging
import os
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from .cameras import DEFAULT_RADIUS, Camera, camera_on_sphere, view_schedule
from .defaults import (
    DEFAULT_DENSE_POINTS,
    DEFAULT_METHOD,
    DEFAULT_N_POINTS,
    DEFAULT_OCCLUDE_SAMPLES_PER_VIEW,
    DEFAULT_RESOLUTION,
    DEFAULT_SAMPLES_PER_VIEW,
    DEFAULT_SEED,
    DEFAULT_VIEWS,
)
from .errors import InvalidInputError
from .resources import check_memory, estimate_job_memory
from .sampling import check_seed, sample_surface
from .visibility.registry import check_keywords, method_info, resolution_option, visible_mask

if TYPE_CHECKING:  # trimesh (and scipy) is imported by occlude(), which takes files and meshes
    import trimesh

__all__ = [
    "OccludedCloud", "object_key", "derive_rng", "sample_rng", "draw_sample", "pose_samples", "count_padded",
    "DenseCloud", "dense_cloud", "occlude_object", "occlude", "PaddedSamplesWarning",
]  # fmt: skip

log = logging.getLogger(__name__)

#: Stream tags keep the dense-sampling and the per-sample generators independent.
_DENSE_STREAM, _DRAW_STREAM = 0, 1
#: :func:`occlude` uses a given mesh as it is when its bounding box is already centred with
#: largest side 1 within this (object units): normalising again is not bit-exact, and the
#: samples must equal those ``generate`` writes from the same file.
NORMALISED_ATOL = 1e-9


class PaddedSamplesWarning(UserWarning):
    """Some samples hold repeated points: fewer points were visible than a sample holds."""


@dataclass
class OccludedCloud:
    """One occluded sample: a fixed-size point set seen from one pose.

    Attributes
    ----------
    points : (n, 3) float32
        World (object) frame, normalised mesh units.
    face_index : (n,) int64
        Face of the source mesh each point lies on.
    elevation_deg, azimuth_deg, radius : float
        The camera pose (degrees, degrees, object units).
    label : int
        Class index (−1 if unknown).
    class_name, source : str
        Class name and source mesh path.
    split : str
        The data-set split of the source mesh (``"train"``, ``"test"``; ``""`` if unknown).
    sample_index : int
        Which of the pose's random draws this is.
    n_visible : int
        Visible points in the dense cloud for this pose.  If ``n_visible < n``, the
        sample holds every visible point once plus repeats drawn at random (``padded``).
    """

    points: NDArray[np.float32]
    face_index: NDArray[np.int64]
    elevation_deg: float
    azimuth_deg: float
    radius: float
    label: int = -1
    class_name: str = ""
    source: str = ""
    sample_index: int = 0
    n_visible: int = 0
    split: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def padded(self) -> bool:
        """True if fewer points were visible than the sample holds (repeats added)."""
        return self.n_visible < len(self.points)


def object_key(name: str) -> int:
    """A stable 64-bit key of an object's name (BLAKE2b), for seeding.

    64 bits make a collision between two objects' seeds negligible even over all of
    ShapeNet (~5e-12 for 1e4 objects; a 32-bit CRC would give ~1 %).
    """
    # surrogateescape: a name from a non-UTF-8 file name (PEP 383) keys on its original
    # bytes; valid UTF-8 names give the same bytes, and so the same keys, as before.
    return int.from_bytes(hashlib.blake2b(name.encode("utf-8", "surrogateescape"), digest_size=8).digest(), "little")


def derive_rng(seed: int, *keys: int) -> np.random.Generator:
    """An independent generator for ``(seed, *keys)`` (``numpy.random.SeedSequence``).

    Raises InvalidInputError (:func:`~zbuf_occlude.sampling.check_seed`) for a negative seed.
    """
    if seed is None or isinstance(seed, np.random.Generator):
        raise InvalidInputError(f"seed must be a non-negative integer here (it is mixed with keys), got {seed!r}")
    return np.random.default_rng(np.random.SeedSequence([check_seed(seed), *(int(k) for k in keys)]))


def sample_rng(seed: int, key: int, pose_index: int, sample_index: int) -> np.random.Generator:
    """The generator of one sample's draw: ``(seed, key, pose_index, sample_index)``.

    Readers of compact data sets call it to redraw exactly the samples the farm drew.
    """
    return derive_rng(seed, key, _DRAW_STREAM, pose_index, sample_index)


def draw_sample(
    visible_index: NDArray[np.int64], n_points: int, rng: np.random.Generator
) -> tuple[NDArray[np.int64], int]:
    """Draw ``n_points`` indices without replacement from ``visible_index``.

    If fewer are visible, all of them are taken once and the rest are repeats drawn
    uniformly at random (PointNet-style padding); the caller sees that from the returned
    count of visible points.

    Returns
    -------
    chosen : (n_points,) int64
        Indices into the dense cloud (empty if nothing is visible).
    n_visible : int
    """
    n_visible = len(visible_index)
    if n_visible == 0:
        return np.zeros(0, dtype=np.int64), 0
    if n_visible >= n_points:
        return rng.choice(visible_index, size=n_points, replace=False), n_visible
    extra = rng.choice(visible_index, size=n_points - n_visible, replace=True)
    return rng.permutation(np.concatenate([visible_index, extra])), n_visible


def pose_samples(
    visible_index: NDArray[np.int64],
    n_points: int,
    *,
    seed: int,
    key: int,
    pose_index: int,
    sample_indices: Iterable[int],
) -> list[NDArray[np.int64]]:
    """The samples of one pose: for each sample index, ``n_points`` indices into the dense
    cloud, drawn by :func:`draw_sample` with :func:`sample_rng`.

    The one place samples are drawn, for the writers and for readers that rebuild samples
    from stored visibility masks, so both give the same bytes.

    Returns
    -------
    chosen : list of (n_points,) int64
        One per sample index; empty if nothing is visible.
    """
    if len(visible_index) == 0:
        return []
    return [draw_sample(visible_index, n_points, sample_rng(seed, key, pose_index, s))[0] for s in sample_indices]


def count_padded(n_visible: Sequence[int] | NDArray[np.integer], n_points: int, samples_per_view: int) -> int:
    """How many samples of an object were padded with repeats (:func:`draw_sample`).

    Parameters
    ----------
    n_visible : (P,) int
        Visible points of the dense cloud per pose (a record's ``n_visible``).
    n_points, samples_per_view : int
        Points per sample; samples drawn per pose (a pose that sees nothing has none).

    Returns
    -------
    int
        ``samples_per_view`` times the number of poses with ``0 < n_visible < n_points``.
    """
    nv = np.asarray(n_visible, dtype=np.int64)
    return int(np.count_nonzero((nv > 0) & (nv < int(n_points)))) * int(samples_per_view)


@dataclass
class DenseCloud:
    """The per-object dense cloud (sampled once, reused for every pose, paper §3.4)."""

    points: NDArray[np.float64]
    face_index: NDArray[np.int64]


def dense_cloud(
    mesh: trimesh.Trimesh, key: int, *, seed: int = 0, count: int | None = DEFAULT_DENSE_POINTS, density: float | None = None
) -> DenseCloud:
    """Sample the object's dense cloud with the generator of ``(seed, key)``.

    ``count`` points area-weighted, or ``density`` points per unit area (Algorithm 1).
    """
    rng = derive_rng(seed, key, _DENSE_STREAM)
    if density is not None:
        points, face_index = sample_surface(mesh, density=density, seed=rng)
    else:
        points, face_index = sample_surface(mesh, count=count, seed=rng)
    return DenseCloud(points, face_index)


def occlude_object(
    mesh: trimesh.Trimesh,
    poses: Sequence[tuple[float, float]],
    *,
    key: int,
    n_points: int = DEFAULT_N_POINTS,
    samples_per_view: int = DEFAULT_SAMPLES_PER_VIEW,
    seed: int = DEFAULT_SEED,
    dense: DenseCloud | None = None,
    method: str = DEFAULT_METHOD,
    resolution: int = DEFAULT_RESOLUTION,
    radius: float = DEFAULT_RADIUS,
    label: int = -1,
    class_name: str = "",
    source: str = "",
    split: str = "",
    **method_options,
) -> Iterator[tuple[int, NDArray[np.bool_], list[OccludedCloud]]]:
    """Yield ``(pose_index, visible (M,) bool, clouds)`` for each pose of one object.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Normalised (max extent 1), world frame.
    poses : sequence of (elevation_deg, azimuth_deg)
    key : int
        The object's seed key (:func:`object_key` of a stable name).
    n_points, samples_per_view : int
        Points per sample and samples drawn per pose.
    dense : DenseCloud, optional
        Default: :func:`dense_cloud` ``(mesh, key, seed=seed)``.
    method : str
        Visibility method; image-space methods keep the points on the GPU across poses.
    resolution, radius : camera image size (pixels) and distance (object units).
    label, class_name, source, split
        Copied into every cloud (:class:`OccludedCloud`).

    Raises
    ------
    InvalidInputError
        ``n_points < 1`` or ``samples_per_view < 0``.
    InsufficientMemoryError
        (an InvalidInputError) The object's job would not fit in the memory available
        (:func:`zbuf_occlude.resources.check_memory`), checked before any allocation.
    """
    if n_points < 1 or samples_per_view < 0:
        raise InvalidInputError(f"need n_points >= 1 and samples_per_view >= 0, got {n_points}, {samples_per_view}")
    check_keywords(method, method_options)  # a misspelt option must not run with the default
    # Refuse before allocating what cannot fit (the OOM killer gives no message).
    check_memory(
        estimate_job_memory(
            points=int(n_points), samples_per_view=int(samples_per_view),
            dense_points=len(dense.points) if dense is not None else DEFAULT_DENSE_POINTS,
            resolution=resolution, faces=len(mesh.faces),
        )
    )  # fmt: skip
    dense = dense or dense_cloud(mesh, key, seed=seed)
    session = method_info(method).session
    scene = session(mesh, dense.points, dense.face_index) if session is not None else None
    one_shot_options = {**resolution_option(method, resolution), **method_options}
    try:
        for pose_index, (el, az) in enumerate(poses):
            camera: Camera = camera_on_sphere(el, az, radius, resolution=resolution)
            if scene is not None:
                visible = scene.visible(camera, **method_options)
            else:
                visible = visible_mask(mesh, dense.points, camera, method, face_index=dense.face_index, **one_shot_options)
            visible_index = np.flatnonzero(visible)
            if len(visible_index) == 0 and samples_per_view:
                log.warning("%s: nothing visible from el=%g az=%g; no sample", source or "mesh", el, az)
            chosen = pose_samples(
                visible_index, n_points, seed=seed, key=key, pose_index=pose_index, sample_indices=range(samples_per_view)
            )
            clouds = [
                OccludedCloud(
                    points=dense.points[c].astype(np.float32),
                    face_index=dense.face_index[c],
                    elevation_deg=float(el),
                    azimuth_deg=float(az),
                    radius=float(radius),
                    label=label,
                    class_name=class_name,
                    source=source,
                    sample_index=sample_index,
                    n_visible=len(visible_index),
                    split=split,
                )
                for sample_index, c in enumerate(chosen)
            ]
            yield pose_index, visible, clouds
    finally:
        if scene is not None:
            scene.release()


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
        ``elevation_deg``, ``azimuth_deg`` (degrees), ``radius``, ``sample_index``, and
        ``n_visible``, the dense points visible from its pose.  When ``n_visible <
        n_points`` the cloud holds every visible point once plus repeats (``cloud.padded``),
        and a :class:`PaddedSamplesWarning` says how many clouds are.

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

    from .mesh import load_mesh, normalize_mesh

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
            mesh, poses, key=key, n_points=n_points, samples_per_view=samples_per_view, seed=seed, dense=dense,
            method=method, resolution=resolution, radius=radius, source=source,
        )  # fmt: skip
        for c in pose_clouds
    ]
    n_padded = sum(c.padded for c in clouds)
    if n_padded:
        warnings.warn(
            f"{n_padded} of {len(clouds)} clouds hold repeated points: fewer than n_points={n_points} points were "
            f"visible from their poses (each cloud's n_visible says how many; raise dense_points or lower n_points)",
            PaddedSamplesWarning, stacklevel=2,
        )  # fmt: skip
    return clouds
