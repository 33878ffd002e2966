"""Real-world mesh assets: which axis is up, and what unit the file is in.

A mesh made for a game, a simulator or a CAD tool is a scene of parts (wheels, doors) with
their own transforms, in a unit and with an up axis of its tool's choosing.  trimesh flattens
the scene (:mod:`zbuf_occlude.mesh.formats`); this module decides the rotation that brings
the file's up axis to +z (the pipeline's frame: cameras, the ground of a LiDAR scene) and
what the file says about its unit.

Up axis, by format, when ``up="auto"``:

* glTF 2.0 (``.gltf``, ``.glb``): **+y**.  The specification fixes it ("glTF uses a
  right-handed coordinate system ... +Y is up", Khronos glTF 2.0 §3.4 *Coordinate System
  and Units*), and its unit is the metre.  Blender's exporter follows it (its default
  ``export_yup=True`` turns Blender's z-up scene to +y), as do three.js and Khronos' tools.
  One exception, read from the file's ``asset.generator``: **trimesh** writes the
  vertices as they are, with no axis conversion (checked: a box tall along z exported by
  trimesh 4–5 has ``max = [.., .., 2.5]`` in its accessor), and reads them back the same
  way, so a file it wrote holds the frame of the mesh it was given, which in this
  package's world (trimesh, ModelNet) is z up: taken **as stored, +z**, so that a
  z-up mesh written by trimesh comes back standing.
* COLLADA (``.dae``): the file's ``<asset><up_axis>`` (``X_UP``, ``Y_UP`` or ``Z_UP``),
  **Y_UP when absent** (COLLADA 1.5 specification, *asset* element: "up_axis ... default
  Y_UP"); the unit is ``<unit meter="...">`` (default 1.0).
* A file at a ShapeNetCore path (``SYNSET/MODEL_ID/models/model_normalized.obj``, v2, or
  ``SYNSET/MODEL_ID/model.obj``, v1; :func:`zbuf_occlude.mesh.paths.shapenet_path`):
  **+y**, ShapeNetCore's alignment (up ``(0, 1, 0)``, front ``(0, 0, -1)`` in v2), whatever
  wrote it.
* Wavefront OBJ has no convention of its own; the exporter named in the file's first
  comment lines decides: Blender's OBJ exporter writes Y up by default (``axis_up='Y'``),
  MakeHuman works in a Y-up frame; anything else (3ds Max exports used by Gazebo, ModelNet,
  trimesh) is taken **as stored, +z**.
* OFF, PLY, STL: as stored, +z (ModelNet's frame).

``auto`` is a rule, not a measurement: a file that breaks its format's convention needs an
explicit ``up``.  The rule applied is kept in the mesh's metadata (``up_source``).

Materials: each mesh of a scene has its own (trimesh keeps ``visual.material.name`` for OBJ/MTL's
``usemtl`` groups, one mesh each, and for glTF's primitives), and flattening the scene into one
mesh drops them.  :func:`face_materials` keeps them per face, in the flattened mesh's order
(:func:`zbuf_occlude.mesh.flatten.flatten_scene`), for ``mesh.metadata[FACE_MATERIALS]``; a face
of a mesh without a material has the name ``""``.  The reflectance lookup reads them first
(:func:`zbuf_occlude.sensors.scene.materials.scene_optics`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError, MeshLoadError
from zbuf_occlude.io.regular_files import open_regular_file
from zbuf_occlude.mesh.paths import shapenet_path

if TYPE_CHECKING:  # trimesh is imported by the readers, when a file is read
    import trimesh

__all__ = [
    "FACE_MATERIALS", "MAX_MATERIAL_NAME_CHARS", "UP_AXES", "UP_CHOICES", "FaceMaterials", "collada_asset", "declared_units_m",
    "face_materials", "face_materials_of", "gltf_generator", "resolve_up", "up_rotation",
]  # fmt: skip

#: Key of a mesh's ``metadata`` that holds its faces' materials (:class:`FaceMaterials`, module docstring).
FACE_MATERIALS = "face_materials"
#: Longest material name kept: a name is a label (MTL and glTF names are a few words), not a text.
MAX_MATERIAL_NAME_CHARS = 256

#: Axes a file may declare as up (the rotation sends it to +z).
UP_AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
#: What ``load_mesh(up=...)`` and ``--up`` accept.
UP_CHOICES = ("auto", *UP_AXES)

#: Bytes of a COLLADA file searched for its ``<asset>`` block, which the schema puts first;
#: the head of the file, not the whole (a hostile file may be gigabytes).
_COLLADA_HEAD_BYTES = 1 << 16
#: Bytes of an OBJ file searched for the exporter's comment.
_OBJ_HEAD_BYTES = 1024
#: Bytes of a glTF file searched for ``asset.generator``: trimesh writes ``asset`` near the
#: top of the JSON (GLB: the JSON chunk starts at byte 20); a file whose ``asset`` lies
#: further on is read by the specification's rule.
_GLTF_HEAD_BYTES = 1 << 16
#: glTF writers known to store vertices without turning them to +y (module docstring).
_GLTF_AS_STORED_GENERATORS = ("trimesh",)
_GENERATOR = re.compile(rb'"generator"\s*:\s*"([^"\\]{0,256})"')

_OBJ_Y_UP_EXPORTERS = (("blender", "Blender's OBJ exporter (default axis_up='Y')"),
                       ("make_clothes", "MakeHuman export (Y-up frame)"),
                       ("makehuman", "MakeHuman export (Y-up frame)"))  # fmt: skip


#: (rotation axis, angle in degrees) of the quarter or half turn that sends each up axis to +z.
_UP_TURNS = {"+y": ((1.0, 0.0, 0.0), 90.0), "-y": ((1.0, 0.0, 0.0), -90.0), "+x": ((0.0, 1.0, 0.0), -90.0),
             "-x": ((0.0, 1.0, 0.0), 90.0), "-z": ((1.0, 0.0, 0.0), 180.0)}  # fmt: skip


def up_rotation(axis: str) -> NDArray[np.float64]:
    """(4, 4) float64 proper rotation that sends ``axis`` to +z.

    A turn about x for ±y and −z (+y up gives ``(x, y, z) → (x, −z, y)``, the usual
    glTF → z-up map, which keeps x), about y for ±x; the identity for +z.

    Raises
    ------
    InvalidInputError
        ``axis`` not one of :data:`UP_AXES`.
    """
    if axis not in UP_AXES:
        raise InvalidInputError(f"up axis must be one of {', '.join(UP_CHOICES)}, got {axis!r}")
    if axis == "+z":
        return np.eye(4)
    direction, degrees = _UP_TURNS[axis]
    import trimesh  # here, not at import: the CLI's option checks import UP_CHOICES

    m = trimesh.transformations.rotation_matrix(np.radians(degrees), direction)
    return np.round(m, 15)  # exact zeros and ones for quarter turns


def collada_asset(head: bytes) -> tuple[str | None, float | None]:
    """The ``<up_axis>`` (as ``+x``/``+y``/``+z``) and ``<unit meter>`` of a COLLADA file's head.

    A regular expression over the first bytes, no XML parser: nothing in the file is
    expanded or fetched.  ``None`` for what is not declared (or not a positive finite number).
    """
    text = head[:_COLLADA_HEAD_BYTES].decode("latin-1")
    up = re.search(r"<up_axis>\s*([XYZ])_UP\s*</up_axis>", text, re.IGNORECASE)
    unit = re.search(r"<unit\b[^>]*\bmeter\s*=\s*[\"']([^\"']+)[\"']", text)
    meters = None
    if unit:
        try:
            meters = float(unit.group(1))
        except ValueError:
            meters = None
        if meters is not None and not (np.isfinite(meters) and meters > 0):
            meters = None
    return ("+" + up.group(1).lower()) if up else None, meters


def gltf_generator(head: bytes) -> str | None:
    """``asset.generator`` of a glTF file (``.gltf`` text or GLB bytes) from its first bytes, or None.

    A regular expression, not a JSON parser: only the head is read, nothing is expanded.
    """
    found = _GENERATOR.search(head[:_GLTF_HEAD_BYTES])
    return found.group(1).decode("latin-1") if found else None


def _head(path: Path, n: int) -> bytes:
    """The first ``n`` bytes of the mesh file ``path`` (a regular file: a FIFO is refused, not waited on)."""
    fh, _ = open_regular_file(path, error=MeshLoadError)
    with fh:
        return fh.read(n)


def resolve_up(path: Path, file_type: str, up: str) -> tuple[str, str]:
    """The up axis of a mesh file and the rule that decided it (module docstring).

    Parameters
    ----------
    path : Path
        The file (its head is read for glTF, COLLADA and OBJ; its path tells a ShapeNetCore model).
    file_type : str
        trimesh's file type (``gltf``, ``glb``, ``dae``, ``obj``, ...).
    up : str
        One of :data:`UP_CHOICES`.

    Returns
    -------
    axis : str
        One of :data:`UP_AXES`.
    source : str
        Why: ``"explicit"``, ``"glTF convention"``, ``"COLLADA <up_axis>"``, ...

    Raises
    ------
    InvalidInputError
        ``up`` not one of :data:`UP_CHOICES`.
    MeshLoadError
        The file is missing, cannot be read or is not a regular file (a FIFO), naming it.
    OSError
        Reading the file fails once it is open.
    """
    if up not in UP_CHOICES:
        raise InvalidInputError(f"up axis must be one of {', '.join(UP_CHOICES)}, got {up!r}")
    if up != "auto":
        return up, "explicit"
    if shapenet_path(path) is not None:
        return "+y", "ShapeNetCore layout (+Y up)"
    if file_type in ("gltf", "glb"):
        generator = gltf_generator(_head(path, _GLTF_HEAD_BYTES)) or ""
        if any(name in generator.lower() for name in _GLTF_AS_STORED_GENERATORS):
            return "+z", f"as stored (+z): written by {generator}, which does not convert axes"
        return "+y", "glTF convention (+Y up)"
    if file_type == "dae":
        declared, _ = collada_asset(_head(path, _COLLADA_HEAD_BYTES))
        return (declared, "COLLADA <up_axis>") if declared else ("+y", "COLLADA default (Y_UP)")
    if file_type == "obj":
        head = _head(path, _OBJ_HEAD_BYTES).decode("latin-1").lower()
        comments = " ".join(line for line in head.splitlines()[:5] if not line.startswith(("v ", "f ")))
        for word, why in _OBJ_Y_UP_EXPORTERS:
            if word in comments:
                return "+y", why
    return "+z", "as stored (+z)"


def declared_units_m(path: Path, file_type: str) -> float | None:
    """Metres per file unit when the format declares it: glTF 1.0 (the metre by
    specification), COLLADA's ``<unit meter>`` (1.0 when absent, its default); None otherwise.

    Raises
    ------
    MeshLoadError
        A COLLADA file that is missing, unreadable or not a regular file (a FIFO), naming it.
    """
    if file_type in ("gltf", "glb"):
        return 1.0
    if file_type == "dae":
        _, meters = collada_asset(_head(path, _COLLADA_HEAD_BYTES))
        return 1.0 if meters is None else meters
    return None


@dataclass(frozen=True)
class FaceMaterials:
    """The material name of each face of a mesh (module docstring).

    Attributes
    ----------
    names : tuple of str
        The distinct names, ``""`` for faces of a mesh that had none; each at most
        :data:`MAX_MATERIAL_NAME_CHARS` characters.
    index : (F,) int32
        Each face's row in ``names``.
    """

    names: tuple[str, ...]
    index: NDArray[np.int32]

    def select(self, rows: NDArray[np.int64] | NDArray[np.bool_]) -> FaceMaterials:
        """The materials of the faces ``rows`` (indices or a mask) of the mesh, for a mesh made of those faces."""
        return FaceMaterials(self.names, self.index[rows])


def _material_name(geometry: Any) -> str:
    """``geometry.visual.material.name`` (trimesh's for OBJ/MTL and glTF), ``""`` without one, cut to a label's length."""
    name = getattr(getattr(getattr(geometry, "visual", None), "material", None), "name", None)
    return name[:MAX_MATERIAL_NAME_CHARS] if isinstance(name, str) else ""


def face_materials(scene: trimesh.Scene) -> FaceMaterials:
    """The material of every face of ``scene`` flattened, in :func:`~zbuf_occlude.mesh.flatten.flatten_scene`'s order.

    Parameters
    ----------
    scene : trimesh.Scene
        As a trimesh loader returns it: each mesh (geometry) with its own ``visual.material``.

    Returns
    -------
    FaceMaterials
        ``index`` (F,) int32 over the flattened mesh's F faces: mesh instances in the order of
        ``scene.graph.nodes_geometry``, each mesh's faces in file order (points and paths have none).

    Notes
    -----
    The instances are :func:`~zbuf_occlude.mesh.flatten.mesh_instances`'s; a scene
    :func:`~zbuf_occlude.mesh.flatten.flatten_scene` refuses (a mesh node not below the root
    frame) is refused there, before its materials are asked for.
    """
    from zbuf_occlude.mesh.flatten import mesh_instances

    names: dict[str, int] = {}
    parts = []
    for _, geometry_name in mesh_instances(scene):
        geometry = scene.geometry[geometry_name]
        code = names.setdefault(_material_name(geometry), len(names))
        parts.append(np.full(len(geometry.faces), code, dtype=np.int32))
    index = np.concatenate(parts) if parts else np.zeros(0, dtype=np.int32)
    return FaceMaterials(tuple(names), index)


def face_materials_of(mesh: Any) -> FaceMaterials | None:
    """``mesh.metadata[FACE_MATERIALS]`` where it holds one material per face of ``mesh``, else None (a mesh
    from a file without materials, or one made or changed since it was loaded)."""
    found = (getattr(mesh, "metadata", None) or {}).get(FACE_MATERIALS)
    if not isinstance(found, FaceMaterials) or len(found.index) != len(getattr(mesh, "faces", ())):
        return None
    return found
