"""zbuf_occlude.io.progress: a tqdm bar when stderr is a terminal, newline-terminated lines when it
is a file or a pipe, nothing when progress is off; the interval between lines and its variable."""

from __future__ import annotations

import io
import time

import pytest

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io import progress as progress_module
from zbuf_occlude.io.progress import PROGRESS_INTERVAL_ENV, LineProgress, progress, progress_interval_s


@pytest.fixture(autouse=True)
def _no_line_yet(monkeypatch):
    """Each test starts as a fresh process would: no progress line written yet."""
    monkeypatch.setattr(LineProgress, "_last_line_t", 0.0)


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _stderr(monkeypatch, kind: str) -> io.StringIO:
    """stderr as a file (``"log"``) or a terminal; set in the test itself, after pytest's capture has set its own."""
    err = _Terminal() if kind == "terminal" else io.StringIO()
    monkeypatch.setattr("sys.stderr", err)
    return err


def _run(n: int, **kwargs) -> None:
    with progress(total=n, desc="generate", unit="obj", **kwargs) as bar:
        for _ in range(n):
            bar.update(1)


def test_in_a_log_every_update_is_one_line_with_done_and_total_and_no_carriage_return(monkeypatch):
    log = _stderr(monkeypatch, "log")
    _run(4, interval_s=0)
    text = log.getvalue()
    assert "\r" not in text and text.endswith("\n")
    lines = text.splitlines()
    assert [line.split(",")[0] for line in lines] == [f"generate: {i}/4 obj" for i in range(1, 5)]
    assert "ETA" not in lines[0] and "obj/s" not in lines[0]  # one item done: no rate yet (module docstring)
    assert "ETA" in lines[1] and "obj/s" in lines[1]  # rate and time left while it runs
    assert "ETA" not in lines[-1]


class _Clock:
    """tqdm's clock, moved by hand."""

    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


@pytest.mark.parametrize("where", ["log", "terminal"])
def test_the_eta_leaves_out_the_first_item_which_carries_the_start_up(monkeypatch, where):
    # the first mesh after an install waits for numba (18 s), the other 19 take 1 s each: the
    # ETA after the third is 17 s, not the 17 × 20 / 3 s that the mean since the start gives
    err = _stderr(monkeypatch, where)
    clock = _Clock()
    monkeypatch.setattr("tqdm.std.time", clock)
    bar = progress(total=20, desc="generate", unit="obj", interval_s=0)
    for step in (18.0, 1.0, 1.0):
        clock.t += step
        bar.update(1)
    assert bar.format_dict["rate"] == pytest.approx(1.0)
    bar.refresh()
    last = err.getvalue().replace("\r", "\n").splitlines()[-1]
    assert "ETA 00:17" in last if where == "log" else "<00:17" in last, last
    assert "00:20 elapsed" in last if where == "log" else "00:20<" in last, last  # elapsed counts the first item
    bar.close()


def test_in_a_log_lines_are_spaced_by_the_interval_and_a_last_line_says_where_it_ended(monkeypatch):
    log = _stderr(monkeypatch, "log")
    _run(50, interval_s=3600)
    assert log.getvalue().splitlines() == [log.getvalue().splitlines()[0]]
    assert log.getvalue().startswith("generate: 50/50 obj, ")


def test_in_a_log_a_transient_bar_writes_no_last_line(monkeypatch):
    log = _stderr(monkeypatch, "log")
    with progress(total=3, desc="epoch 1/2", unit="batch", leave=False, interval_s=3600) as bar:
        bar.update(3)
    assert log.getvalue() == ""


def test_in_a_log_the_postfix_and_the_iterable_form_work(monkeypatch):
    log = _stderr(monkeypatch, "log")
    seen = []
    bar = progress(range(3), desc="compare", unit="call", interval_s=0)
    for i in bar:
        seen.append(i)
        bar.set_postfix(failed=0, refresh=False)
    bar.close()
    assert seen == [0, 1, 2]
    assert log.getvalue().splitlines()[-1].startswith("compare: 3/3 call, ")
    assert "failed=0" in log.getvalue()


def test_on_a_terminal_it_is_a_tqdm_bar_redrawn_in_place(monkeypatch):
    terminal = _stderr(monkeypatch, "terminal")
    bar = progress(total=4, desc="generate", unit="obj")
    assert not isinstance(bar, LineProgress)
    bar.update(4)
    bar.close()
    assert "\r" in terminal.getvalue() and "4/4" in terminal.getvalue()


@pytest.mark.parametrize("where", ["log", "terminal"])
def test_disabled_progress_writes_nothing(where, monkeypatch):
    err = _stderr(monkeypatch, where)
    _run(4, enabled=False, interval_s=0)
    for _ in progress(range(3), desc="x", enabled=False):
        pass
    assert err.getvalue() == ""


