"""The schema of a data set's metadata, checked when it is opened (pydantic models).

A data set may come from anyone, so nothing in it is trusted: the card
(``dataset_card.json``), every line of ``manifest.jsonl``, ``shape_names.txt`` and each
shard as it is opened are checked here, and anything that does not fit raises
:class:`~zbuf_occlude.errors.DatasetFormatError` naming the file and the field, never a
``KeyError`` or a raw h5py error.  The layout itself is described in
:mod:`zbuf_occlude.dataset.layout`; paths in the metadata are checked by
:func:`zbuf_occlude.io.safe_paths.path_inside`.

Unknown fields are allowed (a newer writer may add some); missing or mistyped ones are not.
Numbers must be JSON numbers (``"2048"`` is refused), poses pairs of numbers.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from zbuf_occlude.dataset.layout import CARD_FILE, CARD_SHA256_FILE, COLUMN_TYPES, POINT_COLUMNS, SHAPE_NAMES_FILE
from zbuf_occlude.dataset.storage import StorageKind, storage_kind
from zbuf_occlude.errors import DatasetFormatError, InvalidInputError
from zbuf_occlude.io.file_errors import KEY_CHARS
from zbuf_occlude.io.caps import MAX_CARD_CHECKSUM_BYTES, MAX_LIST_BYTES, MAX_MANIFEST_BYTES, MAX_METADATA_BYTES
from zbuf_occlude.io.hdf5 import Column, declared_nbytes, open_hdf5
from zbuf_occlude.io.atomic import size_mismatch
from zbuf_occlude.io.json_files import loads_json
from zbuf_occlude.resources import check_memory
from zbuf_occlude.io.regular_files import open_regular_file, read_text_file
from zbuf_occlude.io.safe_paths import control_character, path_inside

__all__ = [
    "CardParams",
    "Card",
    "PointSetCard",
    "VISIBILITY_FROM",
    "ManifestRecord",
    "ObjectRecord",
    "OkRecord",
    "Plan",
    "CHECKSUM_ALGORITHM",
    "read_card",
    "card_sha256_line",
    "check_card_sha256",
    "read_manifest",
    "read_shape_names",
    "check_records",
    "check_point_set_records",
    "checked_shards",
    "check_declared_rows",
    "check_shard",
    "open_shard",
    "describe_validation_error",
]

#: What the card's ``checksums`` field says when every file of every object has one in the manifest.
CHECKSUM_ALGORITHM = "sha256"
#: Problems listed per validation error before "and N more".
MAX_LISTED = 5
#: Bytes of memory the manifest's records take per byte of manifest (each line held as a dict and
#: a checked :class:`OkRecord`): 11.9 at the peak by tracemalloc over 20,000 of the farm's 734-byte
#: records; rounded up.  Checked before the manifest is read.
MANIFEST_MEMORY_PER_BYTE = 16

NonNegativeInt = Annotated[int, Field(ge=0)]
PositiveInt = Annotated[int, Field(ge=1)]
Sha256 = Annotated[str, Field(pattern=r"^[0-9a-f]{64}$")]


class _Model(BaseModel):
    # strict: JSON numbers only (no "2048"); extra fields: a newer writer may add some
    model_config = ConfigDict(strict=True, extra="allow")


class CardParams(_Model):
    """The parameters in the card the reader needs (the rest are kept as they are)."""

    n_points: PositiveInt
    samples_per_view: PositiveInt
    seed: NonNegativeInt
    sensor: str | None = None


class JoinedFile(_Model):
    """A file made from the shards for other readers (``generate --format h5``: PointNet's
    ``occluded_<split>.h5`` and ``<split>_files.txt``), with its SHA-256."""

    path: str
    sha256: str
    split: str


#: Where a card's objects were seen from (``visibility_from``): point-set inputs only, or both.
VISIBILITY_FROM = ("points", "points and meshes")


class PointSetCard(_Model):
    """The card's ``point_sets``: how the clouds of point-set files became objects (written only
    when the data set has some; :func:`zbuf_occlude.farm.journal.point_set_card`)."""

    #: Objects that are clouds of point-set files, and how many of them had normals in their file.
    n_objects: NonNegativeInt
    n_with_normals: NonNegativeInt
    #: The registered visibility method of their poses (``"point-splat"``) and its settings.
    visibility: str
    settings: dict[str, float | int]
    #: What each object's dense cloud is, and the ``face_index`` of its samples.
    dense_cloud: str
    face_index: int

    @model_validator(mode="after")
    def _counts(self) -> PointSetCard:
        if self.n_with_normals > self.n_objects:
            raise ValueError("n_with_normals exceeds n_objects")
        return self


class Card(_Model):
    """``dataset_card.json``."""

    format_version: NonNegativeInt = 0
    storage: str
    params: CardParams
    #: ``(elevation_deg, azimuth_deg)`` of every pose, degrees.
    poses: list[tuple[float, float]]
    splits: list[str] | None = None
    shape_names: list[str] | None = None
    #: ``"sha256"``: every file of every finished object has its checksum in the manifest.
    checksums: str | None = None
    #: Files joined from the shards (PointNet's layout), each with its SHA-256; ``None``: none.
    joined_files: list[JoinedFile] | None = None
    #: ``"points"``: every object is a cloud of a point-set file, its visibility decided from its
    #: points; ``"points and meshes"``: some are; ``None``: every object is a mesh.
    visibility_from: Literal[VISIBILITY_FROM] | None = None
    #: How the point-set objects were made (:class:`PointSetCard`); ``None``: there are none.
    point_sets: PointSetCard | None = None

    @model_validator(mode="after")
    def _point_sets_said(self) -> Card:
        if (self.visibility_from is None) != (self.point_sets is None):
            raise ValueError("'visibility_from' and 'point_sets' go together: both or neither")
        return self


class ManifestRecord(_Model):
    """Any line of ``manifest.jsonl``: only the status decides what else it must hold."""

    status: str


class ObjectRecord(_Model):
    """One object's record, ``records/<index>.json`` and a line of ``manifest.jsonl``: what the farm's
    worker writes (:func:`zbuf_occlude.farm.worker.process_object`, every field, nothing else) and
    what readers check (:class:`OkRecord`)."""

    # the writer's model: a field the worker writes must be declared here
    model_config = ConfigDict(strict=True, extra="forbid")

    object_index: NonNegativeInt
    name: str
    source: str
    class_name: str
    label: NonNegativeInt
    split: str
    #: The object's seed key (:func:`zbuf_occlude.geometry.samples.object_key`).
    key: int
    seed: NonNegativeInt
    params_digest: str
    #: ``"pending"`` while it renders, then ``"ok"`` or ``"failed"`` (with ``error``).
    status: str
    error: str | None
    #: Shard files, relative to the data set folder, and their SHA-256 (parallel lists).
    shards: list[str]
    sha256: list[Sha256] | None
    #: Distinct visible points per pose: visible dense points plus top-up points (``farm --sensor``: returns per scan).
    n_visible: list[NonNegativeInt]
    n_samples: NonNegativeInt
    bytes: NonNegativeInt
    #: Per-point columns its shard keeps beside ``data`` (``farm --sensor`` with a sensor that records
    #: several returns per pulse: :data:`~zbuf_occlude.dataset.layout.POINT_COLUMNS`); ``None``: none.
    point_columns: list[str] | None = None
    #: Poses with ``0 < n_visible < n_points`` (their samples repeat points), dense points, faces.
    n_padded_poses: NonNegativeInt | None = None
    #: Per pose, how many of its ``n_visible`` points were topped up on the faces it sees
    #: (:func:`zbuf_occlude.geometry.samples.top_up`); ``None``: none (``--sensor``, older writers).
    n_topped_up: list[NonNegativeInt] | None = None
    n_dense: NonNegativeInt | None = None
    n_faces: NonNegativeInt | None = None
    #: The up axis the mesh was read with (``+x`` … ``-z``) and why (the file, the layout, or the option).
    up: str | None = None
    up_source: str | None = None
    #: A cloud of a point-set file: its row there; its visibility method (``"point-splat"``),
    #: ``visibility_from`` ``"points"``, and whether the file's normals were used (else they were
    #: estimated from the points).  ``None``: a mesh.
    cloud: NonNegativeInt | None = None
    visibility: str | None = None
    visibility_from: Literal["points"] | None = None
    normals: bool | None = None
    #: Wall seconds, when it finished (ISO 8601, UTC), the OpenGL renderer, the process.
    time_s: float | None = None
    finished_at: str | None = None
    renderer: str | None = None
    #: The machine's name: written by earlier versions only (a data set names no machine), still read.
    host: str | None = None
    pid: int | None = None
    peak_rss_mb: float | None = None

    @field_validator("point_columns")
    @classmethod
    def _known_columns(cls, names: list[str] | None) -> list[str] | None:
        unknown = [name for name in names or () if name not in POINT_COLUMNS]
        if unknown:
            raise ValueError(f"{len(unknown):,} per-point column(s) this zbuf_occlude does not read; it reads {tuple(POINT_COLUMNS)}")
        if names is not None and len(set(names)) != len(names):
            raise ValueError("a per-point column is named twice")
        return names


class OkRecord(ObjectRecord):
    """A line of ``manifest.jsonl`` whose object finished (``status == "ok"``), as readers check it:
    the fields they need (a newer writer may add more)."""

    model_config = ConfigDict(strict=True, extra="allow")

    seed: NonNegativeInt | None = None
    params_digest: str | None = None
    error: str | None = None
    shards: list[str] = Field(min_length=1)
    #: ``None``: missing (readable only with ``verify=False``).
    sha256: list[Sha256] | None = None
    n_samples: NonNegativeInt | None = None
    bytes: NonNegativeInt | None = None

    @model_validator(mode="after")
    def _parallel(self) -> OkRecord:
        if self.sha256 is not None and len(self.sha256) != len(self.shards):
            raise ValueError(f"sha256 has {len(self.sha256)} entries for {len(self.shards)} shards")
        return self


class PlanObject(_Model):
    """One object of a farm's ``plan.json``."""

    index: NonNegativeInt
    name: str
    source: str
    class_name: str
    split: str
    label: NonNegativeInt
    #: A cloud of a point-set file: its row there (absent for a mesh).
    cloud: NonNegativeInt | None = None


