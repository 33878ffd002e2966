"""Scenes for sensor scans: objects on a ground plane, occluders, and where the sensor stands.

World frame: right-handed, metres, z up; the ground is the plane ``z = ground_z_m``.
A scene is built in Python (:class:`ScanScene`, :class:`SceneObject`) or read from a JSON/YAML
file with the same fields (:func:`load_scene`)::

    {"ground": {"z_m": 0.0, "half_extent_m": 80.0},
     "objects": [{"mesh": "car.off", "class": "car", "position_m": [10, 0], "yaw_deg": 30,
                  "size_m": 4.5}],
     "occluders": [{"mesh": {"box_m": [0.5, 2.0, 1.0]}, "position_m": [6, 0.5]}],
     "sensor": {"height_m": 1.8}}

``mesh`` is a file path (relative paths are relative to the spec file), or a primitive:
``{"box_m": [x, y, z]}`` or ``{"cylinder": {"radius_m": r, "height_m": h}}``.  A mesh file is
normalised (:func:`zbuf_occlude.load_mesh`: centred, max extent 1) and scaled so that its
largest dimension is ``size_m``; a primitive keeps its metric size unless ``size_m`` is given.
Every object then stands on the ground (its lowest vertex at ``ground_z_m``), its bounding
box centred on ``position_m`` (x, y; a third value is added to the standing height), turned
by ``yaw_deg`` about +z.  Object ids: 0 is the ground, objects and occluders are numbered
from 1 in the order given (objects first).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError, MeshLoadError

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = ["SceneObject", "ScanScene", "BuiltScene", "load_scene", "GROUND_ID", "sensor_pose", "check_width_profile", "width_profile_factors"]

#: Key of a warped object's local mesh ``metadata``: ``(F,) int64``, each face's row in the mesh as loaded.
FACE_ROWS = "face_rows_as_loaded"
#: ``object_id`` of the ground plane's returns.
GROUND_ID = 0
#: Most sections of a scene cylinder.  At 4096 a facet spans 0.09°, finer than any preset's
#: angular step (0.1–0.4°), so more sections change no scan; the limit is checked before
#: trimesh allocates (1e8 sections would need tens of GB).
MAX_CYLINDER_SECTIONS = 4096
#: Largest ground half-extent, metres: the scene is ray-cast in float32 (Embree), whose 24-bit
#: mantissa keeps 1 mm steps up to 2**24 mm ≈ 16.8 km from the origin; a larger ground loses
#: the returns' millimetres (1e300 overflows float32 and returns nothing at all).
MAX_GROUND_HALF_EXTENT_M = 2.0**24 * 1e-3


def sensor_pose(position_m, yaw_deg: float = 0.0) -> NDArray[np.float64]:
    """(4, 4) float64 sensor → world transform: a translation and a turn about +z (degrees)."""
    p = np.asarray(position_m, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(p)) or not math.isfinite(yaw_deg):
        raise InvalidInputError(f"sensor position {position_m!r} and yaw {yaw_deg!r} must be finite")
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    m = np.eye(4)
    m[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    m[:3, 3] = p
    return m


def check_width_profile(profile) -> tuple[float, ...]:
    """``profile`` as a tuple of floats, checked: at least 2 finite factors > 0 (:class:`SceneObject` ``width_profile``).

    Raises
    ------
    InvalidInputError
        Anything else, naming the value.
    """
    try:
        out = tuple(float(v) for v in profile)
    except (TypeError, ValueError):
        out = ()
    if len(out) < 2 or not all(math.isfinite(v) and v > 0 for v in out):
        raise InvalidInputError(f"width_profile must be 2 or more factors > 0, one per relative-height bin, got {profile!r}")
    return out


def width_profile_factors(z: NDArray[np.floating], profile: tuple[float, ...]) -> NDArray[np.float64]:
    """The horizontal stretch of each height ``z (N,)`` under a width profile: ``(N,) float64``.

    ``profile`` holds ``K`` factors at the centres ``(k + 0.5) / K`` of ``K`` equal bins of the
    relative height ``(z − min z) / (max z − min z)``; the factor is linear between centres and
    constant beyond the outer ones (all ``profile[0]`` when ``z`` has no extent).
    """
    z = np.asarray(z, dtype=np.float64)
    extent = float(np.ptp(z)) if len(z) else 0.0
    if extent <= 0:
        return np.full(len(z), profile[0])
    k = len(profile)
    return np.interp((z - z.min()) / extent, (np.arange(k) + 0.5) / k, np.asarray(profile, dtype=np.float64))


def _split_tall_faces(v: NDArray[np.float64], faces: NDArray[np.int64], bins: int):
    """Bisect every edge that spans more than half a profile bin in height (``ptp(z) / (2 · bins)``),
    so that a warp by :func:`width_profile_factors` bends long walls too: a post's sides have
    vertices only at its ends.  Edges are measured with x and y squashed 1000x, so that only
    their height counts (a midpoint stays a midpoint under the squash).  Returns the new
    vertices ``(V', 3) float64``, faces ``(F', 3) int64`` and each new face's row in ``faces``."""
    import trimesh.remesh

    extent = float(np.ptp(v[:, 2]))
    if extent <= 0:
        return v.copy(), faces, np.arange(len(faces))
    squash = np.array([1e-3, 1e-3, 1.0])
    sv, sf, rows = trimesh.remesh.subdivide_to_size(v * squash, faces, extent / (2 * bins), max_iter=12, return_index=True)
    return sv / squash, np.asarray(sf, dtype=np.int64), np.asarray(rows, dtype=np.int64)


