"""A trimesh scene flattened into one mesh, in time linear in its number of nodes.

A glTF, GLB or COLLADA file is a scene: meshes placed by a tree of nodes, each with a
transform from its parent.  ``trimesh.Scene.to_mesh`` bakes every mesh at its node, but
finds each node's transform by a fresh search from the root (``SceneGraph.get``): a chain of
*n* nodes costs *n²* steps (a 200,000-node chain took 385 s), and its product of the *k*
transforms on a path (``numpy.linalg.multi_dot``) plans the order in *k³* steps and recurses
*k* deep (a path of 1,000 transforms fails with ``RecursionError``).

Here the tree is walked once from the root (depth first, iteratively), each node's state built
from its parent's in constant time, so flattening costs one visit per edge and at most
:data:`EXACT_PATH_TRANSFORMS` matrix products per mesh instance, whatever the depth.

The result is bit for bit what ``Scene.to_mesh`` gives (trimesh 4 to 5.2) for every path of at
most :data:`EXACT_PATH_TRANSFORMS` transforms.  trimesh's rule for one node, kept here:

* a node directly under the root takes its edge's matrix as it is;
* deeper, the matrices on the path from the root are taken in order, those within 1e-8 of
  the identity dropped, and multiplied as ``multi_dot`` does for equal square matrices: from
  the right, ``M1 @ (M2 @ (... @ Mk))`` (its chain-order plan has only ties and keeps the
  first split);
* the product is then repaired towards a rigid transform when it is within
  ``graph.repair_rigid`` of one (``trimesh.transformations.fix_rigid``).

A longer path (only hand-made or hostile files have one) is multiplied from the left up to its
last :data:`EXACT_PATH_TRANSFORMS` transforms: the same matrix up to rounding.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:  # trimesh is imported by the functions, when a file is read
    import trimesh

__all__ = ["EXACT_PATH_TRANSFORMS", "IDENTITY_ATOL", "flatten_scene", "mesh_instances", "node_transforms"]

#: Transforms on one root-to-node path multiplied exactly as trimesh does (from the right).
#: Real assets have at most a handful (the 48 street meshes of the test data: 6); the bound
#: keeps the work per mesh instance constant on a hostile 50,000-deep chain.
EXACT_PATH_TRANSFORMS = 32
#: A matrix within this of the identity (largest absolute difference) is left out of a
#: path's product: trimesh's ``SceneGraph.get`` rule, kept so that results stay identical.
IDENTITY_ATOL = 1e-8

_IDENTITY = np.eye(4)
_IDENTITY.flags.writeable = False


def _from_right(matrices: tuple[NDArray[np.float64], ...]) -> NDArray[np.float64]:
    """``M1 @ (M2 @ (... @ Mk))`` with ``np.dot``: ``numpy.linalg.multi_dot``'s order for square matrices."""
    if not matrices:
        return _IDENTITY
    product = matrices[-1]
    for matrix in reversed(matrices[:-1]):
        product = np.dot(matrix, product)
    return product


#: A node's path state: the product (from the left) of transforms beyond the exact window, or
#: None, and the last transforms of its path (at most EXACT_PATH_TRANSFORMS).
_State = tuple["NDArray[np.float64] | None", tuple["NDArray[np.float64]", ...]]


def _child_state(state: _State, matrix: NDArray[np.float64] | None) -> _State:
    head, tail = state
    if matrix is None or np.abs(matrix - _IDENTITY).max() <= IDENTITY_ATOL:
        return state
    tail = (*tail, matrix)
    if len(tail) > EXACT_PATH_TRANSFORMS:
        head = tail[0] if head is None else np.dot(head, tail[0])
        tail = tail[1:]
    return head, tail


