"""Files a mesh names (glTF buffers, OBJ materials) are read only when regular and inside its folder: a FIFO never blocks."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.mesh.named_files import folder_resolver

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")

#: A guard, not a measurement: a refusal is immediate, a blocked reader waits forever.
_CHILD_SECONDS = 30

_LOAD = """
import sys
from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.mesh.load import load_mesh
try:
    mesh = load_mesh(sys.argv[1])
except MeshLoadError as exc:
    print("MeshLoadError:", exc)
else:
    print("loaded", len(mesh.faces))
"""


def _load_in_child(path: Path) -> str:
    try:
        done = subprocess.run([sys.executable, "-c", _LOAD, str(path)], capture_output=True, text=True, timeout=_CHILD_SECONDS, check=False)
    except subprocess.TimeoutExpired:
        pytest.fail(f"load_mesh({path.name}) blocked for {_CHILD_SECONDS} s on a FIFO it names")
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def test_gltf_buffer_uri_naming_a_fifo_is_refused(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "data.bin")
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "buffers": [{"uri": "data.bin", "byteLength": 36}], "bufferViews": [{"buffer": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}],
    }  # fmt: skip
    path = tmp_path / "fifo.gltf"
    path.write_text(json.dumps(doc))
    out = _load_in_child(path)
    assert "MeshLoadError" in out and "data.bin" in out and "FIFO" in out, out


@pytest.mark.slow
def test_obj_mtllib_naming_a_fifo_does_not_block(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "mat.mtl")
    path = tmp_path / "tri.obj"
    path.write_text("mtllib mat.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    out = _load_in_child(path)
    # trimesh treats a material it cannot read as absent; the geometry is what matters here.
    assert "loaded 1" in out, out


def test_the_mesh_file_itself_may_not_be_a_fifo(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "pipe.obj")
    out = _load_in_child(tmp_path / "pipe.obj")
    assert "MeshLoadError" in out and "FIFO" in out, out


def test_resolver_keeps_names_inside_the_folder(tmp_path: Path) -> None:
    (tmp_path / "secret").write_bytes(b"s")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "ok.bin").write_bytes(b"ok")
    resolver = folder_resolver(tmp_path / "sub" / "mesh.gltf")
    assert resolver.get("ok.bin") == b"ok"
    with pytest.raises(MeshLoadError, match=r"mesh\.gltf: a file it names: the path leaves"):
        resolver.get("../secret")
    (tmp_path / "sub" / "link").symlink_to(tmp_path / "secret")
    with pytest.raises(MeshLoadError, match="link"):
        resolver.get("link")
