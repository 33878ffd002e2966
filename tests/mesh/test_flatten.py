"""Scene flattening: trimesh's Scene.to_mesh, bit for bit, in one walk of the scene graph."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.mesh.flatten import EXACT_PATH_TRANSFORMS, flatten_scene, node_transforms

needs_collada = pytest.mark.skipif(importlib.util.find_spec("collada") is None, reason="pycollada (extra 'collada') not installed")


def _matrix(kind: str, rng: np.random.Generator) -> np.ndarray:
    """An edge matrix of each kind trimesh's rule treats apart."""
    if kind == "identity":
        return np.eye(4)
    if kind == "near_identity":  # within 1e-8: trimesh leaves it out of a path's product
        return np.eye(4) + 1e-9 * rng.standard_normal((4, 4)) * np.array([1, 1, 1, 0])[:, None]
    m = trimesh.transformations.random_rotation_matrix(rng.random(3))
    m[:3, 3] = rng.normal(size=3) * 10
    if kind == "scaled":  # a mirror and a scale: not rigid
        m = m @ np.diag([-2.0, 0.5, 3.0, 1.0])
    if kind == "column_major":  # as trimesh's glTF reader leaves a node's "matrix" (reshape then .T)
        m = np.ascontiguousarray(m.T).T
    return m


def _random_scene(parents: list[int], kinds: list[str], meshes: list[bool], seed: int) -> trimesh.Scene:
    """Node i hangs under node parents[i] (< i) or the root (-1); a triangle of its own where meshes[i]."""
    rng = np.random.default_rng(seed)
    scene = trimesh.Scene()
    root = scene.graph.base_frame
    for i, (parent, kind, has_mesh) in enumerate(zip(parents, kinds, meshes, strict=True)):
        kwargs = {"frame_to": f"n{i}", "frame_from": root if parent < 0 else f"n{parent}", "matrix": _matrix(kind, rng)}
        if has_mesh:
            scene.geometry[f"g{i}"] = trimesh.Trimesh(rng.normal(size=(3, 3)), [[0, 1, 2]], process=False)
            kwargs["geometry"] = f"g{i}"
        scene.graph.update(**kwargs)
    return scene


@st.composite
def forests(draw: st.DrawFn) -> tuple[list[int], list[str], list[bool], int]:
    n = draw(st.integers(1, 24))
    # parents mostly the node just before: deep paths of many transforms
    parents = [draw(st.one_of(st.just(i - 1), st.integers(-1, i - 1))) for i in range(n)]
    kinds = draw(st.lists(st.sampled_from(["identity", "near_identity", "rigid", "scaled", "column_major"]), min_size=n, max_size=n))
    meshes = draw(st.lists(st.booleans(), min_size=n, max_size=n))
    return parents, kinds, meshes, draw(st.integers(0, 2**32 - 1))


@given(forests())
@settings(max_examples=60, deadline=None)
def test_transforms_and_mesh_equal_trimesh_bit_for_bit(forest: tuple[list[int], list[str], list[bool], int]) -> None:
    scene = _random_scene(*forest)
    geometry_nodes = set(scene.graph.nodes_geometry)
    ours = node_transforms(scene.graph, geometry_nodes)
    for node in geometry_nodes:  # paths of at most 24 transforms: within the exact window
        np.testing.assert_array_equal(ours[node], scene.graph.get(node)[0], err_msg=str(node))
    if geometry_nodes:
        flat, theirs = flatten_scene(scene), scene.to_mesh()
        np.testing.assert_array_equal(flat.vertices, theirs.vertices)
        np.testing.assert_array_equal(flat.faces, theirs.faces)


def test_a_path_longer_than_the_exact_window_is_the_same_matrix_up_to_rounding() -> None:
    n = EXACT_PATH_TRANSFORMS + 20
    scene = _random_scene(list(range(-1, n - 1)), ["rigid"] * n, [False] * (n - 1) + [True], seed=7)
    leaf = f"n{n - 1}"
    np.testing.assert_allclose(node_transforms(scene.graph, {leaf})[leaf], scene.graph.get(leaf)[0], rtol=0, atol=1e-9)


