"""Read the data sets that :func:`zbuf_occlude.farm.run_farm` writes: :class:`OccludedDataset`.

The folder layout and the shard schemas are in :mod:`zbuf_occlude.dataset.layout`; each storage
kind (the farm's ``dense`` and ``compact``, ``farm --sensor``'s crops, ``generate``'s ``h5``,
``npz`` and ``ply``) reads its samples through :mod:`zbuf_occlude.dataset.storage`, and the order of
the samples is :func:`zbuf_occlude.dataset.index.sample_index`'s.
"""

from __future__ import annotations

import itertools
import os
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.dataset.index import PoseFilter, PoseFilters, SampleIndex, sample_index
from zbuf_occlude.dataset.layout import CARD_FILE, FORMAT_VERSION, MANIFEST_FILE, POINT_COLUMNS
from zbuf_occlude.dataset.storage import BYTES_PER_POINT, StorageKind, storage_kind
from zbuf_occlude.defaults import DEFAULT_FARM_DENSE_POINTS
from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError, ShardChecksumError
from zbuf_occlude.io.safe_paths import path_inside
from zbuf_occlude.mesh.paths import SPLITS, name_set
from zbuf_occlude.resources import available_memory, check_memory

if TYPE_CHECKING:  # the schema (pydantic) is imported when a data set is opened, not with the package
    from zbuf_occlude.dataset.schema import Card

__all__ = ["OccludedDataset", "default_object_cache", "object_cache_bytes"]

#: Share of the memory available, when a data set is opened, that the compact reader's object
#: cache may fill by default (:func:`default_object_cache`).  Small, because every process that
#: reads keeps its own cache: a ``DataLoader`` with 4 workers may fill 4 × 5 %.
OBJECT_CACHE_MEMORY_FRACTION = 0.05
#: Objects the compact reader keeps by default where the memory available is unknown: a shuffled
#: pass over a data set of this many objects or fewer reads each object's shard once.
OBJECT_CACHE_UNKNOWN_MEMORY = 64
#: HDF5 files the reader keeps open (dense storage), least recently used closed first.
DEFAULT_OPEN_FILES = 16

#: Bytes one point of one sample costs while it is read or redrawn: float32 xyz in the result
#: (12), its index into the dense cloud (int64, 8) and the gathered copy (12), rounded up.
BYTES_PER_SAMPLE_POINT = 40
#: Bytes one sample costs in the index built when a data set is opened
#: (:func:`~zbuf_occlude.dataset.index.sample_index`: four int64 columns per object, then joined,
#: and the pose filter's mask): 89 B at the peak by tracemalloc with one object of 500,000
#: samples (77 with four); rounded up.  Checked before it is built: a card's ``samples_per_view``
#: is data.
BYTES_PER_INDEX_ROW = 96


