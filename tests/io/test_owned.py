"""The owned-folder layer on its own (zbuf_occlude.io.owned): what a run writes, records, replaces
and deletes in a user's folder, and what a hostile folder cannot make it do."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from zbuf_occlude.errors import DatasetBusy, OutputError, UnsafePathError
from zbuf_occlude.io.atomic import _host_tag, file_sha256
from zbuf_occlude.io.locks import LOCK_FILE
from zbuf_occlude.io.owned import LEDGER_FILE, OwnedFolder


def _ledger(root: Path) -> list[dict]:
    return [json.loads(line) for line in (root / LEDGER_FILE).read_text().splitlines()]


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_a_write_is_recorded_with_its_size_and_sha256_before_it_takes_its_name(tmp_path):
    with OwnedFolder(tmp_path, names=[r"a\.txt", r"cls/.*\.bin"]) as folder:
        folder.write_text("a.txt", "hello\n")
        folder.write_bytes("cls/x.bin", b"\x00\x01")
        assert folder.holds("a.txt") and folder.check_unchanged("cls/x.bin")
        assert folder.written() == ["a.txt", "cls/x.bin"] and folder.written(r"cls/.*") == ["cls/x.bin"]
    entries = {e["path"]: e for e in _ledger(tmp_path)}
    assert entries["a.txt"]["size"] == 6 and entries["a.txt"]["sha256"] == file_sha256(tmp_path / "a.txt")
    assert (tmp_path / "cls" / "x.bin").read_bytes() == b"\x00\x01"
    assert not (tmp_path / LOCK_FILE).exists()  # released on exit


def test_a_name_outside_the_kinds_names_is_refused_and_nothing_written(tmp_path):
    with OwnedFolder(tmp_path, names=[r"a\.txt"]) as folder:
        for rel in ("b.txt", "../a.txt", "/etc/a.txt", "sub/a.txt"):
            with pytest.raises(UnsafePathError):
                folder.write_text(rel, "x")
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no ledger line either: nothing was written


def test_a_users_file_is_never_replaced_or_deleted(tmp_path):
    (tmp_path / "a.txt").write_text("mine")
    with OwnedFolder(tmp_path, names=[r"a\.txt"]) as folder:
        with pytest.raises(UnsafePathError, match="a.txt"):
            folder.write_text("a.txt", "ours")
        with pytest.raises(UnsafePathError, match="a.txt"):
            folder.delete(["a.txt"])
    assert (tmp_path / "a.txt").read_text() == "mine"


def test_a_file_of_ours_changed_since_is_kept(tmp_path):
    with OwnedFolder(tmp_path, names=[r"a\.txt"]) as folder:
        folder.write_text("a.txt", "ours")
    (tmp_path / "a.txt").write_text("edited by the user")
    with OwnedFolder(tmp_path, names=[r"a\.txt"]) as folder:
        assert not folder.check_unchanged("a.txt")
        with pytest.raises(UnsafePathError):
            folder.delete(["a.txt"])
    assert (tmp_path / "a.txt").read_text() == "edited by the user"


def test_delete_removes_a_file_of_ours_and_records_it(tmp_path):
    with OwnedFolder(tmp_path, names=[r"a\.txt"]) as folder:
        folder.write_text("a.txt", "ours")
    with OwnedFolder(tmp_path, names=[r"a\.txt"]) as folder:
        assert folder.delete(["a.txt"]) == [tmp_path / "a.txt"]
        assert not folder.holds("a.txt")
    assert not (tmp_path / "a.txt").exists()
    assert _ledger(tmp_path)[-1] == {"deleted": True, "path": "a.txt"}
    with OwnedFolder(tmp_path, names=[r"a\.txt"]) as folder:  # the ledger read again agrees
        assert folder.written() == []


def test_a_second_writer_is_refused_while_the_first_holds_the_folder(tmp_path):
    with OwnedFolder(tmp_path, names=[r"a\.txt"]):
        with pytest.raises(DatasetBusy, match=str(os.getpid())):
            with OwnedFolder(tmp_path, names=[r"a\.txt"]):
                pass


@pytest.mark.parametrize("kind", ["fifo", "symlink", "folder"])
def test_a_lock_file_that_is_not_a_file_is_refused_without_blocking(tmp_path, kind):
    """A FIFO as the lock would block every command on the folder (reading it waits for a writer)."""
    lock = tmp_path / LOCK_FILE
    if kind == "fifo":
        os.mkfifo(lock)
    elif kind == "symlink":
        lock.symlink_to(tmp_path.parent / "elsewhere")
    else:
        lock.mkdir()
    with pytest.raises(UnsafePathError, match=rf"{LOCK_FILE} is a (FIFO|link|folder)"):
        with OwnedFolder(tmp_path, names=[r"a\.txt"]):
            pass


#: A size no lock or ledger of ours reaches, made cheaply as a sparse file (nothing is written).
HUGE_BYTES = 3 << 30

#: Run in a child under an address-space limit: enter an OwnedFolder on argv[1]; print the
#: refusal and exit 3, or print the files the ledger names.
_ENTER_FOLDER = """
import sys
from zbuf_occlude.errors import ZbufOccludeError
from zbuf_occlude.io.owned import OwnedFolder
try:
    with OwnedFolder(sys.argv[1], names=[r"a\\.txt"]) as folder:
        print(folder.written())
