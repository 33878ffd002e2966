"""``--overwrite`` deletes a file a record names only when it is that object's own file, inside
``--out``, still as recorded (zbuf_occlude.farm.ownership through zbuf_occlude.io.owned); a
refusal is one line and deletes nothing."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from conftest import SAMPLE_MESHES

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.dataset.layout import PLAN_FILE

CHAIR = SAMPLE_MESHES / "chair/train/chair_0001.off"
SMALL = ["--views", "0:0", "--dense-points", "500", "--samples-per-view", "1", "--points", "64", "--resolution", "64"]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """A finished farm and a finished ``generate --format npz`` run, copied by each test."""
    root = tmp_path_factory.mktemp("built")
    (root / "meshes" / "chair" / "train").mkdir(parents=True)
    shutil.copy(CHAIR, root / "meshes" / "chair" / "train" / "chair_0001.off")
    assert cli_main(["farm", str(root / "meshes"), "--out", str(root / "farm"), *SMALL, "--no-progress"]) == 0
    assert cli_main(["generate", str(root / "meshes"), "--out", str(root / "npz"), *SMALL, "--format", "npz", "--no-progress"]) == 0
    return root


def _copy(built: Path, tmp_path: Path, which: str) -> tuple[Path, Path]:
    shutil.copytree(built / "meshes", tmp_path / "meshes")
    shutil.copytree(built / which, tmp_path / which)
    return tmp_path / "meshes", tmp_path / which


def _snapshot(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _edit_record(out: Path, **fields) -> None:
    path = out / "records" / "000000.json"
    rec = json.loads(path.read_text())
    rec.update(fields)
    path.write_text(json.dumps(rec))


def _overwrite(cmd: str, src: Path, out: Path, *extra: str) -> int:
    return cli_main([cmd, str(src), "--out", str(out), *SMALL, "--overwrite", "--no-progress", *extra])


@pytest.mark.parametrize(
    "named", ["notes.md", ".", "plan.json", "records", "../outside.txt", "shards/../notes.md", "shards/train_000001.h5"]
)
def test_a_record_naming_another_file_deletes_nothing(built, tmp_path, capsys, named):
    src, out = _copy(built, tmp_path, "farm")
    (out / "notes.md").write_text("mine")
    (tmp_path / "outside.txt").write_text("mine")
    (out / "shards" / "train_000001.h5").write_text("mine")
    _edit_record(out, shards=[named], sha256=["0" * 64])
    before, outside = _snapshot(out), (tmp_path / "outside.txt").read_text()
    assert _overwrite("farm", src, out) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1 and "records/000000.json" in err, err
    assert _snapshot(out) == before and outside == "mine"


def test_a_recorded_shard_changed_since_is_not_deleted(built, tmp_path, capsys):
    src, out = _copy(built, tmp_path, "farm")
    shard = out / "shards" / "train_000000.h5"
    data = bytearray(shard.read_bytes())
    data[len(data) // 2] ^= 0xFF
    shard.write_bytes(bytes(data))
    before = _snapshot(out)
    assert _overwrite("farm", src, out) == 2
    assert "does not match its SHA-256" in capsys.readouterr().err
    assert _snapshot(out) == before


def test_a_record_naming_a_sample_file_of_another_object_is_refused(built, tmp_path, capsys):
    src, out = _copy(built, tmp_path, "npz")
    (out / "other").mkdir()
    (out / "other" / "other_v000_el+000_az000_s00.npz").write_text("mine")
    _edit_record(out, shards=["other/other_v000_el+000_az000_s00.npz"], sha256=[None])
    assert _overwrite("generate", src, out, "--format", "npz") == 2
    assert (out / "other" / "other_v000_el+000_az000_s00.npz").read_text() == "mine"


@pytest.mark.parametrize("which,extra", [("farm", []), ("npz", ["--format", "npz"])])
def test_overwrite_of_an_untouched_run_still_starts_over(built, tmp_path, which, extra):
    src, out = _copy(built, tmp_path, which)
    before = _snapshot(out)
    assert _overwrite("generate" if which == "npz" else "farm", src, out, *extra) == 0
    assert (out / PLAN_FILE).is_file() and set(_snapshot(out)) == set(before)
