"""Inputs: layouts of mesh trees (ModelNet, ShapeNetCore v1/v2, class folders, flat, list
file), --class-from, refused labels, broken links, FIFOs, and bad --out values.

Every tree is built in the test from small trimesh boxes, so nothing here needs ../shared.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
import trimesh

from zbuf_occlude.cli.main import main
from zbuf_occlude.dataset.layout import CARD_FILE, SHAPE_NAMES_FILE
from zbuf_occlude.errors import InvalidInputError

#: One pose, one small sample: a run over a test tree takes seconds.
TINY = ["--views", "0:0", "--points", "32", "--resolution", "64", "--samples-per-view", "1", "--dense-points", "500"]
EXTRA = {"generate": [], "farm": ["--no-progress"]}

CHAIR, PLANE = "03001627", "02691156"
#: ShapeNetCore's taxonomy.json entries (the real file has more fields; these are the ones read).
TAXONOMY = [
    {"synsetId": CHAIR, "name": "chair", "children": ["03002096"], "numInstances": 6778},
    {"synsetId": PLANE, "name": "airplane,aeroplane,plane", "children": [], "numInstances": 4045},
]


def _box(path: Path, k: int = 0) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents=(1.0, 0.5 + 0.1 * k, 0.3)).export(path)
    return path


def shapenet_tree(root: Path, version: int = 2, taxonomy: bool = True) -> Path:
    """Two chairs and one airplane; model id ``m1`` is in both synsets (as in ShapeNetCore)."""
    rel = "models/model_normalized.obj" if version == 2 else "model.obj"
    for k, (synset, model_id) in enumerate([(CHAIR, "m1"), (CHAIR, "m2"), (PLANE, "m1")]):
        _box(root / synset / model_id / rel, k)
    if taxonomy:
        (root / "taxonomy.json").write_text(json.dumps(TAXONOMY), encoding="utf-8")
    return root


def _run(command: str, root: Path, out: Path, *extra: str) -> int:
    return main([command, str(root), "--out", str(out), *TINY, *EXTRA[command], *extra])


def _card(out: Path) -> dict:
    return json.loads((out / CARD_FILE).read_text(encoding="utf-8"))


# -- ShapeNetCore ------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("command", ["farm", "generate"])
def test_a_shapenetcore_v2_tree_gets_its_real_class_names(tmp_path: Path, command: str) -> None:
    root = shapenet_tree(tmp_path / "ShapeNetCore.v2")
    out = tmp_path / "out"
    assert _run(command, root, out) == 0
    card = _card(out)
    assert card["shape_names"] == ["airplane", "chair"]  # not ["models"]
    assert card["layout"] == "shapenetcore-v2"
    assert (out / SHAPE_NAMES_FILE).read_text() == "airplane\nchair\n"
    manifest = [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]
    assert sorted((m["name"], m["class_name"]) for m in manifest) == [
        (f"{PLANE}/m1", "airplane"), (f"{CHAIR}/m1", "chair"), (f"{CHAIR}/m2", "chair"),
    ]  # fmt: skip


@pytest.mark.parametrize("version", [1, 2])
@pytest.mark.parametrize("entry", ["farm", "generate"])
def test_shapenetcore_without_taxonomy_is_labelled_by_synset_id(tmp_path: Path, version: int, entry: str) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects, scan_paths

    root = shapenet_tree(tmp_path / "sn", version=version, taxonomy=False)
    objects = scan_objects(root).objects if entry == "farm" else scan_paths([root])[0]
    assert {(o.name, o.class_name, o.split) for o in objects} == {
        (f"{CHAIR}/m1", CHAIR, "train"), (f"{CHAIR}/m2", CHAIR, "train"), (f"{PLANE}/m1", PLANE, "train"),
    }  # fmt: skip
    assert scan_objects(root).layout == f"shapenetcore-v{version}"


def test_one_synset_folder_given_takes_the_synset_from_its_own_name(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    root = shapenet_tree(tmp_path / "sn", taxonomy=False)
    scan = scan_objects(root / CHAIR)
    assert [(o.name, o.class_name) for o in scan.objects] == [(f"{CHAIR}/m1", CHAIR), (f"{CHAIR}/m2", CHAIR)]


@pytest.mark.parametrize(
    "text, message",
    [("{not json", "not a readable JSON file"), ('{"a": 1}', "expected a list"),
     ('[{"synsetId": 3, "name": "x"}]', "entry 0 needs text fields"), ('[{"synsetId": "1", "name": "a\\nb"}]', "not printable")],
)  # fmt: skip
def test_a_broken_taxonomy_is_an_error_naming_the_file(tmp_path: Path, text: str, message: str) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    root = shapenet_tree(tmp_path / "sn", taxonomy=False)
    (root / "taxonomy.json").write_text(text, encoding="utf-8")
    with pytest.raises(InvalidInputError, match=message) as info:
        scan_objects(root)
    assert str(root / "taxonomy.json") in str(info.value)


# -- the other layouts ---------------------------------------------------------------------
@pytest.mark.parametrize(
    "files, layout, labels",
    [
        (["chair/train/a.off", "chair/test/b.off", "sofa/train/c.off"], "modelnet",
         {"chair/train/a": ("chair", "train"), "chair/test/b": ("chair", "test"), "sofa/train/c": ("sofa", "train")}),
        (["chair_0001.off", "chair_0002.off", "sofa_0001.off"], "flat",
         {"chair_0001": ("chair", "train"), "chair_0002": ("chair", "train"), "sofa_0001": ("sofa", "train")}),
        (["chair/a.obj", "sofa/b.obj"], "class-folders", {"chair/a": ("chair", "train"), "sofa/b": ("sofa", "train")}),
    ],
)  # fmt: skip
def test_each_layout_is_detected_and_labels_its_meshes(tmp_path: Path, files, layout, labels) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    for k, rel in enumerate(files):
        _box(tmp_path / "root" / rel, k)
    scan = scan_objects(tmp_path / "root")
    assert scan.layout == layout
    assert {o.name: (o.class_name, o.split) for o in scan.objects} == labels


def test_a_modelnet_class_folder_given_alone_keeps_its_class(tmp_path: Path) -> None:
    # the class folder is the root itself: its name is the class, not "train"
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    _box(tmp_path / "chair" / "train" / "a.off")
    _box(tmp_path / "chair" / "test" / "b.off")
    scan = scan_objects(tmp_path / "chair")
    assert (scan.layout, {o.class_name for o in scan.objects}) == ("modelnet", {"chair"})


def test_a_list_file_is_recorded_as_its_layout(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    _box(tmp_path / "a.off")
    (tmp_path / "list.txt").write_text("a.off chair test\n", encoding="utf-8")
    scan = scan_objects(tmp_path / "list.txt")
    assert scan.layout == "list-file" and [(o.class_name, o.split) for o in scan.objects] == [("chair", "test")]
    with pytest.raises(InvalidInputError, match="--class-from applies to folders"):
        scan_objects(tmp_path / "list.txt", class_from=1)


# a mesh in a folder of its own (a glTF with its buffer), or in any folder below its class folder
NESTED = ["car/van.obj", "car/sedan.obj", "pedestrian/man.obj", "pedestrian/walker/scene.obj", "pedestrian/walker/scene.bin"]


@pytest.mark.parametrize("entry", ["farm", "generate"])
def test_a_mesh_in_a_folder_of_its_own_takes_the_class_folder_above(tmp_path: Path, entry: str) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_inputs, scan_objects

    for k, rel in enumerate(NESTED):
        if rel.endswith(".bin"):
            (tmp_path / "root" / rel).write_bytes(b"\0" * 8)  # beside the mesh, not a mesh
        else:
            _box(tmp_path / "root" / rel, k)
    scan = scan_objects(tmp_path / "root") if entry == "farm" else scan_inputs([tmp_path / "root"])
    assert scan.layout == "class-folders" and scan.skipped == []
    assert {o.name: (o.class_name, o.split) for o in scan.objects} == {
        "car/sedan": ("car", "train"), "car/van": ("car", "train"),
        "pedestrian/man": ("pedestrian", "train"), "pedestrian/walker/scene": ("pedestrian", "train"),  # not "walker"
    }  # fmt: skip


def test_the_split_of_a_nested_mesh_is_the_split_folder_below_its_class(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    for k, rel in enumerate(["car/train/van.obj", "car/test/beetle/scene.obj", "pole/lamp.obj"]):
        _box(tmp_path / "root" / rel, k)
    scan = scan_objects(tmp_path / "root")
    assert {o.name: (o.class_name, o.split) for o in scan.objects} == {
        "car/train/van": ("car", "train"), "car/test/beetle/scene": ("car", "test"), "pole/lamp": ("pole", "train"),
    }  # fmt: skip


@pytest.mark.parametrize("command", ["farm", "generate"])
def test_meshes_loose_beside_class_folders_exit_2_naming_them(tmp_path: Path, capsys, command: str) -> None:
    # the folder's own name is no class of the others: which class "stray.obj" is in, no folder says
    for k, rel in enumerate(["stray.obj", "car/van.obj", "pole/lamp.obj"]):
        _box(tmp_path / "root" / rel, k)
    assert _run(command, tmp_path / "root", tmp_path / "out") == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error:") and "\n" not in err, err
    assert "stray.obj" in err and "class folder" in err and "list file" in err
    assert not (tmp_path / "out" / "records").exists()


def test_a_sub_folder_of_several_meshes_is_part_of_its_class_and_said_so(tmp_path: Path, caplog) -> None:
    # vehicle/car/ may be a class of its own or a group inside "vehicle": the class is the
    # folder below the root, and the run says which folders it took as part of their class
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    for k, rel in enumerate(["vehicle/car/a.obj", "vehicle/car/b.obj", "vehicle/bus.obj", "plant/tree.obj"]):
        _box(tmp_path / "root" / rel, k)
    with caplog.at_level("WARNING", logger="zbuf_occlude.mesh.inputs.layouts"):
        scan = scan_objects(tmp_path / "root")
    assert {o.name: o.class_name for o in scan.objects} == {
        "vehicle/car/a": "vehicle", "vehicle/car/b": "vehicle", "vehicle/bus": "vehicle", "plant/tree": "plant",
    }  # fmt: skip
    assert "vehicle/car" in caplog.text and "--class-from" in caplog.text


# -- refused labels and --class-from -----------------------------------------------------------
DEGENERATE = {
    # ShapeNet-like but not ShapeNetCore's file names: ModelNet's rule gives "models" to all
    "container": [f"{CHAIR}/m1/models/model.obj", f"{PLANE}/m2/models/model.obj"],
    # all meshes in one sub-folder: one class for everything
    "one class": ["chairs/a.obj", "chairs/b.obj"],
    # one file name everywhere: the folders above are objects, not classes
    "object folders": ["id1/mesh.obj", "id2/mesh.obj"],
}


@pytest.mark.parametrize("command", ["farm", "generate"])
@pytest.mark.parametrize("kind", sorted(DEGENERATE))
def test_a_tree_whose_classes_look_wrong_exits_2(tmp_path: Path, capsys, command: str, kind: str) -> None:
    for k, rel in enumerate(DEGENERATE[kind]):
        _box(tmp_path / "root" / rel, k)
    assert _run(command, tmp_path / "root", tmp_path / "out") == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error:") and "\n" not in err, err
    assert "--class-from" in err and "list file" in err
    assert not (tmp_path / "out" / "records").exists()


@pytest.mark.slow
@pytest.mark.parametrize("command", ["farm", "generate"])
def test_class_from_names_the_class_folder(tmp_path: Path, command: str) -> None:
    for k, rel in enumerate(DEGENERATE["container"]):
        _box(tmp_path / "root" / rel, k)
    out = tmp_path / "out"
    assert _run(command, tmp_path / "root", out, "--class-from", "3") == 0
    card = _card(out)
    assert card["shape_names"] == [PLANE, CHAIR] and card["layout"] == "class-from:3"


def test_class_from_confirms_one_class_and_takes_the_split_below_it(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    for k, rel in enumerate(["chairs/a.obj", "chairs/b.obj"]):
        _box(tmp_path / "root" / rel, k)
    assert {o.class_name for o in scan_objects(tmp_path / "root", class_from=1).objects} == {"chairs"}
    _box(tmp_path / "mn" / "chair" / "test" / "x" / "mesh.off")
    (obj,) = scan_objects(tmp_path / "mn", class_from=3).objects
    assert (obj.class_name, obj.split) == ("chair", "test")


@pytest.mark.parametrize("value", ["0", "-1"])
def test_class_from_below_1_exits_2_naming_the_value(tmp_path: Path, capsys, value: str) -> None:
    _box(tmp_path / "root" / "chair" / "a.obj")
    assert _run("generate", tmp_path / "root", tmp_path / "out", "--class-from", value) == 2
    assert f"--class-from must be an integer >= 1 (1: the folder holding each file), got {value}" in capsys.readouterr().err


# -- what cannot be used is reported -------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("command", ["generate", "farm"])
def test_broken_links_and_link_loops_are_skipped_reported_and_recorded(tmp_path: Path, capsys, command: str) -> None:
    root = tmp_path / "root"
    _box(root / "chair" / "train" / "a.off")
    _box(root / "chair" / "train" / "b.off", 1)
    dangling = root / "chair" / "train" / "gone.off"
    os.symlink(tmp_path / "nowhere.off", dangling)
    loop = root / "chair" / "train" / "loop.off"
    os.symlink(loop, loop)
    out = tmp_path / "out"
    assert _run(command, root, out) == 1
    captured = capsys.readouterr()
    report = captured.out + captured.err
    assert "Traceback" not in captured.err
    for path in (dangling, loop):
        assert f"SKIPPED {path}" in report or f"SKIPPED   {path}" in report, report
    skipped = {s["path"]: s["reason"] for s in _card(out)["skipped_inputs"]}  # relative to the input root
    assert skipped["chair/train/gone.off"].startswith("dangling symbolic link")
    assert skipped["chair/train/loop.off"].startswith("symbolic link loop")
    # nothing of the builder's machine: not the input root, nor the link's (absolute) target
    assert str(tmp_path) not in json.dumps(_card(out))
    assert _card(out)["n_objects_ok"] == 2


def test_a_fifo_in_a_tree_is_reported_never_opened(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.discovery import walk_mesh_files

    _box(tmp_path / "a.off")
    os.mkfifo(tmp_path / "pipe.off")
    files, skipped = walk_mesh_files(tmp_path)
    assert files == [tmp_path / "a.off"]
    assert [(s.path, s.reason) for s in skipped] == [(str(tmp_path / "pipe.off"), "not a regular file (a FIFO); never opened")]


def test_a_fifo_in_a_list_file_is_skipped_with_a_warning(tmp_path: Path, caplog) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    _box(tmp_path / "a.off")
    os.mkfifo(tmp_path / "pipe.off")
    (tmp_path / "list.txt").write_text("a.off chair\npipe.off chair\n", encoding="utf-8")
    scan = scan_objects(tmp_path / "list.txt")
    assert [o.name for o in scan.objects] == ["a"]
    assert [(s.path, s.reason) for s in scan.skipped] == [(str(tmp_path / "pipe.off"), "not a regular file (a FIFO); never opened")]
    assert "pipe.off" in caplog.text


# -- --out and PATH mistakes ---------------------------------------------------------------------
@pytest.mark.parametrize("value", ["", "   "])
@pytest.mark.parametrize("command", ["generate", "farm"])
def test_an_empty_out_exits_2_naming_the_value(tmp_path: Path, capsys, monkeypatch, command: str, value: str) -> None:
    root = tmp_path / "root"
    _box(root / "chair" / "train" / "a.off")
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert _run(command, root, Path(value) if value.strip() else value) == 2  # type: ignore[arg-type]
    assert f"--out must name a folder, got {value!r}" in capsys.readouterr().err
    assert list(work.iterdir()) == []


def test_farm_merge_with_an_empty_out_exits_2(tmp_path: Path, capsys) -> None:
    assert main(["farm-merge", str(tmp_path), "--out", " "]) == 2
    assert "--out must name a folder, got ' '" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["generate", "farm"])
def test_out_naming_a_file_says_so(tmp_path: Path, capsys, command: str) -> None:
    root = tmp_path / "root"
    _box(root / "chair" / "train" / "a.off")
    (tmp_path / "out").write_text("mine\n")
    assert _run(command, root, tmp_path / "out") == 2
    err = capsys.readouterr().err
    assert f"the output folder {tmp_path / 'out'} is a file, not a folder" in err and "File exists" not in err
    assert (tmp_path / "out").read_text() == "mine\n"


def test_generate_refuses_a_file_that_is_no_mesh_before_making_out(tmp_path: Path, capsys) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("not a mesh\n")
    assert main(["generate", str(notes), "--out", str(tmp_path / "out"), *TINY]) == 2
    err = capsys.readouterr().err
    assert f"{notes} is not a mesh file" in err
    assert not (tmp_path / "out").exists()


def test_a_list_file_larger_than_the_cap_is_refused_before_it_is_read(tmp_path: Path, monkeypatch) -> None:
    from zbuf_occlude.mesh.inputs import plan
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    _box(tmp_path / "a.off")
    (tmp_path / "list.txt").write_text("a.off chair\n" * 10, encoding="utf-8")  # 120 bytes
    monkeypatch.setattr(plan, "MAX_LIST_BYTES", 100)  # stands for 64 MiB
    with pytest.raises(InvalidInputError, match=r"list\.txt: 120 bytes, more than the 100 a file read here may have"):
        scan_objects(tmp_path / "list.txt")
