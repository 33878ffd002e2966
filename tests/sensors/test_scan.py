"""Sensors (issue 12): presets, analytic ring patterns, Embree vs z-buffer, noise, seeds, occluders."""

from __future__ import annotations

import json
import math
import re
import shutil
import zipfile

import numpy as np
import pytest
import trimesh

import zbuf_occlude.sensors as S
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.kinds import SENSOR_KINDS, with_beam
from zbuf_occlude.sensors.raycast.embree import cast_embree
from zbuf_occlude.sensors.raycast.zbuffer import cast_zbuffer


def wall(distance_m: float, half_width_m: float, half_height_m: float) -> trimesh.Trimesh:
    """The plane x = distance_m, |y| <= half_width_m, |z| <= half_height_m (two triangles)."""
    d, w, h = distance_m, half_width_m, half_height_m
    v = np.array([[d, -w, -h], [d, w, -h], [d, w, h], [d, -w, h]], float)
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


def azimuth_index(lidar: S.Lidar, points: np.ndarray) -> np.ndarray:
    az = np.degrees(np.arctan2(points[:, 1], points[:, 0])) - lidar.azimuth_offset_deg
    return np.round(np.mod(az, 360.0) / (360.0 / lidar.n_azimuths)).astype(np.int64) % lidar.n_azimuths


# -- presets -----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(S.LIDAR_PRESETS))
def test_preset_beams_match_table(name):
    lidar = S.Lidar.preset(name)
    d, ring, az = lidar.rays()
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    elev = np.degrees(np.arcsin(d[:, 2]))
    assert np.allclose(elev, np.asarray(lidar.elevations_deg)[ring], atol=1e-9)
    got_az = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    assert np.allclose(np.mod(got_az - az + 180, 360) - 180, 0, atol=1e-9)
    steps = np.diff(np.sort(np.unique(np.round(az, 9))))
    assert np.allclose(steps, 360.0 / lidar.n_azimuths)
    assert abs(360.0 / lidar.n_azimuths - lidar.azimuth_step_deg) < 1e-3 * lidar.azimuth_step_deg
    assert len(d) == lidar.n_beams * lidar.n_azimuths
    assert lidar.source


def test_preset_tables_from_data_sheets():
    hdl32 = S.Lidar.preset("hdl32e")
    assert hdl32.n_beams == 32 and min(hdl32.elevations_deg) == -30.67 and max(hdl32.elevations_deg) == 10.67
    assert np.allclose(np.diff(sorted(hdl32.elevations_deg)), 4 / 3, atol=0.0067)
    assert abs(hdl32.azimuth_step_deg - 0.1659) < 1e-3  # 46.08 us firing cycle at 10 Hz
    vlp = S.Lidar.preset("vlp16")
    assert sorted(vlp.elevations_deg) == list(range(-15, 16, 2)) and abs(vlp.azimuth_step_deg - 0.199) < 1e-3
    hdl64 = S.Lidar.preset("hdl64e")
    assert hdl64.n_beams == 64 and max(hdl64.elevations_deg) == 2.0 and abs(min(hdl64.elevations_deg) - -24.33) < 1e-9
    assert abs(hdl64.azimuth_step_deg - 0.09) < 1e-9
    os1 = S.Lidar.preset("os1-64")
    assert os1.n_beams == 64 and np.isclose(np.ptp(os1.elevations_deg), 33.2) and os1.n_azimuths == 1024


