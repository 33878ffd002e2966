"""``realism``, ``fit-sensor`` and ``contact-sheet`` write through the output layer (io/owned.py).

Per command: a user's file of a name the command writes is refused in one line (exit 2) and left
as it is, with nothing else written; a rerun to the same path replaces the command's own files;
an ``--out`` whose folder cannot be made is one line, exit 2, no traceback.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
from conftest import aerial_slab_crops

from zbuf_occlude.cli.main import main
from zbuf_occlude.experiments.realism import REPORT_FILES
from zbuf_occlude.io.owned import LEDGER_FILE

pytestmark = pytest.mark.slow  # the realism runs draw figures; the fixtures scan

#: A folder no process can make, not even root's: procfs refuses mkdir.
UNMAKEABLE = Path("/proc/sys/zbuf_x/out")
MINE = b"my own notes, not an output\n"


@pytest.fixture(scope="module")
def scans(tmp_path_factory) -> Path:
    """Three crops of a car-sized box, written by ``zbuf-occlude scan`` (as test_realism makes them)."""
    out = tmp_path_factory.mktemp("scans") / "gen"
    argv = ["scan", "box", "--extents", "4.5,1.8,1.5", "--distance", "6:10", "--azimuth", "0:360", "--samples", "3", "--crop",
            "--out", str(out), "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def crops(tmp_path_factory) -> Path:
    """Four aerial crops of a flat slab, one class (``--sensor dales-q1560``)."""
    return aerial_slab_crops(tmp_path_factory.mktemp("crops"))


def _argv(command: str, out: Path, scans: Path, crops: Path) -> list[str]:
    """The command writing into ``out`` (the folder of realism; the folder of the file otherwise)."""
    return {
        "realism": ["realism", str(scans), str(scans), "--out", str(out)],
        "fit-sensor": ["fit-sensor", str(crops), "--sensor", "dales-q1560", "--out", str(out / "s.json")],
        "contact-sheet": ["contact-sheet", str(scans), "--out", str(out / "sheet.png"), "--per-class", "1", "--poses", "1", "--dpi", "20"],
    }[command]


#: Every file each command writes, in the folder ``_argv`` gives it.
WRITES = {"realism": list(REPORT_FILES), "fit-sensor": ["s.json", "s.md"], "contact-sheet": ["sheet.png"]}


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error:") and "\n" not in err and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("command, name", [(c, n) for c, names in WRITES.items() for n in names])
def test_a_users_file_of_a_name_it_writes_is_refused_and_left_as_it_is(tmp_path, capsys, scans, crops, command, name) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_bytes(MINE)
    assert main(_argv(command, out, scans, crops)) == 2
    err = _one_line_error(capsys)
    assert str(out / name) in err and "not recorded by a run of ours" in err, err
    assert (out / name).read_bytes() == MINE
    assert sorted(p.name for p in out.iterdir()) == [name]  # nothing else written: every name is checked first


@pytest.mark.parametrize("command", WRITES)
def test_a_file_of_ours_changed_since_is_refused_and_left_as_it_is(tmp_path, capsys, scans, crops, command) -> None:
    out = tmp_path / "out"
    assert main(_argv(command, out, scans, crops)) == 0
    changed = out / WRITES[command][0]
    changed.write_bytes(changed.read_bytes() + b"edited\n")
    before = changed.read_bytes()
    capsys.readouterr()
    assert main(_argv(command, out, scans, crops)) == 2
    assert str(changed) in _one_line_error(capsys)
    assert changed.read_bytes() == before


@pytest.mark.parametrize("command", WRITES)
def test_a_rerun_replaces_its_own_files(tmp_path, scans, crops, command) -> None:
    out = tmp_path / "out"
    assert main(_argv(command, out, scans, crops)) == 0
    first = {name: ((out / name).read_bytes(), (out / name).stat().st_ino) for name in WRITES[command]}
    assert main(_argv(command, out, scans, crops)) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted([*WRITES[command], LEDGER_FILE])
    for name, (data, inode) in first.items():
        assert (out / name).read_bytes() == data  # the same run gives the same bytes ...
        assert (out / name).stat().st_ino != inode, name  # ... in a new file that took the name


def test_realism_without_its_figure_leaves_a_users_png_alone(tmp_path, capsys, scans, crops) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "realism.png").write_bytes(MINE)
    assert main([*_argv("realism", out, scans, crops), "--no-figure"]) == 0
    assert (out / "realism.png").read_bytes() == MINE
    assert (out / "realism.md").is_file()


@pytest.mark.skipif(not sys.platform.startswith("linux") or not os.path.isdir("/proc/sys"), reason="needs Linux procfs")
@pytest.mark.parametrize("command", WRITES)
def test_an_out_whose_folder_cannot_be_made_is_one_line(capsys, scans, crops, command) -> None:
    assert main(_argv(command, UNMAKEABLE, scans, crops)) == 2
    assert "/proc/sys/zbuf_x" in _one_line_error(capsys)
    assert not os.path.lexists(UNMAKEABLE.parent)
