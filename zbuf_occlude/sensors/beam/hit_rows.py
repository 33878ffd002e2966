"""Rows of per-hit columns grouped in runs: the sorting and counting that resolving echoes and attenuating sub-rays share.

Plain numpy over 1-D arrays of one length; no loop over pulses or sub-rays.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError

__all__ = ["group_starts", "hit_columns", "rank_in_run", "sorted_order"]


def hit_columns(**columns: ArrayLike) -> dict[str, np.ndarray]:
    """The per-hit columns as 1-D arrays of one length: integers int64, the rest finite float64 ≥ 0."""
    out: dict[str, np.ndarray] = {}
    for name, value in columns.items():
        a = np.asarray(value)
        integer = name in ("pulse", "surface", "subray")
        if a.ndim != 1 or (integer and a.dtype.kind not in "iu") or (not integer and a.dtype.kind not in "iuf"):
            kind = "an integer" if integer else "a number"
            raise InvalidInputError(f"{name} must be {kind} array of shape (M,), got shape {a.shape} dtype {a.dtype}")
        if integer:
            a = a.astype(np.int64, copy=False)
        else:
            a = a.astype(np.float64, copy=False)
            bad = int(np.sum(~(np.isfinite(a) & (a >= 0))))
            if bad:
                raise InvalidInputError(f"{name} must be finite and >= 0, got {bad} values that are not")
        out[name] = a
    lengths = {name: len(a) for name, a in out.items()}
    if len(set(lengths.values())) > 1:
        raise InvalidInputError(f"the per-hit arrays must have one length, got {lengths}")
    return out


def group_starts(*keys: NDArray) -> NDArray[np.int64]:
    """Indices where a run of equal ``keys`` (arrays of one length, sorted together) starts."""
    n = len(keys[0])
    new = np.zeros(n, bool)
    new[:1] = True
    for key in keys:
        new[1:] |= key[1:] != key[:-1]
    return np.flatnonzero(new)


def rank_in_run(*keys: NDArray) -> NDArray[np.int64]:
    """(n,) int64: the position of each row within its run of equal ``keys`` (0 for the first)."""
    starts = group_starts(*keys)
    return np.arange(len(keys[0])) - np.repeat(starts, np.diff(starts, append=len(keys[0])))


def sorted_order(*keys: NDArray) -> NDArray[np.int64]:
    """``np.lexsort(keys)`` (the last key sorts first), as successive stable argsorts of the
    keys gathered in the order so far: faster than lexsort's indirect passes, and nearly free on
    a key already sorted (the pulses of a scan come pulse by pulse)."""
    order = np.argsort(keys[0], kind="stable")
    for key in keys[1:]:
        order = order[np.argsort(key[order], kind="stable")]
    return order