def test_custom_table_and_errors():
    lidar = S.Lidar("mine", (-1.0, 0.0, 1.0), rotation_hz=5.0, firing_rate_hz=3600.0)
    assert lidar.azimuth_step_deg == 0.5 and lidar.n_azimuths == 720
    for bad in ({"elevations_deg": ()}, {"elevations_deg": (95.0,)}, {"rotation_hz": 0.0}, {"beam": None}):
        with pytest.raises(InvalidInputError, match=next(iter(bad))):
            lidar.with_(**bad)
    for bad in ({"min_range_m": 10.0, "max_range_m": 5.0}, {"dropout": 1.0}, {"range_noise_m": -0.1}):  # the beam's fields
        with pytest.raises(InvalidInputError, match=r"^spinning LiDAR: beam: .*" + next(iter(bad))):
            with_beam(lidar, **bad)
    with pytest.raises(InvalidInputError, match="unknown lidar preset"):
        S.Lidar.preset("hdl128")
    with pytest.raises(InvalidInputError, match="K must be"):
        S.DepthCamera("x", ((0, 0, 1), (0, 1, 1), (0, 0, 1)), 10, 10)


# -- analytic plane ------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["hdl32e", "vlp16"])
def test_wall_gives_analytic_rings(name):
    lidar = with_beam(S.Lidar.preset(name), range_noise_m=0.0)
    D, W, H = 10.0, 3.0, 2.5
    s = S.scan(wall(D, W, H), lidar, np.zeros(3), seed=0)
    # Analytic: beam (e, a) meets x = D at y = D tan a, z = D tan e / cos a.
    d, ring, _ = lidar.rays()
    with np.errstate(divide="ignore"):
        y, z = D * d[:, 1] / d[:, 0], D * d[:, 2] / d[:, 0]
    expected = (d[:, 0] > 0) & (np.abs(y) < W) & (np.abs(z) < H)
    assert len(s) == expected.sum() > 500
    assert np.array_equal(np.bincount(s.ring, minlength=lidar.n_beams), np.bincount(ring[expected], minlength=lidar.n_beams))
    e = np.radians(np.asarray(lidar.elevations_deg)[s.ring])
    a = np.arctan2(s.points[:, 1], s.points[:, 0]).astype(np.float64)
    assert np.allclose(s.points[:, 0], D, atol=1e-5)
    assert np.allclose(s.points[:, 2], D * np.tan(e) / np.cos(a), atol=1e-5)
    assert np.allclose(s.range_m, D / (np.cos(e) * np.cos(a)), atol=1e-5)
    assert np.allclose(s.incidence_deg, np.degrees(np.arccos(np.cos(e) * np.cos(a))), atol=1e-3)
    assert np.allclose(s.normal, [-1, 0, 0], atol=1e-6)
    assert np.all(s.object_id == 1)


def test_range_limits_apply_to_measured_values():
    lidar = with_beam(S.Lidar.preset("hdl32e"), range_noise_m=0.2, max_range_m=10.5)
    s = S.scan(wall(10.0, 5.0, 5.0), lidar, np.zeros(3))
    assert len(s) > 0 and s.range_m.max() <= 10.5
    cam = S.DepthCamera.preset("kinect-v1", max_depth_m=2.0, noise=0.05)
    c = S.scan(wall(2.0, 3.0, 3.0), cam, S.look_at_pose([0, 0, 0], [1, 0, 0]), seed=0)
    assert 1000 < len(c) < 0.7 * 640 * 480 and c.points[:, 2].max() <= 2.0


# -- Embree vs z-buffer --------------------------------------------------------------------------
def _sample_scene(sample_meshes):
    path = sample_meshes[0]
    return S.ScanScene().add(str(path), class_name="x", position_m=(10.0, 0.0), yaw_deg=30.0, size_m=4.5)


@pytest.fixture(scope="module")
def sample_meshes():
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "data" / "samples"
    return sorted(root.rglob("*.off"))


