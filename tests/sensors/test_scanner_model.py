"""The scanner as one model: Beam checks, the kinds table (and no isinstance switch on a sensor class outside it),
return modes, a scanner moving during its sweep, and the ideal beam's scan unchanged."""

from __future__ import annotations

import ast
import hashlib
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.fields import IDEAL_BEAM, Beam
from zbuf_occlude.sensors.beam.echo_energy import returns_of_mode
from zbuf_occlude.sensors.kinds import SENSOR_KINDS, kind_of, sensor_from_spec, sensor_to_json, with_beam
from zbuf_occlude.sensors.patterns.spinning import Lidar, lidar_preset
from zbuf_occlude.sensors.platform import Trajectory
from zbuf_occlude.sensors.scan import scan
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject

PACKAGE = Path(__file__).resolve().parents[2] / "zbuf_occlude"
SENSOR_CLASSES = {kind.cls.__name__ for kind in SENSOR_KINDS}


def _class_switches(tree: ast.AST) -> list[int]:
    """Lines of ``isinstance(x, C)`` / ``type(x) is C`` where C names a sensor class (alone or in a tuple)."""
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) in ("isinstance", "issubclass") and len(node.args) == 2:
            names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)} | {
                n.attr for n in ast.walk(node.args[1]) if isinstance(n, ast.Attribute)
            }
            if names & (SENSOR_CLASSES | {"_PULSED"}):
                lines.append(node.lineno)
    return lines


def _outside_the_kinds_table(finder) -> dict[str, list[int]]:
    """``finder``'s lines in every module of the package but ``sensors/kinds.py``, by module (none: ``{}``)."""
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "kinds.py" and path.parent.name == "sensors":
            continue
        lines = finder(ast.parse(path.read_text(encoding="utf-8")))
        if lines:
            found[str(path.relative_to(PACKAGE))] = lines
    return found


def test_no_module_but_the_kinds_table_switches_on_a_sensor_class():
    assert _outside_the_kinds_table(_class_switches) == {}


def test_the_switch_finder_finds_a_switch():
    code = "def f(s):\n    return isinstance(s, (Lidar, RayTable)) or isinstance(s, sensors.AirborneScanner)\n"
    assert _class_switches(ast.parse(code)) == [2, 2]


KIND_NAMES = {kind.name for kind in SENSOR_KINDS}


def _name_switches(tree: ast.AST) -> list[int]:
    """Lines that compare a name (``kind.name``, ``kind_of(s).name``) or a call's answer (``kind_name(s)``) with a sensor
    kind's name, and tuples of kind names alone: a capability of the kinds table asked for by name.  (The ``lidar``
    training set shares the kind's name: ``train_set == "lidar"`` is no switch.)"""
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            named = {n.value for o in operands for n in ast.walk(o) if isinstance(n, ast.Constant) and isinstance(n.value, str)}
            asks = any((isinstance(o, ast.Attribute) and o.attr == "name") or isinstance(o, ast.Call) for o in operands)
            if named & KIND_NAMES and asks:
                lines.append(node.lineno)
        elif isinstance(node, ast.Assign) and isinstance(node.value, ast.Tuple) and len(node.value.elts) > 1:
            values = {e.value for e in node.value.elts if isinstance(e, ast.Constant)}
            if values and values <= KIND_NAMES:
                lines.append(node.lineno)
    return lines


def test_no_module_asks_a_sensor_kind_by_its_name():
    """``capabilities(sensor).spins`` (or ``.fits``, ``.flies``, ``.trains``), never ``kind.name == "lidar"``: a new kind
    says what it can do in its row of the table, and no guard elsewhere needs to learn its name."""
    assert _outside_the_kinds_table(_name_switches) == {}


