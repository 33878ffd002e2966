"""``farm --sensor``: LiDAR crops of whole data sets, end to end through the command line.

Runs on the shipped meshes (``data/samples``) with two scans of few points per object.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

import zbuf_occlude as zo
from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.dataset.layout import CARD_FILE
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.farm import FarmParams, SensorCropParams
from zbuf_occlude.farm.sensor_crops import farm_datasets
from zbuf_occlude.sensors.request import ScanRequest
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.sensors import Lidar
from zbuf_occlude.sensors.placement import CropDistributions
from zbuf_occlude.sensors.fit import fit_width_scale
from zbuf_occlude.sensors.kinds import kind_of, sensor_to_json, with_beam

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
ARGS = ["--sensor", "hdl32e", "--samples-per-view", "2", "--points", "128", "--per-class", "1", "--splits", "train",
        "--sensor-distance", "5:20", "--sensor-height", "1.6:2.0", "--sensor-size", "2:4.5", "--no-progress"]  # fmt: skip


def _farm(out: Path, *extra: str) -> Path:
    assert cli_main(["farm", str(SAMPLES), "--out", str(out), *ARGS, *extra]) == 0
    return out


def _shard_hashes(out: Path) -> dict[str, str]:
    return {p.relative_to(out).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(out.rglob("*.h5"))}


@pytest.fixture(scope="module")
def sensor_run(tmp_path_factory) -> Path:
    return _farm(tmp_path_factory.mktemp("farm_sensor") / "ds")


def _sensor_position(meta: dict) -> np.ndarray:
    """The sensor in the sample's normalised mesh frame, from the recorded direction and radius."""
    el, az = np.radians(meta["elevation_deg"]), np.radians(meta["azimuth_deg"])
    centre = load_mesh(SAMPLES / meta["source"]).bounds.mean(axis=0)
    return centre + meta["radius"] * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


@pytest.mark.slow
def test_points_lie_on_the_hdl32e_rings_seen_from_the_recorded_sensor(sensor_run):
    ds = OccludedDataset(sensor_run)
    table = np.asarray(Lidar.preset("hdl32e").elevations_deg)
    card = json.loads((sensor_run / CARD_FILE).read_text())
    assert card["params"]["sensor"] == "hdl32e" and card["params"]["sensor_distance_m"] == [5.0, 20.0]
    assert len(ds) >= 8 and ds.sensor == "hdl32e"
    rings_seen = set()
    for i in range(len(ds)):
        points, label, meta = ds[i]
        assert points.shape == (128, 3) and label == ds.labels[i]
        assert 5.0 <= meta["distance_m"] <= 20.0 and 1.6 <= meta["sensor_height_m"] <= 2.0 and 2.0 <= meta["size_m"] <= 4.5
        # mesh frame = world frame rotated about z and scaled uniformly: elevation angles are kept
        d = points.astype(np.float64) - _sensor_position(meta)
        elevation = np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))
        nearest = np.abs(elevation[:, None] - table[None]).min(axis=1)
        assert nearest.max() < 2e-3, (meta["name"], nearest.max())
        rings_seen |= set(np.abs(elevation[:, None] - table[None]).argmin(axis=1).tolist())
        # the sensor stands sensor_height_m above the ground (the mesh's lowest point), in mesh units
        metres_per_unit = meta["size_m"] / np.ptp(load_mesh(SAMPLES / meta["source"]).bounds, axis=0).max()
        ground = load_mesh(SAMPLES / meta["source"]).bounds[0, 2]
        assert abs((_sensor_position(meta)[2] - ground) * metres_per_unit - meta["sensor_height_m"]) < 1e-6
    assert len(rings_seen) >= 5  # not one ring repeated


def test_a_direction_filter_matching_no_scan_is_an_error_not_an_empty_data_set(sensor_run):
    from zbuf_occlude.errors import InvalidInputError

    low = OccludedDataset(sensor_run, elevation_deg=lambda el: el < 30)  # scans from a car roof: a few degrees up
    assert 0 < len(low) <= len(OccludedDataset(sensor_run))
    with pytest.raises(InvalidInputError, match=r"no sample of .* matches elevation_deg=60.* sensor elevations span -?\d"):
        OccludedDataset(sensor_run, elevation_deg=60.0)
    with pytest.raises(InvalidInputError, match=r"matches .*azimuth_deg=<function"):
        OccludedDataset(sensor_run, azimuth_deg=lambda az: az > 1000)


