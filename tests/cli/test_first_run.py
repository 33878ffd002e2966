"""A first run says on stderr that numba compiles the kernels, from the command line only (zbuf_occlude.cli.first_run)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from zbuf_occlude.cli import first_run
from zbuf_occlude.cli.main import main


def test_an_empty_numba_cache_is_cold(tmp_path: Path) -> None:
    """Where NUMBA_CACHE_DIR holds nothing, the kernels are cold (asked in a fresh process: numba
    reads the variable when the kernels are defined); nothing is compiled to ask."""
    code = "from zbuf_occlude.cli.first_run import kernels_cold; print(kernels_cold())"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and run.stdout.strip() == "True", run.stderr
    assert not any(tmp_path.rglob("*.nbc"))  # asking compiled nothing


@pytest.mark.parametrize("found, cold", [(True, False), (False, True)])
def test_the_kernels_are_cold_when_an_index_file_of_numbas_cache_is_missing(monkeypatch, found: bool, cold: bool) -> None:
    monkeypatch.setattr(first_run.os.path, "isfile", lambda path: found)
    assert first_run.kernels_cold() is cold


@pytest.mark.parametrize("cold", [True, False])
def test_the_line_comes_before_the_work_of_a_visibility_command_only_when_cold(monkeypatch, capsys, tmp_path: Path, cold: bool) -> None:
    monkeypatch.setattr(first_run, "kernels_cold", lambda: cold)
    monkeypatch.setattr(first_run, "interactive", lambda: True)
    assert main(["validate", str(tmp_path / "missing.off")]) == 2  # refused after parsing: the line comes first
    err = capsys.readouterr().err.splitlines()
    assert (err[0] == first_run.FIRST_RUN_LINE) is cold and len(err) == 1 + cold, err
    assert main(["info"]) in (0, 1)  # no visibility: no line, cold or not
    assert first_run.FIRST_RUN_LINE not in capsys.readouterr().err


def test_the_library_says_nothing() -> None:
    """Only the command line prints the line: no module of the library outside cli/ names it."""
    import zbuf_occlude

    package = Path(zbuf_occlude.__file__).parent
    users = [p for p in package.rglob("*.py") if "first_run" in p.read_text(encoding="utf-8") and p.parent.name != "cli"]
    assert users == []


def test_a_script_or_a_log_never_gets_the_line(monkeypatch, capsys, tmp_path: Path) -> None:
    """Where stderr is not a terminal (a pipe, a log, a test) an error stays one line, cold or not."""
    monkeypatch.setattr(first_run, "kernels_cold", lambda: True)
    assert not first_run.interactive()  # capsys: not a terminal
    assert main(["validate", str(tmp_path / "missing.off")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and first_run.FIRST_RUN_LINE not in err[0], err
