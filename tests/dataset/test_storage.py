"""Storage kinds (``dataset/storage.py``): the table the farm's writer and the reader share, and its writers."""

from __future__ import annotations

import errno

import h5py
import numpy as np
import pytest

from zbuf_occlude.dataset import storage
from zbuf_occlude.dataset.layout import GENERATE_STORAGES, STORAGE_MODES
from zbuf_occlude.dataset.storage import STORAGE_KINDS, Compact, DenseRows, SampleFiles, SensorCrops, storage_kind
from zbuf_occlude.errors import InvalidInputError, OutputError


def test_every_storage_the_farm_and_generate_write_has_one_kind():
    assert len({id(k) for k in STORAGE_KINDS.values()}) == len(STORAGE_KINDS)
    assert all(k.name == name for name, k in STORAGE_KINDS.items())
    for name in (*STORAGE_MODES, *GENERATE_STORAGES):
        assert storage_kind(name).storage == name and not storage_kind(name).rows_placed
    assert type(storage_kind("dense")) is DenseRows and not storage_kind("dense").provenance
    assert storage_kind("h5").provenance and isinstance(storage_kind("compact"), Compact)
    assert isinstance(storage_kind("npz"), SampleFiles) and not storage_kind("npz").hdf5
    assert isinstance(storage_kind("dense", sensor=True), SensorCrops)


@pytest.mark.parametrize(("name", "sensor"), [("sparse", False), ("compact", True), ("sensor_crops", False), ("npz", True)])
def test_a_storage_no_kind_writes_is_refused(name, sensor):
    # farm --sensor data sets are dense; the table's key of sensor crops is no storage a card may name
    with pytest.raises(InvalidInputError, match=f"unknown storage '{name}'"):
        storage_kind(name, sensor=sensor)


def test_sensor_crops_store_one_sample_per_scan_the_others_samples_per_view():
    n_visible = np.array([0, 4, 9])
    assert storage_kind("dense", sensor=True).rows_per_pose(n_visible, 5).tolist() == [0, 1, 1]
    for name in ("dense", "compact", "h5", "ply"):
        assert storage_kind(name).rows_per_pose(n_visible, 5).tolist() == [0, 5, 5]


def test_kinds_declare_what_the_farm_feeds_them_and_what_their_shards_hold():
    assert storage_kind("compact").occlude_options(7) == {"samples_per_view": 0, "topped_up": True}
    assert storage_kind("dense").occlude_options(7) == {"samples_per_view": 7}
    assert {k.made_from for k in STORAGE_KINDS.values()} == {"poses", "scans"}
    assert storage_kind("dense", sensor=True).made_from == "scans"
    assert storage_kind("dense", sensor=True).shard_datasets == ("data", "elevation_deg", "azimuth_deg")
    with pytest.raises(NotImplementedError):
        storage_kind("dense", sensor=True).write_poses(None, [])


def test_write_datasets_keeps_order_and_compresses_only_what_it_is_told(tmp_path):
    datasets = {"b": np.arange(6, dtype=np.uint8).reshape(2, 3), "a": np.zeros(3), "empty": np.zeros((0, 4), np.uint8)}
    storage.write_datasets(tmp_path / "x.h5", datasets, {"k": 1}, gzip={"b": 4, "empty": 4})
    with h5py.File(tmp_path / "x.h5", "r") as f:
        assert f["b"].compression == "gzip" and f["b"].compression_opts == 4 and f["b"].chunks == (2, 3)
        assert f["a"].compression is None and f["empty"].compression is None and f["empty"].chunks is None
        assert np.array_equal(f["b"][()], datasets["b"]) and f.attrs["k"] == 1


def test_same_inputs_give_the_same_bytes(tmp_path):
    args = (
        np.random.default_rng(0).random((8, 3)),
        np.ones((1, 1), np.uint8),
        np.array([8]),
        np.array([0]),
        np.zeros((0, 3)),
        [(0.0, 0.0)],
        {},
    )
    for name in ("a.h5", "b.h5"):
        storage.write_compact(tmp_path / name, *args, gzip_level=4)
    assert (tmp_path / "a.h5").read_bytes() == (tmp_path / "b.h5").read_bytes()