@pytest.mark.slow
def test_return_physics_options_reach_the_scans(sensor_run, tmp_path):
    out = _farm(tmp_path / "phys", "--sensor-footprint", "--sensor-reflectivity", "0.05:0.1", "--sensor-distance", "15:20")
    card = json.loads((out / CARD_FILE).read_text())
    assert card["params"]["sensor_footprint"] is True and card["params"]["sensor_reflectivity"] == [0.05, 0.1]
    table = np.asarray(Lidar.preset("hdl32e").elevations_deg)
    phys = OccludedDataset(out)
    for i in range(len(phys)):  # footprint returns still lie along their beams' centre directions
        points, _, meta = phys[i]
        d = points.astype(np.float64) - _sensor_position(meta)
        elevation = np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))
        assert np.abs(elevation[:, None] - table[None]).min(axis=1).max() < 2e-3
    # dark objects far away lose returns to the detection threshold: fewer than the same scans without it
    plain = OccludedDataset(_farm(tmp_path / "plain", "--sensor-footprint", "--sensor-distance", "15:20"))
    n_phys = sum(phys.metadata(i)["n_visible"] for i in range(len(phys)))
    n_plain = sum(plain.metadata(i)["n_visible"] for i in range(len(plain)))
    assert 0 < n_phys < n_plain


@pytest.mark.slow
def test_ground_margin_keeps_the_ground_under_each_object(tmp_path):
    out = _farm(tmp_path / "ground", "--sensor-ground-margin", "0.5", "--points", "2048")
    card = json.loads((out / CARD_FILE).read_text())
    assert card["params"]["sensor_ground_margin_m"] == 0.5
    ds = OccludedDataset(out)
    outside = 0
    for i in range(len(ds)):
        points, _, meta = ds[i]
        mesh = load_mesh(SAMPLES / meta["source"])
        per_m = np.ptp(mesh.bounds, axis=0).max() / meta["size_m"]  # mesh units per metre
        lo, hi = mesh.bounds[:, :2]
        beyond = np.maximum(lo - points[:, :2], points[:, :2] - hi).max(axis=1)  # > 0: outside the mesh's outline
        out_of_mesh = beyond > 0.1 * per_m  # 5 σ of the 2 cm range noise
        # those are ground returns (range noise: 2 cm), none further than the 0.5 m margin
        assert np.all(np.abs(points[out_of_mesh, 2] - mesh.bounds[0, 2]) < 0.1 * per_m)
        assert np.all(beyond <= 0.5 * per_m + 1e-4)
        outside += int(out_of_mesh.sum())
    assert outside > 0
    assert "sensor_ground_margin_m" not in FarmParams(sensor="hdl32e").to_dict()  # earlier sensor data sets keep their digest


@pytest.mark.slow
def test_hidden_below_hides_each_objects_bottom(tmp_path):
    out = _farm(tmp_path / "hidden", "--sensor-hidden-below", "0.6:0.8", "--points", "2048")
    card = json.loads((out / CARD_FILE).read_text())
    assert card["params"]["sensor_hidden_below_m"] == [0.6, 0.8]
    ds = OccludedDataset(out)
    for i in range(len(ds)):
        points, _, meta = ds[i]
        mesh = load_mesh(SAMPLES / meta["source"])
        per_m = np.ptp(mesh.bounds, axis=0).max() / meta["size_m"]  # mesh units per metre
        assert 0.6 <= meta["hidden_below_m"] <= 0.8
        # every return lies at least the drawn height above the object's foot (range noise: 2 cm)
        assert points[:, 2].min() >= mesh.bounds[0, 2] + (meta["hidden_below_m"] - 0.1) * per_m
    assert "sensor_hidden_below_m" not in FarmParams(sensor="hdl32e").to_dict()  # earlier sensor data sets keep their digest
    assert cli_main(["verify", str(out)]) == 0


