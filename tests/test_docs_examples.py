"""Every example in README.md and docs/ runs, and the documentation site builds.

Each fenced ```bash and ```python block of README.md and docs/**/*.md is one test (id
``FILE:LINE``).  It runs in a fresh temporary copy of the repository's files (what ``git
ls-files`` lists, plus untracked files git does not ignore; so no ``../shared`` and no build
outputs), with the copy as the working directory, as a user following the pages on a fresh
clone would: **one copy for every page**, the pages one after another (README.md first, then
docs/ in file order) and the blocks of a page in order, so a later block may read what an
earlier one wrote (running one block alone first runs the blocks above it on its page), and an
example that is refused because another page's example wrote the same folder fails.  Examples
write under ``runs/``, each to a folder of its own: a block that leaves anything else new at
the repository root fails.
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
#: The folder under the repository root where the examples write (each to a folder of its own).
EXAMPLE_OUTPUTS = "runs"
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
            body.append(lines[j][len(indent) :] if lines[j].startswith(indent) else lines[j].lstrip())
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
    return block.language == "bash" and any(line.strip().startswith(INSTALL) for line in block.code.splitlines())


def repository_files() -> list[str]:
    """The files a fresh clone would have (tracked, plus untracked files git does not ignore)."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            cwd=ROOT,
            check=True,
            capture_output=True,
        ).stdout
        return [p for p in out.decode("utf-8", "surrogateescape").split("\0") if p and (ROOT / p).is_file()]
    except (OSError, subprocess.CalledProcessError):  # not a git checkout (an sdist): copy the tree
        skip = {".git", ".venv", "site", "__pycache__", ".pytest_cache", ".hypothesis", "out"}
        return [p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*") if p.is_file() and not skip.intersection(p.relative_to(ROOT).parts)]


def numba_cache_files() -> list[str]:
    """The package's compiled kernels in numba's on-disk cache (``__pycache__/*.nbi``, ``*.nbc``), as
    ``scripts/install.sh``'s warm-up leaves them: a reader runs the examples after the install."""
    return [p.relative_to(ROOT).as_posix() for p in (ROOT / "zbuf_occlude").rglob("__pycache__/*.nb[ic]")]


def fresh_copy(dest: Path) -> Path:
    """Copy the repository's files into ``dest``, with the kernels the install compiled (numba finds
    them by the sources' times, which the copy keeps), and give it a ``.venv/bin`` that is this Python."""
    for rel in [*repository_files(), *numba_cache_files()]:
        target = dest / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / rel, target)
    bin_dir = dest / ".venv" / "bin"
    bin_dir.mkdir(parents=True)
    # wrappers, not symlinks: a symlinked venv interpreter would not find its pyvenv.cfg
    exe = shlex.quote(sys.executable)
    for name, line in (
        ("python", f'exec {exe} "$@"'),
        ("python3", f'exec {exe} "$@"'),
        ("zbuf-occlude", f'exec {exe} -m zbuf_occlude "$@"'),
    ):
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
        return subprocess.run(cmd, cwd=copy, env=example_env(copy), capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired as e:
        pytest.fail(f"{block.id}: still running after {TIMEOUT_S:.0f} s (keep examples small)\n{e.stdout or ''}{e.stderr or ''}")


def needs_torch(block: Block) -> bool:
    return bool(re.search(r"\bimport torch\b|\bfrom torch\b|zbuf_occlude\.learn|zbuf-occlude experiment\b", block.code))


BLOCKS = all_blocks()
RUNNABLE = [b for b in BLOCKS if not is_install_block(b)]
INSTALLS = [b for b in BLOCKS if is_install_block(b)]


class _SharedCopy:
    """One fresh copy of the repository for every page, made on first use; remembers which blocks
    have run in it and what its root held before any did."""

    def __init__(self, base: Path):
        self.base = base
        self.root: Path | None = None
        self.done: set[str] = set()  # ids of the blocks that have run
        self.entries: set[str] = set()

    def get(self) -> Path:
        if self.root is None:
            (self.base / "scratch").mkdir(parents=True)
            self.root = fresh_copy(self.base / "repo")
            self.entries = {p.name for p in self.root.iterdir()}
        return self.root

    def new_at_root(self) -> list[str]:
        """What the examples left at the repository root besides ``runs/``."""
        return sorted({p.name for p in self.get().iterdir()} - self.entries - {EXAMPLE_OUTPUTS})


@pytest.fixture(scope="session")
def shared_copy(tmp_path_factory) -> _SharedCopy:
    return _SharedCopy(tmp_path_factory.mktemp("docs_examples"))


@pytest.mark.slow
@pytest.mark.parametrize("block", RUNNABLE, ids=[b.id for b in RUNNABLE])
def test_example_runs(block: Block, shared_copy: _SharedCopy) -> None:
    if needs_torch(block) and importlib.util.find_spec("torch") is None:
        pytest.skip("needs torch (pip install -e '.[learn]')")
    copy = shared_copy.get()
    scratch = copy.parent / "scratch"
    # the blocks above this one on the same page, as a reader would have run them
    for earlier in (b for b in RUNNABLE if b.path == block.path and b.index < block.index and b.id not in shared_copy.done):
        if needs_torch(earlier) and importlib.util.find_spec("torch") is None:
            continue
        r = run_block(earlier, copy, scratch)
        shared_copy.done.add(earlier.id)
        if r.returncode != 0:
            pytest.fail(f"an earlier block of the page, {earlier.id}, failed (exit {r.returncode}):\n{r.stdout}\n{r.stderr}")
    r = run_block(block, copy, scratch)
    shared_copy.done.add(block.id)
    assert r.returncode == 0, f"{block.id} exited {r.returncode}\n--- code\n{block.code}--- stdout\n{r.stdout}\n--- stderr\n{r.stderr}"
    new = shared_copy.new_at_root()
    assert not new, f"{block.id} (or a block above it) left {new} at the repository root: examples write under {EXAMPLE_OUTPUTS}/"


def documented_folder_tree(text: str) -> set[str]:
    """The entries of the folder tree under "## The folder" in docs/guide/outputs.md: the first
    word of each line indented by two spaces (``shards/``, ``<name>/``, ``plan.json``)."""
    section = text[text.index("## The folder") :]
    block = section[section.index("```text") :]
    block = block[: block.index("```", 3)]
    return {m[1] for m in re.finditer(r"^  (\S+)", block, re.MULTILINE)}


@pytest.mark.slow
def test_the_documented_folder_tree_is_what_generate_and_farm_write(tmp_path: Path) -> None:
    """docs/guide/outputs.md's tree, entry for entry, against real runs of generate (h5, npz) and
    farm: each run writes exactly the entries the page says it writes, and nothing else."""
    import json

    from zbuf_occlude.cli.main import main

    tree = documented_folder_tree((ROOT / "docs" / "guide" / "outputs.md").read_text(encoding="utf-8"))
    meshes = [str(ROOT / "data" / "samples" / rel) for rel in ("chair/train/chair_0001.off", "sofa/test/sofa_0681.off")]
    small = ["--views", "0:0", "--points", "64", "--samples-per-view", "1", "--dense-points", "1000", "--resolution", "64"]
    runs = {
        "generate --format h5": (["generate", *meshes, *small], tree - {"<name>/"}),
        "generate --format npz": (["generate", *meshes, *small, "--format", "npz"], tree - {"occluded_train.h5", "occluded_test.h5", "shards/"}),
        "farm": (["farm", str(ROOT / "data" / "samples"), "--classes", "chair,sofa", "--per-class", "1", *small, "--no-progress"],
                 tree - {"occluded_train.h5", "occluded_test.h5", "<name>/"}),
    }  # fmt: skip
    for i, (what, (argv, expected)) in enumerate(runs.items()):
        out = tmp_path / f"run{i}"
        assert main([*argv, "--out", str(out)]) == 0, what
        names = {json.loads(line)["name"].split("/")[0] + "/" for line in (out / "manifest.jsonl").read_text().splitlines()}
        written = {p.name + "/" * p.is_dir() for p in out.iterdir() if not p.name.startswith(".")}
        written = (written - names) | ({"<name>/"} if written & names else set())
        assert written == expected, (
            f"{what}: written but not in the tree {sorted(written - expected)}, in the tree but not written {sorted(expected - written)}"
        )


def test_examples_write_under_runs_each_to_a_folder_of_its_own() -> None:
    """Every ``--out`` of a runnable example is a folder under ``runs/``, and no two pages write
    the same one (a page may come back to its own folder: a resume, a merge)."""
    pages_of: dict[str, set[str]] = {}
    for block in RUNNABLE:
        for out in re.findall(r"--out[ =](\S+)", block.code):
            assert out.startswith(f"{EXAMPLE_OUTPUTS}/"), f"{block.id}: --out {out} is not under {EXAMPLE_OUTPUTS}/"
            pages_of.setdefault(out.rstrip("/"), set()).add(block.path)
    shared = {out: sorted(pages) for out, pages in pages_of.items() if len(pages) > 1}
    assert not shared, f"folders written by the examples of several pages: {shared}"
    assert len(pages_of) > 10  # the examples were found


def _ci_commands() -> list[str]:
    """The commands of .ci/run, without comments, ``set`` and ``cd`` lines."""
    lines = (ROOT / ".ci" / "run").read_text().splitlines()
    return [step.strip() for ln in lines if ln.strip() and not ln.lstrip().startswith(("#", "set ", "cd ")) for step in ln.split("&&")]


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


def heading_slugs(text: str) -> set[str]:
    """The anchors of a Markdown page's headings, as the site's ``toc`` extension makes them
    (Python-Markdown's ``slugify``: NFKD to ASCII, punctuation dropped, lower case, runs of spaces
    and hyphens to one hyphen; an explicit ``{#id}`` wins), headings inside code fences left out."""
    import unicodedata

    slugs, fence = set(), None
    for line in text.splitlines():
        m = FENCE.match(line)
        if m and (fence is None or (m["fence"][0] == fence[0] and len(m["fence"]) >= len(fence) and not m["info"].strip())):
            fence = m["fence"] if fence is None else None
            continue
        heading = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line) if fence is None else None
        if not heading:
            continue
        title = heading[1]
        explicit = re.search(r"\{[^}]*#([\w-]+)[^}]*\}\s*$", title)
        if explicit:
            slugs.add(explicit[1])
            continue
        title = re.sub(r"<[^>]+>", "", re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", title))  # link text, no tags
        value = unicodedata.normalize("NFKD", title).encode("ascii", "ignore").decode("ascii")
        slugs.add(re.sub(r"[-\s]+", "-", re.sub(r"[^\w\s-]", "", value).strip().lower()))
    return slugs


def test_heading_slugs_are_the_sites() -> None:
    text = "# Padding and `n_visible`\n## LiDAR crops: `farm --sensor`\n```bash\n# not a heading\n```\n### The paper's shape {#shape}\n"
    assert heading_slugs(text) == {"padding-and-n_visible", "lidar-crops-farm-sensor", "shape"}


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_links_to_a_section_find_its_heading(path: Path) -> None:
    """Every link ``[..](PAGE.md#anchor)`` or ``[..](#anchor)`` names a heading that exists (a
    link to a README section that was renamed or never written leads nowhere), and no page
    sends the reader to a README section by its quoted title unless the README has it."""
    text = path.read_text(encoding="utf-8")
    broken = []
    for target, anchor in re.findall(r"\]\(([^)\s#]*)#([^)\s]+)\)", text):
        if "://" in target or (target and not target.endswith(".md")):
            continue
        page = (path.parent / target).resolve() if target else path
        if not page.is_file() or anchor not in heading_slugs(page.read_text(encoding="utf-8")):
            broken.append(f"{target}#{anchor}")
    assert not broken, f"{path.relative_to(ROOT)}: links to sections that do not exist: {broken}"
    readme = {h.lower() for h in re.findall(r"^#{1,6}\s+(.+?)\s*$", (ROOT / "README.md").read_text(encoding="utf-8"), re.MULTILINE)}
    named = re.findall(r"README\s*\(?[\"“]([^\"”]+)[\"”]", text)
    assert not [n for n in named if n.lower() not in readme], f"{path.relative_to(ROOT)}: names README sections it lacks: {named}"


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_user_docs_name_no_issue_numbers(path: Path) -> None:
    """Users cannot follow "(issue 12)" or "the default before issue 11": no tracker references."""
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        assert not re.search(r"\bissues? #?\d+|\(#\d+\)", line, re.IGNORECASE), f"{path.name}:{n}: {line}"


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_mesh_format_lists_name_every_format(path: Path) -> None:
    """A paragraph that lists mesh formats (three of OFF, OBJ, PLY, STL, as names or extensions)
    names glTF and COLLADA too (``.gltf``, ``.glb``, ``.dae`` where it lists extensions)."""
    from zbuf_occlude.mesh.formats import SUPPORTED_EXTENSIONS

    for paragraph in re.split(r"\n\s*\n", path.read_text(encoding="utf-8")):
        extensions = set(re.findall(r"(?<![\w/])\.(?:off|obj|ply|stl)\b", paragraph, re.IGNORECASE))
        if len({e.lower() for e in extensions}) >= 3:
            missing = [e for e in SUPPORTED_EXTENSIONS if not re.search(rf"(?<![\w/]){re.escape(e)}\b", paragraph, re.IGNORECASE)]
            assert not missing, f"{path.name}: lists mesh extensions without {missing}:\n{paragraph}"
        every_extension = all(re.search(rf"(?<![\w/]){re.escape(e)}\b", paragraph, re.IGNORECASE) for e in SUPPORTED_EXTENSIONS)
        if len(set(re.findall(r"\b(?:OFF|OBJ|PLY|STL)\b", paragraph))) >= 3 and not every_extension:
            assert "glTF" in paragraph and "COLLADA" in paragraph, f"{path.name}: lists mesh formats without glTF or COLLADA:\n{paragraph}"


def test_the_examples_are_found() -> None:
    """The extractor sees the blocks (a broken parser must not pass by running nothing)."""
    sample = 'text\n```bash\necho a\n```\n\n  ```python title="x.py"\n  print(1)\n  ```\n```text\nnot run\n```\n'
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


@pytest.mark.slow
def test_the_documentation_site_builds_strict(tmp_path: Path) -> None:
    missing = _mkdocs_missing()
    if missing:
        pytest.skip(f"{missing} is not installed (pip install -e '.[docs]')")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "--config-file",
            str(ROOT / "mkdocs.yml"),
            "--site-dir",
            str(tmp_path / "site"),
        ],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    # every public name has an entry on the API page, or a link from it to its entry on a module's
    # page (the listing leaves out a name that is also a module's, like ``scan``, and a constant
    # without a docstring, like ``DEFAULT_RADIUS``)
    import zbuf_occlude as zo

    anchor = r'id="(zbuf_occlude\.[\w.]+)"'
    every_entry = {a for page in (tmp_path / "site" / "api").rglob("*.html") for a in re.findall(anchor, page.read_text(encoding="utf-8"))}
    html = (tmp_path / "site" / "api" / "index.html").read_text(encoding="utf-8")
    reached = set(re.findall(anchor, html)) | (set(re.findall(r'href="[^"#]*#(zbuf_occlude\.[\w.]+)"', html)) & every_entry)
    missing = [name for name in zo.__all__ if name != "__version__" and not any(a.split(".")[-1] == name for a in reached)]
    assert not missing, f"public names without an entry on the API page: {missing}"


