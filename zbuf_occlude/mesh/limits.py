"""Sizes a mesh file declares, checked before trimesh allocates them.

A glTF file is a JSON description of arrays: a 490-byte file can declare an accessor of 1e8
vectors with no buffer behind it (the specification says it is all zeros, and trimesh
allocates them: 10 GB), or one mesh instanced by a thousand nodes (each copy is baked into
the flattened mesh: 1.6 MB of file gave 3e7 triangles).  A COLLADA file instances the same
way: a ``<node>`` places a ``<geometry>`` (``<instance_geometry>``) or another node
(``<instance_node>``), and nodes that instance each other twice per level multiply a small
mesh 2**depth times.  The JSON or XML is read here first, in time linear in its size, and the
file is refused when what it declares passes a cap below, or when the memory it would take
(:mod:`zbuf_occlude.resources`) is more than this machine has.  The error names the file, the
number and the cap.

Caps (each a count real assets stay far below; the reason is beside each constant):

* triangles after instancing: :data:`MAX_MESH_FACES` (10,000,000);
* mesh instances (a mesh or primitive placed by a node) after instancing:
  :data:`MAX_MESH_INSTANCES` (100,000); scene nodes: :data:`MAX_SCENE_NODES` (1,000,000);
* COLLADA node nesting, instances followed: :data:`MAX_SCENE_DEPTH` (256); a glTF hierarchy
  may be as deep as it has nodes (the scene is flattened in linear time,
  :mod:`zbuf_occlude.mesh.flatten`), but not a cycle;
* glTF: bytes of all accessors together: :data:`MAX_ACCESSOR_BYTES` (4 GiB).

COLLADA is XML: it is read with the standard library's expat parser, as pycollada reads it,
refusing what ``defusedxml`` refuses (entity declarations, so no "billion laughs" expansion,
and external entities, so no file or URL is fetched) before pycollada parses the file.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from typing import Any, NamedTuple
from xml.parsers import expat

from zbuf_occlude.errors import InsufficientMemoryError, InvalidInputError, MeshLoadError
from zbuf_occlude.io.json_files import loads_json
from zbuf_occlude.resources import BYTES_PER_FACE, check_memory, format_bytes

__all__ = [
    "BYTES_PER_SCENE_NODE",
    "MAX_ACCESSOR_BYTES",
    "MAX_MESH_FACES",
    "MAX_MESH_INSTANCES",
    "MAX_SCENE_DEPTH",
    "MAX_SCENE_NODES",
    "SceneCounts",
    "check_collada_declared_sizes",
    "check_gltf_declared_sizes",
    "count_collada_scene",
]

#: Triangles a flattened mesh may have, instances counted: 10 million.  Scanned statues and
#: photogrammetry assets reach a few million; at :data:`~zbuf_occlude.resources.BYTES_PER_FACE`
#: this is already ~9 GB of a worker's memory.
MAX_MESH_FACES = 10_000_000
#: Nodes of a scene (glTF nodes; COLLADA nodes after instancing): 1,000,000.  Vehicles,
#: buildings and street scenes hold hundreds to a few thousand.  Flattening is linear
#: (:mod:`zbuf_occlude.mesh.flatten`); trimesh's graph and the walk cost about 0.1 ms and
#: :data:`BYTES_PER_SCENE_NODE` per node: at most a minute or two and 2 GB.
MAX_SCENE_NODES = 1_000_000
#: Mesh instances after instancing (each mesh or primitive a node places): 100,000.  trimesh
#: copies and transforms a mesh per instance (about 0.5 ms each): at most about a minute.
#: The street assets of the test data place 1 to 261.
MAX_MESH_INSTANCES = 100_000
#: Depth of a COLLADA node hierarchy, ``<instance_node>`` followed: 256.  pycollada and trimesh
#: read it by recursion (Python's limit: 1,000 frames); CAD assemblies nest tens deep.
MAX_SCENE_DEPTH = 256
#: Memory a scene node takes while a glTF is read and flattened: ~1.8 KB measured (a
#: 1,000,000-node chain: 1.8 GB peak), rounded up.
BYTES_PER_SCENE_NODE = 2048
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
            total += _count(acc.get("count")) * _TYPE_COMPONENTS.get(acc.get("type"), 16) * _COMPONENT_BYTES.get(acc.get("componentType"), 4)
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


def _check_totals(path: str | PathLike[str], *, faces: int, instances: int, nodes: int, extra_bytes: int = 0) -> None:
    """The caps every format shares, then the memory; MeshLoadError naming ``path``."""
    if nodes > MAX_SCENE_NODES:
        raise MeshLoadError(f"{path}: declares {nodes:,} scene nodes, more than the {MAX_SCENE_NODES:,} accepted")
    if instances > MAX_MESH_INSTANCES:
        raise MeshLoadError(f"{path}: places {instances:,} mesh instances, more than the {MAX_MESH_INSTANCES:,} accepted")
    if faces > MAX_MESH_FACES:
        raise MeshLoadError(f"{path}: declares {faces:,} triangles after node instancing, more than the {MAX_MESH_FACES:,} accepted")
    try:
        needed = extra_bytes + faces * BYTES_PER_FACE + nodes * BYTES_PER_SCENE_NODE
        check_memory(needed, option="the mesh", hint="use a smaller mesh or a machine with more memory")
    except InsufficientMemoryError as exc:
        raise MeshLoadError(f"{path}: {exc}") from None


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
        Naming ``path``: more nodes than :data:`MAX_SCENE_NODES`, a cycle in the node
        hierarchy, accessors declaring more than :data:`MAX_ACCESSOR_BYTES`, more mesh
        instances than :data:`MAX_MESH_INSTANCES` or more triangles than
        :data:`MAX_MESH_FACES` after node instancing, or more memory than is available; the
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
        raise MeshLoadError(f"{path}: its accessors declare {format_bytes(n_bytes)}, more than the {format_bytes(MAX_ACCESSOR_BYTES)} accepted")
    faces_per_mesh, primitives_per_mesh = _mesh_faces(_list(doc, "meshes"), accessors)
    placed = [(instances[i], node["mesh"]) for i, node in enumerate(nodes)
              if isinstance(node, dict) and isinstance(node.get("mesh"), int) and 0 <= node["mesh"] < len(faces_per_mesh)]  # fmt: skip
    _check_totals(
        path, faces=sum(k * faces_per_mesh[m] for k, m in placed), instances=sum(k * primitives_per_mesh[m] for k, m in placed),
        nodes=len(nodes), extra_bytes=n_bytes,
    )  # fmt: skip
    return doc


# -- COLLADA -------------------------------------------------------------------------------
#: Primitives pycollada turns into triangles (and trimesh places once per instance); ``lines``
#: and ``linestrips`` give none.
_COLLADA_PRIMITIVES = frozenset({"triangles", "tristrips", "trifans", "polylist", "polygons"})
#: Characters expat hands over at once (fewer calls on long index lists).
_XML_TEXT_BUFFER = 1 << 16


@dataclass
class _Node:
    """A COLLADA ``<node>``: what it places directly."""

    children: list[_Node] = field(default_factory=list)
    geometries: list[str] = field(default_factory=list)  # instance_geometry ids
    instanced: list[str] = field(default_factory=list)  # instance_node ids


@dataclass
class _Primitive:
    kind: str
    stride: int = 1
    triangles: int = 0


class _ColladaCounts:
    """expat handlers that count what a COLLADA file places, without building its tree.

    Index lists (``<p>``, ``<vcount>``) are counted as their text streams by, in chunks; the
    float arrays are skipped.  Element names are compared without their namespace.
    """

    def __init__(self) -> None:
        self.geometry_faces: dict[str, int] = {}
        self.geometry_primitives: dict[str, int] = {}
        self.nodes_by_id: dict[str, list[_Node]] = {}
        self.visual_scenes: dict[str, list[_Node]] = {}
        self.scene_url: str | None = None
        self._geometry: str | None = None
        self._primitive: _Primitive | None = None
        self._open_nodes: list[_Node] = []
        self._scene_roots: list[_Node] | None = None
        self._text: str | None = None  # "p" or "vcount" while one is open
        self._carry = ""
        self._tokens = 0
        self._vcount_triangles = 0

    def start(self, name: str, attrs: dict[str, str]) -> None:
        tag = name.rpartition("}")[2]
        if tag == "geometry":
            self._geometry = attrs.get("id", "")
            self.geometry_faces.setdefault(self._geometry, 0)
            self.geometry_primitives.setdefault(self._geometry, 0)
        elif tag in _COLLADA_PRIMITIVES and self._geometry is not None:
            self._primitive = _Primitive(tag)
            self.geometry_primitives[self._geometry] += 1
        elif tag == "input" and self._primitive is not None:
            offset = attrs.get("offset", "0")
            if offset.isdigit():
                self._primitive.stride = max(self._primitive.stride, int(offset) + 1)
        elif tag in ("p", "vcount") and self._primitive is not None:
            self._text, self._carry, self._tokens = tag, "", 0
        elif tag == "visual_scene":
            self._scene_roots = self.visual_scenes.setdefault(attrs.get("id", ""), [])
        elif tag == "node":
            node = _Node()
            if self._open_nodes:
                self._open_nodes[-1].children.append(node)
            elif self._scene_roots is not None:
                self._scene_roots.append(node)
            if "id" in attrs:
                self.nodes_by_id.setdefault(attrs["id"], []).append(node)
            self._open_nodes.append(node)
        elif tag in ("instance_geometry", "instance_node") and self._open_nodes:
            url = attrs.get("url", "")
            if url.startswith("#"):  # another file's node or geometry is not read
                node = self._open_nodes[-1]
                (node.geometries if tag == "instance_geometry" else node.instanced).append(url[1:])
        elif tag == "instance_visual_scene" and attrs.get("url", "").startswith("#"):
            self.scene_url = attrs["url"][1:]

    def end(self, name: str) -> None:
        tag = name.rpartition("}")[2]
        if tag == self._text:
            self._close_text()
        elif tag in _COLLADA_PRIMITIVES and self._primitive is not None and self._geometry is not None:
            self.geometry_faces[self._geometry] += self._primitive.triangles
            self._primitive = None
        elif tag == "geometry":
            self._geometry = None
        elif tag == "node" and self._open_nodes:
            self._open_nodes.pop()
        elif tag == "visual_scene":
            self._scene_roots = None

    def text(self, data: str) -> None:
        if self._text is None:
            return
        data = self._carry + data
        tokens = data.split()
        # a number cut between two chunks is kept for the next one
        self._carry = tokens.pop() if tokens and not data[-1].isspace() else ""
        self._count(tokens)

    def _count(self, tokens: list[str]) -> None:
        if self._text == "vcount":  # polylist: a polygon of v corners is v - 2 triangles
            self._vcount_triangles += sum(max(int(t) - 2, 0) for t in tokens if t.isdigit())
        else:
            self._tokens += len(tokens)

    def _close_text(self) -> None:
        self._count([self._carry] if self._carry else [])
        primitive, kind = self._primitive, self._text
        self._text, self._carry = None, ""
        if primitive is None:
            return
        if kind == "vcount":
            primitive.triangles += self._vcount_triangles
            self._vcount_triangles = 0
            return
        corners = self._tokens // primitive.stride
        if primitive.kind == "triangles":
            primitive.triangles += corners // 3
        elif primitive.kind != "polylist":  # polygons, tristrips, trifans: each <p> is n - 2 triangles
            primitive.triangles += max(corners - 2, 0)


def _refuse_entities(*args: Any) -> None:
    raise _EntityRefused


class _EntityRefused(Exception):
    """The XML declares an entity (expansion bombs, external files): refused."""


class SceneCounts(NamedTuple):
    """What a scene places once its instances are followed (:func:`count_collada_scene`)."""

    #: Triangles of every mesh instance together.
    faces: int
    #: Mesh instances: each primitive of each placed geometry (trimesh makes one mesh of each).
    instances: int
    #: Nodes visited, a node instanced k times counted k times.
    nodes: int
    #: Deepest chain of nested nodes, ``<instance_node>`` followed (a top-level node is 1).
    depth: int


def _placed_together(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
    """(faces, instances, nodes, depth) of two sibling subtrees: counts add, depth is the deeper one."""
    return a[0] + b[0], a[1] + b[1], a[2] + b[2], max(a[3], b[3])


def _collada_totals(counts: _ColladaCounts, path: str | PathLike[str]) -> SceneCounts:
    """The scene's counts after instancing, in linear time.

    Each node is evaluated once, children and instanced nodes first (an explicit stack, no
    recursion); a node that instances one of its ancestors is a cycle and is refused.
    """
    totals: dict[int, tuple[int, int, int, int]] = {}
    on_path: set[int] = set()

    def refs(node: _Node) -> list[_Node]:
        return [*node.children, *(n for ident in node.instanced for n in counts.nodes_by_id.get(ident, []))]

    def evaluate(root: _Node) -> tuple[int, int, int, int]:
        stack = [(root, False)]
        while stack:
            node, expanded = stack.pop()
            if id(node) in totals:
                continue
            if not expanded:
                if id(node) in on_path:
                    raise MeshLoadError(f"{path}: its nodes instance each other in a cycle (<instance_node> of an ancestor)")
                on_path.add(id(node))
                stack.append((node, True))
                stack.extend((child, False) for child in refs(node) if id(child) not in totals)
                continue
            on_path.discard(id(node))
            faces = sum(counts.geometry_faces.get(g, 0) for g in node.geometries)
            instances = sum(counts.geometry_primitives.get(g, 0) for g in node.geometries)
            below = (0, 0, 0, 0)  # what the node's children and instanced nodes place
            for child in node.children:
                below = _placed_together(below, totals[id(child)])
            for ident in node.instanced:
                defined = [totals[id(n)] for n in counts.nodes_by_id.get(ident, [])]
                if defined:  # an id defined twice: the larger counts (pycollada keeps one of them)
                    below = _placed_together(below, max(defined))
            totals[id(node)] = (faces + below[0], instances + below[1], 1 + below[2], below[3] + 1)
        return totals[id(root)]

    if counts.scene_url in counts.visual_scenes:
        roots = counts.visual_scenes[counts.scene_url]
    else:  # no <scene> naming one: count them all
        roots = [node for scene in counts.visual_scenes.values() for node in scene]
    scene = (0, 0, 0, 0)
    for root in roots:
        scene = _placed_together(scene, evaluate(root))
    return SceneCounts(*scene)


def count_collada_scene(raw: bytes, path: str | PathLike[str]) -> SceneCounts:
    """Triangles, mesh instances, nodes and depth of a COLLADA file's scene, instances followed.

    The XML is streamed through expat once (nothing is built but one record per ``<node>``),
    entity declarations and external entities refused; triangles are counted from the index
    lists (``<p>``, ``<vcount>``) of every ``<triangles>``, ``<tristrips>``, ``<trifans>``,
    ``<polylist>`` and ``<polygons>`` (a polygon of *v* corners is *v* - 2 triangles, as
    pycollada triangulates it), then multiplied by the nodes that place each ``<geometry>``,
    directly or through ``<instance_node>``, in the scene that ``<scene>`` names (every
    ``<visual_scene>`` when it names none).  COLLADA 1.4 and 1.5 (Khronos COLLADA 1.5.0
    specification, chapter 5: ``node``, ``instance_node``, ``instance_geometry``; chapter 6:
    ``p``, ``vcount``).  On the 12 COLLADA street assets of the test data the triangles equal
    what trimesh loads.

    Parameters
    ----------
    raw : bytes
        The file's content.
    path : path
        The file, for the message.

    Returns
    -------
    counts : SceneCounts
        ``faces``, ``instances``, ``nodes``, ``depth``.

    Raises
    ------
    MeshLoadError
        Naming ``path``: XML that is not well formed or declares entities; nodes that
        instance an ancestor (a cycle).
    """
    counts = _ColladaCounts()
    parser = expat.ParserCreate(namespace_separator="}")  # as ElementTree (and so pycollada) parses
    parser.buffer_text, parser.buffer_size = True, _XML_TEXT_BUFFER
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    parser.EntityDeclHandler = _refuse_entities  # what defusedxml refuses: entities and external ones
    parser.UnparsedEntityDeclHandler = _refuse_entities
    parser.ExternalEntityRefHandler = _refuse_entities
    parser.StartElementHandler, parser.EndElementHandler, parser.CharacterDataHandler = counts.start, counts.end, counts.text
    try:
        parser.Parse(raw, True)
    except _EntityRefused:
        raise MeshLoadError(f"{path}: the XML declares entities (<!ENTITY>); COLLADA needs none, so they are refused") from None
    except expat.ExpatError as exc:
        raise MeshLoadError(f"{path}: not well-formed XML ({expat.ErrorString(exc.code)} at line {exc.lineno})") from None
    return _collada_totals(counts, path)


def check_collada_declared_sizes(raw: bytes, path: str | PathLike[str]) -> None:
    """Refuse a COLLADA file (``.dae``) whose scene, instances followed, passes the caps.

    Linear in the file's size (:func:`count_collada_scene`); nothing it declares is allocated.

    Parameters
    ----------
    raw : bytes
        The file's content.
    path : path
        The file, for the message.

    Raises
    ------
    MeshLoadError
        Naming ``path``: what :func:`count_collada_scene` raises; nesting deeper than
        :data:`MAX_SCENE_DEPTH`; more nodes than :data:`MAX_SCENE_NODES`, mesh instances than
        :data:`MAX_MESH_INSTANCES` or triangles than :data:`MAX_MESH_FACES` after instancing;
        or more memory than is available.  The message gives the number and the cap.
    """
    counts = count_collada_scene(raw, path)
    if counts.depth > MAX_SCENE_DEPTH:
        raise MeshLoadError(f"{path}: its nodes nest {counts.depth:,} deep (instances followed), more than the {MAX_SCENE_DEPTH} accepted")
    _check_totals(path, faces=counts.faces, instances=counts.instances, nodes=counts.nodes)
