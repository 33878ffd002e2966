"""The files of ``experiment sim2real``: their names, the training sets' folders, and ``runs.jsonl``, what a rerun resumes from."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.sim2real.data import FITTED_SETS, OCCLUDED_POINTS, TRAINING_SETS
from zbuf_occlude.experiments.table3.common import CHECKPOINT_FILES
from zbuf_occlude.io.json_files import loads_json
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.io.caps import MAX_METADATA_BYTES
from zbuf_occlude.io.regular_files import read_text_file

__all__ = [
    "REAL_TO_REAL",
    "ALL_SCANS",
    "CHOSEN_ON_FIT_HALF",
    "MESH_SETS",
    "EVERY_SET",
    "SIM2REAL_FILES",
    "SIM2REAL_OUTPUTS",
    "set_folder",
    "confusion_name",
    "load_runs",
    "append_run",
]

#: Name of the real→real context row.
REAL_TO_REAL = "real→real"
#: The scores of the mesh-only sets on every real scan (the second column), from each score of the held-out half.
ALL_SCANS = {"all_scans_mean_class_accuracy": "mean_class_accuracy", "all_scans_overall_accuracy": "overall_accuracy"}
#: Name of the row that takes, per seed, the mesh-only set with the best fit-half validation score.
CHOSEN_ON_FIT_HALF = "chosen on fit half"


def set_folder(kind: str) -> str:
    """The folder of ``kind``'s checkpoints below ``checkpoints/`` (real→real: ``real_to_real``)."""
    return kind.replace("→", "_to_")


def confusion_name(kind: str) -> str:
    """The file of ``kind``'s confusion matrix, summed over seeds (``confusion_lidar_complete.csv``)."""
    return f"confusion_{kind.replace('→', '_to_').replace('+', '_')}.csv"


#: Every mesh-only set a run may train, in report order.
MESH_SETS = (*TRAINING_SETS, OCCLUDED_POINTS, *FITTED_SETS)
#: Every set a run may train, in report order: the mesh-only sets, real→real.
EVERY_SET = (*MESH_SETS, REAL_TO_REAL)
#: The files ``experiment sim2real`` writes at the top of ``--out`` (``fitted_sensor.json`` with
#: ``fit_sensor``, ``fitted_families.json`` with ``fit_families``; a ``confusion_<set>.csv`` per set trained).
SIM2REAL_FILES = (
    "settings.json", "fitted_sensor.json", "fitted_families.json", "real_split.csv", "runs.jsonl", "results.csv", "summary.csv",
    *(confusion_name(kind) for kind in EVERY_SET), "run.json", "table.md",
)  # fmt: skip
#: Every name it writes in ``--out`` (full-match regular expressions): :data:`SIM2REAL_FILES` and
#: the checkpoints of each training run, ``checkpoints/<set>/seed<N>/`` (:data:`~zbuf_occlude.experiments.table3.common.CHECKPOINT_FILES`).
_SET_FOLDERS = "|".join(re.escape(set_folder(kind)) for kind in EVERY_SET)
SIM2REAL_OUTPUTS = (
    *(re.escape(name) for name in SIM2REAL_FILES),
    rf"checkpoints/({_SET_FOLDERS})/seed\d+/({'|'.join(re.escape(name) for name in CHECKPOINT_FILES)})",
)


def load_runs(path: Path) -> dict:
    """The runs an earlier run of this folder recorded in ``runs.jsonl``, by ``(train_set, seed)``:
    a rerun resumes from them.  Read inside the output folder, as a regular file of at most
    :data:`~zbuf_occlude.io.caps.MAX_METADATA_BYTES`.

    Raises
    ------
    InvalidInputError
        ``runs.jsonl`` is not a regular file (a FIFO), too large, or a line is not a run of ours.
    UnsafePathError
        It is a link that leads out of the output folder.
    """
    done = {}
    if os.path.lexists(path):  # a FIFO or a link out of the folder is refused, not skipped
        for number, line in enumerate(read_text_file(path, max_bytes=MAX_METADATA_BYTES, within=path.parent).splitlines(), 1):
            if line.strip():
                r = loads_json(line, what=str(path))
                if not isinstance(r, dict) or not isinstance(r.get("train_set"), str) or not isinstance(r.get("seed"), int):
                    raise InvalidInputError(f"{path}: line {number} is not a run of ours (no train_set and seed)")
                done[(r["train_set"], r["seed"])] = r
    return done


def append_run(folder: OwnedFolder, done: dict, row: dict) -> None:
    done[(row["train_set"], row["seed"])] = row
    folder.write_text("runs.jsonl", "".join(json.dumps(r, default=float) + "\n" for r in done.values()))
