"""``zbuf-occlude verify DIR``: check a data set before trusting it (schema, paths, checksums).

Nothing in a downloaded data set is trusted.  :func:`verify_dataset` checks what
:class:`~zbuf_occlude.dataset.reader.OccludedDataset` checks as it reads, but all of it at once
and without stopping at the first problem: the card, ``shape_names.txt`` and every line of
``manifest.jsonl`` against their schema (:mod:`zbuf_occlude.dataset.schema`), every path named
by the manifest and the file lists (inside the folder, symlinks resolved:
:func:`~zbuf_occlude.io.safe_paths.path_inside`), every file's SHA-256, and every HDF5 shard's
datasets and rows.  The file checks are the reader's own, as each storage kind states them
(:meth:`~zbuf_occlude.dataset.storage.StorageKind.check_file`: :func:`~zbuf_occlude.dataset.schema.open_shard`,
:func:`~zbuf_occlude.dataset.storage.check_visible_bits`, :func:`~zbuf_occlude.dataset.storage.check_point_column`
for the per-point columns a record declares, :func:`~zbuf_occlude.dataset.sample_files.read_sample_points`),
so what ``verify`` passes the reader reads.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from zbuf_occlude.dataset.index import samples_per_pose
from zbuf_occlude.dataset.layout import CARD_FILE, CARD_SHA256_FILE, MANIFEST_FILE, PLAN_FILE, PROTOCOL_FILE, file_list_name
from zbuf_occlude.dataset.storage import StorageKind, storage_kind
from zbuf_occlude.errors import DatasetFormatError, InvalidInputError, ZbufOccludeError
from zbuf_occlude.io.atomic import file_sha256, size_mismatch
from zbuf_occlude.io.caps import MAX_LIST_BYTES, MAX_PROTOCOL_FILE_BYTES
from zbuf_occlude.io.json_files import read_json_file
from zbuf_occlude.io.regular_files import read_text_file
from zbuf_occlude.io.safe_paths import path_inside

if TYPE_CHECKING:  # the schema (pydantic) is imported when a data set is verified
    from zbuf_occlude.dataset.schema import Card, OkRecord

    #: :func:`~zbuf_occlude.dataset.schema.read_manifest`'s lines: (line number, record dict, checked record or None).
    ManifestLines = list[tuple[int, dict[str, Any], OkRecord | None]]

__all__ = ["VerifyReport", "protocol_of", "verify_dataset"]

#: What a ``generate --protocol NAME`` folder is, and what reads it (docs/guide/protocols.md).
PROTOCOL_FOLDERS: dict[str, tuple[str, str]] = {
    "pcn": ("a PCN pairs folder", "read its shards/*.h5 with zbuf_occlude.protocols.read_arrays_h5"),
    "depth": ("a depth-image folder", "read its shards/*.h5 with zbuf_occlude.protocols.read_arrays_h5"),
    "modelnet40-c-occlusion": ("a ModelNet40-C folder", "read its data_occlusion_<severity>.npy and label.npy with numpy.load"),
    "modelnet40-c-lidar": ("a ModelNet40-C folder", "read its data_lidar_<severity>.npy and label.npy with numpy.load"),
}


#: A joined file (``occluded_<split>.h5``, a file list) holds its split's samples once more, in
#: HDF5's layout of one file: larger than this many times its shards' recorded bytes, plus
#: :data:`JOINED_BYTES_SLACK`, it is not one of ours and is not hashed (a sparse file would be read in full).
JOINED_BYTES_FACTOR = 2
JOINED_BYTES_SLACK = 1 << 20


def protocol_of(root: Path) -> str | None:
    """The ``protocol`` field of a run's record in ``root`` (``generate --protocol``: ``protocol.json``,
    or ``protocol_<run>.json`` where runs share the folder, as ModelNet40-C's do), or None.

    The folder is untrusted: a file that is too large, not JSON or without a string field gives None.
    """
    for path in (root / PROTOCOL_FILE, *sorted(root.glob("protocol_*.json"))):
        try:
            name = read_json_file(path, max_bytes=MAX_PROTOCOL_FILE_BYTES, within=root).get("protocol")
        except (OSError, InvalidInputError, AttributeError):  # missing, a FIFO, a link out, too large, not JSON
            continue
        if isinstance(name, str):
            return name
    return None


def _not_a_data_set(root: Path) -> str:
    """Why a folder without a card is not a data set ``verify`` checks, in the user's terms."""
    if (root / PLAN_FILE).is_file():
        return (
            f"{root} has no {CARD_FILE}: an unfinished farm run; run the same `zbuf-occlude farm` command again to "
            "finish it, or `zbuf-occlude farm-merge` after sharded runs"
        )
    return f"{root} has no {CARD_FILE}: not a data set written by `zbuf-occlude farm` or `generate`"


