"""The farm's record has one type, the schema's: the worker writes exactly its fields."""

from __future__ import annotations

import json
import re

import pytest
from pydantic import ValidationError

from zbuf_occlude.dataset.schema import ObjectRecord, OkRecord
from zbuf_occlude.farm.config import FarmParams, record_path
from zbuf_occlude.farm.worker import base_record, write_record
from zbuf_occlude.mesh.inputs.plan import FarmObject


def _object() -> FarmObject:
    return FarmObject(index=3, name="chair_0001", source="/meshes/chair_0001.off", class_name="chair", split="train", label=2)


def test_a_written_record_is_the_schemas_and_readers_accept_it(tmp_path) -> None:
    params = FarmParams(views="0:0", n_points=8, samples_per_view=1)
    record = base_record(_object(), params)
    record.update(status="ok", shards=["shards/00003.h5"], sha256=["a" * 64], n_visible=[5], n_samples=1, bytes=10,
                  n_padded_poses=1, n_dense=64, n_faces=12, time_s=0.5, host="h", pid=1)  # fmt: skip
    written = write_record(tmp_path, _object(), record)
    assert json.loads(record_path(tmp_path, 3).read_text()) == written == record
    OkRecord.model_validate(written)


def test_a_field_the_schema_does_not_declare_is_refused(tmp_path) -> None:
    record = base_record(_object(), FarmParams(views="0:0"))
    with pytest.raises(ValidationError, match="surprise"):
        write_record(tmp_path, _object(), {**record, "surprise": 1})
    with pytest.raises(ValidationError, match="n_samples"):
        write_record(tmp_path, _object(), {**record, "n_samples": "3"})  # strict types: no strings for numbers
    assert not record_path(tmp_path, 3).exists()


def test_readers_keep_fields_a_newer_writer_adds() -> None:
    fields = {"status": "ok", "name": "a", "source": "s", "class_name": "c", "split": "train", "object_index": 0,
              "label": 0, "key": 1, "shards": ["x.h5"], "n_visible": [1]}  # fmt: skip
    assert OkRecord.model_validate({**fields, "newer": True}).model_extra == {"newer": True}
    with pytest.raises(ValidationError):
        ObjectRecord.model_validate({**fields, "newer": True})


# -- the manifest read in bounded memory ------------------------------------------------------------
#: A manifest under the 4 GiB cap whose records could not fit in 3 GB: made sparse (nothing written).
_BIG_MANIFEST_BYTES = 3 << 30


def _big_manifest(tmp_path):
    from conftest import tiny_dataset

    ds = tiny_dataset(tmp_path / "ds")
    with open(ds / "manifest.jsonl", "r+b") as fh:
        fh.truncate(_BIG_MANIFEST_BYTES)  # its lines, then NUL bytes to 3 GiB
    return ds


def test_a_3_gib_manifest_is_refused_by_the_memory_its_records_need_before_it_is_read(tmp_path, monkeypatch):
    """Read whole (and then as a list of its lines) it took 3 GiB and more: a MemoryError under a
    3 GB limit; its records are checked against the memory available first."""
    from memory_limit import HEADROOM_3_GB, OPEN_DATASET, run_cli_limited, run_python_limited

    from zbuf_occlude import OccludedDataset, resources
    from zbuf_occlude.errors import InsufficientMemoryError

    ds = _big_manifest(tmp_path)
    said = rf"^the manifest {ds / 'manifest.jsonl'} \(3,221,225,472 bytes\) needs about 48 GiB of memory"
    monkeypatch.setattr(resources, "available_memory", lambda: (16 << 30, "test budget"))  # plainly, as a 16 GiB machine
    with pytest.raises(InsufficientMemoryError, match=said) as caught:
        OccludedDataset(ds)
    assert "\n" not in str(caught.value)
    monkeypatch.undo()
    done = run_python_limited(OPEN_DATASET, args=[ds], headroom=HEADROOM_3_GB)  # a 3 GB process
    assert done.returncode == 3 and not done.stderr and re.search(said, done.stdout), done.stdout + done.stderr[-2000:]
    assert len(done.stdout.splitlines()) == 1
    checked = run_cli_limited(["verify", str(ds)], headroom=HEADROOM_3_GB)
    assert checked.returncode == 1 and "Traceback" not in checked.stderr, checked.stderr[-2000:]
    assert re.search(said[1:], checked.stderr), checked.stderr
