"""Constants and parameters of a farm run, and the journal paths derived from them."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
import os
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.dataset.layout import STORAGE_MODES, record_name, shard_name
from zbuf_occlude.dataset.storage import storages
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
from zbuf_occlude.mesh.paths import SPLITS
from zbuf_occlude.mesh.scene import UP_CHOICES
from zbuf_occlude.farm.options import OPTION_NAMES
from zbuf_occlude.farm.sensor_params import SENSOR_KEYS, SensorCropParams

if TYPE_CHECKING:  # annotations only: inputs imports nothing from here
    from zbuf_occlude.mesh.inputs.plan import FarmObject

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

GL_LOCK = threading.Lock()  # one GL context per process: threads of a Dask worker take turns


def usable_cpus() -> int:
    """The CPU cores this process may run on: its affinity mask where the system has one
    (``taskset``, a container's or a batch job's CPU set), else every core; at least 1."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


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
    sensor : SensorCropParams, str or None
        ``farm --sensor``: the sensor and the placement of its scans (a name alone: a
        :class:`SensorCropParams` of that sensor with the default placement).  Each object gets
        ``samples_per_view`` scans, each from its own placement, stored as the dense layout's
        rows (dense storage only); ``views``, ``dense_points``, ``density``, ``resolution``,
        ``radius`` and ``method`` do not apply.  ``None``: the z-buffer farm.  Written by
        :meth:`to_dict` as flat ``sensor_*`` keys (:data:`SENSOR_KEYS`), and left out when
        ``None``, so data sets made without a sensor keep their digest.
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
    sensor: SensorCropParams | None = None
    up: str = "auto"

    def __post_init__(self) -> None:
        # messages name the command-line options (OPTION_NAMES), not the fields
        if self.storage not in storages():
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
        if isinstance(self.sensor, str):
            object.__setattr__(self, "sensor", SensorCropParams(self.sensor))
        if self.sensor is not None:
            if not isinstance(self.sensor, SensorCropParams):
                raise InvalidInputError(f"--sensor must name a sensor, got {type(self.sensor).__name__} {self.sensor!r}")
            if self.storage != "dense":
                raise InvalidInputError(f"--sensor writes dense storage only, got --storage {self.storage}")

    @functools.cached_property
    def poses(self) -> list[tuple[float, float]]:
        """``(elevation_deg, azimuth_deg)`` of every pose (none with ``sensor``: each scan has its own, in its shard)."""
        return [] if self.sensor is not None else view_schedule(self.views)

    def to_dict(self) -> dict[str, Any]:
        """The parameters as plain JSON values, as the plan and the card record them (:meth:`from_dict` reads them back)."""
        d: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "sensor":
                d.update({} if value is None else value.to_dict())
            elif not (f.name == "up" and value == "auto"):  # "auto": the digest of data sets made before --up existed
                d[f.name] = value
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> FarmParams:
        """The parameters of a plan's or card's ``params`` (:meth:`to_dict`), flat ``sensor_*`` keys included.

        Raises
        ------
        TypeError
            A key that is no parameter, or ``sensor_*`` keys without a ``sensor``.
        InvalidInputError
            A bad value.
        """
        sensor_keys = {key for key in d if key in SENSOR_KEYS.values()}
        rest = {key: value for key, value in d.items() if key != "sensor" and key not in sensor_keys}
        if d.get("sensor") is None:
            if sensor_keys:
                raise TypeError(f"{', '.join(sorted(sensor_keys))} given without a sensor")
            return cls(**rest)
        return cls(**rest, sensor=SensorCropParams.from_dict(d))

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
        Show progress on stderr (objects, views/s, ETA): a bar on a terminal, a line every 10 s in a
        log (:mod:`zbuf_occlude.io.progress`).
    command : str, optional
        Command line for the data set card (default: this process's ``sys.argv``), recorded with
        its paths relative to the data set or the input root
        (:func:`~zbuf_occlude.farm.journal.portable_command`).
    source_text : str, optional
        What the card names as the source (default: the input root's name,
        :func:`~zbuf_occlude.farm.journal.input_root`).
    inputs : sequence of str or PathLike
        A ready plan: the files and folders its objects were found in, which the input root
        holds (default: the folders of its objects' meshes).
    on_finished : callable, optional
        Called with the data set folder, still under the lock, once an unsharded run has
        written its card (``generate --format h5`` joins its parts there).
    skipped : sequence of (path, reason)
        Inputs the caller's discovery could not take (a ready plan), added to those
        :func:`scan_objects` skips in a folder (unreadable folders, names that are not
        UTF-8); recorded in the card (relative to the input root) and the summary (as given),
        so the run ends with status 1.
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
    defaults : FarmParams, optional
        The command's defaults (default :class:`FarmParams` ``()``, the farm's; ``generate``:
        :data:`GENERATE_DEFAULTS`): an option that does nothing for the plan's input kind is
        refused when it differs from them (:func:`~zbuf_occlude.farm.checks.check_point_set_options`).
    set_params : frozenset of str, optional
        The :class:`FarmParams` fields the user set (the command line's options given): those
        are refused where the plan's input kind does not use them, and kept where it has its
        own default (``n_points`` of point sets); None: the fields that differ from ``defaults``.
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
    inputs: Sequence[str | os.PathLike] = ()
    on_finished: Callable[[Path], Any] | None = None
    skipped: Sequence[tuple[str, str]] = ()
    class_from: int | None = None
    layout: str | None = None
    isolate: bool = False
    progress_label: str = "farm"
    defaults: FarmParams | None = None
    set_params: frozenset[str] | None = None
