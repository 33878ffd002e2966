"""One lookup of every sensor: a preset name (spinning LiDAR, airborne scanner, depth camera) or a JSON file."""

from __future__ import annotations

import os
from dataclasses import fields
from pathlib import Path

from zbuf_occlude.errors import InvalidInputError

__all__ = ["SENSOR_KINDS", "preset_names", "sensor_from_name", "sensor_to_json"]

#: ``"kind"`` of a sensor file, and the class it makes (``"lidar"`` when the file has none).
SENSOR_KINDS = ("lidar", "airborne", "depth_camera")


def preset_names() -> dict[str, tuple[str, ...]]:
    """Every preset name, sorted, by kind (the keys of :data:`SENSOR_KINDS`, in that order): the names
    :func:`sensor_from_name` takes, for help texts and messages."""
    from zbuf_occlude.sensors.airborne import AIRBORNE_PRESETS
    from zbuf_occlude.sensors.depth_camera import DEPTH_CAMERA_PRESETS
    from zbuf_occlude.sensors.lidar import LIDAR_PRESETS

    return dict(zip(SENSOR_KINDS, (tuple(sorted(p)) for p in (LIDAR_PRESETS, AIRBORNE_PRESETS, DEPTH_CAMERA_PRESETS)), strict=True))


def sensor_from_name(name: str | os.PathLike):
    """A :class:`Lidar`, :class:`DepthCamera` or airborne-scanner preset, or a sensor from a JSON file of its fields.

    A sensor file is a JSON object: ``"kind"`` (one of :data:`SENSOR_KINDS`, default
    ``"lidar"``) and the constructor fields of that class (an optional ``"fit"`` block, as
    :func:`~zbuf_occlude.sensors.fit.fit_lidar` writes, is metadata).  An airborne file
    (``"kind": "airborne"``) holds the fields of
    :class:`~zbuf_occlude.sensors.airborne.AirborneScanner`, flight plan included (``n_lines``,
    ``side_overlap``, ``headings_deg``), or ``"preset": NAME`` and the fields it changes.  The
    file is read by :func:`~zbuf_occlude.sensors.spec_files.read_spec_file` (size and nesting
    bounded) and every field is checked by the class (:mod:`zbuf_occlude.sensors.checks`).

    Raises
    ------
    InvalidInputError
        An unknown name, a ``.json`` file that does not exist, or a file that is not JSON, nests too deep, has an unknown kind or
        key, or a field of the wrong type or range (the message names the file and the field).
    """
    from zbuf_occlude.sensors.airborne import AIRBORNE_PRESETS, AirborneScanner, airborne_preset
    from zbuf_occlude.sensors.checks import located, mapping, shown, text
    from zbuf_occlude.sensors.depth_camera import DEPTH_CAMERA_PRESETS, DepthCamera
    from zbuf_occlude.sensors.lidar import LIDAR_PRESETS, Lidar
    from zbuf_occlude.sensors.spec_files import read_spec_file

    if not isinstance(name, (str, os.PathLike)):
        raise InvalidInputError(f"a sensor must be a preset name or a .json file, got {type(name).__name__} {shown(name)}")
    name = os.fspath(name)
    key = name.lower()
    if key in LIDAR_PRESETS:
        return LIDAR_PRESETS[key]
    if key in AIRBORNE_PRESETS:
        return AIRBORNE_PRESETS[key]
    if key in DEPTH_CAMERA_PRESETS:
        return DEPTH_CAMERA_PRESETS[key]
    path = Path(name)
    if path.suffix.lower() == ".json" and path.is_file():
        spec = read_spec_file(path, what="sensor", yaml_ok=False)
        with located(str(path)):
            if not isinstance(spec, dict):
                raise InvalidInputError(
                    f"a sensor file must be a JSON object of the sensor's fields, got {type(spec).__name__} {shown(spec)}"
                )
            kind = text(spec.get("kind", "lidar"), "kind", choices=SENSOR_KINDS)
            cls = {"lidar": Lidar, "airborne": AirborneScanner, "depth_camera": DepthCamera}[kind]
            extra = ("kind", "fit", "preset") if kind == "airborne" else ("kind", "fit")
            spec = mapping(spec, kind, (*extra, *(f.name for f in fields(cls) if f.init)))
            for key in ("kind", "fit"):  # fit: a fitted sensor's estimates (zbuf_occlude.sensors.fit), metadata
                spec.pop(key, None)
            if "preset" in spec:
                return airborne_preset(text(spec.pop("preset"), "preset")).with_(**spec)
            return cls(**_complete(spec, cls))
    if path.suffix.lower() == ".json":
        raise InvalidInputError(f"sensor file {path}: no such file (fit-sensor writes one; or name a preset)")
    raise InvalidInputError(
        f"unknown sensor {shown(name)}; use one of {[n for names in preset_names().values() for n in names]} or a .json file"
    )


def sensor_to_json(sensor) -> dict:
    """A sensor's constructor fields as JSON-ready values with its ``"kind"``: the file
    :func:`sensor_from_name` reads back as an equal sensor.

    Raises
    ------
    InvalidInputError
        Not a :class:`Lidar`, :class:`AirborneScanner` or :class:`DepthCamera`.
    """
    from zbuf_occlude.sensors.airborne import AirborneScanner
    from zbuf_occlude.sensors.depth_camera import DepthCamera
    from zbuf_occlude.sensors.lidar import Lidar

    kinds = {Lidar: "lidar", AirborneScanner: "airborne", DepthCamera: "depth_camera"}
    if type(sensor) not in kinds:
        raise InvalidInputError(f"not a sensor: {type(sensor).__name__}")
    spec: dict = {"kind": kinds[type(sensor)]}
    for f in fields(sensor):
        if f.init:
            v = getattr(sensor, f.name)
            spec[f.name] = list(v) if isinstance(v, tuple) else v
    return spec


def _complete(spec: dict, cls: type) -> dict:
    """``spec`` if it gives every field ``cls`` requires (a missing one is named, not a TypeError)."""
    from dataclasses import MISSING

    missing = [f.name for f in fields(cls) if f.init and f.default is MISSING and f.default_factory is MISSING and f.name not in spec]
    if missing:
        raise InvalidInputError(f"a {cls.__name__} needs {', '.join(missing)}")
    return spec