class Plan(_Model):
    """A farm's ``plan.json`` (what ``farm-merge`` reads from each task folder)."""

    params: dict[str, Any]
    params_digest: str
    plan_digest: str
    source: str
    objects: list[PlanObject]


def describe_validation_error(exc: ValidationError) -> str:
    """``field 'params.n_points': Field required; ...`` for the first few problems."""
    errors = exc.errors(include_url=False)
    parts = []
    for e in errors[:MAX_LISTED]:
        loc = ".".join(
            x if isinstance(x, str) and x.isprintable() and len(x) <= KEY_CHARS else str(x) if isinstance(x, int) else "<a key>"
            for x in e["loc"]
        )  # keys of the file, cut; never a value
        # pydantic's words quote what is expected, never the input, but for a discriminator's tag
        msg = "its tag is none of those expected" if e["type"] == "union_tag_invalid" else e["msg"]
        parts.append(f"field {loc!r}: {msg}" if loc else msg)
    more = f"; and {len(errors) - MAX_LISTED} more" if len(errors) > MAX_LISTED else ""
    return "; ".join(parts) + more


def _read_text(path: Path, what: str, max_bytes: int) -> str:
    """The UTF-8 text of a data set's metadata file ``path`` (a regular file of at most ``max_bytes``,
    inside the data set's folder once links are resolved: :func:`~zbuf_occlude.io.regular_files.read_text_file`)."""
    if not path.exists():
        raise DatasetFormatError(f"{path} is missing: this data set has no {what}")
    return read_text_file(path, max_bytes=max_bytes, error=DatasetFormatError, within=path.parent)


