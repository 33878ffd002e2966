"""The table of formats and its dispatcher (``zbuf_occlude/mesh/formats/__init__.py``): the steps run in their documented order."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
import trimesh

from zbuf_occlude._version import install_hint
from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.mesh import formats
from zbuf_occlude.mesh.formats import (
    EXTENSIONS_TEXT,
    FORMATS,
    SUPPORTED_EXTENSIONS,
    read_trimesh,
)
from zbuf_occlude.mesh.formats.base import Format


def test_every_extension_maps_to_the_one_format_that_declares_it() -> None:
    assert list(SUPPORTED_EXTENSIONS) == [".off", ".obj", ".ply", ".stl", ".glb", ".gltf", ".dae"]  # the order --help lists
    assert EXTENSIONS_TEXT == ".off, .obj, .ply, .stl, .glb, .gltf, .dae"
    for file_type, fmt in FORMATS.items():
        assert fmt.file_type == file_type
        assert all(ext.startswith(".") and ext == ext.lower() for ext in fmt.extensions)
    declared = [ext for fmt in FORMATS.values() for ext in fmt.extensions]
    assert len(declared) == len(set(declared)) and set(declared) == set(SUPPORTED_EXTENSIONS)
    assert FORMATS["dae"].needs == ("collada", "collada") and all(f.needs is None for t, f in FORMATS.items() if t != "dae")


@pytest.fixture
def fake_format(monkeypatch: pytest.MonkeyPatch):
    """Registers a format "fake" whose steps append to the returned list; the test sets how they fail."""
    calls: list[tuple[str, bytes]] = []
    behaviour: dict[str, Exception] = {}

    def check(raw: bytes, path: Path) -> None:
        calls.append(("check", raw))
        if "check" in behaviour:
            raise behaviour["check"]

    def read(raw: bytes, path: Path, file_type: str) -> trimesh.Trimesh:
        calls.append(("read", raw))
        if "read" in behaviour:
            raise behaviour["read"]
        return trimesh.Trimesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]], process=False)

    def install(needs: tuple[str, str] | None = None) -> tuple[list[tuple[str, bytes]], dict[str, Exception]]:
        monkeypatch.setitem(FORMATS, "fake", Format("fake", (".fake",), read=read, check=check, needs=needs))
        return calls, behaviour

    return install


def test_the_check_runs_before_the_reader_on_the_same_bytes(tmp_path: Path, fake_format) -> None:
    calls, _ = fake_format()
    path = tmp_path / "a.fake"
    path.write_bytes(b"bytes of the file")
    mesh = read_trimesh(path, "fake")
    assert len(mesh.faces) == 1
    assert calls == [("check", b"bytes of the file"), ("read", b"bytes of the file")]


def test_a_failed_check_ends_the_load_before_the_reader(tmp_path: Path, fake_format) -> None:
    calls, behaviour = fake_format()
    path = tmp_path / "a.fake"
    behaviour["check"] = MeshLoadError(f"{path}: declares 9 faces but holds 1")
    path.write_bytes(b"x")
    with pytest.raises(MeshLoadError, match=rf"^{re.escape(str(path))}: declares 9 faces but holds 1$"):
        read_trimesh(path, "fake")
    assert [step for step, _ in calls] == ["check"]


def test_a_missing_package_is_named_before_the_file_is_checked(tmp_path: Path, fake_format) -> None:
    calls, _ = fake_format(needs=("no_such_module_zbuf", "extra-name"))
    path = tmp_path / "a.fake"
    path.write_bytes(b"x")
    with pytest.raises(
        MeshLoadError,
        match=rf"^{re.escape(str(path))}: reading FAKE needs the 'no_such_module_zbuf' package: {re.escape(install_hint('extra-name'))}$",
    ):
        read_trimesh(path, "fake")
    assert calls == []


def test_a_structure_that_contradicts_itself_is_named_with_the_format(tmp_path: Path) -> None:
    # a binary STL declaring 2 triangles and holding 1: the check of stl.py, through the table
    path = tmp_path / "cut.stl"
    path.write_bytes(b"\0" * 80 + (2).to_bytes(4, "little") + b"\0" * 50)
    with pytest.raises(
        MeshLoadError,
        match=rf"^{re.escape(str(path))}: cannot parse as STL: binary STL declares 2 triangles \(184 bytes\) but holds 1 \(134 bytes\); the file is cut short$",
    ):
        read_trimesh(path, "stl")


def test_other_errors_of_the_reader_are_left_to_load_mesh(tmp_path: Path, fake_format) -> None:
    _, behaviour = fake_format()
    behaviour["read"] = IndexError("trimesh's own")
    path = tmp_path / "a.fake"
    path.write_bytes(b"x")
    with pytest.raises(IndexError, match="trimesh's own"):
        read_trimesh(path, "fake")


def test_a_fifo_is_refused_before_any_step(tmp_path: Path, fake_format) -> None:
    calls, _ = fake_format()
    path = tmp_path / "a.fake"
    os.mkfifo(path)
    with pytest.raises(MeshLoadError, match="is a FIFO; only regular files are read"):
        read_trimesh(path, "fake")
    assert calls == []


def test_the_package_lists_its_format_modules() -> None:
    # one module per format family, each contributing its entries; the table holds them all
    modules = [formats.off, formats.obj, formats.ply, formats.stl, formats.gltf, formats.collada]
    assert [fmt for module in modules for fmt in module.FORMATS] == list(FORMATS.values())
