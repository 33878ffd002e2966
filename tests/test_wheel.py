"""The pip route of README.md works, as written: the built wheel, installed in a fresh virtual
environment outside the checkout, runs ``zbuf-occlude generate`` on the GPU path with the wheel's
own shaders; ``pip install .`` from the checkout installs the same package.

The commands are README.md's (its ```text block with ``pip wheel``), run with flags that keep
them offline and inside the test: ``--no-build-isolation`` (the test environment's hatchling
builds), and for the installs ``--no-deps --no-index`` into the fresh environment.  Only after
the install does a ``.pth`` file lend it this environment's site-packages for the dependencies.
A ``.pth`` path line adds a folder without running the ``.pth`` files in it, so an editable
install of the checkout there stays inert, and the commands run from a temporary folder with no
``PYTHONPATH``: the test asserts that ``zbuf_occlude`` and its shaders are imported from the new
environment.  The wheel's file name is also the one a missing extra's message gives where the package's
metadata cannot be read (:func:`zbuf_occlude._version.install_hint`).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import site
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from zbuf_occlude._version import WHEEL_NAME

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
SHADERS = REPO / "zbuf_occlude" / "render" / "shaders"
#: Two shipped meshes, in their ModelNet layout (class/split/name.off).
MESHES = ("bathtub/train/bathtub_0001.off", "sofa/test/sofa_0681.off")
#: A data set small enough for llvmpipe: two poses, one 256-point sample each.
GENERATE = ["--views", "0:0,30:120", "--points", "256", "--samples-per-view", "1", "--dense-points", "4096",
            "--resolution", "256", "--format", "npz", "--seed", "3"]  # fmt: skip
CHECK = """
import sys
from pathlib import Path
import zbuf_occlude as zo
from zbuf_occlude.render.shaders import shader_dir
out = Path(sys.argv[1])
print(zo.__file__)
print(shader_dir())
print(sum(len(zo.OccludedDataset(out, split=split)) for split in ("train", "test")))
"""


def _run(cmd: list[str], cwd: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    done = subprocess.run(cmd, check=False, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{cmd}\n{done.stdout[-2000:]}\n{done.stderr[-4000:]}"
    return done


def readme_pip_commands() -> list[list[str]]:
    """The commands of README.md's pip block (the ```text block with ``pip wheel``), comments dropped."""
    blocks = re.findall(r"^```text\n(.*?)^```$", README.read_text(encoding="utf-8"), re.MULTILINE | re.DOTALL)
    (block,) = [b for b in blocks if "pip wheel" in b]
    return [shlex.split(line, comments=True) for line in block.splitlines() if line.split("#")[0].strip()]


def test_the_readme_gives_the_pip_route_this_test_runs() -> None:
    """What the slow test below runs: a checkout's install, a wheel built into dist/ and installed
    by its file name (this version's, as the messages of a missing extra give it), then generate."""
    commands = readme_pip_commands()
    assert [c[:2] for c in commands] == [["pip", "install"], ["pip", "wheel"], ["pip", "install"], ["zbuf-occlude", "generate"]], commands
    assert commands[0] == ["pip", "install", "."] and commands[1] == ["pip", "wheel", ".", "--no-deps", "-w", "dist"]
    assert commands[2] == ["pip", "install", f"dist/{WHEEL_NAME}"]
    assert f"dist/{WHEEL_NAME}[learn]" in README.read_text(encoding="utf-8")


def test_every_wheel_the_docs_name_is_this_versions() -> None:
    """A version bump leaves no page naming the old wheel (the install commands would fail)."""
    pages = [README, *sorted((REPO / "docs").rglob("*.md"))]
    named = {(page.name, m) for page in pages for m in re.findall(r"zbuf_occlude-[^\s'`\[]*\.whl", page.read_text(encoding="utf-8"))}
    assert {page for page, _ in named} >= {"README.md", "getting-started.md"}
    assert all(m == WHEEL_NAME for _, m in named), sorted(named)


def _pip(command: list[str], *, python: Path | None = None) -> list[str]:
    """A README pip command as this test runs it: this interpreter's pip, the checkout for ``.``,
    offline (``--no-build-isolation``; installs: ``--no-deps --no-index`` into ``python``'s venv)."""
    assert command[0] == "pip", command
    args = [str(REPO) if a == "." else a for a in command[1:]]
    target = ["--python", str(python)] if python is not None else []
    offline = ["--no-deps", "--no-index"] if args[0] == "install" else []
    return [sys.executable, "-m", "pip", *target, *args, *offline, "--no-build-isolation", "-q"]