def read_card(path: Path) -> tuple[dict[str, Any], Card]:
    """The card as a dict and as a checked :class:`Card`.

    Raises
    ------
    DatasetFormatError
        Unreadable, not JSON, or a field missing or of the wrong type (named).
    """
    text = _read_text(path, "card", MAX_METADATA_BYTES)
    try:
        card = Card.model_validate_json(text)
    except ValidationError as exc:
        raise DatasetFormatError(f"{path} is not a valid data set card: {describe_validation_error(exc)}") from None
    return loads_json(text, what=str(path)), card


def card_sha256_line(digest: str) -> str:
    """The line of :data:`~zbuf_occlude.dataset.layout.CARD_SHA256_FILE` for a card of SHA-256 ``digest``."""
    return f"{digest}  {CARD_FILE}\n"


def check_card_sha256(root: Path) -> bool:
    """Check the card of data set ``root`` against its SHA-256 file.

    Returns
    -------
    bool
        True when it matches; False when there is no SHA-256 file (a data set written
        before the card had one: it still reads, ``verify`` says so).

    Raises
    ------
    DatasetFormatError
        The SHA-256 file is unreadable or malformed, or the card differs from it (edited
        after it was written: its sizes, ``n_points`` included, cannot be trusted).
    """
    from zbuf_occlude.io.atomic import file_sha256

    sidecar = root / CARD_SHA256_FILE
    if not sidecar.exists():
        return False
    text = _read_text(sidecar, "card checksum", MAX_CARD_CHECKSUM_BYTES)
    digest = text.split(" ", 1)[0]
    if text != card_sha256_line(digest) or len(digest) != 64:
        raise DatasetFormatError(f"{sidecar} is not a SHA-256 line for {CARD_FILE} ('<64 hex digits>  {CARD_FILE}')")
    try:
        actual = file_sha256(root / CARD_FILE)
    except OSError as exc:
        raise DatasetFormatError(f"cannot read {root / CARD_FILE}: {exc}") from None
    if actual != digest:
        raise DatasetFormatError(
            f"{root / CARD_FILE} differs from its SHA-256 in {CARD_SHA256_FILE} (changed after it was written); "
            "its parameters cannot be trusted: get the data set again from its source"
        )
    return True


