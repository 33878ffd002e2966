"""``zbuf-occlude export``: a data set in the layouts that whole families of networks read unchanged.

One function, :func:`export`, and one table of targets, :data:`TARGETS`: a target is one writer
module and one line here, which says what it reads (a farm or generate data set, or a
``generate --protocol`` folder) and which options it takes.  Every target writes through the
owned-folder layer (:mod:`zbuf_occlude.io.owned`) and streams the source one object at a time.

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
"""

from __future__ import annotations

import numbers
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from zbuf_occlude.defaults import DEFAULT_SEED
from zbuf_occlude.errors import ArgumentTypeError, DatasetFormatError, InvalidInputError
from zbuf_occlude.exporters.label_sets import LABEL_SETS, label_set
from zbuf_occlude.geometry.arguments import described
from zbuf_occlude.geometry.sampling import check_seed
from zbuf_occlude.io.owned import OwnedFolder, remove_empty_folders
from zbuf_occlude.io.safe_paths import control_character

__all__ = ["TARGETS", "LABEL_SETS", "ExportResult", "export"]


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
        The files a user opens first (class list, file lists); sample files are in the folder's ledger.
    unit : str
        What one of ``samples`` is: ``"sample"`` (a cloud), or ``"model"`` (``pcn``: an object's views and complete cloud).
    """

    out: Path
    target: str
    samples: dict[str, int]
    files: list[Path]
    unit: str = "sample"


#: What a target reads: a farm or generate data set (``None``), or a ``generate --protocol NAME`` folder (``NAME``).
DATASET = None
#: The options a target may read besides ``--to``, ``--out`` and ``--label-set`` (each refused by a target that does not).
OPTIONS = ("--seed", "--list-prefix")


@dataclass(frozen=True)
class _Target:
    """One ``--to``: what it writes, what it reads, which options it takes.

    ``read(source, label_set_name)`` reads and checks the whole source before ``--out`` is made
    (so a refusal makes nothing); ``write(folder, opened, seed=, list_prefix=)`` writes it and
    returns the files a user opens first and the samples per split.
    """

    summary: str
    names: tuple[str, ...]
    read: Callable[[Path, str], Any]
    write: Callable[..., tuple[list[Path], dict[str, int]]]
    protocol: str | None = DATASET
    options: tuple[str, ...] = ()
    label_sets: tuple[str, ...] = LABEL_SETS
    unit: str = "sample"


@dataclass(frozen=True)
class _Splits:
    """A farm or generate data set, opened: each split's reader and the label set's ids."""

    splits: dict[str, Any]
    labels: dict[str, int]
    names: tuple[str, ...]
    set_name: str

    @property
    def samples(self) -> dict[str, int]:
        return {s: len(ds) for s, ds in self.splits.items()}


def _open_dataset(source: Path, label_set_name: str) -> _Splits:
    """The data set's splits, once the whole data set passed :func:`~zbuf_occlude.dataset.verify.verify_dataset`."""
    from zbuf_occlude.dataset.reader import OccludedDataset
    from zbuf_occlude.mesh.discovery import SPLITS

    whole = OccludedDataset(source)
    labels_set = label_set(label_set_name, whole.shape_names)
    labels = labels_set.labels(whole.shape_names)
    # verify_dataset hashes every file once; the splits reuse that (``whole`` refused missing checksums)
    splits = {s: OccludedDataset(source, split=s, verify=False) for s in (whole.card.get("splits") or SPLITS)}
    _verify_whole(source)
    return _Splits(splits, labels, labels_set.names, labels_set.name)


def _verify_whole(source: Path) -> None:
    """Check every file of the data set (its SHA-256, its paths, what the reader would refuse in it) before anything is written.

    Raises
    ------
    DatasetFormatError
        The first problem :func:`~zbuf_occlude.dataset.verify.verify_dataset` found, and how many more.
    """
    from zbuf_occlude.dataset.verify import verify_dataset

    report = verify_dataset(source)
    if not report.ok:
        more = len(report.problems) - 1
        also = f" (and {more} more problems: `zbuf-occlude verify {source}` lists them)" if more else ""
        raise DatasetFormatError(f"nothing was exported: {report.problems[0]}{also}")


def _pointnet(folder: OwnedFolder, src: _Splits, *, seed: int | None, list_prefix: str | None) -> tuple[list[Path], dict[str, int]]:
    from zbuf_occlude.exporters.pointnet_h5 import write_pointnet_h5

    seed = DEFAULT_SEED if seed is None else seed
    prefix = str(list_prefix).rstrip("/")  # export() gives it (by default data/<out's name>), checked
    return write_pointnet_h5(folder, src.splits, src.labels, src.names, seed=seed, list_prefix=prefix), src.samples


def _modelnet_txt(folder: OwnedFolder, src: _Splits, *, seed: int | None, list_prefix: str | None) -> tuple[list[Path], dict[str, int]]:
    from zbuf_occlude.exporters.modelnet_txt import write_modelnet_txt

    prefix = "modelnet10" if src.set_name == "modelnet10" else "modelnet40"
    return write_modelnet_txt(folder, src.splits, src.labels, src.names, prefix=prefix), src.samples


def _read_pcn(source: Path, label_set_name: str) -> Any:
    from zbuf_occlude.exporters.pcn import plan_pcn

    return plan_pcn(source, label_set_name)


def _pcn(folder: OwnedFolder, plan: Any, *, seed: int | None, list_prefix: str | None) -> tuple[list[Path], dict[str, int]]:
    from zbuf_occlude.exporters.pcn import write_pcn

    return write_pcn(folder, plan), plan.samples


def _names(module: str) -> tuple[str, ...]:
    import importlib

    return importlib.import_module(f"zbuf_occlude.exporters.{module}").FILE_NAMES


#: ``--to``: each target's one line, the names it writes, what it reads and writes, and the options it takes.
TARGETS: dict[str, Callable[[], _Target]] = {
    "pointnet-h5": lambda: _Target("PointNet's modelnet40_ply_hdf5_2048 (PointNet, PointNet++ TF, DGCNN, PCT, PointMLP, CurveNet)",
                                   _names("pointnet_h5"), _open_dataset, _pointnet, options=OPTIONS),
    "modelnet-txt": lambda: _Target("Pointnet_Pointnet2_pytorch's modelnet40_normal_resampled", _names("modelnet_txt"),
                                    _open_dataset, _modelnet_txt),
    "pcn": lambda: _Target("PCN's completion layout, PCN.json and .pcd (PCN, PoinTr, SnowflakeNet, SeedFormer)", _names("pcn"),
                           _read_pcn, _pcn, protocol="pcn", label_sets=("own", "shapenet55"), unit="model"),
}  # fmt: skip


def _check_options(to: str, target: _Target, given: dict[str, object], label_set_name: str) -> None:
    """Refuse an option ``to`` does not read, naming the targets that do."""
    for option, value in given.items():
        if value is not None and option not in target.options:
            takers = [name for name, make in TARGETS.items() if option in make().options]
            raise InvalidInputError(f"{option} applies to --to {', '.join(takers)}, not to --to {to}; leave it out")
    if label_set_name not in target.label_sets:
        raise InvalidInputError(f"--to {to} takes --label-set {' or '.join(target.label_sets)}, not {label_set_name!r}")


def _check_source(source: Path, to: str, target: _Target) -> None:
    """Refuse a source of the other kind (a protocol folder for a data-set target, or the reverse) in one line."""
    from zbuf_occlude.dataset.layout import CARD_FILE
    from zbuf_occlude.dataset.verify import protocol_of

    protocol = None if (source / CARD_FILE).exists() else protocol_of(source)
    if target.protocol is DATASET and protocol is not None:
        readers = [f"--to {name} (a --protocol {t.protocol} folder)" for name, t in ((n, make()) for n, make in TARGETS.items()) if t.protocol]
        raise InvalidInputError(
            f"{source} is a `generate --protocol` folder (--protocol {protocol}), not the farm or generate data set --to {to} reads; "
            f"export it with {', '.join(readers)}, or make a data set with `zbuf-occlude farm` or `generate` without --protocol"
        )
    if target.protocol is not DATASET and (source / CARD_FILE).exists():
        raise InvalidInputError(
            f"{source} is a farm or generate data set ({CARD_FILE}), which holds no complete clouds: export --to {to} reads "
            f"a `generate --protocol {target.protocol}` folder; run `zbuf-occlude generate MESHES --protocol {target.protocol} --out DIR`"
        )


class _ExportFolder(OwnedFolder):
    """The export's folder (:class:`~zbuf_occlude.io.owned.OwnedFolder`), which also keeps the names
    this run wrote: an earlier export's other files are removed once the export is written."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.this_run: set[str] = set()

    @contextmanager
    def write(self, rel: str) -> Iterator[Path]:
        with super().write(rel) as tmp:
            yield tmp
        self.this_run.add(rel)


def _check_kinds(dataset: object, to: object, out: object, label_set_name: object, seed: object, list_prefix: object) -> None:
    """Refuse an argument of the wrong kind before any is used."""
    for name, value in (("dataset", dataset), ("out", out)):
        if not isinstance(value, (str, os.PathLike)) or not isinstance(os.fspath(value), str):
            raise ArgumentTypeError(f"{name} must be a folder's path (str or os.PathLike), got {described(value)}")
    for name, value in (("to", to), ("label_set_name", label_set_name)):
        if not isinstance(value, str):
            raise ArgumentTypeError(f"{name} must be a str, got {described(value)}")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, numbers.Integral)):
        raise ArgumentTypeError(f"seed must be a whole number >= 0 or None, got {described(seed)}")
    if list_prefix is not None and not isinstance(list_prefix, str):
        raise ArgumentTypeError(f"list_prefix must be a str or None, got {described(list_prefix)}")


def _list_prefix(target: _Target, out: Path, list_prefix: str | None) -> str | None:
    """The list files' prefix (default ``data/<out's name>``), refused if it would not stay on one line."""
    if "--list-prefix" not in target.options:
        return list_prefix  # None: refused by _check_options otherwise
    if list_prefix is not None:
        bad = control_character(list_prefix)
        if not list_prefix.strip() or bad is not None:
            said = "is blank" if bad is None else f"holds the control character U+{ord(bad):04X}"
            raise InvalidInputError(f"--list-prefix {list_prefix!r} {said}: it starts each line of the file lists; give a path on one line")
        return list_prefix
    name = out.resolve().name
    bad = control_character(name)
    if bad is not None:
        raise InvalidInputError(
            f"--out's name {name!r} holds the control character U+{ord(bad):04X}, and the file lists name each file "
            "by it (data/<--out's name>/...): rename the folder, or give --list-prefix"
        )
    return f"data/{name}"


def _check_places(source: Path, out: Path) -> None:
    """Refuse ``out`` inside the source, or the source inside ``out`` (links resolved)."""
    from zbuf_occlude.farm.ownership import check_inputs_outside_out

    there, inside = source.resolve(), out.resolve()
    if inside == there or there in inside.parents:
        raise InvalidInputError(f"--out {out} lies inside the data set {source}; choose a folder outside it")
    check_inputs_outside_out(out, [source])


def _remove_earlier(folder: _ExportFolder, earlier: list[str]) -> None:
    """Remove the files of an earlier export into ``folder`` that this one did not write (checked as ours
    and unchanged first), and the folders they leave empty."""
    stale = [rel for rel in earlier if rel not in folder.this_run]
    folder.delete(stale)
    for rel in stale:
        parent = PurePosixPath(rel).parent.as_posix()
        if parent != ".":
            remove_empty_folders(folder.root, parent)


def export(
    dataset: str | os.PathLike,
    to: str,
    out: str | os.PathLike,
    *,
    label_set_name: str = "own",
    seed: int | None = None,
    list_prefix: str | None = None,
) -> ExportResult:
    """Write the data set ``dataset`` into ``out`` in the layout of ``to`` (:data:`TARGETS`).

    Each target reads one kind of source: ``pointnet-h5`` and ``modelnet-txt`` a data set of
    ``farm`` (dense or compact) or ``generate`` (every format); ``pcn`` a ``generate --protocol
    pcn`` folder (:mod:`zbuf_occlude.exporters.pcn`).  A source of the other kind is refused in
    one line that names the targets that read it.

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

    Returns
    -------
    ExportResult
        ``samples``: samples per split (``pcn``: models per split).

    Raises
    ------
    ArgumentTypeError
        An argument of the wrong kind: ``dataset`` or ``out`` not a str or PathLike, ``to`` or
        ``label_set_name`` not a str, ``seed`` not an int, ``list_prefix`` not a str.
    InvalidInputError
        An unknown target or label set, a class the label set lacks, an option the target does
        not read, a blank ``dataset`` or ``out``, a ``seed`` out of range, a blank
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
    from zbuf_occlude.farm.checks import check_out_option

    _check_kinds(dataset, to, out, label_set_name, seed, list_prefix)
    if to not in TARGETS:
        raise InvalidInputError(f"--to must be one of {', '.join(TARGETS)}, got {to!r}")
    check_out_option(dataset, "DATASET")
    check_out_option(out, "--out")
    seed = check_seed(seed, name="--seed")
    target = TARGETS[to]()
    _check_options(to, target, {"--seed": seed, "--list-prefix": list_prefix}, label_set_name)
    source, out = Path(dataset), Path(out)
    list_prefix = _list_prefix(target, out, list_prefix)
    _check_source(source, to, target)
    _check_places(source, out)
    opened = target.read(source, label_set_name)  # the whole source, checked: nothing is made before
    with _ExportFolder(out, names=target.names, what=f"the {to} export") as folder:
        earlier = folder.written("|".join(f"(?:{n})" for n in target.names))
        folder.check_writable(earlier)  # what an earlier export wrote, ours and unchanged, before the first write
        files, samples = target.write(folder, opened, seed=seed, list_prefix=list_prefix)
        _remove_earlier(folder, earlier)
    return ExportResult(out, to, samples, files, target.unit)
