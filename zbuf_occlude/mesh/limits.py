"""Caps on what a mesh file may declare, shared by every format that instances meshes.

A glTF or COLLADA file is a description of a scene: a small file can place one mesh a thousand
times, or declare arrays it does not store, and trimesh allocates what it declares.  Each format
counts what its file declares, in time linear in its size and before trimesh parses it
(:mod:`zbuf_occlude.mesh.formats.gltf`, :mod:`zbuf_occlude.mesh.formats.collada`), and hands
the counts to :func:`check_scene_totals`: the file is refused when a count passes a cap below,
or when the memory it would take (:mod:`zbuf_occlude.resources`) is more than this machine has.
The error names the file, the number and the cap.

Caps (each a count real assets stay far below; the reason is beside each constant):

* triangles after instancing: :data:`MAX_MESH_FACES` (10,000,000);
* mesh instances (a mesh or primitive placed by a node) after instancing:
  :data:`MAX_MESH_INSTANCES` (100,000); scene nodes: :data:`MAX_SCENE_NODES` (1,000,000).

The caps of one format (glTF's accessor bytes, COLLADA's nesting depth) live in its module.
"""

from __future__ import annotations

from os import PathLike

from zbuf_occlude.errors import InsufficientMemoryError, MeshLoadError
from zbuf_occlude.resources import BYTES_PER_FACE, check_memory

__all__ = ["BYTES_PER_SCENE_NODE", "MAX_MESH_FACES", "MAX_MESH_INSTANCES", "MAX_SCENE_NODES", "check_scene_totals"]

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
#: Memory a scene node takes while a glTF is read and flattened: ~1.8 KB measured (a
#: 1,000,000-node chain: 1.8 GB peak), rounded up.
BYTES_PER_SCENE_NODE = 2048


def check_scene_totals(path: str | PathLike[str], *, faces: int, instances: int, nodes: int, extra_bytes: int = 0) -> None:
    """The caps every format shares, then the memory the scene would take.

    Parameters
    ----------
    path : path
        The file, for the message.
    faces, instances, nodes : int
        Triangles, mesh instances and scene nodes the file declares, instances followed.
    extra_bytes : int
        Memory the format allocates besides (glTF: its accessors).

    Raises
    ------
    MeshLoadError
        Naming ``path``: more nodes than :data:`MAX_SCENE_NODES`, mesh instances than
        :data:`MAX_MESH_INSTANCES` or triangles than :data:`MAX_MESH_FACES`, or more memory
        than is available; the message gives the number and the cap.
    """
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