def read_manifest(path: Path, problems: list[str] | None = None) -> list[tuple[int, dict[str, Any], OkRecord | None]]:
    """``(line number, record dict, checked record or None)`` per non-empty line.

    The checked record is an :class:`OkRecord` for ``status == "ok"``, ``None`` for the
    others (failed or pending objects, which the reader skips).  With ``problems``, a bad
    line is appended there (and left out) instead of raising.

    The file is read one line at a time (never whole, nor as a list of its lines), after its size
    is checked against :data:`~zbuf_occlude.io.caps.MAX_MANIFEST_BYTES` and the memory its records will take
    (:data:`MANIFEST_MEMORY_PER_BYTE`) against the memory available.

    Raises
    ------
    DatasetFormatError
        Unreadable, larger than :data:`~zbuf_occlude.io.caps.MAX_MANIFEST_BYTES`, a line that is not UTF-8 or not a JSON
        object, or an ``ok`` line with a missing or mistyped field (the message names the line
        and the field).
    InsufficientMemoryError
        Its records would take more memory than is available (names the manifest).
    UnsafePathError
        It leads outside the data set's folder through a link.
    """
    if not path.exists():
        raise DatasetFormatError(f"{path} is missing: this data set has no manifest")
    fh, size = open_regular_file(path, max_bytes=MAX_MANIFEST_BYTES, error=DatasetFormatError, within=path.parent)
    rows = []
    with fh:
        check_memory(
            size * MANIFEST_MEMORY_PER_BYTE,
            f"the manifest {path} ({size:,} bytes)",
            hint="open it on a machine with more memory, or check where the data set comes from",
        )
        read = 0
        for lineno, raw in enumerate(fh, start=1):  # one line held at a time
            read += len(raw)
            if read > MAX_MANIFEST_BYTES:  # it grew since it was opened
                raise DatasetFormatError(f"{path}: more than the {MAX_MANIFEST_BYTES:,} bytes a manifest of ours holds; refused")
            where = f"{path}:{lineno}"
            try:
                line = raw.decode("utf-8")
                if not line.strip():
                    continue
                status = ManifestRecord.model_validate_json(line).status
                ok = OkRecord.model_validate_json(line) if status == "ok" else None
            except UnicodeDecodeError as exc:
                message = f"{where}: not UTF-8 text (byte {exc.start} of the line); the data set is damaged: get it again from its source"
            except ValidationError as exc:
                message = (
                    f"{where} is not a valid manifest record: {describe_validation_error(exc)}; the data set is damaged: "
                    "rerun the farm command (it rewrites the manifest from the records)"
                )
            else:
                rows.append((lineno, loads_json(line, what=where), ok))
                continue
            if problems is None:
                raise DatasetFormatError(message) from None
            problems.append(message)
    return rows


