"""Writers and readers of occluded point clouds: ``.npz``, ``.ply``, PointNet-layout ``.h5``.

Every write is atomic (:mod:`zbuf_occlude.io.atomic`): a reader or a resumed run never sees a
partial file, and a failed write raises :class:`~zbuf_occlude.errors.OutputError`.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from zbuf_occlude.errors import DatasetFormatError, OutputError
from zbuf_occlude.geometry.samples import OccludedCloud
from zbuf_occlude.io.arrays import load_npz
from zbuf_occlude.io.atomic import atomic_h5, atomic_path
from zbuf_occlude.io.caps import MAX_CLOUD_NPZ_BYTES, MAX_CLOUD_NPZ_POINTS
from zbuf_occlude.io.hdf5 import Column, open_hdf5

__all__ = [
    "write_npz",
    "read_npz",
    "write_ply",
    "write_h5",
    "concat_h5",
    "read_h5",
    "read_h5_clouds",
    "clouds_of_h5",
    "FORMATS",
]

#: File formats :func:`write_clouds` knows.
FORMATS = ("npz", "ply", "h5")

#: The arrays of :func:`write_npz`'s files: name → (dtype kinds accepted, rank).
_NPZ_ARRAYS: dict[str, tuple[str, int]] = {
    "points": ("f", 2), "face_index": ("iu", 1),
    "elevation_deg": ("fiu", 0), "azimuth_deg": ("fiu", 0), "radius": ("fiu", 0),
    "label": ("iu", 0), "sample_index": ("iu", 0), "n_visible": ("iu", 0),
    "class_name": ("U", 0), "source": ("U", 0), "split": ("U", 0),
}  # fmt: skip
#: Arrays files of older versions lack.
_NPZ_OPTIONAL = ("split",)
_KIND_NAMES = {"f": "floats", "iu": "integers", "fiu": "numbers", "U": "text"}


def write_npz(path: str | os.PathLike, cloud: OccludedCloud) -> Path:
    """Write one cloud as ``.npz``: ``points (n, 3) float32``, ``face_index (n,) int64``,
    ``elevation_deg``, ``azimuth_deg``, ``radius``, ``label``, ``class_name``, ``source``,
    ``sample_index``, ``n_visible``, ``split`` (scalars as 0-d arrays)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(
                fh,
                points=np.asarray(cloud.points, dtype=np.float32),
                face_index=np.asarray(cloud.face_index, dtype=np.int64),
                elevation_deg=np.float64(cloud.elevation_deg),
                azimuth_deg=np.float64(cloud.azimuth_deg),
                radius=np.float64(cloud.radius),
                label=np.int64(cloud.label),
                class_name=np.str_(cloud.class_name),
                source=np.str_(cloud.source),
                sample_index=np.int64(cloud.sample_index),
                n_visible=np.int64(cloud.n_visible),
                split=np.str_(cloud.split),
            )
    return path


