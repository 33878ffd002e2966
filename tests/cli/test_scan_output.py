"""``scan`` writes through the owned-folder layer: one line for a folder it cannot make, a user's
file of the same name is left alone, its own files are replaced on a rerun."""

from __future__ import annotations

from pathlib import Path

import pytest

from zbuf_occlude.cli.main import main as cli_main

SCAN = ["scan", "box", "--sensor", "vlp16", "--samples", "1", "--no-progress"]


@pytest.mark.skipif(not Path("/proc/sys").is_dir(), reason="needs Linux's /proc/sys, where no folder can be made")
def test_an_out_that_cannot_be_made_is_one_line(capsys):
    assert cli_main([*SCAN, "--out", "/proc/sys/zbuf_occlude_x"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("zbuf-occlude: error: ") and len(err.strip().splitlines()) == 1 and "--out" in err, err


def test_a_users_file_of_a_scan_name_is_left_alone(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "box_vlp16_s000.npz").write_text("mine")
    assert cli_main([*SCAN, "--out", str(out)]) == 2
    assert "box_vlp16_s000.npz was not recorded by a run of ours" in capsys.readouterr().err
    assert (out / "box_vlp16_s000.npz").read_text() == "mine"


@pytest.mark.parametrize("fmt", ["npz", "both"])
def test_a_rerun_replaces_its_own_files(tmp_path, fmt):
    out = tmp_path / "out"
    assert cli_main([*SCAN, "--out", str(out), "--format", fmt]) == 0
    first = {p.name: p.read_bytes() for p in out.iterdir() if not p.name.startswith(".")}
    assert cli_main([*SCAN, "--out", str(out), "--format", fmt]) == 0
    assert {p.name: p.read_bytes() for p in out.iterdir() if not p.name.startswith(".")} == first
    assert sorted(first) == sorted(f"box_vlp16_s000.{f}" for f in (["npz", "ply"] if fmt == "both" else [fmt]))
