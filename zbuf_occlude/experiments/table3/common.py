"""What both experiments of Table 3 share: their output files, the meshes they plan, and the farm run that renders them.

Every file goes through the output layer (:class:`~zbuf_occlude.io.owned.OwnedFolder`): the
output folder is held for the run, each name it writes (:data:`ELEVATION_OUTPUTS`,
:data:`AUGMENTATION_OUTPUTS`, :data:`COMBINED_OUTPUTS`) is checked before any work, and a file
is replaced only if a run of ours wrote it and it is unchanged since.  The data folder (``--data``,
default ``OUT/data``) is held apart while its own files are written (:data:`DATA_OUTPUTS`); the
farm's data set inside it (``dataset/``) is the farm's.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Sequence
from pathlib import Path

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.table3.config import Table3Config
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.io.regular_files import read_regular_file
from zbuf_occlude.io.tables import read_csv_rows
from zbuf_occlude.mesh.inputs.duplicates import dedupe_meshes

__all__ = [
    "CHECKPOINT_FILES", "AUGMENTATION_SETS", "ELEVATION_OUTPUTS", "AUGMENTATION_OUTPUTS", "COMBINED_OUTPUTS", "DATA_OUTPUTS",
    "owned_folder", "write_mesh_list", "number_rows", "plan_meshes", "render_meshes",
]  # fmt: skip

log = logging.getLogger(__name__)

#: The files of one training run, :data:`zbuf_occlude.learn.training.CHECKPOINT_FILES` (named here:
#: importing learn.training imports torch, which importing this module must not).
CHECKPOINT_FILES = ("last.pt", "best.pt", "history.json")
#: Table 3B's training sets: occluded (C1), complete (C2), both (C3); each trains in ``checkpoints/<set>/``.
AUGMENTATION_SETS = ("C1", "C2", "C3")
#: Every file ``experiment elevation`` writes in ``--out`` (:func:`run_elevation`).
ELEVATION_OUTPUTS = (
    "results.csv", "per_class.csv", "confusion.csv", "accuracy_vs_elevation.png", "run.json", "table.md",
    *(f"checkpoints/{name}" for name in CHECKPOINT_FILES),
)  # fmt: skip
#: Every file ``experiment augmentation`` writes in ``--out`` (:func:`run_augmentation`; ``test3.csv``
#: only with real scans).
AUGMENTATION_OUTPUTS = (
    "results.csv", "test3.csv", "augmentation.png", "run.json", "table.md",
    *(f"checkpoints/{s}/{name}" for s in AUGMENTATION_SETS for name in CHECKPOINT_FILES),
)  # fmt: skip
#: Every file :func:`combine_elevation` writes in its ``out``.
COMBINED_OUTPUTS = ("results.csv", "table.md", "accuracy_vs_elevation.png")
#: The files the experiments write in their data folder, beside the farm's data set ``dataset/``:
#: the farm's list of meshes and the cache of Fig. 12's curve.
DATA_OUTPUTS = ("meshes.txt", "visible_area.csv")


def owned_folder(folder: str | os.PathLike, names: Sequence[str], what: str, *, option: str = "--out") -> OwnedFolder:
    """``folder`` held for a run that writes exactly the files ``names`` (and the folders they lie in)."""
    subfolders = sorted({str(Path(n).parent) for n in names} - {"."})
    return OwnedFolder(folder, files=names, subfolders=subfolders, what=what, option=option)


def write_mesh_list(data_dir: Path, text: str) -> Path:
    """Write the farm's list of meshes, ``data_dir/meshes.txt``, through the data folder's layer.

    A list an earlier version wrote (no ledger then) is taken as ours when it holds exactly this
    run's meshes, so that a data folder shared across models is reused as before.
    """
    data = text.encode("utf-8")
    with owned_folder(data_dir, DATA_OUTPUTS, "the experiment's data folder", option="--data") as folder:
        path = folder.root / "meshes.txt"
        if (folder.recorded("meshes.txt") is None and path.is_file() and not path.is_symlink() and path.stat().st_size == len(data)
                and read_regular_file(path, max_bytes=len(data), within=folder.root) == data):  # fmt: skip
            folder.adopt(["meshes.txt"])
        return folder.write_text("meshes.txt", text)


def number_rows(path: Path, within: Path, *, text: Sequence[str] = ()) -> list[dict]:
    """The rows of a CSV table of ours (:func:`~zbuf_occlude.io.tables.read_csv_rows`, held inside
    ``within``), every column but those in ``text`` a float.

    Raises
    ------
    InvalidInputError
        The file cannot be read (a FIFO, past the cap, not CSV), or holds a value that is not a
        number; the message names it.
    UnsafePathError
        It leads outside ``within``.
    """
    rows = read_csv_rows(path, within=within)
    try:
        return [{k: (v if k in text else float(v)) for k, v in r.items()} for r in rows]
    except (TypeError, ValueError) as exc:  # a short or long row, a word where a number belongs
        raise InvalidInputError(f"{path}: not a table of ours, a value is not a number ({exc})") from None


def _natural(text: str) -> list:
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", text)]


def plan_meshes(root: str | os.PathLike, classes: Sequence[str] | None = None) -> list[dict]:
    """Meshes under ``root`` (ModelNet layout), content duplicates dropped, sorted.

    Returns
    -------
    list of dict
        ``path`` (absolute), ``class_name``, ``split`` (ModelNet's folder), ``name``.

    Raises
    ------
    InvalidInputError
        Nothing found, or an unknown class.
    """
    from zbuf_occlude.mesh.inputs.plan import discover_objects

    objs = discover_objects(root, classes=list(classes) if classes else None)
    by_path = {Path(o.source).resolve(): o for o in objs}
    kept, dropped = dedupe_meshes(sorted(by_path, key=lambda p: _natural(str(p))))
    for dup, orig in dropped:
        log.warning("dropping %s: same mesh as %s", dup, orig)
    rows = [{"path": str(p), "class_name": by_path[p].class_name, "split": by_path[p].split, "name": by_path[p].name}
            for p in kept]  # fmt: skip
    rows.sort(key=lambda r: _natural(r["name"]))
    return rows


def render_meshes(meshes: list[dict], data_dir: Path, views: str, config: Table3Config, progress: bool) -> Path:
    """Farm the meshes (compact storage) into ``data_dir`` (resumes; reuses a finished run)."""
    from zbuf_occlude.farm import FarmParams, RunOptions, run_farm

    list_file = write_mesh_list(data_dir, "".join(f"{m['path']} {m['class_name']} {m['split']}\n" for m in meshes))
    scale = config.scale_values
    params = FarmParams(views=views, samples_per_view=scale.samples_per_view, n_points=config.n_points,
                        dense_points=scale.dense_points, resolution=scale.resolution, seed=config.seed,
                        storage="compact", method=config.method)  # fmt: skip
    run_farm(list_file, data_dir / "dataset", params, RunOptions(progress=progress))
    return data_dir / "dataset"
