"""Point-set inputs as an input kind of their own: their frame, their default ``--points``, the options
they refuse, what the card records and what a run says.

The inputs are PointNet-layout HDF5 files of 2,048 points drawn uniformly on a shipped mesh, as
PointNet's ``modelnet40_ply_hdf5_2048`` clouds are, stored +y up as there.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import h5py
import numpy as np
import pytest

import zbuf_occlude as zo
from zbuf_occlude.cli.main import main
from zbuf_occlude.dataset.layout import CARD_FILE
from zbuf_occlude.farm.checks import check_point_set_options
from zbuf_occlude.farm.config import GENERATE_DEFAULTS, FarmParams
from zbuf_occlude.io.point_sets import stored_up
from zbuf_occlude.mesh.inputs.kinds import DEFAULT_POINT_SET_POINTS, MESH, POINT_SET, POINT_SET_METHOD, plan_nouns
from zbuf_occlude.mesh.inputs.plan import FarmObject
from zbuf_occlude.mesh.inputs.point_sets import load_cloud

REPO_ROOT = Path(__file__).resolve().parents[2]
CHAIR = REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"
VIEWS = ["--views", "0:0,30:45,-30:200", "--samples-per-view", "2"]
#: z-up -> y-up, as ModelNet's clouds are stored in PointNet's files: (x, y, z) -> (x, z, -y).
Z_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def _pointnet_h5(folder: Path, n_clouds: int = 1, points: int = 2048) -> Path:
    """A PointNet-layout file of ``n_clouds`` clouds of the chair, +y up, with its class list."""
    folder.mkdir(parents=True, exist_ok=True)
    mesh = zo.load_mesh(CHAIR)
    clouds = np.stack([zo.sample_surface(mesh, points, seed=s)[0] @ Z_TO_Y_UP.T for s in range(n_clouds)]).astype(np.float32)
    with h5py.File(folder / "ply_data_train0.h5", "w") as f:
        f["data"] = clouds
        f["label"] = np.zeros((n_clouds, 1), dtype=np.uint8)
    (folder / "shape_names.txt").write_text("chair\n")
    return folder / "ply_data_train0.h5"


def _card(out: Path) -> dict:
    return json.loads((out / CARD_FILE).read_text(encoding="utf-8"))


def _cloud(index: int = 0) -> FarmObject:
    return FarmObject(index, f"c{index}", "c.h5", "chair", "train", 0, cloud=index)


def _mesh(index: int = 0) -> FarmObject:
    return FarmObject(index, f"m{index}", "m.off", "chair", "train", 0)


# -- the frame ----------------------------------------------------------------------------------------
def test_a_pointnet_file_is_read_y_up_by_default_and_up_still_overrides(tmp_path) -> None:
    path = _pointnet_h5(tmp_path)
    assert stored_up(path) == ("+y", "PointNet HDF5 layout (+y)")
    chair = zo.normalize_mesh(zo.load_mesh(CHAIR))
    cloud = load_cloud(path, 0)
    assert (cloud.up, cloud.up_source) == ("+y", "PointNet HDF5 layout (+y)")
    # turned back to the mesh's +z-up frame: the same bounding box as the normalised mesh
    np.testing.assert_allclose(cloud.points.min(axis=0), chair.bounds[0], atol=0.02)
    np.testing.assert_allclose(cloud.points.max(axis=0), chair.bounds[1], atol=0.02)
    as_stored = load_cloud(path, 0, up="+z")
    assert (as_stored.up, as_stored.up_source) == ("+z", "explicit")
    np.testing.assert_allclose(as_stored.points, cloud.points @ Z_TO_Y_UP.T, atol=1e-6)


def test_npy_files_and_our_own_data_sets_are_read_as_stored(tmp_path) -> None:
    np.save(tmp_path / "a.npy", np.random.default_rng(0).normal(size=(50, 3)))
    assert stored_up(tmp_path / "a.npy") == ("+z", "as stored (+z)")
    with h5py.File(tmp_path / "own.h5", "w") as f:
        f["data"] = np.zeros((1, 4, 3), np.float32)
        f["pose_index"] = np.zeros(1, np.int64)
        f["face_index"] = np.zeros((1, 4), np.int64)
    assert stored_up(tmp_path / "own.h5")[0] == "+z"
    with h5py.File(tmp_path / "said.h5", "w") as f:
        f["data"] = np.zeros((1, 4, 3), np.float32)
        f.attrs["up"] = "-x"
    assert stored_up(tmp_path / "said.h5")[0] == "-x"


# -- the kind's answers ------------------------------------------------------------------------------
def test_objects_say_their_kind_and_a_plan_its_nouns() -> None:
    assert _cloud().kind is POINT_SET and _mesh().kind is MESH
    assert plan_nouns([_cloud(0), _cloud(1)]) == ("cloud", "clouds")
    assert plan_nouns([_mesh()]) == ("mesh", "meshes")
    assert plan_nouns([_mesh(0), _cloud(1)]) == ("object", "objects")


@pytest.mark.parametrize("field, value", [("dense_points", 5000), ("resolution", 64), ("density", 3.0)])
def test_options_that_do_nothing_for_point_sets_are_refused_naming_them(field, value) -> None:
    params = FarmParams(**{field: value})
    with pytest.raises(zo.InvalidInputError, match=f"--{field.replace('_', '-')} {value} does nothing for point set"):
        check_point_set_options([_cloud()], params)
    # a mesh among the inputs uses them: taken
    assert check_point_set_options([_mesh(0), _cloud(1)], params).method == params.method


def test_a_plan_of_clouds_runs_with_their_method_and_their_points() -> None:
    params = check_point_set_options([_cloud()], GENERATE_DEFAULTS, GENERATE_DEFAULTS, frozenset())
    assert (params.method, params.n_points) == (POINT_SET_METHOD, DEFAULT_POINT_SET_POINTS)
    given = check_point_set_options([_cloud()], GENERATE_DEFAULTS, GENERATE_DEFAULTS, frozenset({"n_points"}))
    assert given.n_points == GENERATE_DEFAULTS.n_points  # --points 2048 given: kept
    with pytest.raises(zo.InvalidInputError, match="--resolution"):  # given, even at the default's value
        check_point_set_options([_cloud()], GENERATE_DEFAULTS, GENERATE_DEFAULTS, frozenset({"resolution"}))


# -- the command line ---------------------------------------------------------------------------------
@pytest.mark.parametrize("command", ["generate", "farm"])
@pytest.mark.parametrize("option", [["--dense-points", "5000"], ["--resolution", "64"], ["--resolution", "1024"]])
def test_the_cli_refuses_them_with_exit_2(tmp_path, capsys, command, option) -> None:
    """Given, even at the default's value (1024 is generate's --resolution), they are refused."""
    _pointnet_h5(tmp_path / "in")
    assert main([command, str(tmp_path / "in"), "--out", str(tmp_path / "out"), *VIEWS, *option, "--no-progress"]) == 2
    said = [line for line in capsys.readouterr().err.splitlines() if "does nothing" in line]
    assert len(said) == 1 and f"{option[0]} {option[1]} does nothing for point set inputs" in said[0], said
    assert not (tmp_path / "out" / CARD_FILE).exists()


@pytest.mark.parametrize("command", ["generate", "farm"])
def test_help_names_point_sets(capsys, command) -> None:
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "point-set files" in text.lower() and "PointNet" in text and "refused for point sets" in text


@pytest.mark.slow
def test_the_default_gives_unpadded_samples_the_card_says_point_splat_and_the_run_says_clouds(tmp_path, capsys) -> None:
    _pointnet_h5(tmp_path / "in", n_clouds=2)
    out = tmp_path / "out"
    assert main(["generate", str(tmp_path / "in"), "--out", str(out), *VIEWS, "--no-progress"]) == 0
    card = _card(out)
    assert card["params"]["n_points"] == DEFAULT_POINT_SET_POINTS
    assert card["n_samples"] == 2 * 3 * 2 and card["n_padded_samples"] == 0
    assert card["params"]["method"] == POINT_SET_METHOD and card["point_sets"]["visibility"] == POINT_SET_METHOD
    assert card["up_axes"] == {"+y (PointNet HDF5 layout (+y))": 2}
    ds = zo.OccludedDataset(out)
    for i in range(len(ds)):
        points = ds[i][0]
        assert len(np.unique(points, axis=0)) == len(points) == DEFAULT_POINT_SET_POINTS  # no repeated point
    printed = capsys.readouterr().out
    assert printed.startswith("2 clouds done, 0 failed") and "meshes" not in printed


@pytest.mark.slow
def test_the_padding_warning_names_the_measured_share(tmp_path, caplog) -> None:
    _pointnet_h5(tmp_path / "in")
    with caplog.at_level(logging.WARNING):
        assert main(["generate", str(tmp_path / "in"), "--out", str(tmp_path / "out"), *VIEWS, "--points", "2048", "--no-progress"]) == 0
    text = caplog.text
    assert "about half" not in text
    assert f"a pose sees about {round(100 * POINT_SET.visible_share)} % of it" in text
