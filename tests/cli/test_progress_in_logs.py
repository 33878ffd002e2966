"""Progress of ``generate``, ``farm`` and ``farm-merge`` when stderr is a file: newline-terminated
lines that say how many objects are done out of how many, never a carriage return; with
``--no-progress``, no progress at all.  Real redirections need a subprocess."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from zbuf_occlude.io.progress import PROGRESS_INTERVAL_ENV

REPO_ROOT = Path(__file__).resolve().parents[2]
MESHES = ("chair/train/chair_0001.off", "sofa/test/sofa_0681.off")
TINY = ["--views", "0:0", "--points", "64", "--dense-points", "2000", "--resolution", "128"]


@pytest.fixture(scope="module")
def tree(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("in")
    for rel in MESHES:
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(REPO_ROOT / "data" / "samples" / rel, root / rel)
    return root


def _stderr_to_file(tmp_path: Path, *args: str) -> str:
    """Run ``zbuf-occlude ARGS`` with stderr redirected to a file (a line per update: interval 0); that file's text."""
    log = tmp_path / "stderr.log"
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT), PROGRESS_INTERVAL_ENV: "0"}
    with log.open("w") as err:
        done = subprocess.run([sys.executable, "-m", "zbuf_occlude", *args], stdout=subprocess.DEVNULL, stderr=err, env=env,
                              cwd=tmp_path, timeout=300)  # fmt: skip
    text = log.read_text()
    assert done.returncode == 0, text
    return text


def _progress_lines(text: str, name: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith(f"{name}: ")]


@pytest.mark.slow
@pytest.mark.parametrize("command", ["generate", "farm"])
def test_redirected_progress_is_newline_terminated_lines_of_done_over_total(command, tree, tmp_path):
    text = _stderr_to_file(tmp_path, command, str(tree), "--out", str(tmp_path / "out"), *TINY)
    assert "\r" not in text
    lines = _progress_lines(text, command)
    assert [re.match(rf"{command}: (\d+)/2 obj, ", line).group(1) for line in lines] == ["1", "2"], text


@pytest.mark.slow
@pytest.mark.parametrize("command", ["generate", "farm"])
def test_no_progress_writes_no_progress(command, tree, tmp_path):
    text = _stderr_to_file(tmp_path, command, str(tree), "--out", str(tmp_path / "out"), *TINY, "--no-progress")
    assert "\r" not in text and _progress_lines(text, command) == [], text


@pytest.mark.slow
def test_farm_merge_progress_in_a_log(tree, tmp_path):
    for task in (0, 1):
        _stderr_to_file(tmp_path, "farm", str(tree), "--out", str(tmp_path / "out"), *TINY, "--shard", f"{task}/2", "--no-progress")
    text = _stderr_to_file(tmp_path, "farm-merge", str(tmp_path / "out"))
    assert "\r" not in text
    assert _progress_lines(text, "farm-merge")[-1].startswith("farm-merge: 2/2 obj, "), text


@pytest.mark.slow
def test_verify_progress_in_a_log(tree, tmp_path):
    _stderr_to_file(tmp_path, "farm", str(tree), "--out", str(tmp_path / "out"), *TINY, "--no-progress")
    text = _stderr_to_file(tmp_path, "verify", str(tmp_path / "out"))
    assert "\r" not in text
    assert [line.split(" obj,")[0] for line in _progress_lines(text, "verify")] == ["verify: 1/2", "verify: 2/2"], text
    quiet = _stderr_to_file(tmp_path, "verify", str(tmp_path / "out"), "--no-progress")
    assert _progress_lines(quiet, "verify") == [], quiet


def test_scan_progress_in_a_log(tmp_path):
    args = ["scan", "box", "--sensor", "vlp16", "--samples", "2", "--out", str(tmp_path / "scans")]
    text = _stderr_to_file(tmp_path, *args)
    assert "\r" not in text
    assert [line.split(" scan")[0] for line in _progress_lines(text, "scan")] == ["scan: 1/2", "scan: 2/2"], text
    quiet = _stderr_to_file(tmp_path, *args, "--no-progress")
    assert _progress_lines(quiet, "scan") == [], quiet
