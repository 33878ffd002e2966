"""Hostile COLLADA files: instancing bombs, deep nesting, entities and cycles are refused before pycollada parses.

Each file is built here, a few KB.  The load that would allocate runs in a child process under a
memory limit and a wall-clock guard (``conftest.load_in_child``).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest
from conftest import load_in_child

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.mesh.formats.collada import (
    MAX_SCENE_DEPTH,
    check_collada_declared_sizes,
    count_collada_scene,
)
from zbuf_occlude.mesh.limits import MAX_MESH_FACES, MAX_MESH_INSTANCES
from zbuf_occlude.mesh.load import load_mesh

needs_collada = pytest.mark.skipif(importlib.util.find_spec("collada") is None, reason="pycollada (extra 'collada') not installed")


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


@pytest.mark.slow
@needs_collada
def test_collada_instancing_past_the_face_cap_is_refused_before_trimesh(tmp_path: Path) -> None:
    # 10,000 triangles placed 2**11 times through instance_node: 20,480,000 triangles from 60 KB.
    # Unchecked, trimesh copies the vertices per instance (GBs); the child's memory limit stops it.
    path = tmp_path / "bomb.dae"
    path.write_text(_dae(10_000, _doubling_nodes(11), '<node><instance_node url="#n11"/></node>'))
    assert path.stat().st_size < 100_000
    out = load_in_child(path)
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
