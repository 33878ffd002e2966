"""``export --to pcn`` reads its source through the reading layer, as a hostile shared folder would
try it: shards whose data live in other files (external links, virtual datasets, external raw
storage), shards that declare what they do not store or what no pcn run writes, links out of the
folder, FIFOs, ``protocol.json`` too large or nested; each refused in one line naming the file,
before ``--out`` is made, and no byte of another file in a ``.pcd``."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import SAMPLE_MESHES

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.errors import DatasetFormatError, InsufficientMemoryError, InvalidInputError, UnsafePathError
from zbuf_occlude.exporters import export
from zbuf_occlude.protocols import get_protocol, run_protocol
from zbuf_occlude.protocols.pcn import COMPLETE_POINTS

MESHES = ("chair/train/chair_0001.off", "desk/test/desk_0201.off")
#: A value no shard holds: a .pcd holding it holds another file's bytes.
SECRET = 4242.0


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("pcn")
    for rel in MESHES:
        (root / "meshes" / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(SAMPLE_MESHES / rel, root / "meshes" / rel)
    run = run_protocol(get_protocol("pcn"), [root / "meshes"], root / "pcn", progress=False)
    assert run.done == 2 and not run.failures
    return root / "pcn"


@pytest.fixture
def source(made, tmp_path) -> Path:
    """A copy of the run, for a test to damage."""
    shutil.copytree(made, tmp_path / "src")
    return tmp_path / "src"


def _secret_file(folder: Path) -> Path:
    """An HDF5 file outside the source, ``/data (COMPLETE_POINTS, 3) float32`` all :data:`SECRET`."""
    folder.mkdir(exist_ok=True)
    with h5py.File(folder / "secret.h5", "w") as f:
        f["data"] = np.full((COMPLETE_POINTS, 3), SECRET, dtype=np.float32)
    return folder / "secret.h5"


def _replace_complete(shard: Path, make) -> None:
    """Rewrite ``shard`` as it is, but for its ``complete`` dataset, which ``make(file)`` makes."""
    with h5py.File(shard, "r") as f:
        arrays = {k: f[k][()] for k in f if k != "complete"}
        attrs = dict(f.attrs)
    shard.unlink()
    with h5py.File(shard, "w") as f:
        for k, v in arrays.items():
            f[k] = v
        f.attrs.update(attrs)
        make(f)


def _chair(source: Path) -> Path:
    return source / "shards" / "pcn_000000.h5"


def _refused(source: Path, out: Path, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        export(source, "pcn", out)
    assert not out.exists()


def test_an_external_link_is_refused(source, tmp_path):
    secret = _secret_file(tmp_path / "elsewhere")
    _replace_complete(_chair(source), lambda f: f.__setitem__("complete", h5py.ExternalLink(str(secret), "/data")))
    _refused(source, tmp_path / "out", DatasetFormatError, r"pcn_000000\.h5: '/complete' is an external link")


def test_a_virtual_dataset_is_refused(source, tmp_path):
    secret = _secret_file(tmp_path / "elsewhere")

    def virtual(f):
        layout = h5py.VirtualLayout(shape=(COMPLETE_POINTS, 3), dtype="f4")
        layout[:] = h5py.VirtualSource(str(secret), "data", shape=(COMPLETE_POINTS, 3))
        f.create_virtual_dataset("complete", layout)

    _replace_complete(_chair(source), virtual)
    _refused(source, tmp_path / "out", DatasetFormatError, r"pcn_000000\.h5: dataset '/complete' is a virtual dataset")


def test_external_raw_storage_is_refused(source, tmp_path):
    raw = tmp_path / "elsewhere.bin"
    raw.write_bytes(np.full((COMPLETE_POINTS, 3), SECRET, dtype="<f4").tobytes())
    _replace_complete(
        _chair(source), lambda f: f.create_dataset("complete", shape=(COMPLETE_POINTS, 3), dtype="<f4", external=[(str(raw), 0, raw.stat().st_size)])
    )  # fmt: skip
    _refused(source, tmp_path / "out", DatasetFormatError, r"pcn_000000\.h5: dataset '/complete' keeps its data in another file")


def test_a_shard_of_a_few_kb_declaring_a_gb_cloud_is_refused_in_one_line(source, tmp_path, capsys):
    _replace_complete(_chair(source), lambda f: f.create_dataset("complete", shape=(100_000_000, 3), dtype="f4", chunks=(65536, 3)))
    assert _chair(source).stat().st_size < 1 << 20
    out = tmp_path / "out"
    assert cli_main(["export", str(source), "--to", "pcn", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "pcn_000000.h5" in err and "declares shape (100000000, 3)" in err
    assert not out.exists()


def test_a_complete_cloud_of_another_size_than_the_run_recorded_is_refused(source, tmp_path):
    """Stored (compressed, so the stored bytes allow it), but not what the run made."""
    _replace_complete(
        _chair(source), lambda f: f.create_dataset("complete", data=np.zeros((COMPLETE_POINTS * 4, 3), "f4"), compression="gzip")
    )
    _refused(
        source,
        tmp_path / "out",
        DatasetFormatError,
        rf"pcn_000000\.h5: 'complete' declares \({COMPLETE_POINTS * 4}, 3\), where the run recorded {COMPLETE_POINTS:,}",
    )


@pytest.mark.parametrize(
    "key, make, said",
    [
        ("partial", lambda f: f.create_dataset("partial", data=np.zeros((10, 4), "f4")), r"'partial' declares \(10, 4\)"),
        ("partial", lambda f: f.create_dataset("partial", data=np.array(["a"], dtype=h5py.string_dtype())), "'partial' holds object"),
        ("partial_offsets", lambda f: f.create_dataset("partial_offsets", data=np.zeros(50, "i8")), r"'partial_offsets' declares \(50,\)"),
        ("partial_offsets", lambda f: f.create_dataset("partial_offsets", data=np.array([0, 5, 3, 1, 2, 3, 4, 5, 6])), "do not cut its"),
    ],
)
def test_arrays_that_no_pcn_run_writes_are_refused(source, tmp_path, key, make, said):
    shard = _chair(source)
    with h5py.File(shard, "a") as f:
        del f[key]
        make(f)
    _refused(source, tmp_path / "out", DatasetFormatError, rf"pcn_000000\.h5: .*{said}")


def test_bad_offsets_in_a_later_shard_refuse_the_export_before_out_is_made(source, tmp_path):
    with h5py.File(source / "shards" / "pcn_000001.h5", "a") as f:
        offsets = f["partial_offsets"][()]
        f["partial_offsets"][...] = offsets[::-1]
    _refused(source, tmp_path / "out", DatasetFormatError, r"pcn_000001\.h5: partial_offsets .* do not cut")


def test_a_symlinked_shard_is_refused(source, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.move(_chair(source), elsewhere / "pcn_000000.h5")
    _chair(source).symlink_to(elsewhere / "pcn_000000.h5")
    _refused(source, tmp_path / "out", UnsafePathError, r"shards/pcn_000000\.h5' leads outside")


def test_a_symlinked_shards_folder_is_refused(source, tmp_path):
    shutil.move(source / "shards", tmp_path / "elsewhere")
    (source / "shards").symlink_to(tmp_path / "elsewhere")
    _refused(source, tmp_path / "out", UnsafePathError, "leads outside")


def test_a_symlinked_protocol_json_is_refused(source, tmp_path):
    shutil.move(source / "protocol.json", tmp_path / "protocol.json")
    (source / "protocol.json").symlink_to(tmp_path / "protocol.json")
    _refused(source, tmp_path / "out", UnsafePathError, "protocol.json leads outside")


def test_a_fifo_shard_is_refused_at_once(source, tmp_path):
    shard = source / "shards" / "pcn_000001.h5"
    shard.unlink()
    os.mkfifo(shard)
    _refused(source, tmp_path / "out", DatasetFormatError, r"pcn_000001\.h5: is a FIFO")


def test_a_fifo_protocol_json_is_refused_at_once(source, tmp_path):
    (source / "protocol.json").unlink()
    os.mkfifo(source / "protocol.json")
    _refused(source, tmp_path / "out", InvalidInputError, r"protocol\.json: is a FIFO")


def test_a_huge_protocol_json_is_refused_unread(source, tmp_path):
    with open(source / "protocol.json", "r+b") as f:
        f.truncate(3 << 30)  # sparse: 3 GiB that cost nothing, never read
    _refused(source, tmp_path / "out", InvalidInputError, r"protocol\.json: 3,221,225,472 bytes, more than")


def test_a_deeply_nested_protocol_json_is_refused(source, tmp_path):
    (source / "protocol.json").write_text("[" * 100_000 + "]" * 100_000)
    _refused(source, tmp_path / "out", InvalidInputError, r"protocol\.json nests arrays or objects deeper")


def test_a_nested_group_in_a_shard_is_refused(source, tmp_path):
    with h5py.File(_chair(source), "a") as f:
        f.create_group("a/b/c")
    _refused(source, tmp_path / "out", DatasetFormatError, r"pcn_000000\.h5: nested group")


def test_a_large_attribute_is_not_read(source, tmp_path):
    with h5py.File(_chair(source), "a") as f:
        del f.attrs["name"]
        f.attrs.create("name", data=np.zeros(60_000, dtype="u1"))  # the most a compact header holds
    _refused(source, tmp_path / "out", DatasetFormatError, r"pcn_000000\.h5: the attribute 'name' is not one value")


def test_the_largest_shard_is_checked_against_the_memory_available(source, tmp_path, monkeypatch):
    from zbuf_occlude import resources

    monkeypatch.setattr(resources, "MIN_CHECKED_BYTES", 0)
    monkeypatch.setattr(resources, "available_memory", lambda: (1 << 20, "a test"))
    _refused(source, tmp_path / "out", InsufficientMemoryError, r"exporting the shard .*pcn_00000[01]\.h5 \([\d,]+ points\) needs about")


def test_a_hard_linked_shard_is_read_as_the_file_it_is(source, tmp_path):
    """A second name is no link out of the folder: what the folder holds is checked and exported."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.move(_chair(source), elsewhere / "pcn_000000.h5")
    os.link(elsewhere / "pcn_000000.h5", _chair(source))
    result = export(source, "pcn", tmp_path / "out")
    assert result.samples == {"train": 1, "test": 1}