def test_the_name_switch_finder_finds_a_switch():
    code = ('def f(s, kind, r):\n    if kind.name != "lidar" or kind_name(s) in ("airborne",):\n        pass\n'
            'KINDS = ("lidar", "airborne")\nSETS = ("lidar", "pooled")\nLIDAR_SET = r["train_set"] == "lidar"\n')  # fmt: skip
    assert sorted(_name_switches(ast.parse(code))) == [2, 2, 4]  # both tests on line 2, the tuple of kinds; not SETS, not a set's name


def test_capabilities_of_each_kind_and_of_anything_else():
    from zbuf_occlude.sensors.kinds import NOT_A_SENSOR, capabilities, sensor_from_name

    table = {name: (k.spins, k.fits, k.trains, k.flies) for name, k in ((k.name, k) for k in SENSOR_KINDS)}
    assert table == {"lidar": (True, True, True, False), "airborne": (False, True, True, True),
                     "ray_table": (False, False, False, False), "depth_camera": (False, False, False, False)}  # fmt: skip
    assert capabilities(sensor_from_name("hdl32e")).spins and capabilities(sensor_from_name("riegl-vq780i")).flies
    for thing in (None, "hdl32e", 3, object()):
        kind = capabilities(thing)
        assert kind is NOT_A_SENSOR and not (kind.pulsed or kind.spins or kind.fits or kind.trains or kind.flies)


def test_every_kind_has_presets_of_its_class_and_pulsed_kinds_a_beam():
    for kind in SENSOR_KINDS:
        assert kind.presets, kind.name
        for name, preset in kind.presets.items():
            assert type(preset) is kind.cls and kind_of(preset) is kind and preset.name == name
            assert preset.source, name
            if kind.pulsed:
                assert isinstance(preset.beam, Beam) and preset.beam.source, name


def test_every_preset_beam_cites_what_it_takes_from_a_data_sheet():
    for kind in SENSOR_KINDS:
        for name, preset in kind.presets.items():
            if kind.pulsed:
                assert not preset.beam.is_ideal, name
                assert any(word in preset.beam.source for word in ("data sheet", "HELIOS++")), name


def test_every_kind_reads_back_from_its_json_and_takes_a_preset_key():
    for kind in SENSOR_KINDS:
        preset = next(iter(kind.presets.values()))
        assert sensor_to_json(sensor_from_spec(sensor_to_json(preset))) == sensor_to_json(preset)
        changed = sensor_from_spec({"kind": kind.name, "preset": preset.name})
        assert sensor_to_json(changed) == sensor_to_json(preset)


def test_a_sensor_file_changes_a_preset_beam_in_part_and_reads_the_flat_layout():
    s = sensor_from_spec({"kind": "lidar", "preset": "hdl32e", "beam": {"footprint_rays": 7}})
    assert s.beam.footprint_rays == 7 and s.beam.divergence_deg == lidar_preset("hdl32e").beam.divergence_deg
    flat = sensor_from_spec({"name": "x", "elevations_deg": [0.0], "range_noise_m": 0.05, "detection_reflectivity": 0.5,
                             "detection_range_m": 50.0, "beam_divergence_deg": 0.2})  # fmt: skip
    assert flat.beam.range_noise_m == 0.05 and flat.beam.divergence_deg == 0.2 and flat.beam.detection_threshold == 0.5 / 50.0**2
    assert (flat.beam.min_range_m, flat.beam.max_range_m) == (1.0, 100.0)  # what the flat layout's fields defaulted to
    with pytest.raises(InvalidInputError, match="give one field twice"):
        sensor_from_spec({"name": "x", "elevations_deg": [0.0], "range_noise_m": 0.05, "beam": {"range_noise_m": 0.01}})


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        ({"kind": "lidar", "preset": "riegl-q1560"}, "one of the spinning LiDAR presets"),
        ({"kind": "lidar", "preset": "hdl32e", "beam": {"footprint_rays": 7, "divergence_deg": 0}}, "needs divergence_deg"),
        ({"kind": "lidar", "preset": "hdl32e", "beam": {"max_returns": 2}}, "range_resolution_m"),
        ({"kind": "lidar", "preset": "hdl32e", "beam": {"laser": 1}}, "laser"),
        ({"kind": "lidar", "preset": "hdl32e", "beam": [1, 2]}, "beam"),
        ({"kind": "depth_camera", "preset": "kinect-v1", "beam": {}}, "beam"),
        (
            {"kind": "airborne", "preset": "riegl-q1560", "beam": {"return_mode": "dual", "max_returns": 3}},
            "return_mode dual records 2 returns per pulse; max_returns 3 contradicts it",
        ),
    ],
)
def test_bad_sensor_files_are_refused_naming_the_field(spec, words):
    with pytest.raises(InvalidInputError, match=words):
        sensor_from_spec(spec)


