"""Storage kinds: one small class per way a data set keeps its samples, shared by the writer and the reader.

A data set's card names its ``storage``; :func:`storage_kind` finds the kind in :data:`STORAGE_KINDS`:

``dense`` (the farm) and ``h5`` (``generate``): :class:`DenseRows`
    One row of ``data (B, n, 3) float32`` per sample (``h5`` adds the provenance columns).
``compact`` (the farm): :class:`Compact`
    The dense cloud once and a visibility bitmask per pose; the reader redraws the samples.
``npz``, ``ply`` (``generate``): :class:`SampleFiles`
    One file per sample.
``farm --sensor``: :class:`SensorCrops`
    ``dense`` on the card, a dense shard whose rows are scans, each with its own placement, and
    per point the LiDAR's return fields when its sensor records several returns per pulse
    (:data:`~zbuf_occlude.dataset.layout.POINT_COLUMNS`, read by :meth:`DenseRows.read_columns`).

A kind says what the farm's worker (:mod:`zbuf_occlude.farm.worker`) needs to write an object
(the options of :func:`~zbuf_occlude.pipeline.occlude_poses`, how its poses are packed into files),
and what :class:`~zbuf_occlude.dataset.reader.OccludedDataset`, :mod:`~zbuf_occlude.dataset.schema`
and ``verify`` need to read it back (the datasets a shard must hold, the samples each pose of a
record gives, how to read samples and their placement, how to check a file).  It also answers for
the farm's plans: the command that writes it, the memory a worker holds and the disk an object
takes (:class:`ObjectSize`), and the names its files take in the output folder.  Names and columns
are in :mod:`zbuf_occlude.dataset.layout`.  A new kind is one class and one entry of
:data:`STORAGE_KINDS`; no other module switches on a kind's name.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.dataset.index import PoseFilters, samples_per_pose
from zbuf_occlude.dataset.layout import POINT_COLUMNS, sample_file_name
from zbuf_occlude.errors import DatasetFormatError, InvalidInputError
from zbuf_occlude.geometry.samples import pool_take, pose_samples

if TYPE_CHECKING:
    from zbuf_occlude.pipeline import PoseResult

__all__ = [
    "StorageKind",
    "DenseRows",
    "Compact",
    "SampleFiles",
    "SensorCrops",
    "STORAGE_KINDS",
    "storage_kind",
    "storages",
    "ShardTarget",
    "ShardSource",
    "ObjectSize",
    "FileCheck",
    "SENSOR_ROW_FIELDS",
    "BYTES_PER_POINT",
    "write_datasets",
    "write_compact",
    "reconstruct_samples",
    "unpack_visible",
    "check_visible_bits",
    "check_point_column",
    "read_point_columns",
]

#: Per-row datasets of a ``farm --sensor`` shard that :meth:`SensorCrops.placement` returns.
SENSOR_ROW_FIELDS = (
    "elevation_deg", "azimuth_deg", "radius", "distance_m", "sensor_height_m", "object_azimuth_deg", "yaw_deg", "size_m",
    "hidden_below_m", "width_scale",
)  # fmt: skip
#: Bytes of one stored point, ``(3,) float32``.
BYTES_PER_POINT = 12


# -- what the writer and the reader hand a kind -------------------------------------------------
@dataclass(frozen=True)
class ShardTarget:
    """Where and what the farm's worker writes for one object of a z-buffer run.

    Attributes
    ----------
    out : Path
        The data set folder.
    name, source : str
        The object's name (sample files go to folders named after it) and mesh file (for messages).
    shard : str
        Its shard, relative to ``out`` (:func:`~zbuf_occlude.dataset.layout.shard_name`).
    object_index, n_points : int
    poses : sequence of (elevation_deg, azimuth_deg)
        Every pose of the run, degrees.
    attrs : mapping
        The shard's HDF5 attributes.
    dense_points : (M, 3) float
        The object's dense cloud (compact storage keeps it).
    gzip_level : int
        gzip level of compressed datasets (compact storage's ``visible_bits``).
    """

    out: Path
    name: str
    source: str
    shard: str
    object_index: int
    n_points: int
    poses: Sequence[tuple[float, float]]
    attrs: Mapping[str, Any]
    dense_points: NDArray[np.floating]
    gzip_level: int


class ShardSource(Protocol):
    """What a kind reads an object's samples through (the reader's files, opened and checked once per process)."""

    n_points: int
    #: The card's global seed and poses ``(P, 2) float64`` (elevation, azimuth; degrees), and its sensor.
    seed: int
    poses: NDArray[np.float64]
    sensor: str | None

    def record(self, obj: int) -> dict[str, Any]:
        """Object ``obj``'s manifest record."""

    def shard(self, obj: int) -> Any:
        """Object ``obj``'s shard, an open ``h5py.File`` (checked by :func:`~zbuf_occlude.dataset.schema.open_shard`)."""

    def sample_file(self, obj: int, row: int) -> NDArray[np.float32]:
        """The points of object ``obj``'s sample file ``row``, checked."""

    def arrays(self, obj: int) -> Any:
        """Object ``obj``'s :meth:`Compact.load_arrays`, cached."""