except ZbufOccludeError as exc:
    print(exc)
    sys.exit(3)
"""


def _enter_limited(folder: Path):
    from memory_limit import run_python_limited

    return run_python_limited(f"import sys; sys.argv[1:] = [{str(folder)!r}]\n" + _ENTER_FOLDER)


def _sparse(path: Path, size: int) -> None:
    with open(path, "wb") as fh:
        fh.truncate(size)


@pytest.mark.parametrize("kind", ["fifo", "huge"])
def test_a_fifo_or_huge_lock_is_refused_in_one_line_plainly_and_under_a_memory_limit(tmp_path, kind):
    """A 3 GB file at the lock's name is someone's data: refused, never read, never broken (deleted)."""
    lock = tmp_path / LOCK_FILE
    if kind == "fifo":
        os.mkfifo(lock)
    else:
        _sparse(lock, HUGE_BYTES)
    said = r"is a FIFO, not a lock of ours" if kind == "fifo" else rf"holds {HUGE_BYTES:,} bytes, more than the \d+ of a lock"
    with pytest.raises(UnsafePathError, match=rf"the lock file {lock} {said}.*move it away") as caught:
        with OwnedFolder(tmp_path, names=[r"a\.txt"]):
            pass
    assert "\n" not in str(caught.value)
    done = _enter_limited(tmp_path)
    assert done.returncode == 3, done.stderr
    assert len(done.stdout.splitlines()) == 1 and str(lock) in done.stdout and not done.stderr, done.stdout + done.stderr
    assert kind == "fifo" or lock.stat().st_size == HUGE_BYTES  # kept as it was
    assert not (tmp_path / "a.txt").exists()


def test_a_3_gb_ledger_is_refused_in_one_line_plainly_and_under_a_memory_limit(tmp_path):
    ledger = tmp_path / LEDGER_FILE
    _sparse(ledger, HUGE_BYTES)
    with pytest.raises(
        UnsafePathError, match=rf"{LEDGER_FILE}: {HUGE_BYTES:,} bytes, more than .* a ledger of ours.*move it away"
    ) as caught:
        with OwnedFolder(tmp_path, names=[r"a\.txt"]):
            pass
    assert "\n" not in str(caught.value)
    done = _enter_limited(tmp_path)
    assert done.returncode == 3 and not done.stderr, done.stderr
    assert len(done.stdout.splitlines()) == 1 and str(ledger) in done.stdout and "a ledger of ours" in done.stdout


def test_a_long_ledger_line_is_skipped_without_being_held(tmp_path):
    """A 100 MiB line (no line of ours passes 8 kB) is read past in bounded pieces; the lines after it hold."""
    with OwnedFolder(tmp_path, names=[r"a\.txt"]) as folder:
        folder.write_text("a.txt", "ours")
    ledger = tmp_path / LEDGER_FILE
    ours = ledger.read_bytes()
    long_line = 100 << 20
    _sparse(ledger, long_line)  # zeros, no newline
    with open(ledger, "ab") as fh:
        fh.write(b"\n" + ours)
    with OwnedFolder(tmp_path, names=[r"a\.txt"]) as folder:
        assert folder.written() == ["a.txt"] and folder.check_unchanged("a.txt")
    done = _enter_limited(tmp_path)
    assert done.returncode == 0 and done.stdout.strip() == "['a.txt']", done.stdout + done.stderr
    # the line held whole would map at least its 100 MiB above the interpreter's footprint
    assert done.peak_bytes - done.footprint_bytes < long_line // 2, done.summary()


def test_a_huge_lock_is_never_read_whole(tmp_path, monkeypatch):
    """The holder's text is read capped: a lock of a few MB is not a lock of ours."""
    import zbuf_occlude.io.locks as locks
    import zbuf_occlude.io.regular_files as regular_files

    reads = []
    real = regular_files.open_regular_file
    monkeypatch.setattr(regular_files, "open_regular_file", lambda *a, **k: reads.append(k.get("max_bytes")) or real(*a, **k))
    (tmp_path / LOCK_FILE).write_bytes(b"1\n" + b"x" * (4 << 20))
    assert locks._lock_holder(tmp_path / LOCK_FILE) == "a process that has just released it"
    assert reads == [locks.MAX_LOCK_BYTES]


