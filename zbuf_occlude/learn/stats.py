"""Statistics over seeds: mean ± standard deviation and an exact one-sided permutation test.

A training set "beats" another when its scores over independent seeds (each seed redraws the
training clouds and the initialisation) are larger than chance relabelling would give.  With
``n`` seeds per group the exact test enumerates all ``C(2n, n)`` ways to split the pooled
scores into two groups (Good, *Permutation, Parametric and Bootstrap Tests of Hypotheses*,
3rd ed., 2005, §3.1); its smallest possible p-value is ``1 / C(2n, n)`` (1/252 for five
seeds each), so five seeds can show p < 0.05 only with a clear separation.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from zbuf_occlude.errors import InvalidInputError

__all__ = ["mean_std", "permutation_p", "MAX_EXACT_SPLITS"]

#: Above this many splits the test samples splits at random instead of enumerating them.
MAX_EXACT_SPLITS = 200_000
#: Random splits drawn when the exact enumeration is too large.
N_RANDOM_SPLITS = 100_000


def mean_std(values: Sequence[float]) -> tuple[float, float]:
    """Mean and sample standard deviation (``ddof=1``; 0 for one value), NaNs ignored."""
    v = np.asarray([x for x in values if np.isfinite(x)], dtype=np.float64)
    if len(v) == 0:
        return float("nan"), float("nan")
    return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0


def permutation_p(a: Sequence[float], b: Sequence[float], *, seed: int = 0) -> float:
    """One-sided p-value of ``mean(a) > mean(b)`` by an exact permutation test.

    The statistic is ``mean(a) − mean(b)``; p is the share of the splits of the pooled
    values into groups of ``len(a)`` and ``len(b)`` (the observed split included) whose
    statistic is at least the observed one (with a relative tolerance of 1e-12 for ties).

    Parameters
    ----------
    a, b : sequence of float
        Scores over seeds (e.g. mean class accuracy); each group needs at least one value.
    seed : int
        Only used when ``C(n_a + n_b, n_a)`` exceeds :data:`MAX_EXACT_SPLITS` (random splits).

    Returns
    -------
    p : float in (0, 1]
        ``1 / C(n_a + n_b, n_a)`` when every value of ``a`` exceeds every value of ``b``.

    Raises
    ------
    InvalidInputError
        An empty group or a non-finite value.
    """
    x, y = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if len(x) == 0 or len(y) == 0:
        raise InvalidInputError(f"permutation test needs two non-empty groups, got {len(x)} and {len(y)} values")
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise InvalidInputError("permutation test values must be finite")
    pooled = np.concatenate([x, y])
    n, k = len(pooled), len(x)
    total = pooled.sum()
    observed = x.mean() - y.mean()
    tol = 1e-12 * max(1.0, float(np.abs(pooled).max()))

    def stat(sum_a: np.ndarray) -> np.ndarray:
        return sum_a / k - (total - sum_a) / (n - k)

    n_splits = math.comb(n, k)
    if n_splits <= MAX_EXACT_SPLITS:
        sums = np.fromiter((pooled[list(c)].sum() for c in itertools.combinations(range(n), k)), dtype=np.float64, count=n_splits)
        return float(np.mean(stat(sums) >= observed - tol))
    rng = np.random.default_rng(seed)
    idx = np.argsort(rng.random((N_RANDOM_SPLITS, n)), axis=1)[:, :k]
    hits = int(np.sum(stat(pooled[idx].sum(axis=1)) >= observed - tol))
    return (hits + 1) / (N_RANDOM_SPLITS + 1)