def object_cache_bytes(n_dense: int, n_poses: int, n_topup: int) -> int:
    """Bytes the reader's object cache holds for one object of compact storage.

    Parameters
    ----------
    n_dense : int
        Points of the object's dense cloud (``dense_points (M, 3) float32``: 12 B each).
    n_poses : int
        Poses of the data set (``visible_bits (P, ceil(M/8)) uint8``: a bit per dense point and pose).
    n_topup : int
        Top-up points of all its poses together (``topup_points (T, 3) float32``: 12 B each).

    Returns
    -------
    int
        ``12 M + P ceil(M / 8) + 12 T`` bytes.
    """
    return BYTES_PER_POINT * (int(n_dense) + int(n_topup)) + int(n_poses) * -(-int(n_dense) // 8)


def default_object_cache(
    n_objects: int, bytes_per_object: int, available: int | None, *, fraction: float = OBJECT_CACHE_MEMORY_FRACTION
) -> int:
    """How many objects the compact reader keeps in memory when ``object_cache`` is not given.

    Every object when they fit in ``fraction`` of the memory available, else as many as fit
    there, at least one.  A shuffled pass reads each object's shard (and unpacks its bitmasks)
    once per object while the cache holds every object, and up to once per sample otherwise.

    Parameters
    ----------
    n_objects : int
        Objects the data set serves (after its split and class filters).
    bytes_per_object : int
        Bytes one object takes in the cache (:func:`object_cache_bytes`; the largest object's).
    available : int or None
        Bytes of memory available (:func:`zbuf_occlude.resources.available_memory`); None:
        unknown, and the cache holds up to :data:`OBJECT_CACHE_UNKNOWN_MEMORY` objects.
    fraction : float
        Share of ``available`` the cache may fill (default :data:`OBJECT_CACHE_MEMORY_FRACTION`).

    Returns
    -------
    int
        ``min(n_objects, fraction * available // bytes_per_object)``, at least 1.
    """
    if available is None:
        fit = OBJECT_CACHE_UNKNOWN_MEMORY
    else:
        fit = int(fraction * available) // max(int(bytes_per_object), 1)
    return max(1, min(int(n_objects), fit))


class _Shards:
    """The files of an :class:`OccludedDataset` (a :class:`~zbuf_occlude.dataset.storage.ShardSource`):
    shards opened and checked once per process, least recently used closed first; each object's
    arrays (:meth:`~zbuf_occlude.dataset.storage.Compact.load_arrays`) cached; every file checked
    against its SHA-256 once per process."""

    def __init__(self, root: Path, kind: StorageKind, card: Card, *, object_cache: int):
        self.root, self.kind = root, kind
        self.n_points, self.seed, self.sensor = card.params.n_points, card.params.seed, card.params.sensor
        #: ``(P, 2) float64``: the card's (elevation, azimuth) of every pose, degrees.
        self.poses = np.asarray(card.poses, dtype=np.float64).reshape(-1, 2)
        self.object_cache = max(1, int(object_cache))
        self.records: list[dict[str, Any]] = []
        self.paths: list[Path] = []  # per object: its shard, checked to lie inside the data set
        self.digests: dict[Path, str] = {}  # file → SHA-256 recorded by the farm
        self.rows: dict[Path, int] = {}  # shard → rows its manifest line promises
        self.topup_rows: dict[Path, int] = {}  # compact shard → top-up points its manifest line promises
        self.verified: set[Path] = set()
        self.reset()

    def add(self, rec: dict[str, Any], shards: list[Path], digests: dict[Path, str], *, rows: int, topup_rows: int) -> None:
        """Object ``len(self.records)``: its record, its files and their SHA-256, the rows its record promises."""
        self.records.append(rec)
        self.paths.append(shards[0])
        self.digests.update(digests)
        self.rows[shards[0]], self.topup_rows[shards[0]] = rows, topup_rows

    # -- per-process state (DataLoader workers and pickling)
    def reset(self) -> None:
        self.pid = os.getpid()
        self.files: OrderedDict[Path, Any] = OrderedDict()
        self.cache: OrderedDict[int, Any] = OrderedDict()

    def __getstate__(self) -> dict[str, Any]:
        return self.__dict__ | {"files": OrderedDict(), "cache": OrderedDict()}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.reset()

    def close(self) -> None:
        for f in self.files.values():
            f.close()
        self.reset()

    # -- ShardSource
    def record(self, obj: int) -> dict[str, Any]:
        return self.records[obj]

    def shard(self, obj: int) -> Any:
        from zbuf_occlude.dataset.schema import open_shard

        path = self.paths[obj]
        if self.pid != os.getpid():  # forked: the parent's HDF5 handles are not ours
            self.reset()
        f = self.files.get(path)
        if f is None:
            self.verify(path)
            f = open_shard(
                path, storage=self.kind.storage, n_points=self.n_points, rows=self.rows.get(path, 0), n_poses=len(self.poses),
                sensor=self.sensor is not None, topup_rows=self.topup_rows.get(path, 0),
                point_columns=self.records[obj].get("point_columns") or (),
            )  # fmt: skip
            self.files[path] = f
            while len(self.files) > DEFAULT_OPEN_FILES:
                self.files.popitem(last=False)[1].close()
        else:
            self.files.move_to_end(path)
        return f

    def sample_file(self, obj: int, row: int) -> NDArray[np.float32]:
        """The points of one of ``generate --format npz|ply``'s sample files, checked once."""
        from zbuf_occlude.dataset.sample_files import read_sample_points

        rel = self.records[obj]["shards"][row]
        path = path_inside(self.root, rel, what=f"{self.root / MANIFEST_FILE} field 'shards'", quoted=False)  # checked on open too
        self.verify(path)
        return read_sample_points(path, self.kind.storage, self.n_points, within=self.root)

    def arrays(self, obj: int) -> Any:
        hit = self.cache.get(obj)
        if hit is not None and self.pid == os.getpid():
            self.cache.move_to_end(obj)
            return hit
        arrays = self.kind.load_arrays(self.shard(obj), self.paths[obj], self.records[obj])
        self.cache[obj] = arrays
        while len(self.cache) > self.object_cache:
            self.cache.popitem(last=False)
        return arrays

    def verify(self, path: Path) -> None:
        """Check a file against its SHA-256 in the manifest, once per process."""
        digest = self.digests.get(path)
        if digest is None or path in self.verified:
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
        self.verified.add(path)


#: How many finished data sets one folder down the "not a finished data set" message names.
SUGGESTED_CHILDREN = 3


def _where_it_may_be(root: Path) -> str:
    """The end of the message for a folder without a card: the finished data sets one folder
    down, if any (``generate --out runs/e`` writes its data set there; a user may open its
    parent), else what finishes one (farm, or farm-merge after sharded runs)."""
    try:
        found = sorted(child for child in root.iterdir() if child.is_dir() and (child / CARD_FILE).is_file())
    except OSError:  # unreadable: no suggestion
        found = []
    if not found:
        return "let `zbuf-occlude farm` finish, or run `zbuf-occlude farm-merge` after sharded runs"
    if len(found) == 1:
        return f"did you mean {found[0]}?"
    shown = ", ".join(str(child) for child in found[:SUGGESTED_CHILDREN])
    more = f" (and {len(found) - SUGGESTED_CHILDREN} more)" if len(found) > SUGGESTED_CHILDREN else ""
    return f"the folders below it are finished data sets: did you mean one of {shown}{more}?"


def _feature_names(features: Sequence[str]) -> tuple[str, ...]:
    """``features`` as a tuple of names, each once.

    Raises
    ------
    ArgumentTypeError
        Not a list or tuple of strings (a bare string would read as its letters).
    InvalidInputError
        A name given twice.
    """
    if not isinstance(features, (list, tuple)) or not all(isinstance(name, str) for name in features):
        raise ArgumentTypeError(f"features must be a tuple of column names, e.g. ('intensity', 'return_number'), got {features!r}")
    twice = [name for name in dict.fromkeys(features) if features.count(name) > 1]
    if twice:
        raise InvalidInputError(f"feature {twice[0]!r} is named twice in features={tuple(features)}")
    return tuple(features)


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
    object_cache : int, optional
        Compact storage: objects whose dense cloud and bitmasks stay in memory, the least
        recently read dropped first (0 or 1: only the last object read).  Default: sized when
        the data set is opened, every selected object if they fit in 5 % of the memory
        available, else as many as fit there (:func:`default_object_cache`; each object takes
        12 B per dense point, a bit per dense point and pose, 12 B per top-up point,
        :func:`object_cache_bytes`), at least 1; 64 where the memory available is unknown.
        Each process that reads (each ``DataLoader`` worker) keeps its own.  A shuffled read
        costs an unpack of the object's shard when its object is not kept, and a redraw of
        the sample always (docs/farm.md gives measured times).
    verify : bool
        Check every shard against its SHA-256 in the manifest before reading it (default).
        A data set whose manifest lacks the checksums is refused unless ``verify=False``:
        without them a changed shard cannot be noticed.
    features : sequence of str
        Per-point columns returned beside xyz, in this order: each sample's points become
        ``(n, 3 + F) float32``, columns ``x, y, z, features[0], ...`` (``ds[i]``,
        :meth:`iter_arrays`, :meth:`to_arrays`).  The names are the LiDAR return fields a
        ``farm --sensor`` data set keeps when its sensor records several returns per pulse
        (:data:`~zbuf_occlude.dataset.layout.POINT_COLUMNS`: ``return_number``,
        ``number_of_returns``, ``intensity``, ``pulse_id``, ``gps_time``, ``scan_angle_deg``;
        :attr:`available_features` lists this data set's).  Each value is cast to float32:
        exact for the return numbers, ``intensity`` and ``scan_angle_deg``; ``gps_time`` and a
        ``pulse_id`` above 2**24 are rounded.  Default: none, xyz only, ``(n, 3)``.

    Attributes
    ----------
    card : dict
        The data set card (parameters, poses, version, command line).
    shape_names : list of str
        Class name of each label.
    storage : {"dense", "compact", "h5", "npz", "ply"}
        The card's storage (:mod:`zbuf_occlude.dataset.storage`; ``farm --sensor`` data sets are ``dense``).
    n_points : int
        Points per sample.
    object_cache : int
        Objects the compact reader keeps in memory (``object_cache`` as given, or as sized).
    features : tuple of str
        The per-point columns each sample returns beside xyz, in order (``features`` as given).
    available_features : tuple of str
        The per-point columns every selected object keeps (its manifest record's ``point_columns``),
        in :data:`~zbuf_occlude.dataset.layout.POINT_COLUMNS` order; empty for z-buffer data sets.

    Raises
    ------
    ArgumentTypeError
        ``features`` is not a sequence of names (a single string is refused: ``("intensity",)``).
    InvalidInputError
        Not a finished farm data set, a newer format, an unknown split or class name, an
        ``elevation_deg``/``azimuth_deg`` filter that leaves none of the chosen samples, or a
        feature that is named twice, unknown, or not kept by every selected object (the message
        names it and the available ones).
    DatasetFormatError
        The card differs from its SHA-256 file (``dataset_card.json.sha256``; a data set
        without one still reads), the card, the manifest or ``shape_names.txt`` does not match its schema
        (:mod:`zbuf_occlude.dataset.schema`; the message names the file, line and field), checksums
        are missing (and ``verify`` is true); on access, a shard that is not HDF5 or
        lacks a dataset or rows, or a per-point column of another shape, dtype or range than
        the schema's (:func:`~zbuf_occlude.dataset.storage.check_point_column`).
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
    >>> lidar = OccludedDataset("crops", features=("intensity", "return_number"))
    >>> points, label, meta = lidar[0]       # (2048, 5) float32: x, y, z, intensity, return_number
    """

    def __init__(
        self,
        path: str | os.PathLike,
        split: str | Sequence[str] | None = None,
        classes: str | Sequence[str] | None = None,
        elevation_deg: PoseFilter = None,
        azimuth_deg: PoseFilter = None,
        *,
        object_cache: int | None = None,
        verify: bool = True,
        features: Sequence[str] = (),
    ):
        self.root = Path(path)
        self.verify = bool(verify)
        self.features: tuple[str, ...] = _feature_names(features)
        card = self._read_card()
        filters = PoseFilters(elevation_deg, azimuth_deg)
        pose_keep = self._pose_keep(filters)
        self._shards = _Shards(self.root, self._kind, card, object_cache=1 if object_cache is None else object_cache)
        rows_per_pose = self._select(card, split, classes)
        if object_cache is None and self._kind.redraws:
            self._shards.object_cache = self._default_object_cache()
        self.object_cache: int = self._shards.object_cache
        self._check_features()
        keep = [self._kind.row_keep(self._shards, obj, rows, pose_keep, filters) for obj, rows in enumerate(rows_per_pose)]
        index = sample_index(rows_per_pose, keep)
        self._check_filtered(index, filters)
        self._obj, self._pose, self._sample, self._row = index.obj, index.pose, index.sample, index.row

    def _read_card(self) -> Card:
        """The card, checked: schema, SHA-256, format version, storage, the size of one sample."""
        card_path = self.root / CARD_FILE
        if not self.root.is_dir():
            raise InvalidInputError(f"no such data set folder: {self.root}")
        if not card_path.is_file():
            raise InvalidInputError(f"{self.root} is not a finished farm data set (no {CARD_FILE}); {_where_it_may_be(self.root)}")
        from zbuf_occlude.dataset.schema import check_card_sha256, read_card, read_shape_names

        self.card, card = read_card(card_path)  # its schema first: a damaged field is named
        check_card_sha256(self.root)  # then its checksum, before any size it declares is used
        if card.format_version > FORMAT_VERSION:
            raise InvalidInputError(
                f"{self.root} has data set format {card.format_version}; this zbuf_occlude reads up to {FORMAT_VERSION}: upgrade it"
            )
        self.storage: str = card.storage
        #: ``farm --sensor``: one sample per scan, each with its own placement stored in its shard row
        self.sensor: str | None = card.params.sensor
        try:
            self._kind = storage_kind(self.storage, sensor=self.sensor is not None)
        except InvalidInputError as exc:
            raise InvalidInputError(f"{card_path}: {exc}") from None
        self.n_points: int = card.params.n_points
        # the card is data: an n_points edited to 1e8 must not allocate GBs for one sample
        check_memory(
            self.n_points * BYTES_PER_SAMPLE_POINT, f"{card_path} field 'params.n_points' ({self.n_points:,})",
            hint="one sample of this data set would not fit in memory: check where the data set comes from",
        )  # fmt: skip
        self.shape_names: list[str] = read_shape_names(self.root, card)
        self._poses = np.asarray(card.poses, dtype=np.float64).reshape(-1, 2)
        return card

    def _default_object_cache(self) -> int:
        """:func:`default_object_cache` for the selected objects, sized by the largest of them;
        a record without ``n_dense`` (earlier writers) counts the farm's default dense cloud."""
        n_poses = len(self._poses)
        largest = max(
            (object_cache_bytes(rec.get("n_dense") or DEFAULT_FARM_DENSE_POINTS, n_poses, sum(rec.get("n_topped_up") or ()))
             for rec in self._shards.records),
            default=0,
        )  # fmt: skip
        found = available_memory()
        return default_object_cache(len(self._shards.records), largest, None if found is None else found[0])

    def _pose_keep(self, filters: PoseFilters) -> NDArray[np.bool_]:
        """``(P,) bool``: the card's poses the filters keep; none of them is a typo, not an empty data set."""
        keep = filters.mask(self._poses[:, 0], self._poses[:, 1])
        if not self._kind.rows_placed and len(keep) and not keep.any():
            elevations = ", ".join(f"{v:g}" for v in sorted(set(self._poses[:, 0].tolist())))
            raise InvalidInputError(f"no pose of {self.root} matches {filters}; its poses have elevations {elevations} (degrees)")
        return keep

    def _select(self, card: Card, split: str | Sequence[str] | None, classes: str | Sequence[str] | None) -> list[NDArray[np.int64]]:
        """Add the finished objects of the chosen splits and classes to the files; their samples per pose."""
        from zbuf_occlude.dataset.schema import check_declared_rows, check_records, checked_shards, read_manifest

        splits, wanted_classes = name_set(split), name_set(classes)
        if wanted_classes is not None and (unknown := wanted_classes - set(self.shape_names)):
            raise InvalidInputError(f"unknown classes {sorted(unknown)} in {self.root}; it has {self.shape_names}")
        known_splits = set(card.splits if card.splits is not None else SPLITS)
        if splits is not None and (unknown := splits - known_splits):
            raise InvalidInputError(f"unknown split(s) {sorted(unknown)} in {self.root}; it has {sorted(known_splits)}")
        manifest_path = self.root / MANIFEST_FILE
        manifest = read_manifest(manifest_path)
        check_records(manifest_path, manifest, card, self.shape_names)
        rows_per_pose, declared = [], 0
        for lineno, rec, checked in manifest:
            if checked is None:  # failed or pending objects have no shard
                continue
            if (splits is not None and checked.split not in splits) or (
                wanted_classes is not None and checked.class_name not in wanted_classes
            ):
                continue
            where = f"{manifest_path}:{lineno}"
            shards, digests = checked_shards(self.root, where, checked, card, verify=self.verify)
            spp = self._kind.rows_per_pose(np.asarray(checked.n_visible, dtype=np.int64), card.params.samples_per_view)
            rows = int(spp.sum())
            check_declared_rows(self._kind, shards, rows, self.n_points, where)
            self._shards.add(rec, shards, digests, rows=rows, topup_rows=int(sum(checked.n_topped_up or ())))
            rows_per_pose.append(spp)
            declared += rows
        check_memory(
            declared * BYTES_PER_INDEX_ROW,
            f"the index of {self.root} ({declared:,} samples declared by its card's samples_per_view and {MANIFEST_FILE})",
            hint="select fewer samples (split, classes), or check where the data set comes from",
        )
        return rows_per_pose

    def _check_features(self) -> None:
        """:attr:`available_features` of the selected objects; each of :attr:`features` among them."""
        kept = [set(rec.get("point_columns") or ()) for rec in self._shards.records]
        common = set.intersection(*kept) if kept else set()
        self.available_features: tuple[str, ...] = tuple(name for name in POINT_COLUMNS if name in common)
        missing = [name for name in self.features if name not in common]
        if missing:
            what = "is not a per-point column of" if missing[0] not in POINT_COLUMNS else "is not kept by every selected object of"
            has = (
                f"it has {self.available_features}"
                if self.available_features
                else ("it has none (farm --sensor keeps them when its sensor records several returns per pulse, max_returns > 1)")
            )
            raise InvalidInputError(f"feature {missing[0]!r} {what} {self.root}; {has}")

    def _check_filtered(self, index: SampleIndex, filters: PoseFilters) -> None:
        """A pose filter that leaves none of the chosen samples is a typo, not an empty data set."""
        if not filters.active or not index.n_unfiltered or len(index):
            return
        if self._kind.rows_placed:
            el, az = np.concatenate(
                [np.column_stack(self._kind.row_directions(self._shards, obj)) for obj in range(len(self._shards.records))]
            ).T
            seen = (
                f"its scans' sensor elevations span {el.min():g} to {el.max():g} and azimuths {az.min():g} to {az.max():g} "
                "(degrees, seen from the object)"
            )
        else:
            seen = "the poses it matches hold no sample of the chosen splits and classes (nothing visible)"
        raise InvalidInputError(f"no sample of {self.root} matches {filters} ({index.n_unfiltered} samples before this filter); {seen}")

    def close(self) -> None:
        """Close the open shard files (reopened on the next access)."""
        self._shards.close()

    # -- sequence protocol -----------------------------------------------------------
    def __len__(self) -> int:
        return len(self._obj)

    def _read(self, start: int, stop: int) -> NDArray:
        """``(stop - start, n, 3 + F)``: the points of samples ``start .. stop - 1``, all of one object, and their features."""
        obj = int(self._obj[start])
        row = self._row[start:stop]
        points = self._kind.read(self._shards, obj, self._pose[start:stop], self._sample[start:stop], row)
        if not self.features:
            return points
        return np.concatenate([points, self._kind.read_columns(self._shards, obj, self.features, row)], axis=-1)

    def metadata(self, i: int) -> dict[str, Any]:
        """The metadata of sample ``i`` (the third item of ``self[i]``) without its points.

        ``source`` is the mesh file relative to the input root, the folder the farm was given,
        which the card's ``source`` names (data sets made by earlier versions: its absolute path).
        """
        i = self._check_index(i)
        obj = int(self._obj[i])
        rec = self._shards.record(obj)
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
        } | self._kind.placement(self._shards, obj, pose, int(self._row[i]))

    def dense_points(self, i: int) -> NDArray[np.float32] | None:
        """The complete cloud that sample ``i`` was drawn from, when the storage keeps it.

        Returns
        -------
        (M, 3) float32 or None
            The object's dense cloud (``compact`` storage: ``--dense-points`` points on its
            surface), object frame, read once per object like the samples; None for the kinds
            that store the samples only (``dense``, ``h5``, ``npz``, ``ply``, ``farm --sensor``).
        """
        i = self._check_index(i)
        if not self._kind.redraws:  # only the kinds that redraw samples keep the cloud they redraw from
            return None
        return self._shards.arrays(int(self._obj[i]))[0]

    def _check_index(self, i: int) -> int:
        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)):
            raise TypeError(f"OccludedDataset indices must be integers, got {type(i).__name__}")
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"index {i} out of range for {n} samples")
        return int(i) % n

    def __getitem__(self, i: int) -> tuple[NDArray[np.float32], int, dict[str, Any]]:
        """``(points (n, 3 + F) float32, label int, metadata dict)`` of sample ``i`` (F: ``len(features)``)."""
        i = self._check_index(i)
        rec = self._shards.record(int(self._obj[i]))
        return self._read(i, i + 1)[0], int(rec["label"]), self.metadata(i)

    def to_arrays(self) -> tuple[NDArray[np.float32], NDArray[np.int64]]:
        """Every selected sample in memory, in this sequence's order.

        Returns
        -------
        data : (B, n, 3 + F) float32
            xyz, then the :attr:`features` in order.
        label : (B,) int64

        Raises
        ------
        InsufficientMemoryError
            ``B * n * (3 + F) * 4`` bytes are more than the memory available (checked before allocating).
        """
        width = 3 + len(self.features)
        check_memory(
            len(self) * self.n_points * width * np.dtype(np.float32).itemsize,
            f"to_arrays() of {self.root} ({len(self):,} samples of {self.n_points:,} points)",
            hint="select fewer samples (split, classes, poses) or read them one at a time (ds[i])",
        )
        data = np.empty((len(self), self.n_points, width), dtype=np.float32)
        for start, block in self.iter_arrays():
            data[start : start + len(block)] = block
        return data, self.labels

    def iter_arrays(self) -> Iterator[tuple[int, NDArray[np.float32]]]:
        """Every selected sample in this sequence's order, one object at a time: memory for one object's samples, not the set's.

        Yields
        ------
        start : int
            Index of the block's first sample in this sequence.
        data : (k, n, 3 + F) float32
            The points of samples ``start .. start + k - 1``, all of one object, object frame,
            then their :attr:`features`.
        """
        bounds = np.flatnonzero(np.diff(self._obj, prepend=-1, append=-1))
        for start, stop in itertools.pairwise(bounds):  # object after object
            yield int(start), self._read(int(start), int(stop))

    @property
    def labels(self) -> NDArray[np.int64]:
        """``(len(self),) int64``: the label of every sample (no points are read)."""
        per_object = np.array([int(r["label"]) for r in self._shards.records], dtype=np.int64)
        return per_object[self._obj] if len(per_object) else np.zeros(0, dtype=np.int64)

    def __repr__(self) -> str:
        return (
            f"OccludedDataset({str(self.root)!r}, storage={self.storage!r}, samples={len(self)}, "
            f"objects={len(self._shards.records)}, n_points={self.n_points}, classes={len(self.shape_names)})"
        )