def test_zbuffer_ranges_match_embree(sample_meshes):
    scene = _sample_scene(sample_meshes)
    built = scene.build()
    lidar = S.Lidar.preset("hdl32e")
    d, _, _ = lidar.rays((-30.0, 30.0))
    origin = np.array([0.0, 0.0, 1.8])
    f_e, t_e = cast_embree(built.mesh, origin, d)
    f_z, t_z, _ = cast_zbuffer(built.mesh, origin, d, resolution=1024)
    on_object = built.face_object[np.maximum(f_e, 0)] == 1
    assert (f_e >= 0).sum() > 5000 and on_object.sum() > 200
    both = (f_e >= 0) & (f_z >= 0)
    with np.errstate(invalid="ignore"):
        agree = both & (np.abs(t_e - t_z) <= 1e-3)
    n_returns = np.count_nonzero((f_e >= 0) | (f_z >= 0))
    assert agree.sum() >= 0.999 * n_returns
    assert np.count_nonzero(agree & on_object) >= 0.999 * on_object.sum()


def test_scan_backends_agree(sample_meshes):
    scene = _sample_scene(sample_meshes)
    lidar = S.Lidar.preset("vlp16")
    a = S.scan(scene, lidar, seed=3, azimuth_range_deg=(-20, 20))
    b = S.scan(scene, lidar, seed=3, azimuth_range_deg=(-20, 20), backend="zbuffer", zbuffer=S.ZBufferView(resolution=1024))
    assert len(a) == len(b) > 1000
    assert np.mean(np.abs(a.range_m - b.range_m) <= 1e-3) >= 0.999


# -- noise, dropout, seeds -----------------------------------------------------------------------
def test_range_noise_sigma_and_dropout():
    sigma = 0.05
    lidar = with_beam(S.Lidar.preset("hdl32e"), range_noise_m=sigma, dropout=0.2)
    clean = S.scan(wall(10.0, 8.0, 6.0), lidar.with_(beam=lidar.beam.with_(range_noise_m=0.0, dropout=0.0)), np.zeros(3))
    noisy = S.scan(wall(10.0, 8.0, 6.0), lidar, np.zeros(3), seed=1)
    keep = len(noisy) / len(clean)
    assert abs(keep - 0.8) < 4 * math.sqrt(0.16 / len(clean))
    # Same rays: noisy returns lie along the clean ones; the error is along the beam.
    dirs = noisy.points / np.linalg.norm(noisy.points, axis=1, keepdims=True)
    true_range = 10.0 / dirs[:, 0].astype(np.float64)
    err = noisy.range_m - true_range
    assert len(err) > 5000
    assert abs(err.std() / sigma - 1.0) < 0.05
    assert abs(err.mean()) < 4 * sigma / math.sqrt(len(err))
    assert np.allclose(np.linalg.norm(noisy.points, axis=1), noisy.range_m, rtol=1e-5)


def test_depth_camera_axial_noise_and_quantisation():
    cam = S.DepthCamera.preset("kinect-v1", quantization_m_per_m2=0.0)
    z = 2.0
    s = S.scan(wall(z, 3.0, 3.0), cam, S.look_at_pose([0, 0, 0], [1, 0, 0]), seed=2)
    depth = s.points[:, 2].astype(np.float64)
    assert len(s) > 100_000
    # Incidence is small over the image; compare with σ(z, θ) per pixel.
    sigma = S.nguyen_axial_sigma_m(z, s.incidence_deg)
    assert abs(((depth - z) / sigma).std() - 1.0) < 0.05
    # Nguyen et al. 2012, Eq. 2 at z = 2 m, small incidence: 1.2 mm + 1.9 mm · 1.6² = 6.06 mm
    assert S.nguyen_axial_sigma_m(2.0, 0.0) == pytest.approx(0.006064, abs=1e-9)
    assert abs((depth - z).std() / 0.006064 - 1.0) < 0.05
    q = S.DepthCamera.preset("kinect-v1", noise="none")
    sq = S.scan(wall(z, 3.0, 3.0), q, S.look_at_pose([0, 0, 0], [1, 0, 0]), seed=2)
    levels = np.unique(np.round(sq.points[:, 2], 5))
    assert len(levels) == 1 and abs(levels[0] - z) <= 2.85e-3 * z * z / 2 + 1e-6
    assert np.all(sq.pixel[:, 0] < 640) and np.all(sq.pixel[:, 1] < 480)


