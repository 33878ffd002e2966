"""Occlusion on the fly: a new random view of every object in every epoch, nothing stored.

:class:`RandomOcclusion` turns an object's dense cloud (with ``face_index``) and its mesh into
one occluded sample: a camera pose is drawn from a :class:`PoseDistribution`, hidden surface
removal keeps the visible points (:func:`zbuf_occlude.visibility.registry.visible_mask`'s
session of the method, CPU ``embree-fast`` by default), and ``n_points`` of them are drawn
(:func:`zbuf_occlude.geometry.samples.draw_sample`: every visible point once before any repeat).
:class:`OnTheFlyOccludedDataset` does this for the meshes under a folder, with the labels and
splits ``generate`` and the farm give them and the farm's dense clouds
(:func:`zbuf_occlude.pipeline.dense_cloud`, same seed, same points).

Point sets (clouds without a mesh: PointNet-layout HDF5, ``.npy``, ``.ply`` point clouds,
:mod:`zbuf_occlude.io.point_sets`) take the same path, with visibility decided from the points
alone (:func:`zbuf_occlude.visibility.point_splats.point_surfels`, once per object and kept up
to :data:`PREPARED_CACHE_BYTES` per process, and its ``visible`` per view) and every sample a subset of the cloud; the data set reads them as the
farm does (:func:`zbuf_occlude.mesh.inputs.point_sets.load_cloud`).

Determinism: sample ``index`` of epoch ``epoch`` uses the generator ``(seed, 3, epoch, index)``
(:func:`zbuf_occlude.geometry.samples.derive_rng`), whatever the worker, the order or the batch size.

DataLoader workers: visibility sessions (Embree scenes, GL objects) are cached per process (an
entry made before a ``fork`` is never used after it); meshes and dense clouds are plain numpy
and are inherited.  The default method runs on the CPU (Embree), so workers need no GL
context.  The epoch reaches the workers in one of two ways: :class:`EpochSampler` sends
``(epoch, index)`` with every index, or ``set_epoch`` on the data set before each epoch, which
writes it to shared memory (:class:`SharedEpoch`) that every worker reads, persistent workers
(``persistent_workers=True``, which keep the caches warm across epochs) included.

Arguments are checked where they are given, as the rest of the API's are: a wrong kind (text
where a count goes, a tuple where a :class:`PoseDistribution` goes) is an
:class:`~zbuf_occlude.errors.ArgumentTypeError`, a wrong value (``n_points=2.7``, a negative
index) an :class:`~zbuf_occlude.errors.InvalidInputError` naming it, never truncated to a
neighbour; a count whose samples would not fit in memory
(:data:`BYTES_PER_ON_THE_FLY_POINT`) is refused when it is given
(:class:`~zbuf_occlude.errors.InsufficientMemoryError`), not when a sample asks for it.
"""

from __future__ import annotations

import functools
import hashlib
import math
import multiprocessing
import multiprocessing.context
import numbers
import os
from collections import OrderedDict
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude.defaults import MAX_POINTS, MAX_SAMPLES, MAX_SEED
from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.geometry.arguments import check_flag, check_points, described
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS, camera_on_sphere
from zbuf_occlude.geometry.samples import derive_rng, draw_sample
from zbuf_occlude.io.point_sets import POINT_SET_SUFFIXES, PointSet
from zbuf_occlude.learn import require_torch
from zbuf_occlude.learn.data import normalize_batch
from zbuf_occlude.mesh.inputs.kinds import INPUT_KINDS, POINT_SET
from zbuf_occlude.mesh.inputs.plan import FarmObject, scan_inputs
from zbuf_occlude.mesh.inputs.point_sets import cloud_frame, load_cloud
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.mesh.scene import UP_AXES, UP_CHOICES
from zbuf_occlude.pipeline import DenseCloud, dense_cloud
from zbuf_occlude.resources import BYTES_PER_DENSE_POINT, check_memory
from zbuf_occlude.sensors.checks import count, is_number, real, reals
from zbuf_occlude.visibility.point_splats import PointSurfels, point_surfels
from zbuf_occlude.visibility.registry import method_info, resolution_option, visible_mask

__all__ = [
    "PoseDistribution",
    "RandomOcclusion",
    "OnTheFlyOccludedDataset",
    "EpochSampler",
    "SharedEpoch",
    "ProcessCache",
    "DEFAULT_ON_THE_FLY_METHOD",
    "DEFAULT_DENSE_ON_THE_FLY",
    "BYTES_PER_ON_THE_FLY_POINT",
    "PREPARED_CACHE_BYTES",
    "prepared_bytes",
    "prepared_cache_bytes",
]

