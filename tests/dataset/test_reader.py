"""OccludedDataset: the reader of farm data sets, both storage modes, filters, loaders."""

from __future__ import annotations

import collections.abc
import json
import pickle
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLE_MESHES

from zbuf_occlude import OccludedDataset
from zbuf_occlude.dataset.layout import MANIFEST_FILE
from zbuf_occlude.dataset.index import samples_per_pose
from zbuf_occlude.dataset.storage import reconstruct_samples, unpack_visible
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.farm import FarmParams, run_farm
from zbuf_occlude.farm.config import RunOptions

#: Shipped real meshes (data/samples), as (path there, class, split): a fresh clone runs it all.
MESHES = [
    ("sofa/test/sofa_0681.off", "sofa", "test"),
    ("chair/train/chair_0001.off", "chair", "train"),
    ("desk/test/desk_0201.off", "desk", "test"),
]
POSES = [(-30.0, 0.0), (0.0, 90.0), (30.0, 180.0), (60.0, 270.0)]
PARAMS = FarmParams(views=",".join(f"{el}:{az}" for el, az in POSES), samples_per_view=2, n_points=96, dense_points=1536, resolution=96)


@pytest.fixture(scope="module")
def datasets(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("meshes")
    for rel, cls, split in MESHES:
        target = root / cls / split / Path(rel).name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.symlink_to(SAMPLE_MESHES / rel)
    out = {}
    for storage in ("dense", "compact"):
        out[storage] = tmp_path_factory.mktemp(storage)
        params = FarmParams(**{**PARAMS.to_dict(), "storage": storage})
        run_farm(root, out[storage], params=params, options=RunOptions(progress=False))
    return out


@pytest.fixture(scope="module", params=["dense", "compact"])
def dataset(request, datasets) -> OccludedDataset:
    return OccludedDataset(datasets[request.param])


def test_items_are_points_label_metadata(dataset):
    n_samples = len(MESHES) * len(POSES) * PARAMS.samples_per_view
    assert len(dataset) == n_samples
    assert isinstance(dataset, collections.abc.Sequence)
    points, label, meta = dataset[0]
    assert points.shape == (PARAMS.n_points, 3) and points.dtype == np.float32
    assert isinstance(label, int) and dataset.shape_names[label] == meta["class_name"]
    for key in ("class_name", "split", "object_index", "pose_index", "sample_index", "elevation_deg", "azimuth_deg", "n_visible", "padded"):
        assert key in meta
    assert (meta["elevation_deg"], meta["azimuth_deg"]) == POSES[meta["pose_index"]]
    assert np.array_equal(dataset[-1][0], dataset[len(dataset) - 1][0])
    with pytest.raises(IndexError):
        dataset[len(dataset)]
    with pytest.raises(TypeError):
        dataset[1:3]
    assert sum(1 for _ in dataset) == len(dataset)
    assert np.array_equal(dataset.labels, [dataset[i][1] for i in range(len(dataset))])
    data, labels = dataset.to_arrays()
    assert data.shape == (len(dataset), PARAMS.n_points, 3)
    assert np.array_equal(data[5], dataset[5][0]) and np.array_equal(labels, dataset.labels)


def test_both_storage_modes_give_the_same_items(datasets):
    dense, compact = OccludedDataset(datasets["dense"]), OccludedDataset(datasets["compact"])
    assert len(dense) == len(compact)
    for i in range(len(dense)):
        (a, la, ma), (b, lb, mb) = dense[i], compact[i]
        assert np.array_equal(a, b) and la == lb and ma == mb


def test_compact_samples_come_from_visible_points(datasets):
    import h5py

    shard = sorted((datasets["compact"] / "shards").glob("*.h5"))[0]
    with h5py.File(shard, "r") as f:
        dense_points, bits, n_visible = f["dense_points"][()], f["visible_bits"][()], f["n_visible"][()]
        key, seed = int(f.attrs["key"]), int(f.attrs["seed"])
    for pose in range(len(POSES)):
        visible = unpack_visible(bits[pose], len(dense_points))
        assert visible.sum() == n_visible[pose]
        samples = reconstruct_samples(
            dense_points, visible, seed=seed, key=key, pose_index=pose, n_points=PARAMS.n_points, sample_indices=[0, 1]
        )
        visible_set = {tuple(p) for p in dense_points[visible]}
        assert all(tuple(p) in visible_set for p in samples.reshape(-1, 3))
        assert not np.array_equal(samples[0], samples[1])
    assert list(samples_per_pose(np.array([0, 5, 1]), 3)) == [0, 3, 3]


def test_compact_samples_of_a_topped_up_pose_come_from_its_visible_and_top_up_points():
    rng = np.random.default_rng(0)
    dense_points = rng.random((50, 3)).astype(np.float32)
    visible = np.zeros(50, dtype=bool)
    visible[::5] = True  # 10 visible dense points
    topup = rng.random((8, 3)).astype(np.float32) + 2.0  # 8 top-up points, told apart by x > 1
    kw = {"seed": 1, "key": 2, "pose_index": 3, "sample_indices": [0, 1]}
    samples = reconstruct_samples(dense_points, visible, n_points=16, topup_points=topup, **kw)
    pool = {p.tobytes() for p in dense_points[visible]} | {p.tobytes() for p in topup}
    for s in samples:  # 18 distinct points offered: 16 distinct drawn, none hidden
        assert len({p.tobytes() for p in s}) == 16 and {p.tobytes() for p in s} <= pool
    assert (samples[..., 0] > 1).any() and (samples[..., 0] < 1).any()
    # without top-up points (or with none) the draw is the one of the mask alone
    plain = reconstruct_samples(dense_points, visible, n_points=8, **kw)
    assert np.array_equal(plain, reconstruct_samples(dense_points, visible, n_points=8, topup_points=topup[:0], **kw))


def test_filters(datasets):
    path = datasets["dense"]
    spv = PARAMS.samples_per_view
    assert len(OccludedDataset(path, split="train")) == len(POSES) * spv
    assert {m["split"] for m in map(OccludedDataset(path, split="test").metadata, range(2 * len(POSES) * spv))} == {"test"}
    assert len(OccludedDataset(path, classes=["sofa", "desk"])) == 2 * len(POSES) * spv
    assert len(OccludedDataset(path, classes="chair")) == len(POSES) * spv
    ds = OccludedDataset(path, elevation_deg=0.0)
    assert len(ds) == len(MESHES) * spv and all(ds.metadata(i)["azimuth_deg"] == 90.0 for i in range(len(ds)))
    assert len(OccludedDataset(path, elevation_deg=[-30, 60])) == len(MESHES) * 2 * spv
    assert len(OccludedDataset(path, elevation_deg=lambda el: el > 0, azimuth_deg=[270.0])) == len(MESHES) * spv
    with pytest.raises(InvalidInputError, match=r"no pose of .* matches .*azimuth_deg=45.0.*elevations -30, 0, 30, 60"):
        OccludedDataset(path, azimuth_deg=45.0)  # a filter matching no pose is a mistake, not an empty data set
    ds = OccludedDataset(path, split="test", classes=["chair"])
    assert len(ds) == 0 and ds.to_arrays()[0].shape == (0, PARAMS.n_points, 3)
    # labels stay the data set's, whatever the filter
    names = (path / "shape_names.txt").read_text().splitlines()
    assert set(OccludedDataset(path, classes="sofa").labels) == {names.index("sofa")}


def test_errors(datasets, tmp_path):
    with pytest.raises(InvalidInputError, match="not a finished farm data set"):
        OccludedDataset(tmp_path)
    with pytest.raises(InvalidInputError, match="unknown classes"):
        OccludedDataset(datasets["dense"], classes=["car"])
    with pytest.raises(InvalidInputError, match="unknown split"):
        OccludedDataset(datasets["dense"], split="val")
    with pytest.raises(InvalidInputError, match="elevation_deg"):
        OccludedDataset(datasets["dense"], elevation_deg=float("nan"))


def test_a_folder_above_a_finished_data_set_names_it(datasets, tmp_path):
    """Opening the folder that holds the data set (``runs/e/data`` for ``runs/e/data/occluded``)
    says where it is, and the folder it names opens."""
    parent = tmp_path / "runs" / "e" / "data"
    shutil.copytree(datasets["dense"], parent / "occluded")
    (parent / "meshes").mkdir()  # a folder that is not a data set is not named
    with pytest.raises(InvalidInputError, match="not a finished farm data set") as err:
        OccludedDataset(parent)
    message = str(err.value)
    assert message.endswith(f"did you mean {parent / 'occluded'}?") and "let `zbuf-occlude farm` finish" not in message, message
    suggested = message.rsplit("did you mean ", 1)[1].rstrip("?")
    assert len(OccludedDataset(suggested)) == len(OccludedDataset(datasets["dense"]))


def test_several_finished_data_sets_below_are_named_up_to_three(tmp_path):
    for name in ("e", "a", "d", "b", "c"):  # a card is all the suggestion looks for
        (tmp_path / name).mkdir()
        (tmp_path / name / "dataset_card.json").write_text("{}")
    (tmp_path / "shards").mkdir()
    with pytest.raises(InvalidInputError) as err:
        OccludedDataset(tmp_path)
    shown = ", ".join(str(tmp_path / name) for name in ("a", "b", "c"))
    assert str(err.value).endswith(f"did you mean one of {shown} (and 2 more)?"), err.value
    for name in ("d", "e"):
        shutil.rmtree(tmp_path / name)
    with pytest.raises(InvalidInputError, match=rf"did you mean one of {re.escape(shown)}\?$"):
        OccludedDataset(tmp_path)


def test_an_unfinished_run_without_data_sets_below_says_to_let_farm_finish(tmp_path):
    (tmp_path / "shards").mkdir()
    with pytest.raises(
        InvalidInputError, match=r"no dataset_card.json\); let `zbuf-occlude farm` finish, or run `zbuf-occlude farm-merge`"
    ):
        OccludedDataset(tmp_path)


def test_pickles_for_loader_workers(dataset):
    dataset[3]  # opens files / fills caches, which must not travel
    clone = pickle.loads(pickle.dumps(dataset))
    for i in (0, 3, len(dataset) - 1):
        a, b = dataset[i], clone[i]
        assert np.array_equal(a[0], b[0]) and a[1:] == b[1:]
    dataset.close()
    assert dataset[3][1] == clone[3][1]


def test_torch_dataloader(datasets):
    torch = pytest.importorskip("torch")
    from torch.utils.data import DataLoader

    ds = OccludedDataset(datasets["compact"], split="test")
    batches = list(DataLoader(ds, batch_size=4, shuffle=False, num_workers=0))
    points, labels, meta = batches[0]
    assert points.shape == (4, PARAMS.n_points, 3) and points.dtype == torch.float32
    assert labels.dtype == torch.int64 and len(meta["class_name"]) == 4
    assert sum(len(b[1]) for b in batches) == len(ds)


def test_failed_objects_are_not_served(datasets, tmp_path):
    # a manifest line with status "failed" (as the farm writes for a bad mesh) is skipped
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(datasets["dense"], copy)
    lines = (copy / MANIFEST_FILE).read_text().splitlines()
    rec = json.loads(lines[0])
    rec.update(status="failed", error="MeshLoadError: test", shards=[])
    (copy / MANIFEST_FILE).write_text("\n".join([json.dumps(rec), *lines[1:]]) + "\n")
    ds = OccludedDataset(copy)
    assert len(ds) == (len(MESHES) - 1) * len(POSES) * PARAMS.samples_per_view
    assert rec["name"] not in {ds.metadata(i)["name"] for i in range(len(ds))}


def test_a_card_declaring_huge_samples_is_refused_before_allocating(tmp_path, monkeypatch):
    # n_points edited to 1e8 in the card: one compact sample would be redrawn into 3.2 GB
    import shutil

    import zbuf_occlude.resources as resources
    from conftest import tiny_dataset

    from zbuf_occlude.errors import InsufficientMemoryError

    ds = tiny_dataset(tmp_path / "ds", "compact")
    card = json.loads((ds / "dataset_card.json").read_text())
    card["params"]["n_points"] = 100_000_000
    (ds / "dataset_card.json").write_text(json.dumps(card))
    (ds / "dataset_card.json.sha256").unlink()  # or re-signed by its author: the checksum is no defence here
    monkeypatch.setattr(resources, "available_memory", lambda: (2**30, "test"))
    with pytest.raises(InsufficientMemoryError, match=r"dataset_card\.json field 'params\.n_points' \(100,000,000\) needs about"):
        OccludedDataset(ds)[0]
    shutil.rmtree(ds)


def test_to_arrays_checks_the_memory_before_allocating(datasets, monkeypatch):

    from zbuf_occlude import resources
    from zbuf_occlude.errors import InsufficientMemoryError

    ds = OccludedDataset(datasets["dense"])
    monkeypatch.setattr(resources, "available_memory", lambda: (1000, "test budget"))
    monkeypatch.setattr(resources, "MIN_CHECKED_BYTES", 0)  # a tiny data set, a tinier budget
    with pytest.raises(InsufficientMemoryError, match=r"to_arrays\(\) of .* samples of .* more than the 1000 B"):
        ds.to_arrays()


def test_an_edited_card_is_caught_by_its_checksum_and_an_old_one_still_reads(tmp_path, capsys):
    import shutil

    from zbuf_occlude.cli.main import main
    from zbuf_occlude.dataset.layout import CARD_SHA256_FILE
    from zbuf_occlude.errors import DatasetFormatError

    from conftest import tiny_dataset

    ds = tiny_dataset(tmp_path / "ds")
    assert (ds / CARD_SHA256_FILE).read_text().endswith("  dataset_card.json\n")
    old = shutil.copytree(ds, tmp_path / "old")
    card = json.loads((ds / "dataset_card.json").read_text())
    card["params"]["n_points"] = 100_000_000
    (ds / "dataset_card.json").write_text(json.dumps(card))
    with pytest.raises(DatasetFormatError, match=r"dataset_card\.json differs from its SHA-256 in dataset_card\.json\.sha256"):
        OccludedDataset(ds)
    assert main(["verify", str(ds)]) == 1
    assert "dataset_card.json differs from its SHA-256" in capsys.readouterr().err
    (old / CARD_SHA256_FILE).unlink()  # a data set written before the card had a checksum
    assert len(OccludedDataset(old)) == 4
    assert main(["verify", str(old)]) == 0
    assert "has no SHA-256 file" in capsys.readouterr().out


def test_the_default_object_cache_holds_a_small_data_set_and_a_share_of_the_memory():
    from zbuf_occlude.dataset.reader import OBJECT_CACHE_UNKNOWN_MEMORY, default_object_cache, object_cache_bytes

    # the farm's default object: 32,768 dense points (12 B each), a bit per point for 100 poses
    per_object = object_cache_bytes(32_768, 100, 0)
    assert per_object == 12 * 32_768 + 100 * 4096
    assert object_cache_bytes(9, 2, 5) == 12 * 9 + 2 * 2 + 12 * 5  # bits rounded up to whole bytes
    assert default_object_cache(200, per_object, 16 * 2**30) == 200  # small data set: every object
    bounded = default_object_cache(1_000_000, per_object, 2**30)  # large data set: 5 % of 1 GiB
    assert bounded == int(0.05 * 2**30) // per_object and 1 < bounded < 1_000_000
    assert default_object_cache(200, per_object, 10 * per_object) == 1  # tiny memory: one object
    assert default_object_cache(0, per_object, 2**30) == 1
    assert default_object_cache(10, per_object, None) == 10  # memory unknown: a fixed count
    assert default_object_cache(10**6, per_object, None) == OBJECT_CACHE_UNKNOWN_MEMORY


def test_a_shuffled_pass_reads_each_object_once_when_the_default_cache_holds_them(datasets, monkeypatch):
    import zbuf_occlude.dataset.reader as reader
    from zbuf_occlude.dataset.storage import Compact

    loads = []
    original = Compact.load_arrays
    monkeypatch.setattr(Compact, "load_arrays", lambda self, f, path, rec: loads.append(path) or original(self, f, path, rec))
    ds = OccludedDataset(datasets["compact"])
    assert ds.object_cache == len(MESHES)
    order = np.random.default_rng(0).permutation(len(ds))
    for i in np.concatenate([order, order]):
        ds[int(i)]
    assert len(loads) == len(MESHES)  # once per object, whatever the order
    assert OccludedDataset(datasets["compact"], object_cache=2).object_cache == 2  # as given
    monkeypatch.setattr(reader, "available_memory", lambda: (1000, "test"))  # less than one object's 5 %
    assert OccludedDataset(datasets["compact"]).object_cache == 1