def test_depth_camera_grazing_incidence_invalid():
    cam = S.DepthCamera.preset("kinect-v1", max_incidence_deg=70.0, noise="none")
    scene = S.ScanScene(ground_half_extent_m=20.0)
    s = S.scan(scene, cam, S.look_at_pose([0, 0, 1.0], [3, 0, 0]), seed=0)
    everything = S.scan(scene, cam.with_(max_incidence_deg=90.0), S.look_at_pose([0, 0, 1.0], [3, 0, 0]), seed=0)
    assert len(s) > 1000 and len(everything) > len(s)
    assert s.incidence_deg.max() <= 70.0 and everything.incidence_deg.max() > 70.0
    assert np.all(s.object_id == S.GROUND_ID)


def test_same_seed_same_bytes():
    lidar = with_beam(S.Lidar.preset("vlp16"), dropout=0.1)
    scene = S.ScanScene().add({"box_m": [2.0, 2.0, 2.0]}, position_m=(6.0, 1.0))
    s1, s2, s3 = (S.scan(scene, lidar, seed=k) for k in (7, 7, 8))
    for k, v in s1.arrays().items():
        assert np.array_equal(v, s2.arrays()[k]), k
    assert not np.array_equal(s1.range_m[: len(s3)], s3.range_m[: len(s1)])


# -- scenes and occluders ------------------------------------------------------------------------
def test_occluder_removes_exactly_the_returns_it_shadows():
    lidar = with_beam(S.Lidar.preset("hdl32e"), range_noise_m=0.0)
    target = {"box_m": [4.5, 1.8, 1.5]}
    blocker = {"cylinder": {"radius_m": 0.3, "height_m": 3.0}}
    alone = S.ScanScene().add(target, position_m=(12.0, 0.0))
    both = S.ScanScene().add(target, position_m=(12.0, 0.0)).add_occluder(blocker, position_m=(6.0, 0.3))
    only_blocker = S.ScanScene(objects=[S.SceneObject(blocker, position_m=(6.0, 0.3))])
    kw = dict(seed=0, azimuth_range_deg=(-30, 30))
    t_alone, t_both, b = (S.scan(sc, lidar, **kw) for sc in (alone, both, only_blocker))

    def keys(s, oid):
        c = s.crop(oid)
        return set(zip(c.ring.tolist(), azimuth_index(lidar, c.points).tolist()))

    shadow = keys(b, 1)
    assert len(shadow) > 50
    kept, before = keys(t_both, 1), keys(t_alone, 1)
    assert kept == before - shadow
    assert len(before & shadow) > 20
    assert keys(t_both, 2) == shadow  # the occluder's own returns (nothing stands in front of it)


def _spec_writers():
    writers = [("json", json.dumps)]
    try:
        import yaml

        writers.append(("yaml", yaml.safe_dump))
    except ImportError:  # the 'yaml' extra is not installed: JSON only
        pass
    return writers


