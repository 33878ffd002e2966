"""``zbuf-occlude export``: a data set in the layouts that whole families of networks read unchanged.

One function, :func:`export`, and one table of targets, :data:`TARGETS`: a target is one module
(:mod:`.pointnet_h5`, :mod:`.modelnet_txt`, :mod:`.pcn`) holding its writer and its
:class:`~zbuf_occlude.exporters.base.Target`, and one entry here.  Every target writes through the
owned-folder layer (:mod:`zbuf_occlude.io.owned`), streams the source one object at a time, and
writes in the frame its network family trains in (+y up, :attr:`~.base.Target.up`) unless
``up`` says otherwise; ``export.json`` beside the files records the frame.

An export is a transaction as far as a folder allows: the arguments, the places (``out`` and the
source outside each other), the names that go on list lines and the *whole* source (every file's
SHA-256, every path) are checked before ``out`` is made; in ``out``, every file an earlier export
recorded is checked to be ours and unchanged before the first is written; once the export is
written, the files of an earlier export that this one did not write again are removed.

Every target writes xyz (and what it derives from xyz), as the networks that read it take it: a
``farm --sensor`` data set's per-point columns (its LiDAR return fields,
:data:`~zbuf_occlude.dataset.layout.POINT_COLUMNS`) are left out by design, since none of these
layouts has a place for them; the files are the same, byte for byte, as an export of the same points
without them.  Read them with ``OccludedDataset(..., features=...)``.

Errors name this module's parameters as a call would (``label_set_name='modelnet10'``); the CLI
names its flags.
"""

from __future__ import annotations

import json
import numbers
import os
import re
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.exporters import modelnet_txt, pcn, pointnet_h5
from zbuf_occlude.exporters.base import DATASET, OPTIONS, ExportOptions, Target, check_up, frame_of
from zbuf_occlude.exporters.label_sets import LABEL_SETS
from zbuf_occlude.geometry.arguments import described
from zbuf_occlude.geometry.sampling import check_seed
from zbuf_occlude.io.deletes import remove_empty_folders
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.io.safe_paths import control_character

__all__ = ["LABEL_SETS", "RECORD_FILE", "TARGETS", "ExportResult", "Target", "export"]

#: ``to``: every target, by name.  A target is added by one module and one entry here.
TARGETS: dict[str, Target] = {t.name: t for t in (pointnet_h5.TARGET, modelnet_txt.TARGET, pcn.TARGET)}
#: What every export writes beside its files: the target, the frame, the samples and how many data files.
RECORD_FILE = "export.json"


@dataclass(frozen=True)
class ExportResult:
    """What :func:`export` wrote.

    Attributes
    ----------
    out : Path
        The export's folder.
    target : str
    samples : dict of str to int
        Samples written per split (``unit`` each).
    files : list of Path
        The files a user opens first (class list, file lists, then :data:`RECORD_FILE`).
    unit : str
        What one of ``samples`` is: ``"sample"`` (a cloud), or ``"model"`` (``pcn``: an object's views and complete cloud).
    up : str
        The export's up axis (``"+y"``: the networks' own frame unless ``up`` chose another).
    frame : str
        The frame, in words (as :data:`RECORD_FILE` records it).
    data_files : int
        How many other files it wrote (the samples; the folder's ledger lists them with their SHA-256).
    """

    out: Path
    target: str
    samples: dict[str, int]
    files: list[Path]
    unit: str = "sample"
    up: str = "+y"
    frame: str = ""
    data_files: int = 0


def _check_options(to: str, target: Target, given: dict[str, object], label_set_name: str) -> None:
    """Refuse a parameter ``to`` does not take, naming the targets that take it."""
    for option, value in given.items():
        if value is not None and option not in target.options:
            takers = [f"to={name!r}" for name, t in TARGETS.items() if option in t.options]
            raise InvalidInputError(f"{option}={value!r} applies to {' and '.join(takers)}, not to to={to!r}; leave it out")
    if label_set_name not in target.label_sets:
        sets = " or ".join(f"label_set_name={s!r}" for s in target.label_sets)
        raise InvalidInputError(f"to={to!r} takes {sets}, not label_set_name={label_set_name!r}")


def _check_source(source: Path, to: str, target: Target) -> None:
    """Refuse a source of the other kind (a protocol folder for a data-set target, or the reverse) in one line."""
    from zbuf_occlude.dataset.layout import CARD_FILE
    from zbuf_occlude.dataset.verify import protocol_of

    protocol = None if (source / CARD_FILE).exists() else protocol_of(source)
    if target.protocol is DATASET and protocol is not None:
        readers = [f"to={name!r} (a --protocol {t.protocol} folder)" for name, t in TARGETS.items() if t.protocol]
        raise InvalidInputError(
            f"{source} is a `generate --protocol` folder (--protocol {protocol}), not the farm or generate data set to={to!r} reads; "
            f"export it with {', '.join(readers)}, or make a data set with `zbuf-occlude farm` or `generate` without --protocol"
        )
    if target.protocol is not DATASET and (source / CARD_FILE).exists():
        raise InvalidInputError(
            f"{source} is a farm or generate data set ({CARD_FILE}), which holds no complete clouds: to={to!r} reads "
            f"a `generate --protocol {target.protocol}` folder; run `zbuf-occlude generate MESHES --protocol {target.protocol} --out DIR`"
        )


