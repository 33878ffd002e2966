"""What the write layer may delete or replace in a user's folder, and the checks before it does.

The rules of :mod:`zbuf_occlude.io.owned`'s deletes, on their own:

* a file is deleted or replaced only under a name a run of its kind writes (``names``, full
  matches relative to the owned folder), inside that folder once links are resolved
  (:func:`~zbuf_occlude.io.safe_paths.path_inside`), and only if it is a regular file that a run
  of ours recorded (:class:`FileRecord`) and whose size and SHA-256 still match the record
  (:func:`check_deletable`);
* a name read from a file (a ledger, a record, a ``protocol.json``) is never deleted without
  these checks; every file of a delete is checked before the first goes (:func:`delete_recorded`);
* a dead writer's temporary is removed only where it names its writer and its target is a name
  of ours (:func:`remove_dead_temps`); folders are removed only when empty (``rmdir``).

A refusal is one line that names the file and says what to do
(:class:`~zbuf_occlude.errors.UnsafePathError`).  Callers import these names from here;
:mod:`zbuf_occlude.io.owned` uses them and does not re-export them.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from zbuf_occlude.errors import UnsafePathError
from zbuf_occlude.io.atomic import file_sha256, temp_is_orphan, temp_owner
from zbuf_occlude.io.safe_paths import path_inside

__all__ = [
    "FileRecord",
    "check_deletable",
    "check_own_name",
    "delete_checked",
    "delete_own_files",
    "delete_recorded",
    "name_allowed",
    "remove_dead_temps",
    "remove_empty_folders",
    "remove_empty_tree",
]


@dataclass(frozen=True)
class FileRecord:
    """What a run recorded of a file it wrote.

    Attributes
    ----------
    sha256 : str or None
        Hex SHA-256 of the file's bytes (``None``: a record of an older version, which names
        the file by a name only a run writes but kept no digest).
    size : int or None
        Its size in bytes (``None``: not recorded, as in a farm record of several files).
    """

    sha256: str | None
    size: int | None = None


def remove_dead_temps(folder: str | os.PathLike, targets: Iterable[str] | None = None, *, ours: Callable[[str], bool] | None = None) -> int:
    """Remove the temporary files of :func:`~zbuf_occlude.io.atomic.atomic_path` whose writer is
    gone (:func:`~zbuf_occlude.io.atomic.temp_is_orphan`); return how many.

    Parameters
    ----------
    folder : str or PathLike
        Where to look (not below it).
    targets : iterable of str, optional
        Only temporaries of these file names (a ``--shard`` task's own); default: all.
    ours : callable ``(file name) -> bool``, optional
        For a folder that is the user's (an owned folder's root, the folder of a named output
        file): only temporaries whose target passes it, and only those that name their writer
        (a ``.x.tmp`` of another program, or of a version that named no writer, is left alone).
        Default: the folder is ours (the farm's ``shards/``, ``records/``), every such temporary.
    """
    folder = Path(folder)
    if not folder.is_dir() or folder.is_symlink():
        return 0
    names = None if targets is None else set(targets)
    removed = 0
    for tmp in folder.glob(".*.tmp"):
        owner = temp_owner(tmp.name)
        if owner is None or (names is not None and owner.target not in names) or not temp_is_orphan(owner):
            continue
        if ours is not None and (owner.pid is None or not ours(owner.target)):
            continue
        if tmp.is_file() or tmp.is_symlink():
            tmp.unlink(missing_ok=True)
            removed += 1
    return removed


def remove_empty_folders(root: str | os.PathLike, rel: str, *, keep: Sequence[str] = ()) -> None:
    """Remove ``root/rel`` and its parents below ``root`` while they are empty folders, stopping
    at any name in ``keep`` (folders other writers may be writing into).  Nothing else goes:
    ``rmdir`` removes only an empty folder."""
    root = Path(root)
    for folder in (Path(rel), *list(Path(rel).parents)[:-1]):
        if str(folder) in keep:
            break
        path = root / folder
        if path.is_symlink() or not path.is_dir() or not Path(os.path.realpath(path)).is_relative_to(Path(os.path.realpath(root))):
            break
        try:
            path.rmdir()
        except OSError:
            break


def remove_empty_tree(folder: str | os.PathLike) -> bool:
    """Remove ``folder`` and the folders below it, deepest first, if no file or link lies anywhere
    in them (a refused run's own empty ``--out``); return whether it is gone.  ``rmdir`` removes
    only an empty folder, so anything written there keeps it."""
    folder = Path(folder)
    if not folder.is_dir() or folder.is_symlink():
        return False
    for below, _, _ in os.walk(folder, topdown=False):
        try:
            os.rmdir(below)
        except OSError:
            return False
    return True


def name_allowed(rel: str, names: Sequence[re.Pattern[str]]) -> bool:
    """True if ``rel`` (``/``-separated, relative to the owned folder) fully matches one of ``names``."""
    return any(p.fullmatch(rel) for p in names)


def check_deletable(
    root: str | os.PathLike, rel: object, names: Sequence[re.Pattern[str]], expected: FileRecord | None, what: str
) -> Path | None:
    """The path of ``root/rel`` once every check of :func:`delete_recorded` passes; ``None`` when
    there is nothing to delete.  Check every file first, then :func:`delete_checked` them.

    Raises
    ------
    UnsafePathError
        As :func:`delete_recorded`.
    """
    root = Path(root)
    if not isinstance(rel, str) or not name_allowed(rel, names):
        raise UnsafePathError(
            f"{what} names {rel!r} in {root}, which is no file a run of ours writes there; nothing was deleted: "
            "the record is not ours (a copied or edited data set) — delete the folder's files yourself, or choose another --out"
        )
    path = path_inside(root, rel, what=what)
    if not os.path.lexists(path):
        return None
    if path.is_symlink() or not path.is_file():
        raise UnsafePathError(
            f"{path} is a link or not a regular file, where a run of ours wrote a file; move it away, or choose another --out"
        )
    if expected is None:
        raise UnsafePathError(
            f"{path} was not recorded by a run of ours ({what}); it is left as it is: move it away, or choose another --out"
        )
    if expected.size is not None and path.stat().st_size != expected.size:
        raise UnsafePathError(
            f"{path} holds {path.stat().st_size:,} bytes where {what} says {expected.size:,}: it was changed since a run "
            "of ours wrote it, and is left as it is; move it away, or choose another --out"
        )
    if expected.sha256 is not None and file_sha256(path) != expected.sha256:
        raise UnsafePathError(
            f"{path} does not match its SHA-256 in {what}: it was changed since a run of ours wrote it, and is left "
            "as it is; move it away, or choose another --out"
        )
    return path


def delete_recorded(
    root: str | os.PathLike,
    files: Iterable[tuple[object, FileRecord | None]],
    *,
    names: Sequence[re.Pattern[str]],
    what: str,
) -> list[Path]:
    """Delete files a run of ours recorded, after checking every one of them.

    All are checked first, then deleted: a refusal deletes nothing.

    Parameters
    ----------
    root : str or PathLike
        The owned folder.
    files : iterable of (str, FileRecord or None)
        Each file's path relative to ``root``, as a record names it, and what was recorded of it.
    names : sequence of compiled patterns
        The names (relative to ``root``) a run of this kind writes; any other name is refused.
    what : str
        The record the names come from, for messages.

    Returns
    -------
    list of Path
        The files deleted (a missing file is skipped).

    Raises
    ------
    UnsafePathError
        A name a run of this kind does not write, one leading outside ``root``, a link or folder
        where a file is recorded, or a file whose size or SHA-256 differ from the record.
    """
    checked = [check_deletable(root, rel, names, rec, what) for rel, rec in files]
    return delete_checked(checked)


def check_own_name(root: str | os.PathLike, name: str, *, what: str) -> Path | None:
    """:func:`check_deletable` for a file of a fixed name of ours (``plan.json``, a card), a name
    the code gives, never one read from a file: it must be a regular file inside ``root``."""
    return check_deletable(root, name, [re.compile(re.escape(name))], FileRecord(None), what)


def delete_own_files(root: str | os.PathLike, names: Iterable[str], *, what: str) -> list[Path]:
    """Delete files of fixed names of ours (:func:`check_own_name`), all checked first."""
    return delete_checked([check_own_name(root, name, what=what) for name in names])


def delete_checked(paths: Iterable[Path | None]) -> list[Path]:
    """Delete the files :func:`check_deletable` returned (``None`` entries are skipped); return them."""
    deleted = []
    for path in paths:
        if path is not None:
            path.unlink(missing_ok=True)
            deleted.append(path)
    return deleted
