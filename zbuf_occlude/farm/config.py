"""Constants and parameters of a farm run, and the journal paths derived from them."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..cameras import DEFAULT_RADIUS, view_schedule
from ..defaults import DEFAULT_METHOD, DEFAULT_N_POINTS, DEFAULT_SAMPLES_PER_VIEW
from ..errors import BackendUnavailable, InvalidInputError, OutputError
from ..layout import GENERATE_STORAGES, STORAGE_MODES, record_name, sample_file_name, shard_name
from ..sampling import check_seed

if TYPE_CHECKING:  # annotations only: inputs imports nothing from here
    from .inputs import FarmObject

log = logging.getLogger(__name__)


#: Dense cloud per object (points on the whole surface, sampled once, paper §3.4).  32768
#: leaves several thousand visible points per pose on ModelNet objects (25–45 % visible),
#: so a 2048-point sample is a proper subsample, and keeps compact storage above 1,000
#: samples/MB (12 bytes per point once + one bit per point and pose); a view costs
#: tens of milliseconds on Mesa llvmpipe.
DEFAULT_FARM_DENSE_POINTS = 32_768
#: Z-buffer image size, pixels.  512² keeps a pixel's footprint (~2.3e-3 of the object's
#: size at the default radius) far below the dense cloud's mean spacing (~5e-3 at 32768
#: points on a unit box), so the candidate window is not the bottleneck of accuracy.
DEFAULT_FARM_RESOLUTION = 512
DEFAULT_VIEWS = "paper100"
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
    "radius": "--radius", "storage": "--storage/--format", "method": "--method",
}  # fmt: skip

GL_LOCK = threading.Lock()  # one GL context per process: threads of a Dask worker take turns


# -- parameters ----------------------------------------------------------------------------
@dataclass(frozen=True)
class FarmParams:
    """Everything that decides the content of a data set (a changed value means a new data set).

    Parameters
    ----------
    views : str
        Pose schedule, :func:`~zbuf_occlude.cameras.view_schedule` (``paper100``: Eq. 11–12).
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
    """

    views: str = DEFAULT_VIEWS
    samples_per_view: int = DEFAULT_SAMPLES_PER_VIEW
    n_points: int = DEFAULT_N_POINTS
    dense_points: int | None = DEFAULT_FARM_DENSE_POINTS
    density: float | None = None
    resolution: int = DEFAULT_FARM_RESOLUTION
    seed: int = 0
    radius: float = DEFAULT_RADIUS
    storage: str = "dense"
    method: str = DEFAULT_METHOD

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

    @functools.cached_property
    def poses(self) -> list[tuple[float, float]]:
        """``(elevation_deg, azimuth_deg)`` of every pose."""
        return view_schedule(self.views)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

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


def sample_file_path(name: str, pose_index: int, cloud, fmt: str) -> str:
    """``generate``'s file of one sample relative to ``--out``, e.g.
    ``chair/train/chair_0001/chair_0001_v007_el+030_az045_s03.npz``: the pose index keeps
    names unique, the angles (whole degrees) keep them readable."""
    return sample_file_name(name, pose_index, cloud.elevation_deg, cloud.azimuth_deg, cloud.sample_index, fmt)


def record_path(out: Path, index: int) -> Path:
    return out / record_name(index)