@dataclass
class VerifyReport:
    """What :func:`verify_dataset` found.

    Attributes
    ----------
    path : str
    problems : list of str
        One line per problem, each naming the file (and line and field); empty when clean.
    objects, files, samples : int
        Finished objects, files checked (and hashed), samples they hold.
    """

    path: str
    problems: list[str] = field(default_factory=list)
    objects: int = 0
    files: int = 0
    samples: int = 0
    #: What is worth knowing but not a problem (a card without its SHA-256 file).
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def summary(self) -> str:
        """One line: ``OK DIR: 3 objects, 3 files (SHA-256 checked), 48 samples``."""
        line = f"OK {self.path}: {self.objects} objects, {self.files} files (SHA-256 checked), {self.samples} samples"
        return "; ".join([line, *self.notes])


@dataclass(frozen=True)
class _RecordFiles:
    """One record's files as the reader opens them (a :class:`~zbuf_occlude.dataset.storage.FileCheck`)."""

    card: Card
    rows: int
    n_files: int
    n_visible: list[int]
    n_topped_up: list[int] | None
    point_columns: list[str]

    @property
    def n_points(self) -> int:
        return self.card.params.n_points

    def open_shard(self, path: Path) -> Any:
        from zbuf_occlude.dataset.schema import open_shard

        return open_shard(
            path, storage=self.card.storage, n_points=self.n_points, rows=self.rows, n_poses=len(self.n_visible),
            sensor=self.card.params.sensor is not None, topup_rows=sum(self.n_topped_up or ()), point_columns=self.point_columns,
        )  # fmt: skip


def _check_folder(root: Path, path: str | os.PathLike) -> None:
    """Refuse what is no data set folder before anything is checked (the usage errors of :func:`verify_dataset`)."""
    if not root.exists():
        raise InvalidInputError(f"verify: no such folder: {path}")
    if not root.is_dir():
        raise InvalidInputError(f"verify: {path} is a file, not a data set folder")
    if not (root / CARD_FILE).exists() and (protocol := protocol_of(root)) is not None:
        folder, reader = PROTOCOL_FOLDERS.get(protocol, (f"a `--protocol {protocol}` folder", "see docs/guide/protocols.md"))
        raise InvalidInputError(
            f"verify: {path} is {folder}, not a farm data set: it was written by `zbuf-occlude generate --protocol "
            f"{protocol}`, whose own layout verify does not check; {reader}"
        )


def _read_card(root: Path, report: VerifyReport) -> Card | None:
    """The card, its SHA-256 file checked; ``None`` (and the problem reported) when it cannot be read."""
    from zbuf_occlude.dataset.schema import check_card_sha256, read_card

    try:
        if (root / CARD_FILE).exists() and not check_card_sha256(root):
            report.notes.append(
                f"{root / CARD_FILE} has no SHA-256 file ({CARD_SHA256_FILE}; written by an older zbuf_occlude): "
                "changes to the card cannot be noticed"
            )
    except ZbufOccludeError as exc:
        report.problems.append(str(exc))
    try:
        return read_card(root / CARD_FILE)[1]
    except ZbufOccludeError as exc:
        report.problems.append(str(exc) if (root / CARD_FILE).exists() else _not_a_data_set(root))
        return None