@pytest.mark.slow
def test_across_sight_width_stretches_each_object_to_the_asked_widths(tmp_path):
    out = _farm(tmp_path / "wide", "--sensor-across-sight-width", "0.6:0.9", "--samples-per-view", "3")
    card = json.loads((out / CARD_FILE).read_text())
    assert card["params"]["sensor_across_sight_width_m"] == [0.6, 0.9]
    # each scan's stretch is drawn from its own mesh's interval: the sensor package's fit for that mesh and seed
    crops = CropDistributions(distance_m=(5.0, 20.0), size_m=(2.0, 4.5))
    params = FarmParams(sensor=SensorCropParams("hdl32e", crops, across_sight_width_m=(0.6, 0.9)))
    ds, fitted = OccludedDataset(out), {}
    for i in range(len(ds)):
        meta = ds.metadata(i)
        if meta["source"] not in fitted:
            fitted[meta["source"]] = fit_width_scale(load_mesh(SAMPLES / meta["source"]), params.sensor.model(), crops, (0.6, 0.9))
        lo, hi = fitted[meta["source"]]
        assert lo <= meta["width_scale"] <= hi and hi == pytest.approx(1.5 * lo)
    assert len({round(lo, 6) for lo, _ in fitted.values()}) == len(fitted) > 1  # one interval per mesh
    assert "sensor_across_sight_width_m" not in FarmParams(sensor="hdl32e").to_dict()  # earlier sensor data sets keep their digest
    assert params.digest() != FarmParams(sensor=SensorCropParams("hdl32e", crops)).digest()
    assert cli_main(["verify", str(out)]) == 0


@pytest.mark.slow
def test_a_sensor_file_with_mixed_pixels_changes_the_scans(sensor_run, tmp_path):
    # a 7-ray footprint whose echoes within 0.75 m merge, against the same footprint without merging
    paths = {}
    for name, separation in (("sharp", 0.0), ("mixed", 0.75)):
        spec = sensor_to_json(
            with_beam(Lidar.preset("hdl32e").with_(name=f"hdl32e-{name}"), footprint_rays=7, echo_separation_m=separation)
        )
        paths[name] = tmp_path / f"{name}.json"
        paths[name].write_text(json.dumps(spec))
    runs = {}
    for name, path in paths.items():
        args = [str(path) if a == "hdl32e" else a for a in ARGS]
        assert cli_main(["farm", str(SAMPLES), "--out", str(tmp_path / name), *args]) == 0
        runs[name] = OccludedDataset(tmp_path / name)
    assert len(runs["sharp"]) == len(runs["mixed"])
    differ = sum(not np.array_equal(runs["sharp"][i][0], runs["mixed"][i][0]) for i in range(len(runs["sharp"])))
    assert differ >= 1


@pytest.mark.slow
def test_same_seed_same_bytes_and_worker_count_changes_nothing(sensor_run, tmp_path):
    again = _farm(tmp_path / "again", "--workers", "1")
    two = _farm(tmp_path / "two", "--workers", "2")
    assert _shard_hashes(again) == _shard_hashes(sensor_run) == _shard_hashes(two)
    assert len(_shard_hashes(sensor_run)) == 5
    other = _farm(tmp_path / "seed1", "--seed", "1")
    assert set(_shard_hashes(other).values()).isdisjoint(_shard_hashes(sensor_run).values())


@pytest.mark.slow
def test_resume_redoes_only_what_is_missing(sensor_run, tmp_path):
    out = _farm(tmp_path / "ds")
    shards = sorted(out.rglob("*.h5"))
    before = {p: p.stat().st_mtime_ns for p in shards}
    shards[2].unlink()  # killed after the record... or before it:
    (out / "records" / "000003.json").unlink()
    assert cli_main(["farm", str(SAMPLES), "--out", str(out), *ARGS]) == 0
    assert _shard_hashes(out) == _shard_hashes(sensor_run)
    redone = sorted(p for p in out.rglob("*.h5") if p.stat().st_mtime_ns != before.get(p))
    assert redone == [shards[2], shards[3]], redone
    assert len(OccludedDataset(out)) == len(OccludedDataset(sensor_run))


