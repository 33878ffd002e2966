"""Per-point columns: a LiDAR's return fields kept by ``farm --sensor`` and read as features.

A sensor that records several returns per pulse (``max_returns`` above 1) makes data sets whose
shards keep ``return_number`` ... ``scan_angle_deg`` per point, declared by each object's
manifest record; ``OccludedDataset(features=...)`` returns them beside xyz; ``verify`` and the
reader refuse a column of the wrong shape, dtype or range; exports write xyz as before.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from zbuf_occlude.cli.main import main
from zbuf_occlude.dataset.layout import POINT_COLUMNS
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.dataset.verify import verify_dataset
from zbuf_occlude.errors import ArgumentTypeError, DatasetFormatError, InvalidInputError
from zbuf_occlude.farm import FarmParams
from zbuf_occlude.farm.sensor_crops import farm_datasets
from zbuf_occlude.sensors.request import ScanRequest
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.sensors import Lidar
from zbuf_occlude.sensors.crops import RETURN_FIELDS, kept_return_fields
from zbuf_occlude.sensors.kinds import sensor_to_json, with_beam

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
FARM = ["--samples-per-view", "2", "--points", "96", "--classes", "chair,table", "--per-class", "1", "--sensor-distance", "4:8",
        "--sensor-height", "1.6:2.0", "--sensor-size", "2:3", "--sensor-reflectivity", "0.4:0.6", "--no-progress"]  # fmt: skip
#: Datasets of a farm --sensor shard of a one-return sensor (as before the return columns existed).
ONE_RETURN_DATASETS = {"data", "label", "object_index", "pose_index", "sample_index", "elevation_deg", "azimuth_deg", "n_visible",
                       "radius", "distance_m", "sensor_height_m", "object_azimuth_deg", "yaw_deg", "size_m", "ring"}  # fmt: skip


def _returns_lidar() -> Lidar:
    return with_beam(Lidar.preset("vlp16"), footprint_rays=7, divergence_deg=0.5, max_returns=3, range_resolution_m=0.3)


@pytest.fixture(scope="module")
def returns_set(tmp_path_factory) -> Path:
    """A farm --sensor data set of a chair (train) and a table (test), scanned with several returns per pulse."""
    tmp = tmp_path_factory.mktemp("returns")
    sensor = tmp / "vlp16_returns.json"
    sensor.write_text(json.dumps(sensor_to_json(_returns_lidar())))
    # every return the sensor records (a training cloud keeps one a pulse unless asked)
    assert main(["farm", str(SAMPLES), "--out", str(tmp / "ds"), "--sensor", str(sensor), "--sensor-returns", "all", *FARM]) == 0
    return tmp / "ds"


def _records(ds: Path) -> list[dict]:
    return [json.loads(s) for s in (ds / "manifest.jsonl").read_text().splitlines() if s.strip()]


def _write_records(ds: Path, records: list[dict]) -> None:
    (ds / "manifest.jsonl").write_text("".join(json.dumps(r, sort_keys=True) + "\n" for r in records))


def _resign(ds: Path) -> None:
    """Every record's SHA-256 and bytes of its shards as they are now, as a data set's author would."""
    records = _records(ds)
    for rec in records:
        rec["sha256"] = [hashlib.sha256((ds / rel).read_bytes()).hexdigest() for rel in rec["shards"]]
        rec["bytes"] = sum((ds / rel).stat().st_size for rel in rec["shards"])
    _write_records(ds, records)


def _rewrite_shard(shard: Path, **replace) -> None:
    """The shard again, datasets replaced (``None``: left out; a callable ``(f, key, old)``: makes it)."""
    with h5py.File(shard, "r") as f:
        arrays = {k: f[k][()] for k in f}
        attrs = dict(f.attrs)
    shard.unlink()
    with h5py.File(shard, "w") as f:
        for key, value in arrays.items():
            new = replace.get(key, value)
            if callable(new):
                new(f, key, value)
            elif new is not None:
                f[key] = new
        f.attrs.update(attrs)


def _shard(ds: Path) -> Path:
    return ds / _records(ds)[0]["shards"][0]


def _stripped(src: Path, dst: Path) -> Path:
    """``src`` without its per-point columns: the data set a one-return sensor would have made of the same points."""
    shutil.copytree(src, dst)
    records = _records(dst)
    for rec in records:
        _rewrite_shard(dst / rec["shards"][0], **{name: None for name in rec.pop("point_columns")})
    _write_records(dst, records)
    _resign(dst)
    return dst


# -- what is written ---------------------------------------------------------------------------------
def test_only_a_sensor_with_several_returns_keeps_return_fields():
    assert kept_return_fields(_returns_lidar()) == RETURN_FIELDS == tuple(POINT_COLUMNS)
    assert kept_return_fields(Lidar.preset("vlp16")) == ()  # max_returns 1: the data set as before
    assert kept_return_fields(with_beam(Lidar.preset("vlp16"), footprint_rays=7)) == ()


def test_a_one_return_sensor_writes_the_shard_as_before(tmp_path):
    mesh = load_mesh(SAMPLES / "chair" / "train" / "chair_0001.off")
    datasets = farm_datasets(mesh, ScanRequest(Lidar.preset("vlp16")), name="chair", label=0, object_index=0, n_samples=1, n_points=32)
    assert set(datasets) == ONE_RETURN_DATASETS


def test_the_shards_keep_the_return_fields_declared_by_their_records(returns_set):
    for rec in _records(returns_set):
        assert rec["point_columns"] == list(POINT_COLUMNS)
        with h5py.File(returns_set / rec["shards"][0], "r") as f:
            rows = len(f["data"])
            for name, spec in POINT_COLUMNS.items():
                assert f[name].shape == (rows, 96) and f[name].dtype == np.dtype(spec.dtype)
    assert verify_dataset(returns_set).ok


def test_the_columns_are_the_crops_return_fields_point_for_point(returns_set):
    # the farm's crops again, from its own parameters: the stored columns are the scans' fields at the stored points
    card = json.loads((returns_set / "dataset_card.json").read_text())
    params = FarmParams.from_dict(card["params"])
    rec = _records(returns_set)[0]
    expected = farm_datasets(
        load_mesh(SAMPLES / rec["source"], up=params.up),
        params.sensor.request(), name=rec["name"], label=rec["label"], object_index=rec["object_index"],
        n_samples=params.samples_per_view, n_points=params.n_points, seed=params.seed, distributions=params.sensor.distributions,
    )  # fmt: skip
    ds = OccludedDataset(returns_set, features=RETURN_FIELDS)
    rows = [i for i in range(len(ds)) if ds.metadata(i)["name"] == rec["name"]]
    got = np.stack([ds[i][0] for i in rows])
    np.testing.assert_array_equal(got[..., :3], expected["data"])
    for k, name in enumerate(RETURN_FIELDS):
        np.testing.assert_array_equal(got[..., 3 + k], expected[name].astype(np.float32))


def test_each_point_keeps_its_own_returns_fields(returns_set):
    # a spinning LiDAR's scan angle is its beam's elevation: the columns sit at the rows of their points' rings
    elevations = np.asarray(_returns_lidar().elevations_deg, dtype=np.float32)
    for rec in _records(returns_set):
        with h5py.File(returns_set / rec["shards"][0], "r") as f:
            assert len(np.unique(f["ring"][()])) > 3
            np.testing.assert_array_equal(f["scan_angle_deg"][()], elevations[f["ring"][()]])


def test_the_return_fields_hold_their_laws(returns_set):
    data, _ = OccludedDataset(returns_set, features=("return_number", "number_of_returns", "pulse_id", "gps_time")).to_arrays()
    rn, nr, pulse, time = (data[..., 3 + k] for k in range(4))
    assert ((1 <= rn) & (rn <= nr) & (nr <= 3)).all()
    assert (nr > 1).any(), "no pulse with several returns: the fixture no longer tests them"
    for sample in range(len(data)):  # the points of one pulse agree on its number of returns and its time
        for p in np.unique(pulse[sample]):
            at = pulse[sample] == p
            assert len(np.unique(nr[sample][at])) == 1 and len(np.unique(time[sample][at])) == 1


# -- reading -----------------------------------------------------------------------------------------
def test_features_come_after_xyz_in_the_order_asked(returns_set):
    plain = OccludedDataset(returns_set)
    both = OccludedDataset(returns_set, features=("scan_angle_deg", "intensity"))
    assert plain.features == () and both.features == ("scan_angle_deg", "intensity")
    assert both.available_features == tuple(POINT_COLUMNS)
    points, label, meta = both[0]
    assert points.shape == (96, 5) and points.dtype == np.float32
    xyz, _, meta0 = plain[0]
    assert xyz.shape == (96, 3) and meta == meta0
    np.testing.assert_array_equal(points[:, :3], xyz)
    with h5py.File(_shard(returns_set), "r") as f:
        row = int(np.flatnonzero(f["pose_index"][()] == meta["pose_index"])[0])
        np.testing.assert_array_equal(points[:, 3], f["scan_angle_deg"][row])
        np.testing.assert_array_equal(points[:, 4], f["intensity"][row])
    data, labels = both.to_arrays()
    blocks = np.concatenate([block for _, block in both.iter_arrays()])
    assert data.shape == (len(both), 96, 5) and np.array_equal(data, blocks)
    np.testing.assert_array_equal(data[..., :3], plain.to_arrays()[0])


def test_default_reading_is_unchanged_by_the_columns(returns_set, tmp_path):
    stripped = _stripped(returns_set, tmp_path / "xyz")
    a, b = OccludedDataset(returns_set).to_arrays(), OccludedDataset(stripped).to_arrays()
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert OccludedDataset(stripped).available_features == ()


@pytest.mark.parametrize(
    ("features", "error", "message"),
    [
        (("reflectance",), InvalidInputError, r"feature 'reflectance' is not a per-point column of .*; it has \('return_number', "),
        (("intensity", "intensity"), InvalidInputError, "feature 'intensity' is named twice"),
        ("intensity", ArgumentTypeError, "features must be a tuple of column names"),
        ((1,), ArgumentTypeError, "features must be a tuple of column names"),
    ],
)
def test_a_feature_that_is_not_one_is_refused_naming_it(returns_set, features, error, message):
    with pytest.raises(error, match=message):
        OccludedDataset(returns_set, features=features)


def test_a_feature_the_data_set_lacks_is_refused_naming_what_it_has(returns_set, tmp_path):
    stripped = _stripped(returns_set, tmp_path / "xyz")
    with pytest.raises(InvalidInputError, match=r"feature 'intensity' is not kept by every selected object of .*it has none"):
        OccludedDataset(stripped, features=("intensity",))
    # one object without them: the data set lacks them, the other objects alone have them
    records = _records(returns_set)
    assert len(records) == 2
    mixed = tmp_path / "mixed"
    shutil.copytree(returns_set, mixed)
    records[0].pop("point_columns")
    _write_records(mixed, records)
    with pytest.raises(InvalidInputError, match="'gps_time' is not kept by every selected object"):
        OccludedDataset(mixed, features=("gps_time",))
    assert OccludedDataset(mixed, classes=records[1]["class_name"], features=("gps_time",)).features == ("gps_time",)


# -- hostile data sets -------------------------------------------------------------------------------
def _corrupt(src: Path, dst: Path, **replace) -> tuple[Path, Path]:
    shutil.copytree(src, dst)
    shard = _shard(dst)
    _rewrite_shard(shard, **replace)
    _resign(dst)
    return dst, shard


def _huge(f, key, old):
    f.create_dataset(key, shape=(old.shape[0], 1 << 40), dtype=old.dtype)  # declared, never written


def _set(value, at=(0, 0)):
    def make(f, key, old):
        new = old.copy()
        new[at] = value
        f[key] = new

    return make


CORRUPTIONS = {
    "short": ({"intensity": lambda f, k, old: f.create_dataset(k, data=old[:, :-1])}, "per-point column 'intensity' is"),
    "longer": ({"gps_time": lambda f, k, old: f.create_dataset(k, data=np.concatenate([old, old]))}, "per-point column 'gps_time' is"),
    "dtype": ({"intensity": lambda f, k, old: f.create_dataset(k, data=old.astype(np.float64))}, "float64, its record declares it"),
    "kind": ({"return_number": lambda f, k, old: f.create_dataset(k, data=old.astype(np.float32))}, "holds float values"),
    "missing": ({"pulse_id": None}, "per-point column 'pulse_id' is missing"),
    "huge": ({"scan_angle_deg": _huge}, "declares shape"),
    "return_number 0": ({"return_number": _set(0)}, r"'return_number' holds a value out of range at row 0, point 0 .* in \[1, 15\]"),
    "return_number 16": (
        {"return_number": _set(16), "number_of_returns": _set(16)},
        r"'return_number' holds a value out of range .* in \[1, 15\]",
    ),
    "return past the pulse's": ({"return_number": _set(3), "number_of_returns": _set(2)}, "at most the point's 'number_of_returns'"),
    "intensity nan": ({"intensity": _set(np.nan)}, "'intensity' holds a value that is not finite"),
    "intensity negative": ({"intensity": _set(-1.0)}, "'intensity' holds a value out of range"),
    "scan angle": ({"scan_angle_deg": _set(200.0, (0, 5))}, r"'scan_angle_deg' holds a value out of range at row 0, point 5"),
    "gps_time inf": ({"gps_time": _set(np.inf)}, "'gps_time' holds a value that is not finite"),
    "pulse_id negative": ({"pulse_id": _set(-1)}, "'pulse_id' holds a value out of range"),
}


@pytest.mark.parametrize("case", list(CORRUPTIONS))
def test_verify_and_the_reader_refuse_a_damaged_column_in_one_line_naming_the_file(returns_set, tmp_path, capsys, case):
    replace, message = CORRUPTIONS[case]
    ds, shard = _corrupt(returns_set, tmp_path / "ds", **replace)
    problems = verify_dataset(ds).problems
    assert len(problems) == 1 and str(shard) in problems[0] and re.search(message, problems[0]), problems
    assert main(["verify", str(ds)]) == 1
    err = capsys.readouterr().err
    found = [line for line in err.splitlines() if line.startswith("PROBLEM")]
    assert len(found) == 1 and str(shard) in found[0] and "Traceback" not in err, err
    with pytest.raises(DatasetFormatError, match=re.escape(str(shard)) + ".*" + message):
        OccludedDataset(ds, features=RETURN_FIELDS).to_arrays()


def test_a_record_naming_an_unknown_column_is_refused(returns_set, tmp_path):
    ds = tmp_path / "ds"
    shutil.copytree(returns_set, ds)
    records = _records(ds)
    records[0]["point_columns"] = ["return_number", "colour"]
    _write_records(ds, records)
    with pytest.raises(
        DatasetFormatError, match=r"manifest.jsonl:1 .*field 'point_columns'.*1 per-point column\(s\) this zbuf_occlude does not read"
    ):
        OccludedDataset(ds)
    assert any("1 per-point column(s) this zbuf_occlude does not read" in p for p in verify_dataset(ds).problems)


# -- export ------------------------------------------------------------------------------------------
def _tree_hashes(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and not p.name.startswith(".")}  # fmt: skip


@pytest.mark.parametrize("target", ["pointnet-h5", "modelnet-txt"])
def test_an_export_writes_the_same_xyz_with_or_without_the_columns(returns_set, tmp_path, target):
    stripped = _stripped(returns_set, tmp_path / "xyz")
    # the same --out name: pointnet-h5's file lists name it
    assert main(["export", str(returns_set), "--to", target, "--out", str(tmp_path / "with" / "export")]) == 0
    assert main(["export", str(stripped), "--to", target, "--out", str(tmp_path / "without" / "export")]) == 0
    with_columns, without = _tree_hashes(tmp_path / "with" / "export"), _tree_hashes(tmp_path / "without" / "export")
    assert with_columns and with_columns == without


#: In a child under an address-space limit (tests/memory_limit.py): read argv[1] with the return
#: number alone; print the refusal and exit 3.
_READ_RETURN_NUMBER = """
import sys
from zbuf_occlude import OccludedDataset
from zbuf_occlude.errors import ZbufOccludeError
try:
    OccludedDataset(sys.argv[1], features=("return_number",)).to_arrays()
