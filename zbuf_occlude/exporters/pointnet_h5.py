"""``export --to pointnet-h5``: the ``modelnet40_ply_hdf5_2048`` layout of PointNet (Qi et al. 2017).

What charlesq34/pointnet's ``provider.py`` and ``train.py`` read, and after them PointNet++ (TF),
DGCNN (``glob(ply_data_%s*.h5)``), PCT, PointMLP and CurveNet:

* ``ply_data_<split><k>.h5``: ``data (m, P, 3) float32`` and ``label (m, 1) uint8`` (``uint16``
  above 256 classes), at most :data:`ROWS_PER_FILE` rows a file.  The rows of every class are
  shuffled across the files with ``seed``: PointNet shuffles only inside a file, so files of one
  class would give batches of one class;
* ``ply_data_<split>_<k>_id2file.json``: each row's mesh and view (``<name>/vPPP_sSS``);
* ``shape_names.txt``: the label set's class names, one per label;
* ``<split>_files.txt``: one line per file, ``<list prefix>/ply_data_<split><k>.h5``, relative to
  the client repository's root as PointNet's are (default prefix ``data/<folder's name>``).

The set is streamed: each object's samples are read once, in the source's order, and written to
the rows the shuffle gave them, so memory holds one object's samples, not the set's.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from zbuf_occlude.io.owned import OwnedFolder

__all__ = ["ROWS_PER_FILE", "FILE_NAMES", "write_pointnet_h5"]

#: Rows per file, as ``modelnet40_ply_hdf5_2048``'s (its last file of a split holds the rest).
ROWS_PER_FILE = 2048
#: Files open at once while rows are scattered; a larger split is written in passes over the source.
MAX_OPEN_FILES = 256
#: The names this target writes (regular expressions, for the owned folder).
FILE_NAMES = (r"ply_data_[a-z]+\d+\.h5", r"ply_data_[a-z]+_\d+_id2file\.json", r"shape_names\.txt", r"[a-z]+_files\.txt")


def _label_dtype(n_classes: int) -> np.dtype:
    return np.dtype(np.uint8 if n_classes <= 256 else np.uint16)


def write_pointnet_h5(
    folder: OwnedFolder,
    splits: Mapping[str, object],
    labels: Mapping[str, int],
    names: Sequence[str],
    *,
    seed: int,
    list_prefix: str,
    rows_per_file: int | None = None,
) -> list[Path]:
    """Write each split of ``splits`` (:class:`~zbuf_occlude.dataset.reader.OccludedDataset` per split) in PointNet's layout.

    Parameters
    ----------
    folder : OwnedFolder
        The export's folder, held.
    splits : mapping of str to OccludedDataset
        The source's samples of each split (an empty one gets an empty file list).
    labels : mapping of str to int
        The label of each class name (:meth:`~zbuf_occlude.exporters.label_sets.LabelSet.labels`).
    names : sequence of str
        The label set's class names (``shape_names.txt``).
    seed : int
        Seed of the shuffle (:func:`numpy.random.default_rng`; split ``k``-th gets ``(seed, k)``).
    list_prefix : str
        What each line of ``<split>_files.txt`` starts with.
    rows_per_file : int, optional
        Rows per file (default :data:`ROWS_PER_FILE`).

    Returns
    -------
    list of Path
        The class list and the file lists (the data files are in the folder's ledger).
    """
    import h5py

    rows_per_file = ROWS_PER_FILE if rows_per_file is None else int(rows_per_file)
    written = [folder.write_text("shape_names.txt", "".join(f"{n}\n" for n in names))]
    dtype = _label_dtype(len(names))
    for k, (split, ds) in enumerate(sorted(splits.items())):
        n = len(ds)
        n_files = -(-n // rows_per_file)
        order = np.random.default_rng([seed, k]).permutation(n)  # row order[j] of the output is sample j's...
        position = np.empty(n, dtype=np.int64)
        position[order] = np.arange(n)  # ... sample i goes to output row position[i]
        label_of = np.array([labels[c] for c in ds.shape_names], dtype=np.int64) if n else np.zeros(0, np.int64)
        all_labels = label_of[ds.labels] if n else np.zeros(0, np.int64)
        files = [f"ply_data_{split}{f}.h5" for f in range(n_files)]
        for first in range(0, n_files, MAX_OPEN_FILES):
            group = range(first, min(first + MAX_OPEN_FILES, n_files))
            with contextlib.ExitStack() as stack:
                data = {}
                for f in group:
                    tmp = stack.enter_context(folder.write(files[f]))
                    h5 = stack.enter_context(h5py.File(tmp, "w"))
                    rows = min(rows_per_file, n - f * rows_per_file)
                    data[f] = h5.create_dataset("data", (rows, ds.n_points, 3), dtype=np.float32)
                    mine = order[f * rows_per_file : f * rows_per_file + rows]
                    h5.create_dataset("label", data=all_labels[mine].astype(dtype)[:, None])
                for start, block in ds.iter_arrays():
                    where = position[start : start + len(block)]
                    file_of = where // rows_per_file
                    for f in np.unique(file_of):
                        if int(f) not in data:
                            continue
                        pick = np.flatnonzero(file_of == f)
                        rows = where[pick] - f * rows_per_file
                        sort = np.argsort(rows)
                        data[int(f)][rows[sort]] = block[pick[sort]]  # h5py writes rows in increasing order
        for f in range(n_files):
            mine = order[f * rows_per_file : (f + 1) * rows_per_file]
            ids = []
            for i in mine:
                meta = ds.metadata(int(i))
                ids.append(f"{meta['name']}/v{meta['pose_index']:03d}_s{meta['sample_index']:02d}")
            folder.write_text(f"ply_data_{split}_{f}_id2file.json", json.dumps(ids) + "\n")
        written.append(folder.write_text(f"{split}_files.txt", "".join(f"{list_prefix}/{name}\n" for name in files)))
    return written
