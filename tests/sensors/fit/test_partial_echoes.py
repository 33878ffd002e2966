"""The fit of a beam's min_echo_reflectance from a per-scan statistic of real and simulated scans."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.fit.partial_echoes import FIT_GRID, fit_min_echo_reflectance

#: Per class: the statistic's level with every echo kept, and how fast a threshold lowers it.
CURVES = {"bush": (0.30, 0.25), "pole": (0.50, 0.40), "car": (0.12, 0.05)}


def _simulated(noise: float = 0.0, n: int = 60, seed: int = 1) -> dict:
    rng = np.random.default_rng(seed)
    jitter = {c: rng.normal(0.0, noise, n) for c in CURVES}  # the same scans at every threshold
    return {t: {c: a - b * t + jitter[c] for c, (a, b) in CURVES.items()} for t in FIT_GRID}


def _real(true: float, noise: float = 0.0, n: int = 80, seed: int = 2) -> dict:
    rng = np.random.default_rng(seed)
    return {c: a - b * true + rng.normal(0.0, noise, n) for c, (a, b) in CURVES.items()}


@settings(max_examples=25, deadline=None)
@given(true=st.floats(0.0, 0.5))
def test_a_threshold_inside_the_grid_is_found_back(true):
    fit = fit_min_echo_reflectance(_real(true), _simulated(), bootstrap=20)
    assert fit.estimate.value == pytest.approx(true, abs=0.0026)  # the search's step
    assert fit.estimate.std < 0.01  # no noise: every resample agrees
    assert fit.grid == FIT_GRID and set(fit.simulated) == set(CURVES)
    assert min(fit.objective) == pytest.approx(fit.objective[int(np.argmin(fit.objective))])


def test_noise_gives_a_spread_that_covers_the_truth():
    fit = fit_min_echo_reflectance(_real(0.2, noise=0.05), _simulated(noise=0.05), bootstrap=200, seed=3)
    e = fit.estimate
    assert 0.0 < e.std < 0.1
    assert abs(e.value - 0.2) < 3 * e.std
    assert e.n == 3 * 80
    assert "fitted min_echo_reflectance" in fit.markdown() and "| bush |" in fit.markdown()


def test_a_real_level_beyond_the_curves_ends_at_the_grid_edge():
    real = {c: np.full(10, a + 0.2) for c, (a, _) in CURVES.items()}  # more outline than any threshold gives
    assert fit_min_echo_reflectance(real, _simulated(), bootstrap=5).estimate.value == 0.0


@pytest.mark.parametrize(
    ("real", "simulated", "words"),
    [
        ({"bush": [0.2]}, {0.0: {"bush": [0.3]}}, "two thresholds or more"),
        ({"bush": [0.2]}, {0.0: {"bush": [0.3]}, 1.5: {"bush": [0.2]}}, "in \\[0, 1\\]"),
        ({"bush": [0.2]}, {0.0: {"bush": [0.3]}, 0.1: {"pole": [0.2]}}, "no simulated scans of class 'bush'"),
        ({"bush": [0.2]}, {0.0: {"bush": [0.3, 0.2]}, 0.1: {"bush": [0.2]}}, "same scans at every threshold"),
        ({"bush": [float("nan")]}, {0.0: {"bush": [0.3]}, 0.1: {"bush": [0.2]}}, "finite"),
        ({"bush": []}, {0.0: {"bush": [0.3]}, 0.1: {"bush": [0.2]}}, "non-empty"),
        ({"bush": [0.0, 0.0]}, {0.0: {"bush": [0.3]}, 0.1: {"bush": [0.2]}}, "median is 0"),
        ({}, {0.0: {"bush": [0.3]}, 0.1: {"bush": [0.2]}}, "one class or more"),
    ],
)
def test_bad_inputs_are_refused_naming_what(real, simulated, words):
    with pytest.raises(InvalidInputError, match=words):
        fit_min_echo_reflectance(real, simulated, bootstrap=5)