def read_shape_names(root: Path, card: Card) -> list[str]:
    """``shape_names.txt``: line i is the class name of label i (checked against the card).

    Raises
    ------
    DatasetFormatError
        Missing or unreadable, a name with a control character, or names that differ
        from the card's ``shape_names``.
    """
    path = root / SHAPE_NAMES_FILE
    text = _read_text(path, "class names", MAX_LIST_BYTES)
    # split on "\n" only: str.splitlines would also split on \x85, \u2028, ... inside a name
    names = text.split("\n")
    if names and names[-1] == "":
        names.pop()
    for i, name in enumerate(names):
        bad = control_character(name)
        if bad is not None or not name:
            raise DatasetFormatError(
                f"{path}:{i + 1}: the class name is empty or holds the control character "
                f"U+{ord(bad or chr(0)):04X}; the label -> name mapping cannot be trusted"
            )
    if card.shape_names is not None and names != card.shape_names:
        raise DatasetFormatError(
            f"{path} does not match the field 'shape_names' of the card ({len(names):,} names and {len(card.shape_names):,})"
        )
    return names


def check_records(
    manifest: Path,
    rows: list[tuple[int, dict[str, Any], OkRecord | None]],
    card: Card,
    shape_names: list[str],
    problems: list[str] | None = None,
) -> None:
    """Cross-checks of the ``ok`` records against the card and the class names.

    With ``problems``, each problem is appended there instead of raising.

    Raises
    ------
    DatasetFormatError
        A label with no line in ``shape_names.txt`` (or another name there), or
        ``n_visible`` with another count than the card's poses (scans for ``--sensor``), or
        ``n_topped_up`` with another count than ``n_visible`` or an entry above its pose's, or
        ``point_columns`` where the card's storage keeps none, or
        point-set objects the card does not account for (:func:`check_point_set_records`).
    """
    n_poses = card.params.samples_per_view if card.params.sensor else len(card.poses)
    try:
        keeps_columns = storage_kind(card.storage, sensor=card.params.sensor is not None).keeps_point_columns
    except InvalidInputError:  # an unknown storage is refused where the card's storage is looked up
        keeps_columns = True
    check_point_set_records(manifest, rows, card, problems)
    for lineno, _, rec in rows:
        if rec is None:
            continue
        where = f"{manifest}:{lineno}"
        found = []
        if rec.label >= len(shape_names) or shape_names[rec.label] != rec.class_name:
            found.append(f"{where}: fields 'label' and 'class_name' do not match a line of {SHAPE_NAMES_FILE} ({len(shape_names)} names)")
        if len(rec.n_visible) != n_poses:
            found.append(
                f"{where}: field 'n_visible' has {len(rec.n_visible)} entries, the card has {n_poses} "
                f"{'scans' if card.params.sensor else 'poses'}"
            )
        topped = rec.n_topped_up
        if topped is not None and (len(topped) != len(rec.n_visible) or any(t > v for t, v in zip(topped, rec.n_visible))):
            found.append(
                f"{where}: field 'n_topped_up' ({len(topped)} entries) does not fit 'n_visible' ({len(rec.n_visible)} "
                "entries): one per pose, each at most the pose's visible points"
            )
        if rec.point_columns and not keeps_columns:
            found.append(f"{where}: field 'point_columns' names some, but the card's storage keeps no per-point columns")
        if found and problems is None:
            raise DatasetFormatError(found[0])
        (problems if problems is not None else []).extend(found)


