"""``zbuf-occlude export``: a data set in the layouts that whole families of networks read unchanged.

One function, :func:`export`, and one table of targets, :data:`TARGETS`: a target is one writer
module and one line here, which says what it reads (a farm or generate data set, or a
``generate --protocol`` folder) and which options it takes.  Every target writes through the
owned-folder layer (:mod:`zbuf_occlude.io.owned`) and streams the source one object at a time.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from zbuf_occlude.defaults import DEFAULT_SEED
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.exporters.label_sets import LABEL_SETS, label_set
from zbuf_occlude.io.owned import OwnedFolder

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

    ``open(source, label_set_name)`` reads and checks the source before ``--out`` is made (so a
    refusal makes nothing); ``write(folder, opened, seed=, list_prefix=)`` writes it and returns
    the files a user opens first and the samples per split.
    """

    summary: str
    names: tuple[str, ...]
    open: Callable[[Path, str], Any]
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
    from zbuf_occlude.dataset.reader import OccludedDataset
    from zbuf_occlude.mesh.discovery import SPLITS

    whole = OccludedDataset(source)
    labels_set = label_set(label_set_name, whole.shape_names)
    labels = labels_set.labels(whole.shape_names)
    splits = {s: OccludedDataset(source, split=s) for s in (whole.card.get("splits") or SPLITS)}
    return _Splits(splits, labels, labels_set.names, labels_set.name)


def _pointnet(folder: OwnedFolder, src: _Splits, *, seed: int | None, list_prefix: str | None) -> tuple[list[Path], dict[str, int]]:
    from zbuf_occlude.exporters.pointnet_h5 import write_pointnet_h5

    prefix = list_prefix if list_prefix is not None else f"data/{folder.root.resolve().name}"
    seed = DEFAULT_SEED if seed is None else seed
    return write_pointnet_h5(folder, src.splits, src.labels, src.names, seed=seed, list_prefix=prefix.rstrip("/")), src.samples


def _modelnet_txt(folder: OwnedFolder, src: _Splits, *, seed: int | None, list_prefix: str | None) -> tuple[list[Path], dict[str, int]]:
    from zbuf_occlude.exporters.modelnet_txt import write_modelnet_txt

    prefix = "modelnet10" if src.set_name == "modelnet10" else "modelnet40"
    return write_modelnet_txt(folder, src.splits, src.labels, src.names, prefix=prefix), src.samples


def _open_pcn(source: Path, label_set_name: str) -> Any:
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
                           _open_pcn, _pcn, protocol="pcn", label_sets=("own", "shapenet55"), unit="model"),
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

    Parameters
    ----------
    dataset : str or PathLike
        The source folder (a data set is checked as :class:`~zbuf_occlude.dataset.reader.OccludedDataset`
        checks it; a protocol folder as :func:`~zbuf_occlude.exporters.pcn.plan_pcn` does).
    to : str
        ``pointnet-h5``, ``modelnet-txt`` or ``pcn``.
    out : str or PathLike
        The export's folder (made; it holds only the export: a run replaces only its own files).
    label_set_name : {"own", "modelnet40", "modelnet10", "shapenet55"}
        Whose label ids to write (:mod:`zbuf_occlude.exporters.label_sets`).  ``pcn`` takes
        ``own`` (ShapeNet's synset id for a ShapeNet class, else the class name) or
        ``shapenet55`` (synset ids only: a class ShapeNet lacks is refused).
    seed : int, optional
        ``pointnet-h5`` only: seed of its shuffle across files (default ``DEFAULT_SEED``).
    list_prefix : str, optional
        ``pointnet-h5`` only: what the file lists' lines start with (default ``data/<out's name>``).

    Returns
    -------
    ExportResult
        ``samples``: samples per split (``pcn``: models per split).

    Raises
    ------
    InvalidInputError
        An unknown target or label set, a class the label set lacks, an option the target does
        not read, a source of the kind the target does not read, duplicate ``pcn`` model ids.
    DatasetFormatError, UnsafePathError, ShardChecksumError
        The source is damaged or altered (as the reader raises them).
    OutputError, DatasetBusy, UnsafePathError
        ``out`` cannot be written, is being written, or holds files that are not an export of ours.
    """
    if to not in TARGETS:
        raise InvalidInputError(f"--to must be one of {', '.join(TARGETS)}, got {to!r}")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise InvalidInputError(f"--seed must be a whole number >= 0, got {seed!r}")
    if list_prefix is not None and (not list_prefix.strip() or "\n" in list_prefix):
        raise InvalidInputError(f"--list-prefix must be a path on one line, got {list_prefix!r}")
    target = TARGETS[to]()
    _check_options(to, target, {"--seed": seed, "--list-prefix": list_prefix}, label_set_name)
    source = Path(dataset)
    _check_source(source, to, target)
    opened = target.open(source, label_set_name)
    out = Path(out)
    if out.resolve() == source.resolve() or source.resolve() in out.resolve().parents:
        raise InvalidInputError(f"--out {out} lies inside the data set {source}; choose a folder outside it")
    with OwnedFolder(out, names=target.names, what=f"the {to} export") as folder:
        files, samples = target.write(folder, opened, seed=seed, list_prefix=list_prefix)
    return ExportResult(out, to, samples, files, target.unit)
