"""Agreement metrics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.visibility.metrics import agreement


def test_agreement_rates_add_up():
    truth = np.array([True, True, False, False, True])
    pred = np.array([True, False, True, False, True])
    a = agreement(pred, truth)
    assert a["accuracy"] == pytest.approx(0.6)
    assert a["false_visible"] == pytest.approx(0.2) and a["false_hidden"] == pytest.approx(0.2)
    assert a["iou"] == pytest.approx(2 / 4)
    assert a["accuracy"] + a["false_visible"] + a["false_hidden"] == pytest.approx(1.0)
    assert a["visible_fraction"] == pytest.approx(0.6) and a["truth_visible_fraction"] == pytest.approx(0.6)


def test_edge_cases():
    assert agreement(np.zeros(3, bool), np.zeros(3, bool))["iou"] == 1.0
    assert math.isnan(agreement(np.zeros(0, bool), np.zeros(0, bool))["accuracy"])
    with pytest.raises(InvalidInputError):
        agreement(np.zeros(2, bool), np.zeros(3, bool))
