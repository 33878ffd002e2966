"""The install script and the extras: the main install brings no PyTorch, ``--test`` brings the CPU build.

``scripts/install.sh`` runs in a temporary copy with stand-ins for ``.venv/bin/python`` (records
each call, fails where told), ``ldconfig`` (the OpenGL libraries are there) and ``nvidia-smi``,
so the test sees which ``pip install`` commands the script would run, without installing.
"""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FAKE_PYTHON = """#!/usr/bin/env bash
echo "$*" >> "$CALLS"
case "$*" in
  *"import torch; print"*) echo 2.13.0+cpu ;;
  *"import torch"*) [ -n "${HAS_TORCH:-}" ] ;;
  *download.pytorch.org*) [ -n "${CPU_INDEX_OK:-}" ] ;;
  *) true ;;
esac
"""


def _executable(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    path.chmod(path.stat().st_mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)


@pytest.fixture
def fake_checkout(tmp_path) -> Path:
    repo = tmp_path / "repo"
    (repo / "scripts").mkdir(parents=True)
    shutil.copy(ROOT / "scripts" / "install.sh", repo / "scripts" / "install.sh")
    _executable(repo / ".venv" / "bin" / "python", FAKE_PYTHON)
    _executable(repo / ".venv" / "bin" / "zbuf-occlude", "#!/usr/bin/env bash\ntrue\n")
    _executable(tmp_path / "bin" / "ldconfig", "#!/usr/bin/env bash\necho libEGL_mesa.so.0 libOSMesa.so.8\n")
    return repo


def _install(repo: Path, *args: str, gpu: bool = False, **env: str) -> tuple[int, list[str], str]:
    bin_dir = repo.parent / "bin"
    # nvidia-smi: a stand-in either way, so that a real one in /usr/bin (a GPU machine) never counts
    if gpu:
        _executable(bin_dir / "nvidia-smi", "#!/usr/bin/env bash\necho 'GPU 0: NVIDIA H100 (UUID: GPU-0)'\n")
    else:
        _executable(bin_dir / "nvidia-smi", "#!/usr/bin/env bash\necho 'NVIDIA-SMI has failed: no NVIDIA driver' >&2\nexit 9\n")
    calls = repo.parent / "calls.txt"
    calls.unlink(missing_ok=True)
    # PATH: the stand-ins first, then the system's bash tools
    path = os.pathsep.join([str(bin_dir), "/usr/bin", "/bin"])
    r = subprocess.run(
        ["bash", str(repo / "scripts" / "install.sh"), *args], capture_output=True, text=True, timeout=60,
        env={"PATH": path, "CALLS": str(calls), "HOME": str(repo.parent), **env},
    )  # fmt: skip
    return r.returncode, calls.read_text().splitlines() if calls.exists() else [], r.stdout + r.stderr


@pytest.mark.skipif(shutil.which("bash") is None or sys.platform == "win32", reason="needs bash")
class TestInstallScript:
    def test_the_main_install_brings_no_torch(self, fake_checkout):
        rc, calls, out = _install(fake_checkout)
        assert rc == 0, out
        installs = [c for c in calls if c.startswith("-m pip install")]
        assert installs == ["-m pip install -q --upgrade pip", "-m pip install -q -e ."]
        assert not any("torch" in c for c in calls)

    @pytest.mark.parametrize("args", [[], ["--test"]])
    def test_the_package_is_compiled_after_it_is_installed(self, fake_checkout, args):
        # installed in place, pip compiles none of it; with PYTHONDONTWRITEBYTECODE each start would
        rc, calls, out = _install(fake_checkout, *args, CPU_INDEX_OK="1")
        assert rc == 0, out
        last_install = max(i for i, c in enumerate(calls) if c.startswith("-m pip install"))
        assert calls[last_install + 1 :] == [
            "-m compileall -q zbuf_occlude", "-m zbuf_occlude.visibility.warmup -q", "-m zbuf_occlude.sensors.warmup -q"
        ], calls  # fmt: skip

    def test_test_install_takes_the_cpu_build_first_without_a_gpu(self, fake_checkout):
        rc, calls, out = _install(fake_checkout, "--test", CPU_INDEX_OK="1")
        assert rc == 0, out
        installs = [c for c in calls if c.startswith("-m pip install")][1:]
        assert len(installs) == 2 and "--isolated" in installs[0] and "download.pytorch.org/whl/cpu" in installs[0]
        assert installs[1] == "-m pip install -q -e .[test,learn,docs]"

    def test_without_the_cpu_index_it_falls_back_to_the_pinned_cpu_wheel(self, fake_checkout):
        rc, calls, out = _install(fake_checkout, "--test")
        assert rc == 0, out
        installs = [c for c in calls if c.startswith("-m pip install")][1:]
        assert installs[1:] == ["-m pip install -q torch==2.13.0", "-m pip install -q -e .[test,learn,docs]"]
        assert "out of reach" in out

    def test_an_installed_torch_is_kept_and_a_gpu_gets_the_extra_alone(self, fake_checkout):
        for env, gpu in (({"HAS_TORCH": "1"}, False), ({}, True)):
            rc, calls, out = _install(fake_checkout, "--test", gpu=gpu, **env)
            assert rc == 0, out
            installs = [c for c in calls if c.startswith("-m pip install")][1:]
            assert installs == ["-m pip install -q -e .[test,learn,docs]"], (env, gpu)

    @pytest.mark.parametrize("args", [[], ["--test"]])
    def test_each_long_step_is_announced_before_it_runs(self, fake_checkout, args):
        """No silent minute: a line says what comes before each pip install, the compile and the numba warm-up."""
        # the stand-in python writes each call into the script's own stdout, in order with its lines
        rc, _, out = _install(fake_checkout, *args, CPU_INDEX_OK="1", CALLS="/dev/stdout")
        assert rc == 0, out
        lines = out.splitlines()
        long_steps = [
            i for i, line in enumerate(lines) if line.startswith(("-m pip install", "-m compileall", "-m zbuf_occlude.visibility.warmup"))
        ]
        assert len(long_steps) >= 4, lines
        for i in long_steps:
            assert not lines[i - 1].startswith(("-m ", "-c ")), (lines[i], lines[:i])  # said before it, not after another call

    @pytest.mark.parametrize("args", [["--bogus"], ["--test", "--test"]])
    def test_bad_options_exit_2_before_any_work(self, fake_checkout, args):
        rc, calls, out = _install(fake_checkout, *args)
        assert rc == 2 and calls == [] and "install.sh" in out


def test_extras_take_version_ranges_and_ci_runs_readmes_test_command():
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    torch_req = next(r for r in extras["learn"] if r.startswith("torch"))
    assert "==" not in torch_req and "<" in torch_req and ">=" in torch_req  # a range: a user's torch is kept
    assert not any(r.startswith("torch") for r in project["dependencies"])
    assert {"mkdocs-material", "mkdocstrings[python]"} <= {r.split(">")[0].split("=")[0] for r in extras["docs"]}
    ci = (ROOT / ".ci" / "run").read_text()
    assert "bash scripts/install.sh --test && .venv/bin/python -m pytest -q" in ci


def test_the_package_and_its_cli_import_no_torch():
    code = "import sys, zbuf_occlude, zbuf_occlude.cli.main; zbuf_occlude.cli.main.build_parser(); print('torch' in sys.modules)"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})  # fmt: skip
    assert r.returncode == 0 and r.stdout.strip() == "False", r.stderr