def test_the_api_index_names_every_public_name() -> None:
    """docs/api/index.md's table names every name of ``zo.__all__`` as ``zo.NAME``."""
    import zbuf_occlude as zo

    text = (ROOT / "docs" / "api" / "index.md").read_text(encoding="utf-8")
    missing = [name for name in zo.__all__ if not re.search(rf"`zo\.{re.escape(name)}`", text)]
    assert not missing, f"docs/api/index.md does not name {missing}"


def _exported(package: str) -> set[str]:
    """The names ``package`` exports (its ``__all__``; ``zbuf_occlude``'s: the ``zo.NAME`` names)."""
    import importlib

    return set(getattr(importlib.import_module(package), "__all__", ()))


def internal_imports_of_public_names(code: str) -> list[str]:
    """``from zbuf_occlude.X.Y import NAME`` in an example where a package above the module exports
    NAME (``zo.NAME`` of ``zo.__all__``, or ``zbuf_occlude.X``'s ``__all__``): the examples show the
    public route, ``zo.NAME`` or ``from zbuf_occlude.X import NAME``; each found import is given with it."""
    import ast

    try:
        tree = ast.parse(code)
    except SyntaxError:
        return []
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("zbuf_occlude."):
            parents = [node.module.rsplit(".", depth)[0] for depth in range(node.module.count("."), 0, -1)]  # shallowest first
            for alias in node.names:
                public = next((p for p in parents if alias.name in _exported(p)), None)
                if public:
                    found.append(
                        f"from {node.module} import {alias.name} -> "
                        + (f"zo.{alias.name}" if public == "zbuf_occlude" else f"from {public} import {alias.name}")
                    )
    return found


