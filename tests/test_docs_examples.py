"""Every example in README.md and docs/ runs, and the documentation site builds.

Each fenced ```bash and ```python block of README.md and docs/**/*.md is one test (id
``FILE:LINE``).  It runs in a fresh temporary copy of the repository's files (what ``git
ls-files`` lists, plus untracked files git does not ignore; so no ``../shared`` and no build
outputs), with the copy as the working directory, as a user following the page on a fresh
clone would: the blocks of one page run in order in one copy of their own, so a later block
may read what an earlier one wrote (running one block alone first runs the blocks above it).
``python`` and ``zbuf-occlude`` (also as ``.venv/bin/python`` and ``.venv/bin/zbuf-occlude``,
the names the install script creates) resolve to the interpreter running the tests, and the
copy's package comes first on ``PYTHONPATH``.

Blocks tagged ```text or ```console (or anything else) are shown, not run: commands that need
data outside the repository or long compute go there, next to a small runnable version.

The install commands (``bash scripts/install.sh [--test] && ...``) are not run (they install
system packages and a virtual environment); instead the test checks that the script exists
and that the README's test command is the one CI runs (``.ci/run``).
"""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: seconds one block may take; the examples are meant to take a few seconds each
TIMEOUT_S = float(os.environ.get("ZBUF_DOCS_EXAMPLE_TIMEOUT", "180"))
RUN_LANGUAGES = {"bash": "bash", "sh": "bash", "shell": "bash", "python": "python", "py": "python"}
FENCE = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>`{3,}|~{3,})(?P<info>[^`]*)$")
INSTALL = "bash scripts/install.sh"
README_LINES_MAX = 200


@dataclass(frozen=True)
class Block:
    path: str  # relative to the repository root
    line: int  # 1-based line of the opening fence
    language: str  # "bash" or "python"
    code: str
    index: int  # position among the runnable blocks of its page

    @property
    def id(self) -> str:
        return f"{self.path}:{self.line}"


def extract_blocks(text: str, path: str) -> list[Block]:
    """The runnable fenced blocks of one Markdown text, in order.

    A fence opens with three or more backticks (or tildes) and an info string whose first word
    is the language; it closes with a fence of the same character at least as long.  Indented
    fences (inside a list or an admonition) are dedented by the opening fence's indentation.
    """
    blocks: list[Block] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence = m["indent"], m["fence"]
        words = m["info"].strip().strip("{}").split()
        language = words[0].lstrip(".").lower() if words else ""
        body: list[str] = []
        j = i + 1
        while j < len(lines):
            close = FENCE.match(lines[j])
            if close and close["fence"][0] == fence[0] and len(close["fence"]) >= len(fence) and not close["info"].strip():
                break
            body.append(lines[j][len(indent):] if lines[j].startswith(indent) else lines[j].lstrip())
            j += 1
        if language in RUN_LANGUAGES:
            n = sum(1 for b in blocks if b.path == path)
            blocks.append(Block(path, i + 1, RUN_LANGUAGES[language], "\n".join(body) + "\n", n))
        i = j + 1
    return blocks


def doc_files() -> list[Path]:
    """README.md and every Markdown file under docs/."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def all_blocks() -> list[Block]:
    out: list[Block] = []
    for f in doc_files():
        out += extract_blocks(f.read_text(encoding="utf-8"), f.relative_to(ROOT).as_posix())
    return out


def is_install_block(block: Block) -> bool:
    return block.language == "bash" and any(
        line.strip().startswith(INSTALL) for line in block.code.splitlines()
    )


def repository_files() -> list[str]:
    """The files a fresh clone would have (tracked, plus untracked files git does not ignore)."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            cwd=ROOT, check=True, capture_output=True,
        ).stdout
        return [p for p in out.decode("utf-8", "surrogateescape").split("\0") if p and (ROOT / p).is_file()]
    except (OSError, subprocess.CalledProcessError):  # not a git checkout (an sdist): copy the tree
        skip = {".git", ".venv", "site", "__pycache__", ".pytest_cache", ".hypothesis", "out"}
        return [
            p.relative_to(ROOT).as_posix()
            for p in ROOT.rglob("*")
            if p.is_file() and not skip.intersection(p.relative_to(ROOT).parts)
        ]


