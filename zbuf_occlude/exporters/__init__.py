"""``zbuf-occlude export``: a data set in the layouts that whole families of networks read unchanged.

One function, :func:`export`, and one table of targets, :data:`TARGETS` (a target is one writer
module and one line here).  Every target writes through the owned-folder layer
(:mod:`zbuf_occlude.io.owned`) and streams the source one object at a time.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

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
        Samples written per split.
    files : list of Path
        The files a user opens first (class list, file lists); sample files are in the folder's ledger.
    """

    out: Path
    target: str
    samples: dict[str, int]
    files: list[Path]


@dataclass(frozen=True)
class _Target:
    summary: str
    names: tuple[str, ...]
    write: Callable[..., list[Path]]


def _pointnet(folder: OwnedFolder, splits, labels, names, *, seed: int, list_prefix: str | None, set_name: str) -> list[Path]:
    from zbuf_occlude.exporters.pointnet_h5 import write_pointnet_h5

    prefix = list_prefix if list_prefix is not None else f"data/{folder.root.resolve().name}"
    return write_pointnet_h5(folder, splits, labels, names, seed=seed, list_prefix=prefix.rstrip("/"))


def _modelnet_txt(folder: OwnedFolder, splits, labels, names, *, seed: int, list_prefix: str | None, set_name: str) -> list[Path]:
    from zbuf_occlude.exporters.modelnet_txt import write_modelnet_txt

    if list_prefix is not None:
        raise InvalidInputError("--list-prefix applies to --to pointnet-h5 (its file lists name paths); modelnet-txt's name ids")
    return write_modelnet_txt(folder, splits, labels, names, prefix="modelnet10" if set_name == "modelnet10" else "modelnet40")


def _names(module: str) -> tuple[str, ...]:
    import importlib

    return importlib.import_module(f"zbuf_occlude.exporters.{module}").FILE_NAMES


#: ``--to``: each target's one line, the names it writes and its writer.
TARGETS: dict[str, Callable[[], _Target]] = {
    "pointnet-h5": lambda: _Target("PointNet's modelnet40_ply_hdf5_2048 (PointNet, PointNet++ TF, DGCNN, PCT, PointMLP, CurveNet)",
                                   _names("pointnet_h5"), _pointnet),
    "modelnet-txt": lambda: _Target("Pointnet_Pointnet2_pytorch's modelnet40_normal_resampled", _names("modelnet_txt"), _modelnet_txt),
}  # fmt: skip


def export(
    dataset: str | os.PathLike,
    to: str,
    out: str | os.PathLike,
    *,
    label_set_name: str = "own",
    seed: int = 0,
    list_prefix: str | None = None,
) -> ExportResult:
    """Write the data set ``dataset`` (``farm`` dense or compact, ``generate`` in every format) into
    ``out`` in the layout of ``to`` (:data:`TARGETS`).

    Parameters
    ----------
    dataset : str or PathLike
        A data set folder (:class:`~zbuf_occlude.dataset.reader.OccludedDataset` reads it; it is
        checked as that reader checks it).
    to : str
        ``pointnet-h5`` or ``modelnet-txt``.
    out : str or PathLike
        The export's folder (made; it holds only the export: a run replaces only its own files).
    label_set_name : {"own", "modelnet40", "modelnet10", "shapenet55"}
        Whose label ids to write (:mod:`zbuf_occlude.exporters.label_sets`).
    seed : int
        Seed of ``pointnet-h5``'s shuffle across files.
    list_prefix : str, optional
        ``pointnet-h5``: what the file lists' lines start with (default ``data/<out's name>``).

    Returns
    -------
    ExportResult

    Raises
    ------
    InvalidInputError
        An unknown target or label set, a class the label set lacks, a bad option.
    DatasetFormatError, UnsafePathError, ShardChecksumError
        The source is damaged or altered (as the reader raises them).
    OutputError, DatasetBusy, UnsafePathError
        ``out`` cannot be written, is being written, or holds files that are not an export of ours.
    """
    from zbuf_occlude.dataset.reader import OccludedDataset
    from zbuf_occlude.mesh.discovery import SPLITS

    if to not in TARGETS:
        raise InvalidInputError(f"--to must be one of {', '.join(TARGETS)}, got {to!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InvalidInputError(f"--seed must be a whole number >= 0, got {seed!r}")
    if list_prefix is not None and (not list_prefix.strip() or "\n" in list_prefix):
        raise InvalidInputError(f"--list-prefix must be a path on one line, got {list_prefix!r}")
    target = TARGETS[to]()
    source = Path(dataset)
    whole = OccludedDataset(source)
    labels_set = label_set(label_set_name, whole.shape_names)
    labels = labels_set.labels(whole.shape_names)
    splits = {s: OccludedDataset(source, split=s) for s in (whole.card.get("splits") or SPLITS)}
    out = Path(out)
    if out.resolve() == source.resolve() or source.resolve() in out.resolve().parents:
        raise InvalidInputError(f"--out {out} lies inside the data set {source}; choose a folder outside it")
    with OwnedFolder(out, names=target.names, what=f"the {to} export") as folder:
        files = target.write(folder, splits, labels, labels_set.names, seed=seed, list_prefix=list_prefix, set_name=labels_set.name)
    return ExportResult(out, to, {s: len(ds) for s, ds in splits.items()}, files)
