"""One lookup of every sensor: a preset name (spinning LiDAR, airborne scanner, depth camera) or a JSON file."""

from __future__ import annotations

import json
from pathlib import Path

from zbuf_occlude.errors import InvalidInputError

__all__ = ["sensor_from_name"]


def sensor_from_name(name: str):
    """A :class:`Lidar`, :class:`DepthCamera` or airborne-scanner preset, or a sensor from a JSON file of its fields.

    An airborne file (``"kind": "airborne"``) holds the fields of
    :class:`~zbuf_occlude.sensors.airborne.AirborneScanner`, flight plan included (``n_lines``,
    ``side_overlap``, ``headings_deg``), or ``"preset": NAME`` and the fields it changes.

    Raises
    ------
    InvalidInputError
        An unknown name, or a file whose fields are wrong (naming the file).
    """
    from zbuf_occlude.sensors.airborne import AIRBORNE_PRESETS, AirborneScanner, airborne_preset
    from zbuf_occlude.sensors.depth_camera import DEPTH_CAMERA_PRESETS, DepthCamera
    from zbuf_occlude.sensors.lidar import LIDAR_PRESETS, Lidar

    key = name.lower()
    if key in LIDAR_PRESETS:
        return LIDAR_PRESETS[key]
    if key in AIRBORNE_PRESETS:
        return AIRBORNE_PRESETS[key]
    if key in DEPTH_CAMERA_PRESETS:
        return DEPTH_CAMERA_PRESETS[key]
    path = Path(name)
    if path.suffix.lower() == ".json" and path.is_file():
        try:
            spec = json.loads(path.read_text(encoding="utf-8"))
            if not isinstance(spec, dict):
                raise TypeError("expected a JSON object of the sensor's fields")
            spec.pop("fit", None)  # a fitted sensor's estimates (zbuf_occlude.sensors.fit): metadata
            kind = spec.pop("kind", "lidar")
            if kind == "airborne" and "preset" in spec:
                return airborne_preset(spec.pop("preset")).with_(**spec)
            return {"lidar": Lidar, "airborne": AirborneScanner}.get(kind, DepthCamera)(**spec)
        except (ValueError, TypeError) as exc:
            raise InvalidInputError(f"{path}: bad sensor file ({exc})") from exc
    raise InvalidInputError(f"unknown sensor {name!r}; use one of {sorted(LIDAR_PRESETS) + sorted(AIRBORNE_PRESETS) + sorted(DEPTH_CAMERA_PRESETS)} or a .json file")
