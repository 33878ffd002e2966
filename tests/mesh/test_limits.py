"""Hostile glTF and COLLADA files: sizes declared to exhaust memory or time are refused before trimesh allocates.

Each file is built here, a few hundred bytes to a few MB.  The loads run in a child process
under a memory limit (RLIMIT_AS) and a wall-clock guard, so that the code before the fix fails
the test (MemoryError, killed, or minutes of work) instead of taking the machine down.
"""

from __future__ import annotations

import base64
import importlib.util
import json
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.mesh.limits import (
    MAX_MESH_FACES,
    MAX_MESH_INSTANCES,
    MAX_SCENE_DEPTH,
    MAX_SCENE_NODES,
    check_collada_declared_sizes,
    check_gltf_declared_sizes,
    count_collada_scene,
)
from zbuf_occlude.mesh.load import load_mesh

#: Memory the child may map: enough for Python, numpy and trimesh, far below any bomb.
_CHILD_MEMORY_BYTES = 3 << 30
#: A guard, not a measurement: the refusals take well under a second.
_CHILD_SECONDS = 60


needs_collada = pytest.mark.skipif(importlib.util.find_spec("collada") is None, reason="pycollada (extra 'collada') not installed")


def _load_in_child(path: Path) -> str:
    """Run load_mesh(path) in a child under a memory limit; return what it printed (the error, or the bounds)."""
    code = textwrap.dedent(
        f"""
        import resource, sys
        resource.setrlimit(resource.RLIMIT_AS, ({_CHILD_MEMORY_BYTES}, {_CHILD_MEMORY_BYTES}))
        from zbuf_occlude.errors import MeshLoadError
        from zbuf_occlude.mesh.load import load_mesh
        try:
            mesh = load_mesh(sys.argv[1], normalize=False, up="+z")
        except MeshLoadError as exc:
            print("MeshLoadError:", exc)
        else:
            print("loaded", len(mesh.faces), mesh.bounds.tolist())
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
    out = _load_in_child(path)
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


# -- COLLADA -------------------------------------------------------------------------------
def _dae(geometry_triangles: int, library_nodes: str, scene_nodes: str, *, doctype: str = "") -> str:
    """A COLLADA 1.4 file: one geometry ``g`` of ``geometry_triangles`` triangles over 3 vertices."""
    p = " ".join(["0 1 2"] * geometry_triangles)
    return f"""<?xml version="1.0" encoding="utf-8"?>{doctype}
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit meter="1"/><up_axis>Z_UP</up_axis></asset>
  <library_geometries><geometry id="g"><mesh>
    <source id="g-pos"><float_array id="g-pos-a" count="9">0 0 0 1 0 0 0 1 0</float_array>
      <technique_common><accessor source="#g-pos-a" count="3" stride="3">
        <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>
    <vertices id="g-v"><input semantic="POSITION" source="#g-pos"/></vertices>
    <triangles count="{geometry_triangles}"><input semantic="VERTEX" source="#g-v" offset="0"/><p>{p}</p></triangles>
  </mesh></geometry></library_geometries>
  <library_nodes>{library_nodes}</library_nodes>
  <library_visual_scenes><visual_scene id="s">{scene_nodes}</visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#s"/></scene>
</COLLADA>
"""


def _doubling_nodes(levels: int) -> str:
    """``n0`` places ``g``; each ``n{k}`` places ``n{k-1}`` twice: ``n{levels}`` is 2**levels copies of ``g``."""
    nodes = ['<node id="n0"><instance_geometry url="#g"/></node>']
    nodes += [f'<node id="n{k}"><node><instance_node url="#n{k - 1}"/></node><node><translate>1 0 0</translate>'
              f'<instance_node url="#n{k - 1}"/></node></node>' for k in range(1, levels + 1)]  # fmt: skip
    return "".join(nodes)


@needs_collada
def test_collada_instancing_past_the_face_cap_is_refused_before_trimesh(tmp_path: Path) -> None:
    # 10,000 triangles placed 2**11 times through instance_node: 20,480,000 triangles from 60 KB.
    # Unchecked, trimesh copies the vertices per instance (GBs); the child's memory limit stops it.
    path = tmp_path / "bomb.dae"
    path.write_text(_dae(10_000, _doubling_nodes(11), '<node><instance_node url="#n11"/></node>'))
    assert path.stat().st_size < 100_000
    out = _load_in_child(path)
    assert f"MeshLoadError: {path}: declares 20,480,000 triangles after node instancing" in out and f"{MAX_MESH_FACES:,}" in out, out


def test_collada_instances_past_the_cap_are_refused() -> None:
    text = _dae(1, _doubling_nodes(17), '<node><instance_node url="#n17"/></node>')
    with pytest.raises(MeshLoadError, match=rf"many.dae: places 131,072 mesh instances, more than the {MAX_MESH_INSTANCES:,}"):
        check_collada_declared_sizes(text.encode(), "many.dae")


def test_collada_nodes_that_instance_an_ancestor_are_refused() -> None:
    nodes = '<node id="a"><instance_geometry url="#g"/><node><instance_node url="#b"/></node></node><node id="b"><instance_node url="#a"/></node>'
    with pytest.raises(MeshLoadError, match="cycle.dae: .*cycle"):
        check_collada_declared_sizes(_dae(1, nodes, '<node><instance_node url="#a"/></node>').encode(), "cycle.dae")


@needs_collada
def test_collada_nesting_deeper_than_the_cap_is_refused(tmp_path: Path) -> None:
    # pycollada and trimesh read nodes by recursion: 2,000 levels end in RecursionError
    depth = 2_000
    path = tmp_path / "deep.dae"
    path.write_text(_dae(1, "", "<node>" * depth + '<instance_geometry url="#g"/>' + "</node>" * depth))
    with pytest.raises(MeshLoadError, match=rf"deep.dae: its nodes nest {depth:,} deep.*{MAX_SCENE_DEPTH}"):
        load_mesh(path)


@pytest.mark.parametrize(
    "doctype",
    [
        # billion laughs: each entity ten of the one before
        '<!DOCTYPE COLLADA [<!ENTITY a "ha"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;"><!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">]>',
        '<!DOCTYPE COLLADA [<!ENTITY secret SYSTEM "file:///etc/passwd">]>',  # an external file
    ],
)
@needs_collada
def test_collada_entities_are_refused(tmp_path: Path, doctype: str) -> None:
    path = tmp_path / "entity.dae"
    path.write_text(_dae(1, "", '<node><instance_geometry url="#g"/></node>', doctype=doctype))  # declared, not even used
    with pytest.raises(MeshLoadError, match=r"entity.dae: the XML declares entities"):
        load_mesh(path)


def test_collada_that_is_not_xml_is_named() -> None:
    with pytest.raises(MeshLoadError, match=r"cut.dae: not well-formed XML \(.* at line \d+\)"):
        check_collada_declared_sizes(_dae(1, "", "").encode()[:-200], "cut.dae")


@needs_collada
def test_collada_counts_match_what_trimesh_loads(tmp_path: Path) -> None:
    """Polylist quads, polygons and triangles, placed by nested nodes and instance_node: the count is exact."""
    import trimesh

    quads = '<polylist count="2"><input semantic="VERTEX" source="#g-v" offset="0"/><input semantic="NORMAL" source="#g-v" offset="1"/>' \
            "<vcount>4 5</vcount><p>" + "0 0 1 1 2 2 0 0 " + "0 0 1 1 2 2 0 0 1 1 </p></polylist>"  # fmt: skip
    polygons = '<polygons count="1"><input semantic="VERTEX" source="#g-v" offset="0"/><p>0 1 2 0 1 2</p></polygons>'
    text = _dae(7, _doubling_nodes(2), '<node><instance_node url="#n2"/><node><instance_geometry url="#g"/></node></node>')
    text = text.replace("</triangles>", "</triangles>" + quads + polygons)
    path = tmp_path / "mixed.dae"
    path.write_text(text)
    counts = count_collada_scene(text.encode(), path)
    loaded = trimesh.load_scene(str(path), process=False)
    # g is 7 + 5 (a quad, a pentagon) + 4 (a hexagon) triangles, placed 4 times through n2 and once directly
    assert counts.faces == (7 + 2 + 3 + 4) * 5 == sum(len(g.faces) for g in loaded.dump())
    assert counts.instances == 3 * 5 == len(loaded.graph.nodes_geometry)
    assert counts.depth == 6  # the scene's node > n2 > its inner node > n1 > its inner node > n0


@pytest.mark.parametrize("skinned", [True, False])
def test_a_skinned_gltf_warns_that_it_loads_in_its_bind_pose(tmp_path: Path, caplog: pytest.LogCaptureFixture, skinned: bool) -> None:
    """trimesh applies no skin: a simulator's character comes in its T-pose, which the user must be told."""
    node = {"mesh": 0, "skin": 0} if skinned else {"mesh": 0}
    doc = {**_embedded_triangle(), "nodes": [node, {"name": "hip"}], "scenes": [{"nodes": [0, 1]}]}
    if skinned:
        doc["skins"] = [{"joints": [1]}]
    path = _gltf(tmp_path, doc, name="walker.gltf")
    with caplog.at_level("WARNING", logger="zbuf_occlude.mesh.formats"):
        mesh = load_mesh(path, normalize=False)
    assert len(mesh.faces) == 1
    warned = [r.getMessage() for r in caplog.records if "bind pose" in r.getMessage()]
    assert warned == ([f"{path}: 1 skinned mesh node(s) load in their bind pose (often a T-pose): skins and animations are not applied"]
                      if skinned else [])  # fmt: skip
