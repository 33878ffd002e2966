"""COLLADA (``.dae``, needs pycollada: the ``collada`` extra): the scene counted and the XML vetted before pycollada parses it.

A COLLADA file instances meshes the way glTF does: a ``<node>`` places a ``<geometry>``
(``<instance_geometry>``) or another node (``<instance_node>``), and nodes that instance each
other twice per level multiply a small mesh 2**depth times.  The XML is read here first, in
time linear in its size, with the standard library's expat parser, as pycollada reads it,
refusing what ``defusedxml`` refuses (entity declarations, so no "billion laughs" expansion,
and external entities, so no file or URL is fetched).  The file is refused when its nesting,
instances followed, passes :data:`MAX_SCENE_DEPTH` (256), or its scene passes the caps every
scene format shares (:mod:`zbuf_occlude.mesh.limits`).  The error names the file, the number
and the cap.

Only the geometry is used: the images a file names are never read (each is one blank pixel).
"""

from __future__ import annotations

import base64
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple
from xml.parsers import expat

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.mesh.formats.base import Format, parse
from zbuf_occlude.mesh.limits import check_scene_totals

if TYPE_CHECKING:
    import trimesh

__all__ = ["FORMATS", "MAX_SCENE_DEPTH", "SceneCounts", "check_collada_declared_sizes", "count_collada_scene", "read_collada"]

#: Depth of a COLLADA node hierarchy, ``<instance_node>`` followed: 256.  pycollada and trimesh
#: read it by recursion (Python's limit: 1,000 frames); CAD assemblies nest tens deep.
MAX_SCENE_DEPTH = 256
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
        :data:`MAX_SCENE_DEPTH`; more nodes, mesh instances or triangles after instancing than
        the caps of :mod:`zbuf_occlude.mesh.limits`; or more memory than is available.  The
        message gives the number and the cap.
    """
    counts = count_collada_scene(raw, path)
    if counts.depth > MAX_SCENE_DEPTH:
        raise MeshLoadError(f"{path}: its nodes nest {counts.depth:,} deep (instances followed), more than the {MAX_SCENE_DEPTH} accepted")
    check_scene_totals(path, faces=counts.faces, instances=counts.instances, nodes=counts.nodes)


#: A 1×1 grey PNG: what every image a COLLADA file names resolves to.
_BLANK_PNG = base64.b64decode("iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAAAAAA6fptVAAAACklEQVR4nGNgAAAAAgABSK+kcQAAAABJRU5ErkJggg==")


def _no_textures_resolver():
    """A trimesh resolver that reads no file: every texture a COLLADA file names is one blank pixel.

    Only the geometry is used, so textures are not loaded: a missing image (Gazebo models name
    textures in other folders) would otherwise make trimesh log a warning with a whole
    traceback per material, and a file could make the loader open paths of its choosing.
    """
    import trimesh

    class _NoTextures(trimesh.resolvers.Resolver):
        def __init__(self) -> None:  # no folder: nothing to resolve against
            pass

        def get(self, name: str) -> bytes:
            return _BLANK_PNG

        def keys(self):
            return iter(())

        def namespaced(self, namespace: str):
            return self

        def write(self, name: str, data) -> None:
            raise NotImplementedError("reading only")

    return _NoTextures()


def read_collada(raw: bytes, path: Path, file_type: str) -> trimesh.Trimesh:
    """A COLLADA file parsed by pycollada through trimesh; the images it names are never read."""
    # the bytes just checked, not the file read again (it could have changed in between)
    return parse(raw, path, "dae", resolver=_no_textures_resolver())


FORMATS = (Format("dae", (".dae",), read=read_collada, check=check_collada_declared_sizes, needs=("collada", "collada"), name="COLLADA"),)
