"""The farm's public names (see ``__init__.py``): read by ``lazy_loader.attach_stub`` and by
type checkers and the API docs."""

from .cli import add_farm_merge_parser, add_farm_parser
from .config import DEFAULT_FARM_DENSE_POINTS, DEFAULT_FARM_RESOLUTION, PAPER_SAMPLES_PER_MB, FarmParams, shard_path
from .inputs import FarmObject, discover_objects, parse_shard, select_shard
from .generate import GENERATE_DEFAULTS, generate, objects_from_paths
from .journal import FarmSummary
from .lifecycle import Terminated
from .lock import DatasetBusy, farm_lock
from .run import merge_farm, run_farm
from .worker import process_object
