"""Seeds and draws of fixed-size samples: the laws every writer and reader relies on."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.geometry.samples import count_padded, derive_rng, draw_sample, object_key, pose_samples, sample_rng


@settings(max_examples=60, deadline=None)
@given(n_visible=st.lists(st.integers(0, 50), max_size=12), n_points=st.integers(1, 40), per_view=st.integers(1, 4))
def test_count_padded_counts_the_samples_of_poses_that_see_too_few(n_visible, n_points, per_view) -> None:
    expected = per_view * sum(1 for n in n_visible if 0 < n < n_points)
    assert count_padded(n_visible, n_points, per_view) == expected
    assert count_padded(np.asarray(n_visible, dtype=np.int32), n_points, per_view) == expected


def test_count_padded_by_hand() -> None:
    # 0 sees nothing (no sample), 3 < 4 is padded, 4 and 9 are not
    assert count_padded([0, 3, 4, 9, 1], 4, 10) == 20
    assert count_padded(np.array([2**40]), 4, 1) == 0  # large counts do not wrap


@settings(max_examples=60, deadline=None)
@given(n_visible=st.integers(0, 30), n_points=st.integers(1, 30), seed=st.integers(0, 2**32 - 1))
def test_a_draw_takes_distinct_points_and_pads_only_when_too_few(n_visible, n_points, seed) -> None:
    visible = np.sort(np.random.default_rng(seed).choice(1000, size=n_visible, replace=False))
    chosen, count = draw_sample(visible, n_points, np.random.default_rng(seed))
    assert count == n_visible and chosen.dtype == np.int64
    if n_visible == 0:
        assert len(chosen) == 0
        return
    assert len(chosen) == n_points and set(chosen) <= set(visible)
    if n_visible >= n_points:
        assert len(set(chosen)) == n_points  # no repeats
    else:
        assert set(chosen) == set(visible)  # every visible point at least once, then repeats
        assert len(chosen) - len(set(chosen)) == n_points - n_visible


def test_seeds_are_stable_and_independent() -> None:
    assert object_key("chair_0001") == object_key("chair_0001") != object_key("chair_0002")
    assert object_key("chair_0001") == 0x370DA12E487FD8EA  # BLAKE2b-64 of the UTF-8 name: the seeds of every data set
    a = sample_rng(0, object_key("a"), 3, 1).random(4)
    assert np.array_equal(a, sample_rng(0, object_key("a"), 3, 1).random(4))
    assert not np.array_equal(a, sample_rng(0, object_key("a"), 3, 2).random(4))
    assert not np.array_equal(derive_rng(0, 1, 0).random(4), derive_rng(0, 1, 1).random(4))  # dense vs draw streams
    drawn = pose_samples(np.arange(10), 4, seed=0, key=object_key("a"), pose_index=3, sample_indices=[0, 1])
    assert [len(d) for d in drawn] == [4, 4] and not np.array_equal(drawn[0], drawn[1])
