"""Sizes a mesh file declares, checked before trimesh allocates them.

A glTF file is a JSON description of arrays: a 490-byte file can declare an accessor of 1e8
vectors with no buffer behind it (the specification says it is all zeros, and trimesh
allocates them: 10 GB), one mesh instanced by a thousand nodes (each copy is baked into the
flattened mesh: 1.6 MB of file gave 3e7 triangles), or 200,000 nodes in one parent → child
chain (trimesh flattens the scene graph in time quadratic in its depth: 385 s).  The JSON is
read here first, in time linear in its size, and the file is refused when what it declares
passes a cap below, or when the memory it would take (:mod:`zbuf_occlude.resources`) is more
than this machine has.  The error names the file, the number and the cap.

Caps (each a count real assets stay far below; the reason is beside each constant):

* triangles after instancing: :data:`MAX_MESH_FACES` (10,000,000);
* nodes: :data:`MAX_SCENE_NODES` (100,000); depth of the hierarchy: :data:`MAX_SCENE_DEPTH` (256);
* bytes of all accessors together: :data:`MAX_ACCESSOR_BYTES` (4 GiB).
"""

from __future__ import annotations

import json
import struct
from collections.abc import Mapping, Sequence
from os import PathLike
from typing import Any

from zbuf_occlude.errors import InsufficientMemoryError, MeshLoadError
from zbuf_occlude.resources import BYTES_PER_FACE, check_memory, format_bytes

__all__ = [
    "MAX_ACCESSOR_BYTES",
    "MAX_MESH_FACES",
    "MAX_SCENE_DEPTH",
    "MAX_SCENE_NODES",
    "check_gltf_declared_sizes",
]

#: Triangles a flattened mesh may have, instances counted: 10 million.  Scanned statues and
#: photogrammetry assets reach a few million; at :data:`~zbuf_occlude.resources.BYTES_PER_FACE`
#: this is already ~9 GB of a worker's memory.
MAX_MESH_FACES = 10_000_000
#: Nodes of a glTF scene: 100,000.  Vehicles, buildings and street scenes hold hundreds to a
#: few thousand.
MAX_SCENE_NODES = 100_000
#: Depth of a glTF node hierarchy: 256.  Character rigs and CAD assemblies nest tens deep;
#: trimesh's flattening costs depth x nodes, so depth is what turns a small file into hours.
MAX_SCENE_DEPTH = 256
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
        doc = json.loads(text)
    except (ValueError, UnicodeDecodeError, RecursionError):
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
            total += _count(acc.get("count")) * _TYPE_COMPONENTS.get(acc.get("type"), 16) * _COMPONENT_BYTES.get(acc.get("componentType"), 4)
    return total


def _mesh_faces(meshes: Sequence[Any], accessors: Sequence[Any]) -> list[int]:
    """Triangles each glTF mesh declares (indices count, else the positions count)."""

    def count_of(index: Any) -> int:
        if isinstance(index, int) and 0 <= index < len(accessors) and isinstance(accessors[index], dict):
            return _count(accessors[index].get("count"))
        return 0

    faces = []
    for mesh in meshes:
        n = 0
        for prim in mesh.get("primitives", []) if isinstance(mesh, dict) else []:
            if not isinstance(prim, dict) or prim.get("mode", 4) not in _TRIANGLE_MODES:
                continue
            attributes = prim.get("attributes") if isinstance(prim.get("attributes"), dict) else {}
            k = count_of(prim["indices"]) if "indices" in prim else count_of(attributes.get("POSITION"))
            n += k // 3 if prim.get("mode", 4) == 4 else max(k - 2, 0)
        faces.append(n)
    return faces


def _instances_and_depth(nodes: Sequence[Any]) -> tuple[list[int], int]:
    """How many times each node is instanced (paths from a root), and the deepest path, in linear time.

    Nodes are visited parents first (Kahn's order over the child lists); a node that is never
    reached that way is on a cycle (the specification forbids them) and counts as depth
    :data:`MAX_SCENE_DEPTH` + 1.
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
    depth = [1] * n
    head = 0
    while head < len(order):
        i = order[head]
        head += 1
        for c in children[i]:
            instances[c] += instances[i]
            depth[c] = max(depth[c], depth[i] + 1)
            parents[c] -= 1
            if parents[c] == 0:
                order.append(c)
    deepest = max(depth, default=0) if len(order) == n else MAX_SCENE_DEPTH + 1
    return instances, deepest


def check_gltf_declared_sizes(raw: bytes, path: str | PathLike[str]) -> None:
    """Refuse a glTF (``.gltf`` text or ``.glb`` bytes) whose declared sizes pass the caps.

    Linear in the JSON's size; nothing the file declares is allocated.

    Parameters
    ----------
    raw : bytes
        The file's content.
    path : path
        The file, for the message.

    Raises
    ------
    MeshLoadError
        Naming ``path``: more nodes than :data:`MAX_SCENE_NODES`, a hierarchy deeper than
        :data:`MAX_SCENE_DEPTH` (or a cycle), more triangles after instancing than
        :data:`MAX_MESH_FACES`, accessors declaring more than :data:`MAX_ACCESSOR_BYTES`, or
        more memory than is available; the message gives the number and the cap.
    """
    doc = _gltf_json(raw)
    if doc is None:
        return
    nodes, accessors = _list(doc, "nodes"), _list(doc, "accessors")
    if len(nodes) > MAX_SCENE_NODES:
        raise MeshLoadError(f"{path}: declares {len(nodes):,} scene nodes, more than the {MAX_SCENE_NODES:,} accepted")
    instances, depth = _instances_and_depth(nodes)
    if depth > MAX_SCENE_DEPTH:
        raise MeshLoadError(f"{path}: its node hierarchy is {depth:,} deep (or has a cycle), more than the {MAX_SCENE_DEPTH} accepted")
    n_bytes = _accessor_bytes(accessors)
    if n_bytes > MAX_ACCESSOR_BYTES:
        raise MeshLoadError(f"{path}: its accessors declare {format_bytes(n_bytes)}, more than the {format_bytes(MAX_ACCESSOR_BYTES)} accepted")
    faces_per_mesh = _mesh_faces(_list(doc, "meshes"), accessors)
    n_faces = sum(
        instances[i] * faces_per_mesh[node["mesh"]]
        for i, node in enumerate(nodes)
        if isinstance(node, dict) and isinstance(node.get("mesh"), int) and 0 <= node["mesh"] < len(faces_per_mesh)
    )
    if n_faces > MAX_MESH_FACES:
        raise MeshLoadError(f"{path}: declares {n_faces:,} triangles after node instancing, more than the {MAX_MESH_FACES:,} accepted")
    try:
        check_memory(n_bytes + n_faces * BYTES_PER_FACE, option="the mesh", hint="use a smaller mesh or a machine with more memory")
    except InsufficientMemoryError as exc:
        raise MeshLoadError(f"{path}: {exc}") from None
