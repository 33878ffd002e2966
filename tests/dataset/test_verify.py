"""``verify`` on what ``generate`` writes by default: PointNet's joined files carry SHA-256 too."""

from __future__ import annotations

import json
import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from zbuf_occlude.cli.main import main
from zbuf_occlude.dataset.verify import verify_dataset

REPO_ROOT = Path(__file__).resolve().parents[2]
CHAIR = REPO_ROOT / "data" / "samples" / "chair"


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("gen") / "o"
    assert main(["generate", str(CHAIR), "--views", "0:0,30:90", "--dense-points", "3000", "--points", "256",
                 "--samples-per-view", "2", "--out", str(out)]) == 0  # fmt: skip
    return out


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


@pytest.mark.slow
def test_verify_accepts_what_generate_writes_by_default(generated, capsys):
    assert (generated / "occluded_train.h5").is_file()
    card = json.loads((generated / "dataset_card.json").read_text())
    assert {e["path"] for e in card["joined_files"]} >= {"occluded_train.h5", "train_files.txt"}
    assert main(["verify", str(generated)]) == 0
    assert capsys.readouterr().out.startswith("OK ")


def test_a_zeroed_sample_in_pointnets_file_is_caught(generated, tmp_path):
    ds = _copy(generated, tmp_path / "ds")
    with h5py.File(ds / "occluded_train.h5", "r+") as f:
        data = f["data"]
        assert np.abs(data[0]).sum() > 0
        data[0] = np.zeros_like(data[0])
    report = verify_dataset(ds)
    assert not report.ok
    assert any("occluded_train.h5 differs from its SHA-256 in the card" in p for p in report.problems), report.problems


def test_a_list_file_pointing_elsewhere_is_caught(generated, tmp_path):
    ds = _copy(generated, tmp_path / "ds")
    (ds / "train_files.txt").write_text("shards/train_000000.h5\n")
    problems = verify_dataset(ds).problems
    assert any("train_files.txt differs from its SHA-256" in p for p in problems), problems
    assert any("does not list the same files as the card's joined files" in p for p in problems), problems


def test_a_missing_joined_file_is_caught(generated, tmp_path):
    ds = _copy(generated, tmp_path / "ds")
    (ds / "occluded_train.h5").unlink()
    assert any("joined file occluded_train.h5 is missing" in p for p in verify_dataset(ds).problems)


def test_a_joined_file_named_outside_the_folder_is_refused(generated, tmp_path):
    ds = _copy(generated, tmp_path / "ds")
    card = json.loads((ds / "dataset_card.json").read_text())
    card["joined_files"][0]["path"] = "../outside.h5"
    (ds / "dataset_card.json").write_text(json.dumps(card))
    problems = verify_dataset(ds).problems
    assert any("joined_files" in p and "the path leaves" in p and "outside.h5" not in p for p in problems), problems


# -- verify and the reader refuse the same files -------------------------------------------------
@pytest.fixture(scope="module")
def farmed(tmp_path_factory) -> dict[str, Path]:
    from conftest import tiny_dataset

    root = tmp_path_factory.mktemp("farmed")
    return {storage: tiny_dataset(root / storage, storage) for storage in ("dense", "compact")}


