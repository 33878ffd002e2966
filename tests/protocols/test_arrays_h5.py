"""A protocol's shards are written and read through the layer: ``write_arrays_h5`` atomically,
``read_arrays_h5`` by the checked HDF5 opener (a regular file, inside the folder it was found in,
no links or external storage, the declared bytes checked against the memory available)."""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np
import pytest

from zbuf_occlude.errors import DatasetFormatError, InsufficientMemoryError, UnsafePathError
from zbuf_occlude.protocols import read_arrays_h5, write_arrays_h5


def _shard(path: Path) -> Path:
    return write_arrays_h5(path, {"points": np.arange(12, dtype=np.float32).reshape(4, 3), "source": np.array(["a.off"])}, {"name": "x"})


def test_write_then_read_gives_the_arrays_strings_and_attributes(tmp_path):
    d = read_arrays_h5(_shard(tmp_path / "s.h5"), within=tmp_path)
    np.testing.assert_array_equal(d["points"], np.arange(12, dtype=np.float32).reshape(4, 3))
    assert list(d["source"]) == ["a.off"] and d["attrs"]["name"] == "x"
    assert [p.name for p in tmp_path.iterdir()] == ["s.h5"]  # no temporary left


def test_only_the_named_datasets_are_read(tmp_path):
    d = read_arrays_h5(_shard(tmp_path / "s.h5"), names=("points",))
    assert set(d) == {"points", "attrs"}
    with pytest.raises(DatasetFormatError, match=r"s\.h5 has no dataset 'complete'"):
        read_arrays_h5(tmp_path / "s.h5", names=("points", "complete"))


def test_a_group_is_no_dataset(tmp_path):
    with h5py.File(_shard(tmp_path / "s.h5"), "a") as f:
        f.create_group("g")
    assert set(read_arrays_h5(tmp_path / "s.h5")) == {"points", "source", "attrs"}


def test_a_shard_linked_from_outside_its_folder_is_refused(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "s.h5").symlink_to(_shard(tmp_path / "elsewhere.h5"))
    with pytest.raises(UnsafePathError, match="leads outside"):
        read_arrays_h5(tmp_path / "run" / "s.h5", within=tmp_path / "run")


def test_a_fifo_is_refused_at_once(tmp_path):
    os.mkfifo(tmp_path / "s.h5")
    with pytest.raises(DatasetFormatError, match=r"s\.h5: is a FIFO"):
        read_arrays_h5(tmp_path / "s.h5")


def test_a_file_that_is_not_hdf5_is_named(tmp_path):
    (tmp_path / "s.h5").write_bytes(b"not hdf5")
    with pytest.raises(DatasetFormatError, match=r"s\.h5 is not a readable HDF5 file"):
        read_arrays_h5(tmp_path / "s.h5")


def test_an_external_link_is_refused(tmp_path):
    secret = _shard(tmp_path / "secret.h5")
    with h5py.File(tmp_path / "s.h5", "w") as f:
        f["points"] = h5py.ExternalLink(str(secret), "/points")
    with pytest.raises(DatasetFormatError, match="external link"):
        read_arrays_h5(tmp_path / "s.h5")


def test_declared_bytes_are_checked_against_the_memory_available(tmp_path, monkeypatch):
    from zbuf_occlude import resources

    with h5py.File(tmp_path / "s.h5", "w") as f:  # stored compressed: 8 MB declared in a few kB
        f.create_dataset("points", data=np.zeros((1 << 21, 1), "f4"), compression="gzip")
    monkeypatch.setattr(resources, "MIN_CHECKED_BYTES", 0)
    monkeypatch.setattr(resources, "available_memory", lambda: (1 << 20, "a test"))
    with pytest.raises(InsufficientMemoryError, match=r"reading .*s\.h5 \(8,388,608 bytes declared\)"):
        read_arrays_h5(tmp_path / "s.h5")
