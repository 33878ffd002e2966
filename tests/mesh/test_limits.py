"""Hostile glTF files: sizes declared to exhaust memory or time are refused before trimesh allocates.

Each file is built here, a few hundred bytes to a few MB.  The loads run in a child process
under a memory limit (RLIMIT_AS) and a wall-clock guard, so that the code before the fix fails
the test (MemoryError, killed, or minutes of work) instead of taking the machine down.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.mesh.limits import (
    MAX_MESH_FACES,
    MAX_SCENE_DEPTH,
    MAX_SCENE_NODES,
    check_gltf_declared_sizes,
)
from zbuf_occlude.mesh.load import load_mesh

#: Memory the child may map: enough for Python, numpy and trimesh, far below any bomb.
_CHILD_MEMORY_BYTES = 3 << 30
#: A guard, not a measurement: the refusals take well under a second.
_CHILD_SECONDS = 60


def _load_in_child(path: Path) -> str:
    """Run load_mesh(path) in a child under a memory limit; return what it printed (the error)."""
    code = textwrap.dedent(
        f"""
        import resource, sys
        resource.setrlimit(resource.RLIMIT_AS, ({_CHILD_MEMORY_BYTES}, {_CHILD_MEMORY_BYTES}))
        from zbuf_occlude.errors import MeshLoadError
        from zbuf_occlude.mesh.load import load_mesh
        try:
            load_mesh(sys.argv[1])
        except MeshLoadError as exc:
            print("MeshLoadError:", exc)
        else:
            print("loaded")
        """
    )
    try:
        done = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=_CHILD_SECONDS, check=False)
    except subprocess.TimeoutExpired:
        pytest.fail(f"load_mesh({path.name}) ran past {_CHILD_SECONDS} s")
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


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
    out = _load_in_child(path)
    assert "MeshLoadError" in out and str(path) in out and "accessors declare" in out, out


def test_node_instancing_past_the_face_cap_is_refused(tmp_path: Path) -> None:
    doc = _triangle_mesh(3 * 100_000)  # 1e5 triangles, instanced by 300 nodes: 3e7
    doc.update(nodes=[{"mesh": 0, "translation": [i, 0, 0]} for i in range(300)], scenes=[{"nodes": list(range(300))}])
    path = _gltf(tmp_path, doc)
    out = _load_in_child(path)
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


def test_a_200000_node_chain_is_refused_in_seconds(tmp_path: Path) -> None:
    """trimesh flattens a chain in quadratic time (385 s for 200,000 nodes); the check is linear."""
    n = 200_000
    nodes = [{"children": [i + 1]} for i in range(n - 1)] + [{"mesh": 0}]
    path = _gltf(tmp_path, {**_triangle_mesh(3), "nodes": nodes, "scenes": [{"nodes": [0]}]})
    out = _load_in_child(path)
    assert "MeshLoadError" in out and f"{MAX_SCENE_NODES:,}" in out, out


def test_a_chain_deeper_than_the_cap_is_refused(tmp_path: Path) -> None:
    n = MAX_SCENE_DEPTH + 1
    nodes = [{"children": [i + 1]} for i in range(n - 1)] + [{"mesh": 0}]
    path = _gltf(tmp_path, {**_triangle_mesh(3), "nodes": nodes, "scenes": [{"nodes": [0]}]})
    with pytest.raises(MeshLoadError, match=rf"{n:,} deep.*{MAX_SCENE_DEPTH}"):
        load_mesh(path)


def test_a_node_cycle_is_refused() -> None:
    doc = {"asset": {"version": "2.0"}, "nodes": [{"children": [1]}, {"children": [0]}]}
    with pytest.raises(MeshLoadError, match="cycle.gltf: .*cycle"):
        check_gltf_declared_sizes(json.dumps(doc).encode(), "cycle.gltf")


def test_glb_json_chunk_is_checked(tmp_path: Path) -> None:
    import struct

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