#: The CPU method: exact, threaded Embree, no GL context to carry into forked workers.
DEFAULT_ON_THE_FLY_METHOD = "embree-fast"
#: Dense points per object, sampled once per worker (32,768 = 16 × a 2,048-point sample).
DEFAULT_DENSE_ON_THE_FLY = 32_768
#: Image resolution passed to image-space methods, pixels (embree-fast ignores it).
_RESOLUTION = 512
_ON_THE_FLY_STREAM = 3  # occlude.py uses streams 0 and 1, the protocols 2
_CACHE_SIZE = 64  # objects per process: meshes, dense clouds and sessions
#: Bytes of prepared point sets (:func:`~zbuf_occlude.visibility.point_splats.point_surfels`)
#: each process keeps, 2 GiB: ModelNet40's 9,843 training clouds of 2,048 points take 2.7 GB
#: (:func:`prepared_bytes`), so that most items of an epoch pay one view, not the preparation
#: (about 4x a view's time at 2,048 points).  Half the available memory when that is less.
PREPARED_CACHE_BYTES = 2 * 1024**3
#: Prepared point sets kept per process at most, whatever their size.
_PREPARED_CACHE_SIZE = 1_000_000
#: Bytes one point of a sample costs while it is drawn: the draw's indices and their padding,
#: the float64 gather of the points, normalize_batch's float64 copies and the float32 result,
#: the face or point index kept.  100 B measured at the peak of a 2,000,000-point sample of a
#: mesh and of a point set (tracemalloc); rounded up.
BYTES_PER_ON_THE_FLY_POINT = 128
#: Largest index or epoch: both are keys of the sample's generator, int64 wherever they are kept.
_MAX_KEY = 2**63 - 1


def _whole(value: object, name: str, *, low: int, high: int) -> int:
    """``value`` as an int: a whole number from ``low`` to ``high`` (``3`` or ``3.0``, never ``2.7``
    taken as 2: :func:`zbuf_occlude.sensors.checks.count`); what is no number at all (text,
    None, a bool) is an ArgumentTypeError."""
    if not is_number(value):
        raise ArgumentTypeError(f"{name} must be an integer, got {described(value)}")
    return count(value, name, low=low, high=high)


class SharedEpoch:
    """An epoch number shared with the processes a DataLoader forks or spawns from this one.

    ``set_epoch`` in the main process must reach workers that outlive an epoch
    (``persistent_workers=True``): a plain attribute would stay at the value the worker was
    made with, and every epoch would repeat the first one's views.  Pickled outside the start
    of a process (``copy.deepcopy``, saving), it becomes an unshared copy of its value.
    """

    def __init__(self, value: int = 0):
        self._shared = multiprocessing.RawValue("q", int(value))

    @property
    def value(self) -> int:
        return int(self._shared.value)

    @value.setter
    def value(self, epoch: int) -> None:
        self._shared.value = int(epoch)

    def __getstate__(self) -> dict:
        if multiprocessing.context.get_spawning_popen() is not None:  # a worker being started: share
            return {"shared": self._shared}
        return {"value": self.value}

    def __setstate__(self, state: dict) -> None:
        self._shared = state["shared"] if "shared" in state else multiprocessing.RawValue("q", int(state["value"]))


