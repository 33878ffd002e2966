"""The Embree oracle's scene: vertex positions ranked as np.unique ranks them."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from zbuf_occlude.visibility.oracle_embree import position_ranks

# few distinct values (many repeats, ties in one column but not the next), signed zeros, extremes
_values = st.sampled_from([0.0, -0.0, 1.0, -1.0, 0.5, -2.5, 1e-300, -1e-300, 5e-324, 1.7e308, -1.7e308, 3.0])


@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(0, 40), st.just(3)), elements=_values))
def test_position_ranks_are_uniques_inverse(positions):
    expected = np.unique(positions, axis=0, return_inverse=True)[1].reshape(-1)
    ranks = position_ranks(positions)
    assert ranks.dtype == np.int64
    np.testing.assert_array_equal(ranks, expected)


@settings(max_examples=50, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(1, 200), st.just(3)), elements=st.floats(-1e6, 1e6, width=32)))
def test_position_ranks_on_spread_values(positions):
    np.testing.assert_array_equal(position_ranks(positions), np.unique(positions, axis=0, return_inverse=True)[1].reshape(-1))


def test_signed_zeros_are_one_position():
    ranks = position_ranks(np.array([[0.0, 1.0, 2.0], [-0.0, 1.0, 2.0], [-1.0, 0.0, 0.0]]))
    np.testing.assert_array_equal(ranks, [1, 1, 0])
