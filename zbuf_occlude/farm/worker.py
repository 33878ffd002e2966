"""The unit of work: one object, all its poses, one shard and one record."""

from __future__ import annotations

import functools
import json
import logging
import os
import resource
import sys
import time
from collections.abc import Iterable, Iterator
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude._version import __version__
from zbuf_occlude.dataset.layout import FORMAT_VERSION
from zbuf_occlude.dataset.schema import ObjectRecord
from zbuf_occlude.dataset.storage import SensorCrops, ShardTarget, StorageKind, storage_kind
from zbuf_occlude.farm.config import COMPACT_GZIP_LEVEL, FATAL_ERRORS, GL_LOCK, FarmParams, record_path, shard_path
from zbuf_occlude.geometry.samples import ObjectProvenance
from zbuf_occlude.io.atomic import file_sha256, write_text
from zbuf_occlude.mesh.inputs.kinds import MESH, POINT_SET
from zbuf_occlude.mesh.inputs.plan import FarmObject
from zbuf_occlude.pipeline import POINT_SET_METHOD, CameraSphere, PoseDraws, PoseResult, dense_cloud, occlude_point_set, occlude_poses

log = logging.getLogger(__name__)


# -- the unit of work --------------------------------------------------------------------------
def package_version() -> str:
    return __version__


def write_json(path: Path, obj: Any) -> None:
    write_text(path, json.dumps(obj, indent=1, sort_keys=True) + "\n")


def _attrs(obj: FarmObject, params: FarmParams) -> dict[str, Any]:
    return {
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
        "zbuf_occlude_version": package_version(),
    }


@functools.lru_cache(maxsize=1)
def _renderer_name() -> str:
    from zbuf_occlude.render import context_info

    try:
        info = context_info()
    except Exception:  # provenance only: never fail an object for it
        return "unknown"
    return f"{info['renderer']} ({info['backend']}, {info['version']})"


def _peak_rss_mb() -> float:
    # ru_maxrss is in KiB on Linux (bytes on macOS)
    scale = 1.0 if sys.platform == "darwin" else 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale / 2**20


def _provenance(obj: FarmObject) -> ObjectProvenance:
    """What each sample of ``obj`` copies from it."""
    return ObjectProvenance(label=obj.label, class_name=obj.class_name, source=obj.source, split=obj.split)


def _scan(obj: FarmObject, params: FarmParams, out: Path, kind: SensorCrops, mesh_path: Path) -> dict[str, Any]:
    """``farm --sensor``: ``samples_per_view`` LiDAR crops of one object into a dense shard.

    Row ``i`` of the shard is scan ``pose_index[i]`` (scans without a return are left out);
    besides the dense layout's datasets it holds the scan's placement (``distance_m``,
    ``sensor_height_m``, ``object_azimuth_deg``, ``yaw_deg``, ``size_m``, ``radius``) and
    ``ring``, and the return fields of a sensor that records several returns per pulse, which
    the record names (``point_columns``).  The record's ``n_visible`` has one entry per scan (0: no return).
    """
    from zbuf_occlude.farm.sensor_crops import farm_datasets
    from zbuf_occlude.mesh.load import load_mesh  # trimesh: imported by the work, not by modules that only read records

    mesh = load_mesh(mesh_path, up=params.up)
    n_scans = int(params.samples_per_view)
    datasets = farm_datasets(
        mesh, params.sensor.request(), name=obj.name, label=obj.label, object_index=obj.index, n_samples=n_scans,
        n_points=params.n_points, seed=params.seed, distributions=params.sensor.distributions,
        across_sight_width_m=params.sensor.across_sight_width_m,
    )  # fmt: skip
    n_visible = np.zeros(n_scans, dtype=np.int64)
    n_visible[datasets["pose_index"]] = datasets["n_visible"]
    held = kind.write_rows(out / shard_path(obj), datasets, {**_attrs(obj, params), "sensor": params.sensor.name})  # its point_columns
    return {
        **_files_record(out, [shard_path(obj)], n_visible, len(datasets["data"]), params.n_points),
        "n_dense": 0,
        **_mesh_record(mesh),
        **held,
    }