def test_zbuffer_farm_parameters_keep_their_digest():
    # data sets made before --sensor existed keep their digest: no sensor key in to_dict
    # (method named: those data sets were made when the default was "zbuffer")
    assert FarmParams(method="zbuffer").digest() == "caf646a92272b6ce"
    assert FarmParams(storage="compact", seed=3, method="zbuffer").digest() == "f3f5104aab0cd7df"
    assert "sensor" not in FarmParams().to_dict()
    assert FarmParams(sensor="hdl32e").digest() != FarmParams(sensor="vlp16").digest()
    assert (
        FarmParams(sensor="hdl32e").digest() != FarmParams(sensor=SensorCropParams("hdl32e", CropDistributions(size_m=(1.0, 2.0)))).digest()
    )


@pytest.mark.parametrize(
    "bad, words",
    [
        (["--sensor", "hdl99"], "hdl99"),
        (["--sensor", "hdl32e", "--storage", "compact"], "--storage"),
        (["--sensor-distance", "5:10"], "--sensor-distance needs --sensor"),
        (["--sensor", "hdl32e", "--sensor-distance", "10:5"], "--sensor-distance"),
        (["--sensor", "hdl32e", "--sensor-size", "0:2"], "--sensor-size"),
        (["--sensor-footprint"], "--sensor-footprint needs --sensor"),
        (["--sensor", "hdl32e", "--sensor-reflectivity", "0.5:0.1"], "--sensor-reflectivity"),
        (["--sensor", "kinect-v1", "--sensor-footprint"], "kinect-v1"),
        (["--sensor", "hdl64e", "--sensor-footprint"], "has no divergence (divergence_deg 0): give --sensor-divergence DEG"),
        (["--sensor", "hdl64e", "--sensor-divergence", "0"], "--sensor-divergence must be a number > 0 degrees, got 0"),
        (["--sensor", "hdl32e", "--sensor-divergence", "91"], "--sensor-divergence must be a full angle of at most 90 degrees, got 91"),
        (["--sensor", "kinect-v1", "--sensor-divergence", "0.2"], "--sensor-divergence: kinect-v1 is a depth camera, which has no beam"),
        (["--sensor", "riegl-q1560", "--sensor-reflectivity", "0.2"], "--sensor-reflectivity: riegl-q1560 is an airborne scanner"),
        (["--sensor-ground-margin", "1"], "--sensor-ground-margin needs --sensor"),
        (["--sensor", "hdl32e", "--sensor-ground-margin", "-1"], "--sensor-ground-margin must be a number >= 0 metres, got -1"),
        (["--sensor-hidden-below", "0.5"], "--sensor-hidden-below needs --sensor"),
        (
            ["--sensor", "hdl32e", "--sensor-hidden-below=-0.5:1"],
            "--sensor-hidden-below must be >= 0 metres above the ground, got (-0.5, 1.0)",
        ),
        (["--sensor-across-sight-width", "0.5"], "--sensor-across-sight-width needs --sensor"),
        (["--sensor", "hdl32e", "--sensor-across-sight-width", "0:0"], "--sensor-across-sight-width must have HI > 0 metres"),
        (["--sensor", "riegl-q1560", "--sensor-across-sight-width", "0.5"], "spinning LiDAR"),
        (["--sensor", "kinect-v1"], "--sensor: kinect-v1 is a depth camera, which has no beam; the farm scans with a pulsed sensor"),
        (["--sensor", "hdl32e", "--sensor-footprint-cast", "adaptive"], "--sensor-footprint-cast adaptive skips the sub-rays"),
    ],
)
def test_bad_sensor_options_are_clear_errors(tmp_path, bad, words, capsys):
    status = cli_main(["farm", str(SAMPLES), "--out", str(tmp_path / "bad"), "--no-progress", *bad])
    assert status == 2
    assert words in capsys.readouterr().err
    assert not list((tmp_path / "bad").rglob("*.h5"))


def test_sensor_params_are_checked():
    with pytest.raises(InvalidInputError, match="--sensor-height must be >= 0 metres, got"):
        FarmParams.from_dict({**FarmParams(sensor="hdl32e").to_dict(), "sensor_height_m": [-1.0, 2.0]})
    with pytest.raises(InvalidInputError, match="farm --sensor draws no width_scale"):  # the card could not record it
        SensorCropParams("hdl32e", CropDistributions(width_scale=(1.0, 2.0)))
    with pytest.raises(InvalidInputError, match="kinect-v1 is a depth camera, which has no beam"):
        SensorCropParams("kinect-v1", CropDistributions(reflectivity=(0.1, 0.2)))
    with pytest.raises(InvalidInputError, match="--sensor writes dense storage only"):
        FarmParams(sensor="hdl32e", storage="compact")


