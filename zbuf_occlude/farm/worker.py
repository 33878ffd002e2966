"""The unit of work: one object, all its poses, one shard and one record."""

from __future__ import annotations

import functools
import json
import logging
import os
import resource
import socket
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from zbuf_occlude._version import __version__
from zbuf_occlude.dataset.layout import FORMAT_VERSION, SAMPLE_FILE_FORMATS
from zbuf_occlude.dataset.schema import ObjectRecord
from zbuf_occlude.farm.config import (
    COMPACT_GZIP_LEVEL,
    FATAL_ERRORS,
    GL_LOCK,
    FarmParams,
    record_path,
    sample_file_path,
    shard_path,
)
from zbuf_occlude.geometry.samples import OccludedCloud
from zbuf_occlude.io.atomic import atomic_h5, file_sha256, write_text
from zbuf_occlude.io.clouds import write_h5, write_npz, write_ply
from zbuf_occlude.io.safe_paths import check_relative_name, path_inside
from zbuf_occlude.mesh.inputs import FarmObject
from zbuf_occlude.pipeline import dense_cloud, occlude_poses

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


def _scan(obj: FarmObject, params: FarmParams, out: Path) -> dict[str, Any]:
    """``farm --sensor``: ``samples_per_view`` LiDAR crops of one object into a dense shard.

    Row ``i`` of the shard is scan ``pose_index[i]`` (scans without a return are left out);
    besides the dense layout's datasets it holds the scan's placement (``distance_m``,
    ``sensor_height_m``, ``object_azimuth_deg``, ``yaw_deg``, ``size_m``, ``radius``) and
    ``ring``.  The record's ``n_visible`` has one entry per scan (0: no return).
    """
    from zbuf_occlude.farm.sensor_crops import farm_datasets
    from zbuf_occlude.mesh.load import load_mesh  # trimesh: imported by the work, not by modules that only read records

    mesh = load_mesh(obj.source, up=params.up)
    n_scans = int(params.samples_per_view)
    datasets = farm_datasets(
        mesh, params.sensor_model(), name=obj.name, label=obj.label, object_index=obj.index, n_samples=n_scans,
        n_points=params.n_points, seed=params.seed, distributions=params.crop_distributions(),
        across_sight_width_m=params.sensor_across_sight_width_m,
    )  # fmt: skip
    n_visible = np.zeros(n_scans, dtype=np.int64)
    n_visible[datasets["pose_index"]] = datasets["n_visible"]
    rel = shard_path(obj)
    _write_datasets(out / rel, datasets, {**_attrs(obj, params), "sensor": params.sensor})
    b = len(datasets["data"])
    return {
        "shards": [rel],
        "sha256": [file_sha256(out / rel)],
        "n_visible": n_visible.tolist(),
        "n_samples": b,
        "n_padded_poses": int(np.count_nonzero((n_visible > 0) & (n_visible < params.n_points))),
        "n_dense": 0,
        "n_faces": int(len(mesh.faces)),
        "bytes": int((out / rel).stat().st_size),
        **_up_record(mesh),
    }


def _up_record(mesh) -> dict[str, str]:
    """The up axis the mesh was read with and the rule that chose it (the card sums them)."""
    from zbuf_occlude.mesh.load import METADATA_KEY

    meta = mesh.metadata.get(METADATA_KEY, {})
    return {"up": str(meta.get("up", "+z")), "up_source": str(meta.get("up_source", "as stored (+z)"))}


def _write_datasets(path: Path, datasets: dict[str, np.ndarray], attrs: dict[str, Any]) -> None:
    """One shard of named arrays (insertion order, no modification times: same inputs, same bytes)."""
    with atomic_h5(path) as f:
        for key, data in datasets.items():
            f.create_dataset(key, data=data, track_times=False)
        f.attrs.update(attrs)


