"""The sample index (``dataset/index.py``): pure functions from samples per pose and keep masks to item places."""

from __future__ import annotations

import numpy as np
import pytest

from zbuf_occlude.dataset.index import PoseFilters, pose_mask, sample_index, samples_per_pose
from zbuf_occlude.errors import InvalidInputError


def test_samples_per_pose_stores_none_where_nothing_is_visible():
    got = samples_per_pose(np.array([0, 5, 1]), 3)
    assert got.tolist() == [0, 3, 3] and got.dtype == np.int64


def test_the_index_is_object_after_object_pose_major_then_sample():
    # object 0: poses of 0, 2, 2 samples; object 1: 1, 0 (written as in the shards: pose-major)
    index = sample_index([np.array([0, 2, 2]), np.array([1, 0])])
    assert index.obj.tolist() == [0, 0, 0, 0, 1]
    assert index.pose.tolist() == [1, 1, 2, 2, 0]
    assert index.sample.tolist() == [0, 1, 0, 1, 0]
    assert index.row.tolist() == [0, 1, 2, 3, 0]
    assert index.n_unfiltered == len(index) == 5
    assert all(a.dtype == np.int64 for a in (index.obj, index.pose, index.sample, index.row))


def test_kept_rows_keep_their_shard_row_and_sample_index():
    keep = [np.array([False, True, True, False]), None, np.array([True])]
    index = sample_index([[2, 2], [3], [0, 1]], keep)
    # object 0 keeps rows 1 (pose 0, sample 1) and 2 (pose 1, sample 0); object 1 all; object 2 its one row
    assert index.obj.tolist() == [0, 0, 1, 1, 1, 2]
    assert index.pose.tolist() == [0, 1, 0, 0, 0, 1]
    assert index.sample.tolist() == [1, 0, 0, 1, 2, 0]
    assert index.row.tolist() == [1, 2, 0, 1, 2, 0]
    assert index.n_unfiltered == 8


def test_no_object_and_objects_without_samples_give_an_empty_index():
    for rows in ([], [[0, 0], [0]]):
        index = sample_index(rows)
        assert len(index) == 0 and index.n_unfiltered == 0 and index.row.dtype == np.int64


def test_a_keep_mask_of_another_length_is_refused():
    with pytest.raises(ValueError, match="object 1"):
        sample_index([[1], [2, 1]], [None, np.ones(2, dtype=bool)])


def test_pose_filters_values_predicates_and_mistakes():
    el, az = np.array([-30.0, 0.0, 30.0 + 1e-9]), np.array([0.0, 90.0, 180.0])
    assert not PoseFilters().active and PoseFilters().mask(el, az).all()
    assert PoseFilters(elevation_deg=30).mask(el, az).tolist() == [False, False, True]  # within 1e-6 degrees
    assert PoseFilters(elevation_deg=lambda e: e < 10, azimuth_deg=[0, 90]).mask(el, az).tolist() == [True, True, False]
    assert str(PoseFilters(azimuth_deg=[90])) == "elevation_deg=None, azimuth_deg=[90]"
    with pytest.raises(InvalidInputError, match="azimuth_deg must be a number"):
        PoseFilters(azimuth_deg=float("nan")).mask(el, az)
    assert pose_mask(el, None, "elevation_deg").tolist() == [True, True, True]