def read_npz(path: str | os.PathLike) -> OccludedCloud:
    """Read a cloud written by :func:`write_npz`, checking the file before anything is inflated.

    The file may come from anyone: :func:`zbuf_occlude.io.arrays.load_npz` opens only a regular
    file (a FIFO or a device named ``x.npz`` is refused at once instead of blocking or reading
    without end), reads its arrays' sizes from the zip directory and the ``.npy`` headers (cap
    :data:`~zbuf_occlude.io.caps.MAX_CLOUD_NPZ_BYTES`), and every array's declared shape and dtype is checked here before
    any is inflated, from that same open file; nothing is unpickled.

    Parameters
    ----------
    path : str or PathLike
        A ``.npz`` of :func:`write_npz`.

    Returns
    -------
    OccludedCloud
        ``points (n, 3)`` in the file's float dtype (float32 as written), ``face_index (n,)``
        in its integer dtype; ``split`` is ``""`` in files that have none (older versions).

    Raises
    ------
    DatasetFormatError
        Naming the file and what is wrong: missing or unreadable, not a regular file (a FIFO,
        a device, a folder), not a zip or damaged, arrays inflating past
        :data:`~zbuf_occlude.io.caps.MAX_CLOUD_NPZ_BYTES` or a header declaring more than its member holds, an object
        (pickled) array, a missing array, ``points`` not ``(n, 3)`` floats with ``n`` at most
        :data:`~zbuf_occlude.io.caps.MAX_CLOUD_NPZ_POINTS`, ``face_index`` not ``(n,)`` integers, or a scalar that is not
        0-d of its kind (numbers for the pose and counts, text for the names).
    """
    path = Path(path)

    def check(declared: dict[str, tuple[tuple[int, ...], np.dtype]]) -> None:
        missing = [k for k in _NPZ_ARRAYS if k not in declared and k not in _NPZ_OPTIONAL]
        if missing:
            raise DatasetFormatError(f"{path}: not a cloud of write_npz: no array {', '.join(map(repr, missing))}")
        for key, (shape, dtype) in declared.items():
            _check_declared(path, key, shape, dtype)
        n = declared["points"][0][0]
        if declared["face_index"][0] != (n,):
            raise DatasetFormatError(f"{path}: face_index is declared {declared['face_index'][0]}, not ({n},) like points")

    # one open file: a regular file, its sizes and headers checked, then the arrays read from it
    a = load_npz(path, max_bytes=MAX_CLOUD_NPZ_BYTES, error=DatasetFormatError, keys=_NPZ_ARRAYS, check=check)
    return OccludedCloud(
        points=a["points"],
        face_index=a["face_index"],
        elevation_deg=float(a["elevation_deg"]),
        azimuth_deg=float(a["azimuth_deg"]),
        radius=float(a["radius"]),
        label=int(a["label"]),
        class_name=str(a["class_name"]),
        source=str(a["source"]),
        sample_index=int(a["sample_index"]),
        n_visible=int(a["n_visible"]),
        split=str(a["split"]) if "split" in a else "",  # files of older versions have none
    )


def _check_declared(path: Path, key: str, shape: tuple[int, ...], dtype: np.dtype) -> None:
    """Refuse array ``key`` of a cloud ``.npz`` whose header declares another rank or kind."""
    kinds, rank = _NPZ_ARRAYS[key]
    if dtype.kind not in kinds or len(shape) != rank:
        expected = {1: "(n,)", 2: "(n, 3)"}.get(rank, "0-d")
        raise DatasetFormatError(f"{path}: {key} is declared {shape} {dtype}, not a {expected} array of {_KIND_NAMES[kinds]}")
    if key == "points" and (shape[1] != 3 or shape[0] > MAX_CLOUD_NPZ_POINTS):
        raise DatasetFormatError(f"{path}: points is declared {shape}, not (n, 3) with n at most {MAX_CLOUD_NPZ_POINTS:,}")


def write_ply(path: str | os.PathLike, cloud: OccludedCloud) -> Path:
    """Write one cloud as binary little-endian ``.ply`` (x, y, z float32 and a ``face_index``
    int32 property), readable by Open3D, trimesh and CloudCompare; the pose goes in
    ``comment`` lines of the header."""
    pts = np.asarray(cloud.points, dtype=np.float32)
    rows = np.empty(len(pts), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("face_index", "<i4")])
    rows["x"], rows["y"], rows["z"] = pts.T
    rows["face_index"] = cloud.face_index
    header = "\n".join(
        [
            "ply",
            "format binary_little_endian 1.0",
            "comment zbuf_occlude occluded point cloud",
            f"comment elevation_deg {cloud.elevation_deg:.6f}",
            f"comment azimuth_deg {cloud.azimuth_deg:.6f}",
            f"comment radius {cloud.radius:.6f}",
            f"comment class {cloud.class_name or '-'} label {cloud.label} sample {cloud.sample_index} n_visible {cloud.n_visible}",
            f"comment split {cloud.split or '-'}",
            f"element vertex {len(pts)}",
            "property float x",
            "property float y",
            "property float z",
            "property int face_index",
            "end_header",
        ]
    )
    path = Path(path)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            # a PLY header is ASCII: a non-ASCII class name is escaped, not a crash
            fh.write(header.encode("ascii", "backslashreplace") + b"\n")
            fh.write(rows.tobytes())
    return path