def test_a_ledger_past_its_cap_is_refused_before_it_is_read(tmp_path, monkeypatch):
    import zbuf_occlude.io.owned as owned

    with OwnedFolder(tmp_path, names=[r"a\.txt"]) as folder:
        folder.write_text("a.txt", "ours")
    monkeypatch.setattr(owned, "MAX_LEDGER_BYTES", 10)
    with pytest.raises(UnsafePathError, match=rf"{LEDGER_FILE}: \d+ bytes, more than the 10"):
        with OwnedFolder(tmp_path, names=[r"a\.txt"]):
            pass


def test_a_hard_linked_ledger_is_refused_and_the_file_elsewhere_unchanged(tmp_path):
    """The ledger is appended in place: a second name would make us write outside --out."""
    outside = tmp_path / "outside.txt"
    outside.write_text("secret\n")
    out = tmp_path / "out"
    out.mkdir()
    os.link(outside, out / LEDGER_FILE)
    with pytest.raises(UnsafePathError, match="2 names"):
        with OwnedFolder(out, names=[r"a\.txt"]) as folder:
            folder.write_text("a.txt", "x")
    assert outside.read_text() == "secret\n" and not (out / "a.txt").exists()


@pytest.mark.parametrize("kind", ["symlink", "fifo"])
def test_a_ledger_that_is_a_link_or_fifo_is_refused(tmp_path, kind):
    ledger = tmp_path / LEDGER_FILE
    if kind == "symlink":
        (tmp_path / "elsewhere.jsonl").write_text("")
        ledger.symlink_to(tmp_path / "elsewhere.jsonl")
    else:
        os.mkfifo(ledger)
    with pytest.raises(UnsafePathError, match="link or not a file"):
        with OwnedFolder(tmp_path, names=[r"a\.txt"]):
            pass


def test_damaged_and_deeply_nested_ledger_lines_are_skipped_not_a_traceback(tmp_path):
    with OwnedFolder(tmp_path, names=[r"a\.txt", r"b\.txt"]) as folder:
        folder.write_text("a.txt", "ours")
    with open(tmp_path / LEDGER_FILE, "a") as fh:
        fh.write("[" * 4000 + "]" * 4000 + "\n")  # nested past the JSON reader's depth
        fh.write('{"path": "b.txt", "size": "x", "sha256": 1}\n')  # wrong kinds
        fh.write("not json\n" + '{"path": "b.txt", "sha2')  # a torn last line
    with OwnedFolder(tmp_path, names=[r"a\.txt", r"b\.txt"]) as folder:
        assert folder.written() == ["a.txt"] and folder.check_unchanged("a.txt")