def _primitive_args(spec: dict) -> tuple[str, dict[str, Any]]:
    """The checked arguments of a primitive's trimesh constructor (before anything is allocated)."""
    if "box_m" in spec:
        extents = np.asarray(spec["box_m"], dtype=np.float64)
        if extents.shape != (3,) or np.any(~np.isfinite(extents)) or np.any(extents <= 0):
            raise InvalidInputError(f"box_m must be 3 positive sizes in metres, got {spec['box_m']!r}")
        return "box", {"extents": extents}
    if "cylinder" in spec:
        c = spec["cylinder"]
        r, h = float(c.get("radius_m", 0)), float(c.get("height_m", 0))
        if not (r > 0 and h > 0 and math.isfinite(r) and math.isfinite(h)):
            raise InvalidInputError(f"cylinder needs radius_m > 0 and height_m > 0, got {c!r}")
        sections = c.get("sections", 48)
        if isinstance(sections, bool) or not isinstance(sections, int) or not 3 <= sections <= MAX_CYLINDER_SECTIONS:
            raise InvalidInputError(f"cylinder sections must be an integer from 3 to {MAX_CYLINDER_SECTIONS}, got {sections!r}")
        return "cylinder", {"radius": r, "height": h, "sections": sections}
    raise InvalidInputError(f"unknown primitive {spec!r}; use {{'box_m': [x, y, z]}} or {{'cylinder': {{'radius_m': r, 'height_m': h}}}}")


def _primitive(spec: dict) -> trimesh.Trimesh:
    import trimesh

    kind, kwargs = _primitive_args(spec)
    return getattr(trimesh.creation, kind)(**kwargs)


