"""glTF 2.0 (``.gltf`` text, ``.glb`` binary): the sizes its JSON declares checked before trimesh allocates them.

A glTF file is a JSON description of arrays: a 490-byte file can declare an accessor of 1e8
vectors with no buffer behind it (the specification says it is all zeros, and trimesh
allocates them: 10 GB), or one mesh instanced by a thousand nodes (each copy is baked into
the flattened mesh: 1.6 MB of file gave 3e7 triangles).  The JSON is read here first, in time
linear in its size, and the file is refused when what it declares passes a cap: the bytes of
all accessors together, :data:`MAX_ACCESSOR_BYTES` (4 GiB), and the caps every scene format
shares (:mod:`zbuf_occlude.mesh.limits`).  A hierarchy may be as deep as it has nodes (the
scene is flattened in linear time, :mod:`zbuf_occlude.mesh.flatten`), but not a cycle.

Buffers and images the file names are read inside its folder
(:func:`zbuf_occlude.mesh.named_files.folder_resolver`).  Skins and animations are not
applied: a skinned character loads in its bind pose, with a warning.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Mapping, Sequence
from os import PathLike
from pathlib import Path
from typing import Any

from zbuf_occlude.errors import InvalidInputError, MeshLoadError
from zbuf_occlude.io.json_files import loads_json
from zbuf_occlude.mesh.formats.base import Format, read_with_named_files
from zbuf_occlude.mesh.limits import MAX_SCENE_NODES, check_scene_totals
from zbuf_occlude.resources import format_bytes

log = logging.getLogger(__name__)

__all__ = ["FORMATS", "MAX_ACCESSOR_BYTES", "check_gltf", "check_gltf_declared_sizes"]

#: Bytes all accessors of a glTF file declare together: 4 GiB, the most a GLB can hold
#: (its length field is a uint32).
MAX_ACCESSOR_BYTES = 4 << 30

#: glTF 2.0 §3.6.2.2 accessor element sizes.
_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_TYPE_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: Primitive modes (glTF 2.0 §3.7.2.1) and triangles per index count: TRIANGLES n/3,
#: TRIANGLE_STRIP and TRIANGLE_FAN n-2; points and lines give none.
_TRIANGLE_MODES = {4, 5, 6}


def _gltf_json(raw: bytes) -> Mapping[str, Any] | None:
    """The JSON document of a ``.gltf`` or ``.glb``; None when it cannot be read (trimesh reports it)."""
    text = raw
    if raw[:4] == b"glTF":
        if len(raw) < 20:
            return None
        length, kind = struct.unpack_from("<I4s", raw, 12)
        if kind != b"JSON":
            return None
        text = raw[20 : 20 + length]
    try:
        doc = loads_json(text, what="glTF JSON")
    except InvalidInputError:
        return None
    return doc if isinstance(doc, dict) else None


def _count(value: Any) -> int:
    return value if isinstance(value, int) and not isinstance(value, bool) and value >= 0 else 0


def _list(doc: Mapping[str, Any], key: str) -> Sequence[Any]:
    value = doc.get(key, [])
    return value if isinstance(value, list) else []


def _accessor_bytes(accessors: Sequence[Any]) -> int:
    total = 0
    for acc in accessors:
        if isinstance(acc, dict):
            total += (
                _count(acc.get("count")) * _TYPE_COMPONENTS.get(acc.get("type"), 16) * _COMPONENT_BYTES.get(acc.get("componentType"), 4)
            )
    return total


def _mesh_faces(meshes: Sequence[Any], accessors: Sequence[Any]) -> tuple[list[int], list[int]]:
    """Triangles each glTF mesh declares (indices count, else the positions count), and its primitives."""

    def count_of(index: Any) -> int:
        if isinstance(index, int) and 0 <= index < len(accessors) and isinstance(accessors[index], dict):
            return _count(accessors[index].get("count"))
        return 0

    faces, primitives = [], []
    for mesh in meshes:
        n, prims = 0, mesh.get("primitives", []) if isinstance(mesh, dict) else []
        for prim in prims if isinstance(prims, list) else []:
            if not isinstance(prim, dict) or prim.get("mode", 4) not in _TRIANGLE_MODES:
                continue
            attributes = prim.get("attributes") if isinstance(prim.get("attributes"), dict) else {}
            k = count_of(prim["indices"]) if "indices" in prim else count_of(attributes.get("POSITION"))
            n += k // 3 if prim.get("mode", 4) == 4 else max(k - 2, 0)
        faces.append(n)
        primitives.append(len(prims) if isinstance(prims, list) else 0)  # trimesh places each primitive
    return faces, primitives


def _instances(nodes: Sequence[Any]) -> list[int] | None:
    """How many times each node is instanced (paths from a root), in linear time; None on a cycle.

    Nodes are visited parents first (Kahn's order over the child lists); a node that is never
    reached that way is on a cycle (the specification forbids them).
    """
    n = len(nodes)
    children = [[c for c in (node.get("children", []) if isinstance(node, dict) else []) if isinstance(c, int) and 0 <= c < n]
                for node in nodes]  # fmt: skip
    parents = [0] * n
    for kids in children:
        for c in kids:
            parents[c] += 1
    order = [i for i in range(n) if parents[i] == 0]
    instances = [1 if parents[i] == 0 else 0 for i in range(n)]
    head = 0
    while head < len(order):
        i = order[head]
        head += 1
        for c in children[i]:
            instances[c] += instances[i]
            parents[c] -= 1
            if parents[c] == 0:
                order.append(c)
    return instances if len(order) == n else None


def check_gltf_declared_sizes(raw: bytes, path: str | PathLike[str]) -> Mapping[str, Any] | None:
    """Refuse a glTF (``.gltf`` text or ``.glb`` bytes) whose declared sizes pass the caps.

    Linear in the JSON's size; nothing the file declares is allocated.

    Parameters
    ----------
    raw : bytes
        The file's content.
    path : path
        The file, for the message.

    Returns
    -------
    dict or None
        The file's JSON document, checked (None when it cannot be parsed: trimesh then
        reports the file).

    Raises
    ------
    MeshLoadError
        Naming ``path``: more nodes than :data:`~zbuf_occlude.mesh.limits.MAX_SCENE_NODES`, a
        cycle in the node hierarchy, accessors declaring more than :data:`MAX_ACCESSOR_BYTES`,
        more mesh instances than :data:`~zbuf_occlude.mesh.limits.MAX_MESH_INSTANCES` or more
        triangles than :data:`~zbuf_occlude.mesh.limits.MAX_MESH_FACES` after node instancing, or
        more memory than is available; the
        message gives the number and the cap.
    """
    doc = _gltf_json(raw)
    if doc is None:
        return None
    nodes, accessors = _list(doc, "nodes"), _list(doc, "accessors")
    if len(nodes) > MAX_SCENE_NODES:  # before the walk: its lists take memory per node
        raise MeshLoadError(f"{path}: declares {len(nodes):,} scene nodes, more than the {MAX_SCENE_NODES:,} accepted")
    instances = _instances(nodes)
    if instances is None:
        raise MeshLoadError(f"{path}: its node hierarchy has a cycle (a node is its own ancestor), which glTF forbids")
    n_bytes = _accessor_bytes(accessors)
    if n_bytes > MAX_ACCESSOR_BYTES:
        raise MeshLoadError(
            f"{path}: its accessors declare {format_bytes(n_bytes)}, more than the {format_bytes(MAX_ACCESSOR_BYTES)} accepted"
        )
    faces_per_mesh, primitives_per_mesh = _mesh_faces(_list(doc, "meshes"), accessors)
    placed = [(instances[i], node["mesh"]) for i, node in enumerate(nodes)
              if isinstance(node, dict) and isinstance(node.get("mesh"), int) and 0 <= node["mesh"] < len(faces_per_mesh)]  # fmt: skip
    check_scene_totals(
        path, faces=sum(k * faces_per_mesh[m] for k, m in placed), instances=sum(k * primitives_per_mesh[m] for k, m in placed),
        nodes=len(nodes), extra_bytes=n_bytes,
    )  # fmt: skip
    return doc


def _warn_bind_pose(doc: Mapping[str, Any] | None, path: Path) -> None:
    """Log a warning naming ``path`` when its glTF ``doc`` has skinned mesh nodes: trimesh applies
    neither skins nor animations, so such a character (a simulator's pedestrian) loads in the pose
    it was modelled in, often a T-pose with the arms out, not as it stands or walks."""
    nodes = doc.get("nodes") if doc is not None else None
    skinned = sum(isinstance(n, dict) and "mesh" in n and "skin" in n for n in nodes) if isinstance(nodes, list) else 0
    if skinned:
        log.warning("%s: %d skinned mesh node(s) load in their bind pose (often a T-pose): skins and animations are not applied",
                    path, skinned)  # fmt: skip


def check_gltf(raw: bytes, path: Path) -> None:
    """:func:`check_gltf_declared_sizes`, then a warning when skinned nodes will load in their bind pose."""
    _warn_bind_pose(check_gltf_declared_sizes(raw, path), path)


FORMATS = (
    Format("glb", (".glb",), read=read_with_named_files, check=check_gltf),
    Format("gltf", (".gltf",), read=read_with_named_files, check=check_gltf),
)
