"""Files a mesh names (glTF buffers, OBJ materials) are read only when regular: a FIFO never blocks."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from zbuf_occlude.errors import InvalidInputError, MeshLoadError
from zbuf_occlude.mesh.named_files import (
    file_digest,
    folder_resolver,
    read_regular_file,
)

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


def test_read_regular_file_refuses_fifos_and_sizes_past_the_cap(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "pipe")
    with pytest.raises(MeshLoadError, match="pipe: is a FIFO"):
        read_regular_file(tmp_path / "pipe")
    with pytest.raises(InvalidInputError, match="pipe: is a FIFO"):
        file_digest(tmp_path / "pipe", max_bytes=10, error=InvalidInputError)
    (tmp_path / "big").write_bytes(b"x" * 11)
    with pytest.raises(MeshLoadError, match=r"big: 11 bytes, more than the 10"):
        read_regular_file(tmp_path / "big", max_bytes=10)
    with pytest.raises(MeshLoadError, match=r"big: 11 bytes, more than the 10"):
        file_digest(tmp_path / "big", max_bytes=10)
    assert read_regular_file(tmp_path / "big", max_bytes=11) == b"x" * 11


def test_resolver_keeps_names_inside_the_folder(tmp_path: Path) -> None:
    (tmp_path / "secret").write_bytes(b"s")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "ok.bin").write_bytes(b"ok")
    resolver = folder_resolver(tmp_path / "sub" / "mesh.gltf")
    assert resolver.get("ok.bin") == b"ok"
    with pytest.raises(MeshLoadError, match=r"mesh\.gltf: a file it names: '\.\./secret' leaves"):
        resolver.get("../secret")
    (tmp_path / "sub" / "link").symlink_to(tmp_path / "secret")
    with pytest.raises(MeshLoadError, match="link"):
        resolver.get("link")
