"""Occlusion on the fly given what a careless caller or a hostile shared folder gives it
(learn/on_the_fly.py): wrong kinds and values from Python, counts past memory, clouds float64
cannot normalise, and class or split lists that link out of a point set's folder.  Each is one
named error (never a bare TypeError, ValueError or AttributeError, never a value truncated)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from zbuf_occlude import resources  # noqa: E402
from zbuf_occlude.errors import (  # noqa: E402
    ArgumentTypeError,
    InsufficientMemoryError,
    InvalidInputError,
    ZbufOccludeError,
)
from zbuf_occlude.learn import OnTheFlyOccludedDataset, PoseDistribution, RandomOcclusion  # noqa: E402
from zbuf_occlude.learn.on_the_fly import EpochSampler  # noqa: E402

CLOUD = np.random.default_rng(0).normal(size=(400, 3))
SECRET = "SECRET_FROM_OUTSIDE"


def _named(error: type[Exception], words: str, call) -> None:
    with pytest.raises(error, match=words) as info:
        call()
    assert isinstance(info.value, ZbufOccludeError) and "\n" not in str(info.value), info.value


# -- RandomOcclusion and PoseDistribution from Python ------------------------------------------------
CONSTRUCTION = {
    "n_points 2.7": (InvalidInputError, "n_points must be an integer from 1 to 100000000, got a number that is not whole", lambda: RandomOcclusion(2.7)),
    "n_points 10**11": (InvalidInputError, "n_points must be .*got a whole number outside that range", lambda: RandomOcclusion(n_points=10**11)),
    "n_points 0": (InvalidInputError, "n_points must be an integer from 1", lambda: RandomOcclusion(0)),
    "n_points text": (ArgumentTypeError, "n_points must be an integer, got str '5'", lambda: RandomOcclusion("5")),
    "n_points None": (ArgumentTypeError, "n_points must be an integer, got NoneType", lambda: RandomOcclusion(None)),
    "n_points bool": (ArgumentTypeError, "n_points must be an integer, got bool", lambda: RandomOcclusion(True)),
    "seed 1.5": (InvalidInputError, "seed must be an integer from 0 .*got a number that is not whole", lambda: RandomOcclusion(8, seed=1.5)),
    "seed text": (ArgumentTypeError, "seed must be an integer, got str 'a'", lambda: RandomOcclusion(8, seed="a")),
    "seed negative": (InvalidInputError, "seed must be an integer from 0", lambda: RandomOcclusion(8, seed=-1)),
    "poses tuple": (ArgumentTypeError, r"poses must be a PoseDistribution, got tuple \(1, 2\)", lambda: RandomOcclusion(8, poses=(1, 2))),
    "method number": (ArgumentTypeError, "method must be the name of a visibility method, got int 3", lambda: RandomOcclusion(8, method=3)),
    "method unknown": (InvalidInputError, "unknown visibility method 'z-buffer'", lambda: RandomOcclusion(8, method="z-buffer")),
    "normalize text": (ArgumentTypeError, "normalize must be True or False, got str 'no'", lambda: RandomOcclusion(8, normalize="no")),
    "elevation text": (InvalidInputError, r"elevation_deg\[0\] must be a finite number, got a string of 1 character", lambda: PoseDistribution(("a", 1.0))),
    "elevation number": (InvalidInputError, "elevation_deg must be a list of 2 numbers, got a whole number", lambda: PoseDistribution(5)),
    "azimuth nan": (InvalidInputError, r"azimuth_deg\[1\] must be a finite number, got NaN", lambda: PoseDistribution(azimuth_deg=(0, np.nan))),
    "radius text": (InvalidInputError, "radius must be a finite number > 0, got a string of 1 character", lambda: PoseDistribution(radius="x")),
    "uniform_area text": (ArgumentTypeError, "uniform_area must be True or False", lambda: PoseDistribution(uniform_area="yes")),
    "severity 2.7": (InvalidInputError, "severity must be an integer from 1 to 5, got a number that is not whole", lambda: PoseDistribution.modelnet40c(2.7)),
    "sampler seed": (ArgumentTypeError, "seed must be an integer, got str 'a'", lambda: EpochSampler(range(4), seed="a")),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(CONSTRUCTION))
def test_wrong_kinds_and_values_are_refused_where_they_are_given(case) -> None:
    error, words, call = CONSTRUCTION[case]
    _named(error, words, call)


def test_whole_numbers_of_any_kind_are_taken() -> None:
    assert RandomOcclusion(np.int64(64), seed=np.uint8(3)).n_points == 64 == RandomOcclusion(64.0).n_points
    poses = PoseDistribution([10, 20], np.array([0, 90]), np.float32(2.5))
    assert poses == PoseDistribution((10.0, 20.0), (0.0, 90.0), 2.5) and hash(poses) == hash(PoseDistribution((10, 20), (0, 90), 2.5))


def test_a_sample_that_would_exhaust_memory_is_refused_at_construction(monkeypatch) -> None:
    monkeypatch.setattr(resources, "available_memory", lambda: (2**30, "test budget"))
    _named(InsufficientMemoryError, r"n_points=50,000,000 needs about 5\.96 GiB .*lower n_points", lambda: RandomOcclusion(50_000_000))
    assert RandomOcclusion(5_000_000).n_points == 5_000_000  # 610 MiB: fits


CALLS = {
    "index 1.5": (InvalidInputError, "index must be an integer from 0 .*got a number that is not whole", {"index": 1.5}),
    "index text": (ArgumentTypeError, "index must be an integer, got str 'a'", {"index": "a"}),
    "index negative": (InvalidInputError, "index must be an integer from 0", {"index": -1}),
    "epoch text": (ArgumentTypeError, "epoch must be an integer, got str 'a'", {"epoch": "a"}),
    "key unhashable": (ArgumentTypeError, "key must be hashable", {"key": [1, 2]}),
    "up number": (InvalidInputError, "up must be one of", {"up": 3}),
    "points text": (ArgumentTypeError, "points must be a numeric array, got str 'x.h5'", {"mesh": "x.h5"}),
    "array with a dense cloud": (ArgumentTypeError, "takes a trimesh.Trimesh and its DenseCloud", {"dense": CLOUD}),
}


@pytest.mark.parametrize("case", sorted(CALLS))
def test_a_call_with_the_wrong_kinds_is_a_named_error(case) -> None:
    error, words, kwargs = CALLS[case]
    args = {"mesh": CLOUD, "dense": None, "index": 0} | kwargs
    occlusion = RandomOcclusion(32)
    _named(error, words, lambda: occlusion(args.pop("mesh"), args.pop("dense"), args.pop("index"), **args))
    _named(ArgumentTypeError, "epoch must be an integer, got str 'a'", lambda: occlusion.set_epoch("a"))


@pytest.mark.parametrize(
    ("points", "said"),
    [(np.vstack([CLOUD, [[1e200, 1e200, 1e200]]]), "distinct points become"),
     (np.vstack([CLOUD, [[1e200, 0.0, 0.0]]]), "distinct points become"),
     (np.array([[-1.5e308, 0.0, 0.0], [1.5e308, 1.0, 1.0], [0.0, 0.5, 0.5]]), "extent overflows float64")],
    ids=["outlier 1e200", "outlier on one axis", "extent 3e308"],
)  # fmt: skip
def test_a_cloud_that_cannot_be_normalised_is_refused_not_sampled_as_one_point(points, said) -> None:
    """Before, every sample of it held one repeated point, and the call said it was done."""
    _named(InvalidInputError, f"the point set 'points': .*{said}", lambda: RandomOcclusion(64)(points, None, 0))


def test_a_cloud_float64_can_normalise_is_sampled() -> None:
    out = RandomOcclusion(64)(np.vstack([CLOUD, [[50.0, 0.0, 0.0]]]), None, 0)  # an outlier, not a collapse
    assert out["n_visible"] > 0 and len(np.unique(out["points"], axis=0)) > 1


# -- the data set over a hostile folder ------------------------------------------------------------
def _pointnet_folder(root: Path) -> Path:
    import h5py

    root.mkdir(parents=True)
    with h5py.File(root / "ply_data_train0.h5", "w") as f:
        f["data"] = np.stack([CLOUD, CLOUD * [1.0, 0.5, 1.0]]).astype(np.float32)
        f["label"] = np.array([[0], [1]], np.uint8)
    (root / "train_files.txt").write_text("ply_data_train0.h5\n")
    return root


@pytest.mark.parametrize("listing", ["shape_names.txt", "train_files.txt"])
def test_a_list_that_links_out_never_names_a_class_or_a_split(tmp_path, listing) -> None:
    secret = tmp_path / "elsewhere.txt"
    secret.write_text(f"{SECRET}_A\n{SECRET}_B\nply_data_train0.h5\n")
    root = _pointnet_folder(tmp_path / "set")
    if listing == "train_files.txt":
        (root / "shape_names.txt").write_text("chair\nsofa\n")
        (root / "train_files.txt").unlink()
    os.symlink(secret, root / listing)
    with pytest.raises(InvalidInputError, match=f"{listing} leads outside") as info:  # UnsafePathError, or the file skipped for it
        OnTheFlyOccludedDataset(root, n_points=32)
    assert SECRET not in str(info.value) and "\n" not in str(info.value)
    (root / listing).unlink()
    (root / listing).write_text("chair\nsofa\n" if listing == "shape_names.txt" else "ply_data_train0.h5\n")
    ds = OnTheFlyOccludedDataset(root, n_points=32, split="train")
    assert ds.shape_names == ["chair", "sofa"] and len(ds) == 2


DATASET = {
    "root number": (ArgumentTypeError, "mesh_root must be a path or a list of paths, got int 5", {"mesh_root": 5}),
    "root list of numbers": (ArgumentTypeError, "mesh_root must be a path or a list of paths", {"mesh_root": [1, 2]}),
    "views 2.7": (
        InvalidInputError,
        "views_per_object must be an integer from 1 to 100000, got a number that is not whole",
        {"views_per_object": 2.7},
    ),
    "dense text": (ArgumentTypeError, "dense_points must be an integer, got str 'x'", {"dense_points": "x"}),
    "split number": (ArgumentTypeError, "split must be a str", {"split": 1}),
    "up list": (InvalidInputError, "up must be one of", {"up": ["+z"]}),
    "n_points 2.7": (InvalidInputError, "n_points must be an integer .*got a number that is not whole", {"n_points": 2.7}),
}


@pytest.mark.parametrize("case", sorted(DATASET))
def test_the_data_set_refuses_wrong_kinds_before_it_scans(tmp_path, case) -> None:
    error, words, kwargs = DATASET[case]
    args = {"mesh_root": _pointnet_folder(tmp_path / "set")} | kwargs
    _named(error, words, lambda: OnTheFlyOccludedDataset(args.pop("mesh_root"), **args))


def test_a_sample_index_of_the_wrong_kind_is_named_and_the_end_is_an_index_error(tmp_path) -> None:
    root = _pointnet_folder(tmp_path / "set")
    ds = OnTheFlyOccludedDataset(root, n_points=32)
    _named(ArgumentTypeError, "index must be an integer, got float 1.0", lambda: ds.sample(1.0))
    _named(ArgumentTypeError, "index must be an integer, got str '0'", lambda: ds["0"])
    with pytest.raises(IndexError):  # a Dataset's end, as Python's sequences say it
        ds.sample(len(ds))
    assert ds[np.int64(1)][0].shape == (32, 3)