@dataclass
class SceneObject:
    """One object of a scene.

    Parameters
    ----------
    mesh : str, Path, dict or trimesh.Trimesh
        Mesh file, primitive spec (module docstring) or a mesh in metres.
    class_name : str
    position_m : (2,) or (3,) float
        Bounding-box centre on the ground (x, y), metres; an optional z is added to the height
        at which the object stands.
    yaw_deg : float
        Turn about +z, degrees.
    size_m : float or (3,) float, optional
        Largest dimension after scaling, metres; or the three extents (x, y, z in the mesh's
        z-up frame, before the yaw), metres, for a non-uniform scale.  Default: a mesh file keeps its normalised
        size (max extent 1 m); a primitive or a given mesh keeps its own size in metres.
    up : {"z", "y"}
        The mesh's up axis; "y" meshes (glTF) are turned to z-up first.
    width_scale : float
        After the scaling to ``size_m``, stretch the object's horizontal axes (x and y) by this
        factor, > 0: a post made as thick as a tree trunk, keeping its height.  Default 1.
    width_profile : sequence of float, optional
        A horizontal stretch that varies with height: ``K >= 2`` factors > 0 at the centres of
        ``K`` equal bins of the mesh's relative height (0: its lowest vertex, 1: its top),
        linear in between and constant beyond the outer centres (:func:`width_profile_factors`).
        Each vertex's x and y move away from (or towards) the footprint centre by its factor,
        before the scaling to ``size_m`` (which still measures the mesh as loaded) and on top of
        ``width_scale``: a person's legs made as narrow as real scans show them, a sign pole's
        plate as narrow as a trunk.  The object's mesh (``build``'s local mesh) is the warped
        one, its faces cut where they span more than half a bin in height; its
        ``metadata[FACE_ROWS]`` gives each face's row as loaded, which the scene's
        ``face_local`` reports.  None (default): no warp.
    """

    mesh: Any
    class_name: str = ""
    position_m: tuple[float, ...] = (0.0, 0.0)
    yaw_deg: float = 0.0
    size_m: float | None = None
    up: str = "z"
    width_scale: float = 1.0
    width_profile: tuple[float, ...] | None = None

    def build(self, base: Path | None = None) -> tuple[trimesh.Trimesh, NDArray[np.float64]]:
        """The object's mesh in its local frame (as loaded, stretched by ``width_scale`` and warped
        by ``width_profile``: the object's own shape) and its (4, 4) local → world transform (the
        scaling to ``size_m``, the yaw and the position), with the ground at z = 0."""
        import trimesh

        from zbuf_occlude.mesh.load import load_mesh  # trimesh: imported when a scene is built

        if isinstance(self.mesh, trimesh.Trimesh):
            local = self.mesh
        elif isinstance(self.mesh, dict):
            local = _primitive(self.mesh)
        else:
            path = Path(self.mesh)
            if base is not None and not path.is_absolute():
                path = base / path
            local = load_mesh(path)
        vertices = np.asarray(local.vertices, dtype=np.float64)
        if self.up not in ("z", "y"):
            raise InvalidInputError(f"object {self.class_name or self.mesh!r}: up must be 'z' or 'y', got {self.up!r}")
        rot_up = np.eye(3) if self.up == "z" else np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
        size = self.size_m
        v = vertices @ rot_up.T
        if size is None:
            scale = np.ones(3)
        else:
            size_arr = np.asarray(size, dtype=np.float64).reshape(-1)
            if size_arr.shape not in ((1,), (3,)) or not np.all(np.isfinite(size_arr)) or np.any(size_arr <= 0):
                raise InvalidInputError(f"object {self.class_name or self.mesh!r}: size_m must be one or three sizes > 0 metres, got {size!r}")
            extents = np.ptp(v, axis=0)
            if len(size_arr) == 1:
                scale = np.full(3, size_arr[0] / extents.max())
            else:
                if np.any(extents <= 0):
                    raise InvalidInputError(f"object {self.class_name or self.mesh!r}: a flat mesh cannot take three extents {size!r}")
                scale = size_arr / extents
        if not (math.isfinite(self.width_scale) and self.width_scale > 0):
            raise InvalidInputError(f"object {self.class_name or self.mesh!r}: width_scale must be a number > 0, got {self.width_scale!r}")
        # The object's own shape, stretch and warp, is its local mesh; the transform only sizes, turns and places it.
        faces, rows = np.asarray(local.faces, dtype=np.int64), None
        if self.width_profile is not None:
            try:
                profile = check_width_profile(self.width_profile)
            except InvalidInputError as exc:
                raise InvalidInputError(f"object {self.class_name or self.mesh!r}: {exc}") from None
            v, faces, rows = _split_tall_faces(v, faces, len(profile))
            factors = width_profile_factors(v[:, 2], profile)
            centre_xy = (v[:, :2].min(axis=0) + v[:, :2].max(axis=0)) / 2
            v[:, :2] = centre_xy + (v[:, :2] - centre_xy) * factors[:, None]
        if self.width_scale != 1.0:
            v = v * np.array([self.width_scale, self.width_scale, 1.0])
        if self.width_profile is not None or self.width_scale != 1.0:
            local = trimesh.Trimesh(v @ rot_up, faces, process=False)  # rot_up is orthonormal: v @ rot_up undoes it
            if rows is not None:
                local.metadata[FACE_ROWS] = rows
        pos = np.asarray(self.position_m, dtype=np.float64).reshape(-1)
        if pos.shape not in ((2,), (3,)) or not np.all(np.isfinite(pos)):
            raise InvalidInputError(f"object {self.class_name or self.mesh!r}: position_m must be 2 or 3 finite metres, got {self.position_m!r}")
        c, s = math.cos(math.radians(self.yaw_deg)), math.sin(math.radians(self.yaw_deg))
        yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        lo, hi = v.min(axis=0) * scale, v.max(axis=0) * scale
        centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])  # footprint centre, bottom
        m = np.eye(4)
        m[:3, :3] = yaw @ (scale[:, None] * rot_up)
        m[:3, 3] = -(yaw @ centre) + np.array([pos[0], pos[1], pos[2] if len(pos) == 3 else 0.0])
        return local, m