#: ``params`` of the plan of a ``farm --sensor`` run with every crop option set, as the farm wrote
#: it when FarmParams held the settings as flat ``sensor_*`` fields, and that plan's ``params_digest``.
EARLIER_SENSOR_PLAN_PARAMS = {
    "dense_points": 32768, "density": None, "method": "auto", "n_points": 128, "radius": 4.0, "resolution": 512,
    "samples_per_view": 3, "seed": 7, "sensor": "hdl32e", "sensor_across_sight_width_m": [1.0, 2.0],
    "sensor_distance_m": [6.0, 18.0], "sensor_footprint": True, "sensor_ground_margin_m": 0.3, "sensor_height_m": [1.5, 2.1],
    "sensor_hidden_below_m": [0.1, 0.5], "sensor_reflectivity": [0.2, 0.8], "sensor_size_m": [2.0, 4.0], "storage": "dense",
    "views": "paper100",
}  # fmt: skip
EARLIER_SENSOR_PLAN_DIGEST = "846529b76e7de8d5"


def test_a_plan_written_with_flat_sensor_keys_reads_back_as_the_same_parameters():
    params = FarmParams.from_dict(EARLIER_SENSOR_PLAN_PARAMS)
    crops = params.sensor.distributions
    assert params.sensor.name == "hdl32e" and params.sensor.footprint is True and params.sensor.across_sight_width_m == (1.0, 2.0)
    assert (crops.distance_m, crops.height_m, crops.size_m) == ((6.0, 18.0), (1.5, 2.1), (2.0, 4.0))
    assert (crops.reflectivity, crops.ground_margin_m, crops.hidden_below_m) == ((0.2, 0.8), 0.3, (0.1, 0.5))
    assert params.to_dict() == EARLIER_SENSOR_PLAN_PARAMS and params.digest() == EARLIER_SENSOR_PLAN_DIGEST
    assert json.dumps(params.to_dict(), sort_keys=True) == json.dumps(EARLIER_SENSOR_PLAN_PARAMS, sort_keys=True)


@pytest.mark.parametrize(
    "params",
    [
        FarmParams(views="grid25", samples_per_view=2, n_points=64, storage="compact", seed=3),
        FarmParams(up="+y", density=50.0),
        FarmParams(sensor="vlp16"),
        FarmParams(
            samples_per_view=4,
            n_points=256,
            seed=9,
            sensor=SensorCropParams(
                "hdl32e",
                CropDistributions(
                    distance_m=(6.0, 18.0),
                    height_m=2.0,
                    size_m=(2.0, 4.0),
                    reflectivity=(0.2, 0.8),
                    ground_margin_m=0.3,
                    hidden_below_m=(0.1, 0.5),
                ),
                footprint=True,
                across_sight_width_m=(1.0, 2.0),
                divergence_deg=0.3,
            ),
        ),
    ],
    ids=["compact", "density", "sensor-defaults", "sensor-every-setting"],
)
def test_farm_params_read_back_from_their_dict(params):
    again = FarmParams.from_dict(json.loads(json.dumps(params.to_dict())))  # as a plan or card holds them
    assert again == params and again.digest() == params.digest()


def test_sensor_keys_without_a_sensor_are_refused():
    with pytest.raises(TypeError, match="sensor_distance_m given without a sensor"):
        FarmParams.from_dict({"views": "0:0", "sensor_distance_m": [1.0, 2.0]})


@pytest.mark.slow
def test_the_padding_warning_of_a_sensor_farm_names_what_applies(tmp_path, caplog):
    # 4,000 points per sample: more than a 5-20 m HDL-32E scan of a 2-4.5 m object returns
    args = [a if a != "128" else "4000" for a in ARGS]
    with caplog.at_level("WARNING", logger="zbuf_occlude"):
        assert cli_main(["farm", str(SAMPLES), "--out", str(tmp_path / "ds"), *args]) == 0
    warning = " ".join(r.getMessage() for r in caplog.records if "repeated points" in r.getMessage())
    assert "move the sensor closer or lower --points" in warning and "--dense-points" not in warning


