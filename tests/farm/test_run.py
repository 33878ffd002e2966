"""The render farm: layout, determinism (workers, shards, selection, Dask), resume, failures.

Runs on the shipped real ModelNet meshes (``data/samples``, so a fresh clone runs it all)
with few poses and points, so the whole file takes well under a minute on a 2-core
machine with Mesa llvmpipe.
"""

from __future__ import annotations

import argparse
import errno
import json
import shlex
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import SAMPLE_MESHES

from zbuf_occlude.cli.farm import add_farm_merge_parser, add_farm_parser
from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.dataset.layout import CARD_FILE, FORMAT_VERSION, MANIFEST_FILE, SHAPE_NAMES_FILE
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.dataset.storage import unpack_visible
from zbuf_occlude.errors import InvalidInputError, OutputError
from zbuf_occlude.farm import FarmParams, SensorCropParams, merge_farm, parse_shard, run_farm, select_shard
from zbuf_occlude.farm.config import RunOptions
from zbuf_occlude.geometry.cameras import camera_on_sphere
from zbuf_occlude.geometry.samples import ObjectProvenance, object_key, pose_samples
from zbuf_occlude.mesh.inputs.plan import FarmObject, discover_objects
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.pipeline import CameraSphere, PoseDraws, dense_cloud, occlude_poses
from zbuf_occlude.sensors.placement import CropDistributions
from zbuf_occlude.visibility.registry import method_info, visible_mask

REPO_ROOT = Path(__file__).resolve().parents[2]
#: Shipped real meshes (224–7608 faces), as (path under data/samples, class, split).
SMALL_MESHES = [
    ("sofa/test/sofa_0681.off", "sofa", "test"),
    ("monitor/train/monitor_0001.off", "monitor", "train"),
    ("chair/train/chair_0001.off", "chair", "train"),
    ("stool/train/stool_0002.off", "stool", "train"),
    ("desk/test/desk_0201.off", "desk", "test"),
]
#: Few poses, points and pixels: enough to exercise every code path quickly.
PARAMS = FarmParams(views="0:0,40:90,-40:200,85:300", samples_per_view=2, n_points=128, dense_points=2048, resolution=96)


def make_tree(root: Path, meshes=SMALL_MESHES) -> Path:
    """A ModelNet-style tree ROOT/<class>/<split>/<name>.off of symlinks to the real meshes."""
    for rel, cls, split in meshes:
        target = root / cls / split / Path(rel).name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.symlink_to(SAMPLE_MESHES / rel)
    return root


def shard_arrays(out: Path) -> dict[str, dict[str, np.ndarray]]:
    """Every dataset of every shard, keyed by the object's name (not its index)."""
    result = {}
    for shard in sorted((out / "shards").glob("*.h5")):
        with h5py.File(shard, "r") as f:
            result[str(f.attrs["name"])] = {k: f[k][()] for k in f if k != "object_index"}
    return result


def assert_same_samples(a: Path, b: Path) -> None:
    sa, sb = shard_arrays(a), shard_arrays(b)
    assert sa.keys() == sb.keys()
    for name in sa:
        assert sa[name].keys() == sb[name].keys()
        for key in sa[name]:
            assert np.array_equal(sa[name][key], sb[name][key]), (name, key)
            assert sa[name][key].dtype == sb[name][key].dtype


@pytest.fixture(scope="module")
def tree(tmp_path_factory) -> Path:
    return make_tree(tmp_path_factory.mktemp("meshes"))


@pytest.fixture(scope="module")
def dense_run(tree, tmp_path_factory):
    out = tmp_path_factory.mktemp("dense")
    summary = run_farm(tree, out, params=PARAMS, options=RunOptions(progress=False, command="test dense"))
    return out, summary


@pytest.fixture(scope="module")
def compact_run(tree, tmp_path_factory):
    out = tmp_path_factory.mktemp("compact")
    summary = run_farm(tree, out, params=FarmParams(**{**PARAMS.to_dict(), "storage": "compact"}), options=RunOptions(progress=False))
    return out, summary


def _manifest(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / MANIFEST_FILE).read_text().splitlines()]


def _expected_object(rec: dict, params: FarmParams, root: Path):
    """What a shard must hold, rebuilt from the public pieces: the dense cloud of the
    object's *name* key and its visibility by the farm's method from every pose (``root``:
    the folder the farm was given, which ``source`` is relative to)."""
    mesh = load_mesh(root / rec["source"])
    dense = dense_cloud(mesh, object_key(rec["name"]), seed=params.seed, count=params.dense_points)
    with method_info(params.method).session(mesh, dense.points, dense.face_index) as scene:
        visible = [scene.visible(camera_on_sphere(el, az, params.radius, resolution=params.resolution)) for el, az in params.poses]
    return mesh, dense, visible


# -- inputs ------------------------------------------------------------------------------
def test_discover_tree_labels_splits_and_keys(tree):
    objects = discover_objects(tree)
    assert [o.name for o in objects] == sorted(o.name for o in objects)
    assert {(o.class_name, o.split) for o in objects} == {(c, s) for _, c, s in SMALL_MESHES}
    shape_names = sorted({c for _, c, _ in SMALL_MESHES})
    assert all(o.label == shape_names.index(o.class_name) for o in objects)
    assert [o.index for o in objects] == list(range(len(objects)))
    chair = next(o for o in objects if o.class_name == "chair")
    assert chair.name == "chair/train/chair_0001" and chair.key == object_key("chair/train/chair_0001")

    # the key (and so every sample) does not depend on the selection
    subset = discover_objects(tree, classes="chair,sofa", splits=["train"])
    assert [o.name for o in subset] == ["chair/train/chair_0001"]
    assert subset[0].key == chair.key
    assert len(discover_objects(tree, per_class=1, splits="test")) == 2
    with pytest.raises(InvalidInputError, match="not found"):
        discover_objects(tree, classes=["car"])
    with pytest.raises(InvalidInputError, match="no such"):
        discover_objects(tree / "missing")


def test_discover_flat_folder_and_list_file(tmp_path):
    flat = tmp_path / "flat"
    flat.mkdir()
    for rel, _, _ in SMALL_MESHES[:3]:
        (flat / Path(rel).name).symlink_to(SAMPLE_MESHES / rel)
    objects = discover_objects(flat)
    assert {o.class_name for o in objects} == {"sofa", "monitor", "chair"}  # from <class>_<NNNN>
    assert {o.split for o in objects} == {"train"}

    listing = tmp_path / "list.txt"
    listing.write_text(
        f"# path label [split]\n{SAMPLE_MESHES / SMALL_MESHES[0][0]} couch test\nflat/{Path(SMALL_MESHES[2][0]).name}   seat\n\n"
    )
    objects = discover_objects(listing)
    # sorted by name: the absolute path ("/...") before "flat/..."
    assert [(o.class_name, o.split, o.label) for o in objects] == [("couch", "test", 0), ("seat", "train", 1)]
    assert objects[1].name == "flat/chair_0001" and Path(objects[1].source).is_file()
    bad = tmp_path / "bad.txt"
    bad.write_text("just_a_path\n")
    with pytest.raises(InvalidInputError, match="bad.txt:1"):
        discover_objects(bad)


