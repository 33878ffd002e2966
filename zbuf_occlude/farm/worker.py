"""The unit of work: one object, all its poses, one shard and one record."""

from __future__ import annotations

import errno
import functools
import json
import logging
import os
import resource
import socket
import sys
import time
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from ..dataset import (
    FORMAT_VERSION,
)
from ..io import atomic_path, file_sha256, write_text
from ..mesh import load_mesh
from ..occlude import dense_cloud, occlude_object
from .config import COMPACT_GZIP_LEVEL, FarmParams, _FATAL, _GL_LOCK, _record_path, shard_path
from .inputs import FarmObject

log = logging.getLogger(__name__)


# -- the unit of work --------------------------------------------------------------------------
def _version() -> str:
    from .. import __version__  # deferred: the package imports this module while it initialises

    return __version__


def _write_json(path: Path, obj: Any) -> None:
    write_text(path, json.dumps(obj, indent=1, sort_keys=True) + "\n")


def _write_h5(path: Path, fill: Callable[[Any], None]) -> tuple[int, str]:
    """Write an HDF5 file atomically; return its size in bytes and its SHA-256 (hex)."""
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
        # hashed before the rename: the digest is of the bytes this process wrote
        digest = file_sha256(tmp)
    return path.stat().st_size, digest


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
    from ..render import context_info

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

    n_bytes, sha256 = _write_h5(path, fill)
    return {
        "shards": [shard_path(obj)],
        "sha256": [sha256],
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
