"""A resumed run removes the temporary files that dead writers left in every folder a run writes
into (zbuf_occlude.io.deletes.remove_dead_temps), and only those."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

from conftest import SAMPLE_MESHES

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.io.atomic import _host_tag

CHAIR = SAMPLE_MESHES / "chair/train/chair_0001.off"
SMALL = ["--views", "0:0", "--dense-points", "500", "--samples-per-view", "1", "--points", "64", "--resolution", "64", "--no-progress"]


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_a_resumed_generate_removes_dead_writers_temps_everywhere(tmp_path):
    (tmp_path / "in" / "chair" / "train").mkdir(parents=True)
    shutil.copy(CHAIR, tmp_path / "in" / "chair" / "train" / CHAIR.name)
    out = tmp_path / "out"
    argv = ["generate", str(tmp_path / "in"), "--out", str(out), "--format", "npz", *SMALL]
    assert cli_main(argv) == 0
    dead, alive = _dead_pid(), os.getpid()
    folders = [out, out / "records", out / "tasks", out / "chair" / "train" / "chair_0001"]
    for folder in folders:
        for pid in (dead, alive):
            (folder / f".x.npz.{pid}-{_host_tag()}-abc.tmp").write_text("partial")
    assert cli_main(argv) == 0
    for folder in folders:
        assert sorted(p.name for p in folder.glob(".*.tmp")) == [f".x.npz.{alive}-{_host_tag()}-abc.tmp"], folder