def test_internal_imports_of_public_names_are_found() -> None:
    code = (
        "import zbuf_occlude as zo\nfrom zbuf_occlude.geometry.cameras import camera_on_sphere\nfrom zbuf_occlude.protocols import project\n"
        "from zbuf_occlude.io.clouds import read_npz\nfrom zbuf_occlude.io import write_npz\nfrom zbuf_occlude.learn.models import PointNet\n"
    )
    assert internal_imports_of_public_names(code) == [
        "from zbuf_occlude.geometry.cameras import camera_on_sphere -> zo.camera_on_sphere",
        "from zbuf_occlude.io.clouds import read_npz -> from zbuf_occlude.io import read_npz",
    ]


@pytest.mark.parametrize("block", [b for b in RUNNABLE if b.language == "python"], ids=lambda b: b.id)
def test_python_examples_use_the_public_name(block: Block) -> None:
    assert not internal_imports_of_public_names(block.code), (
        f"{block.id}: use the public names: {internal_imports_of_public_names(block.code)}"
    )


def test_visible_mask_quotes_embree_fasts_measured_agreement() -> None:
    """``visible_mask``'s docstring calls ``embree-fast`` near-exact with the agreement of
    docs/results/visibility.md's table (worst mesh, mean), not exact."""
    from zbuf_occlude.visibility.registry import visible_mask

    row = next(ln for ln in (ROOT / "docs" / "results" / "visibility.md").read_text(encoding="utf-8").splitlines()
               if ln.startswith("| `embree-fast` (= `auto`"))  # fmt: skip
    worst, mean = re.findall(r"(\d+\.\d+) %", row)[:2]
    doc = " ".join(visible_mask.__doc__.split())
    assert f"near-exact: it agreed with the oracle on {mean} % of points on average and {worst} % on the worst mesh" in doc, doc
    assert "both exact" not in doc