def test_a_dead_writers_temporary_below_the_root_is_removed_and_others_kept(tmp_path):
    dead = f"{_dead_pid()}-{_host_tag()}-abc"
    (tmp_path / "cls").mkdir()
    ours = tmp_path / "cls" / f".x.txt.{dead}.tmp"
    theirs = tmp_path / "cls" / f".notes.md.{dead}.tmp"
    for path in (ours, theirs):
        path.write_text("x")
    with OwnedFolder(tmp_path, names=[r"cls/.*\.txt"]):
        pass
    assert not ours.exists() and theirs.exists()


def test_a_subfolder_that_leads_out_is_never_cleaned(tmp_path):
    dead = f"{_dead_pid()}-{_host_tag()}-abc"
    outside = tmp_path / "outside"
    outside.mkdir()
    tmp = outside / f".x.txt.{dead}.tmp"
    tmp.write_text("x")
    out = tmp_path / "out"
    out.mkdir()
    (out / "cls").symlink_to(outside)
    with OwnedFolder(out, names=[r"cls/.*\.txt"]):
        pass
    assert tmp.exists()


def test_a_folder_that_cannot_be_made_is_one_output_error(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="file"):
        with OwnedFolder(tmp_path / "file" / "out", names=[r"a\.txt"]):
            pass


def test_file_sha256_refuses_a_fifo_without_waiting_on_it(tmp_path):
    os.mkfifo(tmp_path / "pipe")
    with pytest.raises(OSError, match="not a regular file"):
        file_sha256(tmp_path / "pipe")
    (tmp_path / "f").write_bytes(b"abc")
    assert file_sha256(tmp_path / "f") == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"


# -- write_many: many small files, a few fsyncs a batch ----------------------------------------------


def test_a_batch_records_every_file_once_with_its_size_and_sha256(tmp_path):
    with OwnedFolder(tmp_path, names=[r"cls/x\d+\.txt"]) as folder:
        with folder.write_many(batch_files=4) as batch:
            for i in range(10):  # two full batches and one of two
                batch.write_bytes(f"cls/x{i}.txt", f"{i}\n".encode() * (i + 1))
        assert folder.written() == sorted(folder.this_run) == sorted(f"cls/x{i}.txt" for i in range(10))
        assert all(folder.check_unchanged(f"cls/x{i}.txt") for i in range(10))
    entries = _ledger(tmp_path)
    assert [e["path"] for e in entries] == [f"cls/x{i}.txt" for i in range(10)]  # one line a file, in order
    for e in entries:
        assert e["size"] == (tmp_path / e["path"]).stat().st_size and e["sha256"] == file_sha256(tmp_path / e["path"])
    assert sorted(p.name for p in (tmp_path / "cls").iterdir()) == sorted(f"x{i}.txt" for i in range(10))  # no temporary left


def test_a_batch_appends_its_ledger_lines_in_one_write_before_any_file_takes_its_name(tmp_path, monkeypatch):
    seen = []
    real_replace = os.replace

    def replace(src, dst):
        seen.append((Path(dst).name, len(_ledger(tmp_path))))
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    with OwnedFolder(tmp_path, names=[r"x\d\.txt"]) as folder, folder.write_many(batch_files=3) as batch:
        for i in range(5):
            batch.write_bytes(f"x{i}.txt", b"data")
    assert sorted(seen) == [("x0.txt", 3), ("x1.txt", 3), ("x2.txt", 3), ("x3.txt", 5), ("x4.txt", 5)]


