"""Standard output that cannot be written, for every command (``cli.main``): a reader that went away
(``zbuf-occlude info | head -1``) ends the command quietly with exit status 141; a stdout on a full
disk (``> /dev/full``) lets the command finish its files, then says so on one line, exit 1.  Never a
traceback, and never Python's "Exception ignored" at exit.  Real file descriptors need a subprocess.
"""

from __future__ import annotations

import errno
import io
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from zbuf_occlude.cli import main as cli_main

REPO_ROOT = Path(__file__).resolve().parents[2]
CHAIR = REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"
DEV_FULL = Path("/dev/full")
needs_dev_full = pytest.mark.skipif(not DEV_FULL.exists(), reason="no /dev/full here")

#: A command that prints 200,000 lines, then leaves a marker file: did it run to its end?
_LOUD = """
import sys
from pathlib import Path
import zbuf_occlude.cli.main as m

def loud(args):
    for i in range(200_000):
        print(f"line {{i}}")
    Path({marker!r}).write_text("done")
    return 0

m.cmd_info = loud
sys.exit(m.main(["info"]))
"""


def _run(argv: list[str], stdout, *, unbuffered: bool = True, code: str | None = None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    if unbuffered:
        env["PYTHONUNBUFFERED"] = "1"
    command = [sys.executable, "-c", code] if code else [sys.executable, "-m", "zbuf_occlude", *argv]
    return subprocess.run(command, stdout=stdout, stderr=subprocess.PIPE, text=True, env=env, cwd=REPO_ROOT, timeout=300)


def _closed_pipe() -> int:
    """The write end of a pipe whose reader is gone: every write fails with EPIPE."""
    read, write = os.pipe()
    os.close(read)
    return write


def _clean(stderr: str) -> None:
    assert "Traceback" not in stderr and "Exception ignored" not in stderr, stderr


@pytest.mark.slow
@pytest.mark.parametrize("argv", [["info"], ["--help"], ["--version"], ["farm", "--help"]])
def test_a_reader_that_went_away_ends_quietly_with_141(argv) -> None:
    write = _closed_pipe()
    try:
        done = _run(argv, write)
    finally:
        os.close(write)
    _clean(done.stderr)
    assert done.returncode == 141 and done.stderr == "", done.stderr


@pytest.mark.parametrize("unbuffered", [True, False])
def test_a_closed_pipe_stops_a_long_command_at_once(tmp_path, unbuffered) -> None:
    marker = tmp_path / "finished"
    write = _closed_pipe()
    try:
        done = _run([], write, unbuffered=unbuffered, code=_LOUD.format(marker=str(marker)))
    finally:
        os.close(write)
    _clean(done.stderr)
    assert done.returncode == 141 and not marker.exists()  # nobody reads it: printing on is waste


@needs_dev_full
@pytest.mark.parametrize("unbuffered", [True, False])
def test_a_full_stdout_lets_the_command_finish_then_says_so_once(tmp_path, unbuffered) -> None:
    marker = tmp_path / "finished"
    with DEV_FULL.open("w") as full:
        done = _run([], full, unbuffered=unbuffered, code=_LOUD.format(marker=str(marker)))
    _clean(done.stderr)
    assert done.returncode == 1 and marker.read_text() == "done"
    lines = done.stderr.strip().splitlines()
    assert lines == ["zbuf-occlude: error: could not write to standard output (No space left on device); "
                     "the command finished its work; what it printed is lost"], done.stderr  # fmt: skip


@pytest.mark.slow
@needs_dev_full
def test_farm_into_dev_full_finishes_the_data_set_and_exits_1_without_a_traceback(tmp_path) -> None:
    root = tmp_path / "in" / "chair" / "train"
    root.mkdir(parents=True)
    shutil.copy(CHAIR, root / CHAIR.name)
    out = tmp_path / "ds"
    argv = ["farm", str(tmp_path / "in"), "--out", str(out), "--views", "0:0", "--dense-points", "2000", "--samples-per-view", "1",
            "--no-progress"]  # fmt: skip
    with DEV_FULL.open("w") as full:
        done = _run(argv, full)
    _clean(done.stderr)
    assert done.returncode == 1, done.stderr
    assert "could not write to standard output" in done.stderr and "finished its work" in done.stderr
    from zbuf_occlude.dataset.verify import verify_dataset

    assert verify_dataset(out).ok  # the data set is finished


@needs_dev_full
def test_usage_errors_still_exit_2_with_stdout_full(tmp_path) -> None:
    with DEV_FULL.open("w") as full:
        done = _run(["scan", "box", "--samples", "-1", "--out", str(tmp_path / "o")], full)
    _clean(done.stderr)
    assert done.returncode == 2 and "--samples must be an integer >= 1, got -1" in done.stderr


# -- in-process: only stdout's own errors are told so --------------------------------------------------------
class _Failing(io.StringIO):
    def __init__(self, code: int) -> None:
        super().__init__()
        self.code = code

    def write(self, text: str) -> int:
        raise OSError(self.code, os.strerror(self.code))


@pytest.mark.parametrize(("code", "status"), [(errno.ENOSPC, 1), (errno.EIO, 1), (errno.EPIPE, 141)])
def test_main_tells_stdout_errors_and_restores_sys_stdout(monkeypatch, capsys, code, status) -> None:
    monkeypatch.setattr(cli_main, "cmd_info", lambda args: print("report") or 0)
    failing = _Failing(code)
    monkeypatch.setattr(sys, "stdout", failing)
    assert cli_main.main(["info"]) == status
    assert sys.stdout is failing
    err = capsys.readouterr().err
    assert ("could not write to standard output" in err) == (code != errno.EPIPE), err


def test_another_files_oserror_is_a_bug_with_its_traceback(monkeypatch) -> None:
    def disk_full(args):
        raise OSError(errno.ENOSPC, "No space left on device", "shard.h5")

    monkeypatch.setattr(cli_main, "cmd_info", disk_full)
    with pytest.raises(OSError, match="shard.h5"):
        cli_main.main(["info"])


# -- no stdout at all (a shell's ``>&-``): the result cannot be reported, so the command fails ----------------
@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    from conftest import tiny_dataset

    return tiny_dataset(tmp_path_factory.mktemp("tiny") / "ds")


def _closed_stdout(argv: list[str]) -> subprocess.CompletedProcess:
    """``zbuf-occlude ARGV >&-``: started with file descriptor 1 closed (Python's sys.stdout is then None)."""
    command = shlex.join([sys.executable, "-m", "zbuf_occlude", *argv]) + " >&-"
    return subprocess.run(["bash", "-c", command], stderr=subprocess.PIPE, text=True, cwd=REPO_ROOT, timeout=300)


@pytest.mark.parametrize("command", ["verify", "contact-sheet"])
def test_a_closed_stdout_fails_the_command_in_one_line(tiny, tmp_path, command) -> None:
    argv = ["verify", str(tiny), "--no-progress"] if command == "verify" else [
        "contact-sheet", str(tiny), "--out", str(tmp_path / "sheet.png"), "--per-class", "1", "--poses", "1", "--dpi", "20"]  # fmt: skip
    done = _closed_stdout(argv)
    _clean(done.stderr)
    assert done.returncode == 1, done.stderr
    assert done.stderr.splitlines() == ["zbuf-occlude: error: could not write to standard output (standard output is closed); "
                                        "the command finished its work; what it printed is lost"], done.stderr  # fmt: skip


@pytest.mark.parametrize("stream", [None, "closed"])
def test_main_fails_when_stdout_is_none_or_closed(monkeypatch, capsys, stream) -> None:
    monkeypatch.setattr(cli_main, "cmd_info", lambda args: print("report") or 0)
    if stream is None:
        monkeypatch.setattr(sys, "stdout", None)
    else:
        closed = io.StringIO()
        closed.close()  # a write raises ValueError: I/O operation on closed file
        monkeypatch.setattr(sys, "stdout", closed)
    assert cli_main.main(["info"]) == 1
    assert "could not write to standard output (standard output is closed)" in capsys.readouterr().err


# -- no stderr (``2>&-``): messages and progress are lost, the run is not -----------------------------------
@pytest.mark.parametrize("progress", [[], ["--no-progress"]], ids=["progress", "no-progress"])
def test_a_farm_with_stderr_closed_finishes_its_data_set(tmp_path, progress) -> None:
    root = tmp_path / "in" / "chair" / "train"
    root.mkdir(parents=True)
    shutil.copy(CHAIR, root / CHAIR.name)
    out = tmp_path / "ds"
    argv = ["farm", str(tmp_path / "in"), "--out", str(out), "--views", "0:0", "--dense-points", "500", "--samples-per-view", "1",
            "--points", "64", "--resolution", "64", *progress]  # fmt: skip
    command = shlex.join([sys.executable, "-m", "zbuf_occlude", *argv]) + " 2>&-"
    done = subprocess.run(["bash", "-c", command], stdout=subprocess.PIPE, text=True, cwd=REPO_ROOT, timeout=300)
    assert done.returncode == 0 and "(finished)" in done.stdout, done.stdout
    from zbuf_occlude.dataset.verify import verify_dataset

    assert verify_dataset(out).ok


def test_progress_without_stderr_is_a_bar_that_shows_nothing(monkeypatch) -> None:
    from zbuf_occlude.io.progress import progress

    monkeypatch.setattr(sys, "stderr", None)
    assert list(progress(range(3), desc="x")) == [0, 1, 2]
    with progress(total=3, desc="x", interval_s=0) as bar:
        bar.update(3)
    assert bar.disable