def test_farm_datasets_are_reproducible_per_sample():
    kw = dict(name="bed", label=3, object_index=7, n_points=256, seed=11, distributions=CropDistributions(distance_m=(5, 15)))
    a = farm_datasets(str(SAMPLES / "bed" / "train" / "bed_0001.off"), ScanRequest(zo.Lidar.preset("vlp16")), n_samples=3, **kw)
    b = farm_datasets(str(SAMPLES / "bed" / "train" / "bed_0001.off"), ScanRequest(zo.Lidar.preset("vlp16")), n_samples=2, **kw)
    assert a["data"].shape == (3, 256, 3) and np.all(a["label"] == 3) and np.all(a["object_index"] == 7)
    # sample k depends on (seed, name, k) only
    for key in ("data", "distance_m", "n_visible", "ring"):
        assert np.array_equal(a[key][:2], b[key]), key
    assert len(set(a["distance_m"].tolist())) == 3
    assert np.all((a["ring"] >= 0) & (a["ring"] < 16))


@pytest.mark.parametrize("name", ["hdl32e", "livox-mid70", "riegl-q1560"])
def test_the_footprint_widens_the_beam_of_every_pulsed_preset(name):
    # the farm's --sensor-footprint goes through with_beam, as scan's --footprint: any pattern, the beam's own divergence
    base = SensorCropParams(name).model()
    wide = SensorCropParams(name, footprint=True).model()
    # a one-ray beam gets 7 sub-rays; a beam of its own wider footprint (an airborne preset's 19) keeps it
    assert kind_of(wide) is kind_of(base) and wide.beam == base.beam.with_(footprint_rays=max(7, base.beam.footprint_rays))
    assert sensor_to_json(wide.with_(beam=base.beam)) == sensor_to_json(base)  # nothing but the beam changed


def test_a_divergence_gives_a_preset_without_one_its_footprint():
    with pytest.raises(
        InvalidInputError, match=r"--sensor-footprint samples the beam's divergence cone, and hdl64e's beam .* give --sensor-divergence"
    ):
        SensorCropParams("hdl64e", footprint=True)
    sensor = SensorCropParams("hdl64e", footprint=True, divergence_deg=0.2).model()
    assert sensor.beam.divergence_deg == 0.2 and sensor.beam.footprint_rays == 7
    assert SensorCropParams("hdl32e", footprint=True, divergence_deg=0.5).model().beam.divergence_deg == 0.5
    with pytest.raises(InvalidInputError, match=r"--sensor-divergence 0.5 widens a footprint's cone, .* give --sensor-footprint too"):
        SensorCropParams("hdl32e", divergence_deg=0.5).model()  # a one-ray beam: the divergence alone would change nothing
    with pytest.raises(InvalidInputError, match="--sensor-divergence must be"):
        SensorCropParams("hdl32e", divergence_deg=float("nan"))


def test_the_divergence_is_recorded_only_when_given():
    # earlier sensor data sets keep their digest; a divergence is a new data set
    assert "sensor_divergence_deg" not in FarmParams(sensor="hdl32e").to_dict()
    given = FarmParams(sensor=SensorCropParams("hdl32e", footprint=True, divergence_deg=0.3))
    assert given.to_dict()["sensor_divergence_deg"] == 0.3 and given.digest() != FarmParams(sensor="hdl32e").digest()


def _echo_sensor(tmp_path: Path) -> Path:
    """An HDL-32E whose receiver resolves two echoes a pulse (the preset records one return): a sensor file."""
    path = tmp_path / "hdl32e_two_returns.json"
    path.write_text(json.dumps({"kind": "lidar", "preset": "hdl32e", "name": "hdl32e-2r",
                                "beam": {"max_returns": 2, "range_resolution_m": 0.5}}))  # fmt: skip
    return path