@dataclass(frozen=True)
class ObjectSize:
    """The sizes of one object of a run, which a kind turns into its memory and disk estimates.

    Attributes
    ----------
    n_poses : int
        Poses per object (0 for ``farm --sensor``, whose scans carry their own).
    samples_per_view, n_points : int
        Samples drawn per pose, points per sample.
    dense_points : int
        Dense cloud per object (0: unknown, as with ``--density``).
    """

    n_poses: int
    samples_per_view: int
    n_points: int
    dense_points: int = 0


class FileCheck(Protocol):
    """What a kind checks one of an object's files against (``verify``: the manifest's record and
    the reader's checks)."""

    #: Points per sample (the card's), samples the record's ``n_visible`` implies, files the record names.
    n_points: int
    rows: int
    n_files: int
    #: The record's ``n_visible`` and ``n_topped_up`` (``None``: none recorded).
    n_visible: Sequence[int]
    n_topped_up: Sequence[int] | None
    #: The per-point columns the record declares (``point_columns``; empty: none).
    point_columns: Sequence[str]

    def open_shard(self, path: Path) -> Any:
        """The shard ``path`` opened by :func:`~zbuf_occlude.dataset.schema.open_shard` against the record
        (an ``h5py.File``, used as a context manager)."""


def write_datasets(path: Path, datasets: Mapping[str, NDArray], attrs: Mapping[str, Any], *, gzip: Mapping[str, int] | None = None) -> None:
    """One HDF5 shard of named arrays, atomically (insertion order, no modification times: same inputs, same bytes).

    Parameters
    ----------
    gzip : mapping of dataset name to level, optional
        Datasets stored gzip-compressed at that level in one chunk (an empty one is stored plain).

    Raises
    ------
    OutputError
        The file cannot be written (a full disk says so).
    """
    from zbuf_occlude.io.atomic import atomic_h5

    gzip = gzip or {}
    with atomic_h5(path) as f:
        for key, data in datasets.items():
            level = gzip.get(key) if np.asarray(data).size else None
            packed = {} if level is None else {"chunks": np.shape(data), "compression": "gzip", "compression_opts": level}
            f.create_dataset(key, data=data, track_times=False, **packed)
        f.attrs.update(attrs)


