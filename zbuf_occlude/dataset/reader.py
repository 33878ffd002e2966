"""Read the data sets that :func:`zbuf_occlude.farm.run_farm` writes: :class:`OccludedDataset`.

The folder layout, the storage modes and the shard schemas are in :mod:`zbuf_occlude.dataset.layout`;
this module reads them (both storage modes, and ``generate``'s folders in every ``--format``:
``h5`` parts like dense shards, ``npz``/``ply`` sample files through :mod:`zbuf_occlude.dataset.sample_files`).
"""

from __future__ import annotations

import itertools
import os
from collections import OrderedDict
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.dataset.layout import (
    CARD_FILE,
    FORMAT_VERSION,
    MANIFEST_FILE,
    SAMPLE_FILE_FORMATS,
    STORAGE_MODES,
)
from zbuf_occlude.errors import InvalidInputError, ShardChecksumError
from zbuf_occlude.geometry.samples import pool_take, pose_samples
from zbuf_occlude.io.safe_paths import path_inside
from zbuf_occlude.mesh.discovery import SPLITS, name_set
from zbuf_occlude.resources import check_memory

__all__ = ["OccludedDataset", "reconstruct_samples", "unpack_visible", "samples_per_pose"]

#: Objects whose compact arrays (dense cloud and bitmasks, ~1 MB each) the reader keeps.
DEFAULT_OBJECT_CACHE = 8
#: HDF5 files the reader keeps open (dense storage), least recently used closed first.
DEFAULT_OPEN_FILES = 16
#: Degrees: a pose matches a requested elevation/azimuth within this (poses are stored
#: as the exact floats of the schedule, so this only absorbs decimal round trips).
POSE_MATCH_ATOL_DEG = 1e-6

#: Bytes one point of one sample costs while it is read or redrawn: float32 xyz in the result
#: (12), its index into the dense cloud (int64, 8) and the gathered copy (12), rounded up.
BYTES_PER_SAMPLE_POINT = 40

#: Per-row datasets of a ``farm --sensor`` shard that :meth:`OccludedDataset.metadata` returns.
SENSOR_ROW_FIELDS = (
    "elevation_deg", "azimuth_deg", "radius", "distance_m", "sensor_height_m", "object_azimuth_deg", "yaw_deg", "size_m",
    "hidden_below_m", "width_scale",
)  # fmt: skip

PoseFilter = float | Iterable[float] | Callable[[float], bool] | None


def samples_per_pose(n_visible: NDArray[np.integer], samples_per_view: int) -> NDArray[np.int64]:
    """``(P,) int64``: samples stored per pose (none where nothing is visible)."""
    return np.where(np.asarray(n_visible) > 0, int(samples_per_view), 0).astype(np.int64)


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


def _pose_mask(values: NDArray[np.float64], spec: PoseFilter, name: str) -> NDArray[np.bool_]:
    if spec is None:
        return np.ones(len(values), dtype=bool)
    if callable(spec):
        return np.array([bool(spec(float(v))) for v in values], dtype=bool)
    wanted = np.atleast_1d(np.asarray(spec, dtype=np.float64))
    if wanted.ndim != 1 or not np.all(np.isfinite(wanted)):
        raise InvalidInputError(f"{name} must be a number, a sequence of numbers or a predicate, got {spec!r}")
    return np.isclose(values[:, None], wanted[None, :], rtol=0.0, atol=POSE_MATCH_ATOL_DEG).any(axis=1)