def _render(obj: FarmObject, params: FarmParams, out: Path) -> dict[str, Any]:
    if params.sensor is not None:
        return _scan(obj, params, out)
    if params.storage in SAMPLE_FILE_FORMATS:  # the name becomes folders under out: `...off` (name "..") must not leave it
        check_relative_name(obj.name, what=f"the name of {obj.source}")
    from zbuf_occlude.mesh.load import load_mesh  # trimesh: imported by the work, not by modules that only read records

    mesh = load_mesh(obj.source, up=params.up)
    dense = dense_cloud(mesh, obj.key, seed=params.seed, count=params.dense_points, density=params.density)
    poses = params.poses
    common = dict(
        key=obj.key, n_points=params.n_points, seed=params.seed, dense=dense, method=params.method,
        resolution=params.resolution, radius=params.radius, label=obj.label, class_name=obj.class_name,
        source=obj.source, split=obj.split,
    )  # fmt: skip
    n_visible = np.zeros(len(poses), dtype=np.int64)  # distinct visible points per pose, top-up included
    n_topped_up = np.zeros(len(poses), dtype=np.int64)
    if params.storage in SAMPLE_FILE_FORMATS:
        # generate's npz/ply: one file per sample under DATASET/<name>/
        written: list[str] = []
        for pose in occlude_poses(mesh, poses, samples_per_view=params.samples_per_view, **common):
            n_visible[pose.pose_index], n_topped_up[pose.pose_index] = pose.n_visible, len(pose.topped_up)
            for c in pose.clouds:
                rel = sample_file_path(obj.name, pose.pose_index, c, params.storage)
                (write_npz if params.storage == "npz" else write_ply)(path_inside(out, rel, what=obj.source), c)
                written.append(rel)
        files = written
        b = len(written)
    elif params.storage in ("dense", "h5"):
        clouds_all: list[OccludedCloud] = []
        pose_of: list[int] = []
        for pose in occlude_poses(mesh, poses, samples_per_view=params.samples_per_view, **common):
            n_visible[pose.pose_index], n_topped_up[pose.pose_index] = pose.n_visible, len(pose.topped_up)
            clouds_all.extend(pose.clouds)
            pose_of.extend([pose.pose_index] * len(pose.clouds))
        b = len(clouds_all)
        # dense (farm): PointNet's columns only; h5 (generate): with face_index, radius, source, class
        write_h5(
            out / shard_path(obj), clouds_all, n_points=params.n_points, provenance=params.storage == "h5",
            columns={"object_index": np.full(b, obj.index, dtype=np.int64), "pose_index": np.asarray(pose_of, np.int64)},
            attrs=_attrs(obj, params),
        )  # fmt: skip
        files = [shard_path(obj)]
    else:
        n_dense = len(dense.points)
        bits = np.zeros((len(poses), (n_dense + 7) // 8), dtype=np.uint8)
        topped_up: list[np.ndarray] = []
        # samples_per_view=0: only the masks and the top-up points are needed, the reader draws the samples
        for pose in occlude_poses(mesh, poses, samples_per_view=0, topped_up=True, **common):
            n_visible[pose.pose_index], n_topped_up[pose.pose_index] = pose.n_visible, len(pose.topped_up)
            bits[pose.pose_index] = np.packbits(pose.visible)
            topped_up.append(pose.topped_up.points)
        b = int(np.count_nonzero(n_visible) * params.samples_per_view)
        topup_points = np.concatenate(topped_up) if topped_up else np.zeros((0, 3))
        _write_compact(
            out / shard_path(obj), dense.points, bits, n_visible, n_topped_up, topup_points, poses, _attrs(obj, params)
        )
        files = [shard_path(obj)]

    # hashed right after writing, under the data set's lock: nobody else writes these files
    return {
        "shards": files,
        "sha256": [file_sha256(out / rel) for rel in files],
        "n_visible": n_visible.tolist(),
        "n_samples": b,
        "n_padded_poses": int(np.count_nonzero((n_visible > 0) & (n_visible < params.n_points))),
        "n_topped_up": n_topped_up.tolist(),
        "n_dense": int(len(dense.points)),
        "n_faces": int(len(mesh.faces)),
        "bytes": int(sum((out / rel).stat().st_size for rel in files)),
        **_up_record(mesh),
    }


def _write_compact(path: Path, dense_points, bits, n_visible, n_topped_up, topup_points, poses, attrs: dict[str, Any]) -> None:
    """The compact shard: dense cloud once, visibility bits and top-up points per pose (layout:
    :mod:`zbuf_occlude.dataset.layout`)."""
    el_az = np.asarray(poses, dtype=np.float64).reshape(-1, 2)
    with atomic_h5(path) as f:
        f.create_dataset("dense_points", data=dense_points.astype(np.float32), track_times=False)
        f.create_dataset(
            "visible_bits", data=bits, chunks=bits.shape if bits.size else None,
            compression="gzip" if bits.size else None,
            compression_opts=COMPACT_GZIP_LEVEL if bits.size else None, track_times=False,
        )  # fmt: skip
        f.create_dataset("n_visible", data=n_visible, track_times=False)
        f.create_dataset("n_topped_up", data=n_topped_up, track_times=False)
        f.create_dataset("topup_points", data=np.asarray(topup_points, dtype=np.float32).reshape(-1, 3), track_times=False)
        f.create_dataset("elevation_deg", data=el_az[:, 0], track_times=False)
        f.create_dataset("azimuth_deg", data=el_az[:, 1], track_times=False)
        f.attrs.update(attrs)
        f.attrs["n_dense"] = len(dense_points)


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
    record = base_record(obj, params)
    t0 = time.perf_counter()
    try:
        with GL_LOCK:
            record.update(_render(obj, params, out))
        record["status"] = "ok"
    except FATAL_ERRORS:
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
    return write_record(out, obj, record)


def write_record(out: Path, obj: FarmObject, record: dict[str, Any]) -> dict[str, Any]:
    """Write ``record`` as the schema's :class:`~zbuf_occlude.dataset.schema.ObjectRecord` (a field
    it does not declare, or a value of the wrong type, is our bug: pydantic's ``ValidationError``)."""
    record = ObjectRecord.model_validate(record).model_dump(exclude_unset=True)
    write_json(record_path(out, obj.index), record)
    return record
