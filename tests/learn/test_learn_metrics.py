"""zbuf_occlude.learn.metrics: mean class accuracy and the class-balanced cross-entropy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from zbuf_occlude.learn.metrics import balanced_nll, mean_class_accuracy


def test_mean_class_accuracy_weighs_every_class_equally() -> None:
    y = np.array([0] * 9 + [1])
    everything_zero = np.zeros(10, np.int64)
    assert mean_class_accuracy(y, everything_zero, 2) == pytest.approx(0.5)  # overall accuracy would say 0.9
    assert mean_class_accuracy(y, y, 2) == 1.0
    assert mean_class_accuracy(y, y, 3) == 1.0  # a class absent from y does not count


def test_balanced_nll_by_hand() -> None:
    prob = np.array([[0.5, 0.5], [0.25, 0.75], [0.9, 0.1]])
    y = np.array([0, 0, 1])
    # class 0: mean of -log 0.5 and -log 0.25; class 1: -log 0.1; then the mean of the two
    expected = ((math.log(2) + math.log(4)) / 2 + math.log(10)) / 2
    assert balanced_nll(prob, y) == pytest.approx(expected)
    assert np.isfinite(balanced_nll(np.array([[1.0, 0.0]]), np.array([1])))  # floored, not infinite
    assert np.isnan(balanced_nll(np.zeros((0, 2)), np.zeros(0, np.int64)))
