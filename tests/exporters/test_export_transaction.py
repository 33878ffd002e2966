"""``export`` as a transaction: the whole source checked before ``--out`` is made, the places and
the list lines checked first, a re-export that removes what the earlier one wrote and this one does
not (and nothing a user put there), and the Python API's arguments refused by kind, each in one line."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from conftest import SAMPLE_MESHES

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.errors import ArgumentTypeError, DatasetFormatError, InvalidInputError, UnsafePathError
from zbuf_occlude.exporters import export
from zbuf_occlude.farm import FarmParams, run_farm
from zbuf_occlude.farm.config import RunOptions

#: A chair (train) and a desk (test); the second data set has the chair alone.
BOTH = ("chair/train/chair_0001.off", "desk/test/desk_0201.off")
TRAIN_ONLY = ("chair/train/chair_0001.off",)
#: The files of the test split that PointNet's and Pointnet_Pointnet2_pytorch's layouts write.
POINTNET_TEST = ("ply_data_test0.h5", "ply_data_test_0_id2file.json", "test_files.txt")
MODELNET_TEST = ("modelnet40_test.txt", "desk/desk_0001.txt")


def _farm(out: Path, meshes: tuple[str, ...]) -> Path:
    """A dense farm data set of shipped meshes, two poses, one 64-point sample each (about a second)."""
    tree = out.parent / f"{out.name}_meshes"
    for rel in meshes:
        (tree / rel).parent.mkdir(parents=True, exist_ok=True)
        (tree / rel).symlink_to(SAMPLE_MESHES / rel)
    params = FarmParams(views="0:0,30:90", samples_per_view=1, n_points=64, dense_points=1024, resolution=64, storage="dense")
    run_farm(tree, out, params=params, options=RunOptions(progress=False))
    return out


@pytest.fixture(scope="module")
def sets(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("sets")
    return {"both": _farm(root / "both", BOTH), "train": _farm(root / "train", TRAIN_ONLY)}


def _listing(folder: Path) -> dict[str, bytes]:
    """Every file below ``folder`` (the layer's ledger and lock left out) and its bytes."""
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and not p.name.startswith(".zbuf_occlude")
    }