def write_h5(
    path: str | os.PathLike,
    clouds: Sequence[OccludedCloud],
    *,
    shape_names: Sequence[str] = (),
    columns: Mapping[str, ArrayLike] | None = None,
    attrs: Mapping[str, Any] | None = None,
    provenance: bool = True,
    n_points: int | None = None,
) -> Path:
    """Write clouds of equal size ``n`` to one ``.h5`` file in PointNet's layout.

    The one HDF5 writer of zbuf_occlude: ``generate --format h5`` and the farm's dense
    shards both come from here (schema in :mod:`zbuf_occlude.dataset.layout`).

    Datasets, one row per cloud: ``data (B, n, 3) float32``, ``label (B,) int64``,
    ``elevation_deg (B,)``, ``azimuth_deg (B,)`` float64 (degrees), ``sample_index (B,)``,
    ``n_visible (B,)`` int64; with ``provenance`` also ``face_index (B, n) int32``,
    ``radius (B,) float64``, ``source (B,)``, ``class_name (B,)`` and ``split (B,)`` UTF-8 strings.

    Parameters
    ----------
    columns : mapping of name to (B,) array, optional
        More per-row datasets (the farm's ``object_index``, ``pose_index``), stored as int64.
    attrs : mapping, optional
        File attributes (besides ``shape_names``, written when given).
    provenance : bool
        Write the per-point and per-row provenance datasets above (the farm's dense shards
        leave them out: the manifest holds the source and class, and ``face_index`` would
        add a third to the size).
    n_points : int, optional
        ``n`` when ``clouds`` is empty.

    Raises
    ------
    OutputError
        Clouds of different sizes, or the file cannot be written (disk full included).
    """
    import h5py

    sizes = {len(c.points) for c in clouds}
    if len(sizes) > 1:
        raise OutputError(f"cannot write clouds of sizes {sorted(sizes)} into one HDF5 file: use one --points value")
    n = sizes.pop() if sizes else int(n_points or 0)
    text = h5py.string_dtype("utf-8")
    path = Path(path)
    with atomic_h5(path) as f:

        def put(key: str, data, dtype=None) -> None:
            # no modification times: the same inputs give the same bytes
            f.create_dataset(key, data=data, dtype=dtype, track_times=False)

        put("data", np.asarray([c.points for c in clouds], dtype=np.float32).reshape(len(clouds), n, 3))
        put("label", np.asarray([c.label for c in clouds], dtype=np.int64))
        put("elevation_deg", np.asarray([c.elevation_deg for c in clouds], dtype=np.float64))
        put("azimuth_deg", np.asarray([c.azimuth_deg for c in clouds], dtype=np.float64))
        for key, values in (columns or {}).items():
            put(key, np.asarray(values, dtype=np.int64).reshape(len(clouds)))
        put("sample_index", np.asarray([c.sample_index for c in clouds], dtype=np.int64))
        put("n_visible", np.asarray([c.n_visible for c in clouds], dtype=np.int64))
        if provenance:
            put("face_index", np.asarray([c.face_index for c in clouds], dtype=np.int32).reshape(len(clouds), n))
            put("radius", np.asarray([c.radius for c in clouds], dtype=np.float64))
            put("source", [c.source for c in clouds], text)
            put("class_name", [c.class_name for c in clouds], text)
            put("split", [c.split for c in clouds], text)
        if shape_names or provenance:
            f.attrs["shape_names"] = list(shape_names)
        f.attrs.update(dict(attrs or {}))
    return path