def test_a_mesh_node_off_the_root_is_an_error() -> None:
    scene = trimesh.Scene()
    scene.geometry["g"] = trimesh.creation.box()
    scene.graph.update(frame_to="lost", frame_from="elsewhere", geometry="g")
    with pytest.raises(ValueError, match="not below the scene's root frame"):
        flatten_scene(scene)


class _CountedEdges(dict):
    """A scene graph's edge table that counts how often it is read."""

    reads = 0

    def get(self, key, default=None):
        self.reads += 1
        return super().get(key, default)

    def __getitem__(self, key):
        self.reads += 1
        return super().__getitem__(key)

    def __contains__(self, key) -> bool:
        self.reads += 1
        return super().__contains__(key)


@pytest.mark.slow
def test_a_50000_deep_chain_is_walked_once() -> None:
    """Each edge read a bounded number of times (trimesh reads a path per mesh: n² / 2 here)."""
    n, every = 50_000, 1_000
    scene = trimesh.Scene()
    scene.geometry["tri"] = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False)
    step = trimesh.transformations.translation_matrix([1.0, 0.0, 0.0])
    parent = scene.graph.base_frame
    for i in range(n):
        extra = {"geometry": "tri"} if (i + 1) % every == 0 else {}
        scene.graph.update(frame_to=f"n{i}", frame_from=parent, matrix=step, **extra)
        parent = f"n{i}"
    forest = scene.graph.transforms
    forest.edge_data = counted = _CountedEdges(forest.edge_data)
    mesh = flatten_scene(scene)
    assert counted.reads <= 3 * n, counted.reads
    # the mesh under node i (depth i + 1) moved i + 1 along x
    np.testing.assert_array_equal(mesh.vertices[::3, 0], np.arange(every, n + 1, every, dtype=float))


def _nested_scene() -> trimesh.Scene:
    """A box and a cylinder under rotated, scaled parents, two deep, as an asset's parts are."""
    scene = trimesh.Scene()
    t = trimesh.transformations
    body = t.concatenate_matrices(t.translation_matrix([0.3, -1.2, 2.0]), t.rotation_matrix(0.7, [0.2, 1.0, 0.3]))
    scene.graph.update(frame_to="body", frame_from=scene.graph.base_frame, matrix=body)
    scene.graph.update(frame_to="axle", frame_from="body", matrix=t.rotation_matrix(1.1, [1, 0, 0]) @ np.diag([1.5, 1.5, 0.7, 1]))
    scene.add_geometry(trimesh.creation.box(extents=(4.0, 2.0, 1.0)), node_name="shell", parent_node_name="body",
                       transform=t.rotation_matrix(0.3, [0, 0, 1]))  # fmt: skip
    for side in (-1, 1):
        scene.add_geometry(trimesh.creation.cylinder(radius=0.4, height=0.3), node_name=f"wheel{side}", parent_node_name="axle",
                           transform=t.translation_matrix([1.3, side * 1.1, -0.5]) @ t.rotation_matrix(0.9, [0.3, 0.1, 1]))  # fmt: skip
    return scene


@pytest.mark.parametrize("file_type", ["glb", "gltf", pytest.param("dae", marks=needs_collada)])
def test_exported_files_flatten_as_trimesh_does(tmp_path: Path, file_type: str) -> None:
    path = tmp_path / f"car.{file_type}"
    if file_type == "dae":
        path.write_bytes(trimesh.exchange.dae.export_collada(_nested_scene().dump()))  # COLLADA: parts as exported
    else:
        _nested_scene().export(path)
    loaded = trimesh.load_scene(path, process=False)
    flat, theirs = flatten_scene(loaded), loaded.to_mesh()
    assert len(flat.faces) == 12 + 2 * len(trimesh.creation.cylinder(radius=0.4, height=0.3).faces)
    np.testing.assert_array_equal(flat.vertices, theirs.vertices)
    np.testing.assert_array_equal(flat.faces, theirs.faces)


def test_shipped_samples_load_as_before(sample_mesh_files: list[Path]) -> None:
    for path in sample_mesh_files:
        loaded = trimesh.load_scene(path, process=False)
        flat, theirs = flatten_scene(loaded), loaded.to_mesh()
        np.testing.assert_array_equal(flat.vertices, theirs.vertices)
        np.testing.assert_array_equal(flat.faces, theirs.faces)
