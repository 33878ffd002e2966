"""Hostile scene and sensor files: one line naming the file and the field, never a traceback, a wrong scan or a bomb.

Covers :mod:`zbuf_occlude.io.spec_files` (reading), :mod:`zbuf_occlude.sensors.checks`
(fields) and their users: :func:`~zbuf_occlude.sensors.scene.objects.load_scene`,
:func:`~zbuf_occlude.sensors.kinds.sensor_from_name` and the dataclasses' own checks.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError, UnsafePathError
from zbuf_occlude.sensors.scene import objects as scene_module
from zbuf_occlude.sensors.patterns.airborne import AirborneScanner
from zbuf_occlude.sensors.scan import scan_airborne
from zbuf_occlude.sensors.checks import MAX_SCENE_OBJECTS, MAX_SENSOR_RAYS, SHOWN_CHARS, key_text, value_kind
from zbuf_occlude.sensors.patterns.depth_camera import DepthCamera
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.kinds import LEGACY_BEAM_KEYS, SENSOR_KINDS, sensor_from_name
from zbuf_occlude.sensors.patterns.spinning import Lidar, lidar_preset
from zbuf_occlude.sensors.patterns.ray_table import RayTable
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject
from zbuf_occlude.sensors.scene.files import load_scene

yaml = pytest.importorskip("yaml", reason="YAML scenes need the [yaml] extra (PyYAML)")

#: Values no numeric field accepts: not finite, not a number, or too large for a float.
NOT_A_FINITE_NUMBER = [math.nan, math.inf, -math.inf, True, False, "5", [], {}, 10**400]
#: Longest message accepted: a file name, a field, what is expected and a quoted value.
MAX_MESSAGE_CHARS = 600

# -- helpers --------------------------------------------------------------------------------------


def _write(path: Path, spec) -> Path:
    """``spec`` as JSON (Python writes NaN / Infinity, as Python's json reads them) or YAML (.nan, .inf)."""
    path.write_text(yaml.safe_dump(spec) if path.suffix == ".yaml" else json.dumps(spec))
    return path


def _refusal(call, *args) -> str:
    """The message of the InvalidInputError that ``call(*args)`` raises (any other outcome fails)."""
    with pytest.raises(InvalidInputError) as info:
        call(*args)
    message = str(info.value)
    assert "\n" not in message and len(message) <= MAX_MESSAGE_CHARS, message[:2000]
    return message


def _scene_refusal(path: Path) -> str:
    """Refused when loaded or, at the latest, when built; the message names the file when loading refuses it."""

    def load_and_build():
        load_scene(path).build()

    return _refusal(load_and_build)


BOX = {"box_m": [1.0, 2.0, 1.5]}


def _valid_scene() -> dict:
    return {
        "ground": {"z_m": 0.0, "half_extent_m": 40.0},
        "objects": [
            {"mesh": {"box_m": [1.0, 2.0, 1.5]}, "class": "car", "position_m": [10.0, 0.0, 0.5], "yaw_deg": 30.0, "size_m": [4.5, 1.8, 1.5]}
        ],
        "occluders": [{"mesh": {"cylinder": {"radius_m": 0.2, "height_m": 3.0, "sections": 16}}, "position_m": [6.0, 1.0], "size_m": 3.0}],
        "sensor": {"height_m": 1.8, "position_m": [0.0, 0.5]},
    }


#: Every numeric field of a scene file: its path in :func:`_valid_scene`.
SCENE_NUMBERS = [
    ("ground", "z_m"), ("ground", "half_extent_m"), ("sensor", "height_m"), ("sensor", "position_m", 0),
    ("sensor", "position_m", 1), ("objects", 0, "position_m", 0), ("objects", 0, "position_m", 2), ("objects", 0, "yaw_deg"),
    ("objects", 0, "size_m", 1), ("objects", 0, "mesh", "box_m", 2), ("occluders", 0, "size_m"),
    ("occluders", 0, "mesh", "cylinder", "radius_m"), ("occluders", 0, "mesh", "cylinder", "height_m"),
    ("occluders", 0, "mesh", "cylinder", "sections"),
]  # fmt: skip


def _set(spec, path: tuple, value):
    node = spec
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return spec


def _field_name(path: tuple) -> str:
    """The name a message gives the field at ``path``: its last key (``position_m[0]`` for an item)."""
    keys = [k for k in path if isinstance(k, str)]
    return f"{keys[-1]}[{path[-1]}]" if isinstance(path[-1], int) else keys[-1]


# -- the known failures ---------------------------------------------------------------------------


def _billion_laughs(levels: int) -> str:
    """A scene whose objects' positions are ``levels`` anchors of nine aliases each, the last
    object quoting the deepest under an unknown key: 9**levels values in ~60 bytes a level."""
    lines = ["objects:", "  - mesh: {box_m: [1, 1, 1]}", "    position_m: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    for k in range(1, levels):
        lines += ["  - mesh: {box_m: [1, 1, 1]}", f"    position_m: &a{k} [{', '.join([f'*a{k - 1}'] * 9)}]"]
    lines += ["  - mesh: {box_m: [1, 1, 1]}", f"    colour: *a{levels - 1}"]
    return "\n".join(lines) + "\n"


def test_yaml_aliases_are_refused_before_anything_is_expanded(tmp_path: Path) -> None:
    path = tmp_path / "laughs.yaml"
    path.write_text(_billion_laughs(6))  # 531,441 values: formatted whole, the message was 1.6 MB
    start = time.perf_counter()
    message = _refusal(load_scene, path)
    assert time.perf_counter() - start < 5.0
    assert "laughs.yaml" in message and "alias" in message and "line 5" in message


@pytest.mark.slow
def test_the_billion_laughs_scene_is_refused_in_a_process_capped_at_1_gib(tmp_path: Path) -> None:
    """9**11 values from 800 bytes grew past 8 GB; run where a regression dies of MemoryError instead."""
    path = tmp_path / "laughs.yaml"
    path.write_text(_billion_laughs(11))
    assert path.stat().st_size < 1200
    code = (
        "import resource, sys\n"
        "resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n"
        "from zbuf_occlude.cli.main import main\n"
        f"sys.exit(main(['scan', {str(path)!r}, '--out', {str(tmp_path / 'out')!r}]))\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"},
    )
    assert run.returncode == 2, run.stderr[-2000:]
    assert "Traceback" not in run.stderr and "laughs.yaml" in run.stderr and "alias" in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("suffix", [".json", ".yaml"])
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_a_non_finite_yaw_is_refused_not_an_empty_scan(tmp_path: Path, suffix: str, value: float) -> None:
    spec = {"objects": [{"mesh": dict(BOX), "position_m": [5, 0], "yaw_deg": value}]}
    message = _refusal(load_scene, _write(tmp_path / f"scene{suffix}", spec))
    assert (
        f"scene{suffix}: objects[0]: yaw_deg must be a finite number, got {'NaN' if math.isnan(value) else 'an infinite number'}" in message
    )


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"mesh": [1, 2]}, "mesh"), ({"mesh": 5}, "mesh"), ({"mesh": None}, "mesh"), ({"mesh": ""}, "mesh"),
        ({"size_m": "big"}, "size_m"), ({"size_m": {}}, "size_m"), ({"size_m": []}, "size_m"), ({"size_m": [1, 2]}, "size_m"),
        ({"position_m": "ab"}, "position_m"), ({"position_m": []}, "position_m"), ({"position_m": [1, 2, 3, 4]}, "position_m"),
        ({"mesh": {"cylinder": [1, 2]}}, "mesh.cylinder"), ({"mesh": {"cylinder": "x"}}, "mesh.cylinder"),
        ({"mesh": {"cylinder": {"radius_m": 1}}}, "height_m"), ({"mesh": {"box_m": [1, 1]}}, "box_m"),
        ({"mesh": {"box_m": 1}}, "box_m"), ({"mesh": {"sphere": 1}}, "sphere"), ({"mesh": {}}, "mesh"),
        ({"mesh": {"box_m": [1, 1, 1], "cylinder": {"radius_m": 1, "height_m": 1}}}, "mesh"), ({"class": ["car"]}, "class"),
        ({"up": "x"}, "up"), ({"up": 1}, "up"), ({"colour": "red"}, "colour"), ({"mesh": "\ud800.off"}, "mesh"),
    ],
)  # fmt: skip
def test_wrong_types_in_a_scene_object_name_the_file_and_field(tmp_path: Path, change: dict, field: str) -> None:
    spec = {"objects": [{"mesh": dict(BOX), "position_m": [5, 0], **change}]}
    message = _refusal(load_scene, _write(tmp_path / "scene.json", spec))
    assert "scene.json: objects[0]" in message and field in message, message


