"""What a run may replace or delete in its output folder: only what an earlier run of ours there wrote.

The rule, for ``farm``, ``generate`` and ``farm-merge`` (``--overwrite`` or not):

* An input (the folder or list file given, and every mesh it names) inside ``--out`` is refused
  before anything is touched: a run writes and deletes there.
* A folder that holds no earlier run of ours (no ``plan.json``) must hold none of the names a run
  writes (``shards/``, ``records/``, ``tasks/``, the card, manifest, ``shape_names.txt``, the file
  lists, ``generate``'s joined files and per-mesh folders); an empty folder of such a name is
  fine.  Otherwise the run is refused, naming the first such file: it is somebody else's (a
  PointNet download's ``shape_names.txt``, the user's own ``records/``).
* A ``plan.json`` that is not a plan of ours is such a foreign file too.
* ``--overwrite`` over an earlier run of ours deletes only the files that run recorded: each
  object's record and the files its record names, the object's shard, the plan, card, manifest,
  class names, file lists and joined files, and the task journal's own files.  Anything else
  under ``--out``, inside ``shards/`` or ``records/`` too, is left where it is.  A record may
  name only its own object's shard or sample files, each still matching its recorded SHA-256
  (:mod:`zbuf_occlude.io.owned`); every file is checked before the first is deleted.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from zbuf_occlude.dataset.layout import (
    CARD_FILE,
    CARD_SHA256_FILE,
    MANIFEST_FILE,
    PLAN_FILE,
    RECORD_DIR,
    SHAPE_NAMES_FILE,
    SHARD_DIR,
    TASK_DIR,
    file_list_name,
    split_file_name,
)
from zbuf_occlude.dataset.storage import STORAGE_KINDS, storage_kind
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.farm.config import record_path, shard_path
from zbuf_occlude.farm.journal import objects_of, read_json, read_plan
from zbuf_occlude.io.deletes import FileRecord, check_deletable, check_own_name, delete_checked, delete_own_files, remove_empty_folders
from zbuf_occlude.mesh.paths import SPLITS
from zbuf_occlude.mesh.inputs.plan import FarmObject

__all__ = ["check_inputs_outside_out", "check_no_foreign_files", "earlier_plan", "wipe_earlier_run", "written_names"]

#: Files of ``tasks/`` that a run writes (``task-I-of-N.json``, ``manifest-I-of-N.jsonl``); locks stay.
_TASK_FILE = re.compile(r"(task-\d+-of-\d+\.json|manifest-\d+-of-\d+\.jsonl)")
#: The lock files of ``--shard I/N`` tasks (zbuf_occlude.farm.lock), made before the plan is written.
_TASK_LOCK = re.compile(r"lock-\d+-of-\d+\.lock")


def check_inputs_outside_out(out: str | os.PathLike, inputs: Iterable[str | os.PathLike]) -> None:
    """Refuse an input (a mesh, a folder or list file of meshes) that lies inside ``out``, symlinks resolved.

    Raises
    ------
    InvalidInputError
        The first such input, named with ``out``.
    """
    target = Path(out).resolve()
    for source in inputs:
        path = Path(source).resolve()
        if path == target or target in path.parents:
            raise InvalidInputError(
                f"the input {source} lies inside --out {out}: a run writes and deletes files there; "
                "move the input out of it or choose another --out"
            )


def written_names(objects: Sequence[FarmObject] = (), storage: str | None = None) -> list[str]:
    """The names directly under the output folder that a run writes: the journal, the data set's
    files, and those the files of its storage take (:meth:`~zbuf_occlude.dataset.storage.StorageKind.top_names`:
    for ``generate --format npz|ply`` the first folder of each object's name).

    Raises
    ------
    InvalidInputError
        No storage kind is ``storage`` (:func:`~zbuf_occlude.dataset.storage.storage_kind`).
    """
    names = [SHARD_DIR, RECORD_DIR, TASK_DIR, CARD_FILE, CARD_SHA256_FILE, MANIFEST_FILE, SHAPE_NAMES_FILE]
    splits = sorted({*SPLITS, *(o.split for o in objects)})
    names += [file_list_name(s) for s in splits] + [split_file_name(s) for s in splits]
    if storage is not None:
        names += storage_kind(storage).top_names(o.name for o in objects)
    return names


def earlier_plan(out: Path) -> dict[str, Any] | None:
    """The plan of an earlier run of ours in ``out`` (``None`` if there is none).

    Raises
    ------
    InvalidInputError
        ``out/plan.json`` exists but is not a plan of ours: it is not ours to replace.
    """
    try:
        return read_plan(out)
    except InvalidInputError as exc:
        raise InvalidInputError(
            f"{out / PLAN_FILE} was not written by zbuf_occlude ({exc}); a run would replace it: move it away, or choose another --out"
        ) from None


def _holds_something(path: Path) -> bool:
    if not os.path.lexists(path):
        return False
    if path.is_dir() and not path.is_symlink():
        # the tasks of one array start together: their locks come before anybody's plan
        return any(not (path.name == TASK_DIR and _TASK_LOCK.fullmatch(p.name)) for p in path.iterdir())
    return True


def check_no_foreign_files(out: Path, objects: Sequence[FarmObject] = (), storage: str | None = None) -> None:
    """Refuse to write into a folder whose files of our names are not ours (module docstring).

    Raises
    ------
    InvalidInputError
        ``out`` holds no earlier run of ours but holds one of :func:`written_names` (the first
        is named), or its ``plan.json`` is not ours.
    """
    if earlier_plan(out) is not None:
        return
    for name in written_names(objects, storage):
        if _holds_something(out / name):
            what = "holds files that were" if (out / name).is_dir() else "was"
            raise InvalidInputError(
                f"{out / name} {what} not written by zbuf_occlude ({out} holds no earlier run: no {PLAN_FILE}), "
                "and a run would replace or delete it: move it away, or choose an empty --out"
            )


def _own_names(o: FarmObject) -> list[re.Pattern[str]]:
    """The only files an object's record may name: those a storage kind writes for it, its shard or
    ``generate``'s sample files of it (:meth:`~zbuf_occlude.dataset.storage.StorageKind.own_files`)."""
    patterns = dict.fromkeys(p for kind in STORAGE_KINDS.values() for p in kind.own_files(o.name, shard_path(o)))
    return [re.compile(p) for p in patterns]


def _record_files(out: Path, o: FarmObject) -> list[Path | None]:
    """The files of object ``o`` that ``--overwrite`` deletes, each checked (:func:`check_deletable`):
    those its record names (name, size and SHA-256 as recorded), its shard and its record."""
    where = record_path(out, o.index)
    what = f"the record {where}"
    rec = read_json(where, within=out)
    names = _own_names(o)
    shards = (rec or {}).get("shards")
    shards = shards if isinstance(shards, list) else []
    digests = (rec or {}).get("sha256")
    digests = digests if isinstance(digests, list) and len(digests) == len(shards) else [None] * len(shards)
    checked = [check_deletable(out, rel, names, FileRecord(d if isinstance(d, str) else None), what) for rel, d in zip(shards, digests)]
    if shard_path(o) not in shards:  # a shard written before its record, by a run stopped in between
        checked.append(check_deletable(out, shard_path(o), names, FileRecord(None), f"the shard of object {o.index}"))
    checked.append(check_own_name(out, os.path.relpath(where, out), what=f"the record of object {o.index}"))
    return checked


def wipe_earlier_run(out: Path, objects: Sequence[FarmObject] | None = None) -> None:
    """``--overwrite``: delete what the earlier run of ours in ``out`` recorded (module docstring).

    Every file is checked before any is deleted (:func:`~zbuf_occlude.io.deletes.check_deletable`):
    a record may name only its object's shard or sample files, inside ``out``, each still matching
    its recorded SHA-256; a refusal deletes nothing.

    Parameters
    ----------
    out : Path
        The output folder; nothing is deleted when it holds no plan of ours.
    objects : sequence of FarmObject, optional
        A ``--shard I/N`` task's objects: only theirs go, and the card (the data set is no longer
        finished).  Default: the whole earlier run.

    Raises
    ------
    InvalidInputError
        The earlier plan is not ours (:func:`earlier_plan`).
    UnsafePathError
        A record names a file that is not its object's, one outside ``out``, a link or folder, or
        a file changed since it was recorded; nothing was deleted.
    """
    plan = earlier_plan(out)
    if plan is None:
        return
    everything = objects is None
    doomed: list[Path | None] = []
    for o in objects_of(plan) if objects is None else objects:
        doomed += _record_files(out, o)
    fixed = [CARD_SHA256_FILE, CARD_FILE]  # names of our own, never read from a file
    if everything:
        tasks = out / TASK_DIR
        if tasks.is_dir() and not tasks.is_symlink():
            fixed += [f"{TASK_DIR}/{p.name}" for p in tasks.iterdir() if _TASK_FILE.fullmatch(p.name)]
        splits = {o.split for o in objects_of(plan)}
        fixed += [
            MANIFEST_FILE,
            SHAPE_NAMES_FILE,
            *(f for s in sorted({*SPLITS, *splits}) for f in (file_list_name(s), split_file_name(s))),
        ]
    doomed += [check_own_name(out, name, what="the earlier run") for name in fixed]
    delete_checked(doomed)
    for o in objects_of(plan) if objects is None else objects:
        remove_empty_folders(out, o.name, keep=(SHARD_DIR, RECORD_DIR))  # generate's per-mesh folders it emptied
    if not everything:
        return
    for name in (SHARD_DIR, RECORD_DIR, TASK_DIR):
        remove_empty_folders(out, name)
    delete_own_files(out, [PLAN_FILE], what="the earlier plan")
