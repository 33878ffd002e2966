"""Scenes for sensor scans: objects on a ground plane, occluders, and where the sensor stands.

World frame: right-handed, metres, z up; the ground is the plane ``z = ground_z_m``.
A scene is built in Python (:class:`ScanScene`, :class:`SceneObject`) or read from a JSON/YAML
file with the same fields (:func:`~zbuf_occlude.sensors.scene.files.load_scene`)::

    {"ground": {"z_m": 0.0, "half_extent_m": 80.0},
     "objects": [{"mesh": "car.off", "class": "car", "position_m": [10, 0], "yaw_deg": 30,
                  "size_m": 4.5}],
     "occluders": [{"mesh": {"box_m": [0.5, 2.0, 1.0]}, "position_m": [6, 0.5]}],
     "sensor": {"height_m": 1.8}}

``mesh`` is a file path (relative to the spec file, inside its folder), or a primitive:
``{"box_m": [x, y, z]}`` or ``{"cylinder": {"radius_m": r, "height_m": h}}``.  A mesh file is
normalised (:func:`zbuf_occlude.load_mesh`: centred, max extent 1) and scaled so that its
largest dimension is ``size_m``; a primitive keeps its metric size unless ``size_m`` is given.
Every object then stands on the ground (its lowest vertex at ``ground_z_m``), its bounding
box centred on ``position_m`` (x, y; a third value is added to the standing height), turned
by ``yaw_deg`` about +z.  Object ids: 0 is the ground, objects and occluders are numbered
from 1 in the order given (objects first).  ``"foliage": {"leaf_area_density": 1.0}`` (also
``leaf_side_m``, ``shell_m``, ``keep_surface``, ``seed``) fills the object's crown with leaves
at its size in metres (:class:`~zbuf_occlude.sensors.scene.foliage.Foliage`).

Every field is checked where the dataclass is made (:mod:`zbuf_occlude.sensors.checks`: numbers
finite and in range, types, unknown keys).  Primitives and width profiles are in
:mod:`~zbuf_occlude.sensors.scene.object_shapes`; a scene file, which may come from anyone, is read by
:mod:`~zbuf_occlude.sensors.scene.files`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.limits import MAX_MESH_FACES
from zbuf_occlude.mesh.scene import FACE_MATERIALS, FaceMaterials, face_materials_of
from zbuf_occlude.sensors.checks import MAX_COORDINATE_M, MAX_PATH_CHARS, is_number, located, real, reals, text, value_kind
from zbuf_occlude.sensors.scene.foliage import LEAF_MATERIAL, MAX_LEAVES, Foliage
from zbuf_occlude.sensors.scene.object_shapes import (
    FACE_ROWS,
    check_width_profile,
    is_trimesh,
    primitive_args,
    primitive_mesh,
    warp_to_width_profile,
)

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = [
    "SceneObject",
    "ScanScene",
    "BuiltScene",
    "GROUND_ID",
    "sensor_pose",
]

#: ``object_id`` of the ground plane's returns.
GROUND_ID = 0
#: Largest ground half-extent, metres: the scene is ray-cast in float32 (Embree), whose 24-bit
#: mantissa keeps 1 mm steps up to 2**24 mm ≈ 16.8 km from the origin; a larger ground loses
#: the returns' millimetres (1e300 overflows float32 and returns nothing at all).  Object
#: positions, sizes and the sensor's place are bounded by the same figure.
MAX_GROUND_HALF_EXTENT_M = MAX_COORDINATE_M


def sensor_pose(position_m, yaw_deg: float = 0.0) -> NDArray[np.float64]:
    """(4, 4) float64 sensor → world transform: a translation and a turn about +z (degrees)."""
    p = np.asarray(position_m, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(p)) or not math.isfinite(yaw_deg):
        raise InvalidInputError("sensor position and yaw must be finite")
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    m = np.eye(4)
    m[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    m[:3, 3] = p
    return m


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
        linear in between and constant beyond the outer centres
        (:func:`~zbuf_occlude.sensors.scene.object_shapes.width_profile_factors`).
        Each vertex's x and y move away from (or towards) the footprint centre by its factor,
        before the scaling to ``size_m`` (which still measures the mesh as loaded) and on top of
        ``width_scale``: a person's legs made as narrow as real scans show them, a sign pole's
        plate as narrow as a trunk.  The object's mesh (``build``'s local mesh) is the warped
        one, its faces cut where they span more than half a bin in height; its
        ``metadata[FACE_ROWS]`` gives each face's row as loaded, which the scene's
        ``face_local`` reports.  None (default): no warp.
    foliage : Foliage or mapping, optional
        Leaves filling the crown (:class:`~zbuf_occlude.sensors.scene.foliage.Foliage`, or a mapping of
        its fields: a scene file's ``foliage``), grown on the object at its size in metres
        (:func:`~zbuf_occlude.sensors.scene.foliage.add_foliage`, after ``width_scale`` and
        ``width_profile``): square leaves in metres whatever the scaling.  The leaves' faces follow
        the mesh's, their rows in ``face_local`` counted on from the mesh's face count as loaded,
        their material ``"grown_leaf"`` (foliage's reflectance, opaque: the gaps are between the
        leaves).  The object is sized and placed by its mesh alone.  None (default): no leaves.

    Raises
    ------
    InvalidInputError
        Naming the field: a ``mesh`` that is none of the above (or a primitive with a bad
        field), a ``position_m`` or ``size_m`` that is not 2–3 (1 or 3) finite numbers within
        :data:`MAX_GROUND_HALF_EXTENT_M` metres (sizes > 0), a non-finite ``yaw_deg``, ``up``
        not "z" or "y", ``width_scale`` not > 0, a bad ``width_profile``
        (:func:`~zbuf_occlude.sensors.scene.object_shapes.check_width_profile`), a bad ``foliage``
        (:class:`~zbuf_occlude.sensors.scene.foliage.Foliage`; at build: more than
        :data:`~zbuf_occlude.sensors.scene.foliage.MAX_LEAVES` leaves, a mesh without volume).
    """

    mesh: Any
    class_name: str = ""
    position_m: tuple[float, ...] = (0.0, 0.0)
    yaw_deg: float = 0.0
    size_m: float | None = None
    up: str = "z"
    width_scale: float = 1.0
    width_profile: tuple[float, ...] | None = None
    foliage: Foliage | Mapping | None = None

    def __post_init__(self) -> None:
        self._check()

    def _check(self) -> None:
        """Check every field and normalise the numbers to floats (the one place of these rules;
        :meth:`build` checks again, as fields may be changed after construction).

        Raises
        ------
        InvalidInputError
            The message starts with the field's name (``yaw_deg must be a finite number, got NaN``).
        """
        mesh = self.mesh
        if isinstance(mesh, (str, os.PathLike)):
            name = os.fspath(mesh)
            try:
                ok = isinstance(name, str) and 0 < len(name) <= MAX_PATH_CHARS and "\0" not in name and bool(os.fsencode(name))
            except UnicodeError:  # a lone surrogate ("\ud800", which JSON's \u escapes can write) names no file
                ok = False
            if not ok:
                raise InvalidInputError(
                    f"mesh must be a file path of 1 to {MAX_PATH_CHARS} characters, without NUL or lone surrogates, got {value_kind(mesh)}"
                )
        elif isinstance(mesh, Mapping):
            primitive_args(mesh)  # checked before anything is allocated
        elif not is_trimesh(mesh):
            raise InvalidInputError(
                "mesh must be a mesh file path, a primitive {'box_m': [x, y, z]} or {'cylinder': {'radius_m': r, 'height_m': h}}, "
                f"or a trimesh.Trimesh, got {value_kind(mesh)}"
            )
        text(self.class_name, "class_name")
        where = {"low": -MAX_COORDINATE_M, "high": MAX_COORDINATE_M}
        self.position_m = reals(self.position_m, "position_m", lengths=(2, 3), expected="2 or 3 numbers (x, y[, z]) in metres", **where)
        self.yaw_deg = real(self.yaw_deg, "yaw_deg")
        if self.size_m is not None:
            size = {"low": 0.0, "low_open": True, "high": MAX_COORDINATE_M}
            if is_number(self.size_m):
                self.size_m = real(self.size_m, "size_m", **size)
            else:
                sizes = reals(self.size_m, "size_m", lengths=(1, 3), expected="one size or 3 extents (x, y, z) in metres", **size)
                self.size_m = sizes[0] if len(sizes) == 1 else sizes
        text(self.up, "up", choices=("z", "y"))
        self.width_scale = real(self.width_scale, "width_scale", low=0.0, low_open=True)
        if self.width_profile is not None:
            self.width_profile = check_width_profile(self.width_profile)
        if self.foliage is not None:
            with located("foliage"):
                self.foliage = Foliage.of(self.foliage)

    def build(self, base: Path | None = None, *, max_faces: int = MAX_MESH_FACES) -> tuple[trimesh.Trimesh, NDArray[np.float64]]:
        """The object's mesh in its local frame (as loaded, stretched by ``width_scale``, warped by
        ``width_profile``, with ``foliage``'s leaves: the object's own shape) and its (4, 4) local →
        world transform (the scaling to ``size_m``, the yaw and the position), with the ground at z = 0.

        ``max_faces`` bounds the faces the leaves may bring the mesh to (what a scene's triangle
        cap leaves for it), checked before any leaf is drawn.

        Raises
        ------
        InvalidInputError
            A field that is wrong (:meth:`_check`), three extents for a flat mesh.
        MeshLoadError
            The mesh file cannot be loaded.
        """
        import trimesh

        from zbuf_occlude.mesh.load import load_mesh  # trimesh: imported when a scene is built

        self._check()
        if isinstance(self.mesh, trimesh.Trimesh):
            local = self.mesh
        elif isinstance(self.mesh, Mapping):
            local = primitive_mesh(self.mesh)
        else:
            path = Path(self.mesh)
            if base is not None and not path.is_absolute():
                path = base / path
            local = load_mesh(path)
        vertices = np.asarray(local.vertices, dtype=np.float64)
        rot_up = np.eye(3) if self.up == "z" else np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
        size = self.size_m
        v = vertices @ rot_up.T
        if size is None:
            scale = np.ones(3)
        else:
            size_arr = np.asarray(size, dtype=np.float64).reshape(-1)
            extents = np.ptp(v, axis=0)
            if len(size_arr) == 1:
                scale = np.full(3, size_arr[0] / extents.max())
            else:
                if np.any(extents <= 0):
                    raise InvalidInputError("size_m: a flat mesh cannot take three extents; give one size")
                scale = size_arr / extents
        # The object's own shape, stretch and warp, is its local mesh; the transform only sizes, turns and places it.
        faces, rows = np.asarray(local.faces, dtype=np.int64), None
        if self.width_profile is not None:
            v, faces, rows = warp_to_width_profile(v, faces, self.width_profile)
        if self.width_scale != 1.0:
            v = v * np.array([self.width_scale, self.width_scale, 1.0])
        lo, hi = v.min(axis=0) * scale, v.max(axis=0) * scale  # the mesh's own box: leaves at its edge do not move it
        if self.width_profile is not None or self.width_scale != 1.0 or self.foliage is not None:
            materials = face_materials_of(local)
            if materials is not None and rows is not None:  # each face keeps its file's material, a split face its parent's
                materials = materials.select(rows)
            if self.foliage is not None:
                with located("foliage"):
                    v, faces, rows, materials = _with_leaves(self.foliage, v, faces, scale, rows, len(local.faces), materials, max_faces)
            local = trimesh.Trimesh(v @ rot_up, faces, process=False)  # rot_up is orthonormal: v @ rot_up undoes it
            if rows is not None:
                local.metadata[FACE_ROWS] = rows
            if materials is not None:
                local.metadata[FACE_MATERIALS] = materials
        pos = self.position_m
        c, s = math.cos(math.radians(self.yaw_deg)), math.sin(math.radians(self.yaw_deg))
        yaw = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])  # footprint centre, bottom
        m = np.eye(4)
        m[:3, :3] = yaw @ (scale[:, None] * rot_up)
        m[:3, 3] = -(yaw @ centre) + np.array([pos[0], pos[1], pos[2] if len(pos) == 3 else 0.0])
        return local, m