@pytest.mark.parametrize(
    ("changes", "words"),
    [
        ({"footprint_rays": 7}, "divergence_deg"),
        ({"max_returns": 3}, "range_resolution_m"),
        ({"range_resolution_m": 0.5}, "needs max_returns above 1"),
        (
            {"return_mode": "strongest", "max_returns": 2, "range_resolution_m": 1.0},
            "return_mode strongest records 1 return per pulse; max_returns 2",
        ),
        ({"echo_separation_m": 0.5}, "footprint_rays above 1"),
        ({"min_range_m": 5.0, "max_range_m": 2.0}, "min_range_m must be below max_range_m"),
        ({"intensity_scale": 0.0}, "intensity_scale"),
        ({"wavelength_nm": True}, "wavelength_nm"),
        ({"profile": "flat"}, "profile"),
        ({"dropout": 1.0}, "dropout"),
    ],
)
def test_beam_rules_are_checked_once_naming_the_field(changes, words):
    with pytest.raises(InvalidInputError, match=words):
        Beam(**changes)


def test_with_beam_refuses_a_camera_and_changes_a_lidar():
    camera = SENSOR_KINDS[-1].presets["kinect-v1"]
    with pytest.raises(InvalidInputError, match="no beam"):
        with_beam(camera, footprint_rays=7)
    assert with_beam(lidar_preset("vlp16"), footprint_rays=19).beam.footprint_rays == 19


def test_intensity_counts_scale_and_saturate():
    beam = Beam(intensity_scale=1000.0, max_intensity=255)
    assert beam.intensity_counts([0.0, 0.1, 0.2555, 10.0, np.nan, -1.0]).tolist() == [0, 100, 255, 255, 0, 0]
    with pytest.raises(InvalidInputError, match="intensity_scale"):
        IDEAL_BEAM.intensity_counts([1.0])


def test_return_modes_pick_velodyne_and_hesai_returns():
    pulse = np.array([0, 0, 0, 1, 2, 2])
    energy = np.array([1.0, 3.0, 2.0, 5.0, 4.0, 1.0])
    assert returns_of_mode(pulse, energy, "first").tolist() == [0, 3, 4]
    assert returns_of_mode(pulse, energy, "strongest").tolist() == [1, 3, 4]
    assert returns_of_mode(pulse, energy, "last").tolist() == [2, 3, 5]
    # dual: last and strongest; where the last is the strongest (pulse 1), only it; pulse 2: strongest 4, last 5
    assert returns_of_mode(pulse, energy, "dual").tolist() == [1, 2, 3, 4, 5]
    last_strongest = returns_of_mode(np.array([0, 0, 0]), np.array([1.0, 2.0, 3.0]), "dual")
    assert last_strongest.tolist() == [1, 2]  # the last is the strongest: the last and the second strongest


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 4), st.floats(0.0, 10.0)), min_size=1, max_size=30))
def test_return_modes_keep_one_or_two_returns_per_pulse_in_order(rows):
    rows = sorted(rows, key=lambda r: r[0])
    pulse = np.array([r[0] for r in rows])
    energy = np.array([r[1] for r in rows])
    for mode, most in (("first", 1), ("strongest", 1), ("last", 1), ("dual", 2)):
        chosen = returns_of_mode(pulse, energy, mode)
        assert np.all(np.diff(chosen) > 0)
        counts = np.bincount(pulse[chosen], minlength=5)
        assert np.all(counts[np.unique(pulse)] >= 1) and counts.max() <= most
        if mode in ("first", "last"):  # the pulse's echo nearest the sensor, or farthest (rows are in range order)
            rows_of = [np.flatnonzero(pulse == p) for p in np.unique(pulse)]
            assert chosen.tolist() == [r[0] if mode == "first" else r[-1] for r in rows_of]
        if mode == "strongest":
            for p in np.unique(pulse):
                assert energy[chosen[pulse[chosen] == p]][0] == energy[pulse == p].max()


