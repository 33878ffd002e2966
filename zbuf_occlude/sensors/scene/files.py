"""Scene files: a :class:`~zbuf_occlude.sensors.scene.objects.ScanScene` read from JSON or YAML.

The format is in :mod:`zbuf_occlude.sensors.scene.objects`'s docstring; its keys are :data:`SCENE_KEYS`,
:data:`GROUND_KEYS`, :data:`SENSOR_KEYS` and :data:`OBJECT_KEYS` (a primitive's:
:data:`~zbuf_occlude.sensors.scene.object_shapes.PRIMITIVE_KEYS`).

A scene file may come from anyone.  It is read by :func:`~zbuf_occlude.io.spec_files.read_spec_file`
(size and nesting bounded, no YAML aliases), every field is checked where the dataclass is
made (:mod:`zbuf_occlude.sensors.checks`: numbers finite and in range, types, unknown keys),
a mesh file it names must lie inside the scene file's folder (relative, no ``..``, symlinks
resolved: :func:`zbuf_occlude.io.safe_paths.path_inside`), and it holds at most
:data:`~zbuf_occlude.sensors.checks.MAX_SCENE_OBJECTS` objects.  Every error is one line that
names the file and the field (``street.yaml: objects[2]: yaw_deg must be a finite number, got NaN``), never a
value of the file (:func:`~zbuf_occlude.sensors.checks.value_kind`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.checks import MAX_SCENE_OBJECTS, located, mapping, value_kind
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject

__all__ = ["load_scene", "scene_from_dict", "SCENE_KEYS", "GROUND_KEYS", "SENSOR_KEYS", "OBJECT_KEYS"]

#: Keys of a scene file, of its ``ground``, ``sensor`` and objects.
SCENE_KEYS = ("ground", "objects", "occluders", "sensor")
GROUND_KEYS = ("z_m", "half_extent_m")
SENSOR_KEYS = ("height_m", "position_m")
OBJECT_KEYS = ("mesh", "class", "position_m", "yaw_deg", "size_m", "up", "foliage")


def scene_from_dict(spec: Mapping, base_dir: Path | None = None) -> ScanScene:
    """A scene from the JSON/YAML structure of :mod:`zbuf_occlude.sensors.scene.objects`'s docstring.

    Parameters
    ----------
    spec : mapping
    base_dir : Path, optional
        The scene file's folder: a mesh path must be relative and lie inside it (symlinks
        resolved).  None: paths as given (a scene built in Python).

    Raises
    ------
    InvalidInputError
        Unknown keys or bad values, more than :data:`~zbuf_occlude.sensors.checks.MAX_SCENE_OBJECTS`
        objects (the message names the field: ``objects[2]: yaw_deg ...``); :class:`~zbuf_occlude.errors.UnsafePathError`
        for a mesh path that leaves ``base_dir``.
    """
    from zbuf_occlude.io.safe_paths import path_inside

    spec = mapping(spec, "scene", SCENE_KEYS)
    lists = {}
    for key in ("objects", "occluders"):
        items = spec.get(key)
        if items is not None and not isinstance(items, list):
            raise InvalidInputError(f"{key} must be a list of objects, got {value_kind(items)}")
        lists[key] = items or []
    if len(lists["objects"]) + len(lists["occluders"]) > MAX_SCENE_OBJECTS:
        raise InvalidInputError(
            f"the scene holds {len(lists['objects']) + len(lists['occluders']):,} objects and occluders, more than {MAX_SCENE_OBJECTS:,}"
        )

    def obj(d: object, where: str) -> SceneObject:
        with located(where):
            d = mapping(d, "object", OBJECT_KEYS, required=("mesh",))
            made = SceneObject(
                d["mesh"],
                d.get("class", ""),
                d.get("position_m", (0.0, 0.0)),
                d.get("yaw_deg", 0.0),
                d.get("size_m"),
                d.get("up", "z"),
                foliage=d.get("foliage"),
            )
            if base_dir is not None and isinstance(made.mesh, str):  # a file named by a scene file stays in its folder
                path_inside(base_dir, made.mesh, what="mesh", quoted=False)
        return made

    ground = spec.get("ground", {})
    if ground is None or isinstance(ground, bool):
        ground, has_ground = {}, bool(ground)
    else:
        ground, has_ground = mapping(ground, "ground", GROUND_KEYS), True
    sensor = mapping(spec.get("sensor", {}), "sensor", SENSOR_KEYS)
    if not (has_ground or lists["objects"] or lists["occluders"]):
        raise InvalidInputError("the scene is empty: no ground and no objects")
    return ScanScene(
        objects=[obj(d, f"objects[{i}]") for i, d in enumerate(lists["objects"])],
        occluders=[obj(d, f"occluders[{i}]") for i, d in enumerate(lists["occluders"])],
        ground=has_ground,
        ground_z_m=ground.get("z_m", 0.0),
        ground_half_extent_m=ground.get("half_extent_m", 80.0),
        sensor_height_m=sensor.get("height_m", 1.8),
        sensor_position_m=sensor.get("position_m", (0.0, 0.0)),
        base_dir=base_dir,
    )


def load_scene(path: str | Path) -> ScanScene:
    """Read a scene spec from ``.json``, ``.yaml`` or ``.yml`` (:mod:`zbuf_occlude.sensors.scene.objects`'s docstring).

    The file is read by :func:`~zbuf_occlude.io.spec_files.read_spec_file` (a regular
    file of at most :data:`~zbuf_occlude.io.caps.MAX_SPEC_FILE_BYTES`, nested at
    most 64 levels, no YAML aliases), then :func:`scene_from_dict` with the file's folder.

    Raises
    ------
    InvalidInputError
        Missing or unparsable file, unknown format, bad fields (the message names the file and
        the field); :class:`~zbuf_occlude.errors.UnsafePathError` for a mesh path outside the
        file's folder.
    """
    from zbuf_occlude.io.spec_files import read_spec_file

    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"{path}: no such scene file")
    spec = read_spec_file(path, what="scene")
    with located(str(path)):
        return scene_from_dict(spec, base_dir=path.parent)
