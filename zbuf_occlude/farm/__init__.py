"""The render farm: whole occluded data sets, headless, parallel, deterministic, resumable.

One object is the unit of work (Sryamkin et al. 2023, §3.4, §4.3): load and normalise the
mesh once, sample its dense cloud once, decide visibility from every pose with the points
kept on the GPU (:class:`~zbuf_occlude.visibility.zbuffer.Scene`), and draw
``samples_per_view`` samples per pose (:func:`~zbuf_occlude.pipeline.occlude_object`).
Each object's result is one shard, written atomically, then a small record; a run that
is killed and started again skips every object whose record and shard are there.

Determinism: every random draw comes from :func:`~zbuf_occlude.geometry.samples.derive_rng` of the
global seed and the object's key, :func:`~zbuf_occlude.geometry.samples.object_key` of its path
relative to the input root without the suffix (the name ``zbuf-occlude generate`` uses),
so an object's samples do not depend on the worker count, the executor, ``--shard``,
``--classes`` or ``--per-class``.  They do depend on the OpenGL implementation (the GL
renderer is recorded per object).

Executors: in-process (``workers=1``), a process pool started with ``spawn`` (one GL
context per worker process, never inherited across ``fork``), or Dask distributed
(``scheduler="tcp://HOST:PORT"`` or ``dask_local=N``).  Beyond one machine, ``shard=(I, N)``
runs the I-th of N deterministic partitions (a SLURM array or Kubernetes indexed job) and
:func:`merge_farm` joins the outputs.  The folder layout is in :mod:`zbuf_occlude.dataset.layout`.

Safety: one writer per data set (``lock``: :func:`farm_lock`, a ``--shard`` task locks only
its own part), a SHA-256 of every file in its record (checked on resume and by the reader),
workers that die with their parent and SIGTERM handled like Ctrl-C (``lifecycle``), and every
option checked before any mesh is loaded (``checks``).  ``zbuf-occlude generate`` is this
engine with one worker, its own defaults and npz/ply/h5 writers (``generate``).

Modules: ``inputs`` (discovering objects, shards), ``config`` (parameters, constants,
journal paths), ``options`` (the option of each parameter), ``sensor_params`` (``--sensor``'s
parameters), ``checks`` (up-front checks), ``worker`` (one object), ``journal`` (records,
manifest, card, summary), ``lock``, ``lifecycle``, ``run`` (executors, :func:`run_farm`,
:func:`merge_farm`), ``generate``, ``shards`` (``--shard I/N``).  The objects it renders come
from :mod:`zbuf_occlude.mesh.inputs.plan`; its commands are in :mod:`zbuf_occlude.cli.farm`.
"""

# Each name is imported from its module when first used (the imports are in __init__.pyi):
# ``zbuf-occlude --help`` builds the farm's parsers without loading meshes or visibility.
import lazy_loader as _lazy

__getattr__, __dir__, _stub_names = _lazy.attach_stub(__name__, __file__)

# The same names as __init__.pyi's (a test checks), written out because the API docs read __all__ here.
__all__ = [
    "FarmParams",
    "SensorCropParams",
    "RunOptions",
    "FarmSummary",
    "DatasetBusy",
    "Terminated",
    "farm_lock",
    "generate",
    "GENERATE_DEFAULTS",
    "process_object",
    "shard_path",
    "select_shard",
    "parse_shard",
    "run_farm",
    "merge_farm",
    "DEFAULT_FARM_DENSE_POINTS",
    "DEFAULT_FARM_RESOLUTION",
    "PAPER_SAMPLES_PER_MB",
]
