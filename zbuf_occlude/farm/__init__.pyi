"""The farm's public names (see ``__init__.py``): read by ``lazy_loader.attach_stub`` and by
type checkers and the API docs."""

from .config import (
    DEFAULT_FARM_DENSE_POINTS,
    DEFAULT_FARM_RESOLUTION,
    GENERATE_DEFAULTS,
    PAPER_SAMPLES_PER_MB,
    FarmParams,
    RunOptions,
    shard_path,
)
from .generate import generate
from .journal import FarmSummary
from .lifecycle import Terminated
from .lock import DatasetBusy, farm_lock
from .run import merge_farm, run_farm
from .sensor_params import SensorCropParams
from .shards import parse_shard, select_shard
from .worker import process_object
