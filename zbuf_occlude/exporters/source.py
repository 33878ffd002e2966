"""The source of ``pointnet-h5`` and ``modelnet-txt``: a farm or generate data set, opened and checked whole."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from zbuf_occlude.errors import DatasetFormatError
from zbuf_occlude.exporters.label_sets import label_set

__all__ = ["Splits", "open_dataset", "sample_file"]


@dataclass(frozen=True)
class Splits:
    """A farm or generate data set, opened: each split's reader and the label set's ids.

    Attributes
    ----------
    splits : dict of str to OccludedDataset
    labels : dict of str to int
        The label of each of the data set's class names.
    names : tuple of str
        The label set's class names, in label order.
    set_name : str
        The label set's name.
    """

    splits: dict[str, Any]
    labels: dict[str, int]
    names: tuple[str, ...]
    set_name: str

    @property
    def samples(self) -> dict[str, int]:
        """Samples per split."""
        return {s: len(ds) for s, ds in self.splits.items()}


def open_dataset(source: Path, label_set_name: str) -> Splits:
    """The data set's splits, once the whole data set passed :func:`~zbuf_occlude.dataset.verify.verify_dataset`.

    Raises
    ------
    InvalidInputError
        An unknown label set, or a class the set lacks.
    DatasetFormatError
        The first problem :func:`~zbuf_occlude.dataset.verify.verify_dataset` found, and how many more.
    """
    from zbuf_occlude.dataset.reader import OccludedDataset
    from zbuf_occlude.mesh.paths import SPLITS

    whole = OccludedDataset(source)
    labels_set = label_set(label_set_name, whole.shape_names)
    labels = labels_set.labels(whole.shape_names)
    # verify_dataset hashes every file once; the splits reuse that (``whole`` refused missing checksums)
    splits = {s: OccludedDataset(source, split=s, verify=False) for s in (whole.card.get("splits") or SPLITS)}
    _verify_whole(source)
    return Splits(splits, labels, labels_set.names, labels_set.name)


def _verify_whole(source: Path) -> None:
    """Check every file of the data set (its SHA-256, its paths, what the reader would refuse in it) before anything is written."""
    from zbuf_occlude.dataset.verify import verify_dataset

    report = verify_dataset(source)
    if not report.ok:
        more = len(report.problems) - 1
        also = f" (and {more} more problems: `zbuf-occlude verify {source}` lists them)" if more else ""
        raise DatasetFormatError(f"nothing was exported: {report.problems[0]}{also}")


def sample_file(meta: dict) -> str:
    """Where a sample comes from, as the exports' id maps name it: ``<mesh name>/vPPP_sSS`` (its pose and sample index)."""
    return f"{meta['name']}/v{meta['pose_index']:03d}_s{meta['sample_index']:02d}"