@pytest.mark.parametrize("writer", ["write_compact", "write_datasets"])
def test_hdf5_disk_full_becomes_enospc_and_other_errors_pass_unchanged(tmp_path, monkeypatch, writer):
    # HDF5 reports a full disk in the message only (errno None): the writers give it ENOSPC,
    # which atomic_path turns into "disk full"; other OSErrors pass through as they are
    import h5py as h5

    args, kwargs = {"write_compact": ((np.zeros((8, 3)), np.zeros((1, 1), np.uint8), np.array([3]), np.array([0]), np.zeros((0, 3)),
                                       [(0.0, 0.0)], {}), {"gzip_level": 4}),
                    "write_datasets": (({"data": np.zeros(3)}, {}), {})}[writer]  # fmt: skip
    for raised, expected_errno in ((OSError("Unable to create file (No space left on device)"), errno.ENOSPC),
                                   (OSError(errno.EACCES, "No space left? no: permission"), errno.EACCES),
                                   (OSError("Unable to create file (file locked)"), None)):  # fmt: skip

        def fail(*a, raised=raised, **k):
            raise raised

        monkeypatch.setattr(h5, "File", fail)
        with pytest.raises(OutputError) as info:  # atomic_path names the file and the cause
            getattr(storage, writer)(tmp_path / "x.h5", *args, **kwargs)
        cause = info.value.__cause__
        assert cause.errno == expected_errno and str(raised.args[-1]) in str(cause)
        if expected_errno == errno.ENOSPC:
            assert cause.strerror == str(raised) and "disk full" in str(info.value)
        else:
            assert cause is raised and "disk full" not in str(info.value)
        assert not list(tmp_path.glob("*.h5*"))  # nothing partial left


class _Rows:
    """A ShardSource holding one object's ``data`` in memory."""

    def __init__(self, data):
        self.data = data

    def shard(self, obj):
        return {"data": self.data}


class _Watched:
    """An array that records how it is indexed (one row, or the whole dataset with ``[()]``)."""

    def __init__(self, array):
        self.array, self.calls = array, []

    def __getitem__(self, key):
        self.calls.append(key)
        return self.array[key]


def test_dense_rows_read_one_row_alone_and_several_from_the_whole_dataset():
    data = _Watched(np.arange(5 * 2 * 3, dtype=np.float32).reshape(5, 2, 3))
    kind, idx = storage_kind("dense"), np.array([0])
    one = kind.read(_Rows(data), 0, idx, idx, np.array([3]))
    assert one.shape == (1, 2, 3) and np.array_equal(one[0], data.array[3]) and data.calls == [3]
    rows = np.array([1, 2, 4])
    assert np.array_equal(kind.read(_Rows(data), 0, rows, rows, rows), data.array[rows]) and data.calls[1:] == [()]


def test_the_table_says_what_each_command_writes():
    assert storage.storages("farm") == STORAGE_MODES and storage.storages("generate") == GENERATE_STORAGES
    assert storage.storages() == (*STORAGE_MODES, *GENERATE_STORAGES)
    assert [k.name for k in STORAGE_KINDS.values() if k.joins_splits] == ["h5"]


def test_every_kind_of_the_table_states_its_estimates_and_names():
    size = storage.ObjectSize(n_poses=3, samples_per_view=2, n_points=16, dense_points=100)
    for kind in STORAGE_KINDS.values():
        points, held = kind.memory_held(size)
        assert min(points, held, kind.disk_bytes(size)) >= 0, kind
    assert storage_kind("npz").top_names(["chair/train/a", "..", "lamp/b"]) == ["chair", "lamp"]
    assert storage_kind("dense").top_names(["chair/train/a"]) == []