def test_the_adaptive_footprint_needs_a_footprint_whose_echoes_are_resolved(tmp_path: Path):
    with pytest.raises(InvalidInputError, match=r"--sensor-footprint-cast adaptive skips the sub-rays .* hdl32e fires one ray"):
        SensorCropParams("hdl32e", footprint=True, footprint_cast="adaptive")  # the preset resolves no echoes
    with pytest.raises(InvalidInputError, match=r"--sensor-footprint-cast adaptive skips the sub-rays"):
        SensorCropParams(str(_echo_sensor(tmp_path)), footprint_cast="adaptive")  # one ray a pulse
    with pytest.raises(InvalidInputError, match=r"--sensor, --sensor-footprint-cast: kinect-v1 is a .*, which has no beam"):
        SensorCropParams("kinect-v1", footprint_cast="adaptive")  # no pulses
    params = SensorCropParams(str(_echo_sensor(tmp_path)), footprint=True, footprint_cast="adaptive", returns="all")
    assert params.footprint_mode == "adaptive" and SensorCropParams("hdl32e").footprint_mode == "exact"
    for value in ("yes", 1, None, True):  # one of the three names
        with pytest.raises(InvalidInputError, match="--sensor-footprint-cast must be one of auto, exact, adaptive"):
            SensorCropParams(str(_echo_sensor(tmp_path)), footprint=True, footprint_cast=value, returns="all")


def test_the_default_cast_is_adaptive_where_the_sensor_resolves_a_footprints_echoes(tmp_path: Path):
    sensor = str(_echo_sensor(tmp_path))
    assert SensorCropParams(sensor, footprint=True, returns="all").footprint_mode == "adaptive"  # 7 sub-rays, two echoes resolved
    assert SensorCropParams("riegl-q1560", returns="all").footprint_mode == "adaptive"  # an airborne preset's 19 sub-rays
    assert SensorCropParams("riegl-q1560").footprint_mode == "exact"  # one return a pulse, the strongest: no echoes resolved
    assert SensorCropParams(sensor, returns="all").footprint_mode == "exact"  # one ray: nothing to skip
    assert SensorCropParams("hdl32e", footprint=True).footprint_mode == "exact"  # 7 sub-rays, one return: no echoes resolved
    assert SensorCropParams(sensor, footprint=True, footprint_cast="exact", returns="all").footprint_mode == "exact"


def test_a_depth_camera_is_no_farm_sensor():
    with pytest.raises(InvalidInputError, match="--sensor: kinect-v1 is a depth camera, which has no beam; the farm scans with a pulsed"):
        SensorCropParams("kinect-v1")


def test_the_card_records_the_adaptive_cast_only_where_it_was_used(tmp_path: Path):
    sensor = str(_echo_sensor(tmp_path))
    exact = FarmParams(sensor=SensorCropParams(sensor, footprint=True, footprint_cast="exact", returns="all"))
    adaptive = FarmParams(sensor=SensorCropParams(sensor, footprint=True, footprint_cast="adaptive", returns="all"))
    default = FarmParams(sensor=SensorCropParams(sensor, footprint=True, returns="all"))
    assert "sensor_adaptive_footprint" not in exact.to_dict()  # earlier data sets, cast exact, keep their digest
    assert adaptive.to_dict()["sensor_adaptive_footprint"] is True and adaptive.digest() != exact.digest()
    assert default.digest() == adaptive.digest() and default == adaptive  # one cast, one value
    assert "sensor_adaptive_footprint" not in FarmParams(sensor=SensorCropParams("hdl32e")).to_dict()  # one ray: exact
    for params in (exact, adaptive):
        assert SensorCropParams.from_dict(params.sensor.to_dict()) == params.sensor
    with pytest.raises(InvalidInputError, match=r"sensor_adaptive_footprint \(--sensor-footprint-cast\) must be true or false, got str"):
        SensorCropParams.from_dict({**adaptive.sensor.to_dict(), "sensor_adaptive_footprint": "yes"})