def _occlude(obj: FarmObject, params: FarmParams, out: Path, kind: StorageKind, mesh_path: Path) -> dict[str, Any]:
    """The poses of one object, by its input kind (:attr:`~zbuf_occlude.mesh.inputs.FarmObject.kind`), written by its storage kind."""
    kind.check_name(obj.name, what=f"the name of {obj.source}")  # before any work
    return _OCCLUDERS[obj.kind](obj, params, out, kind, mesh_path)


def _occlude_mesh(obj: FarmObject, params: FarmParams, out: Path, kind: StorageKind, mesh_path: Path) -> dict[str, Any]:
    """The z-buffer poses of one mesh."""
    mesh = obj.kind.read(mesh_path, obj.cloud, up=params.up)
    dense = dense_cloud(mesh, obj.key, seed=params.seed, count=params.dense_points, density=params.density)
    results = occlude_poses(
        mesh, params.poses, key=obj.key, draws=PoseDraws(params.n_points, **kind.occlude_options(params.samples_per_view)),
        seed=params.seed, dense=dense, method=params.method, cameras=CameraSphere(params.radius, params.resolution),
        provenance=_provenance(obj),
    )  # fmt: skip
    return {**_write_poses(obj, params, out, kind, dense.points, results), **_mesh_record(mesh)}


def _occlude_points(obj: FarmObject, params: FarmParams, out: Path, kind: StorageKind, path: Path) -> dict[str, Any]:
    """The poses of one cloud of a point-set file: its points are the dense cloud (nothing is
    sampled: ``--dense-points`` and ``--density`` do not apply), their visibility comes from the
    points alone (:func:`~zbuf_occlude.pipeline.occlude_point_set`), written by the storage kind
    as a mesh's are.  The record says so (``visibility``, ``visibility_from``, ``normals``)."""
    cloud = obj.kind.read(path, obj.cloud, up=params.up)
    samples_per_view = kind.occlude_options(params.samples_per_view)["samples_per_view"]  # compact: 0, it redraws
    results = occlude_point_set(
        cloud.points, params.poses, key=obj.key, normals=cloud.normals, n_points=params.n_points,
        samples_per_view=samples_per_view, seed=params.seed, cameras=CameraSphere(params.radius, params.resolution),
        provenance=_provenance(obj),
    )  # fmt: skip
    return {
        **_write_poses(obj, params, out, kind, cloud.points, results),
        "up": cloud.up, "up_source": cloud.up_source,
        "visibility": POINT_SET_METHOD, "visibility_from": "points", "normals": cloud.normals is not None,
    }  # fmt: skip


def _write_poses(
    obj: FarmObject, params: FarmParams, out: Path, kind: StorageKind, dense_points: NDArray[np.float64], results: Iterable[PoseResult]
) -> dict[str, Any]:
    """Write one object's poses with its storage kind; the record's fields of what was written
    (files, visible and topped-up points per pose, the dense cloud's size)."""
    poses = params.poses
    n_visible = np.zeros(len(poses), dtype=np.int64)  # distinct visible points per pose, top-up included
    n_topped_up = np.zeros(len(poses), dtype=np.int64)

    def counted(results: Iterable[PoseResult]) -> Iterator[PoseResult]:
        for pose in results:
            n_visible[pose.pose_index], n_topped_up[pose.pose_index] = pose.n_visible, len(pose.topped_up)
            yield pose

    target = ShardTarget(
        out=out, name=obj.name, source=obj.source, shard=shard_path(obj), object_index=obj.index, n_points=params.n_points,
        poses=poses, attrs=_attrs(obj, params), dense_points=dense_points, gzip_level=COMPACT_GZIP_LEVEL,
    )  # fmt: skip
    files = kind.write_poses(target, counted(results))
    n_samples = int(kind.rows_per_pose(n_visible, params.samples_per_view).sum())
    return {
        **_files_record(out, files, n_visible, n_samples, params.n_points),
        "n_topped_up": n_topped_up.tolist(),
        "n_dense": int(len(dense_points)),
    }


#: How the farm sees an object of each input kind (:mod:`zbuf_occlude.mesh.inputs.kinds`).
_OCCLUDERS = {MESH: _occlude_mesh, POINT_SET: _occlude_points}

#: How the farm makes the input of each kind (:attr:`~zbuf_occlude.dataset.storage.StorageKind.made_from`).
_PRODUCERS = {"poses": _occlude, "scans": _scan}