def test_an_error_in_a_batch_keeps_the_batches_before_it_and_leaves_no_temporary(tmp_path):
    with OwnedFolder(tmp_path, names=[r"x\d\.txt"]) as folder:
        with pytest.raises(RuntimeError, match="boom"), folder.write_many(batch_files=2) as batch:
            for i in range(3):
                batch.write_bytes(f"x{i}.txt", b"data")
            raise RuntimeError("boom")
        assert folder.written() == ["x0.txt", "x1.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [LEDGER_FILE, "x0.txt", "x1.txt"]
    assert [e["path"] for e in _ledger(tmp_path)] == ["x0.txt", "x1.txt"]


def test_a_batch_killed_after_its_ledger_lines_is_cleaned_and_rewritten_by_the_next_run(tmp_path):
    # the writer dies between recording its batch and naming its files: recorded files that are
    # absent, and temporaries of a dead writer; the next run removes those and writes every file
    code = f"""
import os, sys
from zbuf_occlude.io.owned import OwnedFolder
real = os.replace
def die(src, dst):
    if os.path.basename(dst) == "x2.txt":
        os._exit(3)
    real(src, dst)
os.replace = die
with OwnedFolder({str(tmp_path)!r}, names=[r"x\\d\\.txt"]) as folder, folder.write_many(batch_files=4) as batch:
    for i in range(4):
        batch.write_bytes(f"x{{i}}.txt", b"first")
"""
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 3
    named = {p.name for p in tmp_path.iterdir() if not p.name.startswith(".")}
    recorded = {e["path"] for e in _ledger(tmp_path)}
    assert named <= recorded == {f"x{i}.txt" for i in range(4)}  # no file of ours unrecorded
    assert "x2.txt" not in named and any(p.name.endswith(".tmp") for p in tmp_path.iterdir())
    with OwnedFolder(tmp_path, names=[r"x\d\.txt"]) as folder, folder.write_many() as batch:
        for i in range(4):
            batch.write_bytes(f"x{i}.txt", b"second")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([LEDGER_FILE, *(f"x{i}.txt" for i in range(4))])
    assert all((tmp_path / f"x{i}.txt").read_bytes() == b"second" for i in range(4))


def test_a_batch_refuses_a_users_file_a_foreign_name_and_a_name_twice_writing_none_of_that_batch(tmp_path):
    (tmp_path / "x1.txt").write_text("mine")
    with OwnedFolder(tmp_path, names=[r"x\d\.txt"]) as folder:
        for bad in (["x0.txt", "x1.txt"], ["x0.txt", "../x2.txt"], ["x0.txt", "y.txt"], ["x0.txt", "x0.txt"]):
            with pytest.raises(UnsafePathError), folder.write_many() as batch:
                for rel in bad:
                    batch.write_bytes(rel, b"ours")
            assert folder.written() == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x1.txt"] and (tmp_path / "x1.txt").read_text() == "mine"


def test_a_batch_into_a_subfolder_linked_out_is_refused(tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    root = tmp_path / "out"
    root.mkdir()
    (root / "cls").symlink_to(elsewhere)
    with OwnedFolder(root, names=[r"cls/x\d\.txt"]) as folder, pytest.raises(UnsafePathError), folder.write_many() as batch:
        batch.write_bytes("cls/x0.txt", b"ours")
    assert list(elsewhere.iterdir()) == []


def test_a_full_disk_in_a_batch_is_one_output_error_and_leaves_no_temporary(tmp_path, monkeypatch):
    import errno

    real_fdopen = os.fdopen
    opened = []

    class Full:
        def __init__(self, fh):
            self.fh = fh

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def fileno(self):
            return self.fh.fileno()

        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")

    def fdopen(fd, *args, **kwargs):
        opened.append(fd)
        fh = real_fdopen(fd, *args, **kwargs)
        return Full(fh) if len(opened) == 2 else fh

    monkeypatch.setattr(os, "fdopen", fdopen)
    with OwnedFolder(tmp_path, names=[r"x\d\.txt"]) as folder, pytest.raises(OutputError, match="disk full"), folder.write_many() as batch:
        for i in range(3):
            batch.write_bytes(f"x{i}.txt", b"data")
    assert sorted(p.name for p in tmp_path.iterdir()) == []