def _with_leaves(foliage: Foliage, v: NDArray[np.float64], faces: NDArray[np.int64], scale: NDArray[np.float64], rows: NDArray[np.int64] | None,
                 loaded_faces: int, materials: FaceMaterials | None, max_faces: int) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64], FaceMaterials]:  # fmt: skip
    """The object's vertices (z-up, unscaled) and faces (the mesh's none without ``keep_surface``) with ``foliage``'s leaves
    grown on it at its size in metres (``v · scale``), brought back unscaled (the transform scales them again: square leaves
    in metres); the faces' rows as loaded (the leaves' counted on from ``loaded_faces``) and materials (the leaves'
    :data:`~zbuf_occlude.sensors.scene.foliage.LEAF_MATERIAL`, the mesh's faces their own or ``""``); at most ``max_faces`` faces
    in all, checked before any leaf is drawn."""
    import trimesh

    room = (max_faces - (len(faces) if foliage.keep_surface else 0)) // 2  # two triangles a leaf
    leafy = foliage.grow(trimesh.Trimesh(v * scale, faces, process=False), max_leaves=min(MAX_LEAVES, max(0, room)))
    kept = len(faces) if foliage.keep_surface or foliage.leaf_area_density == 0 else 0  # the mesh's faces, first, or none
    n_leaves = len(leafy.faces) - kept
    rows = (np.arange(len(faces), dtype=np.int64) if rows is None else rows)[:kept]
    rows = np.concatenate([rows, loaded_faces + np.arange(n_leaves, dtype=np.int64)])
    names, index = (materials.names, materials.index[:kept]) if materials is not None else (("",), np.zeros(kept, np.int32))
    leaf = len(names)
    materials = FaceMaterials((*names, LEAF_MATERIAL), np.concatenate([index, np.full(n_leaves, leaf, np.int32)]))
    return np.asarray(leafy.vertices, np.float64) / scale, np.asarray(leafy.faces, np.int64), rows, materials


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
    base_dir : Path, optional
        Folder of the scene file: relative mesh paths are read from it.

    Raises
    ------
    InvalidInputError
        ``ground`` not a bool; ``ground_z_m``, ``sensor_position_m`` or ``sensor_height_m``
        (>= 0) not finite or beyond :data:`MAX_GROUND_HALF_EXTENT_M` metres;
        ``ground_half_extent_m`` not in (0, :data:`MAX_GROUND_HALF_EXTENT_M`]; an object
        that is not a :class:`SceneObject`.
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
        far = f"<= {MAX_GROUND_HALF_EXTENT_M:.0f} metres (float32 ray casting)"
        if not isinstance(self.ground, (bool, np.bool_)):
            raise InvalidInputError(f"ground must be true or false, got {value_kind(self.ground)}")
        self.ground_z_m = real(self.ground_z_m, "ground z_m", low=-MAX_GROUND_HALF_EXTENT_M, high=MAX_GROUND_HALF_EXTENT_M)
        self.ground_half_extent_m = real(
            self.ground_half_extent_m,
            "ground half_extent_m",
            low=0.0,
            low_open=True,
            high=MAX_GROUND_HALF_EXTENT_M,
            expected=f"> 0 and {far}",
        )
        # the same rule as the farm's --sensor-height and CropDistributions.height_m
        self.sensor_height_m = real(self.sensor_height_m, "sensor height_m", low=0.0, expected=">= 0 metres (above the ground)")
        real(self.sensor_height_m, "sensor height_m", high=MAX_GROUND_HALF_EXTENT_M, expected=far)
        self.sensor_position_m = reals(
            self.sensor_position_m, "sensor position_m", lengths=(2,), expected="2 numbers (x, y) in metres",
            low=-MAX_GROUND_HALF_EXTENT_M, high=MAX_GROUND_HALF_EXTENT_M,
        )  # fmt: skip
        for name in ("objects", "occluders"):
            items = getattr(self, name)
            if not isinstance(items, (list, tuple)):
                raise InvalidInputError(f"{name} must be a list of SceneObject, got {type(items).__name__}")
            bad = next((i for i, obj in enumerate(items) if not isinstance(obj, SceneObject)), None)
            if bad is not None:
                raise InvalidInputError(f"{name}[{bad}] must be a SceneObject, got {value_kind(items[bad])}")
            if isinstance(items, tuple):  # add() appends to the list given
                setattr(self, name, list(items))

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
        x, y = self.sensor_position_m
        return sensor_pose([x, y, self.ground_z_m + self.sensor_height_m])

    def _object_build(self, obj: SceneObject, max_faces: int) -> tuple[trimesh.Trimesh, NDArray[np.float64]]:
        """``obj.build(self.base_dir, max_faces=max_faces)``, once per object of this scene."""
        hit = self._object_builds.get(id(obj))
        if hit is None or hit[0] is not obj:
            hit = self._object_builds[id(obj)] = (obj, *obj.build(self.base_dir, max_faces=max_faces))
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
        n_vertices = n_faces = 0
        if self.ground:
            h = self.ground_half_extent_m
            g = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]]) + [0.0, 0.0, self.ground_z_m]
            vertices.append(g)
            faces.append(np.array([[0, 1, 2], [0, 2, 3]]))
            face_object.append(np.zeros(2, np.int32))
            face_local.append(np.arange(2))
            n_vertices = 4
        for oid, obj in enumerate([*self.objects, *self.occluders], start=1):
            where = f"objects[{oid - 1}]" if oid <= len(self.objects) else f"occluders[{oid - 1 - len(self.objects)}]"
            with located(where):  # by its place in the scene: its class and mesh are a file's values, never quoted
                local, m = self._object_build(obj, MAX_MESH_FACES - n_faces)  # leaves are counted against what the cap leaves
            n_faces += len(local.faces)
            if n_faces > MAX_MESH_FACES:  # each mesh file is capped on its own; a scene may name one 10,000 times
                raise InvalidInputError(f"the scene holds more than {MAX_MESH_FACES:,} triangles by {where}; use fewer or simpler meshes")
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
