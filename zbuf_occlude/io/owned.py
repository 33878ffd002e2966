"""The one way the package writes into, replaces in and deletes from a user's folder.

A folder a command writes (``--out``) is *owned* while the command runs: :class:`OwnedFolder`

* takes the folder's lock (:func:`zbuf_occlude.io.locks.acquire_lock`);
* checks the layout (:func:`check_layout`): no subfolder or file it writes leads out through a link;
* writes atomically (:func:`~zbuf_occlude.io.atomic.atomic_path`) and records each file it wrote
  in the folder's ledger (:data:`LEDGER_FILE`, one JSON line per file: its name, size and
  SHA-256), *before* the file takes its name, so a run killed at any instant leaves a ledger that
  names every file of ours;
* replaces or deletes only a file it recorded, whose size and SHA-256 still match, under a name
  a run of its kind writes (its ``names``); a name read from a file (a ledger, a record, a
  ``protocol.json``) is never deleted without these checks (:func:`delete_recorded`);
* removes the temporary files and locks that dead writers left (:func:`remove_dead_temps`).

The delete rules themselves (what may be deleted or replaced, and the checks before) live in
:mod:`zbuf_occlude.io.deletes`.

Many small files (a text file per sample) go through :meth:`OwnedFolder.write_many`, with the
same order per file at the cost of a few ``fsync`` calls per batch rather than two per file:
every temporary of a batch is complete and synced (together, on threads, which the file system
commits as one) before the batch's ledger lines are appended and synced in one write, and only
then do the files take their names; each folder they went into is synced once at the end.

A refusal is one line that names the file and says what to do
(:class:`~zbuf_occlude.errors.UnsafePathError` or :class:`~zbuf_occlude.errors.OutputError`).
The farm keeps its ledger in its per-object records (their SHA-256s) and takes task-scoped
locks, so it calls the same functions (:func:`~zbuf_occlude.io.locks.acquire_lock`, :func:`check_layout`,
:func:`delete_recorded`, :func:`remove_dead_temps`) rather than the class.  A test walks the
package's syntax trees: no other module unlinks, renames, replaces or removes a path.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import stat
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO

from zbuf_occlude.errors import InvalidInputError, OutputError, UnsafePathError
from zbuf_occlude.io.atomic import atomic_path, file_sha256, new_temp, raise_output_error, write_csv
from zbuf_occlude.io.caps import MAX_LEDGER_BYTES, MAX_LEDGER_LINE_BYTES
from zbuf_occlude.io.deletes import FileRecord, check_deletable, delete_recorded, name_allowed, remove_dead_temps
from zbuf_occlude.io.json_files import loads_json
from zbuf_occlude.io.locks import LOCK_FILE, acquire_lock
from zbuf_occlude.resources import check_memory
from zbuf_occlude.io.regular_files import open_regular_file
from zbuf_occlude.io.safe_paths import path_inside

__all__ = [
    "LEDGER_FILE",
    "BatchWriter",
    "OwnedFolder",
    "check_layout",
    "make_folder",
    "owned_file",
]

log = logging.getLogger(__name__)

#: The ledger: one JSON line per file written (``{"path", "size", "sha256"}``) or deleted
#: (``{"path", "deleted": true}``); the last line about a path holds.
LEDGER_FILE = ".zbuf_occlude-written.jsonl"
#: Bytes of memory the ledger's records take per byte of ledger read (a path, a SHA-256 and a
#: size per line become a dict entry and a FileRecord: 2.3x measured on 156-byte lines by
#: tracemalloc; shorter names cost more per byte), checked before the ledger is read.
LEDGER_MEMORY_PER_BYTE = 4
#: Files per batch of :meth:`OwnedFolder.write_many`: at most this many temporaries at once.
BATCH_FILES = 64
#: Threads that sync a batch's temporaries: concurrent fsyncs are committed together (ext4's
#: journal; 64 files of 150 kB: about 0.8 ms a file against 4 ms synced one after another).
_SYNC_THREADS = 8


def make_folder(folder: str | os.PathLike, *, option: str = "--out") -> Path:
    """Create ``folder`` (and its parents) and check it can be written.

    Raises
    ------
    OutputError
        It is a file, or it cannot be created or written (one line naming it and saying: choose
        a writable ``option``).
    """
    folder = Path(folder)
    if os.path.lexists(folder) and not folder.is_dir():
        raise OutputError(f"the output folder {folder} is a file, not a folder; choose another {option}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the output folder {folder}: {exc.strerror or exc}; choose a writable {option}") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"the output folder {folder} is not writable; choose a writable {option}")
    return folder


def check_layout(root: str | os.PathLike, names: Iterable[str] = ()) -> None:
    """Refuse a folder where a name a run writes or deletes (a subfolder, a file) leads out of it.

    Each of ``names`` must stay inside ``root`` once symlinks are resolved
    (:func:`~zbuf_occlude.io.safe_paths.path_inside`): a link to elsewhere is refused, not
    followed (``OUT/shards`` linked to another folder would have a run replace, or
    ``--overwrite`` delete, the files there).

    Raises
    ------
    UnsafePathError
        One of them leads outside ``root`` (the message names it and where it leads).
    """
    for name in names:
        path_inside(root, name, what=f"the output folder {root}")


@contextmanager
def owned_file(path: str | os.PathLike, *, option: str = "--out") -> Iterator[Path]:
    """Write one output file that a command names (``contact-sheet --out sheet.png``) through the
    layer: its folder is held (:class:`OwnedFolder`, with only this name), and the file is written
    atomically and recorded; an existing file of that name is replaced only if a run of ours wrote
    it and it is unchanged since.  Yields the temporary path to write.

    Raises
    ------
    OutputError, DatasetBusy, UnsafePathError
        As :class:`OwnedFolder` and :meth:`OwnedFolder.write`.
    """
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{option} {path} is a folder; name the file to write")
    with OwnedFolder(path.parent, files=[path.name], what=f"the file {path.name}", option=option) as folder:
        with folder.write(path.name) as tmp:
            yield tmp


class OwnedFolder:
    """An output folder held for one run: the lock, the layout, atomic recorded writes, checked deletes.

    Use it as a context manager; the module docstring states the rules.

    Parameters
    ----------
    root : str or PathLike
        The folder (created, with a one-line error when it cannot be).
    names : sequence of str
        Regular expressions (full match, ``/``-separated, relative to ``root``) of every file a
        run of this kind writes; nothing else is written, replaced or deleted.
    files : sequence of str
        File names the run writes, taken literally (beside ``names``).
    subfolders : sequence of str
        The folders below ``root`` it writes into (checked by :func:`check_layout`).
    what : str
        What the folder holds, for messages (``"the protocol run"``).
    option : str
        The option that named it, for messages.

    Raises
    ------
    OutputError, DatasetBusy, UnsafePathError
        On entering: the folder cannot be made, another live process holds it, or its layout
        leads out.
    """

    def __init__(self, root: str | os.PathLike, *, names: Sequence[str] = (), files: Sequence[str] = (),
                 subfolders: Sequence[str] = (), what: str = "the run", option: str = "--out"):  # fmt: skip
        self.root = Path(root)
        self.names = [re.compile(n) for n in (*names, *map(re.escape, files))]
        self.subfolders = tuple(subfolders)
        self.what = what
        self.option = option
        self._lock: Any = None
        self._ledger: dict[str, FileRecord] = {}
        #: The files this run wrote (:meth:`write`, :meth:`write_many`), relative to ``root``.
        self.this_run: set[str] = set()

    # -- holding ----------------------------------------------------------------------------
    def __enter__(self) -> OwnedFolder:
        make_folder(self.root, option=self.option)
        self._lock = acquire_lock(self.root / LOCK_FILE, f"{self.what} in {self.root}")
        try:
            check_layout(self.root, self.subfolders)
            self._ledger = self._read_ledger()
            for folder in self._written_folders():
                prefix = "" if folder == "." else f"{folder}/"
                remove_dead_temps(self.root / folder, ours=lambda name, prefix=prefix: name_allowed(prefix + name, self.names))
        except BaseException:
            self._lock.release()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self._lock.release()

    def _written_folders(self) -> list[str]:
        """Folders a dead writer of ours may have left a temporary in: the root, the declared
        subfolders, the root's folders one level down (a class folder) and every folder the
        ledger names, each inside ``root`` (links resolved)."""
        found = {".", *self.subfolders, *(Path(rel).parent.as_posix() for rel in self._ledger)}
        try:
            found.update(e.name for e in os.scandir(self.root) if e.is_dir(follow_symlinks=False))
        except OSError:
            pass
        folders = []
        for folder in sorted(found):
            try:
                path_inside(self.root, folder, what=f"the output folder {self.root}")
            except UnsafePathError:
                continue  # a folder that leads out is never cleaned
            folders.append(folder)
        return folders

    @property
    def ledger_path(self) -> Path:
        return self.root / LEDGER_FILE

    def _read_ledger(self) -> dict[str, FileRecord]:
        """The ledger's files; lines that are damaged or not ours (a torn last line) are skipped.

        Read in bounded memory: its size is checked before it is read (against
        :data:`~zbuf_occlude.io.caps.MAX_LEDGER_BYTES`, then the memory its records would take against the memory
        available), and line by line, each at most :data:`~zbuf_occlude.io.caps.MAX_LEDGER_LINE_BYTES` bytes held (a longer
        line, never one of ours, is skipped without being held whole).

        Raises
        ------
        UnsafePathError
            It is a link, not a regular file, has another name, or is larger than any ledger of ours.
        InsufficientMemoryError
            Its records would take more memory than is available (names the ledger).
        """
        ledger: dict[str, FileRecord] = {}
        path = self.ledger_path
        if not os.path.lexists(path):
            return ledger
        self._check_ledger_file(path)
        fh, size = open_regular_file(path, error=UnsafePathError)
        with fh:
            if size > MAX_LEDGER_BYTES:
                raise UnsafePathError(
                    f"{path}: {size:,} bytes, more than the {MAX_LEDGER_BYTES:,} a ledger of ours holds; it is damaged or "
                    f"not ours: move it away, or choose another {self.option}"
                )
            check_memory(
                size * LEDGER_MEMORY_PER_BYTE, f"the ledger {path} ({size:,} bytes)", hint=f"move it away, or choose another {self.option}"
            )
            for line in _bounded_lines(fh, MAX_LEDGER_LINE_BYTES):
                try:
                    entry = loads_json(line, what=str(path))
                except InvalidInputError:  # damaged, torn or nested past any line of ours
                    continue
                rel = entry.get("path") if isinstance(entry, dict) else None
                if not isinstance(rel, str):
                    continue
                if entry.get("deleted") is True:
                    ledger.pop(rel, None)
                elif isinstance(entry.get("sha256"), str) and isinstance(entry.get("size"), int):
                    ledger[rel] = FileRecord(entry["sha256"], entry["size"])
        return ledger

    def _check_ledger_file(self, path: Path) -> None:
        """Refuse a ledger that is a link, not a regular file, or has another name (a hard link):
        it is appended in place, so a second name would make us write into a file outside ``root``."""
        info = path.lstat()
        if stat.S_ISLNK(info.st_mode) or not stat.S_ISREG(info.st_mode):
            raise UnsafePathError(f"{path} is a link or not a file; move it away, or choose another {self.option}")
        if info.st_nlink > 1:
            raise UnsafePathError(
                f"{path} has {info.st_nlink} names (a hard link to a file elsewhere); it is appended in place, so it "
                f"is refused: move it away, or choose another {self.option}"
            )

    def _append(self, entry: dict[str, Any]) -> None:
        self._append_lines([entry])

    def _append_lines(self, entries: Sequence[dict[str, Any]]) -> None:
        """Append ``entries`` to the ledger, one JSON line each, in one write and one fsync."""
        line = "".join(json.dumps(entry, sort_keys=True) + "\n" for entry in entries).encode("utf-8")
        try:
            fd = os.open(self.ledger_path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o666)
            try:
                info = os.fstat(fd)
                if not stat.S_ISREG(info.st_mode) or info.st_nlink > 1:  # swapped in since it was read
                    raise UnsafePathError(f"{self.ledger_path} is not a file of one name; move it away, or choose another {self.option}")
                view = memoryview(line)
                while view:  # a regular file takes it at once, but write may take fewer bytes
                    view = view[os.write(fd, view) :]
                os.fsync(fd)
            finally:
                os.close(fd)
        except OSError as exc:
            raise OutputError(f"cannot write {self.ledger_path}: {exc.strerror or exc}; choose a writable {self.option}") from None

    # -- names ------------------------------------------------------------------------------
    def recorded(self, rel: str) -> FileRecord | None:
        """What the ledger says of ``root/rel`` (``None``: not a file of ours)."""
        return self._ledger.get(rel)

    def holds(self, rel: str) -> bool:
        """True if ``root/rel`` is a file of ours that is still as it was written (its size matches;
        the bytes are compared by :meth:`check_unchanged`)."""
        rec = self._ledger.get(rel)
        path = self.root / rel
        return rec is not None and path.is_file() and not path.is_symlink() and path.stat().st_size == rec.size

    def check_unchanged(self, rel: str) -> bool:
        """True if ``root/rel`` is a file of ours whose size and SHA-256 match the ledger."""
        return self.holds(rel) and file_sha256(self.root / rel) == self._ledger[rel].sha256

    def path(self, rel: str) -> Path:
        """``root/rel`` once ``rel`` is a name this kind of run writes and stays inside ``root``.

        Raises
        ------
        UnsafePathError
            Any other name.
        """
        if not name_allowed(rel, self.names):
            raise UnsafePathError(f"{rel!r} is no file {self.what} writes in {self.root}; refused")
        return path_inside(self.root, rel, what=f"{self.what} in {self.root}")

    def adopt(self, rels: Iterable[str]) -> None:
        """Record files of ``names`` that a run of ours wrote before the ledger existed (an earlier
        version's run, recognised by its own record), as they are now."""
        for rel in rels:
            path = self.path(rel)
            if rel not in self._ledger and path.is_file() and not path.is_symlink():
                rec = FileRecord(file_sha256(path), path.stat().st_size)
                self._append({"path": rel, "sha256": rec.sha256, "size": rec.size})
                self._ledger[rel] = rec

    # -- writing and deleting -----------------------------------------------------------------
    def _check_replaceable(self, rel: str, path: Path) -> None:
        if not os.path.lexists(path):
            return
        check_deletable(self.root, rel, self.names, self._ledger.get(rel), f"the ledger {self.ledger_path}")

    def check_writable(self, rels: Iterable[str]) -> None:
        """Check, before any work, that :meth:`write` may write each of ``rels`` (a refusal then writes nothing).

        Raises
        ------
        UnsafePathError
            As :meth:`write`: no name of this kind, or a file of that name that is not ours or
            was changed since.
        """
        for rel in rels:
            self._check_replaceable(rel, self.path(rel))

    @contextmanager
    def write(self, rel: str) -> Iterator[Path]:
        """Yield a temporary path; on success it is recorded in the ledger and renamed to ``root/rel``.

        Raises
        ------
        UnsafePathError
            ``rel`` is no name of this kind, or a file of that name exists that is not ours or was
            changed since (it is left as it is).
        OutputError
            The file cannot be written.
        """
        path = self.path(rel)
        self._check_replaceable(rel, path)

        def record(tmp: Path) -> None:
            rec = FileRecord(file_sha256(tmp), tmp.stat().st_size)
            self._append({"path": rel, "sha256": rec.sha256, "size": rec.size})
            self._ledger[rel] = rec

        with atomic_path(path, before_replace=record) as tmp:
            yield tmp
        self.this_run.add(rel)

    @contextmanager
    def write_many(self, *, batch_files: int = BATCH_FILES) -> Iterator[BatchWriter]:
        """Yield a :class:`BatchWriter` for many small files: each is checked and written as by
        :meth:`write`, and they are recorded and named ``batch_files`` at a time (module docstring).

        The files of a batch appear once it is complete: when the writer fills, and on leaving the
        block.  An error in the block (or in a write) removes the temporaries of the batch under
        way; the batches before it stay, recorded and named.  A run killed at any instant leaves
        no file of ours unrecorded and none torn under its name: before the ledger's lines only
        temporaries (removed by the next run's sweep, :func:`remove_dead_temps`), after them files
        recorded and not yet named, as :meth:`write` may.

        Raises
        ------
        UnsafePathError, OutputError
            As :meth:`write`; also a name written twice in one batch.
        """
        batch = BatchWriter(self, max(int(batch_files), 1))
        try:
            yield batch
            batch.flush()
        finally:
            batch.discard()  # after an error: the temporaries of the batch under way

    def write_text(self, rel: str, text: str) -> Path:
        """Write UTF-8 ``text`` to ``root/rel`` (:meth:`write`)."""
        with self.write(rel) as tmp:
            tmp.write_text(text, encoding="utf-8")
        return self.root / rel

    def write_bytes(self, rel: str, data: bytes) -> Path:
        """Write ``data`` to ``root/rel`` (:meth:`write`): an encoded array, a PNG
        (:mod:`zbuf_occlude.io.encodings`)."""
        with self.write(rel) as tmp:
            tmp.write_bytes(data)
        return self.root / rel

    def write_csv(self, rel: str, rows: Sequence[dict], fieldnames: Sequence[str] | None = None) -> Path:
        """Write dict rows as CSV to ``root/rel`` (:meth:`write`; columns as :func:`~zbuf_occlude.io.atomic.write_csv`)."""
        with self.write(rel) as tmp:
            write_csv(tmp, rows, fieldnames, atomic=False)
        return self.root / rel

    def delete(self, rels: Iterable[str]) -> list[Path]:
        """Delete files of ours (:func:`delete_recorded` against the ledger); a refusal deletes nothing."""
        rels = list(rels)
        deleted = delete_recorded(
            self.root, [(rel, self._ledger.get(rel)) for rel in rels], names=self.names, what=f"the ledger {self.ledger_path}"
        )
        for rel in rels:
            if rel in self._ledger and not os.path.lexists(self.root / rel):
                self._append({"path": rel, "deleted": True})
                del self._ledger[rel]
        return deleted

    def written(self, pattern: str | None = None) -> list[str]:
        """The ledger's files (those matching ``pattern`` when given), sorted."""
        rx = re.compile(pattern) if pattern is not None else None
        return sorted(r for r in self._ledger if rx is None or rx.fullmatch(r))


class BatchWriter:
    """The files of :meth:`OwnedFolder.write_many` under way: :meth:`write_bytes` adds one.

    Its temporaries are :func:`~zbuf_occlude.io.atomic.new_temp`'s, as :func:`~zbuf_occlude.io.atomic.atomic_path`'s
    (their writer in their name, for :func:`remove_dead_temps`), but synced once each, together, at :meth:`flush`:
    a file's sync before its rename would flush the disk's cache once a file.
    """

    def __init__(self, folder: OwnedFolder, batch_files: int):
        self._folder = folder
        self._batch_files = batch_files
        self._entries: dict[str, dict[str, Any]] = {}  # rel -> its ledger line, in the order written
        self._files: list[tuple[Path, Path]] = []  # (temporary, target)

    def write_bytes(self, rel: str, data: bytes) -> Path:
        """Write ``data`` to ``root/rel`` with the batch; return that path (the file takes its name
        once the batch is flushed).

        Raises
        ------
        UnsafePathError
            As :meth:`OwnedFolder.write`, or ``rel`` is already in this batch.
        OutputError
            The temporary cannot be written (the batch's temporaries are removed).
        """
        folder = self._folder
        path = folder.path(rel)
        if rel in self._entries:
            raise UnsafePathError(f"{rel!r} is written twice in one batch in {folder.root}; refused")
        folder._check_replaceable(rel, path)
        try:
            tmp = new_temp(path)
        except OutputError:
            self.discard()
            raise
        self._files.append((tmp, path))
        try:
            with os.fdopen(os.open(tmp, os.O_WRONLY | getattr(os, "O_NOFOLLOW", 0)), "wb") as fh:
                fh.write(data)
        except OSError as exc:
            self.discard()
            raise_output_error(path, exc)
        self._entries[rel] = {"path": rel, "sha256": hashlib.sha256(data).hexdigest(), "size": len(data)}
        if len(self._entries) >= self._batch_files:
            self.flush()
        return path

    def flush(self) -> None:
        """Sync the batch's temporaries, record them all, name them, and sync their folders."""
        if not self._entries:
            return
        folder = self._folder
        parents = sorted({path.parent for _, path in self._files})
        try:
            with ThreadPoolExecutor(min(_SYNC_THREADS, len(self._files)), thread_name_prefix="owned-sync") as pool:
                list(pool.map(_sync_file, [tmp for tmp, _ in self._files]))
            folder._append_lines(list(self._entries.values()))  # recorded before any takes its name
            for entry in self._entries.values():
                folder._ledger[entry["path"]] = FileRecord(entry["sha256"], entry["size"])
            for named, (tmp, path) in enumerate(self._files):
                try:
                    os.replace(tmp, path)
                except OSError as exc:
                    del self._files[:named]
                    raise_output_error(path, exc)
            self._files = []
            for parent in parents:
                _sync_file(parent)
        except BaseException:
            self.discard()
            raise
        folder.this_run.update(self._entries)
        self._entries = {}

    def discard(self) -> None:
        """Remove the temporaries of the batch under way (after an error)."""
        for tmp, _ in self._files:
            tmp.unlink(missing_ok=True)
        self._entries, self._files = {}, []


def _bounded_lines(fh: BinaryIO, max_line: int) -> Iterator[bytes]:
    """The lines of the open file ``fh`` of at most ``max_line`` bytes (newline included); longer
    lines are skipped, read ``max_line + 1`` bytes at a time, so no more than that is ever held."""
    while line := fh.readline(max_line + 1):
        if len(line) <= max_line:
            yield line
            continue
        while not line.endswith(b"\n") and (line := fh.readline(max_line + 1)):
            pass  # the rest of a line too long to be ours


def _sync_file(path: Path) -> None:
    """fsync a file or folder by path (a folder: the names it holds)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_DIRECTORY", 0) * path.is_dir())
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        os.fsync(fd)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
