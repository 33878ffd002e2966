"""A protocol run writes and deletes only its own files inside ``--out`` (zbuf_occlude.io.owned),
whatever a copied folder's ``protocol.json``, ledger or links say."""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

import pytest

from zbuf_occlude.errors import DatasetBusy, InvalidInputError, UnsafePathError, ZbufOccludeError
from zbuf_occlude.io.locks import LOCK_FILE, acquire_lock
from zbuf_occlude.io.owned import LEDGER_FILE
from zbuf_occlude.protocols import ProtocolOptions, get_protocol, run_protocol

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
MESH = "chair/train/chair_0001.off"
PROTOCOL, OPTIONS = get_protocol("modelnet40-c-occlusion"), ProtocolOptions(severity=1)
#: The run's record and shards: ModelNet40-C's runs share a folder, one record per corruption and severity.
RECORD, SHARD = "protocol_modelnet40-c-occlusion-s1.json", "modelnet40-c-occlusion-s1_000000.h5"


@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    """One finished run (its folder is copied by each test, as a user copies a data set)."""
    root = tmp_path_factory.mktemp("first")
    (root / "meshes" / MESH).parent.mkdir(parents=True)
    shutil.copyfile(SAMPLES / MESH, root / "meshes" / MESH)
    run = run_protocol(PROTOCOL, [root / "meshes"], root / "out", OPTIONS, progress=False)
    assert run.done == 1 and not run.failures
    return root


@pytest.fixture
def copied(first_run, tmp_path):
    shutil.copytree(first_run / "meshes", tmp_path / "meshes")
    shutil.copytree(first_run / "out", tmp_path / "out")
    return tmp_path


def _run(root: Path, **kw):
    return run_protocol(PROTOCOL, [root / "meshes"], root / "out", OPTIONS, progress=False, **kw)


@pytest.mark.parametrize("name", ["{victim}/keep", "../victim/keep", "../../victim/keep", "x/../../victim/keep"])
def test_a_protocol_name_from_the_file_never_names_a_file_to_delete(copied, name):
    victim = copied / "victim"
    victim.mkdir()
    for i in range(2):
        (victim / f"keep_{i:06d}.h5").write_text("mine")
    recorded = json.loads((copied / "out" / RECORD).read_text())
    recorded["protocol"] = name.format(victim=victim)
    (copied / "out" / RECORD).write_text(json.dumps(recorded))
    with pytest.raises(InvalidInputError, match="was not written by zbuf_occlude"):
        _run(copied, overwrite=True)
    assert sorted(p.read_text() for p in victim.iterdir()) == ["mine", "mine"]


def test_shards_a_link_to_a_folder_outside_is_refused(tmp_path):
    (tmp_path / "meshes" / MESH).parent.mkdir(parents=True)
    shutil.copyfile(SAMPLES / MESH, tmp_path / "meshes" / MESH)
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / SHARD).write_text("mine")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "shards").symlink_to(outside)
    with pytest.raises(UnsafePathError, match="leads outside"):
        _run(tmp_path)
    assert [p.read_text() for p in outside.iterdir()] == ["mine"]


def test_a_ledger_naming_a_user_file_deletes_nothing(copied):
    notes = copied / "out" / "notes.md"
    notes.write_text("mine")
    with open(copied / "out" / LEDGER_FILE, "a") as fh:
        fh.write(json.dumps({"path": "notes.md", "sha256": "0" * 64, "size": 4}) + "\n")
        fh.write(json.dumps({"path": "shards/../notes.md", "sha256": "0" * 64, "size": 4}) + "\n")
    run = _run(copied, overwrite=True)
    assert run.done == 1 and notes.read_text() == "mine"


def test_an_edited_shard_is_not_deleted_and_nothing_is(copied):
    shard = copied / "out" / "shards" / SHARD
    data = bytearray(shard.read_bytes())
    data[len(data) // 2] ^= 0xFF  # same size, other bytes
    shard.write_bytes(bytes(data))
    before = {p: p.read_bytes() for p in (copied / "out").rglob("*") if p.is_file()}
    with pytest.raises(UnsafePathError, match="does not match its SHA-256"):
        _run(copied, overwrite=True)
    assert {p: p.read_bytes() for p in (copied / "out").rglob("*") if p.is_file()} == before


def test_a_user_file_of_a_name_the_run_writes_is_refused_before_any_work(tmp_path):
    (tmp_path / "meshes" / MESH).parent.mkdir(parents=True)
    shutil.copyfile(SAMPLES / MESH, tmp_path / "meshes" / MESH)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "shape_names.txt").write_text("my classes\n")
    with pytest.raises(InvalidInputError, match="shape_names.txt was not written by a run of ours"):
        _run(tmp_path)
    assert (tmp_path / "out" / "shape_names.txt").read_text() == "my classes\n"
    assert not (tmp_path / "out" / "shards").exists()