def concat_h5(
    path: str | os.PathLike,
    parts: Sequence[str | os.PathLike],
    *,
    fill: Mapping[str, str] | None = None,
    attrs: Mapping[str, Any] | None = None,
) -> Path:
    """Join files of :func:`write_h5`'s layout row-wise into one, streaming (one part's
    column in memory at a time, so a split of any size is joined in little memory).

    Every part has the first part's datasets, ``(B_i, ...)`` with equal trailing shapes; the
    result has each with ``sum(B_i)`` rows, in the order of ``parts``.

    Parameters
    ----------
    fill : mapping of name to str, optional
        UTF-8 per-row datasets to write with this value where a part lacks them (parts of
        older versions).
    attrs : mapping, optional
        File attributes.

    Raises
    ------
    OutputError
        Parts whose datasets differ, or the file cannot be written (disk full included).
    DatasetFormatError
        A part is not HDF5 or points elsewhere (:func:`zbuf_occlude.io.hdf5.check_hdf5`).
    """
    import h5py

    if not parts:
        raise OutputError(f"nothing to join into {path}")
    fill = dict(fill or {})
    with contextlib.ExitStack() as stack:
        sources = [stack.enter_context(open_hdf5(p)) for p in parts]
        keys = [k for k in sources[0].keys() if k not in fill] + list(fill)
        rows = [len(src["data"]) for src in sources]
        with atomic_h5(path) as f:
            for key in keys:
                first = sources[0].get(key)
                if first is None:  # a fill column
                    shape, dtype = (), h5py.string_dtype("utf-8")
                else:
                    shape, dtype = first.shape[1:], first.dtype
                out = f.create_dataset(key, shape=(sum(rows), *shape), dtype=dtype, track_times=False)
                start = 0
                for src, n, name in zip(sources, rows, parts):
                    if key in src and src[key].shape[1:] == shape:
                        out[start : start + n] = src[key][()]
                    elif key in fill:
                        out[start : start + n] = [fill[key]] * n
                    else:
                        raise OutputError(f"cannot join {name} into {path}: its {key!r} differs from {parts[0]}'s")
                    start += n
            f.attrs.update(dict(attrs or {}))
    return Path(path)


def read_h5(path: str | os.PathLike, columns: Mapping[str, Column] | None = None) -> dict[str, np.ndarray]:
    """Every dataset of a file written by :func:`write_h5`, as numpy arrays (strings decoded).

    The file is checked first (:func:`zbuf_occlude.io.hdf5.check_hdf5`): only data stored inside
    it, no links, numbers or strings, and ``columns`` (e.g. the data set schema
    :data:`zbuf_occlude.dataset.schema.SHARD_COLUMNS`) when given.

    Raises
    ------
    DatasetFormatError
        Not HDF5, or the file points elsewhere or holds other types (names file and dataset).
    """
    out: dict[str, np.ndarray] = {}
    with open_hdf5(path, columns) as f:
        for key, ds in f.items():
            out[key] = ds.asstr()[()] if ds.dtype.kind == "O" else ds[()]
        out["shape_names"] = np.asarray(list(f.attrs.get("shape_names", [])), dtype=str)
    return out


def read_h5_clouds(path: str | os.PathLike) -> list[OccludedCloud]:
    """The clouds of a file written by :func:`write_h5`, in order (its inverse)."""
    return clouds_of_h5(read_h5(path))


def clouds_of_h5(d: Mapping[str, np.ndarray]) -> list[OccludedCloud]:
    """The clouds of :func:`read_h5`'s arrays (with provenance columns), in order."""
    return [
        OccludedCloud(
            points=d["data"][i],
            face_index=d["face_index"][i].astype(np.int64),
            elevation_deg=float(d["elevation_deg"][i]),
            azimuth_deg=float(d["azimuth_deg"][i]),
            radius=float(d["radius"][i]),
            label=int(d["label"][i]),
            class_name=str(d["class_name"][i]),
            source=str(d["source"][i]),
            sample_index=int(d["sample_index"][i]),
            n_visible=int(d["n_visible"][i]),
            split=str(d["split"][i]) if "split" in d else "",  # files of older versions have none
        )
        for i in range(len(d["data"]))
    ]
