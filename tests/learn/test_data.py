"""zbuf_occlude.learn.data: class-balanced epochs."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.learn.data import balanced_epoch_rows


@settings(max_examples=60, deadline=None)
@given(sizes=st.lists(st.integers(1, 40), min_size=1, max_size=5), seed=st.integers(0, 2**32 - 1))
def test_balanced_epoch_has_every_class_equally_often(sizes: list[int], seed: int) -> None:
    labels = np.repeat(np.arange(len(sizes)) * 3, sizes)  # class indices need not be 0..K-1
    np.random.default_rng(seed).shuffle(labels)
    rows = balanced_epoch_rows(labels, np.random.default_rng(seed))
    per_class = len(labels) // len(sizes)
    assert rows.dtype == np.int64 and len(rows) == per_class * len(sizes)
    assert rows.min() >= 0 and rows.max() < len(labels)
    counts = {int(c): int((labels[rows] == c).sum()) for c in np.unique(labels)}
    assert set(counts.values()) == {per_class}
    for c in np.unique(labels):  # a class's rows are used evenly: none twice before every one once
        uses = np.bincount(rows[labels[rows] == c], minlength=len(labels))[labels == c]
        assert uses.max() - uses.min() <= 1


def test_balanced_epoch_is_seeded_and_shuffled() -> None:
    labels = np.array([0] * 90 + [1] * 10)
    a = balanced_epoch_rows(labels, np.random.default_rng(1))
    assert np.array_equal(a, balanced_epoch_rows(labels, np.random.default_rng(1)))
    assert not np.array_equal(a, balanced_epoch_rows(labels, np.random.default_rng(2)))
    assert 0 < (labels[a[:50]] == 1).mean() < 1  # the classes are mixed, not one block after the other
    assert len(balanced_epoch_rows(np.zeros(0, np.int64), np.random.default_rng(0))) == 0