def _wall() -> trimesh.Trimesh:
    """A flat wall 60 m long along x, its face to the sensor in the plane y = 5 m."""
    wall = trimesh.creation.box(extents=(60.0, 0.2, 8.0))
    wall.apply_translation((0.0, 5.1, 2.0))
    return wall


def test_a_scanner_moving_during_its_sweep_has_the_motion_distortion_of_a_real_one():
    speed = 10.0
    lidar = lidar_preset("hdl32e").with_(beam=IDEAL_BEAM.with_(min_range_m=1.0, max_range_m=100.0))
    start = np.eye(4)
    start[:3, 3] = (-1.0, 0.0, 1.8)
    moving = Trajectory.linear(start, (speed, 0.0, 0.0), 0.2, start_s=100.0)
    world = scan(_wall(), lidar, moving, frame="world", seed=0)
    raw = scan(_wall(), lidar, moving, frame="sensor", seed=0)
    wall = world.points[:, 1] > 4.0
    assert wall.sum() > 1000
    t = world.gps_time
    assert t.min() >= 100.0 and t.max() <= 100.0 + 1.0 / lidar.rotation_hz  # each point its own time, within one revolution
    # in the world the wall stands still; in the raw sweep it has slid back by speed × time, to 1 mm
    assert np.abs(world.points[wall, 1] - 5.0).max() < 1e-3
    expected = raw.points.astype(np.float64) + start[:3, 3] + np.outer(t - 100.0, (speed, 0.0, 0.0))
    assert np.abs(expected - world.points).max() < 1e-3
    assert np.ptp(t[wall]) * speed > 0.3  # the wall fills half the sweep: about half a metre of travel
    # against the scanner standing still at the start: each pulse met the wall speed × its time further along x, to 1 mm
    still = scan(_wall(), lidar, start, frame="world", seed=0)
    both, i, j = np.intersect1d(world.pulse_id[wall], still.pulse_id, return_indices=True)
    assert len(both) > 1000
    slid = world.points[wall][i].astype(np.float64) - still.points[j]
    assert np.abs(slid - np.outer(t[wall][i] - 100.0, (speed, 0.0, 0.0))).max() < 1e-3


def test_a_still_trajectory_scans_as_its_pose():
    pose = np.eye(4)
    pose[:3, 3] = (0.0, 0.0, 1.8)
    lidar = lidar_preset("vlp16")
    a = scan(_wall(), lidar, pose, seed=3)
    b = scan(_wall(), lidar, Trajectory.static(pose), seed=3)
    for key, value in a.arrays().items():
        assert np.array_equal(value, b.arrays()[key]), key


def test_a_trajectory_shorter_than_the_sweep_is_refused():
    short = Trajectory.linear(np.eye(4), (1.0, 0.0, 0.0), 0.01)
    with pytest.raises(InvalidInputError, match="outside its span"):
        scan(_wall(), lidar_preset("vlp16"), short)


