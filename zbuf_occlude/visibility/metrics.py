"""Agreement of a visibility mask with the oracle's.

All rates are fractions of *all* tested points, so ``accuracy = 1 − false_visible −
false_hidden``; ``iou`` is the intersection over union of the two visible sets.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError

__all__ = ["agreement"]


def agreement(predicted: NDArray[np.bool_], truth: NDArray[np.bool_]) -> dict[str, float]:
    """Compare a visibility mask with the ground truth.

    Parameters
    ----------
    predicted, truth : (N,) bool

    Returns
    -------
    dict
        ``n`` points, ``accuracy``, ``false_visible`` (hidden points called visible),
        ``false_hidden`` (visible points called hidden), ``iou`` of the visible sets (1.0 if
        both are empty), ``visible_fraction`` and ``truth_visible_fraction``; every rate is
        NaN when N is 0.

    Raises
    ------
    InvalidInputError
        Shapes differ.
    """
    p = np.asarray(predicted, dtype=bool)
    t = np.asarray(truth, dtype=bool)
    if p.shape != t.shape or p.ndim != 1:
        raise InvalidInputError(f"masks must be (N,) of equal length, got {p.shape} and {t.shape}")
    if len(t) == 0:
        nan = float("nan")
        return {"n": 0.0, "accuracy": nan, "false_visible": nan, "false_hidden": nan, "iou": nan,
                "visible_fraction": nan, "truth_visible_fraction": nan}  # fmt: skip
    n = len(t)
    fv = int(np.count_nonzero(p & ~t))
    fh = int(np.count_nonzero(~p & t))
    union = int(np.count_nonzero(p | t))
    return {
        "n": float(len(t)),
        "accuracy": 1.0 - (fv + fh) / n,
        "false_visible": fv / n,
        "false_hidden": fh / n,
        "iou": 1.0 if union == 0 else int(np.count_nonzero(p & t)) / union,
        "visible_fraction": float(np.count_nonzero(p)) / n,
        "truth_visible_fraction": float(np.count_nonzero(t)) / n,
    }