def node_transforms(graph: trimesh.scene.transforms.SceneGraph, nodes: set[Hashable]) -> dict[Hashable, NDArray[np.float64]]:
    """(4, 4) float64 transform from the root frame to each of ``nodes``, one walk of the tree.

    Parameters
    ----------
    graph : trimesh.scene.transforms.SceneGraph
        A scene's graph (``scene.graph``): a forest (one parent per node) with a matrix on
        each edge, the parent → child transform in the file's units.
    nodes : set
        The nodes whose transform is wanted (the mesh instances: ``graph.nodes_geometry``).

    Returns
    -------
    transforms : dict
        node → (4, 4) float64 matrix, ``graph.get(node)[0]`` of trimesh for paths of at most
        :data:`EXACT_PATH_TRANSFORMS` transforms (module docstring).  Read-only arrays.

    Raises
    ------
    ValueError
        A node of ``nodes`` is not below the root frame (trimesh: "No path").

    Notes
    -----
    Each edge below the root is visited once (``graph.transforms.edge_data`` read once per
    edge), and each node of ``nodes`` costs at most :data:`EXACT_PATH_TRANSFORMS` products.
    """
    from trimesh.transformations import fix_rigid

    forest, root, repair = graph.transforms, graph.base_frame, graph.repair_rigid
    edges, children = forest.edge_data, forest.children
    found: dict[Hashable, NDArray[np.float64]] = {}

    def finish(node: Hashable, state: _State, direct: NDArray[np.float64] | None) -> None:
        if direct is not None:
            matrix = direct  # one edge from the root: its matrix as it is, as trimesh takes it
        else:
            head, tail = state
            matrix = _from_right(tail) if head is None else np.dot(head, _from_right(tail))
        if repair is not None:
            matrix = fix_rigid(matrix, max_deviance=repair)
        matrix = matrix.view()
        matrix.flags.writeable = False
        found[node] = matrix

    start: _State = (None, ())
    if root in nodes:
        finish(root, start, None)
    # Depth first; a level is dropped when its last child is taken, so a chain holds one level
    # and memory grows with the levels that still have children to visit, not with the depth.
    stack: list[tuple[Hashable, _State, list[Hashable], int]] = [(root, start, children.get(root, []), 0)]
    seen = {root}
    while stack:
        parent, state, kids, index = stack.pop()
        if index >= len(kids):
            continue
        if index + 1 < len(kids):
            stack.append((parent, state, kids, index + 1))
        child = kids[index]
        if child in seen:  # a forest has no cycle; refuse to walk one if a graph holds it
            continue
        seen.add(child)
        edge = edges.get((parent, child), {})
        child_state = _child_state(state, edge.get("matrix"))
        if child in nodes:
            # trimesh takes an edge from the root as it is, whichever parent the forest kept
            direct = edges[(root, child)].get("matrix") if (root, child) in edges else None
            finish(child, child_state, direct)
        if child in children:
            stack.append((child, child_state, children[child], 0))
    missing = [node for node in nodes if node not in found]
    if missing:
        raise ValueError(f"{len(missing):,} mesh node(s) are not below the scene's root frame (first: {missing[0]!r})")
    return found


def mesh_instances(scene: trimesh.Scene) -> list[tuple[Hashable, str]]:
    """``(node, geometry name)`` of each triangle mesh instance of ``scene``, in the order of
    ``scene.graph.nodes_geometry``: the meshes :func:`flatten_scene` concatenates, in its order."""
    import trimesh

    graph = scene.graph
    instances = [(node, graph.transforms.node_data[node]["geometry"]) for node in graph.nodes_geometry]
    return [(node, name) for node, name in instances if isinstance(scene.geometry.get(name), trimesh.Trimesh)]


def flatten_scene(scene: trimesh.Scene) -> trimesh.Trimesh:
    """Every mesh of ``scene`` at its node, concatenated into one Trimesh (``Scene.to_mesh``, linear).

    Parameters
    ----------
    scene : trimesh.Scene
        As a trimesh loader returns it.

    Returns
    -------
    mesh : trimesh.Trimesh
        vertices (V, 3) float64 in the root frame (file units), faces (F, 3) int64; instances in
        the order of ``scene.graph.nodes_geometry``, each mesh's vertices and faces in file
        order.  Points and paths are dropped, as ``Scene.to_mesh`` drops them.

    Raises
    ------
    ValueError
        A mesh node not below the root frame.
    """
    import trimesh

    instances = mesh_instances(scene)
    transforms = node_transforms(scene.graph, {node for node, _ in instances})
    meshes = []
    for node, name in instances:
        # what Scene.dump does for each instance: a copy, the transform applied, named
        current = scene.geometry[name].copy()
        current.apply_transform(transforms[node])
        current.metadata["name"] = name
        current.metadata["node"] = node
        meshes.append(current)
    return trimesh.util.concatenate(meshes)