def check_point_set_records(
    manifest: Path, rows: list[tuple[int, dict[str, Any], OkRecord | None]], card: Card, problems: list[str] | None = None
) -> None:
    """The clouds of point-set files among the manifest's objects against the card's ``point_sets``.

    Every line with a ``cloud`` (a point-set input, whatever its status) is counted in the card's
    ``point_sets.n_objects``; a finished one says ``visibility_from`` ``"points"`` and a mesh does
    not; the finished ones whose file gave normals are the card's ``n_with_normals``.  With
    ``problems``, each problem is appended there instead of raising.

    Raises
    ------
    DatasetFormatError
        A count or a record that does not fit the card (the message names the line or the field).
    """
    found = []
    for lineno, _doc, rec in rows:
        said = rec.visibility_from if rec is not None else None
        if rec is not None and (rec.cloud is not None) != (said == "points"):
            found.append(
                f"{manifest}:{lineno}: field 'visibility_from' is {'not ' if rec.cloud is not None else ''}\"points\" for "
                f"{'a cloud of a point-set file' if rec.cloud is not None else 'a mesh'} (field 'cloud')"
            )
    clouds = sum(isinstance(doc.get("cloud"), int) for _, doc, _ in rows)
    with_normals = sum(rec.normals is True for _, _, rec in rows if rec is not None and rec.cloud is not None)
    said_clouds = card.point_sets.n_objects if card.point_sets is not None else 0
    if clouds != said_clouds:
        found.append(
            f"{manifest}: {clouds} objects are clouds of point-set files (field 'cloud'), the card's field "
            "'point_sets' says another number; the data set was changed after it was written"
        )
    elif card.point_sets is not None and with_normals != card.point_sets.n_with_normals:
        found.append(
            f"{manifest}: {with_normals} finished clouds used their file's normals (field 'normals'), the card's field "
            "'point_sets.n_with_normals' says another number"
        )
    if found and problems is None:
        raise DatasetFormatError(found[0])
    (problems if problems is not None else []).extend(found)


def checked_shards(root: Path, where: str, rec: OkRecord, card: Card, *, verify: bool) -> tuple[list[Path], dict[Path, str]]:
    """The shards of an ``ok`` record, each inside ``root``, and their SHA-256 (none when not ``verify``).

    Parameters
    ----------
    where : str
        ``manifest.jsonl:LINE``, for messages.

    Raises
    ------
    UnsafePathError
        A shard path is absolute, has ``..`` or leads outside ``root``.
    DatasetFormatError
        ``verify`` and the record has no ``sha256``: a changed shard could not be noticed.
    """
    shards = [path_inside(root, rel, what=f"{where} field 'shards'", quoted=False) for rel in rec.shards]
    if not verify:
        return shards, {}
    if rec.sha256 is None:
        said = " although the card says every file has one (field 'checksums'): the manifest was altered" if card.checksums else ""
        raise DatasetFormatError(
            f"{where}: the object has no SHA-256 (field 'sha256'){said}; a changed shard could not be "
            "noticed. Check the data set's source, then open it with OccludedDataset(..., verify=False) if you trust it "
            "(`zbuf-occlude verify DIR` lists every problem)"
        )
    mismatch = size_mismatch(shards, rec.bytes)  # before any shard is hashed or opened
    if mismatch is not None:
        raise DatasetFormatError(f"{where}: {mismatch}; the data set was changed after it was written")
    return shards, dict(zip(shards, rec.sha256))


