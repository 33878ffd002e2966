"""Seeds and draws of fixed-size samples: the laws every writer and reader relies on."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.geometry.samples import (
    TOPUP_MAX_CANDIDATES_FACTOR,
    TOPUP_MAX_ROUNDS,
    count_padded,
    derive_rng,
    draw_sample,
    object_key,
    pool_index,
    pool_take,
    pose_samples,
    sample_rng,
    top_up,
    topup_rng,
)


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


# -- top-up: more visible points on the faces a pose sees -----------------------------------------
#: Four unit squares side by side in the plane z = 0 (x in [0, 4]), two triangles each.
SQUARES = np.array(
    [[[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x + 1.0, 1.0, 0.0]] for x in range(4)]
    + [[[x, 0.0, 0.0], [x + 1.0, 1.0, 0.0], [x, 1.0, 0.0]] for x in range(4)],
    dtype=np.float64,
)


def _window(x_max: float):
    """A visibility test that sees the points with x < x_max; ``calls`` gets the candidates of each call, ``kept`` the visible ones."""
    calls, kept = [], []

    def test(points, face_index):
        assert points.shape == (len(face_index), 3) and face_index.dtype == np.int64
        visible = points[:, 0] < x_max
        calls.append(len(points))
        kept.append(int(visible.sum()))
        return visible

    test.kept = kept
    return test, calls


def _top_up(test, n_missing=50, n_points=64, seen=(0, 4), fraction=1.0, pose_index=0):
    return top_up(SQUARES, np.asarray(seen), n_missing, test, seed=3, key=7, pose_index=pose_index, n_points=n_points,
                  visible_fraction=fraction)  # fmt: skip


def test_top_up_draws_on_the_seen_faces_and_keeps_the_visible_points() -> None:
    test, calls = _window(0.5)  # half of the seen square (faces 0 and 4, x in [0, 1]) is visible
    extra = _top_up(test, fraction=0.5)
    assert len(extra) >= 50 and extra.points.shape == (len(extra), 3) and extra.points.dtype == np.float64
    assert set(extra.face_index.tolist()) <= {0, 4} and (extra.points[:, 0] < 0.5).all()  # seen faces, visible only
    assert (extra.points[:, 2] == 0.0).all() and (extra.points[:, :2] >= 0).all() and (extra.points[:, :2] <= 1).all()
    assert len(np.unique(extra.points, axis=0)) == len(extra)  # distinct
    assert extra.candidates == sum(calls) and extra.rounds == len(calls)
    # uniform on the faces: the kept points spread over the visible half (not all near a corner)
    assert 0.15 < extra.points[:, 1].mean() < 0.85 and 0.1 < extra.points[:, 0].mean() < 0.4


def test_top_up_is_seeded_by_its_own_stream_and_the_pose() -> None:
    a = _top_up(_window(0.5)[0])
    b = _top_up(_window(0.5)[0])
    assert np.array_equal(a.points, b.points) and np.array_equal(a.face_index, b.face_index)  # same bytes
    assert not np.array_equal(a.points[:10], _top_up(_window(0.5)[0], pose_index=1).points[:10])
    assert not np.array_equal(topup_rng(3, 7, 0, 0).random(4), sample_rng(3, 7, 0, 0).random(4))
    assert not np.array_equal(topup_rng(3, 7, 0, 0).random(4), topup_rng(3, 7, 0, 1).random(4))  # rounds differ


def test_top_up_draws_nothing_when_nothing_is_missing_or_seen() -> None:
    test, calls = _window(0.5)
    assert len(_top_up(test, n_missing=0)) == 0 and len(_top_up(test, seen=())) == 0 and not calls
    flat = SQUARES.copy()
    flat[:, :, 1] = 0.0  # zero-area faces: no surface to draw on
    assert len(top_up(flat, np.array([0]), 5, test, seed=0, key=0, pose_index=0, n_points=8, visible_fraction=1.0)) == 0


def test_a_tiny_visible_surface_stops_at_the_bound_and_stays_short() -> None:
    test, calls = _window(0.001)  # 0.1 % of the seen faces is visible
    extra = _top_up(test, n_missing=60, n_points=64, fraction=0.001)
    assert extra.candidates == sum(calls) == TOPUP_MAX_CANDIDATES_FACTOR * 64  # the whole budget, not more
    assert extra.rounds <= TOPUP_MAX_ROUNDS and len(extra) < 60


@settings(max_examples=40, deadline=None)
@given(x_max=st.floats(0.01, 1.0), n_missing=st.integers(1, 200), seen=st.sampled_from([(0, 4), (0, 1, 4, 5), (2,)]),
       fraction=st.floats(0.0, 1.0))  # fmt: skip
def test_top_up_is_bounded_and_stops_only_when_done_or_out_of_budget(x_max, n_missing, seen, fraction) -> None:
    test, calls = _window(x_max)
    n_points = 256
    extra = _top_up(test, n_missing=n_missing, n_points=n_points, seen=seen, fraction=fraction)
    assert extra.rounds == len(calls) <= TOPUP_MAX_ROUNDS
    assert extra.candidates == sum(calls) <= TOPUP_MAX_CANDIDATES_FACTOR * n_points
    assert (extra.points[:, 0] < x_max).all() and set(extra.face_index.tolist()) <= set(seen)
    done = len(extra) >= n_missing
    assert done or extra.rounds == TOPUP_MAX_ROUNDS or extra.candidates == TOPUP_MAX_CANDIDATES_FACTOR * n_points
    assert sum(test.kept) == len(extra)  # every visible candidate is kept
    assert sum(test.kept[:-1]) < n_missing  # no round after the missing points were found


def test_the_pool_is_the_visible_dense_points_then_the_top_up_points() -> None:
    visible = np.array([2, 5, 7], dtype=np.int64)
    assert pool_index(visible, 10, 0) is visible  # no top-up: the draws are the ones without it
    assert pool_index(visible, 10, 3).tolist() == [2, 5, 7, 10, 11, 12]
    dense, extra = np.arange(30.0).reshape(10, 3), -np.arange(9.0).reshape(3, 3)
    assert np.array_equal(pool_take(dense, extra, np.array([11, 2, 10])), np.stack([extra[1], dense[2], extra[0]]))
    assert np.array_equal(pool_take(dense, None, np.array([3, 1])), dense[[3, 1]])


def test_a_topped_up_pose_draws_distinct_points_and_a_full_pose_draws_as_before() -> None:
    key = object_key("a")
    visible = np.arange(0, 40, 2)  # 20 visible of 40 dense points
    before = pose_samples(visible, 16, seed=0, key=key, pose_index=1, sample_indices=[0, 1])
    assert all(np.array_equal(x, y) for x, y in zip(before, pose_samples(visible, 16, seed=0, key=key, pose_index=1,
                                                                          sample_indices=[0, 1], n_dense=40)))  # fmt: skip
    drawn = pose_samples(visible, 30, seed=0, key=key, pose_index=1, sample_indices=[0, 1], n_dense=40, n_topped_up=15)
    for d in drawn:  # 20 + 15 >= 30: no repeats, from the pool only
        assert len(set(d.tolist())) == 30 and set(d.tolist()) <= set(visible.tolist()) | set(range(40, 55))
    short = pose_samples(visible, 40, seed=0, key=key, pose_index=1, sample_indices=[0], n_dense=40, n_topped_up=5)[0]
    assert set(short.tolist()) == set(visible.tolist()) | set(range(40, 45))  # every pool point, then repeats