def _check_kinds(dataset: object, to: object, out: object, label_set_name: object, seed: object, list_prefix: object) -> None:
    """Refuse an argument of the wrong kind before any is used."""
    for name, value in (("dataset", dataset), ("out", out)):
        if not isinstance(value, (str, os.PathLike)) or not isinstance(os.fspath(value), str):
            raise ArgumentTypeError(f"{name} must be a folder's path (str or os.PathLike), got {described(value)}")
        if not os.fspath(value).strip():
            raise InvalidInputError(f"{name}={os.fspath(value)!r}: name a folder")
    for name, value in (("to", to), ("label_set_name", label_set_name)):
        if not isinstance(value, str):
            raise ArgumentTypeError(f"{name} must be a str, got {described(value)}")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, numbers.Integral)):
        raise ArgumentTypeError(f"seed must be a whole number >= 0 or None, got {described(seed)}")
    if list_prefix is not None and not isinstance(list_prefix, str):
        raise ArgumentTypeError(f"list_prefix must be a str or None, got {described(list_prefix)}")


def _list_prefix(target: Target, out: Path, list_prefix: str | None) -> str | None:
    """The list files' prefix (default ``data/<out's name>``), refused if it would not stay on one line."""
    if "list_prefix" not in target.options:
        return list_prefix  # None: refused by _check_options otherwise
    if list_prefix is not None:
        bad = control_character(list_prefix)
        if not list_prefix.strip() or bad is not None:
            said = "is blank" if bad is None else f"holds the control character U+{ord(bad):04X}"
            raise InvalidInputError(f"list_prefix={list_prefix!r} {said}: it starts each line of the file lists; give a path on one line")
        return list_prefix
    name = out.resolve().name
    bad = control_character(name)
    if bad is not None:
        raise InvalidInputError(
            f"out={str(out)!r}: its name {name!r} holds the control character U+{ord(bad):04X}, and the file lists name each "
            "file by it (data/<out's name>/...): rename the folder, or give list_prefix"
        )
    return f"data/{name}"


def _check_places(source: Path, out: Path) -> None:
    """Refuse ``out`` inside the source, or the source inside ``out`` (links resolved)."""
    there, inside = source.resolve(), out.resolve()
    if inside == there or there in inside.parents:
        raise InvalidInputError(f"out={str(out)!r} lies inside the data set {source}; choose a folder outside it")
    if inside in there.parents:
        raise InvalidInputError(
            f"the data set {source} lies inside out={str(out)!r}: an export writes and deletes files there; "
            "move the data set out of it or choose another folder"
        )


def _remove_earlier(folder: OwnedFolder, earlier: list[str]) -> None:
    """Remove the files of an earlier export into ``folder`` that this one did not write (checked as ours
    and unchanged first), and the folders they leave empty."""
    stale = [rel for rel in earlier if rel not in folder.this_run]
    folder.delete(stale)
    for rel in stale:
        parent = PurePosixPath(rel).parent.as_posix()
        if parent != ".":
            remove_empty_folders(folder.root, parent)


def _checked_up(target: Target, up: object) -> str:
    return target.up if up is None else check_up(up)


