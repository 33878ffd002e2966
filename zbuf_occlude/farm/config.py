"""Constants and parameters of a farm run, and the journal paths derived from them."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.dataset.layout import GENERATE_STORAGES, STORAGE_MODES, record_name, shard_name
from zbuf_occlude.defaults import (
    DEFAULT_DENSE_POINTS,
    DEFAULT_FARM_DENSE_POINTS,
    DEFAULT_FARM_RESOLUTION,
    DEFAULT_FARM_VIEWS,
    DEFAULT_METHOD,
    DEFAULT_N_POINTS,
    DEFAULT_RESOLUTION,
    DEFAULT_SAMPLES_PER_VIEW,
)
from zbuf_occlude.defaults import DEFAULT_VIEWS as GENERATE_VIEWS
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError, OutputError
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS, view_schedule
from zbuf_occlude.geometry.sampling import check_seed
from zbuf_occlude.mesh.discovery import SPLITS
from zbuf_occlude.mesh.scene import UP_CHOICES

if TYPE_CHECKING:  # annotations only: inputs imports nothing from here
    from zbuf_occlude.mesh.inputs import FarmObject

log = logging.getLogger(__name__)


#: The farm's poses under their older name here (:data:`zbuf_occlude.defaults.DEFAULT_FARM_VIEWS`).
DEFAULT_VIEWS = DEFAULT_FARM_VIEWS
#: The paper's data set, Sryamkin et al. 2023, Table 2: 28.8 samples per MB.
PAPER_SAMPLES_PER_MB = 28.8
#: Bytes in one MB of "samples per MB" (decimal, 10^6).
BYTES_PER_MB = 1e6
#: Seconds between rewrites of the manifest while a run goes on (it is also written at the end).
MANIFEST_INTERVAL_S = 10.0
#: gzip level of the compact visibility bitmasks (level 4 is within a few % of 9, much faster).
COMPACT_GZIP_LEVEL = 4
#: Errors that stop the whole run instead of failing one object: nothing else would work.
FATAL_ERRORS = (OutputError, BackendUnavailable)

#: Command-line option of each parameter, for messages (``storage`` is ``--format`` in ``generate``).
OPTION_NAMES = {
    "views": "--views", "samples_per_view": "--samples-per-view", "n_points": "--points",
    "dense_points": "--dense-points", "density": "--density", "resolution": "--resolution", "seed": "--seed",
    "radius": "--radius", "storage": "--storage/--format", "method": "--method", "sensor": "--sensor",
    "sensor_distance_m": "--sensor-distance", "sensor_height_m": "--sensor-height", "sensor_size_m": "--sensor-size",
    "sensor_reflectivity": "--sensor-reflectivity", "sensor_footprint": "--sensor-footprint",
    "sensor_ground_margin_m": "--sensor-ground-margin", "sensor_hidden_below_m": "--sensor-hidden-below",
    "sensor_across_sight_width_m": "--sensor-across-sight-width", "up": "--up",
}  # fmt: skip

#: ``farm --sensor``: per-scan placement drawn uniformly from these intervals (metres).
#: Distance 5–25 m: the range in which an HDL-32E returns more than a few dozen points from a
#: car (LiDARNet v2's cars lie 3–25 m away); height 1.6–2.0 m: a LiDAR on a car roof; size
#: 4.5 m: a car's length (the object's largest dimension).
DEFAULT_SENSOR_DISTANCE_M = (5.0, 25.0)
DEFAULT_SENSOR_HEIGHT_M = (1.6, 2.0)
DEFAULT_SENSOR_SIZE_M = (4.5, 4.5)
_SENSOR_FIELDS = ("sensor_distance_m", "sensor_height_m", "sensor_size_m")
_SENSOR_OPTIONAL_INTERVALS = ("sensor_reflectivity", "sensor_hidden_below_m", "sensor_across_sight_width_m")

GL_LOCK = threading.Lock()  # one GL context per process: threads of a Dask worker take turns


# -- parameters ----------------------------------------------------------------------------
@dataclass(frozen=True)
class FarmParams:
    """Everything that decides the content of a data set (a changed value means a new data set).

    Parameters
    ----------
    views : str
        Pose schedule, :func:`~zbuf_occlude.geometry.cameras.view_schedule` (``paper100``: Eq. 11–12).
    samples_per_view, n_points : int
        Samples drawn per pose, points per sample.
    dense_points : int or None
        Dense cloud size per object; ignored when ``density`` is given.
    density : float or None
        Dense cloud as points per unit area of the normalised mesh (Algorithm 1).
    resolution : int
        Z-buffer image size, pixels.
    seed : int
    radius : float
        Camera distance, object units (max extent 1).
    storage : {"dense", "compact"}
    method : str
        Visibility method (registry name).
    sensor : str or None
        ``farm --sensor``: a sensor preset (``hdl32e``...) or JSON file
        (:func:`zbuf_occlude.cli.sensors.sensor_from_name`).  Each object gets
        ``samples_per_view`` scans, each from its own placement (see below), stored as the
        dense layout's rows (dense storage only); ``views``, ``dense_points``, ``density``,
        ``resolution``, ``radius`` and ``method`` do not apply.  ``None``: the z-buffer farm.
    sensor_distance_m, sensor_height_m, sensor_size_m : (lo, hi)
        Per scan, uniform draws of the horizontal sensor-object distance, the sensor height
        above the ground and the object's largest dimension, metres; the object's direction
        and heading are uniform over 0–360° (:class:`zbuf_occlude.sensors.placement.CropDistributions`).
        Left out of :meth:`to_dict` and :meth:`digest` when ``sensor`` is ``None``, so data sets
        made without a sensor keep their digest.
    sensor_reflectivity : (lo, hi) or None
        Return physics: the object's Lambertian reflectivity, drawn per scan; the sensor's
        radiometric detection threshold then applies (:func:`zbuf_occlude.sensors.scan`).
    sensor_footprint : bool
        Return physics: 7 rays per firing in the beam's divergence cone, strongest echo.
    sensor_ground_margin_m : float or None
        Keep the ground returns under each object, inside its footprint grown by this margin,
        metres (:class:`~zbuf_occlude.sensors.placement.CropDistributions` ``ground_margin_m``);
        ``None``: the object's returns only.  Left out of :meth:`to_dict` when ``None``.
    sensor_hidden_below_m : (lo, hi) or None
        Hide each object's returns lower than a height drawn per scan, metres above the ground
        (:class:`~zbuf_occlude.sensors.placement.CropDistributions` ``hidden_below_m``); ``None``:
        nothing hidden.  Left out of :meth:`to_dict` when ``None``.
    sensor_across_sight_width_m : (lo, hi) or None
        Stretch each mesh horizontally so that its crops are, at the median, as wide across the
        line of sight as this interval, metres, drawn per scan
        (:func:`~zbuf_occlude.sensors.fit.fit_width_scale`, a spinning LiDAR only); ``None``: the
        meshes' own proportions.  Left out of :meth:`to_dict` when ``None``.
    up : str
        The meshes' up axis (:data:`zbuf_occlude.mesh.scene.UP_CHOICES`), turned to +z by
        :func:`~zbuf_occlude.mesh.load.load_mesh`; ``"auto"``: per file, by its layout and
        format (ShapeNetCore +y, glTF +y, ...; :mod:`zbuf_occlude.mesh.scene`).  Each
        record and the card say the axis used and why.  Left out of :meth:`to_dict` and
        :meth:`digest` when ``"auto"``, so earlier data sets keep their digest.
    """

    views: str = DEFAULT_FARM_VIEWS
    samples_per_view: int = DEFAULT_SAMPLES_PER_VIEW
    n_points: int = DEFAULT_N_POINTS
    dense_points: int | None = DEFAULT_FARM_DENSE_POINTS
    density: float | None = None
    resolution: int = DEFAULT_FARM_RESOLUTION
    seed: int = 0
    radius: float = DEFAULT_RADIUS
    storage: str = "dense"
    method: str = DEFAULT_METHOD
    sensor: str | None = None
    sensor_distance_m: tuple[float, float] = DEFAULT_SENSOR_DISTANCE_M
    sensor_height_m: tuple[float, float] = DEFAULT_SENSOR_HEIGHT_M
    sensor_size_m: tuple[float, float] = DEFAULT_SENSOR_SIZE_M
    sensor_reflectivity: tuple[float, float] | None = None
    sensor_footprint: bool = False
    sensor_ground_margin_m: float | None = None
    sensor_hidden_below_m: tuple[float, float] | None = None
    sensor_across_sight_width_m: tuple[float, float] | None = None
    up: str = "auto"

    def __post_init__(self) -> None:
        # messages name the command-line options (OPTION_NAMES), not the fields
        if self.storage not in (*STORAGE_MODES, *GENERATE_STORAGES):
            raise InvalidInputError(f"--storage must be one of {STORAGE_MODES}, got {self.storage!r}")
        seed = check_seed(self.seed, name=OPTION_NAMES["seed"])
        if not isinstance(seed, int):  # None or a Generator: a run must be reproducible from its card
            raise InvalidInputError(f"{OPTION_NAMES['seed']} must be a non-negative integer, got {self.seed!r}")
        object.__setattr__(self, "seed", seed)
        for field, lowest in (("samples_per_view", 1), ("n_points", 1), ("resolution", 1)):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lowest:
                raise InvalidInputError(f"{OPTION_NAMES[field]} must be an integer >= {lowest}, got {value!r}")
        if not (isinstance(self.radius, (int, float, np.floating)) and np.isfinite(self.radius)):
            raise InvalidInputError(f"--radius must be a finite number of object units, got {self.radius!r}")
        if self.density is not None:
            if not (np.isfinite(self.density) and self.density > 0):
                raise InvalidInputError(f"--density must be > 0 points per unit area, got {self.density}")
            object.__setattr__(self, "dense_points", None)
        elif self.dense_points is None or self.dense_points < 1:
            raise InvalidInputError(f"--dense-points must be >= 1, got {self.dense_points}")
        view_schedule(self.views)  # raises InvalidInputError on a bad spec
        if self.up not in UP_CHOICES:
            raise InvalidInputError(f"--up must be one of {', '.join(UP_CHOICES)}, got {self.up!r}")
        if self.sensor is not None:
            self._check_sensor()

    def _check_sensor(self) -> None:
        if self.storage != "dense":
            raise InvalidInputError(f"--sensor writes dense storage only, got --storage {self.storage}")
        self.sensor_model()  # raises InvalidInputError naming an unknown sensor
        for field in _SENSOR_FIELDS:
            value = getattr(self, field)
            try:
                lo, hi = (float(v) for v in value)
            except (TypeError, ValueError):
                raise InvalidInputError(f"{OPTION_NAMES[field]} must be an interval LO:HI of metres, got {value!r}") from None
            if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi) or lo < 0 or (field != "sensor_height_m" and lo <= 0):
                raise InvalidInputError(f"{OPTION_NAMES[field]} must be LO:HI with 0 < LO <= HI metres, got {value!r}")
            object.__setattr__(self, field, (lo, hi))
        for field in _SENSOR_OPTIONAL_INTERVALS:
            value = getattr(self, field)
            if value is not None:
                try:
                    lo, hi = (float(v) for v in value)
                except (TypeError, ValueError):
                    lo = hi = float("nan")
                positive = field == "sensor_across_sight_width_m"  # a width of nothing cannot be fitted
                if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo <= hi) or (positive and not hi > 0):
                    raise InvalidInputError(f"{OPTION_NAMES[field]} must be LO:HI with 0 <= LO <= HI{', HI > 0' if positive else ''}, got {value!r}")
                object.__setattr__(self, field, (lo, hi))
        object.__setattr__(self, "sensor_footprint", bool(self.sensor_footprint))
        if self.sensor_ground_margin_m is not None:
            from zbuf_occlude.sensors.placement import check_ground_margin

            object.__setattr__(self, "sensor_ground_margin_m", check_ground_margin(self.sensor_ground_margin_m, "--sensor-ground-margin"))
        self.sensor_model()  # footprint needs a beam divergence

    def sensor_model(self):
        """The :class:`~zbuf_occlude.sensors.Lidar` or :class:`~zbuf_occlude.sensors.DepthCamera` of ``sensor``.

        Raises
        ------
        InvalidInputError
            Unknown sensor, or ``sensor_footprint``/``sensor_reflectivity`` for a depth camera
            or a LiDAR without a beam divergence.
        """
        from zbuf_occlude.sensors.lidar import Lidar
        from zbuf_occlude.sensors.presets import sensor_from_name

        sensor = sensor_from_name(self.sensor)
        if (self.sensor_footprint or self.sensor_reflectivity is not None) and not isinstance(sensor, Lidar):
            raise InvalidInputError(f"--sensor-footprint and --sensor-reflectivity model LiDARs; {self.sensor} is not one")
        if self.sensor_across_sight_width_m is not None and not isinstance(sensor, Lidar):
            raise InvalidInputError(f"--sensor-across-sight-width measures across a spinning LiDAR's line of sight; {self.sensor} is not one")
        return sensor.with_(footprint_rays=7) if self.sensor_footprint else sensor

    def crop_distributions(self):
        """``farm --sensor``'s per-scan placement, a :class:`~zbuf_occlude.sensors.placement.CropDistributions`."""
        from zbuf_occlude.sensors.placement import CropDistributions

        return CropDistributions(
            distance_m=self.sensor_distance_m, height_m=self.sensor_height_m, azimuth_deg=(0.0, 360.0),
            yaw_deg=(0.0, 360.0), size_m=self.sensor_size_m, reflectivity=self.sensor_reflectivity,
            ground_margin_m=self.sensor_ground_margin_m, hidden_below_m=self.sensor_hidden_below_m,
        )  # fmt: skip

    @functools.cached_property
    def poses(self) -> list[tuple[float, float]]:
        """``(elevation_deg, azimuth_deg)`` of every pose (none with ``sensor``: each scan has its own, in its shard)."""
        return [] if self.sensor is not None else view_schedule(self.views)

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        if self.up == "auto":  # the digest of data sets made before --up existed
            del d["up"]
        if self.sensor is None:  # the z-buffer farm's parameters, and digest, as before --sensor existed
            for field in ("sensor", *_SENSOR_FIELDS, "sensor_footprint", "sensor_ground_margin_m", *_SENSOR_OPTIONAL_INTERVALS):
                del d[field]
        else:
            d.update({field: list(d[field]) for field in (*_SENSOR_FIELDS, *_SENSOR_OPTIONAL_INTERVALS) if d[field] is not None})
            for field in ("sensor_ground_margin_m", "sensor_hidden_below_m", "sensor_across_sight_width_m"):  # the digest of sensor data sets made before they existed
                if d[field] is None:
                    del d[field]
        return d

    def digest(self) -> str:
        """Short hash of the parameters; records carry it so stale results are never mixed in."""
        return _digest(self.to_dict())