def check_declared_rows(kind: StorageKind, shards: Sequence[Path], rows: int, n_points: int, where: str) -> None:
    """Refuse a record that promises more samples than its shard can hold, before anything of their
    size is allocated (the reader's index of samples, ``verify``'s reads): the rule the reader and
    ``verify`` share.

    Parameters
    ----------
    kind : StorageKind
        The data set's; only a kind whose samples are stored rows (``stored_bytes_per_point`` > 0)
        bounds them by its shard's size.
    shards : sequence of Path
        The record's files (an HDF5 kind's: its one shard), inside the data set.
    rows : int
        Samples the record promises (its ``n_visible`` and the card's ``samples_per_view``).
    n_points : int
        Points per sample (the card's ``params.n_points``).
    where : str
        ``manifest.jsonl:LINE``, for messages.

    Raises
    ------
    DatasetFormatError
        ``rows * n_points * stored_bytes_per_point`` is more than the shard's size on disk (names
        the record, the shard and both numbers).
    """
    if not kind.stored_bytes_per_point or len(shards) != 1:
        return
    try:
        size = shards[0].stat().st_size
    except OSError:  # missing: refused where it is opened, with what is wrong with it
        return
    need = int(rows) * int(n_points) * kind.stored_bytes_per_point
    if need > size:
        raise DatasetFormatError(
            f"{where}: its object's {int(rows):,} samples of {int(n_points):,} points take {need:,} bytes, more than its shard "
            f"{shards[0]} holds ({size:,} bytes); the data set was changed after it was written: get it again from its source"
        )


def _shape(f: Any, key: str) -> tuple[int, ...] | None:
    item = f.get(key)
    return tuple(item.shape) if item is not None and hasattr(item, "shape") else None


