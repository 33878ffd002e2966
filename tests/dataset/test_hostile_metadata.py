"""Hostile data-set files: a sparse file where a shard goes, deep JSON in the metadata.

A shard swapped for a sparse 1 TB file must be refused from its size, before a byte of it is
hashed (io.atomic.size_mismatch, the one check before every hash); JSON nested thousands of
levels deep is one line naming the file (io.json_files.loads_json), never a RecursionError.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import SAMPLE_MESHES

import zbuf_occlude.io.atomic as atomic
from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.dataset.layout import CARD_FILE, MANIFEST_FILE, PROTOCOL_FILE
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.dataset.verify import verify_dataset
from zbuf_occlude.errors import DatasetFormatError

SMALL = ["--views", "0:0", "--dense-points", "500", "--samples-per-view", "1", "--points", "64", "--resolution", "64"]
DEEP = "[" * 50_000 + "]" * 50_000


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ds") / "farm"
    assert cli_main(["farm", str(SAMPLE_MESHES / "chair"), "--out", str(out), *SMALL, "--no-progress"]) == 0
    return out


@pytest.fixture
def copy(dataset: Path, tmp_path: Path) -> Path:
    import shutil

    target = tmp_path / "copy"
    shutil.copytree(dataset, target)
    return target


def _no_hashing(monkeypatch) -> None:
    """Hashing a file larger than 100 MB fails the test (the card and small files may be hashed)."""
    real = atomic.file_sha256

    def refuse(path, **kwargs):
        if Path(path).stat().st_size > 10**8:
            raise AssertionError(f"hashed {path}")
        return real(path, **kwargs)

    for module in ("zbuf_occlude.io.atomic", "zbuf_occlude.dataset.verify", "zbuf_occlude.farm.journal"):
        monkeypatch.setattr(f"{module}.file_sha256", refuse)


def _sparse_shard(root: Path) -> Path:
    rec = json.loads((root / MANIFEST_FILE).read_text().splitlines()[0])
    shard = root / rec["shards"][0]
    with open(shard, "r+b") as fh:
        fh.truncate(10**12)  # a hole: no disk, but 1 TB to read
    return shard


@pytest.mark.slow
def test_verify_refuses_a_sparse_shard_from_its_size_without_reading_it(copy, monkeypatch):
    _sparse_shard(copy)
    _no_hashing(monkeypatch)
    report = verify_dataset(copy)
    assert not report.ok
    assert any("1,000,000,000,000 bytes where the record says" in p for p in report.problems), report.problems


def test_the_reader_refuses_a_sparse_shard_when_it_opens_the_data_set(copy, monkeypatch):
    _sparse_shard(copy)
    _no_hashing(monkeypatch)
    with pytest.raises(DatasetFormatError, match="bytes where the record says"):
        OccludedDataset(copy)


@pytest.mark.slow
def test_a_resumed_farm_redoes_a_sparse_shard_without_hashing_it(copy, monkeypatch):
    shard = _sparse_shard(copy)
    calls = []
    real = atomic.file_sha256

    def counted(path, **kwargs):
        calls.append(Path(path))
        return real(path, **kwargs)

    monkeypatch.setattr("zbuf_occlude.farm.journal.file_sha256", counted)
    assert cli_main(["farm", str(SAMPLE_MESHES / "chair"), "--out", str(copy), *SMALL, "--no-progress"]) == 0
    assert shard not in calls and shard.stat().st_size < 10**9


@pytest.mark.slow
def test_verify_refuses_a_sparse_joined_file_without_reading_it(tmp_path, monkeypatch):
    out = tmp_path / "gen"
    assert cli_main(["generate", str(SAMPLE_MESHES / "chair"), "--out", str(out), *SMALL]) == 0
    card = json.loads((out / CARD_FILE).read_text())
    joined = out / next(e["path"] for e in card["joined_files"] if e["path"].endswith(".h5"))
    with open(joined, "r+b") as fh:
        fh.truncate(10**12)
    _no_hashing(monkeypatch)
    report = verify_dataset(out)
    assert any("more than the shards of its split" in p for p in report.problems), report.problems


def test_a_deep_protocol_json_is_not_a_traceback(tmp_path, capsys):
    (tmp_path / PROTOCOL_FILE).write_text('{"protocol": ' + DEEP + "}")
    status = cli_main(["verify", str(tmp_path)])
    err = capsys.readouterr().err
    assert status in (1, 2) and "Traceback" not in err


@pytest.mark.parametrize("where", ["card", "manifest"])
def test_deep_json_in_a_data_set_is_one_line_naming_the_file(copy, capsys, where):
    if where == "card":
        (copy / CARD_FILE).write_text('{"extra": ' + DEEP + "}")
        (copy / (CARD_FILE + ".sha256")).unlink()
    else:
        (copy / MANIFEST_FILE).write_text('{"status": "ok", "x": ' + DEEP + "}\n")
    with pytest.raises(DatasetFormatError, match=CARD_FILE if where == "card" else MANIFEST_FILE):
        OccludedDataset(copy)
    status = cli_main(["verify", str(copy)])
    err = capsys.readouterr().err + capsys.readouterr().out
    assert status in (1, 2) and "Traceback" not in err and "RecursionError" not in err
