"""The render farm: whole occluded data sets, headless, parallel, deterministic, resumable.

One object is the unit of work (Sryamkin et al. 2023, §3.4, §4.3): load and normalise the
mesh once, sample its dense cloud once, decide visibility from every pose with the points
kept on the GPU (:class:`~zbuf_occlude.visibility.zbuffer.Scene`), and draw
``samples_per_view`` samples per pose (:func:`~zbuf_occlude.occlude.occlude_object`).
Each object's result is one shard, written atomically, then a small record; a run that
is killed and started again skips every object whose record and shard are there.

Determinism: every random draw comes from :func:`~zbuf_occlude.occlude.derive_rng` of the
global seed and the object's key, :func:`~zbuf_occlude.occlude.object_key` of its path
relative to the input root without the suffix (the name ``zbuf-occlude generate`` uses),
so an object's samples do not depend on the worker count, the executor, ``--shard``,
``--classes`` or ``--per-class``.  They do depend on the OpenGL implementation (the GL
renderer is recorded per object).

Executors: in-process (``workers=1``), a process pool started with ``spawn`` (one GL
context per worker process, never inherited across ``fork``), or Dask distributed
(``scheduler="tcp://HOST:PORT"`` or ``dask_local=N``).  Beyond one machine, ``shard=(I, N)``
runs the I-th of N deterministic partitions (a SLURM array or Kubernetes indexed job) and
:func:`merge_farm` joins the outputs.  The folder layout is in :mod:`zbuf_occlude.dataset`.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import errno
import functools
import hashlib
import json
import logging
import multiprocessing
import os
import re
import resource
import shlex
import shutil
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from .cameras import DEFAULT_RADIUS, view_schedule
from .dataset import (
    CARD_FILE,
    FORMAT_VERSION,
    MANIFEST_FILE,
    SHAPE_NAMES_FILE,
    SHARD_DIR,
    SPLITS,
    STORAGE_MODES,
    file_list_name,
)
from .errors import BackendUnavailable, InvalidInputError, OutputError
from .io import atomic_path
from .mesh import SUPPORTED_EXTENSIONS, load_mesh
from .occlude import dense_cloud, object_key, occlude_object

__all__ = [
    "FarmObject",
    "FarmParams",
    "FarmSummary",
    "discover_objects",
    "process_object",
    "shard_path",
    "select_shard",
    "parse_shard",
    "run_farm",
    "merge_farm",
    "add_farm_parser",
    "add_farm_merge_parser",
    "DEFAULT_FARM_DENSE_POINTS",
    "DEFAULT_FARM_RESOLUTION",
    "PAPER_SAMPLES_PER_MB",
]

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
DEFAULT_SAMPLES_PER_VIEW = 10
DEFAULT_N_POINTS = 2048
#: The paper's data set, Sryamkin et al. 2023, Table 2: 28.8 samples per MB.
PAPER_SAMPLES_PER_MB = 28.8
#: Bytes in one MB of "samples per MB" (decimal, 10^6).
BYTES_PER_MB = 1e6
#: Seconds between rewrites of the manifest while a run goes on (it is also written at the end).
MANIFEST_INTERVAL_S = 10.0
#: gzip level of the compact visibility bitmasks (level 4 is within a few % of 9, much faster).
COMPACT_GZIP_LEVEL = 4
#: Split of an object whose path names none (flat folder, list file without a split column).
DEFAULT_SPLIT = "train"
#: Names of the farm's journal inside the output folder.
RECORD_DIR, TASK_DIR, PLAN_FILE = "records", "tasks", "plan.json"
#: Errors that stop the whole run instead of failing one object: nothing else would work.
_FATAL = (OutputError, BackendUnavailable)

_MESH_SUFFIXES = tuple(SUPPORTED_EXTENSIONS)
_GL_LOCK = threading.Lock()  # one GL context per process: threads of a Dask worker take turns


# -- inputs ------------------------------------------------------------------------------
@dataclass(frozen=True)
class FarmObject:
    """One mesh of the farm's plan.

    Attributes
    ----------
    index : int
        Position in the plan (``object_index`` in the shards); shards and records are named by it.
    name : str
        Path relative to the input root (or as written in the list file), POSIX, without
        suffix; the seed key is :func:`~zbuf_occlude.occlude.object_key` ``(name)``.
    source : str
        The mesh file.
    class_name, split : str
    label : int
        Line of ``shape_names.txt``.
    """

    index: int
    name: str
    source: str
    class_name: str
    split: str
    label: int

    @property
    def key(self) -> int:
        """Seed key of the object (CRC-32 of ``name``)."""
        return object_key(self.name)


def _natural_key(text: str) -> list:
    # "chair_2" < "chair_10"; integer labels of a list file sort numerically.
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", text)]


def _class_and_split(rel: Path) -> tuple[str, str]:
    parent = rel.parent
    if parent.name in SPLITS and parent.parent.name:
        return parent.parent.name, parent.name
    if parent.name:
        return parent.name, DEFAULT_SPLIT
    # flat folder: ModelNet file names are <class>_<NNNN>
    return re.sub(r"_\d+$", "", rel.stem) or rel.stem, DEFAULT_SPLIT


def _scan_tree(root: Path) -> list[tuple[str, str, str, str]]:
    found = []
    for path in root.rglob("*"):
        if path.suffix.lower() not in _MESH_SUFFIXES or not path.is_file():
            continue
        rel = path.relative_to(root)
        if any(part.startswith(".") for part in rel.parts):
            continue  # hidden folders and temporary files
        class_name, split = _class_and_split(rel)
        found.append((rel.with_suffix("").as_posix(), str(path), class_name, split))
    return found


def _read_list_file(list_file: Path) -> list[tuple[str, str, str, str]]:
    found = []
    base = list_file.parent
    for lineno, raw in enumerate(list_file.read_text(encoding="utf-8").splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        tokens = line.rsplit(maxsplit=2)
        if len(tokens) == 3 and tokens[2] in SPLITS:
            path_text, label, split = tokens
        else:
            tokens = line.rsplit(maxsplit=1)
            if len(tokens) != 2:
                raise InvalidInputError(f"{list_file}:{lineno}: expected 'PATH LABEL [train|test]', got {raw!r}")
            (path_text, label), split = tokens, DEFAULT_SPLIT
        path = Path(path_text)
        name = path.with_suffix("").as_posix()
        found.append((name, str(path if path.is_absolute() else base / path), label, split))
    return found


def discover_objects(
    source: str | os.PathLike,
    *,
    classes: Sequence[str] | str | None = None,
    per_class: int | None = None,
    splits: Sequence[str] | str = SPLITS,
) -> list[FarmObject]:
    """The farm's plan: meshes under ``source``, filtered, labelled and numbered.

    Parameters
    ----------
    source : str or PathLike
        A ModelNet-style tree ``ROOT/<class>/<split>/<name>.off`` (nested deeper is fine:
        the class and split are the two folders above the file), a folder of class
        folders ``ROOT/<class>/<name>.off``, a flat folder ``ROOT/<class>_<NNNN>.off``, or
        a list file with one ``PATH LABEL [SPLIT]`` per line (paths relative to the list
        file; ``#`` starts a comment; ``LABEL`` is a class name).  Any extension of
        :data:`zbuf_occlude.mesh.SUPPORTED_EXTENSIONS`.  Objects without a split are in
        ``train``.
    classes : sequence of str or comma-separated str, optional
        Keep these classes only.
    per_class : int, optional
        Keep the first K objects (by name, natural order) of each class and split.
    splits : sequence of str or comma-separated str
        Keep these splits.

    Returns
    -------
    objects : list of FarmObject
        Sorted by name; ``index`` is the position, ``label`` the position of the class in
        the sorted (natural order) list of kept classes.

    Raises
    ------
    InvalidInputError
        ``source`` missing, nothing found, an unknown class, or ``per_class < 1``.
    """
    source = Path(source).absolute()  # the manifest's source paths must not depend on the working folder
    if source.is_dir():
        found = _scan_tree(source)
    elif source.is_file():
        found = _read_list_file(source)
    else:
        raise InvalidInputError(f"no such mesh folder or list file: {source}")
    if not found:
        raise InvalidInputError(f"no mesh files ({', '.join(_MESH_SUFFIXES)}) under {source}")
    if classes is not None:
        wanted = set(_split_names(classes))
        unknown = wanted - {f[2] for f in found}
        if unknown:
            have = sorted({f[2] for f in found}, key=_natural_key)
            raise InvalidInputError(f"classes {sorted(unknown)} not found under {source}; it has {have}")
        found = [f for f in found if f[2] in wanted]
    split_set = set(_split_names(splits))
    found = [f for f in found if f[3] in split_set]
    found.sort(key=lambda f: _natural_key(f[0]))
    if per_class is not None:
        if per_class < 1:
            raise InvalidInputError(f"--per-class must be >= 1, got {per_class}")
        taken: dict[tuple[str, str], int] = {}
        kept = []
        for f in found:
            n = taken.get((f[2], f[3]), 0)
            if n < per_class:
                kept.append(f)
                taken[(f[2], f[3])] = n + 1
        found = kept
    if not found:
        raise InvalidInputError(f"no meshes left under {source} after the class/split selection")
    names = [f[0] for f in found]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})[:5]
        raise InvalidInputError(f"mesh names must be unique (they seed the samples); repeated: {dup}")
    shape_names = sorted({f[2] for f in found}, key=_natural_key)
    labels = {c: i for i, c in enumerate(shape_names)}
    objects = [FarmObject(i, name, src, cls, split, labels[cls]) for i, (name, src, cls, split) in enumerate(found)]
    keys: dict[int, str] = {}
    for o in objects:
        if o.key in keys:
            log.warning(
                "objects %s and %s share the seed key %d (CRC-32 collision): their draws are correlated",
                keys[o.key], o.name, o.key,
            )  # fmt: skip
        keys[o.key] = o.name
    return objects


def _split_names(spec: Sequence[str] | str) -> list[str]:
    if isinstance(spec, str):
        return [s.strip() for s in spec.split(",") if s.strip()]
    return [str(s) for s in spec]


def parse_shard(text: str) -> tuple[int, int]:
    """``"I/N"`` → ``(I, N)`` with ``0 <= I < N``.

    Raises
    ------
    InvalidInputError
        Malformed or out of range.
    """
    m = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", text)
    if not m or not 0 <= int(m.group(1)) < int(m.group(2)):
        raise InvalidInputError(
            f"--shard must be I/N with 0 <= I < N (e.g. 3/16 for ${{SLURM_ARRAY_TASK_ID}}/16), got {text!r}"
        )
    return int(m.group(1)), int(m.group(2))


def select_shard(objects: Sequence[FarmObject], index: int, count: int) -> list[FarmObject]:
    """The ``index``-th of ``count`` deterministic partitions (object ``i`` goes to task ``i mod count``;
    round robin spreads classes and mesh sizes evenly)."""
    if not 0 <= index < count:
        raise InvalidInputError(f"shard index must satisfy 0 <= I < N, got {index}/{count}")
    return [o for o in objects if o.index % count == index]


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
    method: str = "zbuffer"

    def __post_init__(self) -> None:
        if self.storage not in STORAGE_MODES:
            raise InvalidInputError(f"storage must be one of {STORAGE_MODES}, got {self.storage!r}")
        if self.samples_per_view < 1 or self.n_points < 1 or self.resolution < 1:
            raise InvalidInputError(
                "need samples_per_view, n_points and resolution >= 1, got "
                f"{self.samples_per_view}, {self.n_points}, {self.resolution}"
            )
        if self.density is not None:
            if not (np.isfinite(self.density) and self.density > 0):
                raise InvalidInputError(f"density must be > 0 points per unit area, got {self.density}")
            object.__setattr__(self, "dense_points", None)
        elif self.dense_points is None or self.dense_points < 1:
            raise InvalidInputError(f"dense_points must be >= 1, got {self.dense_points}")
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


def _plan_digest(objects: Sequence[FarmObject]) -> str:
    return _digest([[o.index, o.name, o.class_name, o.split, o.label] for o in objects])


def shard_path(obj: FarmObject) -> str:
    """The shard of ``obj`` relative to the data set folder."""
    return f"{SHARD_DIR}/{obj.split}_{obj.index:06d}.h5"


def _record_path(out: Path, index: int) -> Path:
    return out / RECORD_DIR / f"{index:06d}.json"


# -- the unit of work --------------------------------------------------------------------------
def _version() -> str:
    from . import __version__  # deferred: the package imports this module while it initialises

    return __version__


def _write_json(path: Path, obj: Any) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=1, sort_keys=True) + "\n", encoding="utf-8")


def _write_h5(path: Path, fill: Callable[[Any], None]) -> int:
    import h5py

    with atomic_path(path) as tmp:
        try:
            with h5py.File(tmp, "w") as f:
                fill(f)
        except OSError as exc:
            # HDF5 reports a full disk in its message, not always in errno
            if exc.errno is None and "No space left" in str(exc):
                raise OSError(errno.ENOSPC, str(exc)) from exc
            raise
    return path.stat().st_size


def _attrs(f, obj: FarmObject, params: FarmParams) -> None:
    f.attrs.update(
        {
            "format_version": FORMAT_VERSION,
            "storage": params.storage,
            "object_index": obj.index,
            "name": obj.name,
            "class_name": obj.class_name,
            "split": obj.split,
            "label": obj.label,
            "key": obj.key,
            "seed": params.seed,
            "n_points": params.n_points,
            "samples_per_view": params.samples_per_view,
            "params_digest": params.digest(),
            "zbuf_occlude_version": _version(),
        }
    )


@functools.lru_cache(maxsize=1)
def _renderer_name() -> str:
    from .render import context_info

    try:
        info = context_info()
    except Exception:  # provenance only: never fail an object for it
        return "unknown"
    return f"{info['renderer']} ({info['backend']}, {info['version']})"


def _peak_rss_mb() -> float:
    # ru_maxrss is in KiB on Linux (bytes on macOS)
    scale = 1.0 if sys.platform == "darwin" else 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale / 2**20


def _render(obj: FarmObject, params: FarmParams, out: Path) -> dict[str, Any]:
    mesh = load_mesh(obj.source)
    dense = dense_cloud(mesh, obj.key, seed=params.seed, count=params.dense_points, density=params.density)
    poses = params.poses
    common = dict(
        key=obj.key, n_points=params.n_points, seed=params.seed, dense=dense, method=params.method,
        resolution=params.resolution, radius=params.radius, label=obj.label, class_name=obj.class_name,
        source=obj.source,
    )  # fmt: skip
    n_visible = np.zeros(len(poses), dtype=np.int64)
    path = out / shard_path(obj)
    if params.storage == "dense":
        rows: list[tuple[int, int, np.ndarray]] = []
        for pose_index, visible, clouds in occlude_object(mesh, poses, samples_per_view=params.samples_per_view, **common):
            n_visible[pose_index] = int(visible.sum())
            rows.extend((pose_index, c.sample_index, c.points) for c in clouds)
        b = len(rows)

        def fill(f) -> None:
            pose_index = np.array([r[0] for r in rows], dtype=np.int64)
            el_az = np.asarray(poses, dtype=np.float64).reshape(-1, 2)
            f.create_dataset(
                "data", data=np.stack([r[2] for r in rows]) if rows else np.zeros((0, params.n_points, 3), np.float32),
                dtype=np.float32, track_times=False,
            )  # fmt: skip
            f.create_dataset("label", data=np.full(b, obj.label, dtype=np.int64), track_times=False)
            f.create_dataset("elevation_deg", data=el_az[pose_index, 0], dtype=np.float64, track_times=False)
            f.create_dataset("azimuth_deg", data=el_az[pose_index, 1], dtype=np.float64, track_times=False)
            f.create_dataset("object_index", data=np.full(b, obj.index, dtype=np.int64), track_times=False)
            f.create_dataset("pose_index", data=pose_index, track_times=False)
            f.create_dataset("sample_index", data=np.array([r[1] for r in rows], dtype=np.int64), track_times=False)
            f.create_dataset("n_visible", data=n_visible[pose_index], track_times=False)
            _attrs(f, obj, params)

    else:
        n_dense = len(dense.points)
        bits = np.zeros((len(poses), (n_dense + 7) // 8), dtype=np.uint8)
        # samples_per_view=0: only the masks are needed, the reader draws the samples
        for pose_index, visible, _ in occlude_object(mesh, poses, samples_per_view=0, **common):
            n_visible[pose_index] = int(visible.sum())
            bits[pose_index] = np.packbits(visible)
        b = int(np.count_nonzero(n_visible) * params.samples_per_view)

        def fill(f) -> None:
            el_az = np.asarray(poses, dtype=np.float64).reshape(-1, 2)
            f.create_dataset("dense_points", data=dense.points.astype(np.float32), track_times=False)
            f.create_dataset(
                "visible_bits", data=bits, chunks=bits.shape if bits.size else None,
                compression="gzip" if bits.size else None,
                compression_opts=COMPACT_GZIP_LEVEL if bits.size else None, track_times=False,
            )  # fmt: skip
            f.create_dataset("n_visible", data=n_visible, track_times=False)
            f.create_dataset("elevation_deg", data=el_az[:, 0], track_times=False)
            f.create_dataset("azimuth_deg", data=el_az[:, 1], track_times=False)
            _attrs(f, obj, params)
            f.attrs["n_dense"] = n_dense

    n_bytes = _write_h5(path, fill)
    return {
        "shards": [shard_path(obj)],
        "n_visible": n_visible.tolist(),
        "n_samples": b,
        "n_padded_poses": int(np.count_nonzero((n_visible > 0) & (n_visible < params.n_points))),
        "n_dense": int(len(dense.points)),
        "n_faces": int(len(mesh.faces)),
        "bytes": int(n_bytes),
    }


def _base_record(obj: FarmObject, params: FarmParams) -> dict[str, Any]:
    return {
        "object_index": obj.index,
        "name": obj.name,
        "source": obj.source,
        "class_name": obj.class_name,
        "label": obj.label,
        "split": obj.split,
        "key": obj.key,
        "seed": params.seed,
        "params_digest": params.digest(),
        "status": "pending",
        "error": None,
        "shards": [],
        "n_visible": [],
        "n_samples": 0,
        "bytes": 0,
    }


def process_object(obj: FarmObject, params: FarmParams, out: str | os.PathLike) -> dict[str, Any]:
    """Render one object, write its shard and record (atomically), return the record.

    The function every executor runs (it must be importable by Dask workers).  A mesh
    that fails gets ``status="failed"`` and its error in the record; the farm goes on.

    Raises
    ------
    OutputError
        The shard or record cannot be written (disk full, unwritable folder): fatal.
    BackendUnavailable
        No OpenGL context: fatal, no object could be rendered.
    """
    out = Path(out)
    record = _base_record(obj, params)
    t0 = time.perf_counter()
    try:
        with _GL_LOCK:
            record.update(_render(obj, params, out))
        record["status"] = "ok"
    except _FATAL:
        raise
    except Exception as exc:  # a bad mesh must not stop a farm of thousands; the manifest keeps why
        record.update(status="failed", error=f"{type(exc).__name__}: {exc}")
        log.warning("object %s (%s) failed: %s", obj.index, obj.source, record["error"])
        log.debug("traceback of %s", obj.source, exc_info=True)
    record.update(
        time_s=round(time.perf_counter() - t0, 4),
        finished_at=datetime.now(timezone.utc).isoformat(timespec="seconds"),
        renderer=_renderer_name() if record["status"] == "ok" else None,
        host=socket.gethostname(),
        pid=os.getpid(),
        peak_rss_mb=round(_peak_rss_mb(), 1),
    )
    _write_json(_record_path(out, obj.index), record)
    return record


# -- executors -----------------------------------------------------------------------------
def _serial(todo: Sequence[FarmObject], params: FarmParams, out: Path) -> Iterator[dict[str, Any]]:
    for obj in todo:
        yield process_object(obj, params, out)


def _pool(todo: Sequence[FarmObject], params: FarmParams, out: Path, workers: int) -> Iterator[dict[str, Any]]:
    # spawn: a forked child would inherit the parent's GL state; each worker makes its own context
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        pending = {pool.submit(process_object, obj, params, str(out)) for obj in todo}
        try:
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in finished:
                    yield fut.result()
        finally:
            for fut in pending:
                fut.cancel()


def _dask(
    todo: Sequence[FarmObject], params: FarmParams, out: Path, scheduler: str | None, dask_local: int | None
) -> Iterator[dict[str, Any]]:
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError as exc:
        raise BackendUnavailable("the Dask executor needs dask.distributed: pip install 'zbuf-occlude[dask]'") from exc
    with contextlib.ExitStack() as stack:
        if scheduler:
            try:
                client = stack.enter_context(Client(scheduler))
            except (OSError, TimeoutError) as exc:
                raise BackendUnavailable(f"cannot reach the Dask scheduler {scheduler}: {exc}") from exc
        else:
            # one thread per worker process: each process owns one GL context
            cluster = stack.enter_context(
                LocalCluster(n_workers=dask_local, threads_per_worker=1, processes=True, dashboard_address=None)
            )
            client = stack.enter_context(Client(cluster))
        # a fresh token per run: a long-lived scheduler may still know the keys of an earlier run
        token = f"{params.digest()}-{os.getpid()}-{time.time_ns()}"
        futures = [
            client.submit(process_object, obj, params, str(out), key=f"zbuf-farm-{token}-{obj.index}", pure=False)
            for obj in todo
        ]
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            client.cancel(futures)


# -- journal, manifest, card -------------------------------------------------------------------
def _read_json(path: Path) -> Any | None:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _finished(out: Path, obj: FarmObject, digest: str) -> dict[str, Any] | None:
    """The record of ``obj`` if it finished (ok, same parameters, shard present and whole)."""
    rec = _read_json(_record_path(out, obj.index))
    if not rec or rec.get("params_digest") != digest or rec.get("name") != obj.name or rec.get("status") != "ok":
        return None
    for rel in rec["shards"]:
        shard = out / rel
        if not shard.is_file() or shard.stat().st_size != rec["bytes"]:
            return None
    return rec


def _remove_stale_temps(out: Path, objects: Sequence[FarmObject], everything: bool) -> None:
    # atomic_path leaves ".<name>.<random>.tmp" behind when a run is SIGKILLed mid-write;
    # a sharded task removes only its own, other tasks may be writing theirs right now
    names = None if everything else {Path(shard_path(o)).name for o in objects} | {f"{o.index:06d}.json" for o in objects}
    for folder in (out / SHARD_DIR, out / RECORD_DIR, out):
        if not folder.is_dir():
            continue
        for tmp in folder.glob(".*.tmp"):
            target = tmp.name[1:].rsplit(".", 2)[0]
            if names is None or target in names:
                tmp.unlink(missing_ok=True)


def _plan_doc(objects: Sequence[FarmObject], params: FarmParams, source: str) -> dict[str, Any]:
    return {
        "format_version": FORMAT_VERSION,
        "params": params.to_dict(),
        "params_digest": params.digest(),
        "plan_digest": _plan_digest(objects),
        "source": source,
        "objects": [dataclasses.asdict(o) for o in objects],
    }


def _objects_of(plan: dict[str, Any]) -> list[FarmObject]:
    return [FarmObject(**o) for o in plan["objects"]]


def _shape_names(objects: Sequence[FarmObject]) -> list[str]:
    names: dict[int, str] = {}
    for o in objects:
        if names.setdefault(o.label, o.class_name) != o.class_name:
            raise InvalidInputError(f"label {o.label} is used by classes {names[o.label]!r} and {o.class_name!r}")
    return [names.get(i, f"unused_{i}") for i in range(max(names) + 1)] if names else []


def _manifest_lines(objects: Sequence[FarmObject], params: FarmParams, records: dict[int, dict[str, Any]]) -> str:
    return "".join(json.dumps(records.get(o.index) or _base_record(o, params), sort_keys=True) + "\n" for o in objects)


def _write_text(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def _folder_bytes(out: Path) -> int:
    return sum(p.stat().st_size for p in out.rglob("*") if p.is_file())


def _finalize(out: Path, plan: dict[str, Any], records: dict[int, dict[str, Any]], commands: list[str]) -> None:
    """Write manifest, shape names, file lists and (last: it marks the data set finished) the card."""
    objects = _objects_of(plan)
    params = FarmParams(**plan["params"])
    _write_text(out / MANIFEST_FILE, _manifest_lines(objects, params, records))
    shape_names = _shape_names(objects)
    _write_text(out / SHAPE_NAMES_FILE, "".join(f"{n}\n" for n in shape_names))
    splits = sorted({o.split for o in objects}, key=lambda s: (s not in SPLITS, s))
    for split in splits:
        ok_in_split = [o for o in objects if o.split == split and records[o.index]["status"] == "ok"]
        shards = [s for o in ok_in_split for s in records[o.index]["shards"]]
        _write_text(out / file_list_name(split), "".join(f"{s}\n" for s in shards))
    ok = [r for r in records.values() if r["status"] == "ok"]
    card = {
        "format_version": FORMAT_VERSION,
        "tool": "zbuf_occlude",
        "version": _version(),
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "commands": commands,
        "source": plan["source"],
        "storage": params.storage,
        "params": params.to_dict(),
        "params_digest": plan["params_digest"],
        "plan_digest": plan["plan_digest"],
        "poses": [list(p) for p in params.poses],
        "splits": splits,
        "shape_names": shape_names,
        "n_objects": len(objects),
        "n_objects_ok": len(ok),
        "n_objects_failed": len(objects) - len(ok),
        "n_samples": int(sum(r["n_samples"] for r in ok)),
        "shard_bytes": int(sum(r["bytes"] for r in ok)),
        "renderers": sorted({r["renderer"] for r in ok if r.get("renderer")}),
        "seed_derivation": "numpy SeedSequence([seed, blake2b64(name), stream, pose_index, sample_index]), "
        "zbuf_occlude.occlude.derive_rng; stream 0 = dense cloud, 1 = sample draws",
        "reference": "Sryamkin, Msallam, Klestov 2023, "
        "A method to create real-like point clouds for 3D object classification",
    }
    _write_json(out / CARD_FILE, card)


# -- summary -------------------------------------------------------------------------------------
@dataclass
class FarmSummary:
    """What a farm run (or merge) did; :meth:`format` is the one-screen report the CLI prints."""

    out: str
    objects: int
    done: int
    failed: int
    resumed: int
    samples: int
    bytes: int
    wall_s: float
    views: int
    storage: str
    finished: bool
    workers: str = "1 process"
    peak_rss_mb: float = 0.0
    failures: list[tuple[str, str]] = field(default_factory=list)

    @property
    def samples_per_mb(self) -> float:
        return self.samples / (self.bytes / BYTES_PER_MB) if self.bytes else 0.0

    @property
    def views_per_s(self) -> float:
        return self.views / self.wall_s if self.wall_s > 0 else 0.0

    def format(self) -> str:
        """Multi-line human summary."""
        lines = [
            f"zbuf-occlude farm: {self.out}  "
            f"({'finished' if self.finished else 'this task done; run farm-merge when all tasks are'})",
            f"  objects   {self.done} done ({self.resumed} from an earlier run), {self.failed} failed, "
            f"{self.objects} planned",
            f"  samples   {self.samples:,}  ({self.storage} storage)",
            f"  bytes     {self.bytes:,} ({self.bytes / BYTES_PER_MB:.1f} MB)  ->  {self.samples_per_mb:,.1f} samples/MB "
            f"(paper, Table 2: {PAPER_SAMPLES_PER_MB})",
            f"  wall      {self.wall_s:.1f} s, {self.views} views rendered, {self.views_per_s:.1f} views/s, "
            f"{self.workers}, peak RSS per worker {self.peak_rss_mb:.0f} MB",
        ]
        for name, error in self.failures[:10]:
            lines.append(f"  FAILED    {name}: {error}")
        if len(self.failures) > 10:
            lines.append(f"  ... and {len(self.failures) - 10} more failures (see {MANIFEST_FILE})")
        return "\n".join(lines)


# -- the farm ----------------------------------------------------------------------------------
def _prepare_out(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the output folder {out}: {exc.strerror or exc}; choose a writable --out") from exc
    if not os.access(out, os.W_OK | os.X_OK):
        raise OutputError(f"the output folder {out} is not writable; choose a writable --out")


def _wipe(out: Path, objects: Sequence[FarmObject] | None) -> None:
    """``--overwrite``: remove the farm's own files (all, or those of ``objects`` for a sharded task)."""
    if objects is None:
        for name in (SHARD_DIR, RECORD_DIR, TASK_DIR):
            shutil.rmtree(out / name, ignore_errors=True)
        for name in (PLAN_FILE, CARD_FILE, MANIFEST_FILE, SHAPE_NAMES_FILE, *(file_list_name(s) for s in SPLITS)):
            (out / name).unlink(missing_ok=True)
        return
    (out / CARD_FILE).unlink(missing_ok=True)
    for o in objects:
        _record_path(out, o.index).unlink(missing_ok=True)
        (out / shard_path(o)).unlink(missing_ok=True)


def _check_compatible(out: Path, plan: dict[str, Any]) -> None:
    old = _read_json(out / PLAN_FILE)
    if old is None:
        if (out / PLAN_FILE).exists():
            raise OutputError(f"{out / PLAN_FILE} is unreadable; use --overwrite to start over")
        return
    if old.get("params_digest") != plan["params_digest"]:
        diff = {k: (old["params"].get(k), v) for k, v in plan["params"].items() if old["params"].get(k) != v}
        raise InvalidInputError(
            f"{out} holds a farm run with other parameters {diff} (old, new); use --overwrite to start over or another --out"
        )
    if old.get("plan_digest") != plan["plan_digest"]:
        raise InvalidInputError(
            f"{out} holds a farm run over other objects ({len(old['objects'])} vs {len(plan['objects'])}: --classes, "
            "--per-class, --splits or the input changed); use --overwrite or another --out"
        )


def _estimate_bytes(params: FarmParams) -> int:
    poses = len(params.poses)
    dense = params.dense_points or 0
    if params.storage == "compact":
        return dense * 12 + poses * (dense + 7) // 8
    return poses * params.samples_per_view * params.n_points * 12


def run_farm(
    source: str | os.PathLike | Sequence[FarmObject],
    out: str | os.PathLike,
    *,
    params: FarmParams | None = None,
    classes: Sequence[str] | str | None = None,
    per_class: int | None = None,
    splits: Sequence[str] | str = SPLITS,
    workers: int = 1,
    shard: tuple[int, int] = (0, 1),
    scheduler: str | None = None,
    dask_local: int | None = None,
    overwrite: bool = False,
    progress: bool = True,
    command: str | None = None,
) -> FarmSummary:
    """Build (or resume) an occluded data set from many meshes.

    Parameters
    ----------
    source : str, PathLike or sequence of FarmObject
        Mesh tree, flat folder or list file (:func:`discover_objects`), or a ready plan.
    out : str or PathLike
        Data set folder (layout: :mod:`zbuf_occlude.dataset`).
    params : FarmParams, optional
        What to render; default :class:`FarmParams` ``()`` (paper100, 10 samples of 2048
        points per pose, 32768 dense points, 512² z-buffer, seed 0, dense storage).
    classes, per_class, splits
        Selection, see :func:`discover_objects` (ignored for a ready plan).
    workers : int
        Processes rendering in parallel on this machine (``spawn``ed, one GL context each).
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

    Returns
    -------
    FarmSummary

    Raises
    ------
    InvalidInputError
        Bad parameters or selection; ``out`` holds a run with other parameters.
    OutputError
        ``out`` cannot be created or written, or the disk is full (finished objects are kept).
    BackendUnavailable
        No OpenGL 4.3 context, or Dask requested but not installed or unreachable.
    """
    t0 = time.perf_counter()
    params = params or FarmParams()
    if workers < 1:
        raise InvalidInputError(f"--workers must be >= 1, got {workers}")
    if scheduler and dask_local:
        raise InvalidInputError("give either --scheduler or --dask-local, not both")
    if dask_local is not None and dask_local < 1:
        raise InvalidInputError(f"--dask-local must be >= 1, got {dask_local}")
    task, n_tasks = shard
    if isinstance(source, (str, os.PathLike)):
        source_text = str(Path(source).resolve())
        objects = discover_objects(source, classes=classes, per_class=per_class, splits=splits)
    else:
        objects, source_text = list(source), "<objects given by the caller>"
        if [o.index for o in objects] != list(range(len(objects))):
            raise InvalidInputError("a ready plan must number its objects 0, 1, 2, ... in order")
    mine = select_shard(objects, task, n_tasks)
    out = Path(out)
    _prepare_out(out)
    plan = _plan_doc(objects, params, source_text)
    if overwrite:
        _wipe(out, None if n_tasks == 1 else mine)
    else:
        _check_compatible(out, plan)
    _write_json(out / PLAN_FILE, plan)
    command = command or shlex.join(sys.argv)
    _write_json(
        out / TASK_DIR / f"task-{task}-of-{n_tasks}.json",
        {"shard": [task, n_tasks], "command": command, "version": _version(), "host": socket.gethostname(),
         "started": datetime.now(timezone.utc).isoformat(timespec="seconds"), "objects": [o.index for o in mine]},
    )  # fmt: skip
    _remove_stale_temps(out, mine, everything=n_tasks == 1)

    digest = params.digest()
    records: dict[int, dict[str, Any]] = {}
    for o in mine:
        rec = _finished(out, o, digest)
        if rec is not None:
            records[o.index] = rec
    resumed = len(records)
    todo = [o for o in mine if o.index not in records]
    if todo:
        need, free = _estimate_bytes(params) * len(todo), shutil.disk_usage(out).free
        if need > free:
            log.warning("about %.0f MB still to write to %s but only %.0f MB free", need / 1e6, out, free / 1e6)
    log.info("%d objects in this task, %d finished earlier, %d to render", len(mine), resumed, len(todo))

    out = out.resolve()  # workers (Dask: possibly on other machines) may not share our working folder
    if scheduler or dask_local:
        records_iter = _dask(todo, params, out, scheduler, dask_local)
        workers_text = f"dask {scheduler or f'LocalCluster({dask_local})'}"
    elif workers > 1 and len(todo) > 1:
        records_iter = _pool(todo, params, out, min(workers, len(todo)))
        workers_text = f"{min(workers, len(todo))} processes"
    else:
        records_iter = _serial(todo, params, out)
        workers_text = "1 process"

    manifest = out / (MANIFEST_FILE if n_tasks == 1 else f"{TASK_DIR}/manifest-{task}-of-{n_tasks}.jsonl")
    views = 0
    peak = 0.0
    last_manifest = time.monotonic()
    from tqdm.auto import tqdm

    bar = tqdm(total=len(mine), initial=resumed, unit="obj", desc="farm", disable=not progress or None, dynamic_ncols=True)
    t_render = time.perf_counter()
    try:
        for rec in records_iter:
            records[rec["object_index"]] = rec
            peak = max(peak, rec.get("peak_rss_mb", 0.0))
            if rec["status"] == "ok":
                views += len(rec["n_visible"])
            n_failed = sum(r["status"] != "ok" for r in records.values())
            bar.update(1)
            rate = views / max(time.perf_counter() - t_render, 1e-9)
            bar.set_postfix(views_s=f"{rate:.1f}", failed=n_failed, refresh=False)
            if time.monotonic() - last_manifest > MANIFEST_INTERVAL_S:
                _write_text(manifest, _manifest_lines(mine, params, records))
                last_manifest = time.monotonic()
    finally:
        bar.close()
        with contextlib.suppress(OutputError):  # a full disk must not hide the original error
            _write_text(manifest, _manifest_lines(mine, params, records))

    finished = False
    if n_tasks == 1:
        _finalize(out, plan, records, [command])
        finished = True
    else:
        log.info("task %d/%d done; run `zbuf-occlude farm-merge %s` when all %d tasks are", task, n_tasks, out, n_tasks)
    ok = [r for r in records.values() if r["status"] == "ok"]
    return FarmSummary(
        out=str(out),
        objects=len(mine),
        done=len(ok),
        failed=len(records) - len(ok),
        resumed=resumed,
        samples=int(sum(r["n_samples"] for r in ok)),
        bytes=_folder_bytes(out) if finished else int(sum(r["bytes"] for r in ok)),
        wall_s=time.perf_counter() - t0,
        views=views,
        storage=params.storage,
        finished=finished,
        workers=workers_text,
        peak_rss_mb=peak,
        failures=[(r["name"], r["error"]) for r in records.values() if r["status"] != "ok"],
    )


def merge_farm(
    inputs: Sequence[str | os.PathLike], out: str | os.PathLike | None = None, *, progress: bool = True
) -> FarmSummary:
    """Join the outputs of ``--shard I/N`` tasks into one finished data set.

    Parameters
    ----------
    inputs : sequence of str or PathLike
        Task output folders (the same folder for tasks that shared one ``--out``).
    out : str or PathLike, optional
        The data set folder (default: the first input).  Shards of other inputs are
        copied in (atomically); a merge can be rerun.
    progress : bool
        tqdm bar over copied shards.

    Raises
    ------
    InvalidInputError
        An input is not a farm output, inputs disagree on parameters or plan, or objects
        have no result yet (the message names them: rerun their tasks).
    OutputError
        ``out`` cannot be written.
    """
    t0 = time.perf_counter()
    if not inputs:
        raise InvalidInputError("farm-merge needs at least one task output folder")
    folders = [Path(p) for p in inputs]
    out = Path(out) if out is not None else folders[0]
    plans = []
    for folder in folders:
        plan = _read_json(folder / PLAN_FILE)
        if plan is None:
            raise InvalidInputError(f"{folder} is not a farm output (no readable {PLAN_FILE})")
        plans.append(plan)
    for folder, plan in zip(folders[1:], plans[1:]):
        if (plan["params_digest"], plan["plan_digest"]) != (plans[0]["params_digest"], plans[0]["plan_digest"]):
            raise InvalidInputError(f"{folder} was made with other parameters or objects than {folders[0]}; cannot merge")
    plan = plans[0]
    _prepare_out(out)
    if out.resolve() not in {f.resolve() for f in folders}:
        _check_compatible(out, plan)
    _write_json(out / PLAN_FILE, plan)
    objects = _objects_of(plan)
    digest = plan["params_digest"]
    records: dict[int, dict[str, Any]] = {}
    failed: dict[int, dict[str, Any]] = {}
    commands: list[str] = []
    from tqdm.auto import tqdm

    for folder in folders:
        for task_file in sorted((folder / TASK_DIR).glob("task-*.json")):
            doc = _read_json(task_file)
            if doc and doc.get("command") not in commands:
                commands.append(doc["command"])
            if doc and folder.resolve() != out.resolve():
                _write_json(out / TASK_DIR / task_file.name, doc)
        for o in tqdm(objects, desc=f"merge {folder.name}", unit="obj", disable=not progress or None, leave=False):
            if o.index in records:
                continue
            rec = _finished(folder, o, digest)
            if rec is None:
                other = _read_json(_record_path(folder, o.index))
                if other and other.get("params_digest") == digest and other.get("status") == "failed":
                    failed[o.index] = other
                continue
            if folder.resolve() != out.resolve():
                for rel in rec["shards"]:
                    with atomic_path(out / rel) as tmp:
                        shutil.copyfile(folder / rel, tmp)
                _write_json(_record_path(out, o.index), rec)
            records[o.index] = rec
    for index, rec in failed.items():
        if index not in records:
            records[index] = rec
            _write_json(_record_path(out, index), rec)
    missing = [o for o in objects if o.index not in records]
    if missing:
        names = ", ".join(f"{o.index}:{o.name}" for o in missing[:5])
        raise InvalidInputError(
            f"{len(missing)} of {len(objects)} objects have no result yet ({names}{', ...' if len(missing) > 5 else ''}); "
            "rerun the tasks that own them (object i belongs to task i mod N), then merge again"
        )
    commands.append(shlex.join(sys.argv))
    _finalize(out, plan, records, commands)
    ok = [r for r in records.values() if r["status"] == "ok"]
    return FarmSummary(
        out=str(out),
        objects=len(objects),
        done=len(ok),
        failed=len(objects) - len(ok),
        resumed=len(ok),
        samples=int(sum(r["n_samples"] for r in ok)),
        bytes=_folder_bytes(out),
        wall_s=time.perf_counter() - t0,
        views=0,
        storage=plan["params"]["storage"],
        finished=True,
        workers="merge",
        failures=[(r["name"], r["error"]) for r in records.values() if r["status"] != "ok"],
    )


# -- command line (called from zbuf_occlude.cli) -------------------------------------------------
def _farm_command(args: argparse.Namespace) -> int:
    if args.density is not None and args.dense_points is not None:
        raise InvalidInputError("give either --density or --dense-points, not both")
    params = FarmParams(
        views=args.views,
        samples_per_view=args.samples_per_view,
        n_points=args.points,
        dense_points=args.dense_points if args.dense_points is not None else DEFAULT_FARM_DENSE_POINTS,
        density=args.density,
        resolution=args.resolution,
        seed=args.seed,
        radius=args.radius,
        storage=args.storage,
    )
    summary = run_farm(
        args.root,
        args.out,
        params=params,
        classes=args.classes,
        per_class=args.per_class,
        splits=args.splits,
        workers=args.workers,
        shard=parse_shard(args.shard) if args.shard else (0, 1),
        scheduler=args.scheduler,
        dask_local=args.dask_local,
        overwrite=args.overwrite,
        progress=not args.no_progress,
        command=shlex.join(["zbuf-occlude", *sys.argv[1:]]) if sys.argv else None,
    )
    print(summary.format())
    return 1 if summary.failed else 0


def _merge_command(args: argparse.Namespace) -> int:
    summary = merge_farm(args.inputs, args.out, progress=not args.no_progress)
    print(summary.format())
    return 1 if summary.failed else 0


def add_farm_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``farm`` subcommand to an ``argparse`` subparsers object (``func`` → exit status)."""
    p = subparsers.add_parser(
        "farm",
        help="build a whole occluded data set (parallel, resumable, sharded, Dask)",
        description="Render every mesh of ROOT from every pose and write a PointNet-style HDF5 data set to --out. "
        "Run the same command again to resume; objects already finished are skipped.",
    )
    p.add_argument(
        "root", help="ModelNet-style tree ROOT/<class>/<split>/<name>.off, a flat folder, or a list file 'PATH LABEL [SPLIT]'"
    )
    p.add_argument("--out", required=True, help="data set folder")
    sel = p.add_argument_group("selection")
    sel.add_argument("--classes", help="comma-separated class names (default: all)")
    sel.add_argument("--per-class", type=int, help="first K meshes (by name) of each class and split")
    sel.add_argument("--splits", default="train,test", help="comma-separated splits (default: train,test)")
    r = p.add_argument_group("rendering")
    r.add_argument("--views", default=DEFAULT_VIEWS, help="paper100 | grid25 | fibonacci:N | EL:AZ,... (default: paper100)")
    r.add_argument(
        "--samples-per-view", type=int, default=DEFAULT_SAMPLES_PER_VIEW, help="random draws per pose (default: 10)"
    )
    r.add_argument("--points", type=int, default=DEFAULT_N_POINTS, help="points per sample (default: 2048)")
    dense = r.add_mutually_exclusive_group()
    dense.add_argument(
        "--dense-points", type=int, help=f"dense cloud per mesh, sampled once (default: {DEFAULT_FARM_DENSE_POINTS})"
    )
    dense.add_argument("--density", type=float, help="dense cloud as points per unit area of the normalised mesh")
    r.add_argument(
        "--resolution", type=int, default=DEFAULT_FARM_RESOLUTION, help=f"z-buffer size, pixels (default: {DEFAULT_FARM_RESOLUTION})"
    )
    r.add_argument(
        "--radius", type=float, default=DEFAULT_RADIUS, help=f"camera distance, object units (default: {DEFAULT_RADIUS})"
    )
    r.add_argument("--seed", type=int, default=0, help="global seed (default: 0)")
    r.add_argument(
        "--storage", choices=STORAGE_MODES, default="dense", help="dense: PointNet HDF5; compact: dense cloud + visibility bits"
    )
    ex = p.add_argument_group("execution")
    ex.add_argument("--workers", type=int, default=1, help="worker processes on this machine (default: 1)")
    ex.add_argument(
        "--shard", help="I/N: render the I-th of N partitions (SLURM array, Kubernetes indexed job); then farm-merge"
    )
    dask = ex.add_mutually_exclusive_group()
    dask.add_argument("--scheduler", help="Dask scheduler address tcp://HOST:PORT (out must be on a shared file system)")
    dask.add_argument("--dask-local", type=int, metavar="N", help="run on a local Dask cluster of N worker processes")
    ex.add_argument("--overwrite", action="store_true", help="start over instead of resuming")
    ex.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_farm_command)
    return p


def add_farm_merge_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``farm-merge`` subcommand (``func`` → exit status)."""
    p = subparsers.add_parser(
        "farm-merge",
        help="join the outputs of `farm --shard I/N` tasks into one data set",
        description="Check that every object of the plan has a result, copy shards from other task folders, "
        "and write the manifest, file lists and data set card.",
    )
    p.add_argument("inputs", nargs="+", help="task output folders (one folder if all tasks shared --out)")
    p.add_argument("--out", help="data set folder (default: the first input)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_merge_command)
    return p