@pytest.mark.parametrize("suffix, dump", _spec_writers())
def test_scene_spec_file_equals_builder(tmp_path, sample_meshes, suffix, dump):
    shutil.copy(sample_meshes[0], tmp_path / sample_meshes[0].name)  # a scene file's meshes lie in its folder
    spec = {
        "ground": {"z_m": 0.0, "half_extent_m": 40.0},
        "objects": [{"mesh": sample_meshes[0].name, "class": "x", "position_m": [10, 0], "yaw_deg": 30, "size_m": 4.5}],
        "occluders": [{"mesh": {"box_m": [0.5, 2.0, 1.0]}, "position_m": [6, 0.5]}],
        "sensor": {"height_m": 1.7},
    }
    (tmp_path / f"s.{suffix}").write_text(dump(spec))
    from_file = S.load_scene(tmp_path / f"s.{suffix}")
    built = (S.ScanScene(ground_half_extent_m=40.0, sensor_height_m=1.7)
             .add(str(sample_meshes[0]), class_name="x", position_m=(10, 0), yaw_deg=30, size_m=4.5)
             .add_occluder({"box_m": [0.5, 2.0, 1.0]}, position_m=(6, 0.5)))  # fmt: skip
    lidar = S.Lidar.preset("vlp16")
    a, b = S.scan(from_file, lidar, seed=1), S.scan(built, lidar, seed=1)
    assert len(a) > 0 and np.array_equal(a.points, b.points) and np.array_equal(a.object_id, b.object_id)
    # object stands on the ground with the requested size
    m = from_file.build()
    v = m.mesh.vertices[m.mesh.faces[m.face_object == 1].ravel()]
    c, s_ = math.cos(math.radians(-30)), math.sin(math.radians(-30))
    aligned = v @ np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]]).T  # undo the yaw
    assert abs(v[:, 2].min()) < 1e-9 and abs(np.ptp(aligned, axis=0).max() - 4.5) < 1e-9
    centre = (aligned.min(0)[:2] + aligned.max(0)[:2]) / 2
    assert np.allclose(centre, [10 * c, 10 * s_], atol=1e-9)
    (tmp_path / "bad.json").write_text(json.dumps({"objets": []}))
    with pytest.raises(InvalidInputError, match="unknown scene keys"):
        S.load_scene(tmp_path / "bad.json")


def test_npz_and_ply_roundtrip(tmp_path):
    scene = S.ScanScene().add({"box_m": [2.0, 2.0, 2.0]}, position_m=(6.0, 0.0))
    s = S.scan(scene, S.Lidar.preset("vlp16"), seed=0, frame="world")
    s.to_npz(tmp_path / "s.npz")
    r = S.read_scan_npz(tmp_path / "s.npz")
    assert np.array_equal(r.points, s.points) and np.array_equal(r.ring, s.ring) and r.frame == "world"
    assert np.allclose(r.sensor_position, [0, 0, 1.8])
    with np.load(tmp_path / "s.npz") as z:
        assert {"points", "ring", "range_m", "face_index", "object_id", "normal", "incidence_deg", "sensor_position"} <= set(z.files)
    cloud = trimesh.load(tmp_path / s.to_ply(tmp_path / "s.ply").name)
    assert np.allclose(np.asarray(cloud.vertices), s.points)
    # world frame: range is the distance to the sensor position
    assert np.allclose(np.linalg.norm(s.points - s.sensor_position, axis=1), s.range_m, rtol=1e-5)


def test_zbuffer_rechecks_widened_gpu_hits_in_float64():
    """Rays 1e-5 m below a triangle's edge: the GPU's widened float32 test (1e-5 in barycentrics)
    accepts the triangle; the float64 re-check must send them on to the wall behind."""
    tri = np.array([[5.0, -1.0, -1.0], [5.0, 1.0, -1.0], [5.0, 0.0, 1.0]])
    wall_v = np.array([[10.0, -20, -20], [10.0, 20, -20], [10.0, 20, 20], [10.0, -20, 20]])
    mesh = trimesh.Trimesh(np.vstack([tri, wall_v]), [[0, 1, 2], [3, 4, 5], [3, 5, 6]], process=False)
    y = np.linspace(-0.5, 0.5, 201)
    d = np.column_stack([np.full_like(y, 5.0), y, np.full_like(y, -1.0 - 1e-5)])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    f_z, t_z, n_fallback = cast_zbuffer(mesh, np.zeros(3), d, resolution=512)
    f_e, t_e = cast_embree(mesh, np.zeros(3), d)
    assert np.all(f_e >= 1) and np.array_equal(f_z, f_e)
    assert np.allclose(t_z, t_e, atol=1e-6) and n_fallback > 0