def _read_manifest(root: Path, card: Card, problems: list[str]) -> ManifestLines | None:
    """The manifest's lines, each record checked against the card and ``shape_names.txt``; ``None``
    when the manifest cannot be read."""
    from zbuf_occlude.dataset.schema import check_records, read_manifest, read_shape_names

    try:
        shape_names = read_shape_names(root, card)
    except ZbufOccludeError as exc:
        problems.append(str(exc))
        shape_names = None
    try:
        rows = read_manifest(root / MANIFEST_FILE, problems)
    except ZbufOccludeError as exc:
        problems.append(str(exc))
        return None
    if shape_names is not None:
        check_records(root / MANIFEST_FILE, rows, card, shape_names, problems)
    return rows


def _kind_of(root: Path, card: Card, problems: list[str]) -> StorageKind | None:
    """The card's storage kind; ``None`` (a problem) when the reader refuses it: its files are still counted and hashed."""
    try:
        return storage_kind(card.storage, sensor=card.params.sensor is not None)
    except InvalidInputError as exc:
        problems.append(f"{root / CARD_FILE}: {exc}")
        return None


def _check_record(root: Path, where: str, rec: OkRecord, check: _RecordFiles, kind: StorageKind | None, report: VerifyReport) -> None:
    """One finished object's files: inside the folder, present, of their recorded sizes and SHA-256, and
    what the reader would refuse in them (:meth:`~zbuf_occlude.dataset.storage.StorageKind.check_file`)."""
    problems = report.problems
    try:
        files = [path_inside(root, rel, what=f"{where} field 'shards'", quoted=False) for rel in rec.shards]
    except ZbufOccludeError as exc:
        problems.append(str(exc))
        return
    missing = [rel for rel, file in zip(rec.shards, files) if not file.is_file()]
    if missing:
        problems.extend(f"{where}: the file {rel} is missing" for rel in missing)
        return
    mismatch = size_mismatch(files, rec.bytes)  # before a byte is read
    if mismatch is not None:
        problems.append(f"{where}: {mismatch} (changed after it was written)")
        return
    if kind is not None:
        from zbuf_occlude.dataset.schema import check_declared_rows

        try:  # as the reader checks it, before a byte is read
            check_declared_rows(kind, files, check.rows, check.n_points, where)
        except ZbufOccludeError as exc:
            problems.append(str(exc))
            return
    for i, (rel, file) in enumerate(zip(rec.shards, files)):
        report.files += 1
        if rec.sha256 is not None and file_sha256(file) != rec.sha256[i]:
            problems.append(f"{where}: {rel} differs from its SHA-256 in the manifest (changed after it was written)")
            continue
        if kind is None:
            continue
        try:
            kind.check_file(file, check)
        except ZbufOccludeError as exc:
            problems.append(str(exc))


def _check_objects(root: Path, card: Card, kind: StorageKind | None, rows: ManifestLines, report: VerifyReport, *,
                   progress: bool) -> tuple[dict[str, list[str]], dict[str, int]]:  # fmt: skip
    """Every finished object's files (:func:`_check_record`); the files listed per split and the
    shards' recorded bytes per split, which bound the joined files."""
    from zbuf_occlude.io.progress import progress as progress_bar

    manifest = root / MANIFEST_FILE
    listed: dict[str, list[str]] = {}
    split_bytes: dict[str, int] = {}
    missing_checksums = 0
    for lineno, _, rec in progress_bar(rows, desc="verify", unit="obj", enabled=progress):
        if rec is None:
            continue
        report.objects += 1
        listed.setdefault(rec.split, []).extend(rec.shards)
        split_bytes[rec.split] = split_bytes.get(rec.split, 0) + (rec.bytes or 0)
        missing_checksums += rec.sha256 is None
        # a storage the reader refuses: its samples counted as a kind of samples_per_view per pose would
        n_rows = int((kind.rows_per_pose if kind else samples_per_pose)(rec.n_visible, card.params.samples_per_view).sum())
        report.samples += n_rows
        check = _RecordFiles(card, n_rows, len(rec.shards), rec.n_visible, rec.n_topped_up, rec.point_columns or [])
        _check_record(root, f"{manifest}:{lineno}", rec, check, kind, report)
    if missing_checksums:
        said = " although the card's field 'checksums' says every file has one" if card.checksums else ""
        report.problems.append(
            f"{manifest}: {missing_checksums} finished objects have no SHA-256 (field 'sha256'){said}: changes to their "
            "files cannot be noticed; OccludedDataset reads them only with verify=False"
        )
    return listed, split_bytes