@dataclass(frozen=True)
class PoseDistribution:
    """Where the random camera is: on a sphere band around the object, looking at its centre.

    Attributes
    ----------
    elevation_deg : (low, high)
        Degrees, within [−90, 90].
    azimuth_deg : (low, high)
        Degrees.
    radius : float
        Object units (the mesh normalised to maximum extent 1).
    uniform_area : bool
        True: directions uniform in area on the band (``sin(el)`` uniform); False: the
        elevation angle itself uniform (as ModelNet40-C draws it).

    Raises
    ------
    InvalidInputError
        A bound or the radius that is not a finite number (naming it), bounds that are not a
        pair, out of order or out of range, or a radius inside the object's bounding sphere.
    ArgumentTypeError
        ``uniform_area`` not a bool.
    """

    elevation_deg: tuple[float, float] = (-90.0, 90.0)
    azimuth_deg: tuple[float, float] = (0.0, 360.0)
    radius: float = DEFAULT_RADIUS
    uniform_area: bool = True

    def __post_init__(self) -> None:
        # kinds first, each named; then the pairs as floats (a list given compares and hashes as the tuple)
        object.__setattr__(self, "elevation_deg", reals(self.elevation_deg, "elevation_deg", lengths=(2,)))
        object.__setattr__(self, "azimuth_deg", reals(self.azimuth_deg, "azimuth_deg", lengths=(2,)))
        object.__setattr__(self, "radius", real(self.radius, "radius", low=0.0, low_open=True))
        object.__setattr__(self, "uniform_area", check_flag(self.uniform_area, "uniform_area"))
        (el0, el1), (az0, az1) = self.elevation_deg, self.azimuth_deg
        if not (-90.0 <= el0 <= el1 <= 90.0) or not (az0 <= az1) or not all(map(math.isfinite, (az0, az1, self.radius))):
            raise InvalidInputError(
                f"bad pose distribution: elevation {self.elevation_deg}, azimuth {self.azimuth_deg}, radius {self.radius}"
            )
        camera_on_sphere(0.0, 0.0, self.radius, resolution=8)  # raises CameraError for a radius inside the object

    @classmethod
    def modelnet40c(cls, severity: int) -> PoseDistribution:
        """ModelNet40-C's occlusion cameras (:func:`zbuf_occlude.protocols.modelnet40c.occlusion_pose`).

        Their ``angle_x ~ U[2π/3, 5π/6]`` and ``angle_z ~ U[θ ± π/5]``, ``θ = 2π·severity/5``, put
        the camera at elevation ``angle_x − 90°`` ∈ [30°, 60°] and azimuth ``angle_z + 90°``,
        3 units from an object of maximum extent 2: radius 1.5 here (maximum extent 1).
        """
        theta = 72.0 * _whole(severity, "ModelNet40-C severity", low=1, high=5)
        return cls((30.0, 60.0), (theta + 90.0 - 36.0, theta + 90.0 + 36.0), 1.5, uniform_area=False)

    def draw(self, rng: np.random.Generator) -> tuple[float, float]:
        """One ``(elevation_deg, azimuth_deg)``."""
        (el0, el1), (az0, az1) = self.elevation_deg, self.azimuth_deg
        if self.uniform_area:
            s = rng.uniform(math.sin(math.radians(el0)), math.sin(math.radians(el1)))
            el = math.degrees(math.asin(min(1.0, max(-1.0, s))))
        else:
            el = rng.uniform(el0, el1)
        return float(el), float(rng.uniform(az0, az1))


class ProcessCache(OrderedDict):
    """A small LRU cache; with ``per_process`` it forgets what was made in another process (after a fork).

    It holds at most ``size`` entries and, with ``max_bytes``, at most that many bytes by
    ``nbytes(value)`` (the newest entry is kept whatever its size): the least recently used go first.
    """

    def __init__(self, size: int, *, per_process: bool = True, max_bytes: int | None = None, nbytes=None):
        super().__init__()
        self.size, self.pid, self.per_process = size, os.getpid(), per_process
        self.max_bytes, self.nbytes, self.held_bytes = max_bytes, nbytes, 0
        self._sizes: dict = {}

    def get_or_build(self, key, build):
        if self.per_process and self.pid != os.getpid():  # inherited across fork: Embree/GL state of the parent
            self.clear()
            self.pid = os.getpid()
        if key in self:
            self.move_to_end(key)
            return self[key]
        value = self[key] = build()
        if self.max_bytes is not None:
            self._sizes[key] = int(self.nbytes(value))
            self.held_bytes += self._sizes[key]
        while len(self) > self.size or (self.max_bytes is not None and len(self) > 1 and self.held_bytes > self.max_bytes):
            old_key, old = self.popitem(last=False)
            self.held_bytes -= self._sizes.pop(old_key, 0)
            if hasattr(old, "release"):
                old.release()
        return value

    def clear(self) -> None:
        super().clear()
        self._sizes.clear()
        self.held_bytes = 0

    def __reduce__(self):
        # what a cache holds (Embree scenes, GL objects) belongs to its process: a copy -- a
        # spawned DataLoader worker's -- starts empty (OrderedDict's own pickling called
        # ProcessCache() without its size, and copied the entries)
        return (functools.partial(type(self), self.size, per_process=self.per_process, max_bytes=self.max_bytes, nbytes=self.nbytes), ())