def test_no_pcd_holds_another_files_bytes_when_an_attack_is_refused(source, tmp_path):
    """The external link again, with the secret's shape: refused, and nothing holds the secret."""
    secret = _secret_file(tmp_path / "elsewhere")
    _replace_complete(_chair(source), lambda f: f.__setitem__("complete", h5py.ExternalLink(str(secret), "/data")))
    with pytest.raises(DatasetFormatError):
        export(source, "pcn", tmp_path / "out")
    record = json.loads((source / "protocol.json").read_text())
    assert record["protocol"] == "pcn" and not (tmp_path / "out").exists()


def test_a_shard_changed_after_the_plan_is_checked_again_when_it_is_read(source, tmp_path):
    from zbuf_occlude.exporters.pcn import FILE_NAMES, plan_pcn, write_pcn
    from zbuf_occlude.io.owned import OwnedFolder

    plan = plan_pcn(source)
    _replace_complete(
        _chair(source), lambda f: f.create_dataset("complete", data=np.zeros((COMPLETE_POINTS * 4, 3), "f4"), compression="gzip")
    )
    with (
        OwnedFolder(tmp_path / "out", names=FILE_NAMES) as folder,
        pytest.raises(DatasetFormatError, match=r"pcn_000000\.h5: 'complete' declares"),
    ):
        write_pcn(folder, plan)
    assert not list((tmp_path / "out").rglob("*.pcd"))