def test_shards_partition_the_plan(tree):
    objects = discover_objects(tree)
    parts = [select_shard(objects, i, 3) for i in range(3)]
    assert sorted(o.index for p in parts for o in p) == list(range(len(objects)))
    assert parse_shard("2/16") == (2, 16)
    for bad in ("16/16", "a/b", "3"):
        with pytest.raises(InvalidInputError):
            parse_shard(bad)


# -- output layout ----------------------------------------------------------------------------
def test_dense_layout_counts_labels_manifest_card(dense_run):
    out, summary = dense_run
    assert summary.finished and summary.failed == 0 and summary.done == len(SMALL_MESHES)
    shape_names = (out / SHAPE_NAMES_FILE).read_text().splitlines()
    assert shape_names == sorted({c for _, c, _ in SMALL_MESHES})
    manifest = [json.loads(line) for line in (out / MANIFEST_FILE).read_text().splitlines()]
    assert len(manifest) == len(SMALL_MESHES)
    total = 0
    for rec in manifest:
        assert rec["status"] == "ok" and rec["error"] is None
        for key in ("source", "class_name", "split", "shards", "n_visible", "seed", "key", "time_s", "renderer"):
            assert key in rec
        assert len(rec["n_visible"]) == len(PARAMS.poses) and min(rec["n_visible"]) > 0
        assert rec["key"] == object_key(rec["name"]) and rec["seed"] == PARAMS.seed
        with h5py.File(out / rec["shards"][0], "r") as f:
            b = len(PARAMS.poses) * PARAMS.samples_per_view
            assert f["data"].shape == (b, PARAMS.n_points, 3) and f["data"].dtype == np.float32
            assert f["label"].shape == (b,) and f["label"].dtype.kind == "i"
            assert set(f["label"][()]) == {shape_names.index(rec["class_name"])} == {rec["label"]}
            for key in ("elevation_deg", "azimuth_deg", "object_index", "sample_index", "pose_index", "n_visible"):
                assert f[key].shape == (b,)
            assert set(f["object_index"][()]) == {rec["object_index"]}
            assert np.array_equal(f["sample_index"][()], np.tile(np.arange(PARAMS.samples_per_view), len(PARAMS.poses)))
            poses = np.asarray(PARAMS.poses)[f["pose_index"][()]]
            assert np.array_equal(f["elevation_deg"][()], poses[:, 0]) and np.array_equal(f["azimuth_deg"][()], poses[:, 1])
            assert np.abs(f["data"][()]).max() <= 0.5 + 1e-6  # normalised: max extent 1, centred
        total += rec["n_samples"]
    assert total == summary.samples == len(SMALL_MESHES) * len(PARAMS.poses) * PARAMS.samples_per_view
    for split in ("train", "test"):
        listed = (out / f"{split}_files.txt").read_text().split()
        assert listed == [r["shards"][0] for r in manifest if r["split"] == split]
    card = json.loads((out / CARD_FILE).read_text())
    assert card["version"] and card["commands"] == ["test dense"] and card["params"]["n_points"] == PARAMS.n_points
    assert card["poses"] == [list(p) for p in PARAMS.poses] and card["n_samples"] == total
    assert "FAILED" not in summary.format() and "samples/MB" in summary.format()
    assert not list(out.rglob(".*.tmp"))


# -- determinism ------------------------------------------------------------------------------
@pytest.mark.slow
def test_worker_count_does_not_change_a_bit(tree, dense_run, tmp_path):
    summary = run_farm(tree, tmp_path / "w2", params=PARAMS, options=RunOptions(workers=2, progress=False))
    assert summary.workers == "2 processes" and summary.done == len(SMALL_MESHES)
    assert_same_samples(dense_run[0], tmp_path / "w2")


def test_shards_then_merge_equal_one_run(tree, dense_run, tmp_path):
    for i in range(2):
        s = run_farm(tree, tmp_path / f"task{i}", params=PARAMS, options=RunOptions(shard=(i, 2), progress=False))
        assert not s.finished and not (tmp_path / f"task{i}" / CARD_FILE).exists()
    with pytest.raises(InvalidInputError, match="no result yet"):
        merge_farm([tmp_path / "task0"], tmp_path / "partial", progress=False)
    merged = merge_farm([tmp_path / "task0", tmp_path / "task1"], tmp_path / "merged", progress=False)
    assert merged.finished and merged.done == len(SMALL_MESHES)
    assert_same_samples(dense_run[0], tmp_path / "merged")
    a = json.loads((dense_run[0] / CARD_FILE).read_text())
    b = json.loads((tmp_path / "merged" / CARD_FILE).read_text())
    assert (a["params_digest"], a["plan_digest"], a["n_samples"]) == (b["params_digest"], b["plan_digest"], b["n_samples"])

    # tasks sharing one --out (a shared file system), merged in place
    for i in (1, 0):
        run_farm(tree, tmp_path / "shared", params=PARAMS, options=RunOptions(shard=(i, 2), progress=False))
    merge_farm([tmp_path / "shared"], progress=False)
    assert_same_samples(dense_run[0], tmp_path / "shared")
    assert OccludedDataset(tmp_path / "shared").to_arrays()[0].shape[0] == dense_run[1].samples


def test_selection_does_not_change_an_objects_samples(tree, dense_run, tmp_path):
    run_farm(tree, tmp_path / "sel", params=PARAMS, options=RunOptions(classes=["stool", "sofa"], progress=False))
    full, sel = shard_arrays(dense_run[0]), shard_arrays(tmp_path / "sel")
    assert set(sel) == {"sofa/test/sofa_0681", "stool/train/stool_0002"}
    for name, arrays in sel.items():
        assert np.array_equal(arrays["data"], full[name]["data"])


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_data_set(tree, dense_run, tmp_path):
    pytest.importorskip("distributed")
    summary = run_farm(tree, tmp_path / "dask", params=PARAMS, options=RunOptions(dask_local=2, progress=False))
    assert summary.workers.startswith("dask") and summary.done == len(SMALL_MESHES)
    assert_same_samples(dense_run[0], tmp_path / "dask")


