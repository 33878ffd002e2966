"""Hostile glTF files: sizes declared to exhaust memory or time are refused before trimesh allocates.

Each file is built here, a few hundred bytes to a few MB.  The loads that would allocate run in a
child process under a memory limit and a wall-clock guard (``conftest.load_in_child``).
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import pytest
from conftest import load_in_child

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.mesh.formats.gltf import check_gltf_declared_sizes
from zbuf_occlude.mesh.limits import MAX_MESH_FACES, MAX_MESH_INSTANCES, MAX_SCENE_NODES
from zbuf_occlude.mesh.load import load_mesh


def _gltf(tmp_path: Path, doc: dict, name: str = "bomb.gltf") -> Path:
    doc = {"asset": {"version": "2.0"}, "scene": 0, **doc}
    path = tmp_path / name
    path.write_text(json.dumps(doc, separators=(",", ":")))
    return path


def _triangle_mesh(n_indices: int) -> dict:
    """A mesh whose accessors have no bufferView (zeros by the specification): nothing stored, all declared."""
    return {
        "accessors": [{"componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 1]},
                      {"componentType": 5125, "count": n_indices, "type": "SCALAR"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
    }  # fmt: skip


def test_accessor_without_buffer_declaring_1e8_vectors_is_refused(tmp_path: Path) -> None:
    doc = _triangle_mesh(3)
    doc["accessors"][0]["count"] = 100_000_000  # 1.2 GB of zeros for positions
    doc["accessors"].append({"componentType": 5126, "count": 100_000_000, "type": "MAT4"})  # 6.4 GB more
    doc.update(nodes=[{"mesh": 0}], scenes=[{"nodes": [0]}])
    path = _gltf(tmp_path, doc)
    assert path.stat().st_size < 1000
    out = load_in_child(path)
    assert "MeshLoadError" in out and str(path) in out and "accessors declare" in out, out


def test_node_instancing_past_the_face_cap_is_refused(tmp_path: Path) -> None:
    doc = _triangle_mesh(3 * 100_000)  # 1e5 triangles, instanced by 300 nodes: 3e7
    doc.update(nodes=[{"mesh": 0, "translation": [i, 0, 0]} for i in range(300)], scenes=[{"nodes": list(range(300))}])
    path = _gltf(tmp_path, doc)
    out = load_in_child(path)
    assert "MeshLoadError" in out and "30,000,000 triangles" in out and f"{MAX_MESH_FACES:,}" in out, out


def test_shared_children_multiply_instances() -> None:
    # 8 levels of two nodes, each the child of both nodes above: the last level is reached
    # 2**7 ways per node, so 256 copies of a 1e5-triangle mesh from 16 nodes.
    doc = {"asset": {"version": "2.0"}, **_triangle_mesh(3 * 100_000)}
    levels = 8
    doc["nodes"] = [{"children": [2 * level + 2, 2 * level + 3]} if level < levels - 1 else {"mesh": 0}
                    for level in range(levels) for _ in range(2)]  # fmt: skip
    with pytest.raises(MeshLoadError, match="shared.gltf: declares 25,600,000 triangles after node instancing"):
        check_gltf_declared_sizes(json.dumps(doc).encode(), "shared.gltf")


@pytest.mark.slow
def test_more_nodes_than_the_cap_are_refused_before_the_walk() -> None:
    doc = {"asset": {"version": "2.0"}, "nodes": [{}] * (MAX_SCENE_NODES + 1)}
    with pytest.raises(MeshLoadError, match=rf"nodes.gltf: declares {MAX_SCENE_NODES + 1:,} scene nodes.*{MAX_SCENE_NODES:,}"):
        check_gltf_declared_sizes(json.dumps(doc).encode(), "nodes.gltf")


def _embedded_triangle() -> dict:
    """One triangle (0,0,0), (1,0,0), (0,1,0) in a base64 buffer: a mesh trimesh really reads."""
    data = b"".join(struct.pack("<3f", *v) for v in ((0, 0, 0), (1, 0, 0), (0, 1, 0)))
    return {
        "buffers": [{"byteLength": len(data), "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
        "bufferViews": [{"buffer": 0, "byteLength": len(data)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
    }


@pytest.mark.slow
def test_a_50000_deep_chain_loads_in_linear_time(tmp_path: Path) -> None:
    """Every node moves its child 1 along x; the triangle at the root and at the leaf.

    trimesh's Scene.to_mesh searches each node's path from the root (quadratic in the depth) and
    multiplies a path's matrices with multi_dot (cubic planning, recursion as deep as the path:
    RecursionError past ~1,000); the scene is now walked once.  The guard is a wall-clock limit
    for the child, not a measurement: the load takes a few seconds.
    """
    n = 50_000
    nodes = [{"children": [i + 1], "translation": [1, 0, 0]} for i in range(n - 1)] + [{"mesh": 0, "translation": [1, 0, 0]}]
    nodes[0]["mesh"] = 0
    path = _gltf(tmp_path, {**_embedded_triangle(), "nodes": nodes, "scenes": [{"nodes": [0]}]}, name="chain.gltf")
    out = load_in_child(path)
    assert out.startswith("loaded 2 "), out
    assert json.loads(out.split(" ", 2)[2]) == [[1.0, 0.0, 0.0], [n + 1.0, 1.0, 0.0]]  # the leaf moved n times


def test_instances_past_the_cap_are_refused() -> None:
    # 18 levels of two nodes, each the child of both above: 2**17 paths to each leaf node,
    # 262,144 one-triangle instances: few triangles, but a trimesh copy per instance
    doc = {"asset": {"version": "2.0"}, **_triangle_mesh(3)}
    levels = 18
    doc["nodes"] = [{"children": [2 * level + 2, 2 * level + 3]} if level < levels - 1 else {"mesh": 0}
                    for level in range(levels) for _ in range(2)]  # fmt: skip
    with pytest.raises(MeshLoadError, match=rf"many.gltf: places 262,144 mesh instances, more than the {MAX_MESH_INSTANCES:,}"):
        check_gltf_declared_sizes(json.dumps(doc).encode(), "many.gltf")


def test_a_node_cycle_is_refused() -> None:
    doc = {"asset": {"version": "2.0"}, "nodes": [{"children": [1]}, {"children": [0]}]}
    with pytest.raises(MeshLoadError, match="cycle.gltf: .*cycle"):
        check_gltf_declared_sizes(json.dumps(doc).encode(), "cycle.gltf")


def test_glb_json_chunk_is_checked(tmp_path: Path) -> None:
    doc = {"asset": {"version": "2.0"}, **_triangle_mesh(3)}
    doc["accessors"][0]["count"] = 10**12
    body = json.dumps(doc).encode()
    body += b" " * (-len(body) % 4)
    glb = b"glTF" + struct.pack("<II", 2, 20 + len(body)) + struct.pack("<I4s", len(body), b"JSON") + body
    path = tmp_path / "bomb.glb"
    path.write_bytes(glb)
    with pytest.raises(MeshLoadError, match=rf"{path.name}.*accessors declare"):
        load_mesh(path)


def test_a_small_scene_with_instances_still_loads(tmp_path: Path) -> None:
    import trimesh

    scene = trimesh.Scene()
    box = trimesh.creation.box()
    for i in range(3):
        scene.add_geometry(box, node_name=f"box{i}", geom_name="box", transform=trimesh.transformations.translation_matrix([2 * i, 0, 0]))
    path = tmp_path / "three.glb"
    scene.export(path)
    assert len(load_mesh(path).faces) == 3 * len(box.faces)


@pytest.mark.parametrize("skinned", [True, False])
def test_a_skinned_gltf_warns_that_it_loads_in_its_bind_pose(tmp_path: Path, caplog: pytest.LogCaptureFixture, skinned: bool) -> None:
    """trimesh applies no skin: a simulator's character comes in its T-pose, which the user must be told."""
    node = {"mesh": 0, "skin": 0} if skinned else {"mesh": 0}
    doc = {**_embedded_triangle(), "nodes": [node, {"name": "hip"}], "scenes": [{"nodes": [0, 1]}]}
    if skinned:
        doc["skins"] = [{"joints": [1]}]
    path = _gltf(tmp_path, doc, name="walker.gltf")
    with caplog.at_level("WARNING", logger="zbuf_occlude.mesh.formats.gltf"):
        mesh = load_mesh(path, normalize=False)
    assert len(mesh.faces) == 1
    warned = [r.getMessage() for r in caplog.records if "bind pose" in r.getMessage()]
    assert warned == ([f"{path}: 1 skinned mesh node(s) load in their bind pose (often a T-pose): skins and animations are not applied"]
                      if skinned else [])  # fmt: skip