def export(
    dataset: str | os.PathLike,
    to: str,
    out: str | os.PathLike,
    *,
    label_set_name: str = "own",
    seed: int | None = None,
    list_prefix: str | None = None,
    up: str | None = None,
    progress: bool = True,
) -> ExportResult:
    """Write the data set ``dataset`` into ``out`` in the layout of ``to`` (:data:`TARGETS`).

    Each target reads one kind of source: ``pointnet-h5`` and ``modelnet-txt`` a data set of
    ``farm`` (dense or compact) or ``generate`` (every format); ``pcn`` a ``generate --protocol
    pcn`` folder (:mod:`zbuf_occlude.exporters.pcn`).  A source of the other kind is refused in
    one line that names the targets that read it.

    Each target writes in the frame its networks train in: **+y up** for all three (PointNet's
    ``modelnet40_ply_hdf5_2048``, whose augmentation turns about y; the ModelNet text files;
    PCN), turned from the data set's +z up by ``(x, y, z) → (x, z, −y)``; ``up`` chooses
    another.  :data:`RECORD_FILE` records it beside the files, which the loaders read unchanged.

    The whole source is checked before ``out`` is made: a data set as ``zbuf-occlude verify``
    checks it (every file's SHA-256 and path), a protocol folder as :func:`~zbuf_occlude.exporters.pcn.plan_pcn`
    does; a refusal writes nothing.  An export into the folder of an earlier export replaces
    that export's files and removes those it does not write again (a split the source no longer
    has); files of ``out`` that no export of ours wrote are never touched.

    Parameters
    ----------
    dataset : str or PathLike
        The source folder (a data set is checked as :class:`~zbuf_occlude.dataset.reader.OccludedDataset`
        and :func:`~zbuf_occlude.dataset.verify.verify_dataset` check it; a protocol folder as
        :func:`~zbuf_occlude.exporters.pcn.plan_pcn` does).
    to : str
        ``pointnet-h5``, ``modelnet-txt`` or ``pcn``.
    out : str or PathLike
        The export's folder (made; it holds only the export: a run replaces only its own files),
        outside the source, and the source not inside it.
    label_set_name : {"own", "modelnet40", "modelnet10", "shapenet55"}
        Whose label ids to write (:mod:`zbuf_occlude.exporters.label_sets`).  ``pcn`` takes
        ``own`` (ShapeNet's synset id for a ShapeNet class, else the class name) or
        ``shapenet55`` (synset ids only: a class ShapeNet lacks is refused).
    seed : int, optional
        ``pointnet-h5`` only: seed of its shuffle across files, 0 to 2**63 - 1 (default ``DEFAULT_SEED``).
    list_prefix : str, optional
        ``pointnet-h5`` only: what the file lists' lines start with (default ``data/<out's name>``),
        one line: no control characters, in it or in the default's ``out`` name.
    up : {"+y", "+z", "-y", "+x", "-x", "-z"}, optional
        The axis that is the objects' up in the export (default: the target's, ``+y``).
    progress : bool
        A progress bar (or a line every 10 s in a log) on stderr while the samples are written.

    Returns
    -------
    ExportResult
        ``samples``: samples per split (``pcn``: models per split); ``up`` and ``frame``; ``data_files``.

    Raises
    ------
    ArgumentTypeError
        An argument of the wrong kind: ``dataset`` or ``out`` not a str or PathLike, ``to`` or
        ``label_set_name`` not a str, ``seed`` not an int, ``list_prefix`` not a str.
    InvalidInputError
        An unknown target, label set or ``up``, a class the label set lacks, a parameter the
        target does not take, a blank ``dataset`` or ``out``, a ``seed`` out of range, a blank
        ``list_prefix``, a control character in ``list_prefix`` (or in ``out``'s name where it
        is the default prefix), ``out`` inside the source or the source inside ``out``, a source
        of the kind the target does not read, duplicate ``pcn`` model ids.
    DatasetFormatError, UnsafePathError, ShardChecksumError
        The source is damaged or altered (any file: nothing is written), or a file of it leads
        outside it.
    InsufficientMemoryError
        The export's buffers (a split's shuffle, a ``pcn`` shard) would not fit in memory.
    OutputError, DatasetBusy, UnsafePathError
        ``out`` cannot be written, is being written, or holds files that are not an export of
        ours, or files of an earlier export that were changed since.
    """
    _check_kinds(dataset, to, out, label_set_name, seed, list_prefix)
    if to not in TARGETS:
        raise InvalidInputError(f"to={to!r}: give one of {', '.join(map(repr, TARGETS))}")
    seed = check_seed(seed, name="seed")
    target = TARGETS[to]
    _check_options(to, target, dict(zip(OPTIONS, (seed, list_prefix), strict=True)), label_set_name)
    up = _checked_up(target, up)
    source, out = Path(dataset), Path(out)
    list_prefix = _list_prefix(target, out, list_prefix)
    _check_source(source, to, target)
    _check_places(source, out)
    opened = target.read(source, label_set_name)  # the whole source, checked: nothing is made before
    names = (*target.file_names, re.escape(RECORD_FILE))
    with OwnedFolder(out, names=names, what=f"the {to} export") as folder:
        earlier = folder.written("|".join(f"(?:{n})" for n in names))
        folder.check_writable(earlier)  # what an earlier export wrote, ours and unchanged, before the first write
        written = target.write(folder, opened, ExportOptions(seed, list_prefix, up, bool(progress)))
        data_files = len(folder.this_run) - len(written.files)
        frame = frame_of(target, up)
        record = {"target": to, **frame, "label_set": label_set_name, "samples": written.samples, "data_files": data_files}
        files = [*written.files, folder.write_text(RECORD_FILE, json.dumps(record, indent=1, sort_keys=True) + "\n")]
        _remove_earlier(folder, earlier)
    return ExportResult(out, to, written.samples, files, target.unit, up, frame["frame"], data_files)