@pytest.mark.slow
def test_dask_scheduler_address_gives_the_same_data_set(tree, dense_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        summary = run_farm(tree, tmp_path / "sched", params=PARAMS, options=RunOptions(scheduler=address, progress=False))
    assert summary.workers == f"dask {address}" and summary.done == len(SMALL_MESHES)
    assert_same_samples(dense_run[0], tmp_path / "sched")


@pytest.mark.slow
def test_unreachable_dask_scheduler_is_a_clear_error(tree, tmp_path, capsys):
    dask = pytest.importorskip("dask")
    pytest.importorskip("distributed")
    # nothing listens on port 1; a short connect timeout keeps the test quick
    with dask.config.set({"distributed.comm.timeouts.connect": "2s"}):
        status = cli_main(["farm", str(tree), "--out", str(tmp_path / "x"), "--views", "0:0", "--points", "16",
                           "--dense-points", "256", "--scheduler", "tcp://127.0.0.1:1", "--no-progress"])  # fmt: skip
    assert status == 2
    err = capsys.readouterr().err
    assert "cannot reach the Dask scheduler tcp://127.0.0.1:1" in err and "Traceback" not in err
    assert not list((tmp_path / "x").rglob("*.h5"))


def test_compact_reconstructs_the_dense_output_exactly(compact_run, dense_run):
    summary = compact_run[1]
    assert summary.samples == dense_run[1].samples
    dense_ds, compact_ds = OccludedDataset(dense_run[0]), OccludedDataset(compact_run[0])
    assert compact_ds.storage == "compact" and len(compact_ds) == len(dense_ds)
    (a, la), (b, lb) = dense_ds.to_arrays(), compact_ds.to_arrays()
    assert a.dtype == b.dtype == np.float32
    assert np.array_equal(a, b) and np.array_equal(la, lb)
    for i in (0, len(dense_ds) // 2, len(dense_ds) - 1):
        assert np.array_equal(dense_ds[i][0], compact_ds[i][0]) and dense_ds[i][2] == compact_ds[i][2]


# -- content: the samples are the named object's occluded points -----------------------------
def test_dense_shards_hold_occluded_samples_of_the_named_objects_dense_cloud(dense_run, tree):
    # Every row is exactly the draw of (seed, object_key(name), pose, sample) from the
    # visible points of the dense cloud of object_key(name); and the oracle agrees that
    # the points are visible (a generator without occlusion samples ~half hidden points).
    out = dense_run[0]
    hidden = total = 0
    for rec in _manifest(out):
        mesh, dense, visible = _expected_object(rec, PARAMS, tree)
        assert rec["n_visible"] == [int(v.sum()) for v in visible]
        with h5py.File(out / rec["shards"][0], "r") as f:
            data, pose_index, sample_index = f["data"][()], f["pose_index"][()], f["sample_index"][()]
            assert int(f.attrs["key"]) == object_key(rec["name"])
        for row in range(len(data)):
            pose, s = int(pose_index[row]), int(sample_index[row])
            [chosen] = pose_samples(
                np.flatnonzero(visible[pose]), PARAMS.n_points, seed=PARAMS.seed, key=object_key(rec["name"]),
                pose_index=pose, sample_indices=[s],
            )  # fmt: skip
            assert np.array_equal(data[row], dense.points[chosen].astype(np.float32)), (rec["name"], row)
            camera = camera_on_sphere(*PARAMS.poses[pose], PARAMS.radius)
            truth = visible_mask(mesh, dense.points[chosen], camera, "oracle", face_index=dense.face_index[chosen])
            hidden += int((~truth).sum())
            total += len(chosen)
    # measured: 12 of the 5 x 4 x 2 x 128 = 5120 sampled points (0.23 %) hidden by the oracle
    # (the z-buffer at 96² px); a generator without occlusion: ~50 %
    assert hidden <= 0.01 * total, (hidden, total)


def test_compact_shards_hold_the_named_dense_cloud_and_its_visibility_bits(compact_run, tree):
    # the documented layout: dense_points of the object's name key, and per pose the
    # visibility mask packed by numpy.packbits (big bit order: point 0 is bit 7 of byte 0)
    out = compact_run[0]
    for rec in _manifest(out):
        _, dense, visible = _expected_object(rec, PARAMS, tree)
        with h5py.File(out / rec["shards"][0], "r") as f:
            assert np.array_equal(f["dense_points"][()], dense.points.astype(np.float32)), rec["name"]
            bits, n_visible = f["visible_bits"][()], f["n_visible"][()]
            assert int(f.attrs["n_dense"]) == len(dense.points)
        for pose, vis in enumerate(visible):
            assert np.array_equal(np.unpackbits(bits[pose], count=len(vis)).astype(bool), vis), (rec["name"], pose)
            assert np.array_equal(unpack_visible(bits[pose], len(vis)), vis)
            assert bits[pose][0] >> 7 == vis[0]
            assert n_visible[pose] == vis.sum() == rec["n_visible"][pose]


@pytest.mark.slow
def test_topped_up_poses_through_the_farm_and_the_reader(tree, tmp_path):
    # fewer dense points visible than a sample holds: every pose is topped up and no sample is
    # padded; dense and compact storage serve the same bytes, whatever the worker count, and verify
    # passes on both
    from zbuf_occlude.dataset.verify import verify_dataset

    params = FarmParams(**{**PARAMS.to_dict(), "n_points": 600, "dense_points": 800, "samples_per_view": 2})
    runs = {}
    for storage, workers in (("dense", 1), ("compact", 1), ("compact_w2", 2)):
        p = FarmParams(**{**params.to_dict(), "storage": storage.split("_")[0]})
        options = RunOptions(classes="sofa,stool", progress=False, workers=workers)
        summary = run_farm(tree, tmp_path / storage, params=p, options=options)
        assert summary.done == 2 and summary.padded == 0 and "padded" not in summary.format()
        assert json.loads((tmp_path / storage / CARD_FILE).read_text())["n_padded_samples"] == 0
        report = verify_dataset(tmp_path / storage)
        assert report.ok, report.problems
        runs[storage] = OccludedDataset(tmp_path / storage)
    assert_same_samples(tmp_path / "compact", tmp_path / "compact_w2")
    for rec in _manifest(tmp_path / "dense"):
        assert rec["n_padded_poses"] == 0 and min(rec["n_topped_up"]) > 0 and min(rec["n_visible"]) >= 600
    assert _manifest(tmp_path / "dense") != [] and [r["n_topped_up"] for r in _manifest(tmp_path / "compact")] == [
        r["n_topped_up"] for r in _manifest(tmp_path / "dense")
    ]
    dense_ds, compact_ds = runs["dense"], runs["compact"]
    assert len(dense_ds) == len(compact_ds) == 2 * len(params.poses) * 2
    assert all(np.array_equal(x, y) for x, y in zip(dense_ds.to_arrays(), compact_ds.to_arrays()))
    by_name = {}
    for rec in _manifest(tmp_path / "dense"):
        _, dense, visible = _expected_object(rec, params, tree)
        by_name[rec["name"]] = (dense.points.astype(np.float32), visible)
    for i in range(len(dense_ds)):
        (a, _, meta), (b, _, meta_b) = dense_ds[i], compact_ds[i]
        assert np.array_equal(a, b) and meta == meta_b
        assert not meta["padded"] and meta["n_topped_up"] > 0 and len(np.unique(a, axis=0)) == 600  # distinct points
        points, visible = by_name[meta["name"]]
        vis = visible[meta["pose_index"]]
        assert meta["n_visible"] - meta["n_topped_up"] == vis.sum() < 600
        # the points taken from the dense cloud are visible ones; the others are the pose's top-up
        dense_rows = {p.tobytes() for p in a} & {p.tobytes() for p in points}
        assert dense_rows <= {p.tobytes() for p in points[vis]} and len(dense_rows) < 600


def test_a_tiny_visible_surface_pads_through_the_farm_and_is_counted(shingles_tree, tmp_path, caplog):
    # the shingles show from 0:0 and 0:180 only strips of the faces they see: even topped up, their
    # samples are short and padded, counted per sample in the card, the warning and the reader
    from zbuf_occlude.dataset.verify import verify_dataset

    params = FarmParams(views="0:0,0:180", samples_per_view=2, n_points=1024, dense_points=4000, resolution=64, method="oracle")
    arrays = {}
    for storage in ("dense", "compact"):
        out = tmp_path / storage
        with caplog.at_level("WARNING"):
            summary = run_farm(shingles_tree, out, params=FarmParams(**{**params.to_dict(), "storage": storage}),
                               options=RunOptions(progress=False))  # fmt: skip
        (rec,) = _manifest(out)
        assert rec["n_padded_poses"] == 2 and min(rec["n_topped_up"]) > 0 and max(rec["n_visible"]) < 1024
        assert summary.padded == 4 == json.loads((out / CARD_FILE).read_text())["n_padded_samples"]
        assert any("4 of 4 samples hold repeated points" in r.getMessage() for r in caplog.records)
        assert verify_dataset(out).ok
        ds = OccludedDataset(out)
        for i in range(len(ds)):
            points, _, meta = ds[i]
            assert meta["padded"] and len(np.unique(points, axis=0)) == meta["n_visible"] < 1024
        arrays[storage] = ds.to_arrays()[0]
    assert np.array_equal(arrays["dense"], arrays["compact"])


@pytest.mark.slow
def test_the_readme_and_farm_guide_examples_pad_under_5_percent(tmp_path, monkeypatch):
    # the first examples a user runs: README's farm line and the farm guide's demo, as written
    readme = (REPO_ROOT / "README.md").read_text()
    guide = (REPO_ROOT / "docs" / "farm.md").read_text()
    lines = [next(line for line in text.splitlines() if line.startswith("zbuf-occlude farm data/samples "))
             for text in (readme, guide)]  # fmt: skip
    monkeypatch.chdir(REPO_ROOT)  # the examples name data/samples relative to a checkout
    for n, line in enumerate(lines):
        args = shlex.split(line)[1:]
        args[args.index("--out") + 1] = str(tmp_path / f"example{n}")
        assert cli_main([*args, "--no-progress"] if "--no-progress" not in args else args) == 0
        card = json.loads((tmp_path / f"example{n}" / CARD_FILE).read_text())
        assert card["n_samples"] > 0 and card["n_padded_samples"] < 0.05 * card["n_samples"], (line, card["n_padded_samples"])


# -- resume, failures, errors ---------------------------------------------------------------
@pytest.mark.slow
def test_sigkill_mid_run_then_resume_loses_and_repeats_nothing(tree, tmp_path):
    out = tmp_path / "killed"
    params = FarmParams(**{**PARAMS.to_dict(), "views": "fibonacci:24"})
    script = textwrap.dedent(
        f"""
        from zbuf_occlude.farm import FarmParams, RunOptions, run_farm
        run_farm({str(tree)!r}, {str(out)!r}, params=FarmParams(**{params.to_dict()!r}), options=RunOptions(progress=False))
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=REPO_ROOT)
    deadline = time.monotonic() + 120
    try:
        while not list((out / "records").glob("*.json")):
            assert proc.poll() is None, "the farm ended before it could be killed"
            assert time.monotonic() < deadline
            time.sleep(0.01)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    before = {p.name: p.stat().st_mtime_ns for p in (out / "records").glob("*.json")}
    assert 0 < len(before) < len(SMALL_MESHES)
    assert not (out / CARD_FILE).exists()

    summary = run_farm(tree, out, params=params, options=RunOptions(progress=False))
    assert summary.finished and summary.done == len(SMALL_MESHES) and summary.resumed == len(before)
    after = {p.name: p.stat().st_mtime_ns for p in (out / "records").glob("*.json")}
    assert all(after[name] == mtime for name, mtime in before.items())  # not redone
    assert not list(out.rglob(".*.tmp"))

    clean = run_farm(tree, tmp_path / "clean", params=params, options=RunOptions(progress=False))
    assert clean.samples == summary.samples
    assert_same_samples(out, tmp_path / "clean")  # nothing missing, nothing twice
    again = run_farm(tree, out, params=params, options=RunOptions(progress=False))
    assert again.resumed == len(SMALL_MESHES) and again.views == 0


def test_other_parameters_need_overwrite(tree, dense_run, tmp_path):
    out = tmp_path / "ow"
    small = FarmParams(**{**PARAMS.to_dict(), "views": "0:0"})
    run_farm(tree, out, params=small, options=RunOptions(classes=["chair"], progress=False))
    with pytest.raises(InvalidInputError, match="other parameters"):
        run_farm(tree, out, params=PARAMS, options=RunOptions(classes=["chair"], progress=False))
    with pytest.raises(InvalidInputError, match="other objects"):
        run_farm(tree, out, params=small, options=RunOptions(progress=False))
    summary = run_farm(tree, out, params=PARAMS, options=RunOptions(classes=["chair"], overwrite=True, progress=False))
    assert summary.resumed == 0 and summary.samples == len(PARAMS.poses) * PARAMS.samples_per_view


@pytest.mark.slow
def test_corrupt_mesh_is_recorded_and_skipped(tmp_path):
    root = make_tree(tmp_path / "meshes", SMALL_MESHES[:2])
    bad = root / "chair" / "train" / "chair_0999.off"
    bad.parent.mkdir(parents=True)
    bad.write_text("OFF\n3 1 0\n0 0 0\n1 nan 0\n")
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    add_farm_parser(sub)
    add_farm_merge_parser(sub)
    p = PARAMS
    args = parser.parse_args(
        ["farm", str(root), "--out", str(tmp_path / "out"), "--views", p.views, "--samples-per-view", str(p.samples_per_view),
         "--points", str(p.n_points), "--dense-points", str(p.dense_points), "--resolution", str(p.resolution), "--no-progress"]
    )  # fmt: skip
    assert args.func(args) == 1  # exit status: something failed
    manifest = [json.loads(line) for line in (tmp_path / "out" / MANIFEST_FILE).read_text().splitlines()]
    by_name = {r["name"]: r for r in manifest}
    assert by_name["chair/train/chair_0999"]["status"] == "failed"
    assert "MeshLoadError" in by_name["chair/train/chair_0999"]["error"]
    assert sum(r["status"] == "ok" for r in manifest) == 2
    ds = OccludedDataset(tmp_path / "out")
    assert {ds.metadata(i)["class_name"] for i in range(len(ds))} == {"sofa", "monitor"}
    assert "chair_0999" not in (tmp_path / "out" / "train_files.txt").read_text()
    args = parser.parse_args(["farm-merge", str(tmp_path / "out"), "--no-progress"])
    assert args.func(args) == 1


def test_unwritable_output_folder(tree, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    with pytest.raises(OutputError, match="cannot create the output folder"):
        run_farm(tree, blocker / "out", params=PARAMS, options=RunOptions(progress=False))


@pytest.mark.parametrize("error", [OSError(errno.ENOSPC, "No space left on device"), OSError("file write failed: No space left on device")])
def test_disk_full_is_a_clear_error_and_leaves_no_partial_files(tree, tmp_path, monkeypatch, error):
    def full(*args, **kwargs):
        raise error

    monkeypatch.setattr(h5py, "File", full)
    with pytest.raises(OutputError, match="disk full"):
        run_farm(tree, tmp_path / "full", params=PARAMS, options=RunOptions(classes=["chair"], progress=False))
    assert not list((tmp_path / "full").rglob("*.h5")) and not list((tmp_path / "full").rglob(".*.tmp"))


@pytest.mark.slow
def test_cli_farm_and_farm_merge_run_with_their_options(tree, tmp_path):
    # the options reach run_farm: selection, rendering, storage, seed, shards, merge
    base = ["--classes", "chair,sofa,stool", "--per-class", "1", "--splits", "train", "--views", "0:0,40:90",
            "--samples-per-view", "3", "--points", "64", "--density", "2000", "--resolution", "64",
            "--storage", "compact", "--no-progress"]  # fmt: skip
    common = [*base, "--seed", "7", "--method", "zbuffer"]
    for i in range(2):
        assert cli_main(["farm", str(tree), "--out", str(tmp_path / f"t{i}"), "--shard", f"{i}/2", *common]) == 0
    assert not (tmp_path / "t0" / CARD_FILE).exists()  # a shard is not a finished data set
    assert cli_main(["farm-merge", str(tmp_path / "t0"), str(tmp_path / "t1"), "--out", str(tmp_path / "m"), "--no-progress"]) == 0
    ds = OccludedDataset(tmp_path / "m")
    card = json.loads((tmp_path / "m" / CARD_FILE).read_text())
    assert ds.storage == "compact" and ds.n_points == 64
    assert card["params"]["seed"] == 7 and card["params"]["density"] == 2000.0 and card["params"]["dense_points"] is None
    assert card["params"]["resolution"] == 64 and card["poses"] == [[0.0, 0.0], [40.0, 90.0]]
    assert card["params"]["method"] == "zbuffer"
    names = {ds.metadata(i)["name"] for i in range(len(ds))}
    assert names == {"chair/train/chair_0001", "stool/train/stool_0002"}  # sofa is in test only
    assert len(ds) == 2 * 2 * 3
    manifest = _manifest(tmp_path / "m")
    for rec in manifest:  # --density 2000: about 2000 points per unit area of the normalised mesh
        area = load_mesh(tree / rec["source"]).area
        with h5py.File(tmp_path / "m" / rec["shards"][0], "r") as f:
            assert abs(int(f.attrs["n_dense"]) - 2000 * area) < 5 * np.sqrt(2000 * area) + 1
    # --seed 7 and the same object in a seed-0 run: other samples
    assert cli_main(["farm", str(tree), "--out", str(tmp_path / "s0"), *base]) == 0
    other = OccludedDataset(tmp_path / "s0", classes="chair")
    assert not np.array_equal(other[0][0], OccludedDataset(tmp_path / "m", classes="chair")[0][0])
    # usage errors exit 2 before any work
    for bad in (["--density", "1", "--dense-points", "5"], ["--scheduler", "tcp://h:1", "--dask-local", "2"]):
        with pytest.raises(SystemExit) as exc:
            cli_main(["farm", str(tree), "--out", str(tmp_path / "bad"), *bad])
        assert exc.value.code == 2
    assert cli_main(["farm", str(tree), "--out", str(tmp_path / "bad"), "--shard", "2/2", "--no-progress"]) == 2
    assert cli_main(["farm", str(tree), "--out", str(tmp_path / "bad"), "--method", "nope", "--no-progress"]) == 2
    assert not (tmp_path / "bad").exists() or not list((tmp_path / "bad").rglob("*.h5"))


def test_ready_plan_of_repeated_meshes(tmp_path):
    # the benchmark's way to repeat a few real meshes as distinct objects (distinct keys)
    src = str(SAMPLE_MESHES / SMALL_MESHES[2][0])
    objects = [FarmObject(i, f"rep{i}/chair_0001", src, "chair", "train", 0) for i in range(2)]
    summary = run_farm(objects, tmp_path / "rep", params=PARAMS, options=RunOptions(progress=False))
    arrays = shard_arrays(tmp_path / "rep")
    assert summary.done == 2 and not np.array_equal(arrays["rep0/chair_0001"]["data"], arrays["rep1/chair_0001"]["data"])


# -- the worker alone: one object, its shard and its record (oracle: no GL, fast) ----------------
def _box_object(tmp_path: Path) -> FarmObject:
    import trimesh

    path = tmp_path / "box.off"
    trimesh.creation.box(extents=(1.0, 0.5, 0.25)).export(path)
    return FarmObject(index=3, name="box/train/box_0001", source=str(path), class_name="box", split="train", label=2)


#: From el=0 the box shows its 0.5 x 0.25 end (~7 % of the dense points), from el=90 its top
#: (~29 %): with 150 points the first pose is topped up (not padded), the second needs nothing.
WORKER_PARAMS = dict(views="0:0,90:0", samples_per_view=3, n_points=150, dense_points=1000, resolution=32, method="oracle", seed=5)


def _worker_truth(obj: FarmObject, params: FarmParams):
    mesh = load_mesh(obj.source)
    dense = dense_cloud(mesh, object_key(obj.name), seed=params.seed, count=params.dense_points)
    visible = [visible_mask(mesh, dense.points, camera_on_sphere(el, az, params.radius, resolution=params.resolution), "oracle",
                            face_index=dense.face_index) for el, az in params.poses]  # fmt: skip
    return mesh, dense, visible


def _check_record(rec: dict, obj: FarmObject, params: FarmParams, out: Path, mesh, dense, visible) -> None:
    import os

    from zbuf_occlude.io.atomic import file_sha256

    n_visible = [int(v.sum()) for v in visible]
    assert 0 < n_visible[0] < params.n_points <= n_visible[1]
    assert rec["status"] == "ok" and rec["error"] is None
    for field in ("index", "name", "source", "class_name", "label", "split", "key"):
        assert rec["object_index" if field == "index" else field] == getattr(obj, field), field
    assert (rec["seed"], rec["params_digest"]) == (params.seed, params.digest())
    # the end-on pose is topped up to n_points distinct visible points, the top pose is not touched
    assert rec["n_topped_up"][0] > 0 and rec["n_visible"][0] == n_visible[0] + rec["n_topped_up"][0] >= params.n_points
    assert rec["n_topped_up"][1] == 0 and rec["n_visible"][1] == n_visible[1] and rec["n_padded_poses"] == 0
    assert all(type(v) is int for v in rec["n_visible"])  # counts, not floats, in the JSON record
    assert rec["n_dense"] == len(dense.points) == params.dense_points and rec["n_faces"] == len(mesh.faces) == 12
    assert rec["sha256"] == [file_sha256(out / s) for s in rec["shards"]]
    assert rec["bytes"] == sum((out / s).stat().st_size for s in rec["shards"]) > 0
    assert "host" not in rec and rec["pid"] == os.getpid() and rec["time_s"] >= 0 and rec["peak_rss_mb"] > 1
    assert isinstance(rec["renderer"], str) and rec["renderer"]
    from zbuf_occlude.farm.config import record_path

    assert json.loads(record_path(out, obj.index).read_text()) == rec


def _shard_attrs(obj: FarmObject, params: FarmParams) -> dict:
    from zbuf_occlude import __version__

    return {"format_version": FORMAT_VERSION, "storage": params.storage, "object_index": obj.index, "name": obj.name,
            "class_name": obj.class_name, "split": obj.split, "label": obj.label, "key": obj.key, "seed": params.seed,
            "n_points": params.n_points, "samples_per_view": params.samples_per_view, "params_digest": params.digest(),
            "zbuf_occlude_version": __version__}  # fmt: skip


def test_worker_compact_shard_holds_the_dense_cloud_bits_and_poses(tmp_path):
    from zbuf_occlude.farm.config import record_path, shard_path
    from zbuf_occlude.farm.worker import process_object

    obj, params = _box_object(tmp_path), FarmParams(**WORKER_PARAMS, storage="compact")
    out = tmp_path / "out"
    rec = process_object(obj, params, out)
    mesh, dense, visible = _worker_truth(obj, params)
    _check_record(rec, obj, params, out, mesh, dense, visible)
    assert json.loads(record_path(out, obj.index).read_text()) == rec
    assert rec["shards"] == [shard_path(obj)] and rec["n_samples"] == 2 * 3  # both poses see something
    with h5py.File(out / shard_path(obj), "r") as f:
        assert np.array_equal(f["dense_points"][()], dense.points.astype(np.float32)) and f["dense_points"].dtype == np.float32
        bits = f["visible_bits"][()]
        assert bits.shape == (2, (1000 + 7) // 8) and bits.dtype == np.uint8
        assert all(np.array_equal(unpack_visible(bits[i], 1000), visible[i]) for i in range(2))
        assert f["visible_bits"].compression == "gzip"
        assert f["n_visible"][()].tolist() == rec["n_visible"] and f["n_topped_up"][()].tolist() == rec["n_topped_up"]
        assert f["elevation_deg"][()].tolist() == [0.0, 90.0] and f["azimuth_deg"][()].tolist() == [0.0, 0.0]
        topup = f["topup_points"][()]
        attrs = {k: (v.item() if hasattr(v, "item") else v) for k, v in f.attrs.items()}
    assert attrs == {**_shard_attrs(obj, params), "n_dense": 1000}
    # the top-up points of each pose, pose after pose, as float32: those occlude_poses draws
    poses = list(occlude_poses(mesh, params.poses, key=obj.key, draws=PoseDraws(n_points=150, samples_per_view=0), seed=5, dense=dense,
                               method="oracle", cameras=CameraSphere(resolution=32)))  # fmt: skip
    expected = np.concatenate([p.topped_up.points for p in poses]).astype(np.float32)
    assert topup.dtype == np.float32 and len(topup) == sum(rec["n_topped_up"]) and np.array_equal(topup, expected)


def test_worker_dense_shard_holds_each_poses_samples(tmp_path):
    from zbuf_occlude.farm.config import shard_path
    from zbuf_occlude.farm.worker import process_object

    obj, params = _box_object(tmp_path), FarmParams(**WORKER_PARAMS, storage="dense")
    out = tmp_path / "out"
    rec = process_object(obj, params, out)
    mesh, dense, visible = _worker_truth(obj, params)
    _check_record(rec, obj, params, out, mesh, dense, visible)
    assert rec["shards"] == [shard_path(obj)] and rec["n_samples"] == 6
    with h5py.File(out / shard_path(obj), "r") as f:
        assert f["pose_index"][()].tolist() == [0, 0, 0, 1, 1, 1] and f["object_index"][()].tolist() == [3] * 6
        data = f["data"][()]
        attrs = {k: (v.item() if hasattr(v, "item") else v) for k, v in f.attrs.items()}
    for row in data[3:]:  # the top pose: every point a dense point visible from it
        hit = np.abs(dense.points.astype(np.float32)[None] - row[:, None]).max(axis=2) == 0
        assert hit.any(axis=1).all() and visible[1][hit.argmax(axis=1)].all()
    for row in data[:3]:  # the end-on pose: 150 distinct points, its visible dense points among them
        assert len(np.unique(row, axis=0)) == 150
    assert {k: attrs[k] for k in _shard_attrs(obj, params)} == _shard_attrs(obj, params)
    # exactly the draws of (seed, key, pose, sample) from the pose's visible and top-up points
    poses = list(occlude_poses(mesh, params.poses, key=obj.key, draws=PoseDraws(n_points=150, samples_per_view=0), seed=5, dense=dense,
                               method="oracle", cameras=CameraSphere(resolution=32)))  # fmt: skip
    for pose in (0, 1):
        extra = poses[pose].topped_up
        chosen = pose_samples(np.flatnonzero(visible[pose]), 150, seed=5, key=obj.key, pose_index=pose, sample_indices=range(3),
                              n_dense=1000, n_topped_up=len(extra))  # fmt: skip
        table = np.concatenate([dense.points, extra.points]).astype(np.float32)
        assert np.array_equal(data[3 * pose : 3 * pose + 3], table[np.stack(chosen)])


@pytest.mark.parametrize("storage", ["npz", "ply"])
def test_worker_sample_files_one_per_sample(tmp_path, storage):
    from zbuf_occlude.farm.worker import process_object
    from zbuf_occlude.io.clouds import read_npz

    obj, params = _box_object(tmp_path), FarmParams(**WORKER_PARAMS, storage=storage)
    out = tmp_path / "out"
    rec = process_object(obj, params, out)
    mesh, dense, visible = _worker_truth(obj, params)
    _check_record(rec, obj, params, out, mesh, dense, visible)
    assert rec["n_samples"] == len(rec["shards"]) == 6 and all(s.endswith("." + storage) for s in rec["shards"])
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*." + storage)) == sorted(rec["shards"])
    assert all((out / s).read_bytes()[:3] == (b"ply" if storage == "ply" else b"PK\x03") for s in rec["shards"])
    if storage == "npz":
        clouds = [read_npz(out / s) for s in rec["shards"]]
        assert sorted((c.elevation_deg, c.sample_index) for c in clouds) == [(0.0, 0), (0.0, 1), (0.0, 2), (90.0, 0), (90.0, 1), (90.0, 2)]
        # each sample carries its object's provenance and its camera's distance
        assert {(c.provenance, c.radius) for c in clouds} == {(ObjectProvenance(2, "box", obj.source, "train"), params.radius)}


def test_worker_records_a_failed_object_and_raises_fatal_errors(tmp_path, monkeypatch):
    from zbuf_occlude.farm import worker
    from zbuf_occlude.farm.config import record_path

    obj = FarmObject(index=4, name="gone", source=str(tmp_path / "gone.off"), class_name="x", split="test", label=0)
    params = FarmParams(**WORKER_PARAMS, storage="compact")
    rec = worker.process_object(obj, params, tmp_path)
    assert rec["status"] == "failed" and rec["error"].startswith("MeshLoadError: ") and rec["renderer"] is None
    assert rec["shards"] == [] and rec["n_samples"] == 0 and json.loads(record_path(tmp_path, 4).read_text()) == rec

    def full(*a, **k):
        raise OutputError("disk full")

    monkeypatch.setattr(worker, "_render", full)
    with pytest.raises(OutputError):
        worker.process_object(_box_object(tmp_path), params, tmp_path)


def test_worker_provenance_renderer_and_peak_memory(monkeypatch):
    # the record names the GL renderer (or "unknown" if no context: never a failure) and
    # the process's peak resident memory in MiB (ru_maxrss is KiB on Linux)
    import resource

    import zbuf_occlude.render as render
    from zbuf_occlude.farm import worker

    monkeypatch.setattr(render, "context_info", lambda: {"renderer": "R", "backend": "B", "version": "V"})
    worker._renderer_name.cache_clear()
    try:
        assert worker._renderer_name() == "R (B, V)"
        worker._renderer_name.cache_clear()

        def broken():
            raise RuntimeError("no display")

        monkeypatch.setattr(render, "context_info", broken)
        assert worker._renderer_name() == "unknown"
    finally:
        worker._renderer_name.cache_clear()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    assert before <= worker._peak_rss_mb() <= resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def test_worker_sensor_shard_is_the_crops_datasets_and_its_record(tmp_path):
    # farm --sensor: the shard holds farm_datasets' arrays as they are (same order) plus the
    # object's attributes and the sensor; the record counts returns per scan
    from zbuf_occlude.farm.config import shard_path
    from zbuf_occlude.farm.sensor_crops import farm_datasets
    from zbuf_occlude.farm.worker import process_object
    from zbuf_occlude.io.atomic import file_sha256

    obj = _box_object(tmp_path)
    crops = CropDistributions(distance_m=(4.0, 6.0), height_m=(1.0, 1.5), size_m=(2.0, 3.0))
    params = FarmParams(sensor=SensorCropParams("hdl32e", crops), samples_per_view=3, n_points=64, seed=2)
    out = tmp_path / "out"
    rec = process_object(obj, params, out)
    mesh = load_mesh(obj.source)
    expected = farm_datasets(mesh, params.sensor.request(), name=obj.name, label=obj.label, object_index=obj.index, n_samples=3,
                             n_points=64, seed=2, distributions=crops)  # fmt: skip
    n_visible = np.zeros(3, dtype=np.int64)
    n_visible[expected["pose_index"]] = expected["n_visible"]
    assert rec["status"] == "ok" and rec["shards"] == [shard_path(obj)] and rec["n_samples"] == len(expected["data"]) > 0
    assert rec["n_visible"] == n_visible.tolist() and rec["n_dense"] == 0 and rec["n_faces"] == 12
    assert all(type(v) is int for v in rec["n_visible"])
    assert rec["n_padded_poses"] == int(np.count_nonzero((n_visible > 0) & (n_visible < 64)))
    assert rec["sha256"] == [file_sha256(out / shard_path(obj))] and rec["bytes"] == (out / shard_path(obj)).stat().st_size
    with h5py.File(out / shard_path(obj), "r") as f:
        assert list(f.keys()) == sorted(expected) or set(f.keys()) == set(expected)
        for key, value in expected.items():
            assert np.array_equal(f[key][()], value) and f[key].dtype == value.dtype, key
        attrs = {k: (v.item() if hasattr(v, "item") else v) for k, v in f.attrs.items()}
    assert attrs == {**_shard_attrs(obj, params), "sensor": "hdl32e"}


def test_worker_a_pose_with_exactly_n_points_visible_is_not_padded(tmp_path):
    from zbuf_occlude.farm.worker import process_object

    obj = _box_object(tmp_path)
    _, _, visible = _worker_truth(obj, FarmParams(**WORKER_PARAMS, storage="compact"))
    exact = int(visible[1].sum())  # the top pose's visible count
    rec = process_object(obj, FarmParams(**{**WORKER_PARAMS, "n_points": exact}, storage="compact"), tmp_path / "out")
    assert rec["n_visible"][1] == exact and rec["n_topped_up"][1] == 0  # not padded, so not topped up
    assert rec["n_topped_up"][0] > 0 and rec["n_padded_poses"] == 0  # only the end-on pose is topped up


def test_worker_shards_store_no_times_and_compact_bits_are_one_gzip_chunk(tmp_path, monkeypatch):
    # same inputs, same bytes: no HDF5 modification times in any dataset the worker writes
    # (h5py does not read track_times back, so the calls are watched)
    from zbuf_occlude.farm.config import COMPACT_GZIP_LEVEL, shard_path
    from zbuf_occlude.farm.worker import process_object

    calls = []
    create = h5py.Group.create_dataset

    def watch(self, name, *args, **kwargs):
        calls.append((name, kwargs.get("track_times", True)))
        return create(self, name, *args, **kwargs)

    monkeypatch.setattr(h5py.Group, "create_dataset", watch)
    obj = _box_object(tmp_path)
    for storage in ("compact", "dense"):
        calls.clear()
        process_object(obj, FarmParams(**WORKER_PARAMS, storage=storage), tmp_path / storage)
        assert calls and all(track is False for _, track in calls), (storage, calls)
    with h5py.File(tmp_path / "compact" / shard_path(obj), "r") as f:
        assert f["visible_bits"].chunks == f["visible_bits"].shape and f["visible_bits"].compression_opts == COMPACT_GZIP_LEVEL
    calls.clear()
    sensor = SensorCropParams("hdl32e", CropDistributions(distance_m=(4.0, 5.0)))
    process_object(obj, FarmParams(sensor=sensor, samples_per_view=1, n_points=16), tmp_path / "sensor")
    assert calls and all(track is False for _, track in calls), calls


def test_worker_record_format_base_and_timing_fields(tmp_path):
    import re
    from datetime import datetime, timezone

    from zbuf_occlude.farm.config import record_path
    from zbuf_occlude.farm.worker import base_record, process_object

    obj, params = _box_object(tmp_path), FarmParams(**WORKER_PARAMS, storage="compact")
    assert base_record(obj, params) == {
        "object_index": 3, "name": "box/train/box_0001", "source": obj.source, "class_name": "box", "label": 2,
        "split": "train", "key": obj.key, "seed": 5, "params_digest": params.digest(), "status": "pending", "error": None,
        "shards": [], "sha256": [], "n_visible": [], "n_samples": 0, "bytes": 0}  # fmt: skip
    rec = process_object(obj, params, tmp_path)
    text = record_path(tmp_path, 3).read_text()
    assert text == json.dumps(rec, indent=1, sort_keys=True) + "\n"
    assert isinstance(rec["time_s"], float) and rec["time_s"] == round(rec["time_s"], 4) and 0 <= rec["time_s"] < 600
    assert isinstance(rec["peak_rss_mb"], float) and rec["peak_rss_mb"] == round(rec["peak_rss_mb"], 1)
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\+00:00", rec["finished_at"])
    assert abs((datetime.now(timezone.utc) - datetime.fromisoformat(rec["finished_at"])).total_seconds()) < 600


def test_worker_h5_and_npz_samples_carry_the_objects_provenance(tmp_path):
    # generate's layouts keep each sample's class, source and camera radius (dense does not)
    from zbuf_occlude.farm.config import shard_path
    from zbuf_occlude.farm.worker import process_object
    from zbuf_occlude.io.clouds import read_npz

    obj = _box_object(tmp_path)
    rec = process_object(obj, FarmParams(**WORKER_PARAMS, storage="npz", radius=3.5), tmp_path / "npz")
    for s in rec["shards"]:
        c = read_npz(tmp_path / "npz" / s)
        assert (c.class_name, c.source, c.label, c.radius) == ("box", obj.source, 2, 3.5) and len(c.points) == 150
    process_object(obj, FarmParams(**WORKER_PARAMS, storage="h5", radius=3.5), tmp_path / "h5")
    process_object(obj, FarmParams(**WORKER_PARAMS, storage="dense", radius=3.5), tmp_path / "dense")
    with h5py.File(tmp_path / "h5" / shard_path(obj), "r") as f, h5py.File(tmp_path / "dense" / shard_path(obj), "r") as g:
        assert {"face_index", "radius"} <= set(f) and not {"face_index", "radius"} & set(g)
        assert f["radius"][()].tolist() == [3.5] * 6 and f["data"].shape == (6, 150, 3)
        assert [x.decode() if isinstance(x, bytes) else x for x in f["class_name"][()]] == ["box"] * 6
        assert [x.decode() if isinstance(x, bytes) else x for x in f["source"][()]] == [obj.source] * 6
        assert f["object_index"].dtype == np.int64 and f["pose_index"].dtype == np.int64


def test_merge_counts_padded_samples_as_one_run_does(tree, shingles_tree, tmp_path):
    # the shingles' poses stay padded even topped up (a tiny visible surface); the real meshes' are not
    mixed = make_tree(tmp_path / "mixed", SMALL_MESHES[:2])
    (mixed / "shingles" / "train").mkdir(parents=True)
    (mixed / "shingles" / "train" / "shingles_0001.off").symlink_to(shingles_tree / "shingles" / "train" / "shingles_0001.off")
    params = FarmParams(views="0:0,0:180", samples_per_view=1, n_points=1024, dense_points=4000, resolution=64, method="oracle")
    whole = run_farm(mixed, tmp_path / "whole", params=params, options=RunOptions(progress=False))
    assert whole.padded == 2 and whole.samples == 6
    for i in range(2):
        run_farm(mixed, tmp_path / f"task{i}", params=params, options=RunOptions(shard=(i, 2), progress=False))
    merged = merge_farm([tmp_path / "task0", tmp_path / "task1"], tmp_path / "merged", progress=False)
    assert (merged.padded, merged.samples, merged.done) == (whole.padded, whole.samples, whole.done)
    card = json.loads((tmp_path / "merged" / CARD_FILE).read_text())
    assert card["n_padded_samples"] == merged.padded


def test_a_mesh_file_given_to_farm_points_to_generate(tmp_path, capsys):
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    mesh = REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"
    with pytest.raises(InvalidInputError, match="is a mesh file.*zbuf-occlude generate"):
        scan_objects(mesh)
    assert cli_main(["farm", str(mesh), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "is a mesh file" in err and "generate" in err and "expected 'PATH LABEL" not in err


def test_run_options_are_one_object_and_keywords_are_no_options(tmp_path) -> None:
    with pytest.raises(TypeError, match="'workers'"):
        run_farm(tmp_path / "none", tmp_path / "out", PARAMS, workers=2)
    with pytest.raises(TypeError, match="'wrokers'"):
        RunOptions(wrokers=2)


# -- up axis ----------------------------------------------------------------------------------


def _shapenet_tree(root: Path) -> Path:
    """ShapeNetCore v2 layout, two y-up boxes 3 tall along +y (ShapeNetCore's up), OBJ without an exporter comment."""
    import trimesh

    for i, synset in enumerate(("02691156", "03001627")):
        path = root / synset / f"model{i}" / "models" / "model_normalized.obj"
        path.parent.mkdir(parents=True)
        path.write_text(trimesh.exchange.obj.export_obj(trimesh.creation.box(extents=(1.0, 3.0, 0.6)), header=None))
    return root


@pytest.mark.slow
@pytest.mark.parametrize("command", ["farm", "generate"])
def test_shapenet_layout_is_read_y_up_and_the_card_says_so(tmp_path, command):
    tree = _shapenet_tree(tmp_path / "shapenet")
    common = ["--views", "0:0", "--points", "32", "--dense-points", "400", "--resolution", "64"]
    if command == "farm":
        common.append("--no-progress")
    heights = {}
    for up in ("auto", "+z"):
        out = tmp_path / f"{command}_{up}"
        assert cli_main([command, str(tree), "--out", str(out), "--up", up, *common]) == 0
        card = json.loads((out / CARD_FILE).read_text())
        assert card["layout"] == "shapenetcore-v2" and card["up"] == up
        why = "ShapeNetCore layout (+Y up)" if up == "auto" else "explicit"
        assert card["up_axes"] == {f"{'+y' if up == 'auto' else '+z'} ({why})": 2}
        assert all(rec["up"] == ("+y" if up == "auto" else "+z") for rec in _manifest(out))
        ds = OccludedDataset(out)
        pts = np.concatenate([ds[i][0] for i in range(len(ds))])
        heights[up] = np.ptp(pts, axis=0)
    assert heights["auto"][2] > 2 * heights["auto"][0]  # tall along z: +y turned up
    assert heights["+z"][1] > 2 * heights["+z"][2]  # told +z: as stored, tall along y


def test_up_reaches_the_params_and_is_checked():
    assert "up" not in FarmParams().to_dict()  # "auto": the digest of earlier data sets
    assert FarmParams(up="+y").to_dict()["up"] == "+y" and FarmParams(up="+y").digest() != FarmParams().digest()
    with pytest.raises(InvalidInputError, match="--up"):
        FarmParams(up="y")