def _digest(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:16]


def plan_digest(objects: Sequence[FarmObject]) -> str:
    return _digest([[o.index, o.name, o.class_name, o.split, o.label] for o in objects])


def shard_path(obj: FarmObject) -> str:
    """The shard of ``obj`` relative to the data set folder."""
    return shard_name(obj.split, obj.index)


def record_path(out: Path, index: int) -> Path:
    return out / record_name(index)


#: ``generate``'s defaults, smaller poses and larger images than the farm's (one machine, a few meshes):
#: the 5×5 grid of poses, 2048-point samples, 10 per pose, 100,000 dense points, a 1024² z-buffer,
#: written as HDF5 (one file per split, which OccludedDataset, PyTorch and PointNet-style code read;
#: npz/ply give one file per sample, millions of files for a whole data set).
GENERATE_DEFAULTS = FarmParams(
    views=GENERATE_VIEWS, samples_per_view=DEFAULT_SAMPLES_PER_VIEW, n_points=DEFAULT_N_POINTS,
    dense_points=DEFAULT_DENSE_POINTS, resolution=DEFAULT_RESOLUTION, storage="h5",
)  # fmt: skip


@dataclass(frozen=True)
class RunOptions:
    """How a farm run (:func:`~zbuf_occlude.farm.run.run_farm`) is carried out, beside
    :class:`FarmParams` (what it renders).  None of them changes a written sample.

    Attributes
    ----------
    classes, per_class, splits
        Selection, see :func:`scan_objects` (ignored for a ready plan).
    workers : int
        Processes rendering in parallel on this machine (``spawn``ed, one GL context each;
        :func:`~zbuf_occlude.farm.pool.run_in_workers`).  A worker killed by a signal or the
        out-of-memory killer fails only the object it held (recorded, exit status 1).
    shard : (I, N)
        Render only the I-th of N partitions (:func:`select_shard`); with N > 1 the data
        set is completed by :func:`merge_farm` once every task has finished.
    scheduler : str, optional
        Dask scheduler address (``tcp://HOST:PORT``); workers must see ``out`` at the same
        path (shared file system) and have zbuf_occlude installed.
    dask_local : int, optional
        Start a local Dask cluster of this many single-threaded worker processes.
    overwrite : bool
        Start over: remove this run's earlier results (all of them, or this task's objects).
    progress : bool
        Show a tqdm bar (objects, views/s, ETA) on stderr.
    command : str, optional
        Command line for the data set card (default: this process's ``sys.argv``).
    source_text : str, optional
        What the card names as the source of a ready plan.
    on_finished : callable, optional
        Called with the data set folder, still under the lock, once an unsharded run has
        written its card (``generate --format h5`` joins its parts there).
    skipped : sequence of (path, reason)
        Inputs the caller's discovery could not take (a ready plan), added to those
        :func:`scan_objects` skips in a folder (unreadable folders, names that are not
        UTF-8); recorded in the card and the summary, so the run ends with status 1.
    class_from : int, optional
        A folder ``source``: the folder level above each mesh that names its class
        (:func:`scan_objects`).
    layout : str, optional
        The card's ``layout`` of a ready plan (a folder's or list file's is detected).
    isolate : bool
        With one worker, render in a worker process too instead of in this one (the CLI's
        choice): a SIGTERM or Ctrl-C then stops the run within seconds even inside a long
        native call (Embree, the GL driver), which an in-process run finishes first.
    progress_label : str
        The progress bar's name (``generate`` calls it after itself).
    """

    classes: Sequence[str] | str | None = None
    per_class: int | None = None
    splits: Sequence[str] | str = SPLITS
    workers: int = 1
    shard: tuple[int, int] = (0, 1)
    scheduler: str | None = None
    dask_local: int | None = None
    overwrite: bool = False
    progress: bool = True
    command: str | None = None
    source_text: str | None = None
    on_finished: Callable[[Path], Any] | None = None
    skipped: Sequence[tuple[str, str]] = ()
    class_from: int | None = None
    layout: str | None = None
    isolate: bool = False
    progress_label: str = "farm"