except ZbufOccludeError as exc:
    print(exc)
    sys.exit(3)
"""


def test_a_return_past_its_pulses_is_refused_when_the_return_number_is_read_alone(returns_set, tmp_path):
    """verify refused it, and the reader did when both columns were asked for; asked alone, the
    return number was served: the bound holds whenever the record declares number_of_returns."""
    from memory_limit import run_python_limited

    ds, shard = _corrupt(returns_set, tmp_path / "ds", return_number=_set(3, (1, 7)), number_of_returns=_set(2, (1, 7)))
    said = (
        re.escape(str(shard))
        + r": dataset 'return_number' holds a value out of range at row 1, point 7 .*at most the point's 'number_of_returns'"
    )
    assert re.search(said, verify_dataset(ds).problems[0])
    with pytest.raises(DatasetFormatError, match=said) as caught:
        OccludedDataset(ds, features=("return_number",)).to_arrays()
    assert "\n" not in str(caught.value)
    rows = OccludedDataset(ds, features=("return_number",))
    with pytest.raises(DatasetFormatError, match=said):
        rows[1]  # one sample read on its own: the shard's row in the message
    rows[0]  # the rows without a fault read as before
    done = run_python_limited(_READ_RETURN_NUMBER, args=[ds])
    assert done.returncode == 3 and not done.stderr and re.search(said, done.stdout), done.stdout + done.stderr[-2000:]
    assert len(done.stdout.splitlines()) == 1