def _check_joined(root: Path, card: Card, split_bytes: dict[str, int], report: VerifyReport) -> None:
    """The files joined from the shards for other readers (PointNet's h5 and lists), against the card's SHA-256."""
    problems = report.problems
    for entry in card.joined_files or []:
        try:
            file = path_inside(root, entry.path, what=f"{root / CARD_FILE} field 'joined_files'", quoted=False)
        except ZbufOccludeError as exc:
            problems.append(str(exc))
            continue
        if not file.is_file():
            problems.append(f"{root / CARD_FILE}: the joined file {entry.path} is missing")
        elif file.stat().st_size > JOINED_BYTES_FACTOR * split_bytes.get(entry.split, 0) + JOINED_BYTES_SLACK:
            problems.append(
                f"{file} holds {file.stat().st_size:,} bytes, more than the shards of its split could make "
                f"({JOINED_BYTES_FACTOR} x {split_bytes.get(entry.split, 0):,} + {JOINED_BYTES_SLACK:,}); not read"
            )
        elif file_sha256(file) != entry.sha256:
            problems.append(f"{file} differs from its SHA-256 in the card (changed after it was written)")
        else:
            report.files += 1


def _check_file_lists(root: Path, card: Card, listed: dict[str, list[str]], problems: list[str]) -> None:
    """Each split's file list: its paths inside the folder, and the same files as the manifest's
    objects (``listed``) or, where the card has joined files, as those."""
    if card.joined_files is not None:  # the file lists name the joined files, not the shards
        listed = {}
        for entry in card.joined_files:
            if entry.path != file_list_name(entry.split):
                listed.setdefault(entry.split, []).append(entry.path)
    for split in card.splits or sorted(listed):
        list_file = root / file_list_name(split)
        if not list_file.is_file():
            continue
        try:
            lines = [s for s in read_text_file(list_file, max_bytes=MAX_LIST_BYTES, error=DatasetFormatError, within=root).split("\n") if s]
        except InvalidInputError as exc:  # a FIFO, larger than MAX_LIST_BYTES, not UTF-8, a link out of the folder
            problems.append(str(exc))
            continue
        for n, rel in enumerate(lines, start=1):
            try:
                path_inside(root, rel, what=f"{list_file}:{n}", quoted=False)
            except ZbufOccludeError as exc:
                problems.append(str(exc))
        if sorted(lines) != sorted(listed.get(split, [])):
            source = "the card's joined files" if card.joined_files is not None else "the manifest's objects"
            problems.append(f"{list_file} does not list the same files as {source} of split {split}")


def verify_dataset(path: str | os.PathLike, *, progress: bool = False) -> VerifyReport:
    """Check a data set folder and list every problem found.

    In order: the card (and its SHA-256 file), ``shape_names.txt`` and the manifest's records,
    the storage the card names, every finished object's files, the joined files, the file lists.

    Parameters
    ----------
    path : str or PathLike
        The data set folder (``farm --out``, ``generate --out``).
    progress : bool
        Show the objects checked on stderr (:func:`zbuf_occlude.io.progress.progress`).

    Returns
    -------
    VerifyReport
        ``report.ok`` is true when nothing was found.

    Raises
    ------
    InvalidInputError
        ``path`` does not exist or is not a folder, or it is a ``generate --protocol`` folder
        (PCN pairs, depth images, ModelNet40-C arrays: not a data set; the message names its kind
        and what reads it).  These are usage errors, not problems of a data set.
    """
    root = Path(path)
    _check_folder(root, path)
    report = VerifyReport(str(root))
    card = _read_card(root, report)
    rows = None if card is None else _read_manifest(root, card, report.problems)
    if card is None or rows is None:
        return report
    kind = _kind_of(root, card, report.problems)
    listed, split_bytes = _check_objects(root, card, kind, rows, report, progress=progress)
    _check_joined(root, card, split_bytes, report)
    _check_file_lists(root, card, listed, report.problems)
    return report