# -- the whole source before --out -------------------------------------------------------------
@pytest.mark.parametrize("to", ["pointnet-h5", "modelnet-txt"])
def test_a_tampered_shard_is_refused_before_anything_is_written(sets, tmp_path, to):
    source = tmp_path / "src"
    shutil.copytree(sets["both"], source)
    _tamper(source)
    with pytest.raises(DatasetFormatError, match=r"nothing was exported: .*train_\d+\.h5 differs from its SHA-256"):
        export(source, to, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def _tamper(source: Path) -> Path:
    """Flip the last byte of the train shard (read last: the splits are written in order, test first)."""
    shard = next(source.glob("shards/train_*.h5"))
    data = bytearray(shard.read_bytes())
    data[-1] ^= 0xFF  # same size, other bytes
    shard.write_bytes(bytes(data))
    return shard


def test_the_cli_refuses_a_tampered_source_in_one_line_and_makes_no_folder(sets, tmp_path, capsys):
    source = tmp_path / "src"
    shutil.copytree(sets["both"], source)
    shard = _tamper(source)
    assert cli_main(["export", str(source), "--to", "pointnet-h5", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err and shard.name in err
    assert not (tmp_path / "out").exists()


def test_a_source_whose_class_list_was_changed_is_refused_before_out_is_made(sets, tmp_path):
    source = tmp_path / "src"
    shutil.copytree(sets["both"], source)
    (source / "shape_names.txt").write_text("chair\ndesk\n\n")
    with pytest.raises(DatasetFormatError, match="shape_names.txt"):
        export(source, "pointnet-h5", tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_a_source_inside_out_is_refused_and_out_is_left_as_it_is(sets, tmp_path):
    outer = tmp_path / "outer"
    shutil.copytree(sets["both"], outer / "ds")
    (outer / "notes.txt").write_text("mine\n")
    before = _listing(outer)
    with pytest.raises(InvalidInputError, match=r"the data set .*ds lies inside out='.*outer'"):
        export(outer / "ds", "pointnet-h5", outer)
    assert _listing(outer) == before and not (outer / ".zbuf_occlude-written.jsonl").exists()


def test_out_inside_the_source_is_still_refused(sets, tmp_path):
    source = tmp_path / "src"
    shutil.copytree(sets["both"], source)
    with pytest.raises(InvalidInputError, match="inside the data set"):
        export(source, "pointnet-h5", source / "shards" / "export")
    assert not (source / "shards" / "export").exists()


@pytest.mark.parametrize("out", ["", "   ", "\t"])
def test_a_blank_out_is_refused_and_the_working_folder_is_left_alone(sets, tmp_path, monkeypatch, out):
    here = tmp_path / "cwd"
    here.mkdir()
    monkeypatch.chdir(here)
    with pytest.raises(InvalidInputError, match=r"out='.*': name a folder"):
        export(sets["both"], "pointnet-h5", out)
    assert not list(here.iterdir())


def test_a_blank_dataset_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(InvalidInputError, match="dataset='': name a folder"):
        export("", "pointnet-h5", tmp_path / "out")
    assert not (tmp_path / "out").exists()


# -- names on list lines ---------------------------------------------------------------------------
@pytest.mark.parametrize("bad", ["\r", "\n", "\x85", "\u2028", "\x0b", "\x1e"])
def test_a_control_character_in_the_list_prefix_is_refused(sets, tmp_path, bad):
    with pytest.raises(InvalidInputError, match=rf"list_prefix=.* holds the control character U\+{ord(bad):04X}"):
        export(sets["both"], "pointnet-h5", tmp_path / "out", list_prefix=f"data/a{bad}b")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("bad", ["\n", "\r", "\u2029"])
def test_a_line_break_in_outs_name_is_refused_where_it_goes_on_list_lines(sets, tmp_path, bad):
    out = tmp_path / f"mine{bad}evil"
    with pytest.raises(InvalidInputError, match=rf"out=.*: its name .* holds the control character U\+{ord(bad):04X}.*give list_prefix"):
        export(sets["both"], "pointnet-h5", out)
    assert not out.exists()
    export(sets["both"], "pointnet-h5", out, list_prefix="data/mine")  # the name is on no line then
    assert (out / "train_files.txt").read_text().splitlines() == ["data/mine/ply_data_train0.h5"]
    export(sets["both"], "modelnet-txt", tmp_path / f"txt{bad}")  # whose lists do not name the folder


def test_the_cli_refuses_a_control_character_in_one_line_naming_the_value(sets, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli_main(["export", str(sets["both"]), "--to", "pointnet-h5", "--out", str(out), "--list-prefix", "data/x\rdata/y"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and r"'data/x\rdata/y'" in err and "U+000D" in err
    assert not out.exists()


# -- a re-export ---------------------------------------------------------------------------------
def test_a_re_export_removes_the_earlier_splits_and_pointnet_lists_only_the_new_files(sets, tmp_path):
    out = tmp_path / "modelnet40_ply_hdf5_2048"
    export(sets["both"], "pointnet-h5", out)
    assert all((out / name).is_file() for name in POINTNET_TEST)
    (out / "notes.txt").write_text("mine\n")  # a user's files: the ledger does not record them
    (out / "ply_data_val0.h5").write_bytes(b"mine too")
    export(sets["train"], "pointnet-h5", out)
    assert not any((out / name).exists() for name in POINTNET_TEST)
    assert (out / "notes.txt").read_text() == "mine\n" and (out / "ply_data_val0.h5").read_bytes() == b"mine too"
    listed = [line for f in sorted(out.glob("*_files.txt")) for line in f.read_text().splitlines()]
    assert listed == [f"data/{out.name}/ply_data_train0.h5"]
    assert all((out / Path(line).name).is_file() for line in listed)
    assert (out / "shape_names.txt").read_text() == "chair\n"


def test_a_re_export_to_modelnet_txt_removes_the_earlier_split_and_its_folders(sets, tmp_path):
    out = tmp_path / "modelnet40_normal_resampled"
    export(sets["both"], "modelnet-txt", out)
    assert all((out / name).is_file() for name in MODELNET_TEST)
    export(sets["train"], "modelnet-txt", out)
    assert not any((out / name).exists() for name in MODELNET_TEST) and not (out / "desk").exists()
    assert (out / "modelnet40_train.txt").read_text().split() == ["chair_0001", "chair_0002"]


def test_a_changed_file_of_the_earlier_export_is_refused_before_any_is_written(sets, tmp_path):
    out = tmp_path / "out"
    export(sets["both"], "pointnet-h5", out)
    (out / "test_files.txt").write_text("edited by hand\n")
    before = _listing(out)
    with pytest.raises(UnsafePathError, match="test_files.txt"):
        export(sets["train"], "pointnet-h5", out)
    assert _listing(out) == before


def test_a_hard_link_to_an_exported_file_keeps_its_bytes(sets, tmp_path):
    """The layer replaces and removes names: a second name of a file of ours, outside --out, is never written through."""
    out = tmp_path / "out"
    export(sets["both"], "pointnet-h5", out)
    kept = {name: tmp_path / f"kept_{name}" for name in ("ply_data_test0.h5", "shape_names.txt")}
    for name, link in kept.items():
        os.link(out / name, link)
    before = {name: link.read_bytes() for name, link in kept.items()}
    export(sets["train"], "pointnet-h5", out)
    assert not (out / "ply_data_test0.h5").exists() and (out / "shape_names.txt").read_text() == "chair\n"
    assert {name: link.read_bytes() for name, link in kept.items()} == before


def test_an_earlier_folder_that_now_links_out_is_refused_and_nothing_outside_is_removed(sets, tmp_path):
    out = tmp_path / "out"
    export(sets["both"], "modelnet-txt", out)
    elsewhere = tmp_path / "elsewhere"
    shutil.move(out / "desk", elsewhere)  # the same bytes, the ledger's names, but outside --out now
    (out / "desk").symlink_to(elsewhere)
    before = _listing(out)
    with pytest.raises(UnsafePathError, match="leads outside"):
        export(sets["train"], "modelnet-txt", out)
    assert (elsewhere / "desk_0001.txt").is_file() and _listing(out) == before


def test_a_fifo_where_the_earlier_export_wrote_a_file_is_refused_unopened(sets, tmp_path):
    out = tmp_path / "out"
    export(sets["both"], "pointnet-h5", out)
    (out / "test_files.txt").unlink()
    os.mkfifo(out / "test_files.txt")
    with pytest.raises(UnsafePathError, match=r"test_files\.txt is a link or not a regular file"):
        export(sets["train"], "pointnet-h5", out)
    assert (out / "ply_data_test0.h5").is_file()


# -- the Python API's arguments ----------------------------------------------------------------
@pytest.mark.parametrize(
    "kwargs, error, message",
    [
        ({"dataset": 3}, ArgumentTypeError, "dataset must be a folder's path .*got int 3"),
        ({"dataset": b"ds"}, ArgumentTypeError, "dataset must be a folder's path"),
        ({"dataset": None}, ArgumentTypeError, "dataset must be a folder's path .*NoneType"),
        ({"to": None}, ArgumentTypeError, "to must be a str, got NoneType"),
        ({"to": ["pcn"]}, ArgumentTypeError, "to must be a str, got list"),
        ({"to": "ply"}, InvalidInputError, "to='ply': give one of 'pointnet-h5', 'modelnet-txt', 'pcn'"),
        ({"out": 5}, ArgumentTypeError, "out must be a folder's path .*got int 5"),
        ({"seed": "x"}, ArgumentTypeError, "seed must be a whole number >= 0 or None, got str 'x'"),
        ({"seed": 1.5}, ArgumentTypeError, "seed must be a whole number"),
        ({"seed": True}, ArgumentTypeError, "seed must be a whole number"),
        ({"seed": -1}, InvalidInputError, "^seed must be a non-negative integer, got -1"),
        ({"seed": 2**64}, InvalidInputError, "^seed must be at most"),
        ({"list_prefix": 1}, ArgumentTypeError, "list_prefix must be a str or None, got int 1"),
        ({"list_prefix": " "}, InvalidInputError, "list_prefix=' ' is blank"),
        ({"label_set_name": 3}, ArgumentTypeError, "label_set_name must be a str, got int 3"),
        ({"label_set_name": "imagenet"}, InvalidInputError, "not label_set_name='imagenet'"),
    ],
)
def test_wrong_kinds_and_values_from_python_raise_named_errors(sets, tmp_path, monkeypatch, kwargs, error, message):
    monkeypatch.chdir(tmp_path)
    given = {"dataset": sets["both"], "to": "pointnet-h5", "out": tmp_path / "out", **kwargs}
    with pytest.raises(error, match=message):
        export(given.pop("dataset"), given.pop("to"), given.pop("out"), **given)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_users_files_in_a_modelnet_txt_out_are_refused_or_kept_never_replaced(sets, tmp_path):
    # the batched writer replaces only files its ledger recorded: a user's file where a sample goes
    # is refused and kept (files the export wrote before it stay, recorded), one beside the
    # export's files is kept as it is
    out = tmp_path / "out"
    (out / "desk").mkdir(parents=True)
    (out / "desk" / "desk_0001.txt").write_text("mine\n")
    with pytest.raises(UnsafePathError, match="desk_0001.txt"):
        export(sets["both"], "modelnet-txt", out)
    assert (out / "desk" / "desk_0001.txt").read_text() == "mine\n"
    (out / "desk" / "desk_0001.txt").unlink()
    (out / "notes.md").write_text("mine\n")
    export(sets["both"], "modelnet-txt", out)
    export(sets["train"], "modelnet-txt", out)  # a re-export removes its own earlier files only
    assert (out / "notes.md").read_text() == "mine\n"
