"""Classification metrics (numpy only): overall and mean class accuracy, per class, per elevation."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError

__all__ = ["confusion_matrix", "classification_report", "accuracy_by_elevation", "mean_class_accuracy", "balanced_nll"]


def confusion_matrix(y_true: NDArray[np.integer], y_pred: NDArray[np.integer], n_classes: int) -> NDArray[np.int64]:
    """``(K, K) int64``: row = true class, column = predicted class."""
    y_true, y_pred = np.asarray(y_true, dtype=np.int64), np.asarray(y_pred, dtype=np.int64)
    if y_true.shape != y_pred.shape:
        raise InvalidInputError(f"{y_true.shape} true labels but {y_pred.shape} predictions")
    if len(y_true) and (min(y_true.min(), y_pred.min()) < 0 or max(y_true.max(), y_pred.max()) >= n_classes):
        raise InvalidInputError(f"labels outside 0..{n_classes - 1}")
    cm = np.zeros((n_classes, n_classes), dtype=np.int64)
    np.add.at(cm, (y_true, y_pred), 1)
    return cm


def classification_report(y_true: NDArray[np.integer], y_pred: NDArray[np.integer], class_names: Sequence[str]) -> dict:
    """Overall accuracy, mean class accuracy (over classes present in ``y_true``), per-class accuracy, confusion.

    Returns
    -------
    dict
        ``n``, ``overall_accuracy``, ``mean_class_accuracy``, ``per_class`` (name → accuracy,
        NaN for a class without test samples), ``confusion`` (K, K) int64.
    """
    k = len(class_names)
    cm = confusion_matrix(y_true, y_pred, k)
    support = cm.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        per = np.where(support > 0, np.diag(cm) / np.maximum(support, 1), np.nan)
    n = int(cm.sum())
    return {
        "n": n,
        "overall_accuracy": float(np.trace(cm) / n) if n else float("nan"),
        "mean_class_accuracy": float(np.nanmean(per)) if (support > 0).any() else float("nan"),
        "per_class": {name: float(a) for name, a in zip(class_names, per)},
        "confusion": cm,
    }


def accuracy_by_elevation(y_true: NDArray[np.integer], y_pred: NDArray[np.integer], elevation_deg: NDArray[np.floating]) -> list[dict]:
    """Overall accuracy per camera elevation (rows sorted by elevation, degrees; NaN elevations skipped)."""
    y_true, y_pred, el = np.asarray(y_true), np.asarray(y_pred), np.asarray(elevation_deg, dtype=np.float64)
    rows = []
    for e in np.unique(el[np.isfinite(el)]):
        sel = el == e
        rows.append({"elevation_deg": float(e), "n": int(sel.sum()),
                     "accuracy": float((y_true[sel] == y_pred[sel]).mean())})  # fmt: skip
    return rows


def mean_class_accuracy(y_true: NDArray[np.integer], y_pred: NDArray[np.integer], n_classes: int) -> float:
    """Mean over the classes present in ``y_true`` of each class's accuracy (its recall); NaN if empty."""
    return classification_report(y_true, y_pred, [str(i) for i in range(n_classes)])["mean_class_accuracy"]


def balanced_nll(prob: NDArray[np.floating], y_true: NDArray[np.integer], *, floor: float = 1e-12) -> float:
    """Class-balanced cross-entropy: the mean over the classes present of each class's mean ``-log p(true class)``.

    Parameters
    ----------
    prob : (B, K) float
        Predicted class probabilities (softmax).
    y_true : (B,) int
    floor : float
        Probabilities are clipped below at this value, so that one confident mistake gives a
        large but finite loss.

    Returns
    -------
    float
        NaN for an empty set.
    """
    prob, y_true = np.asarray(prob, dtype=np.float64), np.asarray(y_true, dtype=np.int64)
    if len(y_true) == 0:
        return float("nan")
    nll = -np.log(np.clip(prob[np.arange(len(y_true)), y_true], floor, None))
    return float(np.mean([nll[y_true == c].mean() for c in np.unique(y_true)]))