def test_the_interval_comes_from_the_environment(monkeypatch):
    log = _stderr(monkeypatch, "log")
    monkeypatch.delenv(PROGRESS_INTERVAL_ENV, raising=False)
    assert progress_interval_s() == progress_module.PROGRESS_INTERVAL_S
    monkeypatch.setenv(PROGRESS_INTERVAL_ENV, "0")
    assert progress_interval_s() == 0
    _run(3)
    assert len(log.getvalue().splitlines()) == 3


@pytest.mark.parametrize("value", ["soon", "-1", "nan", "inf"])
def test_a_bad_interval_in_the_environment_is_refused_naming_it(monkeypatch, value):
    monkeypatch.setenv(PROGRESS_INTERVAL_ENV, value)
    with pytest.raises(InvalidInputError, match=f"{PROGRESS_INTERVAL_ENV}='{value}'"):
        progress_interval_s()


@pytest.mark.slow
def test_training_writes_lines_not_bars_into_a_log(monkeypatch):
    # `experiment` and `experiment sim2real` train through learn.train: per epoch, lines in a log
    pytest.importorskip("torch", reason="zbuf_occlude.learn needs PyTorch: pip install -e '.[learn]'")
    import numpy as np

    from zbuf_occlude.learn.data import CloudSet
    from zbuf_occlude.learn.training import TrainConfig, train

    rng = np.random.default_rng(0)
    clouds = CloudSet(rng.normal(size=(8, 32, 3)).astype(np.float32), np.arange(8) % 2, np.full(8, np.nan), np.arange(8))
    monkeypatch.setenv(PROGRESS_INTERVAL_ENV, "0")
    log = _stderr(monkeypatch, "log")
    train(clouds, 2, TrainConfig(model="pointnet", epochs=2, batch_size=4, width=0.125, seed=0, patience=0, threads=1))
    assert "\r" not in log.getvalue()
    assert any(line.startswith("pointnet epoch 2/2: 2/2 batch, ") for line in log.getvalue().splitlines()), log.getvalue()


@pytest.mark.slow
def test_sim2real_shows_the_meshes_it_makes_a_set_from(monkeypatch, sample_meshes_dir, tmp_path):
    # the stage that makes the training sets from the meshes (tens of seconds) reports as it goes
    import shutil

    from zbuf_occlude.experiments.sim2real.data import build_set
    from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes

    for cls, names in {"seat": ("chair", "sofa"), "top": ("stool", "table")}.items():  # two meshes a class
        for name in names:
            src = next((sample_meshes_dir / name).rglob("*.off"))
            (tmp_path / cls).mkdir(exist_ok=True)
            shutil.copyfile(src, tmp_path / cls / src.name)
    meshes = find_class_meshes(tmp_path)
    monkeypatch.setenv(PROGRESS_INTERVAL_ENV, "0")
    log = _stderr(monkeypatch, "log")
    build_set("complete", meshes, ["seat", "top"], 4, 16, 0, progress=True)
    assert "\r" not in log.getvalue()
    assert [line.split(",")[0] for line in log.getvalue().splitlines()] == [f"sim2real complete set: {i}/{len(meshes)} mesh"
                                                                            for i in range(1, len(meshes) + 1)]  # fmt: skip


def test_in_a_log_a_slow_run_gives_seconds_per_item_and_the_time_left(monkeypatch):
    log = _stderr(monkeypatch, "log")
    clock = [time.time()]
    monkeypatch.setattr("tqdm.std.time", lambda: clock[0])  # the clock tqdm reads
    with progress(total=4, desc="farm", unit="obj", interval_s=0) as bar:
        for _ in range(2):
            clock[0] += 300.0  # five minutes an object
            bar.update(1)
    assert log.getvalue().splitlines()[1] == "farm: 2/4 obj, 300 s/obj, ETA 10:00, 10:00 elapsed"


@pytest.mark.slow
def test_table3_shows_the_meshes_its_visible_area_curve_is_made_of(monkeypatch, tmp_path):
    # `experiment table3`'s Fig. 12 curve profiles every mesh in turn (seconds each): lines in a log
    pytest.importorskip("torch", reason="zbuf_occlude.experiments.table3 needs PyTorch: pip install -e '.[learn]'")
    from zbuf_occlude.experiments import elevation_profile
    from zbuf_occlude.experiments.table3 import elevation
    from zbuf_occlude.experiments.table3.config import SCALES
    from zbuf_occlude.mesh import load

    monkeypatch.setattr(load, "load_mesh", lambda path: path)  # the profile itself is elevation_profile's tests' job
    monkeypatch.setattr(elevation_profile, "profile_table", lambda mesh, **kw: [{"elevation_deg": 0.0, "area_visible": 1.0}])
    monkeypatch.setenv(PROGRESS_INTERVAL_ENV, "0")
    log = _stderr(monkeypatch, "log")
    meshes = [{"path": f"m{i}.off"} for i in range(3)]
    elevation._visible_area_curve(meshes, tmp_path, SCALES["quick"], "embree-fast", progress=True)
    assert "\r" not in log.getvalue()
    assert [line.split(",")[0] for line in log.getvalue().splitlines()] == [f"table3 visible area: {i}/3 mesh" for i in (1, 2, 3)]


