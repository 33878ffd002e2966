"""Real-world mesh assets: glTF (embedded and external buffers), COLLADA, up axes, units, sizes."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import numpy as np
import pytest
import trimesh

from zbuf_occlude.errors import InvalidInputError, MeshLoadError
from zbuf_occlude.mesh.load import METADATA_KEY, load_mesh
from zbuf_occlude.mesh.scene import collada_asset, gltf_generator, up_rotation

#: The street-object meshes (research-only, next to the repository; skipped when absent).
STREET_OBJECTS = (
    Path(os.environ.get("ZBUF_OCCLUDE_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data")) / "street_objects"
)
needs_collada = pytest.mark.skipif(importlib.util.find_spec("collada") is None, reason="pycollada (extra 'collada') not installed")


def _y_up_tall_box() -> trimesh.Trimesh:
    """A box 1 wide (x), 3 tall along +y (glTF's up), 0.5 deep (z)."""
    return trimesh.creation.box(extents=(1.0, 3.0, 0.5))


#: What trimesh writes as ``asset.generator`` and what Blender's exporter writes, padded to the
#: same length (JSON whitespace) so that a GLB's chunk lengths stay right.
TRIMESH_GENERATOR = b'"https://github.com/mikedh/trimesh"'
BLENDER_GENERATOR = b'"Khronos glTF Blender I/O v4.1.63"'.ljust(len(TRIMESH_GENERATOR))


def as_blender_writes(data: bytes) -> bytes:
    """glTF or GLB bytes written by trimesh, relabelled as Blender's exporter's, which follows
    the specification (+y up); the vertices are untouched."""
    assert TRIMESH_GENERATOR in data
    return data.replace(TRIMESH_GENERATOR, BLENDER_GENERATOR)


def _export_y_up_glb(mesh: trimesh.Trimesh, path: Path) -> Path:
    path.write_bytes(as_blender_writes(mesh.export(file_type="glb")))
    return path


def _tall_with_z_up(mesh: trimesh.Trimesh) -> None:
    ext = mesh.extents
    assert ext[2] == pytest.approx(1.0)  # normalised: the height is the largest side
    assert ext[2] > 2.5 * ext[0] and ext[2] > 2.5 * ext[1]


def test_y_up_glb_box_arrives_tall_with_z_up(tmp_path: Path) -> None:
    path = _export_y_up_glb(_y_up_tall_box(), tmp_path / "tall.glb")
    mesh = load_mesh(path)
    _tall_with_z_up(mesh)
    meta = mesh.metadata[METADATA_KEY]
    assert meta["up"] == "+y" and "glTF" in meta["up_source"]
    np.testing.assert_allclose(meta["extent"], [1.0, 0.5, 3.0], atol=1e-6)  # z-up, file units
    np.testing.assert_allclose(meta["extent_m"], [1.0, 0.5, 3.0], atol=1e-6)  # glTF: metres
    # the rotation is proper (no mirror): +y → +z and +z → −y
    raw = load_mesh(path, normalize=False)
    np.testing.assert_allclose(raw.bounds, [[-0.5, -0.25, -1.5], [0.5, 0.25, 1.5]], atol=1e-6)
    assert load_mesh(path, up="+z").extents[1] == pytest.approx(1.0)  # as stored: tall along y


@pytest.mark.parametrize("file_type", ["glb", "gltf"])
def test_z_up_box_written_by_trimesh_comes_back_standing(tmp_path: Path, file_type: str) -> None:
    # trimesh writes the vertices unconverted and says so in asset.generator: read as stored
    tall = trimesh.creation.box(extents=(1.0, 0.5, 3.0))  # tall along z
    path = tmp_path / f"z_up.{file_type}"
    tall.export(path)
    mesh = load_mesh(path)
    _tall_with_z_up(mesh)
    assert mesh.metadata[METADATA_KEY]["up"] == "+z" and "trimesh" in mesh.metadata[METADATA_KEY]["up_source"]
    _tall_with_z_up(load_mesh(path, up="+z"))


def test_gltf_generator_is_read_from_the_head_only() -> None:
    assert gltf_generator(b'{"asset":{"generator" : "Khronos glTF Blender I/O v1.6.16","version":"2.0"}}') == (
        "Khronos glTF Blender I/O v1.6.16"
    )
    assert gltf_generator(b'{"asset":{"version":"2.0"}}') is None
    assert gltf_generator(b" " * (1 << 16) + b'"generator":"trimesh"') is None  # beyond the head: the spec's rule


@pytest.mark.parametrize("rel", ["02691156/1a2b3c/models/model_normalized.obj", "03001627/4d5e6f/model.obj"])
def test_shapenet_layout_y_up_box_arrives_tall_along_z(tmp_path: Path, rel: str, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / rel
    path.parent.mkdir(parents=True)
    path.write_text(trimesh.exchange.obj.export_obj(_y_up_tall_box(), header=None))  # no exporter comment
    mesh = load_mesh(path)
    _tall_with_z_up(mesh)
    assert mesh.metadata[METADATA_KEY]["up"] == "+y" and "ShapeNetCore" in mesh.metadata[METADATA_KEY]["up_source"]
    assert load_mesh(path, up="+z").extents[1] == pytest.approx(1.0)  # told otherwise: as stored
    depth = 3 if "models" in rel else 2  # folders below the synset
    monkeypatch.chdir(path.parents[depth - 1])  # inside the synset folder: the path given names no synset
    _tall_with_z_up(load_mesh(Path(*path.parts[-depth:])))
    # the same file outside a ShapeNetCore layout (no 8-digit synset folder) is read as stored
    other = tmp_path / "chairs" / "abc" / "model.obj"
    other.parent.mkdir(parents=True)
    other.write_bytes(path.read_bytes())
    assert load_mesh(other).metadata[METADATA_KEY]["up"] == "+z"


def test_gltf_embedded_and_external_buffers(tmp_path: Path) -> None:
    scene = trimesh.Scene()
    scene.add_geometry(_y_up_tall_box())
    wheel = trimesh.creation.icosphere(subdivisions=1, radius=0.25)
    scene.add_geometry(wheel, transform=trimesh.transformations.translation_matrix([2.0, 0.0, 0.0]))
    embedded = tmp_path / "embedded"
    external = tmp_path / "external"
    for folder, embed in ((embedded, True), (external, False)):
        folder.mkdir()
        for name, data in trimesh.exchange.gltf.export_gltf(scene, embed_buffers=embed).items():
            (folder / name).write_bytes(as_blender_writes(data) if name.endswith(".gltf") else data)
    assert len(list(external.glob("*.bin"))) >= 1 and not list(embedded.glob("*.bin"))
    for folder in (embedded, external):
        raw = load_mesh(folder / "model.gltf", normalize=False)
        assert len(raw.faces) == 12 + len(wheel.faces)  # both parts, the node transform baked in
        np.testing.assert_allclose(raw.bounds, [[-0.5, -0.25, -1.5], [2.25, 0.25, 1.5]], atol=1e-6)


def test_gltf_buffer_outside_its_folder_is_refused(tmp_path: Path) -> None:
    folder = tmp_path / "model"
    folder.mkdir()
    files = trimesh.exchange.gltf.export_gltf(trimesh.Scene(_y_up_tall_box()), embed_buffers=False)
    text = files["model.gltf"].decode()
    for name, data in files.items():
        if name.endswith(".bin"):
            (tmp_path / name).write_bytes(data)  # beside the folder, not in it
            text = text.replace(f'"{name}"', f'"../{name}"')
    (folder / "model.gltf").write_text(text)
    with pytest.raises(MeshLoadError, match="model.gltf"):
        load_mesh(folder / "model.gltf")


@needs_collada
def test_collada_round_trip_with_declared_up_axis_and_unit(tmp_path: Path) -> None:
    box = trimesh.creation.box(extents=(1.0, 2.0, 4.0))
    text = trimesh.exchange.dae.export_collada(box).decode()
    assert "<up_axis>Y_UP</up_axis>" in text  # pycollada's default
    plain = tmp_path / "box.dae"
    plain.write_text(text)
    raw = load_mesh(plain, normalize=False, up="+z")
    assert len(raw.faces) == 12 and raw.area == pytest.approx(box.area)
    np.testing.assert_allclose(raw.bounds, box.bounds, atol=1e-6)
    y_up = load_mesh(plain, normalize=False)  # auto: the declared Y_UP
    np.testing.assert_allclose(y_up.extents, [1.0, 4.0, 2.0], atol=1e-6)
    z_up = tmp_path / "z_up_cm.dae"
    z_up.write_text(text.replace("<up_axis>Y_UP</up_axis>", '<unit meter="0.01" name="centimeter"/><up_axis>Z_UP</up_axis>'))
    mesh = load_mesh(z_up)
    meta = mesh.metadata[METADATA_KEY]
    assert meta["up"] == "+z" and meta["units_m"] == pytest.approx(0.01)
    np.testing.assert_allclose(meta["extent_m"], [0.01, 0.02, 0.04], atol=1e-9)


def test_collada_without_pycollada_names_the_extra(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "box.dae"
    path.write_text('<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1"/>')
    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "collada" else real_find_spec(name, *a))
    with pytest.raises(MeshLoadError, match=r"box\.dae.*pip install 'pycollada[^']*' \(the collada extra\)"):
        load_mesh(path)


def test_obj_up_axis_from_its_exporter(tmp_path: Path) -> None:
    body = trimesh.exchange.obj.export_obj(_y_up_tall_box(), header=None)
    blender = tmp_path / "blender.obj"
    blender.write_text("# Blender v2.79 (sub 0) OBJ File: ''\n# www.blender.org\n" + body)
    _tall_with_z_up(load_mesh(blender))
    plain = tmp_path / "plain.obj"
    plain.write_text("# written by hand\n" + body)
    assert load_mesh(plain).metadata[METADATA_KEY]["up"] == "+z"  # no convention: as stored
    _tall_with_z_up(load_mesh(plain, up="+y"))


@pytest.mark.parametrize("axis", ["+x", "-x", "+y", "-y", "+z", "-z"])
def test_up_rotation_is_proper_and_sends_the_axis_to_z(axis: str) -> None:
    m = up_rotation(axis)[:3, :3]
    v = np.zeros(3)
    v["xyz".index(axis[1])] = 1.0 if axis[0] == "+" else -1.0
    np.testing.assert_allclose(m @ v, [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(m) == pytest.approx(1.0)


def test_bad_up_axis_is_refused(tmp_path: Path) -> None:
    path = _export_y_up_glb(_y_up_tall_box(), tmp_path / "box.glb")
    with pytest.raises(InvalidInputError, match="'up'|up axis"):
        load_mesh(path, up="y")


def test_collada_asset_reads_only_what_is_declared() -> None:
    assert collada_asset(b"<asset><up_axis> Z_UP </up_axis><unit meter='0.0254'/></asset>") == ("+z", 0.0254)
    assert collada_asset(b"<asset></asset>") == (None, None)
    assert collada_asset(b'<unit meter="-3"/><up_axis>W_UP</up_axis>') == (None, None)


# -- the street-object meshes (research-only, next to the repository) ---------------------


def _street_files() -> list[Path]:
    if not STREET_OBJECTS.is_dir():
        return []
    return sorted(p for p in STREET_OBJECTS.rglob("*") if p.suffix.lower() in (".obj", ".glb", ".gltf", ".dae"))


@pytest.mark.slow
@needs_collada
@pytest.mark.skipif(not _street_files(), reason="../shared/data/street_objects not present")
def test_every_street_object_loads_and_cars_are_longer_than_tall() -> None:
    files = _street_files()
    assert len(files) == 48
    for path in files:
        mesh = load_mesh(path)
        ext = mesh.extents
        assert abs(ext.max() - 1.0) < 1e-9, path
        if path.parent.name == "car":
            assert max(ext[0], ext[1]) > 1.5 * ext[2], (path, ext)  # longer than tall
        if path.parent.name in ("pole", "pedestrian") or path.parent.parent.name == "pedestrian":
            assert ext[2] >= max(ext[0], ext[1]) - 0.02, (path, ext)  # taller than wide (T-poses: ≈)


#: A COLLADA triangle whose material names a texture that is not there (as Gazebo models do).
COLLADA_WITH_MISSING_TEXTURE = """<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
<asset><up_axis>Z_UP</up_axis></asset>
<library_images><image id="img"><init_from>../materials/textures/missing.png</init_from></image></library_images>
<library_effects><effect id="eff"><profile_COMMON>
 <newparam sid="surf"><surface type="2D"><init_from>img</init_from></surface></newparam>
 <newparam sid="samp"><sampler2D><source>surf</source></sampler2D></newparam>
 <technique sid="common"><lambert><emission><texture texture="samp" texcoord="UV"/></emission>
  <diffuse><texture texture="samp" texcoord="UV"/></diffuse></lambert></technique>
</profile_COMMON></effect></library_effects>
<library_materials><material id="mat"><instance_effect url="#eff"/></material></library_materials>
<library_geometries><geometry id="g"><mesh>
 <source id="pos"><float_array id="pa" count="9">0 0 0 1 0 0 0 1 2</float_array><technique_common>
  <accessor source="#pa" count="3" stride="3"><param name="X" type="float"/><param name="Y" type="float"/>
  <param name="Z" type="float"/></accessor></technique_common></source>
 <vertices id="v"><input semantic="POSITION" source="#pos"/></vertices>
 <triangles count="1" material="m"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles>
</mesh></geometry></library_geometries>
<library_visual_scenes><visual_scene id="s"><node id="n"><instance_geometry url="#g"><bind_material><technique_common>
 <instance_material symbol="m" target="#mat"/></technique_common></bind_material></instance_geometry></node></visual_scene>
</library_visual_scenes>
<scene><instance_visual_scene url="#s"/></scene>
</COLLADA>
"""


@needs_collada
def test_collada_textures_are_not_loaded_and_log_nothing(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "sign.dae"
    path.write_text(COLLADA_WITH_MISSING_TEXTURE)
    with caplog.at_level("DEBUG"):
        mesh = load_mesh(path, normalize=False)
    assert len(mesh.faces) == 1 and mesh.bounds[1][2] == pytest.approx(2.0)  # the geometry, Z_UP as stored
    noisy = [r for r in caplog.records if r.levelno >= 30 or r.exc_info]
    assert not noisy, [r.getMessage() for r in noisy]  # no warning, no traceback per material


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
@pytest.mark.parametrize(("name", "file_type"), [("pipe.obj", "obj"), ("pipe.glb", "glb"), ("pipe.dae", "dae")])
def test_the_head_of_a_fifo_is_never_waited_for(tmp_path: Path, name: str, file_type: str) -> None:
    # the up axis and units read a file's head: a FIFO would block until a writer came
    from zbuf_occlude.mesh.scene import declared_units_m, resolve_up

    os.mkfifo(tmp_path / name)
    with pytest.raises(MeshLoadError, match=rf"{name}: is a FIFO; only regular files are read"):
        resolve_up(tmp_path / name, file_type, "auto")
    if file_type == "dae":
        with pytest.raises(MeshLoadError, match=rf"{name}: is a FIFO"):
            declared_units_m(tmp_path / name, file_type)