# -- the kinds ------------------------------------------------------------------------------------
class StorageKind:
    """One way of keeping samples on disk; a subclass overrides what differs.

    Attributes
    ----------
    name : str
        Its key in :data:`STORAGE_KINDS`.
    storage : str
        What the card's ``storage`` says.
    shard_datasets : tuple of str
        Datasets each of its HDF5 shards must hold; empty: its files are not HDF5 shards.
    redraws : bool
        Samples are redrawn from stored visibility masks, not stored as rows.
    rows_placed : bool
        Each row holds its own sensor direction and placement (``farm --sensor``): pose filters
        and metadata read the shard, not the card's poses.
    made_from : {"poses", "scans"}
        What the farm feeds it: the z-buffer poses of :func:`~zbuf_occlude.pipeline.occlude_poses`
        (:meth:`write_poses`) or ``farm --sensor``'s scans (:meth:`SensorCrops.write_rows`).
    written_by : {"farm", "generate"}
        The command that writes it (:func:`storages`).
    joins_splits : bool
        At the end of a run its shards are joined into one file per split (``generate``'s ``h5``:
        PointNet's ``occluded_<split>.h5`` and file lists).
    keeps_point_columns : bool
        Its shards may keep per-point columns beside the points
        (:data:`~zbuf_occlude.dataset.layout.POINT_COLUMNS`, read by :meth:`read_columns`).
    stored_bytes_per_point : int
        Bytes each point of each sample takes in its shard at least (its rows are stored
        uncompressed); 0: its samples are not stored as rows (redrawn, or files of their own).
        A record promising more rows than its shard can hold is refused before anything of that
        size is allocated (:func:`~zbuf_occlude.dataset.schema.check_declared_rows`).
    """

    name: str = ""
    storage: str = ""
    shard_datasets: tuple[str, ...] = ()
    redraws = False
    rows_placed = False
    made_from = "poses"
    written_by = "farm"
    joins_splits = False
    keeps_point_columns = False
    stored_bytes_per_point = 0

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"

    @property
    def hdf5(self) -> bool:
        """Its files are HDF5 shards (checked by :func:`~zbuf_occlude.dataset.schema.open_shard`)."""
        return bool(self.shard_datasets)

    def rows_per_pose(self, n_visible: NDArray[np.integer], samples_per_view: int) -> NDArray[np.int64]:
        """``(P,) int64``: samples each pose of a record stores (``n_visible``: the record's, per pose)."""
        return samples_per_pose(n_visible, samples_per_view)

    # -- the farm's estimates and names (each kind states its own: a wrong guess would go unnoticed)
    def memory_held(self, size: ObjectSize) -> tuple[int, int]:
        """What a worker holds of one object's samples until they are written, as
        :func:`~zbuf_occlude.resources.estimate_job_memory` counts it: ``(points, samples_held)``,
        the points of a sample and how many samples are held at once.

        Raises
        ------
        NotImplementedError
            The kind states no estimate (every kind of :data:`STORAGE_KINDS` must).
        """
        raise NotImplementedError(f"{self!r} states no memory estimate")

    def disk_bytes(self, size: ObjectSize) -> int:
        """Bytes one object's files take, about (the farm warns when the disk holds less).

        Raises
        ------
        NotImplementedError
            The kind states no estimate (every kind of :data:`STORAGE_KINDS` must).
        """
        raise NotImplementedError(f"{self!r} states no disk estimate")

    def top_names(self, object_names: Iterable[str]) -> list[str]:
        """Names directly under the output folder that its files take besides ``shards/``, sorted
        (none: every file of an HDF5 kind is a shard)."""
        return []

    def own_files(self, name: str, shard: str) -> list[str]:
        """Regular expressions of the files a record of object ``name`` (shard ``shard``) may name,
        relative to the output folder: its shard."""
        return [re.escape(shard)]

    # -- writing
    def check_name(self, name: str, *, what: str) -> None:
        """Refuse an object name this kind cannot write under (before any work is done).

        Raises
        ------
        UnsafePathError
            Sample files: the name would leave the data set folder (``what`` names it).
        """

    def occlude_options(self, samples_per_view: int) -> dict[str, Any]:
        """``samples_per_view`` and ``topped_up`` of the :class:`~zbuf_occlude.pipeline.PoseDraws` whose poses
        :meth:`write_poses` packs (:func:`~zbuf_occlude.pipeline.occlude_poses`)."""
        return {"samples_per_view": int(samples_per_view)}

    def write_poses(self, target: ShardTarget, poses: Iterable[PoseResult]) -> list[str]:
        """Write one object's poses; the files written, relative to ``target.out``.

        Raises
        ------
        OutputError
            A file cannot be written.
        """
        raise NotImplementedError(f"{self!r} is not written from z-buffer poses")

    # -- reading
    def read(self, src: ShardSource, obj: int, pose: NDArray[np.int64], sample: NDArray[np.int64], row: NDArray[np.int64]) -> NDArray:
        """``(k, n, 3)`` points of ``k`` samples of object ``obj`` (their pose, sample index and row; rows ascending)."""
        raise NotImplementedError

    def read_columns(self, src: ShardSource, obj: int, names: Sequence[str], row: NDArray[np.int64]) -> NDArray[np.float32]:
        """``(k, n, F) float32``: the per-point columns ``names`` (at least one) of rows ``row`` (ascending) of object ``obj``.

        Raises
        ------
        NotImplementedError
            The kind keeps no per-point columns (:attr:`keeps_point_columns`).
        """
        raise NotImplementedError(f"{self!r} keeps no per-point columns")

    def row_keep(self, src: ShardSource, obj: int, rows_per_pose: NDArray[np.int64], pose_keep: NDArray[np.bool_],
                 filters: PoseFilters) -> NDArray[np.bool_]:  # fmt: skip
        """``(B,) bool``: which rows of object ``obj`` the pose filters keep (``pose_keep``: the card's poses they keep)."""
        return np.repeat(pose_keep, rows_per_pose)

    def row_directions(self, src: ShardSource, obj: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(B,)`` elevation and azimuth of each row's sensor seen from the object, degrees (kinds whose ``rows_placed``)."""
        raise NotImplementedError(f"{self!r} takes its poses from the card")

    def placement(self, src: ShardSource, obj: int, pose: int, row: int) -> dict[str, Any]:
        """The sensor direction of a sample, degrees (the card's pose)."""
        return {"elevation_deg": float(src.poses[pose, 0]), "azimuth_deg": float(src.poses[pose, 1])}

    # -- checking (verify)
    def check_file(self, path: Path, expect: FileCheck) -> None:
        """Refuse what the reader would refuse in ``path``, one of an object's files.

        An HDF5 kind's record names its one shard: opened as the reader opens it
        (``expect.open_shard``), then :meth:`check_opened`; a record naming other files is
        checked by their sizes and hashes alone.

        Raises
        ------
        ZbufOccludeError
            What the reader would raise (a :class:`~zbuf_occlude.errors.DatasetFormatError` mostly).
        """
        if expect.n_files != 1:
            return
        with expect.open_shard(path) as f:
            self.check_opened(f, path, expect)

    def check_opened(self, f: Any, path: Path, expect: FileCheck) -> None:
        """What the reader checks in an open shard ``f`` beyond :func:`~zbuf_occlude.dataset.schema.open_shard`
        when it reads it (nothing: its rows are read as they are)."""


class DenseRows(StorageKind):
    """PointNet's rows, ``data (B, n, 3) float32`` and one row per sample of the other columns
    (the farm's ``dense``; ``generate``'s ``h5`` adds the provenance columns)."""

    shard_datasets = ("data",)
    keeps_point_columns = True
    stored_bytes_per_point = BYTES_PER_POINT  # 'data', float32 xyz, never compressed

    def __init__(self, name: str, *, provenance: bool, written_by: str = "farm", joins_splits: bool = False):
        self.name = self.storage = name
        self.provenance = provenance
        self.written_by, self.joins_splits = written_by, joins_splits

    def memory_held(self, size: ObjectSize) -> tuple[int, int]:
        return size.n_points, size.n_poses * size.samples_per_view  # one file per object: all its samples

    def disk_bytes(self, size: ObjectSize) -> int:
        return size.n_poses * size.samples_per_view * size.n_points * BYTES_PER_POINT

    def write_poses(self, target: ShardTarget, poses: Iterable[PoseResult]) -> list[str]:
        from zbuf_occlude.io.clouds import write_h5

        clouds, pose_of = [], []
        for pose in poses:
            clouds.extend(pose.clouds)
            pose_of.extend([pose.pose_index] * len(pose.clouds))
        columns = {"object_index": np.full(len(clouds), target.object_index, dtype=np.int64), "pose_index": np.asarray(pose_of, np.int64)}
        write_h5(
            target.out / target.shard, clouds, n_points=target.n_points, provenance=self.provenance, columns=columns, attrs=target.attrs
        )
        return [target.shard]

    def read(self, src: ShardSource, obj: int, pose: NDArray[np.int64], sample: NDArray[np.int64], row: NDArray[np.int64]) -> NDArray:
        return _rows(src.shard(obj)["data"], row)

    def read_columns(self, src: ShardSource, obj: int, names: Sequence[str], row: NDArray[np.int64]) -> NDArray[np.float32]:
        """The columns as :class:`StorageKind`'s, each cast to float32 after :func:`check_point_column`
        checked its values (exact for the integers up to 2**24 and the float32 columns; ``gps_time``
        and a larger ``pulse_id`` round to float32's 24-bit significand).

        Raises
        ------
        DatasetFormatError
            A value out of its column's range (named with the file and the row).
        """
        f = src.shard(obj)
        declared = src.record(obj).get("point_columns") or ()
        columns = read_point_columns(f, Path(f.filename), names, declared, row)
        return np.stack([columns[name].astype(np.float32) for name in names], axis=-1)

    def check_opened(self, f: Any, path: Path, expect: FileCheck) -> None:
        """The values of the per-point columns the record declares (:func:`read_point_columns`), as
        :meth:`read_columns` checks them; their shapes and dtypes were checked on opening."""
        read_point_columns(f, path, expect.point_columns, expect.point_columns)


class SensorCrops(DenseRows):
    """``farm --sensor``: a dense shard whose rows are scans (``pose_index`` the scan), each with its
    own sensor direction (``elevation_deg``, ``azimuth_deg``) and placement (:data:`SENSOR_ROW_FIELDS`, ``ring``)."""

    shard_datasets = ("data", "elevation_deg", "azimuth_deg")
    rows_placed = True
    made_from = "scans"

    def __init__(self) -> None:
        super().__init__("dense", provenance=False)
        self.name = "sensor_crops"

    write_poses = StorageKind.write_poses  # its rows come from scans (write_rows)

    def rows_per_pose(self, n_visible: NDArray[np.integer], samples_per_view: int) -> NDArray[np.int64]:
        return samples_per_pose(n_visible, 1)  # a scan is a pose of one sample

    def write_rows(self, path: Path, datasets: Mapping[str, NDArray], attrs: Mapping[str, Any]) -> dict[str, Any]:
        """Write one object's scans, the datasets of :func:`zbuf_occlude.farm.sensor_crops.farm_datasets`, as they are.

        Returns
        -------
        dict
            The fields of the object's record that say what the shard holds: ``point_columns``,
            the :data:`~zbuf_occlude.dataset.layout.POINT_COLUMNS` among ``datasets`` (in that
            order), when there are some (nothing else: a record without them is as before).
        """
        write_datasets(path, datasets, attrs)
        columns = [name for name in POINT_COLUMNS if name in datasets]
        return {"point_columns": columns} if columns else {}

    def row_directions(self, src: ShardSource, obj: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        f = src.shard(obj)
        return f["elevation_deg"][()], f["azimuth_deg"][()]

    def row_keep(self, src: ShardSource, obj: int, rows_per_pose: NDArray[np.int64], pose_keep: NDArray[np.bool_],
                 filters: PoseFilters) -> NDArray[np.bool_]:  # fmt: skip
        if not filters.active:
            return np.ones(int(np.sum(rows_per_pose)), dtype=bool)
        return filters.mask(*self.row_directions(src, obj))

    def placement(self, src: ShardSource, obj: int, pose: int, row: int) -> dict[str, Any]:
        """The scan's sensor direction and placement (``radius`` in mesh units, the rest in metres and degrees)."""
        f = src.shard(obj)
        return {key: float(f[key][row]) for key in SENSOR_ROW_FIELDS if key in f} | {"sensor": src.sensor}


class Compact(StorageKind):
    """The object's dense cloud once and a visibility bitmask and top-up points per pose; the reader
    redraws the samples bit-identically (:func:`reconstruct_samples`)."""

    name = storage = "compact"
    shard_datasets = ("dense_points", "visible_bits")
    redraws = True

    def occlude_options(self, samples_per_view: int) -> dict[str, Any]:
        # the masks and the top-up points are all it keeps: the reader draws the samples
        return {"samples_per_view": 0, "topped_up": True}

    def memory_held(self, size: ObjectSize) -> tuple[int, int]:
        return 0, size.samples_per_view  # it draws no sample: the masks are counted with the dense cloud

    def disk_bytes(self, size: ObjectSize) -> int:
        # the dense cloud once and one bit per dense point and pose (top-up points are few)
        return size.dense_points * BYTES_PER_POINT + size.n_poses * (size.dense_points + 7) // 8

    def check_opened(self, f: Any, path: Path, expect: FileCheck) -> None:
        """The masks against the record's ``n_visible`` and ``n_topped_up`` (:func:`check_visible_bits`),
        as :meth:`load_arrays` checks them."""
        check_visible_bits(path, f["visible_bits"][()], len(f["dense_points"]), expect.n_visible, expect.n_topped_up)

    def write_poses(self, target: ShardTarget, poses: Iterable[PoseResult]) -> list[str]:
        n_poses, n_dense = len(target.poses), len(target.dense_points)
        bits = np.zeros((n_poses, (n_dense + 7) // 8), dtype=np.uint8)
        n_visible, n_topped_up = np.zeros(n_poses, dtype=np.int64), np.zeros(n_poses, dtype=np.int64)
        topped_up: list[NDArray] = []
        for pose in poses:
            n_visible[pose.pose_index], n_topped_up[pose.pose_index] = pose.n_visible, len(pose.topped_up)
            bits[pose.pose_index] = np.packbits(pose.visible)
            topped_up.append(pose.topped_up.points)
        topup_points = np.concatenate(topped_up) if topped_up else np.zeros((0, 3))
        write_compact(target.out / target.shard, target.dense_points, bits, n_visible, n_topped_up, topup_points, target.poses,
                      target.attrs, gzip_level=target.gzip_level)  # fmt: skip
        return [target.shard]

    def load_arrays(
        self, f: Any, path: Path, rec: Mapping[str, Any]
    ) -> tuple[NDArray[np.float32], NDArray[np.uint8], list[NDArray[np.float32]]]:
        """An object's dense cloud, visibility bits and top-up points of each pose, checked against its record.

        Raises
        ------
        DatasetFormatError
            The masks do not fit the record (:func:`check_visible_bits`).
        """
        n_topped_up = rec.get("n_topped_up")
        dense_points, bits = f["dense_points"][()], f["visible_bits"][()]
        check_visible_bits(path, bits, len(dense_points), rec["n_visible"], n_topped_up)
        # rows of topup_points, pose after pose (open_shard checked their total against n_topped_up)
        topup = f["topup_points"][()] if n_topped_up else np.zeros((0, 3), dtype=np.float32)
        bounds = np.cumsum([0, *(n_topped_up or [0] * len(bits))])
        return dense_points, bits, [topup[a:b] for a, b in itertools.pairwise(bounds)]

    def read(self, src: ShardSource, obj: int, pose: NDArray[np.int64], sample: NDArray[np.int64], row: NDArray[np.int64]) -> NDArray:
        dense_points, bits, topup = src.arrays(obj)
        key = int(src.record(obj)["key"])
        out = np.empty((len(pose), src.n_points, 3), dtype=np.float32)
        for p in np.unique(pose):
            sel = np.flatnonzero(pose == p)
            out[sel] = reconstruct_samples(
                dense_points, unpack_visible(bits[p], len(dense_points)), seed=src.seed, key=key, pose_index=int(p),
                n_points=src.n_points, sample_indices=sample[sel].tolist(), topup_points=topup[int(p)],
            )  # fmt: skip
        return out


class SampleFiles(StorageKind):
    """``generate --format npz|ply``: one file per sample under ``DATASET/<name>/``
    (:func:`~zbuf_occlude.dataset.layout.sample_file_name`), listed in the record's ``shards``."""

    written_by = "generate"

    def __init__(self, name: str):
        self.name = self.storage = name

    def memory_held(self, size: ObjectSize) -> tuple[int, int]:
        return size.n_points, size.samples_per_view  # written pose by pose: one pose's samples

    def disk_bytes(self, size: ObjectSize) -> int:
        return size.n_poses * size.samples_per_view * size.n_points * BYTES_PER_POINT

    def top_names(self, object_names: Iterable[str]) -> list[str]:
        """The first folder of each object's name (a name that is no folder name, ``..``, is
        refused where names are checked)."""
        return sorted({name.split("/")[0] for name in object_names} - {"", ".", ".."})

    def own_files(self, name: str, shard: str) -> list[str]:
        """Its sample files of the object (:func:`~zbuf_occlude.dataset.layout.sample_file_name`)."""
        stem = name.rsplit("/", 1)[-1]
        return [rf"{re.escape(name)}/{re.escape(stem)}_v\d{{3}}_el[+-]\d{{3}}_az\d{{3}}_s\d{{2}}\.{re.escape(self.name)}"]

    def check_file(self, path: Path, expect: FileCheck) -> None:
        """Read the file's points as the reader does (:func:`~zbuf_occlude.dataset.sample_files.read_sample_points`)."""
        from zbuf_occlude.dataset.sample_files import read_sample_points

        read_sample_points(path, self.name, expect.n_points)

    def check_name(self, name: str, *, what: str) -> None:
        from zbuf_occlude.io.safe_paths import check_relative_name

        # the name becomes folders under out: `...off` (name "..") must not leave it
        check_relative_name(name, what=what)

    def write_poses(self, target: ShardTarget, poses: Iterable[PoseResult]) -> list[str]:
        from zbuf_occlude.io.clouds import write_npz, write_ply
        from zbuf_occlude.io.safe_paths import path_inside

        write = write_npz if self.name == "npz" else write_ply
        written: list[str] = []
        for pose in poses:
            for c in pose.clouds:
                rel = sample_file_name(target.name, pose.pose_index, c.elevation_deg, c.azimuth_deg, c.sample_index, self.name)
                write(path_inside(target.out, rel, what=target.source), c)
                written.append(rel)
        return written

    def read(self, src: ShardSource, obj: int, pose: NDArray[np.int64], sample: NDArray[np.int64], row: NDArray[np.int64]) -> NDArray:
        return np.stack([src.sample_file(obj, int(r)) for r in row])


#: Every kind by name; :func:`storage_kind` is the lookup from a card.
STORAGE_KINDS: dict[str, StorageKind] = {
    kind.name: kind
    for kind in (
        DenseRows("dense", provenance=False), Compact(), SensorCrops(),
        DenseRows("h5", provenance=True, written_by="generate", joins_splits=True), SampleFiles("npz"), SampleFiles("ply"),
    )
}  # fmt: skip


def storage_kind(storage: str, *, sensor: bool = False) -> StorageKind:
    """The kind of a data set whose card says ``storage`` (and, with ``sensor``, was made by ``farm --sensor``).

    Raises
    ------
    InvalidInputError
        No kind stores that (``farm --sensor`` data sets are dense).
    """
    kind = STORAGE_KINDS["sensor_crops"] if sensor else STORAGE_KINDS.get(storage)
    if kind is None or kind.storage != storage:
        readable = tuple(dict.fromkeys(k.storage for k in STORAGE_KINDS.values() if k.rows_placed == sensor))
        raise InvalidInputError(f"unknown storage {storage!r}{' for farm --sensor' if sensor else ''}; this zbuf_occlude reads {readable}")
    return kind


def storages(written_by: str | None = None) -> tuple[str, ...]:
    """The storages a card may name, in the order of :data:`STORAGE_KINDS`: all of them, or those
    the command ``written_by`` (``"farm"``, ``"generate"``) writes."""
    return tuple(dict.fromkeys(k.storage for k in STORAGE_KINDS.values() if written_by in (None, k.written_by)))


def _rows(dataset: Any, row: NDArray[np.int64]) -> NDArray:
    """Rows ``row`` (ascending) of an HDF5 dataset: one row read for one sample, else the dataset at
    once (HDF5 point selections are slow)."""
    return dataset[int(row[0])][None] if len(row) == 1 else dataset[()][row]


def read_point_columns(
    f: Any, path: Path, names: Sequence[str], declared: Sequence[str], row: NDArray[np.int64] | None = None
) -> dict[str, NDArray]:
    """The per-point columns ``names`` of an open shard, each checked by :func:`check_point_column`:
    the one rule the reader (:meth:`DenseRows.read_columns`) and ``verify`` (:meth:`DenseRows.check_opened`) apply.

    ``return_number`` is checked against the same rows of ``number_of_returns`` whenever the record
    declares that column, whether or not it was asked for: a return number above its point's
    number of returns is refused however the columns are chosen.

    Parameters
    ----------
    f : h5py.File
        The shard, opened by :func:`~zbuf_occlude.dataset.schema.open_shard` (the declared columns'
        shapes and dtypes checked).
    path : Path
        The shard, for messages.
    names : sequence of str
        Columns to read, among ``declared``.
    declared : sequence of str
        The columns the record declares (its ``point_columns``).
    row : (k,) int64, optional
        Rows to read, ascending (default: all).

    Returns
    -------
    dict of str to (k, n) array
        Each of ``names``, in its stored dtype.

    Raises
    ------
    DatasetFormatError
        A value out of its column's range, or a return number above its number of returns (named
        with the file, the column and the shard's row).
    """
    take = (lambda dataset: dataset[()]) if row is None else (lambda dataset: _rows(dataset, row))
    columns = {name: take(f[name]) for name in names}
    bound = None
    if "return_number" in columns and "number_of_returns" in declared:
        bound = columns["number_of_returns"] if "number_of_returns" in columns else take(f["number_of_returns"])
    for name, values in columns.items():
        check_point_column(path, name, values, bound if name == "return_number" else None, rows=row)
    return columns


def check_point_column(
    path: Path, name: str, values: NDArray, number_of_returns: NDArray | None = None, *, rows: NDArray[np.int64] | None = None
) -> None:
    """Check the values of a per-point column against :data:`~zbuf_occlude.dataset.layout.POINT_COLUMNS`.

    Parameters
    ----------
    path : Path
        The shard, for messages.
    name : str
        A key of ``POINT_COLUMNS``.
    values : (B, n) array
        Its rows.
    number_of_returns : (B, n) array, optional
        With ``return_number``: the same rows of ``number_of_returns``, which bound it.
    rows : (B,) int64, optional
        The shard's row of each of ``values``' rows, for messages (default: ``0 .. B - 1``).

    Raises
    ------
    DatasetFormatError
        A value that is not finite, or out of the column's ``[low, high]``, or a return number
        above its point's number of returns (the message names the file, the column and the row).
    """
    spec = POINT_COLUMNS[name]
    values = np.asarray(values)
    bad = ~np.isfinite(values) if values.dtype.kind == "f" else np.zeros(values.shape, dtype=bool)
    with np.errstate(invalid="ignore"):
        bad |= (values < spec.low) | (values > spec.high)
    said = f"in [{spec.low:g}, {spec.high:g}] ({spec.unit})"
    if number_of_returns is not None and not bad.any():
        bad = values > np.asarray(number_of_returns)
        said = "at most the point's 'number_of_returns'"
    if bad.any():
        at = np.argwhere(bad)[0]
        shard_row = int(at[0]) if rows is None else int(rows[int(at[0])])
        raise DatasetFormatError(
            f"the shard {path}: dataset {name!r} holds a value {'that is not finite' if values.dtype.kind == 'f' and not np.isfinite(values[tuple(at)]) else 'out of range'} at row {shard_row}, point {int(at[-1])} "
            f"({int(bad.sum())} values wrong); it must be {said}: the data set is damaged"
        )


# -- compact storage's arrays ---------------------------------------------------------------------
def write_compact(path: Path, dense_points, bits, n_visible, n_topped_up, topup_points, poses, attrs: Mapping[str, Any], *,
                  gzip_level: int) -> None:  # fmt: skip
    """The compact shard: dense cloud once, visibility bits and top-up points per pose (layout:
    :mod:`zbuf_occlude.dataset.layout`); the bits gzip-compressed at ``gzip_level``.

    Raises
    ------
    OutputError
        The file cannot be written.
    """
    el_az = np.asarray(poses, dtype=np.float64).reshape(-1, 2)
    datasets = {
        "dense_points": dense_points.astype(np.float32), "visible_bits": bits, "n_visible": n_visible,
        "n_topped_up": n_topped_up, "topup_points": np.asarray(topup_points, dtype=np.float32).reshape(-1, 3),
        "elevation_deg": el_az[:, 0], "azimuth_deg": el_az[:, 1],
    }  # fmt: skip
    write_datasets(path, datasets, {**attrs, "n_dense": len(dense_points)}, gzip={"visible_bits": gzip_level})


def unpack_visible(bits: NDArray[np.uint8], n_dense: int) -> NDArray[np.bool_]:
    """Undo :func:`numpy.packbits` of one visibility mask.

    Returns
    -------
    visible : (n_dense,) bool
    """
    return np.unpackbits(np.asarray(bits, dtype=np.uint8), count=int(n_dense)).astype(bool)


def reconstruct_samples(
    dense_points: NDArray[np.float32],
    visible: NDArray[np.bool_],
    *,
    seed: int,
    key: int,
    pose_index: int,
    n_points: int,
    sample_indices: Iterable[int],
    topup_points: NDArray[np.float32] | None = None,
) -> NDArray[np.float32]:
    """Redraw samples of one pose from the dense cloud, the pose's visibility mask and its top-up points.

    :func:`~zbuf_occlude.geometry.samples.pose_samples`, the draw
    :func:`~zbuf_occlude.pipeline.occlude_poses` makes, so the result is bit-identical to
    the ``data`` a dense-storage run writes.

    Parameters
    ----------
    dense_points : (M, 3) float32
        The object's dense cloud, already cast to float32.
    visible : (M,) bool
    seed, key : int
        Global seed and the object's key (manifest fields ``seed``, ``key``).
    pose_index, n_points : int
    sample_indices : iterable of int
    topup_points : (T, 3) float32, optional
        The pose's top-up points (its rows of the shard's ``topup_points``); none by default.

    Returns
    -------
    samples : (S, n_points, 3) float32
        ``S = len(sample_indices)``; ``(0, n_points, 3)`` if nothing is visible.
    """
    n_topped_up = 0 if topup_points is None else len(topup_points)
    chosen = pose_samples(
        np.flatnonzero(visible), n_points, seed=seed, key=key, pose_index=pose_index, sample_indices=sample_indices,
        n_dense=len(dense_points), n_topped_up=n_topped_up,
    )  # fmt: skip
    if not chosen:
        return np.zeros((0, n_points, 3), dtype=np.float32)
    return np.stack([pool_take(dense_points, topup_points, c) for c in chosen]).astype(np.float32, copy=False)


def check_visible_bits(path: Path, bits: Any, n_dense: int, n_visible: Sequence[int], n_topped_up: Sequence[int] | None = None) -> None:
    """Check a compact shard's visibility masks against the manifest's ``n_visible`` and ``n_topped_up``.

    Parameters
    ----------
    bits : (P, ceil(n_dense / 8)) uint8
        The shard's ``visible_bits``.
    n_visible : sequence of int
        The manifest's distinct visible points per pose (dense and topped up).
    n_topped_up : sequence of int, optional
        The manifest's top-up points per pose (``None``: none).

    Raises
    ------
    DatasetFormatError
        A pose whose mask has another number of visible points than ``n_visible - n_topped_up``
        says (a reader would draw samples from no points).
    """
    counts = np.unpackbits(np.asarray(bits, dtype=np.uint8), axis=1, count=int(n_dense)).sum(axis=1)
    dense_visible = np.asarray(n_visible, dtype=np.int64)
    if n_topped_up is not None:
        dense_visible = dense_visible - np.asarray(n_topped_up, dtype=np.int64)
    wrong = np.flatnonzero(counts != dense_visible)
    if len(wrong):
        p = int(wrong[0])
        said = (
            f"'n_visible' minus 'n_topped_up' says {int(dense_visible[p])}"
            if n_topped_up is not None
            else (f"'n_visible' says {int(n_visible[p])}")
        )
        raise DatasetFormatError(
            f"the shard {path}: 'visible_bits' of pose {p} marks {int(counts[p])} visible points, the manifest's field "
            f"{said} ({len(wrong)} poses differ); the data set is damaged"
        )
