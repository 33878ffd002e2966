"""The farm asks a run's storage kind for its estimates and names: a kind registered in the table
(:data:`~zbuf_occlude.dataset.storage.STORAGE_KINDS`) gets its own, not those of a kind it is not."""

from __future__ import annotations

import pytest

from zbuf_occlude.dataset.storage import STORAGE_KINDS, ObjectSize, StorageKind, storage_kind
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.farm import checks
from zbuf_occlude.farm.config import FarmParams
from zbuf_occlude.farm.generate import generate
from zbuf_occlude.farm.ownership import written_names
from zbuf_occlude.farm.run import _estimate_bytes
from zbuf_occlude.mesh.inputs.plan import FarmObject
from zbuf_occlude.resources import estimate_job_memory


class Roomy(StorageKind):
    """A new kind whose every answer differs from the other kinds'."""

    name = storage = "roomy"
    shard_datasets = ("data",)

    def memory_held(self, size: ObjectSize) -> tuple[int, int]:
        return 3 * size.n_points, 1000

    def disk_bytes(self, size: ObjectSize) -> int:
        return 7 * size.n_poses + size.dense_points

    def top_names(self, object_names):
        return ["roomy-index"]


@pytest.fixture
def roomy(monkeypatch):
    kind = Roomy()
    monkeypatch.setitem(STORAGE_KINDS, kind.name, kind)
    return kind


def _params(storage: str) -> FarmParams:
    return FarmParams(views="0:0,30:90", samples_per_view=2, n_points=8, dense_points=10, storage=storage)


def test_a_new_kind_gets_its_own_memory_estimate(roomy, monkeypatch):
    seen = []
    monkeypatch.setattr(checks, "check_memory", seen.append)
    params = _params("roomy")
    checks.check_memory_up_front(params, workers=2)
    assert seen == [estimate_job_memory(points=24, samples_per_view=2, samples_held=1000, dense_points=10,
                                        resolution=params.resolution, workers=2)]  # fmt: skip


def test_a_new_kind_gets_its_own_disk_estimate_and_names(roomy):
    assert storage_kind("roomy") is roomy
    assert _estimate_bytes(_params("roomy")) == 7 * 2 + 10
    objects = [FarmObject(index=0, name="chair/train/chair_0001", source="a.off", class_name="chair", split="train", label=0)]
    assert "roomy-index" in written_names(objects, "roomy") and "roomy-index" not in written_names(objects, "dense")


def test_the_kinds_of_the_table_keep_their_estimates():
    size = ObjectSize(n_poses=2, samples_per_view=2, n_points=8, dense_points=10)
    assert storage_kind("dense").memory_held(size) == storage_kind("h5").memory_held(size) == (8, 4)
    assert storage_kind("npz").memory_held(size) == (8, 2) and storage_kind("compact").memory_held(size) == (0, 2)
    assert storage_kind("dense").disk_bytes(size) == storage_kind("ply").disk_bytes(size) == 2 * 2 * 8 * 12
    assert storage_kind("compact").disk_bytes(size) == 10 * 12 + 2 * 17 // 8


def test_a_kind_that_states_no_estimate_is_not_given_one(monkeypatch):
    class Silent(StorageKind):
        name = storage = "silent"

    monkeypatch.setitem(STORAGE_KINDS, "silent", Silent())
    with pytest.raises(NotImplementedError, match="no memory estimate"):
        checks.check_memory_up_front(_params("silent"))
    with pytest.raises(NotImplementedError, match="no disk estimate"):
        _estimate_bytes(_params("silent"))


def test_generate_writes_only_the_kinds_it_writes(roomy, tmp_path):
    with pytest.raises(InvalidInputError, match=r"generate writes one of \('h5', 'npz', 'ply'\), not 'roomy'"):
        generate([tmp_path / "none.off"], tmp_path / "out", params=_params("roomy"))
    assert not (tmp_path / "out").exists()