@dataclass
class BuiltScene:
    """A scene flattened into one triangle mesh (world frame, metres).

    Attributes
    ----------
    mesh : trimesh.Trimesh
        All faces; ``process=False`` so the face order is as listed.
    face_object : (F,) int32
        Object id of each face (0: ground).
    face_local : (F,) int64
        Row of each face in its object's own mesh (as loaded; the ground: 0 or 1).
    objects : list[SceneObject]
        ``objects[i - 1]`` has id ``i``.
    local_to_world : list of (4, 4) float64
        Per object id (index 0: identity for the ground).
    """

    mesh: trimesh.Trimesh
    face_object: NDArray[np.int32]
    face_local: NDArray[np.int64]
    objects: list[SceneObject]
    local_to_world: list[NDArray[np.float64]]
    local_meshes: list[trimesh.Trimesh | None]

    def world_vertices(self, object_id: int) -> NDArray[np.float64]:
        """``(V, 3) float64``: the vertices of object ``object_id`` (>= 1) in the world frame, metres, as in :attr:`mesh`."""
        return _to_world(self.local_meshes[object_id].vertices, self.local_to_world[object_id])


def _to_world(vertices, local_to_world: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(V, 3)`` local vertices through a ``(4, 4)`` local-to-world transform."""
    return np.asarray(vertices, dtype=np.float64) @ local_to_world[:3, :3].T + local_to_world[:3, 3]


@dataclass
class ScanScene:
    """Objects on a ground plane (module docstring).

    Parameters
    ----------
    objects : list of SceneObject
        The targets (crops are made of these).
    occluders : list of SceneObject
        Other objects; they occlude and return points like any object.
    ground : bool
        Add the ground plane ``z = ground_z_m``, a square of side ``2 · ground_half_extent_m``
        centred on the origin.
    sensor_height_m : float, optional
        Height of the sensor above the ground, for :meth:`default_sensor_pose`.
    sensor_position_m : (2,) float
        Sensor (x, y), metres; default the origin.
    """

    objects: list[SceneObject] = field(default_factory=list)
    occluders: list[SceneObject] = field(default_factory=list)
    ground: bool = True
    ground_z_m: float = 0.0
    ground_half_extent_m: float = 80.0
    sensor_height_m: float = 1.8
    sensor_position_m: tuple[float, float] = (0.0, 0.0)
    base_dir: Path | None = None
    _built: BuiltScene | None = field(default=None, init=False, repr=False, compare=False)
    # each object's build, by identity (kept with it), so that a scene built again after an add builds only what is new
    _object_builds: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        h = self.ground_half_extent_m
        if not (isinstance(h, (int, float)) and 0 < h <= MAX_GROUND_HALF_EXTENT_M):
            raise InvalidInputError(
                f"ground half_extent_m must be > 0 and <= {MAX_GROUND_HALF_EXTENT_M:.0f} metres (float32 ray casting), got {h!r}"
            )
        z = self.sensor_height_m
        # the same rule as the farm's --sensor-height and CropDistributions.height_m
        if not (isinstance(z, (int, float)) and math.isfinite(z) and z >= 0):
            raise InvalidInputError(f"sensor height_m must be >= 0 metres (above the ground), got {z!r}")

    def add(self, mesh, **kwargs) -> ScanScene:
        """Append a target object (``SceneObject(mesh, **kwargs)``); returns self for chaining."""
        self.objects.append(SceneObject(mesh, **kwargs))
        self._built = None
        return self

    def add_occluder(self, mesh, **kwargs) -> ScanScene:
        """Append an occluder (``SceneObject(mesh, **kwargs)``, or ``mesh`` itself when it is a
        :class:`SceneObject` and no keyword is given); returns self."""
        self.occluders.append(mesh if isinstance(mesh, SceneObject) and not kwargs else SceneObject(mesh, **kwargs))
        self._built = None
        return self

    def default_sensor_pose(self) -> NDArray[np.float64]:
        """(4, 4) sensor → world: at ``sensor_position_m``, ``sensor_height_m`` above the ground, yaw 0."""
        x, y = (float(v) for v in self.sensor_position_m)
        return sensor_pose([x, y, self.ground_z_m + float(self.sensor_height_m)])

    def _object_build(self, obj: SceneObject) -> tuple[trimesh.Trimesh, NDArray[np.float64]]:
        """``obj.build(self.base_dir)``, once per object of this scene."""
        hit = self._object_builds.get(id(obj))
        if hit is None or hit[0] is not obj:
            hit = self._object_builds[id(obj)] = (obj, *obj.build(self.base_dir))
        return hit[1], hit[2]

    def build(self) -> BuiltScene:
        """Flatten into one mesh (cached until :meth:`add` or :meth:`add_occluder`; each object's
        own build is kept, so only the objects added since are built again)."""
        import trimesh

        if self._built is not None:
            return self._built
        vertices, faces, face_object, face_local = [], [], [], []
        transforms: list[NDArray[np.float64]] = [np.eye(4)]
        locals_: list[trimesh.Trimesh | None] = [None]
        n_vertices = 0
        if self.ground:
            h = float(self.ground_half_extent_m)
            if not (math.isfinite(h) and h > 0):
                raise InvalidInputError(f"ground_half_extent_m must be > 0 metres, got {self.ground_half_extent_m!r}")
            g = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]]) + [0.0, 0.0, self.ground_z_m]
            vertices.append(g)
            faces.append(np.array([[0, 1, 2], [0, 2, 3]]))
            face_object.append(np.zeros(2, np.int32))
            face_local.append(np.arange(2))
            n_vertices = 4
        for oid, obj in enumerate([*self.objects, *self.occluders], start=1):
            local, m = self._object_build(obj)
            m = m.copy()
            m[2, 3] += self.ground_z_m
            v = _to_world(local.vertices, m)
            f = np.asarray(local.faces, dtype=np.int64)
            vertices.append(v)
            faces.append(f + n_vertices)
            face_object.append(np.full(len(f), oid, np.int32))
            face_local.append(local.metadata.get(FACE_ROWS, np.arange(len(f))))
            transforms.append(m)
            locals_.append(local)
            n_vertices += len(v)
        if not faces:
            raise InvalidInputError("the scene is empty: no ground and no objects")
        mesh = trimesh.Trimesh(np.concatenate(vertices), np.concatenate(faces), process=False, validate=False)
        self._built = BuiltScene(
            mesh, np.concatenate(face_object), np.concatenate(face_local).astype(np.int64),
            [*self.objects, *self.occluders], transforms, locals_,
        )  # fmt: skip
        return self._built

    # -- files ---------------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, spec: dict, base_dir: Path | None = None) -> ScanScene:
        """A scene from the JSON/YAML structure of the module docstring.

        Raises
        ------
        InvalidInputError
            Unknown keys or bad values (the message names them).
        """
        if not isinstance(spec, dict):
            raise InvalidInputError(f"a scene spec must be a mapping, got {type(spec).__name__}")
        unknown = set(spec) - {"ground", "objects", "occluders", "sensor"}
        if unknown:
            raise InvalidInputError(f"unknown scene keys {sorted(unknown)}; use ground, objects, occluders, sensor")

        def obj(d: dict) -> SceneObject:
            allowed = {"mesh", "class", "position_m", "yaw_deg", "size_m", "up"}
            if not isinstance(d, dict) or "mesh" not in d or set(d) - allowed:
                raise InvalidInputError(f"scene object {d!r}: needs 'mesh', allows {sorted(allowed)}")
            if isinstance(d["mesh"], dict):
                _primitive_args(d["mesh"])  # checked now, so that the error names the file
            return SceneObject(d["mesh"], d.get("class", ""), tuple(d.get("position_m", (0.0, 0.0))), float(d.get("yaw_deg", 0.0)), d.get("size_m"), d.get("up", "z"))

        ground = spec.get("ground", {})
        sensor = spec.get("sensor", {})
        return cls(
            objects=[obj(d) for d in spec.get("objects", [])],
            occluders=[obj(d) for d in spec.get("occluders", [])],
            ground=ground is not False and ground is not None,
            ground_z_m=float((ground or {}).get("z_m", 0.0)) if isinstance(ground, dict) else 0.0,
            ground_half_extent_m=float(ground.get("half_extent_m", 80.0)) if isinstance(ground, dict) else 80.0,
            sensor_height_m=float(sensor.get("height_m", 1.8)),
            sensor_position_m=tuple(sensor.get("position_m", (0.0, 0.0))),
            base_dir=base_dir,
        )


def load_scene(path: str | Path) -> ScanScene:
    """Read a scene spec from ``.json``, ``.yaml`` or ``.yml`` (module docstring).

    Raises
    ------
    InvalidInputError
        Missing or unparsable file, unknown format, bad fields.
    """
    path = Path(path)
    if not path.is_file():
        raise InvalidInputError(f"{path}: no such scene file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise InvalidInputError(f"{path}: a scene file must be UTF-8 text ({exc.reason} at byte {exc.start})") from None
    try:  # json and PyYAML parse nested containers recursively: a crafted file exhausts the stack
        suffix = path.suffix.lower()
        if suffix == ".json":
            try:
                spec = json.loads(text)
            except ValueError as exc:
                raise InvalidInputError(f"{path}: cannot parse scene JSON ({exc})") from exc
        elif suffix in (".yaml", ".yml"):
            try:
                import yaml
            except ImportError:
                raise InvalidInputError(f"{path}: YAML scenes need PyYAML: pip install 'zbuf-occlude[yaml]'") from None
            try:
                spec = yaml.safe_load(text)
            except yaml.YAMLError as exc:
                raise InvalidInputError(f"{path}: cannot parse scene YAML ({exc})") from exc
        else:
            raise InvalidInputError(f"{path}: unknown scene format {path.suffix!r}; use .json, .yaml or .yml")
    except RecursionError:  # json and PyYAML parse nested containers recursively
        raise InvalidInputError(f"{path}: the scene is nested too deeply to be a scene (a crafted file?)") from None
    try:
        return ScanScene.from_dict(spec, base_dir=path.parent)
    except RecursionError:
        raise InvalidInputError(f"{path}: the scene is nested too deeply to be a scene (a crafted file?)") from None
    except MeshLoadError:
        raise
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InvalidInputError):
            raise InvalidInputError(f"{path}: {exc}") from exc
        raise InvalidInputError(f"{path}: bad scene field ({exc})") from exc