def test_farm_crops_with_the_adaptive_footprint_are_farm_datasets_adaptive_ones(tmp_path: Path):
    import h5py

    sensor = str(_echo_sensor(tmp_path))
    out = _farm(
        tmp_path / "ds", "--sensor", sensor, "--sensor-footprint", "--classes", "chair", "--sensor-returns", "all"
    )  # adaptive by default
    card = json.loads((out / CARD_FILE).read_text())
    assert card["params"]["sensor_adaptive_footprint"] is True
    (shard,) = sorted(out.rglob("*.h5"))
    with h5py.File(shard, "r") as h:
        written = {key: h[key][()] for key in ("data", "n_visible", "pose_index", "return_number")}
        name = h.attrs["name"]
    params = SensorCropParams.from_dict(card["params"] | {"sensor": sensor})
    mesh = load_mesh(SAMPLES / f"{name}.off")
    kw = {"name": name, "label": 0, "object_index": 0, "n_samples": 2, "n_points": 128, "seed": 0, "distributions": params.distributions}
    adaptive = farm_datasets(mesh, ScanRequest(params.model(), footprint_cast="adaptive"), **kw)
    for key, values in written.items():
        assert np.array_equal(values, adaptive[key]), key
    exact = farm_datasets(mesh, ScanRequest(params.model(), footprint_cast="exact"), **kw)
    assert not all(np.array_equal(exact[key], adaptive[key]) for key in written)  # the adaptive cast changes some returns here


def test_the_footprint_cast_without_a_sensor_is_a_usage_error(tmp_path: Path, capsys):
    assert cli_main(["farm", str(SAMPLES), "--out", str(tmp_path / "ds"), "--sensor-footprint-cast", "exact", "--no-progress"]) == 2
    assert "--sensor-footprint-cast needs --sensor" in capsys.readouterr().err
    assert not (tmp_path / "ds").exists()


def test_each_sample_without_returns_is_named(caplog) -> None:
    """An object beyond the sensor's range has no return: the farm leaves its samples out and names each of them."""
    import logging

    import trimesh

    from zbuf_occlude.farm.sensor_crops import farm_datasets
    from zbuf_occlude.sensors.placement import CropDistributions
    from zbuf_occlude.sensors.request import ScanRequest

    far = CropDistributions(distance_m=(150.0, 150.0), size_m=(1.0, 1.0))  # the VLP-16 reaches 100 m
    with caplog.at_level(logging.WARNING, logger="zbuf_occlude.farm.sensor_crops"):
        out = farm_datasets(trimesh.creation.box((1.0, 1.0, 1.0)), ScanRequest("vlp16"), name="chair/train/cube", label=0,
                            object_index=0, n_samples=3, n_points=16, distributions=far)  # fmt: skip
    assert len(out["data"]) == 0
    (message,) = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert message.startswith("chair/train/cube: samples 0, 1, 2 left out")


def test_min_returns_is_recorded_and_every_airborne_sample_holds_it(tmp_path):
    """``--sensor-min-returns``: on the card (left out when not given, so earlier data sets keep their digest), and no
    airborne sample holds fewer returns of its object; the placement fields are the aircraft's."""
    out = tmp_path / "air"
    argv = ["farm", str(SAMPLES), "--out", str(out), "--sensor", "riegl-q1560", "--samples-per-view", "2", "--points", "64",
            "--per-class", "1", "--splits", "train", "--classes", "chair,stool", "--sensor-size", "4:5",
            "--sensor-min-returns", "8", "--no-progress"]  # fmt: skip
    assert cli_main(argv) == 0
    card = json.loads((out / CARD_FILE).read_text())
    assert card["params"]["sensor_min_returns"] == 8
    assert "sensor_min_returns" not in FarmParams(sensor="hdl32e").to_dict()
    ds = OccludedDataset(out)
    assert len(ds) > 0
    for i in range(len(ds)):
        _, _, meta = ds[i]
        assert meta["n_visible"] >= 8
        assert meta["sensor_height_m"] > 500.0  # the aircraft, not a car roof (riegl-q1560 flies at 1,300 m)
        assert meta["elevation_deg"] > 45.0


@pytest.mark.parametrize("bad", [0, -3, 1.5, "8", None])
def test_a_card_with_a_bad_min_returns_is_refused_naming_the_option(bad):
    params = {**FarmParams(sensor="hdl32e").to_dict(), "sensor_min_returns": bad}
    if bad is None:  # left out when None: the same as not given
        assert FarmParams.from_dict(params).sensor.distributions.min_returns is None
        return
    with pytest.raises(InvalidInputError, match="^--sensor-min-returns must be an integer from 1 to"):
        FarmParams.from_dict(params)