@pytest.mark.parametrize(
    ("spec", "field"),
    [
        ({"sensor": "x"}, "sensor"), ({"sensor": {"position_m": [1, 2, 3, 4]}}, "sensor position_m"),
        ({"sensor": {"height": 2}}, "height"), ({"sensor": {"height_m": -1}}, "sensor height_m"),
        ({"sensor": {"height_m": 1e9}}, "sensor height_m"), ({"ground": "no"}, "ground"), ({"ground": 0}, "ground"),
        ({"ground": {"z": 1}}, "'z'"), ({"ground": {"half_extent_m": 0}}, "half_extent_m"), ({"objects": {"a": 1}}, "objects"),
        ({"objects": "box"}, "objects"), ({"occluders": [5]}, "occluders[0]"), ({"objects": [{"class": "car"}]}, "needs mesh"),
        ({"objets": []}, "objets"), ({1: 2}, "1"), ({"ground": False}, "empty"),
    ],
)  # fmt: skip
def test_wrong_scene_fields_name_the_file_and_field(tmp_path: Path, spec: dict, field: str) -> None:
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(spec))
    message = _refusal(load_scene, path)
    assert message.startswith(f"{path}: ") and field in message, message


@pytest.mark.parametrize("text", ["", "[", "- 1\n- 2\n", "a: !!python/object/apply:os.system [ls]\n", "--- {}\n--- {}\n",
                                  "objects: [{mesh: {box_m: [1, 1, " + "9" * 5000 + "]}}]\n", "objects: " + "[" * 100 + "]" * 100 + "\n"])  # fmt: skip
