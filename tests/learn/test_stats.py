"""Statistics over seeds: mean ± std and the exact one-sided permutation test."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.learn.stats import mean_std, permutation_p

scores = st.lists(st.floats(0.0, 1.0, allow_nan=False, width=32), min_size=1, max_size=6)


def test_full_separation_gives_the_smallest_p() -> None:
    a, b = [0.9, 0.91, 0.92, 0.93, 0.94], [0.5, 0.51, 0.52, 0.53, 0.54]
    assert permutation_p(a, b) == pytest.approx(1 / math.comb(10, 5))
    assert permutation_p(b, a) == pytest.approx(1.0)  # the wrong direction: every split is at least as large


def test_identical_groups_are_not_significant() -> None:
    a = [0.70, 0.75, 0.80, 0.72, 0.78]
    assert permutation_p(a, list(a)) >= 0.5
    assert permutation_p([0.8] * 5, [0.8] * 5) == 1.0  # all ties


def test_one_overlap_gives_the_second_smallest_p() -> None:
    # Only the observed split and one other (the top of b swapped with the bottom of a) reach
    # the observed difference: swapping a=0.60 and b=0.61 gives a larger mean for a.
    a, b = [0.60, 0.9, 0.91, 0.92, 0.93], [0.61, 0.5, 0.51, 0.52, 0.53]
    assert permutation_p(a, b) == pytest.approx(2 / math.comb(10, 5))


@settings(max_examples=60, deadline=None)
@given(scores, scores)
def test_p_is_a_probability_and_the_two_sides_cover_everything(a: list[float], b: list[float]) -> None:
    p_ab, p_ba = permutation_p(a, b), permutation_p(b, a)
    assert 1 / math.comb(len(a) + len(b), len(a)) - 1e-12 <= p_ab <= 1.0
    assert p_ab + p_ba >= 1.0 - 1e-12  # P(T >= t) + P(T <= t) >= 1


@settings(max_examples=40, deadline=None)
@given(scores, scores, st.floats(0.0, 1.0))
def test_raising_a_never_raises_p(a: list[float], b: list[float], shift: float) -> None:
    assert permutation_p([x + shift for x in a], b) <= permutation_p(a, b) + 1e-12


def test_large_groups_sample_random_splits() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(1.0, 0.1, 20), rng.normal(0.0, 0.1, 20)  # C(40, 20) ~ 1.4e11 splits
    p = permutation_p(a, b)
    assert 0 < p < 1e-3


def test_bad_groups_are_refused() -> None:
    with pytest.raises(InvalidInputError):
        permutation_p([], [1.0])
    with pytest.raises(InvalidInputError):
        permutation_p([float("nan")], [1.0])


def test_mean_std() -> None:
    assert mean_std([1.0, 2.0, 3.0]) == pytest.approx((2.0, 1.0))
    assert mean_std([0.5]) == (0.5, 0.0)
    m, s = mean_std([])
    assert math.isnan(m) and math.isnan(s)
