"""Writers and readers of occluded point clouds: ``.npz``, ``.ply``, PointNet-layout ``.h5``.

Every write is atomic: data go to a temporary file in the target folder, are flushed and
fsynced, then renamed over the target (``os.replace``), so a reader or a resumed run never
sees a partial file.  A failed write (unwritable folder, disk full) raises
:class:`~zbuf_occlude.errors.OutputError` and leaves no temporary file behind.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import os
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .errors import OutputError

__all__ = [
    "OccludedCloud",
    "atomic_path",
    "write_text",
    "write_csv",
    "write_npz",
    "read_npz",
    "write_ply",
    "write_h5",
    "read_h5",
    "read_h5_clouds",
    "FORMATS",
]

#: File formats :func:`write_clouds` knows.
FORMATS = ("npz", "ply", "h5")


@dataclass
class OccludedCloud:
    """One occluded sample: a fixed-size point set seen from one pose.

    Attributes
    ----------
    points : (n, 3) float32
        World (object) frame, normalised mesh units.
    face_index : (n,) int64
        Face of the source mesh each point lies on.
    elevation_deg, azimuth_deg, radius : float
        The camera pose (degrees, degrees, object units).
    label : int
        Class index (−1 if unknown).
    class_name, source : str
        Class name and source mesh path.
    sample_index : int
        Which of the pose's random draws this is.
    n_visible : int
        Visible points in the dense cloud for this pose.  If ``n_visible < n``, the
        sample holds every visible point once plus repeats drawn at random (``padded``).
    """

    points: NDArray[np.float32]
    face_index: NDArray[np.int64]
    elevation_deg: float
    azimuth_deg: float
    radius: float
    label: int = -1
    class_name: str = ""
    source: str = ""
    sample_index: int = 0
    n_visible: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def padded(self) -> bool:
        """True if fewer points were visible than the sample holds (repeats added)."""
        return self.n_visible < len(self.points)


@functools.lru_cache(maxsize=1)
def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _raise_output_error(path: Path, exc: OSError) -> None:
    if exc.errno == errno.ENOSPC:
        raise OutputError(f"disk full while writing {path}; free space and run again (finished files are kept)") from exc
    if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        raise OutputError(f"cannot write {path}: permission denied; choose a writable --out folder") from exc
    raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success fsync and rename it to ``path``.

    Raises
    ------
    OutputError
        The folder cannot be created or written, or the disk is full.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.close(fd)
        # mkstemp makes 0600 files; outputs are meant to be shared, so give them the mode a
        # plain open() would (0666 less the umask)
        os.chmod(tmp, 0o666 & ~_umask())
    except OSError as exc:
        _raise_output_error(path, exc)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp_path, path)
    except OSError as exc:
        tmp_path.unlink(missing_ok=True)
        _raise_output_error(path, exc)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (:func:`atomic_path`)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def write_csv(path: str | os.PathLike, rows: Sequence[dict], fieldnames: Sequence[str] | None = None) -> Path:
    """Write dict rows as CSV atomically; columns ``fieldnames`` (default: the first row's keys),
    keys outside them are left out."""
    import csv

    path = Path(path)
    fields = list(fieldnames) if fieldnames is not None else list(rows[0]) if rows else []
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    return path


def write_npz(path: str | os.PathLike, cloud: OccludedCloud) -> Path:
    """Write one cloud as ``.npz``: ``points (n, 3) float32``, ``face_index (n,) int64``,
    ``elevation_deg``, ``azimuth_deg``, ``radius``, ``label``, ``class_name``, ``source``,
    ``sample_index``, ``n_visible`` (scalars as 0-d arrays)."""
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
            )
    return path


def read_npz(path: str | os.PathLike) -> OccludedCloud:
    """Read a cloud written by :func:`write_npz`."""
    with np.load(path) as z:
        return OccludedCloud(
            points=z["points"],
            face_index=z["face_index"],
            elevation_deg=float(z["elevation_deg"]),
            azimuth_deg=float(z["azimuth_deg"]),
            radius=float(z["radius"]),
            label=int(z["label"]),
            class_name=str(z["class_name"]),
            source=str(z["source"]),
            sample_index=int(z["sample_index"]),
            n_visible=int(z["n_visible"]),
        )


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


def write_h5(path: str | os.PathLike, clouds: Sequence[OccludedCloud], *, shape_names: Sequence[str] = ()) -> Path:
    """Write clouds of equal size ``n`` to one ``.h5`` file in PointNet's layout.

    Datasets: ``data (B, n, 3) float32``, ``label (B,) int64``, ``face_index (B, n) int32``,
    ``elevation_deg (B,)``, ``azimuth_deg (B,)``, ``radius (B,)`` float64,
    ``sample_index (B,)``, ``n_visible (B,)`` int64, ``source (B,)`` and ``class_name (B,)``
    UTF-8 strings; attribute ``shape_names`` (index → class name).

    Raises
    ------
    OutputError
        Clouds of different sizes, or the file cannot be written.
    """
    import h5py

    sizes = {len(c.points) for c in clouds}
    if len(sizes) > 1:
        raise OutputError(f"cannot write clouds of sizes {sorted(sizes)} into one HDF5 file: use one --points value")
    n = sizes.pop() if sizes else 0
    text = h5py.string_dtype("utf-8")
    path = Path(path)
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.create_dataset("data", data=np.asarray([c.points for c in clouds], dtype=np.float32).reshape(len(clouds), n, 3))
            f.create_dataset("label", data=np.asarray([c.label for c in clouds], dtype=np.int64))
            f.create_dataset("face_index", data=np.asarray([c.face_index for c in clouds], dtype=np.int32).reshape(len(clouds), n))
            for key in ("elevation_deg", "azimuth_deg", "radius"):
                f.create_dataset(key, data=np.asarray([getattr(c, key) for c in clouds], dtype=np.float64))
            for key in ("sample_index", "n_visible"):
                f.create_dataset(key, data=np.asarray([getattr(c, key) for c in clouds], dtype=np.int64))
            f.create_dataset("source", data=[c.source for c in clouds], dtype=text)
            f.create_dataset("class_name", data=[c.class_name for c in clouds], dtype=text)
            f.attrs["shape_names"] = list(shape_names)
    return path


def read_h5(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Every dataset of a file written by :func:`write_h5`, as numpy arrays (strings decoded)."""
    import h5py

    out: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as f:
        for key, ds in f.items():
            out[key] = ds.asstr()[()] if ds.dtype.kind == "O" else ds[()]
        out["shape_names"] = np.asarray(list(f.attrs.get("shape_names", [])), dtype=str)
    return out


def read_h5_clouds(path: str | os.PathLike) -> list[OccludedCloud]:
    """The clouds of a file written by :func:`write_h5`, in order (its inverse)."""
    d = read_h5(path)
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
        )
        for i in range(len(d["data"]))
    ]