def test_unparsable_yaml_is_one_line_naming_the_file(tmp_path: Path, text: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    assert _refusal(load_scene, path).startswith(f"{path}: ")


@pytest.mark.parametrize("suffix", [".json", ".yaml"])
def test_a_scene_nested_too_deep_is_refused_by_the_parsers_limit(tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"deep{suffix}"
    path.write_text(
        ('{"objects": ' if suffix == ".json" else "objects: ") + "[" * 10_000 + "]" * 10_000 + ("}" if suffix == ".json" else "")
    )
    message = _refusal(load_scene, path)
    assert str(path) in message and "deeper than 64 levels" in message


def test_a_sensor_file_nested_thousands_deep_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "deep.json"
    path.write_text('{"kind": "lidar", "name": ' + "[" * 5000 + "]" * 5000 + "}")
    message = _refusal(sensor_from_name, str(path))
    assert str(path) in message and "deeper than 64 levels" in message


@pytest.mark.parametrize(
    ("spec", "names"),
    [
        ({"kind": "lidar", "name": "x", "elevations_deg": [0.0], "range_nosie_m": 0.1}, "range_nosie_m"),
        ({"kind": "airborne", "preset": "riegl-q1560", "n_line": 3}, "n_line"),
        ({"kind": "depth_camera", "name": "c", "K": [[5, 0, 3], [0, 5, 3], [0, 0, 1]], "width": 8, "height": 8, "fx": 1}, "fx"),
        ({"kind": "lidr", "name": "x"}, "kind"), ({"kind": "lidar", "elevations_deg": [0.0]}, "needs name"),
        ({"kind": "airborne", "preset": 5}, "preset"), ({"kind": "airborne", "preset": "nope"}, "airborne scanner presets"), ([1, 2], "JSON object"),
        ({"kind": "lidar", "name": "../../x", "elevations_deg": [0.0]}, "lidar name"),
        ({"kind": "lidar", "name": "a\nb", "elevations_deg": [0.0]}, "lidar name"),
    ],
)  # fmt: skip
def test_bad_sensor_files_name_the_file_and_field(tmp_path: Path, spec, names: str) -> None:
    path = _write(tmp_path / "sensor.json", spec)
    message = _refusal(sensor_from_name, str(path))
    assert message.startswith(f"{path}: ") and names in message, message


# -- laws: every numeric field, every sensor -----------------------------------------------------


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(path=st.sampled_from(SCENE_NUMBERS), value=st.sampled_from(NOT_A_FINITE_NUMBER), suffix=st.sampled_from([".json", ".yaml"]))
def test_any_non_finite_or_non_number_scene_field_is_refused_naming_it(tmp_path: Path, path: tuple, value, suffix: str) -> None:
    file = _write(tmp_path / f"scene{suffix}", _set(_valid_scene(), path, value))
    message = _refusal(load_scene, file)
    assert message.startswith(f"{file}: ") and _field_name(path) in message, message


def test_the_valid_scene_of_the_laws_loads_and_builds(tmp_path: Path) -> None:
    for suffix in (".json", ".yaml"):
        scene = load_scene(_write(tmp_path / f"scene{suffix}", _valid_scene()))
        assert len(scene.build().local_to_world) == 3 and scene.sensor_position_m == (0.0, 0.5)


def kind_of_class(cls):
    """The :class:`~zbuf_occlude.sensors.kinds.SensorKind` row of a sensor class."""
    return next(kind for kind in SENSOR_KINDS if kind.cls is cls)


def _annotation(cls, name: str) -> str:
    return str(next(f.type for f in fields(cls) if f.name == name))


def _numeric_fields(cls) -> list[str]:
    """Constructor fields whose annotation holds a number (``float``, ``int``, tuples of them)."""
    return [f.name for f in fields(cls) if f.init and ("float" in str(f.type) or "int" in str(f.type))]


VALID_SENSORS = {
    Lidar: {"kind": "lidar", "name": "x", "elevations_deg": [-1.0, 0.0, 1.0], "beam": {"footprint_rays": 7, "divergence_deg": 0.2}},
    AirborneScanner: {"kind": "airborne", "name": "als", "swath_deg": 40.0, "pulse_rate_hz": 1e5, "line_rate_hz": 50.0,
                      "altitude_m": 800.0, "speed_mps": 60.0, "n_lines": 2, "headings_deg": [0.0, 90.0],
                      "beam": {"footprint_rays": 7, "divergence_deg": 0.2, "max_returns": 3, "range_resolution_m": 0.6}},
    RayTable: {"kind": "ray_table", "name": "t", "time_s": [0.0, 0.5], "azimuth_deg": [0.0, 10.0], "elevation_deg": [0.0, -5.0],
               "beam": {"max_returns": 2, "range_resolution_m": 0.5}},
    DepthCamera: {"kind": "depth_camera", "name": "cam", "K": [[50.0, 0.0, 31.5], [0.0, 50.0, 23.5], [0.0, 0.0, 1.0]],
                  "width": 64, "height": 48, "noise": 0.01},
}  # fmt: skip
#: ``(class, field, in_beam)``: every numeric field of every sensor file, a pulsed kind's beam fields (in its ``"beam"``
#: object, :class:`~zbuf_occlude.sensors.beam.fields.Beam`'s) included.
SENSOR_NUMBERS = [(cls, name, False) for cls in VALID_SENSORS for name in _numeric_fields(cls)] + [
    (cls, name, True) for cls in VALID_SENSORS if kind_of_class(cls).pulsed for name in _numeric_fields(Beam)
]
#: The beam keys of the flat layout fit-sensor wrote before scanners had a ``"beam"`` (still read): ``(key, the name its
#: message gives)``.
LEGACY_NUMBERS = [(old, new) for old, new in LEGACY_BEAM_KEYS.items() if new in _numeric_fields(Beam)] + [
    ("detection_reflectivity", "detection_reflectivity"), ("detection_range_m", "detection_range_m"),
]  # fmt: skip


def _with_bad(cls, name: str, value, in_beam: bool = False) -> dict:
    """The valid sensor spec with ``value`` in field ``name`` (inside the list, for a sequence field; in ``"beam"`` with ``in_beam``)."""
    spec = {k: dict(v) if isinstance(v, dict) else v for k, v in VALID_SENSORS[cls].items()}
    if in_beam:
        spec["beam"] = {**spec.get("beam", {}), name: value}
        return spec
    annotation = _annotation(cls, name)
    if annotation.startswith("tuple[tuple"):
        spec[name] = [[value, 0.0, 1.0], *spec[name][1:]]
    elif annotation.startswith("tuple"):
        spec[name] = [value]
    else:
        spec[name] = value
    return spec


def test_every_numeric_sensor_field_is_covered() -> None:
    names = {(Beam if in_beam else cls).__name__ + "." + name for cls, name, in_beam in SENSOR_NUMBERS}
    assert {"Lidar.elevations_deg", "Beam.detection_threshold", "Beam.divergence_deg", "Beam.range_noise_m", "Beam.intensity_scale",
            "AirborneScanner.headings_deg", "AirborneScanner.n_lines", "RayTable.time_s", "DepthCamera.K", "DepthCamera.width",
            "DepthCamera.noise"} <= names  # fmt: skip
    # Lidar: 4 (its ring pattern), AirborneScanner: 9 (swath, rates, flight, plan and turns), RayTable: its 3 columns,
    # DepthCamera: 9; Beam: 17 (every pulse and receiver field), tried in the file of each pulsed kind
    assert len(names) == 4 + 9 + 3 + 9 + 17
    assert "AirborneScanner.turn_s" in names
    assert sum(in_beam for *_, in_beam in SENSOR_NUMBERS) == 3 * 17
    assert {new for _, new in LEGACY_NUMBERS} >= {"min_range_m", "max_range_m", "range_noise_m", "divergence_deg", "footprint_rays"}


@pytest.mark.parametrize("cls", list(VALID_SENSORS))
def test_the_valid_sensor_files_of_the_laws_load(tmp_path: Path, cls) -> None:
    sensor = sensor_from_name(str(_write(tmp_path / "s.json", VALID_SENSORS[cls])))
    assert isinstance(sensor, cls)
    if "beam" in VALID_SENSORS[cls]:  # the file's beam fields reach the beam
        assert all(getattr(sensor.beam, k) == v for k, v in VALID_SENSORS[cls]["beam"].items())


def _python_refusal(cls, name: str, value, in_beam: bool) -> str:
    """The message of the constructor given the bad value: the Beam's for a beam field, the sensor's otherwise."""
    spec = {k: v for k, v in _with_bad(cls, name, value, in_beam).items() if k != "kind"}
    if in_beam:
        return _refusal(lambda: Beam(**spec["beam"]))
    if "beam" in spec:
        spec["beam"] = Beam(**spec["beam"])
    return _refusal(lambda: cls(**spec))


@settings(max_examples=160, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(field=st.sampled_from(SENSOR_NUMBERS), value=st.sampled_from(NOT_A_FINITE_NUMBER))
def test_any_non_finite_or_non_number_sensor_field_is_refused_naming_file_and_field(tmp_path: Path, field: tuple, value) -> None:
    cls, name, in_beam = field
    path = _write(tmp_path / "sensor.json", _with_bad(cls, name, value, in_beam))
    message = _refusal(sensor_from_name, str(path))
    assert message.startswith(f"{path}: ") and name in message, message
    if in_beam:
        assert "beam" in message.split(name)[0], message  # the beam named before its field
    # the same rule in Python: the constructor names the field
    assert name in _python_refusal(cls, name, value, in_beam)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(field=st.sampled_from(LEGACY_NUMBERS), value=st.sampled_from(NOT_A_FINITE_NUMBER), kind=st.sampled_from([Lidar, AirborneScanner]))
def test_a_bad_beam_key_of_the_flat_layout_is_refused_naming_file_and_field(tmp_path: Path, field: tuple, value, kind) -> None:
    key, named = field
    spec = {k: v for k, v in VALID_SENSORS[kind].items() if k != "beam"}
    path = _write(tmp_path / "sensor.json", {**spec, key: value})
    message = _refusal(sensor_from_name, str(path))
    assert message.startswith(f"{path}: ") and named in message, message


#: Every key a lidar file may hold: its fields, the flat layout's beam keys, and the file's own.
LIDAR_FILE_KEYS = {
    "kind",
    "fit",
    "preset",
    *(f.name for f in fields(Lidar)),
    *LEGACY_BEAM_KEYS,
    "detection_reflectivity",
    "detection_range_m",
}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.text(min_size=1, max_size=30).filter(lambda k: k not in LIDAR_FILE_KEYS))
def test_any_unknown_key_of_a_sensor_file_is_refused_naming_it(tmp_path: Path, key: str) -> None:
    path = _write(tmp_path / "sensor.json", {**VALID_SENSORS[Lidar], key: 1})
    message = _refusal(sensor_from_name, str(path))
    assert message.startswith(f"{path}: ") and key_text(key) in message


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.text(min_size=1, max_size=30).filter(lambda k: k not in {f.name for f in fields(Beam)}))
def test_any_unknown_key_of_a_sensor_files_beam_is_refused_naming_it(tmp_path: Path, key: str) -> None:
    spec = VALID_SENSORS[Lidar]
    path = _write(tmp_path / "sensor.json", {**spec, "beam": {**spec["beam"], key: 1}})
    message = _refusal(sensor_from_name, str(path))
    assert message.startswith(f"{path}: ") and "beam" in message and key_text(key) in message


@pytest.mark.parametrize("beam", [[1, 2], "ideal", 5, None, True])
def test_a_beam_that_is_not_an_object_is_refused(tmp_path: Path, beam) -> None:
    path = _write(tmp_path / "sensor.json", {**VALID_SENSORS[Lidar], "beam": beam})
    message = _refusal(sensor_from_name, str(path))
    assert message.startswith(f"{path}: ") and "beam" in message, message


# -- limits: counts, sizes, ranges ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("cls", "change", "field"),
    [
        (Lidar, {"firing_rate_hz": 1e12, "rotation_hz": 1.0}, "rays per revolution"),
        (Lidar, {"elevations_deg": [0.0] * 64, "firing_rate_hz": 1e300, "rotation_hz": 1e-300}, "rays per revolution"),
        (Lidar, {"beam": {"min_range_m": -1.0}}, "min_range_m"), (Lidar, {"beam": {"max_range_m": -5.0}}, "max_range_m"),
        (Lidar, {"detection_range_m": 1e300}, "detection_range_m"),  # the flat layout's range at reflectivity: τ = ρ / R² underflows
        (Lidar, {"beam": {"footprint_rays": 10**400, "divergence_deg": 0.2}}, "footprint_rays"),
        (Lidar, {"beam": {"footprint_rays": 1025, "divergence_deg": 0.2}}, "footprint_rays"), (Lidar, {"elevations_deg": []}, "elevations_deg"),
        (Lidar, {"elevations_deg": [90.0]}, "elevations_deg[0]"), (Lidar, {"beam": {"dropout": 1.0}}, "dropout"),
        (Lidar, {"beam": {"max_returns": 16, "range_resolution_m": 0.5}}, "max_returns"),
        (Lidar, {"beam": {"max_intensity": 65_536}}, "max_intensity"),
        (Lidar, {"beam": {"min_range_m": 5.0, "max_range_m": 5.0}}, "min_range_m must be below max_range_m"),
        (Lidar, {"beam": {"max_range_m": 1e300}}, "max_range_m"),
        (AirborneScanner, {"n_lines": 10**400}, "n_lines"), (AirborneScanner, {"n_lines": 2.5}, "n_lines"),
        (AirborneScanner, {"altitude_m": -1.0}, "altitude_m"), (AirborneScanner, {"pulse_rate_hz": 1e300}, "pulses per line"),
        (AirborneScanner, {"headings_deg": []}, "headings_deg"), (AirborneScanner, {"pattern": ["linear"]}, "pattern"),
        (AirborneScanner, {"beam": {"footprint_rays": 7}}, "divergence_deg"),
        (RayTable, {"time_s": [1.0, 0.0]}, "time_s"), (RayTable, {"elevation_deg": [0.0, 91.0]}, "elevation_deg[1]"),
        (DepthCamera, {"width": 10**9}, "width"), (DepthCamera, {"width": 4096, "height": 4096}, "pixels"),
        (DepthCamera, {"width": 0}, "width"), (DepthCamera, {"max_depth_m": -1.0}, "max_depth_m"),
        (DepthCamera, {"noise": "loud"}, "noise"), (DepthCamera, {"K": [[1, 0, 0], [0, 1, 0]]}, "K"),
        (DepthCamera, {"beam": {"range_noise_m": 0.1}}, "beam"),
    ],
)  # fmt: skip
def test_counts_and_ranges_beyond_their_limits_are_refused(tmp_path: Path, cls, change: dict, field: str) -> None:
    path = _write(tmp_path / "sensor.json", {**VALID_SENSORS[cls], **change})
    message = _refusal(sensor_from_name, str(path))
    assert message.startswith(f"{path}: ") and field in message, message


