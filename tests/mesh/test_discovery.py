"""Mesh discovery: files of 3D formats that are not read are reported, files beside meshes are
not, and a format whose optional package is missing is refused before any work.

Every tree is built in the test from small trimesh boxes, so nothing here needs ../shared.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest
import trimesh

from zbuf_occlude.cli.main import main
from zbuf_occlude.dataset.layout import CARD_FILE
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude._version import install_hint

#: One pose, one small sample: a run over a test tree takes seconds.
TINY = ["--views", "0:0", "--points", "32", "--resolution", "64", "--samples-per-view", "1", "--dense-points", "500"]
#: The smallest COLLADA document: discovery never parses it.
EMPTY_DAE = '<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1"/>'


def _box(path: Path, k: int = 0) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents=(1.0, 0.5 + 0.1 * k, 0.3)).export(path)
    return path


def _write(path: Path, data: bytes | str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    (path.write_bytes if isinstance(data, bytes) else path.write_text)(data)
    return path


def _tree_with_unread_formats(root: Path) -> Path:
    for k, rel in enumerate(["chair/a.obj", "chair/b.obj", "sofa/c.obj"]):
        _box(root / rel, k)
    _write(root / "chair" / "d.fbx", b"Kaydara FBX Binary  \x00")
    _write(root / "sofa" / "e.BLEND", b"BLENDER-v293")
    return root


# -- 3D formats that are not read --------------------------------------------------------------
@pytest.mark.parametrize("entry", ["walk", "farm", "generate"])
def test_files_of_3d_formats_not_read_are_skipped_with_the_reason(tmp_path: Path, entry: str, caplog) -> None:
    from zbuf_occlude.mesh.inputs.discovery import walk_mesh_files
    from zbuf_occlude.mesh.inputs.plan import scan_inputs, scan_objects

    root = _tree_with_unread_formats(tmp_path / "root")
    if entry == "walk":
        files, skipped = walk_mesh_files(root)
        assert [f.name for f in files] == ["a.obj", "b.obj", "c.obj"]
    else:
        scan = scan_objects(root) if entry == "farm" else scan_inputs([root])
        assert [o.name for o in scan.objects] == ["chair/a", "chair/b", "sofa/c"]
        skipped = scan.skipped
    reasons = {s.path: s.reason for s in skipped}
    assert sorted(reasons) == [str(root / "chair" / "d.fbx"), str(root / "sofa" / "e.BLEND")]
    assert reasons[str(root / "chair" / "d.fbx")].startswith("FBX: a 3D format zbuf-occlude does not read")
    assert reasons[str(root / "sofa" / "e.BLEND")].startswith("Blender: a 3D format zbuf-occlude does not read")
    assert all(".glb" in r and "convert" in r for r in reasons.values())
    assert "d.fbx" in caplog.text


def test_files_beside_meshes_are_not_reported(tmp_path: Path) -> None:
    # a glTF's buffer and textures, an OBJ's materials, the notes of a collection: no meshes, no inputs
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    root = tmp_path / "root"
    for name, data in trimesh.exchange.gltf.export_gltf(trimesh.Scene(trimesh.creation.box())).items():
        _write(root / "car" / "beetle" / name, data)
    _box(root / "car" / "van.obj")
    _write(root / "car" / "van.mtl", "newmtl grey\nKd 0.5 0.5 0.5\n")
    _write(root / "car" / "beetle" / "textures" / "paint.png", b"\x89PNG\r\n\x1a\n")
    _box(root / "pole" / "lamp.obj", 1)
    for notes in ("README", "LICENSE", "SOURCE.md", "MANIFEST.csv"):
        _write(root / notes, "text\n")
    scan = scan_objects(root)
    assert scan.skipped == []
    assert sorted(o.name for o in scan.objects) == ["car/beetle/model", "car/van", "pole/lamp"]


def test_a_file_given_in_a_format_not_read_names_the_format(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.discovery import check_input_file

    with pytest.raises(InvalidInputError, match=r"car\.fbx: FBX: a 3D format zbuf-occlude does not read.*convert"):
        check_input_file(tmp_path / "car.fbx")


@pytest.mark.slow
def test_generate_reports_files_it_does_not_read_and_exits_1(tmp_path: Path, capsys) -> None:
    root = _tree_with_unread_formats(tmp_path / "root")
    out = tmp_path / "out"
    assert main(["generate", str(root), "--out", str(out), *TINY]) == 1
    err = capsys.readouterr().err
    assert f"SKIPPED {root / 'chair' / 'd.fbx'}: FBX: a 3D format" in err, err
    card = json.loads((out / CARD_FILE).read_text(encoding="utf-8"))
    assert sorted(s["path"] for s in card["skipped_inputs"]) == ["chair/d.fbx", "sofa/e.BLEND"]
    assert card["n_objects_ok"] == 3


# -- a format whose package is missing ------------------------------------------------------------
def _tree_with_collada(root: Path) -> Path:
    for k, rel in enumerate(["chair/a.obj", "sofa/b.obj"]):
        _box(root / rel, k)
    for rel in ["sofa/c.dae", "sofa/d.DAE", "lamp/e.dae"]:
        _write(root / rel, EMPTY_DAE)
    return root


@pytest.fixture
def no_pycollada(monkeypatch: pytest.MonkeyPatch) -> None:
    """``import collada`` fails as it does without the ``collada`` extra."""
    monkeypatch.setitem(sys.modules, "collada", None)


@pytest.mark.parametrize("entry", ["farm", "generate", "validate"])
def test_a_format_without_its_package_is_refused_at_discovery(tmp_path: Path, no_pycollada, entry: str) -> None:
    from zbuf_occlude.mesh.inputs.discovery import scan_meshes
    from zbuf_occlude.mesh.inputs.plan import scan_inputs, scan_objects

    root = _tree_with_collada(tmp_path / "root")
    scan = {"farm": scan_objects, "generate": lambda r: scan_inputs([r]), "validate": lambda r: scan_meshes([r])}[entry]
    with pytest.raises(BackendUnavailable) as info:
        scan(root)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("3 COLLADA files (.dae) need the 'collada' package, not installed"), message
    assert install_hint("collada") in message and "pip install 'pycollada" in message  # a command that works from any directory
    assert str(root / "lamp" / "e.dae") in message  # one of them, to find them by


def test_the_package_is_checked_once_per_format_not_per_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    root = _tree_with_collada(tmp_path / "root")
    asked: list[str] = []
    real_find_spec = importlib.util.find_spec

    def counting_find_spec(name: str, *args):
        asked.append(name)
        return real_find_spec(name, *args)

    monkeypatch.setattr(importlib.util, "find_spec", counting_find_spec)
    scan_objects(root)
    assert asked.count("collada") == 1


def test_a_format_left_out_by_the_selection_needs_no_package(tmp_path: Path, no_pycollada) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    root = _tree_with_collada(tmp_path / "root")
    assert [o.name for o in scan_objects(root, classes="chair").objects] == ["chair/a"]


@pytest.mark.parametrize("command", ["generate", "farm"])
def test_a_run_without_the_package_exits_2_before_any_work(tmp_path: Path, capsys, no_pycollada, command: str) -> None:
    root = _tree_with_collada(tmp_path / "root")
    out = tmp_path / "out"
    extra = ["--no-progress"] if command == "farm" else []
    assert main([command, str(root), "--out", str(out), *TINY, *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error: 3 COLLADA files (.dae) need the 'collada' package") and "\n" not in err, err
    assert not out.exists()  # nothing written, not even the folder