def _scan_arrays(n: int = 4) -> dict:
    """A minimal scan NPZ's arrays, as Scan.to_npz writes them."""
    rng = np.random.default_rng(0)
    return {"points": rng.normal(size=(n, 3)).astype(np.float32), "range_m": np.ones(n, np.float32),
            "face_index": np.arange(n), "object_id": np.array([1] * n, np.int32), "normal": np.zeros((n, 3), np.float32),
            "incidence_deg": np.zeros(n, np.float32), "sensor_position": np.zeros(3), "sensor_to_world": np.eye(4),
            "frame": np.array("sensor"), "sensor": np.array("vlp16")}  # fmt: skip


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"sensor_to_world": np.eye(2)}, r"sensor_to_world must be a finite \(4, 4\)"),
        ({"points": np.zeros((4, 2), np.float32)}, r"points must be a \(N, 3\) number array, got shape \(4, 2\)"),
        ({"sensor_position": np.array("here")}, r"sensor_position must be a finite \(3,\) number array"),
        ({"sensor_to_world": np.full((4, 4), np.nan)}, "sensor_to_world must be a finite"),
        ({"object_id": np.ones(4, np.float32)}, "object_id must be a \\(N,\\) integer array"),
        ({"range_m": np.ones(3, np.float32)}, "range_m has 3 rows but points has 4"),
        ({"frame": np.array("moon")}, "frame must be one of"),
        (
            {"points": np.array([[0, 0, 0], [np.nan, 0, 0], [0, np.inf, 0], [1, 1, 1]], np.float32)},
            "2 points have NaN or inf coordinates: the scan is damaged",
        ),
    ],
)
def test_read_scan_npz_checks_shapes_and_dtypes(tmp_path, change, match):
    from zbuf_occlude.experiments.realism import read_object_clouds

    path = tmp_path / "scan.npz"
    np.savez(path, **{**_scan_arrays(), **change})
    with pytest.raises(InvalidInputError, match=rf"scan\.npz: {match}"):
        S.read_scan_npz(path)
    with pytest.raises(InvalidInputError, match=rf"scan\.npz: {match}"):  # realism reads through it
        read_object_clouds(path)


def test_read_scan_npz_names_the_file_of_damaged_compressed_data(tmp_path):
    # the headers inflate fine (the size check passes); the damage is further into a member
    path = tmp_path / "scan.npz"
    np.savez_compressed(path, **_scan_arrays(20000))
    raw = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("points.npy")
    middle = info.header_offset + 30 + len(info.filename) + len(info.extra) + info.compress_size // 2
    raw[middle : middle + 64] = bytes(64)
    path.write_bytes(bytes(raw))
    with pytest.raises(InvalidInputError, match=r"scan\.npz: cannot read its arrays \("):
        S.read_scan_npz(path)


def test_read_scan_npz_refuses_inflation_past_the_cap(tmp_path, monkeypatch):
    import importlib

    scan_module = importlib.import_module("zbuf_occlude.sensors.scan_data")

    path = tmp_path / "zeros.npz"
    np.savez_compressed(path, **{**_scan_arrays(), "normal": np.zeros((4, 3), np.float32), "pad": np.zeros(1_000_000)})
    monkeypatch.setattr(scan_module, "MAX_SCAN_NPZ_BYTES", 1 << 20)  # stands for 4 GiB
    with pytest.raises(InvalidInputError, match=r"zeros\.npz: its members inflate to 8,0\d\d,\d+ bytes, more than the 1,048,576"):
        S.read_scan_npz(path)
    np.savez(tmp_path / "ok.npz", **_scan_arrays())
    assert len(S.read_scan_npz(tmp_path / "ok.npz")) == 4


def test_depth_camera_intrinsics_follow_opencv() -> None:
    """Pixel centres at integers (OpenCV, Open3D, and the package's Camera.K): the Kinect's principal
    point is ((W − 1)/2, (H − 1)/2), and the ray of pixel (u, v) projects back onto (u, v) with K."""
    from zbuf_occlude.sensors.patterns.depth_camera import depth_camera_preset

    cam = depth_camera_preset("kinect-v1")
    K = np.asarray(cam.intrinsics)
    assert (K[0, 2], K[1, 2]) == ((cam.width - 1) / 2, (cam.height - 1) / 2)
    directions, pixel = cam.rays()
    uvw = directions @ K.T
    np.testing.assert_allclose(uvw[:, :2] / uvw[:, 2:], pixel, atol=1e-9)