def test_a_run_resumes_and_overwrites_its_own_files(copied):
    assert (_run(copied).resumed, _run(copied, overwrite=True).done) == (1, 1)


def test_a_second_writer_is_refused_while_the_lock_is_held(copied):
    lock = acquire_lock(copied / "out" / LOCK_FILE, "test")
    try:
        with pytest.raises(DatasetBusy, match="being written by pid"):
            _run(copied)
    finally:
        lock.release()


@pytest.mark.parametrize("content", ["", "garbage\n", "999999999\n", "not a pid\nhost\n"])
def test_a_dead_or_damaged_lock_is_taken_over(copied, content):
    lock = copied / "out" / LOCK_FILE
    lock.write_text(content)
    os.utime(lock, (time.time() - 60, time.time() - 60))  # left by a run killed a minute ago
    assert _run(copied).resumed == 1


def test_a_fresh_empty_lock_is_a_writer_starting_and_is_not_broken(copied):
    """A writer creates its lock file, then writes its pid: an empty file that young may be one."""
    (copied / "out" / LOCK_FILE).write_text("")
    with pytest.raises(DatasetBusy):
        _run(copied)


def test_every_refusal_is_one_of_ours(copied):
    (copied / "out" / RECORD).write_text("{not json")
    with pytest.raises(ZbufOccludeError):
        _run(copied)


# -- ModelNet40-C: its corruptions and severities share one folder, as its evaluation reads them ------------
def test_corruptions_and_severities_share_one_folder_without_overwrite(first_run, tmp_path):
    import numpy as np

    shutil.copytree(first_run / "meshes", tmp_path / "meshes")
    out = tmp_path / "out"
    runs = [("modelnet40-c-occlusion", 1), ("modelnet40-c-occlusion", 2), ("modelnet40-c-lidar", 1)]
    for name, severity in runs:
        run = run_protocol(get_protocol(name), [tmp_path / "meshes"], out, ProtocolOptions(severity=severity), progress=False)
        assert run.done == 1 and not run.failures
    label = np.load(out / "label.npy")  # ModelNet40-C's loader: data_<corruption>_<severity>.npy beside one label.npy
    for corruption, severity, n_points in (("occlusion", 1, 1024), ("occlusion", 2, 1024), ("lidar", 1, 768)):
        data = np.load(out / f"data_{corruption}_{severity}.npy")
        assert data.shape == (1, n_points, 3) and data.dtype == np.float32 and label.shape == (1, 1)
    again = run_protocol(PROTOCOL, [tmp_path / "meshes"], out, OPTIONS, progress=False)
    assert (again.resumed, again.done) == (1, 0)
    before = (out / "data_occlusion_2.npy").read_bytes()
    run_protocol(PROTOCOL, [tmp_path / "meshes"], out, OPTIONS, progress=False, overwrite=True)  # only severity 1 starts over
    assert (out / "data_occlusion_2.npy").read_bytes() == before
    assert (out / "shards" / "modelnet40-c-occlusion-s2_000000.h5").is_file()


def test_a_run_of_other_meshes_into_a_shared_folder_is_refused(first_run, tmp_path):
    shutil.copytree(first_run / "out", tmp_path / "out")
    (tmp_path / "other" / "desk" / "test").mkdir(parents=True)
    shutil.copyfile(SAMPLES / "desk/test/desk_0201.off", tmp_path / "other" / "desk" / "test" / "desk_0201.off")
    before = (tmp_path / "out" / "label.npy").read_bytes()
    with pytest.raises(InvalidInputError, match="label.npy holds the labels of other meshes"):
        run_protocol(PROTOCOL, [tmp_path / "other"], tmp_path / "out", ProtocolOptions(severity=2), progress=False)
    assert (tmp_path / "out" / "label.npy").read_bytes() == before


def test_an_earlier_versions_protocol_json_naming_files_outside_deletes_nothing(copied):
    """A folder as earlier versions wrote it (protocol.json, no ledger) is adopted only when its record is ours."""
    victim = copied / "victim"
    victim.mkdir()
    (victim / "keep_000000.h5").write_text("mine")
    recorded = json.loads((copied / "out" / RECORD).read_text())
    recorded["protocol"] = "../victim/keep"
    (copied / "out" / "protocol.json").write_text(json.dumps(recorded))
    (copied / "out" / LEDGER_FILE).unlink()
    with pytest.raises(InvalidInputError, match="protocol.json was not written by zbuf_occlude"):
        _run(copied, overwrite=True)
    assert (victim / "keep_000000.h5").read_text() == "mine"