def check_shard(
    f: Any,
    path: Path,
    *,
    storage: str,
    n_points: int,
    rows: int,
    n_poses: int,
    sensor: bool,
    topup_rows: int = 0,
    point_columns: Sequence[str] = (),
) -> None:
    """Check an open shard (``h5py.File``) against what the manifest says of its object.

    Parameters
    ----------
    rows : int
        Samples (dense) the manifest's ``n_visible`` implies for this object.
    n_poses : int
        Entries of the object's ``n_visible``.
    topup_rows : int
        Compact storage: top-up points of all poses, the sum of the manifest's ``n_topped_up``.
    point_columns : sequence of str
        The per-point columns the manifest's record declares (``point_columns``): each must be
        ``(rows, n_points)`` of its dtype in :data:`~zbuf_occlude.dataset.layout.POINT_COLUMNS`.

    Raises
    ------
    DatasetFormatError
        A dataset is missing or has the wrong shape (or dtype, for a per-point column), or the
        shard holds another number of rows (samples, or compact top-up points) than the manifest promises.
    InvalidInputError
        No storage kind is ``storage`` (:func:`~zbuf_occlude.dataset.storage.storage_kind`).
    """
    kind = storage_kind(storage, sensor=sensor)
    needed = kind.shard_datasets
    missing = [k for k in needed if _shape(f, k) is None]
    if missing:
        raise DatasetFormatError(f"the shard {path} has no dataset {', '.join(map(repr, missing))} ({storage} storage)")
    if kind.redraws:
        dense, bits = _shape(f, "dense_points"), _shape(f, "visible_bits")
        if len(dense) != 2 or dense[1] != 3 or bits != (n_poses, (dense[0] + 7) // 8):
            raise DatasetFormatError(
                f"the shard {path}: 'dense_points' {dense} and 'visible_bits' {bits} do not fit {n_poses} poses "
                "(expected (M, 3) and (poses, ceil(M / 8)))"
            )
        topup = _shape(f, "topup_points")
        if (topup or (0, 3)) != (int(topup_rows), 3):
            raise DatasetFormatError(
                f"the shard {path}: 'topup_points' has shape {topup}, the manifest's field 'n_topped_up' promises "
                f"({int(topup_rows)}, 3); the data set is damaged"
            )
        return
    data = _shape(f, "data")
    if len(data) != 3 or data[1:] != (n_points, 3):
        raise DatasetFormatError(f"the shard {path}: dataset 'data' has shape {data}, expected (B, {n_points}, 3)")
    # exactly: a shard declaring more rows than its object has would be read whole by to_arrays()
    wrong = [k for k in ("data", *(needed[1:])) if _shape(f, k)[0] != rows]
    if wrong:
        more = _shape(f, wrong[0])[0] > rows
        raise DatasetFormatError(
            f"the shard {path} holds {'more' if more else 'fewer'} rows in {', '.join(map(repr, wrong))} than the "
            f"manifest's field 'n_visible' promises ({rows} samples; {wrong[0]!r} declares {_shape(f, wrong[0])[0]}); "
            "the data set is damaged"
        )
    for name in point_columns:
        shape, dtype = _shape(f, name), POINT_COLUMNS[name].dtype
        if shape != (rows, n_points) or f[name].dtype != np.dtype(dtype):
            raise DatasetFormatError(
                f"the shard {path}: per-point column {name!r} is {'missing' if shape is None else f'{shape} {f[name].dtype}'}, "
                f"its record declares it ({rows}, {n_points}) {dtype}; the data set is damaged"
            )


#: :data:`~zbuf_occlude.dataset.layout.COLUMN_TYPES` as :class:`~zbuf_occlude.io.hdf5.Column`.
SHARD_COLUMNS = {name: Column(*spec) for name, spec in COLUMN_TYPES.items()}


def open_shard(
    path: Path,
    *,
    storage: str,
    n_points: int,
    rows: int,
    n_poses: int,
    sensor: bool,
    topup_rows: int = 0,
    point_columns: Sequence[str] = (),
) -> Any:
    """Open a shard for reading after every check that needs no data: the one door the reader
    and ``verify`` use.

    :func:`zbuf_occlude.io.hdf5.check_hdf5` against :data:`SHARD_COLUMNS` (data stored inside
    the file, no links, the schema's dtypes), :func:`check_shard` (datasets, shapes, rows), and
    the memory its datasets declare against the memory available
    (:func:`zbuf_occlude.resources.check_memory`), so that a small file declaring 2e7 rows is
    refused before it is read.  Parameters as :func:`check_shard`.

    Returns
    -------
    h5py.File
        Open for reading; the caller closes it.

    Raises
    ------
    DatasetFormatError
        Not HDF5, or any check of :func:`~zbuf_occlude.io.hdf5.check_hdf5` or :func:`check_shard`.
    InsufficientMemoryError
        Its datasets, read whole, would need more memory than is available (names the file).
    """
    f = open_hdf5(path, SHARD_COLUMNS)
    try:
        check_shard(
            f,
            path,
            storage=storage,
            n_points=n_points,
            rows=rows,
            n_poses=n_poses,
            sensor=sensor,
            topup_rows=topup_rows,
            point_columns=point_columns,
        )
        declared = sum(declared_nbytes(f[k]) for k in f.keys() if _shape(f, k) is not None)
        check_memory(declared, f"the shard {path}", hint="it declares datasets larger than the data set can hold")
    except BaseException:
        f.close()
        raise
    return f