def test_in_a_log_a_line_written_at_a_later_clock_time_does_not_silence_the_next_bar(monkeypatch):
    # the clock set back (or a line stamped by another clock): the next bar still writes its lines
    monkeypatch.setattr(LineProgress, "_last_line_t", time.time() + 3600)
    log = _stderr(monkeypatch, "log")
    _run(2, interval_s=0)
    assert [line.split(",")[0] for line in log.getvalue().splitlines()] == ["generate: 1/2 obj", "generate: 2/2 obj"]


# -- a pseudo-terminal ------------------------------------------------------------------------------
_PTY_BAR = (
    "import time\nfrom zbuf_occlude.io.progress import progress\n"
    "with progress(total=3, desc='pty-bar', unit='obj') as bar:\n"
    "    for _ in range(3):\n        time.sleep(0.05)\n        bar.update(1)\n"
)


def _run_on_pty(argv: list[str], *, stderr_on_pty: bool = True, size: tuple[int, int] | None = None, env: dict | None = None) -> str:
    """Run ``argv`` with stdout (and stderr, unless ``stderr_on_pty`` is False: then a pipe) on a new
    pseudo-terminal of ``size`` (rows, columns; None: unsized, 0 × 0, as ``script`` makes one); what the terminal got."""
    import fcntl
    import os
    import pty
    import struct
    import subprocess
    import termios

    master, slave = pty.openpty()
    if size is not None:
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", size[0], size[1], 0, 0))
    environ = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")} | (env or {})
    proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=slave, stderr=slave if stderr_on_pty else subprocess.PIPE, env=environ)
    os.close(slave)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:  # the child closed its end (EIO on Linux)
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(master)
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == 0, (b"".join(chunks) + (err or b""))[-2000:]
    return b"".join(chunks).decode("utf-8", "replace")


pty_only = pytest.mark.skipif(not hasattr(__import__("os"), "openpty") or __import__("sys").platform == "win32", reason="needs a POSIX pty")


@pty_only
@pytest.mark.parametrize("size", [None, (30, 100)], ids=["unsized", "sized"])
def test_on_a_pseudo_terminal_the_bar_is_drawn_sized_or_not(size):
    """``script`` and friends give a pseudo-terminal of 0 × 0: the bar is drawn there too, at a width of its own."""
    import sys

    screen = _run_on_pty([sys.executable, "-c", _PTY_BAR], size=size)
    assert "pty-bar: 100%|" in screen and "3/3" in screen, screen
    widest = max(len(line) for line in screen.replace("\r\n", "\n").replace("\r", "\n").split("\n"))
    assert widest <= (size[1] if size else progress_module.FALLBACK_COLUMNS)


@pty_only
def test_a_bar_on_an_unsized_terminal_takes_columns_from_the_environment():
    import sys

    screen = _run_on_pty([sys.executable, "-c", _PTY_BAR], env={"COLUMNS": "50", "LINES": "10"})
    bars = [line for line in screen.replace("\r\n", "\n").replace("\r", "\n").split("\n") if "pty-bar" in line]
    assert bars and max(len(b) for b in bars) <= 50 and max(len(b) for b in bars) > 40, bars


@pytest.mark.slow
@pty_only
def test_the_farm_shows_its_bar_on_a_pseudo_terminal_and_none_with_no_progress_or_a_pipe(tmp_path, sample_meshes_dir):
    """A farm of one shipped mesh and two views, under an unsized pseudo-terminal as ``script -qc`` gives."""
    import sys

    def farm(name: str, *extra: str, stderr_on_pty: bool = True) -> str:
        argv = [sys.executable, "-m", "zbuf_occlude", "farm", str(sample_meshes_dir), "--out", str(tmp_path / name), "--classes", "chair",
                "--per-class", "1", "--splits", "train", "--views", "fibonacci:2", "--samples-per-view", "1", "--points", "128",
                "--workers", "1", *extra]  # fmt: skip
        return _run_on_pty(argv, stderr_on_pty=stderr_on_pty)

    assert "farm: 100%|" in farm("bar")
    for screen in (farm("quiet", "--no-progress"), farm("pipe", stderr_on_pty=False)):
        assert "farm:" not in screen.replace("zbuf-occlude farm:", "") and "%|" not in screen, screen