def fresh_copy(dest: Path) -> Path:
    """Copy the repository's files into ``dest`` and give it a ``.venv/bin`` that is this Python."""
    for rel in repository_files():
        target = dest / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / rel, target)
    bin_dir = dest / ".venv" / "bin"
    bin_dir.mkdir(parents=True)
    # wrappers, not symlinks: a symlinked venv interpreter would not find its pyvenv.cfg
    exe = shlex.quote(sys.executable)
    for name, line in (("python", f'exec {exe} "$@"'), ("python3", f'exec {exe} "$@"'),
                       ("zbuf-occlude", f'exec {exe} -m zbuf_occlude "$@"')):
        (bin_dir / name).write_text(f"#!/bin/sh\n{line}\n")
        (bin_dir / name).chmod(0o755)
    return dest


def example_env(copy: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{copy / '.venv' / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join([str(copy), *filter(None, [env.get("PYTHONPATH", "")])])
    env["MPLBACKEND"] = "Agg"
    env.pop("VIRTUAL_ENV", None)
    return env


def run_block(block: Block, copy: Path, scratch: Path) -> subprocess.CompletedProcess:
    script = scratch / f"{block.path.replace('/', '_')}_{block.line}.{'sh' if block.language == 'bash' else 'py'}"
    if block.language == "bash":
        script.write_text("set -euo pipefail\n" + block.code)
        cmd = ["bash", str(script)]
    else:
        script.write_text(block.code)
        cmd = [sys.executable, str(script)]
    try:
        return subprocess.run(
            cmd, cwd=copy, env=example_env(copy), capture_output=True, text=True, timeout=TIMEOUT_S
        )
    except subprocess.TimeoutExpired as e:
        pytest.fail(f"{block.id}: still running after {TIMEOUT_S:.0f} s (keep examples small)\n{e.stdout or ''}{e.stderr or ''}")


def needs_torch(block: Block) -> bool:
    return bool(re.search(r"\bimport torch\b|\bfrom torch\b|zbuf_occlude\.learn|zbuf-occlude experiment\b", block.code))


BLOCKS = all_blocks()
RUNNABLE = [b for b in BLOCKS if not is_install_block(b)]
INSTALLS = [b for b in BLOCKS if is_install_block(b)]


class _Pages:
    """One fresh copy per page; remembers which of its blocks have run there."""

    def __init__(self, base: Path):
        self.base = base
        self.copies: dict[str, tuple[Path, set[int]]] = {}

    def copy_for(self, path: str) -> tuple[Path, set[int]]:
        if path not in self.copies:
            d = self.base / re.sub(r"[^A-Za-z0-9_.-]", "_", path)
            (d / "scratch").mkdir(parents=True)
            self.copies[path] = (fresh_copy(d / "repo"), set())
        return self.copies[path]


@pytest.fixture(scope="session")
def pages(tmp_path_factory) -> _Pages:
    return _Pages(tmp_path_factory.mktemp("docs_examples"))


@pytest.mark.parametrize("block", RUNNABLE, ids=[b.id for b in RUNNABLE])
def test_example_runs(block: Block, pages: _Pages) -> None:
    if needs_torch(block) and importlib.util.find_spec("torch") is None:
        pytest.skip("needs torch (pip install -e '.[learn]')")
    copy, done = pages.copy_for(block.path)
    scratch = copy.parent / "scratch"
    # the blocks above this one on the same page, as a reader would have run them
    for earlier in (b for b in RUNNABLE if b.path == block.path and b.index < block.index and b.index not in done):
        if needs_torch(earlier) and importlib.util.find_spec("torch") is None:
            continue
        r = run_block(earlier, copy, scratch)
        done.add(earlier.index)
        if r.returncode != 0:
            pytest.fail(f"an earlier block of the page, {earlier.id}, failed (exit {r.returncode}):\n{r.stdout}\n{r.stderr}")
    r = run_block(block, copy, scratch)
    done.add(block.index)
    assert r.returncode == 0, f"{block.id} exited {r.returncode}\n--- code\n{block.code}--- stdout\n{r.stdout}\n--- stderr\n{r.stderr}"


def _ci_commands() -> list[str]:
    """The commands of .ci/run, without comments, ``set`` and ``cd`` lines."""
    lines = (ROOT / ".ci" / "run").read_text().splitlines()
    return [
        step.strip() for ln in lines
        if ln.strip() and not ln.lstrip().startswith(("#", "set ", "cd "))
        for step in ln.split("&&")
    ]


@pytest.mark.parametrize("block", INSTALLS, ids=[b.id for b in INSTALLS])
def test_install_commands_are_the_ones_ci_runs(block: Block) -> None:
    """Install blocks are checked, not run: the script exists, and a block that installs and then
    runs the tests runs them exactly as CI does."""
    ci = _ci_commands()
    for line in (ln.strip() for ln in block.code.splitlines()):
        if not line.startswith(INSTALL):
            continue
        script = shlex.split(line.split("&&")[0])[1]
        assert (ROOT / script).is_file(), f"{block.id}: {script} does not exist"
        steps = [s.strip() for s in line.split("&&")]
        if any("pytest" in s for s in steps):
            assert steps == ci, f"{block.id}: the test command {line!r} is not what .ci/run runs: {ci}"


def test_the_readme_has_the_two_commands_and_ci_runs_the_second() -> None:
    readme_installs = [b for b in INSTALLS if b.path == "README.md"]
    lines = [ln.strip() for b in readme_installs for ln in b.code.splitlines() if ln.strip().startswith(INSTALL)]
    assert any("pytest" not in ln and "zbuf-occlude generate" in ln for ln in lines), lines
    assert any("pytest" in ln for ln in lines), lines
    assert any(c.startswith(INSTALL) for c in _ci_commands())


def test_readme_is_short() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= README_LINES_MAX


def test_readme_links_exist() -> None:
    """README is read on the repository's page, outside the site's strict build: its relative
    links (docs pages, the figure) must point at files that exist."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)\s#]+)(?:#[^)]*)?\)", text)
    assert targets
    missing = [t for t in targets if "://" not in t and not (ROOT / t).exists()]
    assert not missing, missing


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_user_docs_name_no_issue_numbers(path: Path) -> None:
    """Users cannot follow "(issue 12)" or "the default before issue 11": no tracker references."""
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        assert not re.search(r"\bissues? #?\d+|\(#\d+\)", line, re.IGNORECASE), f"{path.name}:{n}: {line}"


def test_the_examples_are_found() -> None:
    """The extractor sees the blocks (a broken parser must not pass by running nothing)."""
    sample = "text\n```bash\necho a\n```\n\n  ```python title=\"x.py\"\n  print(1)\n  ```\n```text\nnot run\n```\n"
    got = extract_blocks(sample, "x.md")
    assert [(b.line, b.language, b.code) for b in got] == [(2, "bash", "echo a\n"), (6, "python", "print(1)\n")]
    assert any(b.path == "README.md" and b.language == "python" for b in BLOCKS)
    assert any(b.path == "README.md" and b.language == "bash" and not is_install_block(b) for b in BLOCKS)


def _mkdocs_missing() -> str | None:
    for module, extra in (("mkdocs", "mkdocs"), ("material", "mkdocs-material"), ("mkdocstrings_handlers.python", "mkdocstrings[python]")):
        try:
            if importlib.util.find_spec(module) is None:
                return extra
        except ModuleNotFoundError:
            return extra
    return None


def test_the_documentation_site_builds_strict(tmp_path: Path) -> None:
    missing = _mkdocs_missing()
    if missing:
        pytest.skip(f"{missing} is not installed (pip install -e '.[docs]')")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    r = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml"),
         "--site-dir", str(tmp_path / "site")],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "site" / "api" / "index.html").is_file()