class OccludedDataset(Sequence):
    """Occluded samples of a farm data set, as a sequence of ``(points, label, metadata)``.

    Works for both storage modes, for ``generate``'s folders in every ``--format`` (``h5``,
    ``npz``, ``ply``; module docstring) and with
    ``torch.utils.data.DataLoader`` (torch is not needed otherwise): items are numpy
    arrays, ints and dicts of scalars and strings, which the default collate turns into
    tensors and lists; open files are per process, so loader workers open their own.

    Parameters
    ----------
    path : str or PathLike
        The data set folder (``--out`` of the farm or of ``generate``).
    split : str or sequence of str, optional
        ``"train"``, ``"test"`` (or both, the default).
    classes : str or sequence of str, optional
        Class names to keep (comma-separated string or a sequence).  Labels keep their
        data-set-wide values (line numbers of ``shape_names.txt``).
    elevation_deg, azimuth_deg : float, sequence of float or callable, optional
        Keep poses whose elevation (azimuth), degrees, equals one of the values (within
        1e-6°) or satisfies the predicate, e.g. ``elevation_deg=lambda el: el >= 0``
        (Sryamkin et al. 2023, Table 3A trains and tests on different elevations).
        ``farm --sensor`` data sets: each scan's own sensor direction seen from the object
        (read from the shards), e.g. ``elevation_deg=lambda el: el < 10``.
    object_cache : int
        Compact storage: objects whose dense cloud and bitmasks stay in memory.
    verify : bool
        Check every shard against its SHA-256 in the manifest before reading it (default).
        A data set whose manifest lacks the checksums is refused unless ``verify=False``:
        without them a changed shard cannot be noticed.

    Attributes
    ----------
    card : dict
        The data set card (parameters, poses, version, command line).
    shape_names : list of str
        Class name of each label.
    storage : {"dense", "compact"}
    n_points : int
        Points per sample.

    Raises
    ------
    InvalidInputError
        Not a finished farm data set, a newer format, an unknown split or class name, or an
        ``elevation_deg``/``azimuth_deg`` filter that leaves none of the chosen samples.
    DatasetFormatError
        The card differs from its SHA-256 file (``dataset_card.json.sha256``; a data set
        without one still reads), the card, the manifest or ``shape_names.txt`` does not match its schema
        (:mod:`zbuf_occlude.dataset.schema`; the message names the file, line and field), checksums
        are missing (and ``verify`` is true); on access, a shard that is not HDF5 or
        lacks a dataset or rows.
    UnsafePathError
        A path in the manifest is absolute, has ``..`` or leads outside the folder
        (through a symlink): nothing outside the data set is read.
    ShardChecksumError
        On access: a shard's bytes differ from the SHA-256 in the manifest (it names the
        shard; rerunning the farm command redoes that object).
    InsufficientMemoryError
        The card's ``n_points`` makes one sample larger than the memory available; on
        access, a shard declares datasets larger than it; :meth:`to_arrays` would not fit.

    Examples
    --------
    >>> ds = OccludedDataset("modelnet_occluded", split="train", elevation_deg=[0, 10, 20])
    >>> points, label, meta = ds[0]          # (2048, 3) float32, int, dict
    """

    def __init__(
        self,
        path: str | os.PathLike,
        split: str | Sequence[str] | None = None,
        classes: str | Sequence[str] | None = None,
        elevation_deg: PoseFilter = None,
        azimuth_deg: PoseFilter = None,
        *,
        object_cache: int = DEFAULT_OBJECT_CACHE,
        verify: bool = True,
    ):
        self.root = Path(path)
        self.verify = bool(verify)
        card_path = self.root / CARD_FILE
        if not self.root.is_dir():
            raise InvalidInputError(f"no such data set folder: {self.root}")
        if not card_path.is_file():
            raise InvalidInputError(
                f"{self.root} is not a finished farm data set (no {CARD_FILE}); let `zbuf-occlude farm` finish, "
                "or run `zbuf-occlude farm-merge` after sharded runs"
            )
        # the schema (pydantic) is imported when a data set is opened, not with the package
        from zbuf_occlude.dataset.schema import (
            check_card_sha256,
            check_records,
            checked_shards,
            read_card,
            read_manifest,
            read_shape_names,
        )  # fmt: skip

        self.card, card = read_card(card_path)  # its schema first: a damaged field is named
        check_card_sha256(self.root)  # then its checksum, before any size it declares is used
        version = card.format_version
        if version > FORMAT_VERSION:
            raise InvalidInputError(
                f"{self.root} has data set format {version}; this zbuf_occlude reads up to {FORMAT_VERSION}: upgrade it"
            )
        self.storage: str = card.storage
        if self.storage not in (*STORAGE_MODES, "h5", *SAMPLE_FILE_FORMATS):
            raise InvalidInputError(f"{card_path}: unknown storage {self.storage!r}; this zbuf_occlude reads {STORAGE_MODES}")
        params = card.params
        self.n_points: int = params.n_points
        # the card is data: an n_points edited to 1e8 must not allocate GBs for one sample
        check_memory(
            self.n_points * BYTES_PER_SAMPLE_POINT, option=f"{card_path} field 'params.n_points' ({self.n_points:,})",
            hint="one sample of this data set would not fit in memory: check where the data set comes from",
        )  # fmt: skip
        self._samples_per_view = params.samples_per_view
        #: ``farm --sensor``: one sample per scan, each with its own placement stored in its shard row
        self.sensor: str | None = params.sensor
        self._seed = params.seed
        self.shape_names: list[str] = read_shape_names(self.root, card)
        poses = np.asarray(card.poses, dtype=np.float64).reshape(-1, 2)
        self._elevation, self._azimuth = poses[:, 0], poses[:, 1]
        pose_keep = _pose_mask(self._elevation, elevation_deg, "elevation_deg") & _pose_mask(
            self._azimuth, azimuth_deg, "azimuth_deg"
        )
        if self.sensor is None and len(pose_keep) and not pose_keep.any():  # a typo, not an empty data set
            elevations = ", ".join(f"{v:g}" for v in sorted(set(self._elevation.tolist())))
            raise InvalidInputError(
                f"no pose of {self.root} matches elevation_deg={elevation_deg!r}, azimuth_deg={azimuth_deg!r}; "
                f"its poses have elevations {elevations} (degrees)"
            )

        splits = name_set(split)
        wanted_classes = name_set(classes)
        if wanted_classes is not None and (unknown := wanted_classes - set(self.shape_names)):
            raise InvalidInputError(f"unknown classes {sorted(unknown)} in {self.root}; it has {self.shape_names}")
        known_splits = set(card.splits if card.splits is not None else SPLITS)
        if splits is not None and (unknown := splits - known_splits):
            raise InvalidInputError(f"unknown split(s) {sorted(unknown)} in {self.root}; it has {sorted(known_splits)}")

        self._reset_handles()
        self._objects: list[dict[str, Any]] = []
        self._shards: list[Path] = []  # per object: its shard, checked to lie inside the data set
        self._digests: dict[Path, str] = {}  # shard → SHA-256 recorded by the farm
        self._shard_rows: dict[Path, int] = {}  # shard → rows its manifest line promises
        self._topup_rows: dict[Path, int] = {}  # compact shard → top-up points its manifest line promises
        self._verified: set[Path] = set()
        obj_rows, poses_rows, sample_rows, shard_rows = [], [], [], []
        pose_filtered = elevation_deg is not None or azimuth_deg is not None
        before_pose_filter = 0  # samples of the chosen splits and classes: a pose filter that leaves none of them is a mistake
        scan_directions: list[NDArray[np.float64]] = []  # farm --sensor: each scan's (elevation, azimuth), for that message
        manifest_path = self.root / MANIFEST_FILE
        manifest = read_manifest(manifest_path)
        check_records(manifest_path, manifest, card, self.shape_names)
        for lineno, rec, checked in manifest:
            if checked is None:  # failed or pending objects have no shard
                continue
            if splits is not None and checked.split not in splits:
                continue
            if wanted_classes is not None and checked.class_name not in wanted_classes:
                continue
            shards, digests = checked_shards(self.root, f"{manifest_path}:{lineno}", checked, card, verify=self.verify)
            self._digests.update(digests)
            spp = samples_per_pose(np.asarray(checked.n_visible, dtype=np.int64), 1 if self.sensor else self._samples_per_view)
            self._shard_rows[shards[0]] = int(spp.sum())
            self._topup_rows[shards[0]] = int(sum(checked.n_topped_up or ()))
            pose = np.repeat(np.arange(len(spp)), spp)
            starts = np.cumsum(spp) - spp
            sample = np.arange(len(pose)) - np.repeat(starts, spp)
            if self.sensor is None:
                keep = pose_keep[pose]
            elif elevation_deg is None and azimuth_deg is None:
                keep = np.ones(len(pose), dtype=bool)
            else:  # each scan's own sensor direction, from its shard row
                f = self._file(shards[0])
                el, az = f["elevation_deg"][()], f["azimuth_deg"][()]
                scan_directions.append(np.column_stack([el, az]).astype(np.float64))
                keep = _pose_mask(el, elevation_deg, "elevation_deg") & _pose_mask(az, azimuth_deg, "azimuth_deg")
            before_pose_filter += len(pose)
            obj_rows.append(np.full(int(keep.sum()), len(self._objects), dtype=np.int64))
            poses_rows.append(pose[keep])
            sample_rows.append(sample[keep])
            shard_rows.append(np.flatnonzero(keep))
            self._objects.append(rec)
            self._shards.append(shards[0])

        def cat(parts: list[NDArray[np.int64]]) -> NDArray[np.int64]:
            return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, dtype=np.int64)

        self._obj, self._pose, self._sample, self._row = cat(obj_rows), cat(poses_rows), cat(sample_rows), cat(shard_rows)
        if pose_filtered and before_pose_filter and not len(self._obj):  # a typo, not an empty data set
            directions = np.concatenate(scan_directions) if scan_directions else np.zeros((0, 2))
            seen = (
                f"its scans' sensor elevations span {directions[:, 0].min():g} to {directions[:, 0].max():g} and azimuths "
                f"{directions[:, 1].min():g} to {directions[:, 1].max():g} (degrees, seen from the object)"
                if len(directions) else "the poses it matches hold no sample of the chosen splits and classes (nothing visible)"
            )  # fmt: skip
            raise InvalidInputError(
                f"no sample of {self.root} matches elevation_deg={elevation_deg!r}, azimuth_deg={azimuth_deg!r} "
                f"({before_pose_filter} samples before this filter); {seen}"
            )
        self._object_cache_size = max(1, int(object_cache))
        if not hasattr(self, "_files"):
            self._reset_handles()

    # -- per-process state (DataLoader workers and pickling) ---------------------------
    def _reset_handles(self) -> None:
        self._pid = os.getpid()
        self._files: OrderedDict[Path, Any] = OrderedDict()
        self._compact: OrderedDict[int, tuple[NDArray[np.float32], NDArray[np.uint8], list[NDArray[np.float32]]]] = OrderedDict()

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_files"], state["_compact"] = OrderedDict(), OrderedDict()
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._reset_handles()

    def _file(self, path: Path):
        from zbuf_occlude.dataset.schema import open_shard

        if self._pid != os.getpid():  # forked: the parent's HDF5 handles are not ours
            self._reset_handles()
        f = self._files.get(path)
        if f is None:
            self._verify(path)
            f = open_shard(
                path, storage=self.storage, n_points=self.n_points, rows=self._shard_rows.get(path, 0),
                n_poses=len(self._elevation), sensor=self.sensor is not None, topup_rows=self._topup_rows.get(path, 0),
            )  # fmt: skip
            self._files[path] = f
            while len(self._files) > DEFAULT_OPEN_FILES:
                self._files.popitem(last=False)[1].close()
        else:
            self._files.move_to_end(path)
        return f

    def _verify(self, path: Path) -> None:
        """Check a shard against its SHA-256 in the manifest, once per process."""
        digest = self._digests.get(path)
        if digest is None or path in self._verified:
            return
        from zbuf_occlude.io.atomic import file_sha256

        try:
            actual = file_sha256(path)
        except OSError as exc:
            raise InvalidInputError(f"cannot read the shard {path}: {exc.strerror or exc}") from exc
        if actual != digest:
            raise ShardChecksumError(
                f"the shard {path} was changed after the farm wrote it (SHA-256 {actual[:12]}…, the manifest "
                f"records {digest[:12]}…); run the same farm command again to redo that object"
            )
        self._verified.add(path)

    def _sample_file(self, rel: str) -> NDArray[np.float32]:
        """The points of one of ``generate --format npz|ply``'s sample files, checked once."""
        from zbuf_occlude.dataset.sample_files import read_sample_points

        path = path_inside(self.root, rel, what=f"{self.root / MANIFEST_FILE} field 'shards'")  # checked on open too
        self._verify(path)
        return read_sample_points(path, self.storage, self.n_points)

    def _compact_arrays(self, obj: int) -> tuple[NDArray[np.float32], NDArray[np.uint8], list[NDArray[np.float32]]]:
        """An object's dense cloud, visibility bits and top-up points of each pose (checked once, cached)."""
        hit = self._compact.get(obj)
        if hit is not None and self._pid == os.getpid():
            self._compact.move_to_end(obj)
            return hit
        from zbuf_occlude.dataset.schema import check_visible_bits

        f = self._file(self._shards[obj])
        rec = self._objects[obj]
        n_topped_up = rec.get("n_topped_up")
        dense_points, bits = f["dense_points"][()], f["visible_bits"][()]
        check_visible_bits(self._shards[obj], bits, len(dense_points), rec["n_visible"], n_topped_up)
        # rows of topup_points, pose after pose (open_shard checked their total against n_topped_up)
        topup = f["topup_points"][()] if n_topped_up else np.zeros((0, 3), dtype=np.float32)
        bounds = np.cumsum([0, *(n_topped_up or [0] * len(bits))])
        arrays = (dense_points, bits, [topup[a:b] for a, b in itertools.pairwise(bounds)])
        self._compact[obj] = arrays
        while len(self._compact) > self._object_cache_size:
            self._compact.popitem(last=False)
        return arrays

    def close(self) -> None:
        """Close the open shard files (reopened on the next access)."""
        for f in self._files.values():
            f.close()
        self._reset_handles()

    # -- sequence protocol -----------------------------------------------------------
    def __len__(self) -> int:
        return len(self._obj)

    def _points(self, i: int) -> NDArray[np.float32]:
        obj = int(self._obj[i])
        rec = self._objects[obj]
        if self.storage in SAMPLE_FILE_FORMATS:  # generate --format npz|ply: one file per sample
            return self._sample_file(rec["shards"][int(self._row[i])])
        if self.storage != "compact":
            f = self._file(self._shards[obj])
            return f["data"][int(self._row[i])]
        dense_points, bits, topup = self._compact_arrays(obj)
        pose = int(self._pose[i])
        visible = unpack_visible(bits[pose], len(dense_points))
        return reconstruct_samples(
            dense_points, visible, seed=self._seed, key=int(rec["key"]), pose_index=pose,
            n_points=self.n_points, sample_indices=[int(self._sample[i])], topup_points=topup[pose],
        )[0]  # fmt: skip

    def metadata(self, i: int) -> dict[str, Any]:
        """The metadata of sample ``i`` (the third item of ``self[i]``) without its points."""
        i = self._check_index(i)
        obj = int(self._obj[i])
        rec = self._objects[obj]
        pose = int(self._pose[i])
        n_visible = int(rec["n_visible"][pose])
        n_topped_up = rec.get("n_topped_up")
        return {
            "class_name": rec["class_name"],
            "split": rec["split"],
            "name": rec["name"],
            "source": rec["source"],
            "object_index": int(rec["object_index"]),
            "pose_index": pose,
            "sample_index": int(self._sample[i]),
            "n_visible": n_visible,
            "n_topped_up": int(n_topped_up[pose]) if n_topped_up else 0,
            "padded": n_visible < self.n_points,
        } | self._placement(obj, pose, int(self._row[i]))

    def _placement(self, obj: int, pose: int, row: int) -> dict[str, Any]:
        """The sensor direction of a sample (degrees); for ``farm --sensor`` rows also the
        placement of its scan (``radius`` in mesh units, the rest in metres and degrees)."""
        if self.sensor is None:
            return {"elevation_deg": float(self._elevation[pose]), "azimuth_deg": float(self._azimuth[pose])}
        f = self._file(self._shards[obj])
        out = {key: float(f[key][row]) for key in SENSOR_ROW_FIELDS if key in f}
        out["sensor"] = self.sensor
        return out

    def _check_index(self, i: int) -> int:
        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)):
            raise TypeError(f"OccludedDataset indices must be integers, got {type(i).__name__}")
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"index {i} out of range for {n} samples")
        return int(i) % n

    def __getitem__(self, i: int) -> tuple[NDArray[np.float32], int, dict[str, Any]]:
        """``(points (n, 3) float32, label int, metadata dict)`` of sample ``i``."""
        i = self._check_index(i)
        rec = self._objects[int(self._obj[i])]
        return self._points(i), int(rec["label"]), self.metadata(i)

    def to_arrays(self) -> tuple[NDArray[np.float32], NDArray[np.int64]]:
        """Every selected sample in memory, in this sequence's order.

        Returns
        -------
        data : (B, n, 3) float32
        label : (B,) int64

        Raises
        ------
        InsufficientMemoryError
            ``B * n * 12`` bytes are more than the memory available (checked before allocating).
        """
        check_memory(
            len(self) * self.n_points * 3 * np.dtype(np.float32).itemsize,
            option=f"to_arrays() of {self.root} ({len(self):,} samples of {self.n_points:,} points)",
            hint="select fewer samples (split, classes, poses) or read them one at a time (ds[i])",
        )  # fmt: skip
        data = np.empty((len(self), self.n_points, 3), dtype=np.float32)
        labels = np.empty(len(self), dtype=np.int64)
        bounds = np.flatnonzero(np.diff(self._obj, prepend=-1, append=-1))
        for start, stop in zip(bounds[:-1], bounds[1:]):
            obj = int(self._obj[start])
            rec = self._objects[obj]
            labels[start:stop] = int(rec["label"])
            if self.storage in SAMPLE_FILE_FORMATS:
                data[start:stop] = [self._sample_file(rec["shards"][int(r)]) for r in self._row[start:stop]]
                continue
            if self.storage != "compact":
                rows = self._row[start:stop]
                data[start:stop] = self._file(self._shards[obj])["data"][()][rows]
                continue
            dense_points, bits, topup = self._compact_arrays(obj)
            pose_rows = self._pose[start:stop]
            for pose in np.unique(pose_rows):
                sel = np.flatnonzero(pose_rows == pose) + start
                data[sel] = reconstruct_samples(
                    dense_points, unpack_visible(bits[pose], len(dense_points)), seed=self._seed,
                    key=int(rec["key"]), pose_index=int(pose), n_points=self.n_points,
                    sample_indices=self._sample[sel].tolist(), topup_points=topup[int(pose)],
                )  # fmt: skip
        return data, labels

    @property
    def labels(self) -> NDArray[np.int64]:
        """``(len(self),) int64``: the label of every sample (no points are read)."""
        per_object = np.array([int(r["label"]) for r in self._objects], dtype=np.int64)
        return per_object[self._obj] if len(self._objects) else np.zeros(0, dtype=np.int64)

    def __repr__(self) -> str:
        return (
            f"OccludedDataset({str(self.root)!r}, storage={self.storage!r}, samples={len(self)}, "
            f"objects={len(self._objects)}, n_points={self.n_points}, classes={len(self.shape_names)})"
        )