def test_a_scene_of_too_many_objects_is_refused_before_any_is_built(tmp_path: Path) -> None:
    spec = {"objects": [{"mesh": dict(BOX), "position_m": [5, 0]}] * (MAX_SCENE_OBJECTS + 1)}
    message = _refusal(load_scene, _write(tmp_path / "many.json", spec))
    assert "many.json" in message and f"more than {MAX_SCENE_OBJECTS:,}" in message


def test_a_scene_naming_one_mesh_too_often_is_refused_by_its_triangles(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(scene_module, "MAX_MESH_FACES", 100)  # a box has 12 triangles: the 9th passes 100
    scene = load_scene(_write(tmp_path / "boxes.json", {"ground": False, "objects": [{"mesh": dict(BOX), "position_m": [5, 0]}] * 20}))
    assert "more than 100 triangles by objects[8]" in _refusal(scene.build)


def test_an_airborne_scan_of_too_many_pulses_is_refused_before_casting() -> None:
    big = ScanScene(ground_half_extent_m=16_000.0)
    message = _refusal(scan_airborne, big, sensor_from_name("riegl-q1560"), (0.0, 0.0), 16_000.0)
    assert f"more than {MAX_SENSOR_RAYS:,}" in message
    crawling = sensor_from_name("riegl-q1560").with_(speed_mps=1e-300)
    assert f"more than {MAX_SENSOR_RAYS:,}" in _refusal(scan_airborne, ScanScene(), crawling, (0.0, 0.0), 10.0)


# -- mesh paths stay in the scene's folder --------------------------------------------------------


@pytest.fixture()
def box_file(tmp_path: Path) -> Path:
    import trimesh

    path = tmp_path / "outside" / "box.off"
    path.parent.mkdir()
    trimesh.creation.box(extents=(1.0, 1.0, 1.0)).export(path)
    return path


@pytest.mark.parametrize("how", ["dotdot", "absolute", "symlink"])
def test_a_mesh_outside_the_scene_folder_is_refused(tmp_path: Path, box_file: Path, how: str) -> None:
    folder = tmp_path / "scenes"
    folder.mkdir()
    name = {"dotdot": "../outside/box.off", "absolute": str(box_file), "symlink": "link.off"}[how]
    if how == "symlink":
        (folder / "link.off").symlink_to(box_file)
    with pytest.raises(UnsafePathError) as info:
        load_scene(_write(folder / "scene.json", {"objects": [{"mesh": name, "position_m": [5, 0]}]}))
    assert str(info.value).startswith(f"{folder / 'scene.json'}: objects[0]: mesh: ") and "\n" not in str(info.value)


def test_a_mesh_in_a_subfolder_of_the_scene_is_read(tmp_path: Path, box_file: Path) -> None:
    (tmp_path / "outside" / "sub").mkdir()
    box_file.rename(tmp_path / "outside" / "sub" / "box.off")
    scene = load_scene(
        _write(tmp_path / "outside" / "scene.json", {"objects": [{"mesh": "sub/box.off", "position_m": [5, 0], "size_m": 2.0}]})
    )
    assert np.ptp(scene.build().world_vertices(1), axis=0).max() == pytest.approx(2.0)


# -- messages and the Python API ------------------------------------------------------------------


def test_no_message_formats_a_whole_user_structure(tmp_path: Path) -> None:
    huge = list(range(200_000))
    for spec in ({"objects": [huge]}, {"objects": [{"mesh": dict(BOX), "position_m": huge}]}, {huge[0]: huge, "x": huge},
                 {"objects": [{"mesh": {"cylinder": huge}}]}, {"sensor": {"position_m": [[huge]] * 3}}):  # fmt: skip
        _refusal(load_scene, _write(tmp_path / "scene.json", spec))
    assert len(value_kind([[[huge]]])) <= SHOWN_CHARS and len(value_kind(10**10_000)) <= SHOWN_CHARS


def test_the_python_api_applies_the_same_rules() -> None:
    assert "yaw_deg must be a finite number, got NaN" in _refusal(lambda: SceneObject(dict(BOX), yaw_deg=math.nan))
    assert "position_m must be" in _refusal(lambda: ScanScene().add(dict(BOX), position_m="ab"))
    assert "ground z_m" in _refusal(lambda: ScanScene(ground_z_m=math.inf))
    assert "sensor position_m" in _refusal(lambda: ScanScene(sensor_position_m=(1, 2, 3, 4)))
    assert "rotation_hz must be a finite number > 0, got true" in _refusal(lambda: lidar_preset("vlp16", rotation_hz=True))
    assert "width must be an integer" in _refusal(lambda: DepthCamera("c", VALID_SENSORS[DepthCamera]["K"], "64", 48))
    # a field changed after construction is checked again when the scene is built
    obj = SceneObject(dict(BOX), position_m=(5.0, 0.0))
    obj.yaw_deg = math.nan
    assert "yaw_deg" in _refusal(ScanScene(objects=[obj]).build)


@pytest.mark.parametrize(
    "spec",
    [{"objects": [{"mesh": {"box_m": [1, 1, 1]}, "position_m": [5, 0], "yaw_deg": math.nan}]}, {"sensor": "x"},
     {"objects": [{"mesh": [1, 2]}]}, {"objects": [{"mesh": "../x.off"}]}],
)  # fmt: skip
def test_the_scan_command_exits_2_with_one_line(tmp_path: Path, capsys, spec: dict) -> None:
    from zbuf_occlude.cli.main import main

    path = _write(tmp_path / "scene.json", spec)
    assert main(["scan", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "scene.json" in err and "\n" not in err and "Traceback" not in err