def prepared_bytes(surfels: PointSurfels) -> int:
    """Bytes a prepared cloud holds once it has been viewed: its arrays and their copies in Morton
    order (:attr:`~zbuf_occlude.visibility.point_splats.PointSurfels.order`), 136 B a point."""
    arrays = (surfels.points, surfels.normals, surfels.spacing, surfels.radius)
    return 2 * sum(a.nbytes for a in arrays) + surfels.order.nbytes


def prepared_cache_bytes() -> int:
    """The byte bound of each process's cache of prepared point sets: :data:`PREPARED_CACHE_BYTES`,
    or half the memory available when the cache is made, if that is less."""
    from zbuf_occlude.resources import available_memory

    free = available_memory()
    return PREPARED_CACHE_BYTES if free is None else min(PREPARED_CACHE_BYTES, free[0] // 2)


class RandomOcclusion:
    """One random occluded view of an object, as a transform.

    The object is a mesh with its dense cloud, or a point set (a
    :class:`~zbuf_occlude.io.point_sets.PointSet`, or an ``(N, 3)`` array): then visibility is
    decided from the points alone, with their normals where given
    (:func:`~zbuf_occlude.visibility.point_splats.point_surfels`, prepared once per object and
    kept in a per-process cache bounded by bytes, :data:`PREPARED_CACHE_BYTES`, so that an epoch
    over a data set of clouds pays one view per item;
    :meth:`~zbuf_occlude.visibility.point_splats.PointSurfels.visible` per view).

    Parameters
    ----------
    n_points : int
        Points per sample.
    poses : PoseDistribution
    seed : int
    method : str
        Visibility method of meshes (default :data:`DEFAULT_ON_THE_FLY_METHOD`, CPU, exact);
        point sets always use the point splats (the ``point-splat`` method, with normals).
    normalize : bool
        Centre each sample's bounding box and scale it to maximum extent 1, as the learn
        extra's training data (:func:`zbuf_occlude.learn.data.normalize_batch`).

    Raises
    ------
    InvalidInputError
        ``n_points`` not a whole number from 1 to :data:`~zbuf_occlude.defaults.MAX_POINTS`
        (``2.7`` is refused, not taken as 2), ``seed`` not one from 0 to
        :data:`~zbuf_occlude.defaults.MAX_SEED`, or an unknown method (each naming the value).
    ArgumentTypeError
        An argument of the wrong kind: text or None for ``n_points`` or ``seed``, anything but
        a :class:`PoseDistribution` for ``poses``, a str for ``method``, a bool for ``normalize``.
    InsufficientMemoryError
        A sample of ``n_points`` (:data:`BYTES_PER_ON_THE_FLY_POINT` each) would need more
        memory than is available.
    """

    def __init__(self, n_points: int = 2048, *, poses: PoseDistribution = PoseDistribution(), seed: int = 0,
                 method: str = DEFAULT_ON_THE_FLY_METHOD, normalize: bool = True):  # fmt: skip
        n_points = _whole(n_points, "n_points", low=1, high=MAX_POINTS)
        check_memory(n_points * BYTES_PER_ON_THE_FLY_POINT, option=f"n_points={n_points:,}", hint="lower n_points")
        if not isinstance(poses, PoseDistribution):
            raise ArgumentTypeError(f"poses must be a PoseDistribution, got {described(poses)}")
        if not isinstance(method, str):
            raise ArgumentTypeError(f"method must be the name of a visibility method, got {described(method)}")
        self.n_points, self.poses, self.normalize = n_points, poses, check_flag(normalize, "normalize")
        self.seed = _whole(seed, "seed", low=0, high=MAX_SEED)
        self.method = method_info(method).name
        self._epoch = SharedEpoch()
        self._sessions = ProcessCache(_CACHE_SIZE)
        # numpy only, safe across fork; bounded by bytes, not count: a data set's worth of clouds
        self._prepared = ProcessCache(_PREPARED_CACHE_SIZE, per_process=False, max_bytes=prepared_cache_bytes(), nbytes=prepared_bytes)

    @property
    def epoch(self) -> int:
        """The epoch whose views the next calls draw (:meth:`set_epoch`)."""
        return self._epoch.value

    def set_epoch(self, epoch: int) -> None:
        """Draw the views of ``epoch`` from now on, in this process and in every DataLoader worker
        made from it, persistent ones included (the epoch lives in shared memory).

        Raises
        ------
        InvalidInputError, ArgumentTypeError
            ``epoch`` not a whole number >= 0.
        """
        self._epoch.value = _whole(epoch, "epoch", low=0, high=_MAX_KEY)

    def _visible(self, key, mesh: trimesh.Trimesh, dense: DenseCloud, camera) -> NDArray[np.bool_]:
        session_of = method_info(self.method).session
        if session_of is None:
            return visible_mask(
                mesh, dense.points, camera, self.method, face_index=dense.face_index, **resolution_option(self.method, _RESOLUTION)
            )
        session = self._sessions.get_or_build(key, lambda: session_of(mesh, dense.points, dense.face_index))
        return session.visible(camera)

    def _surfels(self, key, cloud: PointSet, up: str) -> PointSurfels:
        """The point set's surfels in the poses' frame: its bounding box centred on 0 with maximum
        extent 1 (as a loaded mesh), its ``up`` axis turned to +z."""

        def build() -> PointSurfels:
            return point_surfels(*cloud_frame(cloud.points, cloud.normals, up, what=f"the point set {cloud.name!r}"))

        return self._prepared.get_or_build((key, up), build)

    def __call__(self, mesh: trimesh.Trimesh | PointSet | NDArray[np.floating], dense: DenseCloud | None = None,
                 index: int | None = None, *, key: object = None, epoch: int | None = None, up: str = "+z") -> dict:  # fmt: skip
        """The occluded sample ``index`` of the current epoch.

        Parameters
        ----------
        mesh : trimesh.Trimesh, PointSet or (N, 3) float array
            A mesh, normalised (maximum extent 1), world frame, with its ``dense`` cloud; or a
            point set alone (any units and frame: the poses are taken around its bounding
            box normalised to maximum extent 1).
        dense : DenseCloud
            Points on ``mesh`` and their ``face_index``; None for a point set.
        index : int
            The sample's index in its data set (with ``seed`` and the epoch, its generator).
            Required.
        key : hashable, optional
            Identifies the object for the per-process session cache (default: ``id``s of a
            mesh and its dense cloud, the content of a point set).
        epoch : int, optional
            Default: the one of :meth:`set_epoch`.
        up : str
            A point set's up axis (``+z``, ``+y``, ...: :data:`zbuf_occlude.mesh.scene.UP_AXES`),
            from which the elevation of the poses is measured; meshes are z up already.

        Returns
        -------
        dict
            ``points (n_points, 3) float32``, ``elevation_deg``, ``azimuth_deg`` (float),
            ``n_visible`` (int; 0: nothing visible, the sample is then all zeros), and
            ``face_index (n_points,) int64`` for a mesh, or for a point set
            ``point_index (n_points,) int64`` (rows of its cloud, −1 when nothing is visible)
            and, where it has normals, ``normals (n_points, 3) float32``.  Without
            ``normalize``, a point set's sample is in its own frame and units.

        Raises
        ------
        InvalidInputError
            No ``index``, a mesh without its dense cloud or a point set with one, an ``index``
            or ``epoch`` that is not a whole number >= 0, an unknown ``up`` axis, or bad points
            (:func:`~zbuf_occlude.visibility.point_splats.point_surfels`, or a cloud that
            cannot be normalised: :func:`~zbuf_occlude.mesh.inputs.point_sets.cloud_frame`).
        ArgumentTypeError
            A wrong kind: a dense cloud that is not a :class:`~zbuf_occlude.pipeline.DenseCloud`
            beside a mesh that is not a ``trimesh.Trimesh``, text where points or an index go,
            a ``key`` that cannot be hashed.
        """
        if index is None:
            raise InvalidInputError("RandomOcclusion needs the sample's index (with the seed and the epoch, it draws the view)")
        index = _whole(index, "index", low=0, high=_MAX_KEY)
        epoch = self.epoch if epoch is None else _whole(epoch, "epoch", low=0, high=_MAX_KEY)
        if key is not None and not isinstance(key, Hashable):
            raise ArgumentTypeError(f"key must be hashable (it keys the session cache), got {described(key)}")
        if isinstance(mesh, trimesh.Trimesh) if dense is None else isinstance(mesh, PointSet):
            raise InvalidInputError("RandomOcclusion takes a mesh with its dense cloud, or a point set alone (no dense cloud)")
        if dense is not None and not (isinstance(mesh, trimesh.Trimesh) and isinstance(dense, DenseCloud)):
            raise ArgumentTypeError(
                f"RandomOcclusion takes a trimesh.Trimesh and its DenseCloud (zbuf_occlude.pipeline.dense_cloud), got "
                f"{described(mesh)} and {described(dense)}"
            )
        rng = derive_rng(self.seed, _ON_THE_FLY_STREAM, epoch, index)
        el, az = self.poses.draw(rng)
        camera = camera_on_sphere(el, az, self.poses.radius, resolution=_RESOLUTION)
        if dense is None:
            return self._occlude_points(mesh, camera, rng, key, up, (el, az))
        visible = self._visible(key if key is not None else (id(mesh), id(dense)), mesh, dense, camera)
        chosen, n_visible = draw_sample(np.flatnonzero(visible), self.n_points, rng)
        if n_visible == 0:
            points, face = np.zeros((self.n_points, 3), np.float32), np.full(self.n_points, -1, np.int64)
        else:
            points, face = dense.points[chosen].astype(np.float32), dense.face_index[chosen]
            if self.normalize:
                points = normalize_batch(points[None])[0]
        return {"points": points, "face_index": face, "elevation_deg": el, "azimuth_deg": az, "n_visible": n_visible}

    def _occlude_points(self, cloud: PointSet | NDArray[np.floating], camera, rng: np.random.Generator, key: object, up: str,
                        pose: tuple[float, float]) -> dict:  # fmt: skip
        """:meth:`__call__`'s sample of a point set, its pose ``(elevation_deg, azimuth_deg)`` drawn already."""
        if not isinstance(up, str) or up not in UP_AXES:
            raise InvalidInputError(f"up must be one of {', '.join(UP_AXES)}, got {up!r}")
        if not isinstance(cloud, PointSet):
            cloud = PointSet(check_points(cloud), None, None, "points")
        check_points(cloud.points)  # a point set made by hand: (N, 3), finite
        if cloud.normals is not None and np.shape(cloud.normals) != cloud.points.shape:
            raise InvalidInputError(f"normals must have the shape of the points {cloud.points.shape}, got {np.shape(cloud.normals)}")
        if key is None:  # the content, not an id: a freed cloud's id is reused by the next one
            key = hashlib.blake2b(cloud.points.tobytes() + (b"" if cloud.normals is None else cloud.normals.tobytes())).digest()
        visible = self._surfels(key, cloud, up).visible(camera)
        chosen, n_visible = draw_sample(np.flatnonzero(visible), self.n_points, rng)
        if n_visible == 0:
            points, index = np.zeros((self.n_points, 3), np.float32), np.full(self.n_points, -1, np.int64)
            normals = None if cloud.normals is None else np.zeros((self.n_points, 3), np.float32)
        else:
            points, index = cloud.points[chosen].astype(np.float32), np.asarray(chosen, dtype=np.int64)
            normals = None if cloud.normals is None else cloud.normals[chosen].astype(np.float32)
            if self.normalize:
                points = normalize_batch(points[None])[0]
        out = {"points": points, "point_index": index, "elevation_deg": pose[0], "azimuth_deg": pose[1], "n_visible": n_visible}
        return out if normals is None else out | {"normals": normals}


class OnTheFlyOccludedDataset(require_torch().utils.data.Dataset):
    """Meshes or point sets in, a new occluded view of each per epoch out (a ``torch.utils.data.Dataset``).

    Parameters
    ----------
    mesh_root : path or sequence of paths
        Mesh files, point-set files (PointNet-layout HDF5, ``.npy``, ``.ply`` point clouds:
        :mod:`zbuf_occlude.io.point_sets`) and folders of them, found, named, labelled and split
        as ``generate`` and the farm do (:func:`zbuf_occlude.mesh.inputs.scan_inputs`; each
        cloud of a point-set file is one object, labelled by the file's labels and class list
        where it has them, else by its folders: :mod:`zbuf_occlude.mesh.inputs.point_sets`).
    split : str, optional
        Keep the objects of this split (``train``/``test`` from ModelNet's layout, or from
        PointNet's ``train_files.txt``/``test_files.txt``).
    n_points, poses, seed, method, normalize
        As :class:`RandomOcclusion` (``method`` applies to meshes).
    dense_points : int
        Dense cloud per mesh (:func:`zbuf_occlude.pipeline.dense_cloud`, the farm's seed
        stream, so the same points the farm would use with ``--seed``).  A point set's dense
        cloud is its own points, read as the farm reads them
        (:func:`zbuf_occlude.mesh.inputs.point_sets.load_cloud`: up axis turned to +z, bounding box
        centred, largest side 1), and its samples are rows of them.
    views_per_object : int
        Samples per object and epoch (the data set's length is objects × this).
    up : str
        The point sets' up axis (:data:`zbuf_occlude.mesh.scene.UP_CHOICES`; ``auto``: as
        stored, +z); PointNet's and ShapeNetPart's HDF5 files are +y up.  Meshes find theirs as
        :func:`~zbuf_occlude.mesh.load.load_mesh` does.

    Notes
    -----
    ``dataset[i]`` is ``(points, label)``: ``(n_points, 3)`` float32 tensor, int.
    :meth:`sample` gives the full dict of :class:`RandomOcclusion` plus ``label``, ``name``.

    Raises
    ------
    InvalidInputError
        Nothing found, no object in ``split``, an unknown ``up``, counts that are not whole
        numbers >= 1 (``views_per_object`` at most :data:`~zbuf_occlude.defaults.MAX_SAMPLES`,
        ``dense_points`` at most :data:`~zbuf_occlude.defaults.MAX_POINTS`), arguments
        :class:`RandomOcclusion` refuses, or a point-set file refused by its header, labels or
        the lists beside it (:func:`zbuf_occlude.io.point_sets.point_set_labels`,
        :func:`~zbuf_occlude.io.point_sets.shape_names`, naming it; a class or split list that
        links outside the file's folder is an :class:`~zbuf_occlude.errors.UnsafePathError`); a
        file whose cloud is damaged is refused when its sample is drawn, naming it.
    ArgumentTypeError
        ``mesh_root`` not a path or a sequence of paths, ``split`` or ``up`` not a str, and the
        wrong kinds :class:`RandomOcclusion` refuses.
    InsufficientMemoryError
        A mesh's dense cloud of ``dense_points`` would need more memory than is available.
    """

    def __init__(self, mesh_root: str | os.PathLike | Sequence[str | os.PathLike], *, split: str | None = None,
                 n_points: int = 2048, poses: PoseDistribution = PoseDistribution(), seed: int = 0,
                 method: str = DEFAULT_ON_THE_FLY_METHOD, normalize: bool = True,
                 dense_points: int = DEFAULT_DENSE_ON_THE_FLY, views_per_object: int = 1, up: str = "auto"):  # fmt: skip
        roots = [mesh_root] if isinstance(mesh_root, (str, os.PathLike)) else mesh_root
        if not isinstance(roots, (list, tuple)) or not roots or not all(isinstance(r, (str, os.PathLike)) for r in roots):
            raise ArgumentTypeError(f"mesh_root must be a path or a list of paths, got {described(mesh_root)}")
        if not isinstance(up, str) or up not in UP_CHOICES:
            raise InvalidInputError(f"up must be one of {', '.join(UP_CHOICES)}, got {up!r}")
        if split is not None and not isinstance(split, str):
            raise ArgumentTypeError(f"split must be a str ('train', 'test') or None, got {described(split)}")
        views_per_object = _whole(views_per_object, "views_per_object", low=1, high=MAX_SAMPLES)
        dense_points = _whole(dense_points, "dense_points", low=1, high=MAX_POINTS)
        check_memory(dense_points * BYTES_PER_DENSE_POINT, option=f"dense_points={dense_points:,}", hint="lower dense_points")
        self.occlusion = RandomOcclusion(n_points, poses=poses, seed=seed, method=method, normalize=normalize)
        scan = scan_inputs(list(roots), kinds=INPUT_KINDS)
        refused = [s for s in scan.skipped if Path(s.path).suffix.lower() in POINT_SET_SUFFIXES]
        if refused:  # generate and the farm record them and exit 1; a training set would silently lack them
            raise InvalidInputError(str(refused[0]) + (f" (and {len(refused) - 1} more point-set files)" if len(refused) > 1 else ""))
        names = {o.label: o.class_name for o in scan.objects}
        #: Class names by label (``shape_names.txt`` of the farm).
        self.shape_names = [names[i] for i in sorted(names)]
        self.objects: list[FarmObject] = [o for o in scan.objects if split is None or o.split == split]
        if not self.objects:
            raise InvalidInputError(f"no meshes or point sets of split {split!r} under {', '.join(map(str, roots))}")
        self.views_per_object, self.dense_points, self.seed, self.up = views_per_object, dense_points, self.occlusion.seed, up
        self._objects_cache = ProcessCache(_CACHE_SIZE, per_process=False)  # numpy only: safe across fork

    def __len__(self) -> int:
        return len(self.objects) * self.views_per_object

    def set_epoch(self, epoch: int) -> None:
        """Draw the views of ``epoch`` (call before each epoch's DataLoader iteration)."""
        self.occlusion.set_epoch(epoch)

    @property
    def labels(self) -> NDArray[np.int64]:
        """(len,) int64: the label of every index."""
        return np.repeat([o.label for o in self.objects], self.views_per_object).astype(np.int64)

    def _object(self, obj: FarmObject) -> tuple[trimesh.Trimesh, DenseCloud]:
        def build():
            mesh = load_mesh(obj.source)
            return mesh, dense_cloud(mesh, obj.key, seed=self.seed, count=self.dense_points)

        return self._objects_cache.get_or_build(obj.index, build)

    def _point_set(self, obj: FarmObject) -> PointSet:
        def build() -> PointSet:
            cloud = load_cloud(obj.source, int(obj.cloud), up=self.up)  # the farm's frame: z up, largest side 1
            return PointSet(cloud.points, cloud.normals, obj.label, obj.name)

        return self._objects_cache.get_or_build(obj.index, build)

    def sample(self, index: int, epoch: int | None = None) -> dict:
        """Sample ``index`` of ``epoch`` (default: :meth:`set_epoch`'s): :class:`RandomOcclusion`'s dict plus ``label``, ``name``.

        Raises
        ------
        IndexError
            ``index`` outside ``[0, len)`` (a Dataset's end).
        ArgumentTypeError
            ``index`` not an integer (a float is not taken as its floor).
        """
        if not isinstance(index, numbers.Integral) or isinstance(index, (bool, np.bool_)):
            raise ArgumentTypeError(f"index must be an integer, got {described(index)}")
        if not 0 <= index < len(self):
            raise IndexError(f"index {index} out of range for {len(self)} samples")
        obj = self.objects[index // self.views_per_object]
        if obj.kind is POINT_SET:
            out = self.occlusion(self._point_set(obj), None, index, key=obj.index, epoch=epoch)
            out.update(label=obj.label, name=obj.name)
            return out
        mesh, dense = self._object(obj)
        out = self.occlusion(mesh, dense, index, key=obj.index, epoch=epoch)
        out.update(label=obj.label, name=obj.name)
        return out

    def __getitem__(self, index: int | tuple[int, int]):
        """``(points, label)`` of ``index``, or of ``(epoch, index)`` (:class:`EpochSampler`)."""
        torch = require_torch()
        epoch, index = index if isinstance(index, tuple) and len(index) == 2 else (None, index)
        s = self.sample(index, epoch)
        return torch.from_numpy(s["points"]), s["label"]

    def __repr__(self) -> str:
        clouds = sum(o.kind is POINT_SET for o in self.objects)
        method = (
            self.occlusion.method
            if not clouds
            else "point-splat"
            if clouds == len(self.objects)
            else f"{self.occlusion.method} and point-splat"
        )
        return f"OnTheFlyOccludedDataset({len(self.objects)} objects, {len(self)} samples/epoch, {method})"


class EpochSampler(require_torch().utils.data.Sampler):
    """Indices ``(epoch, i)`` for :class:`OnTheFlyOccludedDataset`: the epoch travels with each index.

    Call :meth:`set_epoch` before each epoch (in the main process); works with persistent
    workers.  ``shuffle``: a permutation drawn from ``(seed, epoch)``.
    """

    def __init__(self, data_source, *, shuffle: bool = False, seed: int = 0):
        self.n, self.shuffle, self.epoch = len(data_source), check_flag(shuffle, "shuffle"), 0
        self.seed = _whole(seed, "seed", low=0, high=MAX_SEED)

    def set_epoch(self, epoch: int) -> None:
        self.epoch = _whole(epoch, "epoch", low=0, high=_MAX_KEY)

    def __len__(self) -> int:
        return self.n

    def __iter__(self):
        order = derive_rng(self.seed, _ON_THE_FLY_STREAM, self.epoch).permutation(self.n) if self.shuffle else range(self.n)
        return iter([(self.epoch, int(i)) for i in order])