def _render(obj: FarmObject, params: FarmParams, out: Path, mesh_path: Path) -> dict[str, Any]:
    """Render one object and write its files; the record's fields that say what was written."""
    kind = storage_kind(params.storage, sensor=params.sensor is not None)
    return _PRODUCERS[kind.made_from](obj, params, out, kind, mesh_path)


def _files_record(out: Path, files: list[str], n_visible: NDArray[np.int64], n_samples: int, n_points: int) -> dict[str, Any]:
    """The record's fields of the files written and the samples they hold."""
    # hashed right after writing, under the data set's lock: nobody else writes these files
    return {
        "shards": files,
        "sha256": [file_sha256(out / rel) for rel in files],
        "n_visible": n_visible.tolist(),
        "n_samples": int(n_samples),
        "n_padded_poses": int(np.count_nonzero((n_visible > 0) & (n_visible < n_points))),
        "bytes": int(sum((out / rel).stat().st_size for rel in files)),
    }


def _mesh_record(mesh) -> dict[str, Any]:
    """The faces of the mesh, the up axis it was read with and the rule that chose it (the card sums them)."""
    from zbuf_occlude.mesh.load import METADATA_KEY

    meta = mesh.metadata.get(METADATA_KEY, {})
    return {"n_faces": int(len(mesh.faces)), "up": str(meta.get("up", "+z")), "up_source": str(meta.get("up_source", "as stored (+z)"))}


def base_record(obj: FarmObject, params: FarmParams) -> dict[str, Any]:
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
        "sha256": [],
        "n_visible": [],
        "n_samples": 0,
        "bytes": 0,
        # a point-set input's cloud: its row in the file (a mesh's record has no such field)
        **({"cloud": obj.cloud} if obj.cloud is not None else {}),
    }


def process_object(obj: FarmObject, params: FarmParams, out: str | os.PathLike, root: str | os.PathLike | None = None) -> dict[str, Any]:
    """Render one object, write its shard and record (atomically), return the record.

    The function every executor runs (it must be importable by Dask workers).  A mesh
    that fails gets ``status="failed"`` and its error in the record; the farm goes on.
    The record (and a shard's ``source`` column) holds ``obj.source`` as it is; with
    ``root`` (the input root, :func:`~zbuf_occlude.farm.journal.input_root`), ``obj.source``
    is relative to it, the mesh is read from ``root / obj.source`` and the root is cut
    from the paths in the error, so that the record holds no absolute path.

    Raises
    ------
    OutputError
        The shard or record cannot be written (disk full, unwritable folder): fatal.
    BackendUnavailable
        No OpenGL context: fatal, no object could be rendered.
    """
    out = Path(out)
    mesh_path = Path(obj.source) if root is None else Path(root, obj.source)
    record = base_record(obj, params)
    t0 = time.perf_counter()
    try:
        with GL_LOCK:
            record.update(_render(obj, params, out, mesh_path))
        record["status"] = "ok"
    except FATAL_ERRORS:
        raise
    except Exception as exc:  # a bad mesh must not stop a farm of thousands; the manifest keeps why
        error = f"{type(exc).__name__}: {exc}"
        record.update(status="failed", error=error if root is None else error.replace(f"{Path(root)}{os.sep}", ""))
        # info, not a warning: the run's summary names each failed object once, and the progress bar counts them
        log.info("object %s (%s) failed: %s", obj.index, mesh_path, error)
        log.debug("traceback of %s", mesh_path, exc_info=True)
    record.update(
        time_s=round(time.perf_counter() - t0, 4),
        finished_at=datetime.now(timezone.utc).isoformat(timespec="seconds"),
        # a point set's visibility is decided on the CPU from its points (the record's 'visibility'): no renderer
        renderer=_renderer_name() if record["status"] == "ok" and obj.kind.renders else None,
        pid=os.getpid(),
        peak_rss_mb=round(_peak_rss_mb(), 1),
    )
    return write_record(out, obj, record)


def write_record(out: Path, obj: FarmObject, record: dict[str, Any]) -> dict[str, Any]:
    """Write ``record`` as the schema's :class:`~zbuf_occlude.dataset.schema.ObjectRecord` (a field
    it does not declare, or a value of the wrong type, is our bug: pydantic's ``ValidationError``)."""
    record = ObjectRecord.model_validate(record).model_dump(exclude_unset=True)
    write_json(record_path(out, obj.index), record)
    return record
