"""``experiment elevation|augmentation|sim2real``, ``compare`` and ``elevation-profile`` write through the output layer (io/owned.py).

Per command: a user's file of a name the command writes is refused in one line (exit 2) and left as
it is, with nothing else written (every name is checked before any work); a rerun into the same
folder replaces the command's own files; a sim2real run made before the folder kept a ledger
resumes.  The smallest settings of the commands' own tests.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

pytest.importorskip("torch")

from zbuf_occlude.cli.main import main  # noqa: E402
from zbuf_occlude.errors import BackendUnavailable  # noqa: E402
from zbuf_occlude.experiments.compare.report import COMPARE_OUTPUTS  # noqa: E402
from zbuf_occlude.experiments.table3.common import AUGMENTATION_OUTPUTS, CHECKPOINT_FILES, ELEVATION_OUTPUTS  # noqa: E402
from zbuf_occlude.io.owned import LEDGER_FILE  # noqa: E402

pytestmark = pytest.mark.slow  # the commands render, train or draw figures

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
#: Two classes of two shipped meshes each, one in each split (ModelNet's layout): what Table 3B needs.
TREE = {"chair": {"train": "chair/train/chair_0001.off", "test": "stool/train/stool_0002.off"},
        "table": {"train": "desk/test/desk_0201.off", "test": "table/test/table_0393.off"}}  # fmt: skip
TINY = SAMPLES / "sofa" / "test" / "sofa_0681.off"
MINE = b"my own notes, not an output\n"


@pytest.fixture(scope="module")
def meshes(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("modelnet")
    for cls, splits in TREE.items():
        for split, source in splits.items():
            (root / cls / split).mkdir(parents=True)
            shutil.copy(SAMPLES / source, root / cls / split / Path(source).name)
    return root


@pytest.fixture(scope="module")
def sim2real_inputs(tmp_path_factory) -> tuple[Path, Path]:
    """The meshes and "real" scans of test_sim2real, made once."""
    from test_sim2real import _mesh_root, _real_root

    root = tmp_path_factory.mktemp("sim2real")
    return _mesh_root(root), _real_root(root)


def _gl_or_skip() -> None:
    import zbuf_occlude as zo

    try:
        zo.visible_mask(trimesh.creation.box(), np.zeros((1, 3)) + 0.5, zo.camera_on_sphere(30, 30), "zbuffer", resolution=64)
    except BackendUnavailable as exc:
        pytest.skip(str(exc))


def _argv(command: str, out: Path, meshes: Path | None = None, sim2real: tuple[Path, Path] | None = None) -> list[str]:
    """``command`` writing into ``out`` with its smallest settings (elevation-profile: ``out/ep.png``)."""
    table3 = ["--out", str(out), "--epochs", "1", "--points", "32", "--threads", "1", "--no-progress"]
    if command == "elevation":
        return ["experiment", "elevation", str(meshes), "--model", "pointnet", "--no-profile", *table3]
    if command == "augmentation":
        return ["experiment", "augmentation", str(meshes), "--model", "pointnet", *table3]
    if command == "compare":
        return ["compare", str(TINY), "--methods", "zbuffer,og32", "--dense-points", "200", "--views", "30:45", "--resolution", "64",
                "--resolution-sweep", "64", "--grid-sweep", "8", "--out", str(out), "--no-progress"]  # fmt: skip
    if command == "elevation-profile":
        return ["elevation-profile", str(TINY), "--dense-points", "200", "--azimuths", "1", "--elevations=0,90", "--resolution", "64",
                "--out", str(out / "ep.png"), "--no-progress"]  # fmt: skip
    mesh_root, real = sim2real
    return ["experiment", "sim2real", str(mesh_root), "--real", str(real), "--out", str(out), "--label-map", "Trunk=pole",
            "--points", "32", "--epochs", "1", "--per-class", "4", "--seeds", "1", "--threads", "1", "--no-progress"]  # fmt: skip


#: Names each command writes, a user's file of which is refused (every name, for the cheap refusals).
REFUSED = [
    *(("elevation", name) for name in ELEVATION_OUTPUTS),
    *(("augmentation", name) for name in AUGMENTATION_OUTPUTS if name != "test3.csv"),
    *(("compare", name) for name in COMPARE_OUTPUTS),
    ("elevation-profile", "ep.png"), ("elevation-profile", "ep.csv"),
    ("sim2real", "runs.jsonl"), ("sim2real", "table.md"), ("sim2real", "checkpoints/real_to_real/seed0/best.pt"),
]  # fmt: skip


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()[-1]  # sim2real says each stage on stderr first
    assert err.startswith("zbuf-occlude: error:") and "Traceback" not in err, err
    return err


def _files(out: Path) -> list[str]:
    return sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())


@pytest.mark.parametrize("command, name", REFUSED)
def test_a_users_file_of_a_name_it_writes_is_refused_and_left_as_it_is(tmp_path, capsys, meshes, sim2real_inputs, command, name) -> None:
    if command in ("compare", "elevation-profile"):
        _gl_or_skip()
    out = tmp_path / "out"
    (out / name).parent.mkdir(parents=True)
    (out / name).write_bytes(MINE)
    assert main(_argv(command, out, meshes, sim2real_inputs)) == 2
    err = _one_line_error(capsys)
    assert str(out / name) in err and "not recorded by a run of ours" in err, err
    assert (out / name).read_bytes() == MINE
    assert _files(out) == [name]  # nothing else written: every name is checked first


@pytest.mark.parametrize("command", ["elevation", "compare", "elevation-profile", "sim2real"])
def test_a_rerun_replaces_its_own_files(tmp_path, meshes, sim2real_inputs, command) -> None:
    if command in ("compare", "elevation-profile"):
        _gl_or_skip()
    out = tmp_path / "out"
    argv = _argv(command, out, meshes, sim2real_inputs)
    assert main(argv) == 0
    written = [name for name in _files(out) if not name.startswith(("data/", "."))]  # data/: the farm's and its list's
    first = {name: (out / name).stat().st_ino for name in written}
    assert main(argv) == 0
    assert sorted(f for f in _files(out) if not f.startswith("data/")) == sorted([*written, LEDGER_FILE])
    replaced = [name for name, inode in first.items() if (out / name).stat().st_ino != inode]
    # every file is written anew (a resumed training keeps nothing but its checkpoints' resume point)
    assert {"results.csv", "table.md", "run.json", "report.md", "ep.png", "ep.csv"} & set(written) <= set(replaced)


def test_a_sim2real_run_made_before_the_ledger_resumes_as_before(tmp_path, sim2real_inputs) -> None:
    out = tmp_path / "out"
    argv = _argv("sim2real", out, sim2real=sim2real_inputs)
    assert main(argv) == 0
    (out / LEDGER_FILE).unlink()  # as an earlier version left it
    runs = (out / "runs.jsonl").read_bytes()
    assert main(argv) == 0  # its settings match: its files are ours, and nothing trains again
    assert (out / "runs.jsonl").read_bytes() == runs
    assert "runs.jsonl" in (out / LEDGER_FILE).read_text()


def test_the_checkpoint_names_are_those_training_writes() -> None:
    from zbuf_occlude.learn import training

    assert CHECKPOINT_FILES == training.CHECKPOINT_FILES