def _fresh_venv(venv: Path, cwd: Path) -> tuple[Path, Path]:
    """A venv without pip; returns its python and its purelib."""
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=cwd)
    python = venv / "bin" / "python"
    purelib = Path(_run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], cwd=cwd).stdout.strip())
    return python, purelib


def _lend_dependencies(purelib: Path) -> None:
    """The dependencies, lent only now that the package is in (pip saw no zbuf-occlude but ours)."""
    lent = [p for p in site.getsitepackages() if Path(p).is_dir() and Path(p) != purelib]
    (purelib / "zz_test_dependencies.pth").write_text("".join(f"{p}\n" for p in lent))


def _clean_env(venv: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP", "VIRTUAL_ENV")}
    env["PATH"] = os.pathsep.join([str(venv / "bin"), env.get("PATH", "")])
    return env


@pytest.mark.slow
def test_the_readmes_pip_route_installs_a_wheel_that_generates_a_data_set_on_the_gpu_path(tmp_path):
    # Skip only when the build backend truly cannot be imported (the 'test' extra has it);
    # any failed build with hatchling present is a broken package and fails the test.
    pytest.importorskip("hatchling", reason="hatchling (the build backend, in the 'test' extra) is not installed")
    checkout_install, build, install, _generate = readme_pip_commands()
    elsewhere = tmp_path / "elsewhere"  # where the README's dist/ is written and read
    elsewhere.mkdir()
    _run(_pip(build), cwd=elsewhere)
    (wheel,) = (elsewhere / "dist").glob("zbuf_occlude-*.whl")
    assert wheel.name == WHEEL_NAME  # the name README.md and the messages of a missing extra give
    names = set(zipfile.ZipFile(wheel).namelist())
    glsl = sorted(p.name for p in SHADERS.iterdir() if p.suffix in {".glsl", ".comp", ".vert", ".frag"})
    assert glsl and {f"zbuf_occlude/render/shaders/{name}" for name in glsl} <= names, sorted(names)

    venv = tmp_path / "venv"
    python, purelib = _fresh_venv(venv, tmp_path)
    _run(_pip(install, python=python), cwd=elsewhere)
    _lend_dependencies(purelib)

    meshes = tmp_path / "meshes"
    for name in MESHES:
        (meshes / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / "data" / "samples" / name, meshes / name)
    work = tmp_path / "work"
    work.mkdir()
    env = _clean_env(venv)
    out = work / "out"
    # zbuffer-exact: the binning and points shaders, then zbuffer: the rasteriser's and the candidates'
    for method in ("zbuffer-exact", "zbuffer"):
        _run(
            [str(venv / "bin" / "zbuf-occlude"), "generate", str(meshes), "--out", str(out / method), "--method", method, *GENERATE],
            cwd=work,
            env=env,
        )
    for method in ("zbuffer-exact", "zbuffer"):
        package, shaders, samples = _run([str(python), "-c", CHECK, str(out / method)], cwd=work, env=env).stdout.split()
        assert Path(package).is_relative_to(purelib), package
        assert Path(shaders) == purelib / "zbuf_occlude" / "render" / "shaders"
        assert int(samples) == len(MESHES) * 2

    # `pip install .` from the checkout: the same package, shaders included, in a venv of its own.
    # pip --python would build in that venv, which has no hatchling: this pip builds, and installs
    # under the venv's prefix (--ignore-installed: the checkout's editable install is left alone)
    venv = tmp_path / "venv-checkout"
    python, purelib = _fresh_venv(venv, tmp_path)
    _run([*_pip(checkout_install), "--ignore-installed", "--prefix", str(venv)], cwd=REPO)
    _lend_dependencies(purelib)
    package, shaders, samples = _run([str(python), "-c", CHECK, str(out / "zbuffer-exact")], cwd=work, env=_clean_env(venv)).stdout.split()
    assert Path(package).is_relative_to(purelib), package
    assert {p.name for p in Path(shaders).iterdir()} >= set(glsl) and Path(shaders).is_relative_to(purelib)