@pytest.fixture(scope="module")
def sample_files(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("npz") / "o"
    assert main(["generate", str(CHAIR / "train" / "chair_0001.off"), "--views", "0:0", "--dense-points", "512",
                 "--points", "32", "--resolution", "64", "--samples-per-view", "1", "--format", "npz",
                 "--out", str(out)]) == 0  # fmt: skip
    return out


def _resign(ds: Path, rel: str) -> None:
    """Record the changed file's SHA-256 and size in the manifest, as the data set's author would."""
    from zbuf_occlude.io.atomic import file_sha256

    lines = [json.loads(s) for s in (ds / "manifest.jsonl").read_text().splitlines()]
    for rec in lines:
        if rel in rec.get("shards", []):
            rec["sha256"][rec["shards"].index(rel)] = file_sha256(ds / rel)
            rec["bytes"] = sum((ds / r).stat().st_size for r in rec["shards"])
    (ds / "manifest.jsonl").write_text("".join(json.dumps(r) + "\n" for r in lines))


def _rewrite_shard(shard: Path, **replace) -> None:
    """The shard again, with some datasets replaced (``None``: left out; a callable: makes it in the new file)."""
    with h5py.File(shard, "r") as f:
        arrays = {k: f[k][()] for k in f}
    shard.unlink()
    with h5py.File(shard, "w") as f:
        for key, value in arrays.items():
            new = replace.get(key, value)
            if callable(new):
                new(f, key, value)
            elif new is not None:
                f[key] = new


def _reader_and_verify_refuse(ds: Path, file: Path, message: str, capsys) -> None:
    from zbuf_occlude import OccludedDataset
    from zbuf_occlude.errors import DatasetFormatError

    with pytest.raises(DatasetFormatError, match=re.escape(str(file)) + f".*{message}"):
        OccludedDataset(ds).to_arrays()
    capsys.readouterr()
    assert main(["verify", str(ds)]) == 1
    err = capsys.readouterr().err
    assert str(file) in err and re.search(message, err), err


def _external_storage(tmp: Path):
    def make(f, key, value):
        (tmp / "secret.bin").write_bytes(np.full(value.size, 7, dtype=np.float32).tobytes())
        f.create_dataset(key, shape=value.shape, dtype=np.float32, external=[(str(tmp / "secret.bin"), 0, value.nbytes)])

    return make


def _external_link(target: str, tmp: Path):
    def make(f, key, value):
        with h5py.File(tmp / "secret.h5", "w") as g:
            g["data"] = np.full(value.shape, 7, dtype=np.float32)
        f[key] = h5py.ExternalLink(target.format(tmp=tmp), "/data")

    return make


def _virtual(tmp: Path):
    def make(f, key, value):
        with h5py.File(tmp / "secret.h5", "w") as g:
            g["data"] = np.full(value.shape, 7, dtype=np.float32)
        layout = h5py.VirtualLayout(shape=value.shape, dtype=np.float32)
        layout[:] = h5py.VirtualSource(str(tmp / "secret.h5"), "data", shape=value.shape)
        f.create_virtual_dataset(key, layout)

    return make


HOSTILE_DATA = {
    "external storage": (_external_storage, "external storage"),
    "external link absolute": (lambda tmp: _external_link("{tmp}/secret.h5", tmp), "external link"),
    "external link ../": (lambda tmp: _external_link("../../secret.h5", tmp), "external link"),
    "soft link": (lambda tmp: lambda f, k, v: (f.create_dataset("p", data=v), f.__setitem__(k, h5py.SoftLink("/p"))), "soft link"),
    "virtual dataset": (_virtual, "virtual dataset"),
    "string data": (lambda tmp: lambda f, k, v: f.create_dataset(k, data=["x"] * len(v), dtype=h5py.string_dtype()), "string values"),
    "integer data": (lambda tmp: lambda f, k, v: f.create_dataset(k, data=v.astype(np.int32)), "integer values"),
}


@pytest.mark.parametrize("how", list(HOSTILE_DATA))
def test_a_shard_whose_data_points_elsewhere_is_refused_by_reader_and_verify(farmed, tmp_path, how, capsys):
    # the author re-signs the shard: its SHA-256 is right, what it points to is not covered
    ds = _copy(farmed["dense"], tmp_path / "a" / "b" / "ds")
    rel = json.loads((ds / "manifest.jsonl").read_text().splitlines()[0])["shards"][0]
    make, message = HOSTILE_DATA[how]
    _rewrite_shard(ds / rel, data=make(tmp_path / "a"))
    _resign(ds, rel)
    _reader_and_verify_refuse(ds, ds / rel, message, capsys)


def test_compact_bits_that_contradict_n_visible_are_refused_not_an_index_error(farmed, tmp_path, capsys):
    ds = _copy(farmed["compact"], tmp_path / "ds")
    rel = json.loads((ds / "manifest.jsonl").read_text().splitlines()[0])["shards"][0]
    _rewrite_shard(ds / rel, visible_bits=lambda f, k, v: f.create_dataset(k, data=np.zeros_like(v)))
    _resign(ds, rel)
    _reader_and_verify_refuse(ds, ds / rel, r"'visible_bits' of pose 0 marks 0 visible points", capsys)


def test_a_dense_shard_declaring_more_rows_than_its_object_has_is_refused(farmed, tmp_path, capsys):
    # 2e7 rows declared in a chunked file of a few KB: read whole it would need 7.5 GB
    ds = _copy(farmed["dense"], tmp_path / "ds")
    rel = json.loads((ds / "manifest.jsonl").read_text().splitlines()[0])["shards"][0]

    def huge(f, key, value):
        f.create_dataset(key, shape=(20_000_000, *value.shape[1:]), dtype=value.dtype, chunks=(1, *value.shape[1:]))

    _rewrite_shard(ds / rel, data=huge, label=huge, elevation_deg=huge, azimuth_deg=huge)
    assert (ds / rel).stat().st_size < 100_000
    _resign(ds, rel)
    said = r"declares shape \(20000000.*but stores 0 bytes"
    _reader_and_verify_refuse(ds, ds / rel, said, capsys)
    _refused_under_a_limit(ds, re.escape(str(ds / rel)) + ".*" + said)


def _huge_rows(f, key, value):
    """A dataset declaring 2e7 rows in chunks never written: a few KB on disk."""
    f.create_dataset(key, shape=(20_000_000, *value.shape[1:]), dtype=value.dtype, chunks=(1, *value.shape[1:]))


def _resign_card(ds: Path, samples_per_view: int) -> None:
    """The card with another ``samples_per_view``, and its SHA-256 file to match, as its author would."""
    from zbuf_occlude.dataset.layout import CARD_FILE, CARD_SHA256_FILE
    from zbuf_occlude.dataset.schema import card_sha256_line
    from zbuf_occlude.io.atomic import file_sha256

    card = json.loads((ds / CARD_FILE).read_text())
    card["params"]["samples_per_view"] = samples_per_view
    (ds / CARD_FILE).write_text(json.dumps(card))
    (ds / CARD_SHA256_FILE).write_text(card_sha256_line(file_sha256(ds / CARD_FILE)))


def _open_limited(ds: Path):
    """Open ``ds`` in a child under a user's 3 GB address-space limit (tests/memory_limit.py)."""
    from memory_limit import HEADROOM_3_GB, OPEN_DATASET, run_python_limited

    return run_python_limited(OPEN_DATASET, args=[ds], headroom=HEADROOM_3_GB)


def _refused_under_a_limit(ds: Path, said: str) -> None:
    """The reader (reading every sample) and ``verify`` refuse ``ds`` in one line matching ``said``
    under a 3 GB address-space limit, never a MemoryError."""
    from memory_limit import HEADROOM_3_GB, OPEN_DATASET, run_cli_limited, run_python_limited

    done = run_python_limited(OPEN_DATASET, args=[ds, "to_arrays"], headroom=HEADROOM_3_GB)
    assert done.returncode == 3 and not done.stderr, done.stdout + done.stderr[-2000:]
    assert len(done.stdout.splitlines()) == 1 and re.search(said, done.stdout), done.stdout
    checked = run_cli_limited(["verify", str(ds)], headroom=HEADROOM_3_GB)
    assert checked.returncode == 1 and re.search(said, checked.stderr) and "Traceback" not in checked.stderr, checked.stderr[-2000:]


def test_a_16_kb_shard_whose_card_promises_2e7_rows_is_refused_before_the_index(farmed, tmp_path, capsys):
    """The card's samples_per_view (re-signed) promises 2e7 samples an object and the shard declares
    them in a few KB: refused by its size before the reader's index of 4e7 samples is built (a
    MemoryError under 3 GB before), plainly and under the limit, by the reader and by verify."""
    ds = _copy(farmed["dense"], tmp_path / "ds")
    for line in (ds / "manifest.jsonl").read_text().splitlines():
        rel = json.loads(line)["shards"][0]
        _rewrite_shard(ds / rel, data=_huge_rows, label=_huge_rows, elevation_deg=_huge_rows, azimuth_deg=_huge_rows)
        assert (ds / rel).stat().st_size < 16_000
        _resign(ds, rel)
    _resign_card(ds, 10_000_000)
    said = r"its object's 20,000,000 samples of 64 points take 15,360,000,000 bytes, more than its shard"
    _reader_and_verify_refuse(ds, ds / "manifest.jsonl", said, capsys)
    _refused_under_a_limit(ds, said)


def test_a_compact_card_promising_2e7_samples_an_object_is_refused_before_the_index(farmed, tmp_path, monkeypatch):
    """Compact storage redraws its samples, so no shard bounds them: the memory of the index is
    checked before it is built (4e7 samples, 3.6 GiB; a MemoryError under 3 GB before)."""
    from zbuf_occlude import OccludedDataset, resources
    from zbuf_occlude.errors import InsufficientMemoryError

    ds = _copy(farmed["compact"], tmp_path / "ds")
    _resign_card(ds, 10_000_000)
    said = (
        rf"the index of {re.escape(str(ds))} \(40,000,000 samples declared by its card's samples_per_view and manifest.jsonl\) needs about"
    )
    done = _open_limited(ds)
    assert done.returncode == 3 and not done.stderr, done.stdout + done.stderr[-2000:]
    assert len(done.stdout.splitlines()) == 1 and re.match(said, done.stdout) and "ulimit -v" in done.stdout, done.stdout
    monkeypatch.setattr(resources, "available_memory", lambda: (1 << 30, "test budget"))  # plainly, as a 1 GiB machine
    with pytest.raises(InsufficientMemoryError, match=said):
        OccludedDataset(ds)


def test_a_shard_declaring_more_than_the_memory_available_is_refused_before_reading(farmed, tmp_path, monkeypatch):

    import zbuf_occlude.dataset.schema as schema
    from zbuf_occlude import resources
    from zbuf_occlude.errors import InsufficientMemoryError

    shard = sorted((farmed["dense"] / "shards").glob("*.h5"))[0]
    monkeypatch.setattr(resources, "available_memory", lambda: (1000, "test budget"))
    monkeypatch.setattr(resources, "MIN_CHECKED_BYTES", 0)  # a small shard, a smaller budget
    with pytest.raises(InsufficientMemoryError, match=rf"the shard {shard} needs about .* more than the 1000 B"):
        schema.open_shard(shard, storage="dense", n_points=64, rows=2, n_poses=2, sensor=False)


@pytest.mark.slow
@pytest.mark.parametrize("damage", ["garbage", "no points", "5 points"])
def test_a_damaged_sample_file_is_refused_by_reader_and_verify(sample_files, tmp_path, damage, capsys):
    ds = _copy(sample_files, tmp_path / "ds")
    rel = json.loads((ds / "manifest.jsonl").read_text().splitlines()[0])["shards"][0]
    file = ds / rel
    if damage == "garbage":
        file.write_bytes(b"PK\x03\x04 not a zip at all")
        message = "not a zip file"
    elif damage == "no points":
        np.savez(file.with_suffix(""), other=np.zeros((32, 3), np.float32))
        message = "no array 'points'"
    else:
        np.savez(file.with_suffix(""), points=np.zeros((5, 3), np.float32))
        message = r"declared \(5, 3\)"
    _resign(ds, rel)
    _reader_and_verify_refuse(ds, file, message, capsys)


# -- top-up points of compact shards ------------------------------------------------------------------
@pytest.fixture(scope="module")
def topped_up(tmp_path_factory) -> dict[str, Path]:
    """Two objects whose poses see fewer than 300 of their 400 dense points: every pose is topped up."""
    from conftest import SAMPLE_MESHES

    from zbuf_occlude.farm import FarmParams, run_farm
    from zbuf_occlude.farm.config import RunOptions

    root = tmp_path_factory.mktemp("topped")
    for rel in ("chair/train/chair_0001.off", "desk/test/desk_0201.off"):
        (root / "meshes" / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / "meshes" / rel).symlink_to(SAMPLE_MESHES / rel)
    out = {}
    for storage in ("dense", "compact"):
        params = FarmParams(views="0:0,30:90", samples_per_view=2, n_points=300, dense_points=400, resolution=64,
                            storage=storage)  # fmt: skip
        run_farm(root / "meshes", root / storage, params=params, options=RunOptions(progress=False))
        out[storage] = root / storage
    return out


def _edit_manifest(ds: Path, edit) -> None:
    lines = [json.loads(s) for s in (ds / "manifest.jsonl").read_text().splitlines()]
    edit(lines[0])
    (ds / "manifest.jsonl").write_text("".join(json.dumps(r) + "\n" for r in lines))


def test_verify_passes_topped_up_data_sets_and_both_storages_read_the_same(topped_up):
    from zbuf_occlude import OccludedDataset

    for storage in ("dense", "compact"):
        report = verify_dataset(topped_up[storage])
        assert report.ok and report.samples == 8, report.problems
    dense, compact = OccludedDataset(topped_up["dense"]), OccludedDataset(topped_up["compact"])
    topped = [dense.metadata(i)["n_topped_up"] for i in range(len(dense))]
    assert min(topped) > 0 and not any(dense.metadata(i)["padded"] for i in range(len(dense)))
    for i in range(len(dense)):
        (a, _, ma), (b, _, mb) = dense[i], compact[i]
        assert np.array_equal(a, b) and ma == mb and len(np.unique(a, axis=0)) == 300


def test_top_up_points_that_contradict_the_manifest_are_refused(topped_up, tmp_path, capsys):
    ds = _copy(topped_up["compact"], tmp_path / "rows")
    rel = json.loads((ds / "manifest.jsonl").read_text().splitlines()[0])["shards"][0]
    _rewrite_shard(ds / rel, topup_points=lambda f, k, v: f.create_dataset(k, data=v[:-1]))  # one point dropped
    _resign(ds, rel)
    _reader_and_verify_refuse(ds, ds / rel, r"'topup_points' has shape .* 'n_topped_up' promises", capsys)
    # the manifest moves a point from the top-up to the dense cloud: the masks say otherwise
    ds = _copy(topped_up["compact"], tmp_path / "moved")

    def move(rec):
        rec["n_topped_up"][0] -= 1
        rec["n_topped_up"][1] += 1

    _edit_manifest(ds, move)
    _reader_and_verify_refuse(ds, ds / rel, r"'visible_bits' of pose 0 marks \d+ visible points.*'n_topped_up'", capsys)


def test_a_manifest_whose_n_topped_up_does_not_fit_n_visible_is_refused(topped_up, tmp_path, capsys):
    from zbuf_occlude import OccludedDataset
    from zbuf_occlude.errors import DatasetFormatError

    for name, edit in (("short", lambda rec: rec["n_topped_up"].pop()),
                       ("above", lambda rec: rec["n_topped_up"].__setitem__(0, rec["n_visible"][0] + 1))):  # fmt: skip
        ds = _copy(topped_up["compact"], tmp_path / name)
        _edit_manifest(ds, edit)
        with pytest.raises(DatasetFormatError, match=r"manifest\.jsonl:1: field 'n_topped_up'"):
            OccludedDataset(ds)
        assert main(["verify", str(ds)]) == 1 and "field 'n_topped_up'" in capsys.readouterr().err


def test_a_format_1_compact_data_set_without_top_up_still_reads_and_verifies(farmed, tmp_path):
    # written before top-up: no topup_points nor n_topped_up in its shards, no n_topped_up in its manifest
    from zbuf_occlude import OccludedDataset

    ds = _copy(farmed["compact"], tmp_path / "old")
    assert all(max(json.loads(s)["n_topped_up"]) == 0 for s in (ds / "manifest.jsonl").read_text().splitlines())
    for s in (ds / "manifest.jsonl").read_text().splitlines():
        rel = json.loads(s)["shards"][0]
        _rewrite_shard(ds / rel, topup_points=None, n_topped_up=None)
        _resign(ds, rel)
    lines = [json.loads(s) for s in (ds / "manifest.jsonl").read_text().splitlines()]
    for rec in lines:
        rec.pop("n_topped_up", None)
    (ds / "manifest.jsonl").write_text("".join(json.dumps(r) + "\n" for r in lines))
    assert verify_dataset(ds).ok
    old, new = OccludedDataset(ds), OccludedDataset(farmed["compact"])
    assert np.array_equal(old.to_arrays()[0], new.to_arrays()[0])
    assert old.metadata(0)["n_topped_up"] == 0


# -- folders verify does not check say what they are ----------------------------------------------------------
def test_verify_of_a_missing_folder_or_a_file_says_so(tmp_path, capsys):
    assert main(["verify", str(tmp_path / "MISSING_DIR")]) == 2
    err = capsys.readouterr().err
    assert f"no such folder: {tmp_path / 'MISSING_DIR'}" in err and "finished" not in err
    (tmp_path / "f.txt").write_text("x")
    assert main(["verify", str(tmp_path / "f.txt")]) == 2
    assert "is a file, not a data set folder" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("protocol", "extra", "kind", "reader"),
    [
        ("pcn", ["--complete-points", "256", "--resolution", "32"], "a PCN pairs folder", "read_arrays_h5"),
        ("modelnet40-c-lidar", ["--severity", "1"], "a ModelNet40-C folder", "data_lidar_<severity>.npy"),
    ],
)
def test_verify_of_a_protocol_folder_names_its_kind_and_reader(tmp_path, capsys, protocol, extra, kind, reader):
    out = tmp_path / "pairs"
    assert main(["generate", str(CHAIR / "train"), "--protocol", protocol, *extra, "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["verify", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{out} is {kind}, not a farm data set" in err and reader in err and f"--protocol {protocol}" in err, err
    assert "not a finished" not in err


def test_verify_of_an_unfinished_farm_run_or_another_folder_says_which(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "plan.json").write_text("{}")
    assert any("an unfinished farm run" in p for p in verify_dataset(tmp_path / "run").problems)
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "protocol.json").write_bytes(b"\xff not json")  # untrusted: no traceback
    problems = verify_dataset(tmp_path / "photos").problems
    assert problems == [f"{tmp_path / 'photos'} has no dataset_card.json: not a data set written by `zbuf-occlude farm` or `generate`"]


@pytest.mark.parametrize(("storage", "sensor"), [("sparse", None), ("compact", "hdl32e")])
def test_a_storage_no_kind_reads_is_refused_by_the_reader_and_a_problem_for_verify(farmed, tmp_path, storage, sensor):
    # a card naming a storage the reader refuses (farm --sensor data sets are dense) cannot pass verify
    from zbuf_occlude import OccludedDataset
    from zbuf_occlude.dataset.schema import card_sha256_line
    from zbuf_occlude.errors import InvalidInputError
    from zbuf_occlude.io.atomic import file_sha256

    ds = _copy(farmed["compact"], tmp_path / "ds")
    card = json.loads((ds / "dataset_card.json").read_text())
    card["storage"], card["params"]["sensor"] = storage, sensor
    (ds / "dataset_card.json").write_text(json.dumps(card))
    (ds / "dataset_card.json.sha256").write_text(card_sha256_line(file_sha256(ds / "dataset_card.json")))
    with pytest.raises(InvalidInputError, match=f"dataset_card.json: unknown storage '{storage}'"):
        OccludedDataset(ds)
    problems = verify_dataset(ds).problems
    assert any(f"unknown storage '{storage}'" in p for p in problems), problems


@pytest.mark.parametrize("storage", ["dense", "compact"])
def test_verify_checks_each_file_as_its_storage_kind_says(farmed, monkeypatch, storage):
    # the kind answers for its files: verify holds no check of its own per storage
    from zbuf_occlude.dataset.storage import storage_kind
    from zbuf_occlude.errors import DatasetFormatError

    def refuse(path, expect):
        raise DatasetFormatError(f"{path.name}: {expect.rows} rows of {expect.n_points} points, refused by the kind")

    monkeypatch.setattr(storage_kind(storage), "check_file", refuse)
    problems = verify_dataset(farmed[storage]).problems
    assert problems and all(p.endswith("refused by the kind") for p in problems), problems
