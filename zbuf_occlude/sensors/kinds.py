"""Sensor kinds as a table: each kind's class, presets, file keys and what the pipeline does with it.

A sensor is one of the kinds in :data:`SENSOR_KINDS`.  Everything that differs between kinds is a
field of its :class:`SensorKind` row, read from here: the presets (:func:`sensor_from_name`), a
sensor file's keys (every kind takes ``"preset"`` and a partial ``"beam"``), whether it fires
pulses through a beam (LiDARs) or frames (cameras), and whether it flies a plan of its own.
Nothing outside this module asks a sensor for its class or a kind for its name: ``kind_of(sensor).pulsed``
or ``capabilities(sensor).spins``, not an ``isinstance`` or ``issubclass`` test nor ``kind.name == "lidar"``
(``tests/sensors/test_scanner_model.py`` walks the source for them).

A scanner that fires pulses is a beam (:class:`~zbuf_occlude.sensors.beam.fields.Beam`) fired along a
scan pattern (its class: rings, airborne lines, a table's rows) from a platform (a pose, a
:class:`~zbuf_occlude.sensors.platform.Trajectory`, or an airborne flight plan).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.ray_tables import RAY_TABLE_SUFFIXES
from zbuf_occlude.sensors.patterns.airborne import AIRBORNE_IDEAL_BEAM, AirborneScanner
from zbuf_occlude.sensors.patterns.airborne_presets import AIRBORNE_PRESETS
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.checks import MAX_RANGE_M, given, located, mapping, real, text, value_kind
from zbuf_occlude.sensors.patterns.depth_camera import DEPTH_CAMERA_PRESETS, DepthCamera
from zbuf_occlude.sensors.patterns.spinning import LIDAR_PRESETS, Lidar
from zbuf_occlude.sensors.patterns.ray_table import RAY_TABLE_FILE_BEAM, RAY_TABLE_PRESETS, RayTable, load_ray_table

__all__ = [
    "SENSOR_KINDS",
    "SensorKind",
    "NOT_A_SENSOR",
    "capabilities",
    "kind_of",
    "kind_named",
    "preset_names",
    "sensor_from_name",
    "sensor_to_json",
    "with_beam",
]


@dataclass(frozen=True)
class SensorKind:
    """One kind of sensor.

    Attributes
    ----------
    name : str
        The ``"kind"`` of its sensor files.
    title : str
        What messages and help texts call it ("spinning LiDAR").
    cls : type
        Its class.
    presets : Mapping[str, object]
        Its presets by name.
    pulsed : bool
        Whether it fires pulses through a beam (a ``beam`` field; :func:`~zbuf_occlude.sensors.scan.fire_pulses`).
    flies : bool
        Whether it flies a plan of its own (:func:`~zbuf_occlude.sensors.scan.scan_airborne`)
        rather than standing at a pose or moving along a trajectory.
    array_fields : tuple of str
        Fields given as arrays (a ray table's columns), written to files as lists.
    sweeps_sectors : bool
        Whether its pulses sweep the azimuths evenly, so that a crop may fire only the object's
        azimuth sector (``scan(azimuth_range_deg=)``) and find the same returns there.
    spins : bool
        Whether it spins a fan of fixed elevations (rings) about its vertical axis from the ground:
        what ``fit-sensor`` fits ring by ring (:func:`~zbuf_occlude.sensors.fit.fit_lidar`), across
        whose line of sight a crop's width is measured, and whose partial echoes are fitted.
    fits : bool
        Whether ``fit-sensor`` fits it to real scans (:mod:`zbuf_occlude.sensors.fit`).
    trains : bool
        Whether ``experiment sim2real`` scans its training crops with it (an object placed before a
        ground scanner, or flown over).
    """

    name: str
    title: str
    cls: type
    presets: Mapping[str, object]
    pulsed: bool
    flies: bool = False
    array_fields: tuple[str, ...] = ()
    sweeps_sectors: bool = False
    spins: bool = False
    fits: bool = False
    trains: bool = False


#: Every kind, in the order help texts list them.
SENSOR_KINDS: tuple[SensorKind, ...] = (
    SensorKind("lidar", "spinning LiDAR", Lidar, LIDAR_PRESETS, pulsed=True, sweeps_sectors=True, spins=True, fits=True, trains=True),
    SensorKind("airborne", "airborne scanner", AirborneScanner, AIRBORNE_PRESETS, pulsed=True, flies=True, fits=True, trains=True),
    SensorKind(
        "ray_table", "ray-table scanner", RayTable, RAY_TABLE_PRESETS, pulsed=True, array_fields=("time_s", "azimuth_deg", "elevation_deg")
    ),  # fmt: skip
    SensorKind("depth_camera", "depth camera", DepthCamera, DEPTH_CAMERA_PRESETS, pulsed=False),
)
_BY_CLASS = {kind.cls: kind for kind in SENSOR_KINDS}
_BY_NAME = {kind.name: kind for kind in SENSOR_KINDS}


def kind_of(sensor: object) -> SensorKind:
    """The :class:`SensorKind` of ``sensor``.

    Raises
    ------
    InvalidInputError
        Not a sensor of any kind, naming its type.
    """
    kind = _BY_CLASS.get(type(sensor))
    if kind is None:
        names = ", ".join(k.cls.__name__ for k in SENSOR_KINDS)
        raise InvalidInputError(f"a sensor must be a {names}; got {type(sensor).__name__}")
    return kind


#: What :func:`capabilities` answers for anything that is no sensor: a kind that can do nothing.
NOT_A_SENSOR = SensorKind("", "not a sensor", type(None), {}, pulsed=False)


def capabilities(sensor: object) -> SensorKind:
    """The :class:`SensorKind` of ``sensor``, or :data:`NOT_A_SENSOR` for anything else: what a check of
    what a caller was given asks (``if not capabilities(base).spins: refuse in its own words``)."""
    return _BY_CLASS.get(type(sensor), NOT_A_SENSOR)


def kind_named(name: str) -> SensorKind:
    """The :class:`SensorKind` whose files say ``"kind": name``.

    Raises
    ------
    InvalidInputError
        An unknown kind, naming the known ones.
    """
    return _BY_NAME[text(name, "kind", choices=tuple(_BY_NAME))]


def preset_names() -> dict[str, tuple[str, ...]]:
    """Every preset name, sorted, by kind name (in :data:`SENSOR_KINDS` order): for help texts and messages."""
    return {kind.name: tuple(sorted(kind.presets)) for kind in SENSOR_KINDS}


def with_beam(sensor, **changes):
    """``sensor`` with its beam's fields changed (``with_beam(lidar, footprint_rays=7)``), checked again.

    Raises
    ------
    InvalidInputError
        A sensor without a beam (a depth camera), or a change the beam refuses, naming the field.
    """
    kind = kind_of(sensor)
    if not kind.pulsed:
        raise InvalidInputError(f"the sensor is a {kind.title}: it has no beam to change ({', '.join(sorted(changes))})")
    with located(kind.title):
        return replace(sensor, beam=sensor.beam.with_(**changes))


#: A sensor file's beam keys of the flat layout fit-sensor wrote before scanners had a ``"beam"``:
#: read as the beam's fields (``detection_reflectivity`` and ``detection_range_m`` as τ = ρ / R²).
LEGACY_BEAM_KEYS = {
    "min_range_m": "min_range_m", "max_range_m": "max_range_m", "range_noise_m": "range_noise_m", "dropout": "dropout",
    "dropout_range_per_m": "dropout_range_per_m", "beam_divergence_deg": "divergence_deg", "footprint_rays": "footprint_rays",
    "beam_profile": "profile", "max_returns": "max_returns", "range_resolution_m": "range_resolution_m",
    "echo_separation_m": "echo_separation_m", "power_noise": "power_noise", "detection_threshold": "detection_threshold",
}  # fmt: skip
_LEGACY_DETECTION = ("detection_reflectivity", "detection_range_m")
_BEAM_KEYS = tuple(f.name for f in fields(Beam) if f.init)
#: The beam a flat-layout file without a ``"preset"`` starts from: the defaults the flat fields had (a spinning LiDAR's and
#: a ray table's: 1-100 m, 0.02 m noise, τ = 0.8 / 100²; an airborne scanner's: 0.02 m noise at 1064 nm).
_LEGACY_BEAM = {
    "lidar": RAY_TABLE_FILE_BEAM, "ray_table": RAY_TABLE_FILE_BEAM, "airborne": AIRBORNE_IDEAL_BEAM.with_(range_noise_m=0.02),
}  # fmt: skip


def sensor_from_name(name: str | os.PathLike):
    """A preset of any kind, a sensor from a JSON file, or a ray table from a ``.csv`` or ``.npy`` file.

    A sensor file is a JSON object: ``"kind"`` (a :data:`SENSOR_KINDS` name, default
    ``"lidar"``), optionally ``"preset": NAME`` (a preset of that kind, whose fields the file's
    change), the kind's constructor fields, and for a pulsed kind a ``"beam"`` object of
    :class:`~zbuf_occlude.sensors.beam.fields.Beam` fields, which change the preset's beam (or the
    ``ideal`` beam).  An optional ``"fit"`` block (what :mod:`~zbuf_occlude.sensors.fit` writes) is
    metadata.  Files of the flat layout (beam fields beside the pattern's: :data:`LEGACY_BEAM_KEYS`)
    are read too.  The file is read by :func:`~zbuf_occlude.io.spec_files.read_spec_file`
    (size and nesting bounded); every field is checked by its class.  A ray table file is read by
    :func:`~zbuf_occlude.sensors.patterns.ray_table.load_ray_table` with
    :data:`~zbuf_occlude.sensors.patterns.ray_table.RAY_TABLE_FILE_BEAM`, named by its stem.

    Raises
    ------
    InvalidInputError
        An unknown name, a ``.json`` file that does not exist, or a file that is not JSON, nests
        too deep, has an unknown kind, preset or key, or a field of the wrong type or range (the
        message names the file and the field); what :func:`~zbuf_occlude.sensors.patterns.ray_table.load_ray_table`
        refuses of a ray table file.
    """
    if not isinstance(name, (str, os.PathLike)):
        raise InvalidInputError(f"a sensor must be a preset name or a .json file, got {value_kind(name)}")
    name = os.fspath(name)
    for kind in SENSOR_KINDS:
        if name.lower() in kind.presets:
            return kind.presets[name.lower()]
    path = Path(name)
    if path.suffix.lower() == ".json" and path.is_file():
        from zbuf_occlude.io.spec_files import read_spec_file

        spec = read_spec_file(path, what="sensor", yaml_ok=False)
        with located(str(path)):
            return sensor_from_spec(spec)
    if path.suffix.lower() == ".json":
        raise InvalidInputError(f"sensor file {path}: no such file (fit-sensor writes one; or name a preset)")
    if path.suffix.lower() in RAY_TABLE_SUFFIXES:
        return load_ray_table(path, beam=RAY_TABLE_FILE_BEAM)
    raise InvalidInputError(
        f"unknown sensor {given(name)}; use one of {[n for names in preset_names().values() for n in names]} or a .json file "
        f"(or a ray table: {', '.join(RAY_TABLE_SUFFIXES)})"
    )


def sensor_from_spec(spec: object):
    """The sensor a sensor file's parsed JSON describes (:func:`sensor_from_name`); errors name the field."""
    if not isinstance(spec, dict):
        raise InvalidInputError(f"a sensor file must be a JSON object of the sensor's fields, got {value_kind(spec)}")
    kind = kind_named(spec.get("kind", "lidar"))
    own = tuple(f.name for f in fields(kind.cls) if f.init)
    legacy = (*LEGACY_BEAM_KEYS, *_LEGACY_DETECTION) if kind.pulsed else ()
    spec = mapping(spec, kind.name, ("kind", "fit", "preset", *own, *legacy))
    spec.pop("kind", None)
    spec.pop("fit", None)  # a fitted sensor's estimates (zbuf_occlude.sensors.fit), metadata
    base = None
    if "preset" in spec:
        preset = text(spec.pop("preset"), "preset")
        if preset.lower() not in kind.presets:
            raise InvalidInputError(
                f"preset must be one of the {kind.title} presets {sorted(kind.presets)}, got another string of {len(preset):,} characters"
            )
        base = kind.presets[preset.lower()]
    if kind.pulsed:
        flat = any(key in spec for key in (*LEGACY_BEAM_KEYS, *_LEGACY_DETECTION))
        spec["beam"] = _beam_of(spec, base.beam if base is not None else _LEGACY_BEAM[kind.name] if flat else _default_beam(kind))
    if base is not None:
        return replace(base, **spec)
    missing = [f.name for f in fields(kind.cls) if f.init and f.name not in spec and _required(f)]
    if missing:
        raise InvalidInputError(f"a {kind.cls.__name__} needs {', '.join(missing)}")
    return kind.cls(**spec)


def _default_beam(kind: SensorKind) -> Beam:
    """The beam a kind's class takes when none is given."""
    return next(f.default for f in fields(kind.cls) if f.name == "beam")


def _required(f) -> bool:
    from dataclasses import MISSING

    return f.default is MISSING and f.default_factory is MISSING


def _beam_of(spec: dict, base: Beam) -> Beam:
    """The beam of a sensor file: ``base`` changed by its ``"beam"`` object and any flat-layout keys (popped from ``spec``)."""
    changes = mapping(spec.pop("beam", {}), "beam", _BEAM_KEYS) if "beam" in spec else {}
    for old, new in LEGACY_BEAM_KEYS.items():
        if old in spec:
            if new in changes:
                raise InvalidInputError(f'{old} and beam.{new} give one field twice: keep the one in "beam"')
            changes[new] = spec.pop(old)
    if any(key in spec for key in _LEGACY_DETECTION):
        reflectivity, range_m = spec.pop("detection_reflectivity", 0.8), spec.pop("detection_range_m", 100.0)
        with located("detection_reflectivity / detection_range_m²"):
            if "detection_threshold" in changes:
                raise InvalidInputError(
                    "detection_reflectivity / detection_range_m and a detection_threshold give one field twice: keep one"
                )
            changes["detection_threshold"] = (real(reflectivity, "detection_reflectivity", low=0.0) / real(
                range_m, "detection_range_m", low=1e-3, high=MAX_RANGE_M) ** 2)  # fmt: skip
    return base.with_(**changes) if changes else base  # the beam's own errors say "beam: "


def sensor_to_json(sensor) -> dict:
    """A sensor's constructor fields as JSON-ready values with its ``"kind"`` (and its beam as a ``"beam"`` object):
    the file :func:`sensor_from_name` reads back as an equal sensor.

    Raises
    ------
    InvalidInputError
        Not a sensor of any kind.
    """
    kind = kind_of(sensor)
    spec: dict = {"kind": kind.name}
    for f in fields(sensor):
        if f.init:
            spec[f.name] = _json_value(getattr(sensor, f.name))
    return spec


def _json_value(value):
    """A field's value as JSON: tuples and arrays as lists, a beam as an object of its fields."""
    if isinstance(value, Beam):
        return {f.name: _json_value(getattr(value, f.name)) for f in fields(value) if f.init}
    if hasattr(value, "tolist"):
        return value.tolist()
    return list(value) if isinstance(value, tuple) else value