# -- the scan command: its presets, and meshes it cannot see ----------------------------------------
def test_scan_help_lists_every_preset_of_the_registries(capsys, monkeypatch) -> None:
    from zbuf_occlude.cli.main import main
    from zbuf_occlude.sensors.patterns.airborne_presets import AIRBORNE_PRESETS

    def help_text() -> str:
        with pytest.raises(SystemExit):
            main(["scan", "--help"])
        return re.sub(r"-\s+", "-", " ".join(capsys.readouterr().out.split()))  # argparse wraps lines, after a hyphen too

    text = help_text()
    for kind in SENSOR_KINDS:  # every kind's presets, the ray table's (livox-mid70) too
        for name in kind.presets:
            assert name in text, f"{kind.name} preset {name}"
    assert "optech-galaxy" in text and "livox-mid70" in text
    assert "dales-q1560" in text
    # a preset added to a registry shows up with no other change
    monkeypatch.setitem(AIRBORNE_PRESETS, "my-survey", AIRBORNE_PRESETS["riegl-q1560"].with_(name="my-survey"))
    assert "my-survey" in help_text()


def _plane_mesh(path, corners) -> str:
    trimesh.Trimesh(np.asarray(corners, float), [[0, 1, 2], [0, 2, 3]], process=False).export(path)
    return str(path)


def test_scan_refuses_a_mesh_flat_in_z_naming_it(tmp_path, capsys) -> None:
    # a single square, zero height: on the ground it lies in the ground plane
    from zbuf_occlude.cli.main import main

    square = _plane_mesh(tmp_path / "square.obj", [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    assert main(["scan", square, "--crop", "--samples", "2", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "square.obj: flat in z" in err and "--up" in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_scan_exits_1_naming_each_scan_without_a_return_of_the_object(tmp_path, capsys) -> None:
    # a wall (zero volume, but upright) seen edge-on: every ray passes it; the files are written and named
    from zbuf_occlude.cli.main import main

    edge_on = _plane_mesh(tmp_path / "wall.obj", [[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]])
    assert main(["scan", edge_on, "--crop", "--yaw", "0", "--samples", "2", "--out", str(tmp_path / "out")]) == 1
    captured = capsys.readouterr()
    assert captured.err.count("EMPTY ") == 2 and "no return of the object" in captured.err
    assert "wrote 2 files" in captured.out and "2 of 2 scans hold no return of the object" in captured.out
    # turned to face the sensor, the same wall returns points and the scan succeeds
    assert main(["scan", edge_on, "--crop", "--yaw", "90", "--samples", "2", "--out", str(tmp_path / "facing")]) == 0
    assert "EMPTY" not in capsys.readouterr().err


def test_scan_places_an_airborne_scanner_at_any_offset_and_names_a_missing_sensor_file(tmp_path, capsys) -> None:
    from zbuf_occlude.cli.main import main

    # the aircraft flies far above: an across-track offset below half the object cannot put it inside
    argv = ["scan", "box", "--sensor", "dales-q1560", "--extents", "4.5,1.8,1.5", "--distance", "1", "--azimuth", "90", "--crop"]
    assert main([*argv, "--out", str(tmp_path / "als")]) == 0
    assert main([*argv[:3], "hdl32e", *argv[4:], "--out", str(tmp_path / "lidar")]) == 2  # a ground sensor would be
    assert "may put the sensor inside the object" in capsys.readouterr().err
    assert main(["scan", "box", "--sensor", str(tmp_path / "fitted.json"), "--out", str(tmp_path / "x")]) == 2
    assert "fitted.json: no such file" in capsys.readouterr().err
