"""Hostile point-set files given to ``generate`` and ``farm``: one line each, and the project's exit status.

A point-set file that cannot be read is *skipped* (a ``SKIPPED`` line, the card's
``skipped_inputs``, exit 1, the other inputs done); a cloud that is read but cannot be used is
*failed* (a ``FAILED`` line and a failed record, exit 1), as a mesh that cannot be loaded is; a
file given by name that is no point-set file, or nothing usable at all, is a usage error (exit 2).
Every file is built here.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
import trimesh

from zbuf_occlude.cli.main import main

TINY = ["--views", "0:0", "--points", "64", "--samples-per-view", "1", "--no-progress"]
#: A usable cloud beside each hostile file: the run goes on with it.
GOOD = np.random.default_rng(0).normal(size=(400, 3))

pytestmark = pytest.mark.slow


def _nan(path: Path) -> None:
    bad = GOOD.copy()
    bad[3, 1] = np.nan
    np.save(path, bad)


def _truncated_ply(path: Path) -> None:
    trimesh.PointCloud(GOOD).export(path)
    path.write_bytes(path.read_bytes()[:-100])


def _h5(**datasets) -> Callable[[Path], None]:
    def write(path: Path) -> None:
        with h5py.File(path, "w") as f:
            for key, value in datasets.items():
                f[key] = value

    return write


#: name -> (file name, writer, "skipped" or "failed", what the line must say).
HOSTILE = {
    "pickled objects": ("bad.npy", lambda p: np.save(p, np.array([{"a": 1}], dtype=object), allow_pickle=True), "skipped", "object values"),
    "four columns": ("bad.npy", lambda p: np.save(p, np.zeros((10, 4))), "skipped", r"shape \(10, 4\), not \(N, 3\)"),
    "not npy": ("bad.npy", lambda p: p.write_bytes(b"\x93NUMPY garbage"), "skipped", "format version"),
    "negative label": ("bad.h5", _h5(data=np.zeros((2, 10, 3), np.float32), label=np.array([[-1], [0]], np.int8)), "skipped", "negative"),
    "integer data": ("bad.h5", _h5(data=np.zeros((2, 10, 3), np.int32)), "skipped", "int32 values"),
    "label beyond shape_names": ("bad.h5", _h5(data=np.ones((1, 10, 3), np.float32), label=np.array([[7]])), "skipped", "label 7 has no line"),
    "NaN": ("bad.npy", _nan, "failed", "NaN"),
    "no points": ("bad.npy", lambda p: np.save(p, np.zeros((0, 3))), "failed", "no points"),
    "one point": ("bad.npy", lambda p: np.save(p, np.ones((1, 3))), "failed", "all coincide"),
    "coincident points": ("bad.npy", lambda p: np.save(p, np.ones((50, 3))), "failed", "50 points all coincide"),
    "truncated ply": ("bad.ply", _truncated_ply, "failed", "cannot read as a PLY"),
}  # fmt: skip


def _tree(root: Path, name: str, writer: Callable[[Path], None]) -> Path:
    (root / "good").mkdir(parents=True)
    (root / "bad").mkdir()
    np.save(root / "good" / "cloud.npy", GOOD)
    (root / "bad" / "shape_names.txt").write_text("a\n")
    writer(root / "bad" / name)
    return root / "bad" / name


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_a_hostile_point_set_file_is_one_line_and_exit_1_the_rest_is_done(tmp_path, capsys, case) -> None:
    name, writer, outcome, said = HOSTILE[case]
    bad = _tree(tmp_path / "in", name, writer)
    out = tmp_path / "out"
    assert main(["generate", str(tmp_path / "in"), "--out", str(out), *TINY]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith(("SKIPPED", "FAILED"))]
    assert len(err) == 1 and "Traceback" not in err[0]
    assert err[0].startswith(f"{outcome.upper()} {bad}"), err
    assert re.search(said, err[0]), err
    card = json.loads((out / "dataset_card.json").read_text())
    assert card["n_objects_ok"] == 1  # the good cloud was done
    if outcome == "skipped":
        assert [s["path"] for s in card["skipped_inputs"]] == ["bad/" + name]
    else:
        assert card["n_objects_failed"] == 1
    assert main(["verify", str(out)]) == 0


def test_duplicated_points_are_a_defined_answer(tmp_path) -> None:
    root = tmp_path / "in"
    root.mkdir()
    np.save(root / "dup.npy", np.concatenate([GOOD, GOOD]))
    assert main(["generate", str(root), "--out", str(tmp_path / "out"), *TINY]) == 0


def _not_hdf5(folder: Path) -> Path:
    (folder / "x.h5").write_bytes(b"not hdf5")
    return folder / "x.h5"


def _npy(folder: Path, points: np.ndarray) -> Path:
    np.save(folder / "x.npy", points)
    return folder / "x.npy"


@pytest.mark.parametrize(
    ("command", "make", "said"),
    [
        ("generate", _not_hdf5, r"x\.h5 is not a point-set file"),
        ("generate", lambda d: _npy(d, np.zeros((3, 4))), r"no mesh files .* or point-set files .*x\.npy.*shape \(3, 4\)"),
        ("farm", lambda d: _npy(d, GOOD), r"x\.npy is a point-set file; farm takes a folder"),
    ],
    ids=["not hdf5 by name", "nothing usable", "farm given a file"],
)
def test_usage_errors_are_one_line_and_exit_2(tmp_path, capsys, command, make, said) -> None:
    path = make(tmp_path)
    out = tmp_path / "out"
    assert main([command, str(path), "--out", str(out), *TINY]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error: ") and "\n" not in err and "Traceback" not in err
    assert re.search(said, err), err
    assert not out.exists()


@pytest.mark.parametrize("command", ["generate", "farm"])
def test_a_users_files_in_out_survive_point_set_runs_and_overwrite(tmp_path, command) -> None:
    root = tmp_path / "in"
    (root / "a").mkdir(parents=True)
    np.save(root / "a" / "cloud.npy", GOOD)
    out = tmp_path / "out"
    (out / "mine").mkdir(parents=True)
    (out / "notes.md").write_text("mine")
    (out / "mine" / "keep_000000.h5").write_bytes(b"mine")
    assert main([command, str(root), "--out", str(out), *TINY]) == 0
    np.save(root / "a" / "cloud.npy", GOOD[:300])  # a changed input: the rerun replaces its own files
    assert main([command, str(root), "--out", str(out), *TINY, "--overwrite"]) == 0
    assert (out / "notes.md").read_text() == "mine"
    assert (out / "mine" / "keep_000000.h5").read_bytes() == b"mine"
    assert main(["verify", str(out)]) == 0


def test_a_users_file_where_generate_writes_is_refused_and_kept(tmp_path, capsys) -> None:
    root = tmp_path / "in"
    (root / "a").mkdir(parents=True)
    np.save(root / "a" / "cloud.npy", GOOD)
    out = tmp_path / "out"
    out.mkdir()
    (out / "dataset_card.json").write_text("mine")
    assert main(["generate", str(root), "--out", str(out), *TINY, "--overwrite"]) != 0
    err = capsys.readouterr().err
    assert "Traceback" not in err and "dataset_card.json" in err
    assert (out / "dataset_card.json").read_text() == "mine"