def _digest(s, decimals: int = 3) -> str:
    """sha256 of a scan's arrays rounded to ``decimals`` (robust to last-bit differences between CPUs)."""
    h = hashlib.sha256()
    for key in ("points", "range_m", "face_index", "object_id", "return_number", "number_of_returns", "pulse_id", "ring"):
        value = getattr(s, key)
        value = np.round(value.astype(np.float64), decimals) if value.dtype.kind == "f" else value.astype(np.int64)
        h.update(key.encode() + np.ascontiguousarray(value).tobytes())
    return h.hexdigest()[:16]


def test_the_ideal_beam_scans_as_the_one_ray_first_hit_scan_did():
    """Pinned before the scanner was recomposed (the same scan then had every array bit for bit)."""
    scene = ScanScene(objects=[SceneObject({"box_m": [4.5, 1.8, 1.5]}, "car", (10.0, 0.0), 30.0)])
    s = scan(scene, Lidar("x", tuple(range(-15, 16, 2)), firing_rate_hz=18_000.0), seed=0)
    assert len(s) > 0 and np.all(s.return_number == 1) and np.all(s.intensity == 1.0)
    assert _digest(s) == PINNED_IDEAL


#: ``_digest`` of that scan by the code before the scanner was recomposed, its LiDAR given no noise and no range
#: limits (``Lidar(..., min_range_m=0, max_range_m=1e6, range_noise_m=0)``): 12,836 points.
PINNED_IDEAL = "d679acc1432da854"


def test_a_footprint_too_large_for_the_memory_is_refused_before_the_rays_are_cast(monkeypatch):
    import zbuf_occlude.resources as resources

    monkeypatch.setattr(resources, "available_memory", lambda: (2 * 2**30, "a test"))
    wide = sensor_from_spec({"kind": "lidar", "preset": "hdl64e", "beam": {"footprint_rays": 1024, "divergence_deg": 0.1}})
    with pytest.raises(resources.InsufficientMemoryError, match="footprint_rays 1024"):
        scan(_wall(), wide, np.eye(4))


def test_an_airborne_scan_takes_the_material_table_by_default_for_a_radiometric_multi_return_beam():
    from zbuf_occlude.sensors.patterns.airborne_presets import airborne_preset
    from zbuf_occlude.sensors.scan import scan_airborne

    scene = ScanScene(objects=[SceneObject({"cylinder": {"radius_m": 2.0, "height_m": 5.0}}, "bush", (0.0, 0.0))], ground_half_extent_m=8.0)
    als = airborne_preset("riegl-q1560", altitude_m=300.0)

    def arrays(scanner, **optics):
        return scan_airborne(scene, scanner, (0.0, 0.0), 6.0, seed=1, **optics).arrays()

    def same(a, b):
        return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)

    assert same(arrays(als), arrays(als, reflectivity="table", transmittance="table"))
    assert same(arrays(als, transmittance=0.0), arrays(als, reflectivity="table", transmittance=0.0))  # one given: the other the table's
    assert not same(arrays(als, transmittance=0.0), arrays(als, reflectivity=None, transmittance=0.0))
    assert not same(arrays(als), arrays(als, reflectivity=None, transmittance=None))
    plain = als.with_(beam=als.beam.with_(intensity_scale=None))  # no intensity model: no optics by default
    assert same(arrays(plain), arrays(plain, reflectivity=None, transmittance=None))


def test_a_moving_scan_in_the_sensor_frame_is_not_classified_into_las():
    lidar = lidar_preset("vlp16")
    moving = Trajectory.linear(np.eye(4), (10.0, 0.0, 0.0), 0.2)
    raw = scan(_wall(), lidar, moving, seed=0)
    with pytest.raises(InvalidInputError, match="which LAS cannot classify by height: give frame world"):
        raw.to_las_bytes()
    assert len(scan(_wall(), lidar, moving, seed=0, frame="world").to_las_bytes()) > 0
    assert len(scan(_wall(), lidar, np.eye(4), seed=0).to_las_bytes()) > 0  # standing still: its sensor frame is one frame
