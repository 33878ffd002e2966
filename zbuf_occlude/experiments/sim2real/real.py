"""The real scans of the sim-to-real experiment as clouds, and their fixed halves.

Every choice here depends on a scan's points alone (:func:`scan_key`), never on its file name or
its place in the data set: which points of a scan make its cloud (:func:`real_clouds`) and which
half it falls in (:func:`real_halves`).
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.learn.data import normalize_batch, resample
from zbuf_occlude.real_scans.records import real_label

__all__ = ["KEEP_SCALE_UNIT_M", "real_clouds", "real_scan_rows", "scan_key", "real_halves"]

log = logging.getLogger(__name__)

#: ``keep_scale``: clouds, real and made from meshes alike, are centred and divided by this many
#: metres (a 10 m object spans ±0.5 ... 1).
KEEP_SCALE_UNIT_M = 10.0


def real_scan_rows(scans, names: list[str], label_map: dict[str, str]) -> list[int]:
    """Indices into ``scans`` of the scans :func:`real_clouds` keeps (a label among ``names``), in its order."""
    index = {n: i for i, n in enumerate(names)}
    return [i for i, s in enumerate(scans) if real_label(s.label, index, label_map) in index]


def scan_key(points: NDArray, seed: int = 0) -> int:
    """A 64-bit key of a scan's content: the first 8 bytes of the SHA-256 of ``seed`` and the
    scan's ``(n, 3)`` points as float32, as an unsigned integer.

    The same points give the same key whatever file they came from, its name or its place in
    the data set; another ``seed`` gives an unrelated key (a seeded draw per scan).
    """
    pts = np.ascontiguousarray(points, dtype=np.float32)
    digest = hashlib.sha256(int(seed).to_bytes(8, "little", signed=True) + np.asarray(pts.shape, np.int64).tobytes() + pts.tobytes())
    return int.from_bytes(digest.digest()[:8], "little")


def real_halves(points: Sequence[NDArray], labels: NDArray[np.integer], seed: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """A fixed stratified split of the real scans into two halves, from their content alone.

    Each class's scans are ordered by :func:`scan_key` of their points with ``seed`` (a seeded
    draw per scan: a random order that no file name, no position in the data set and no other
    class changes); the first ``n // 2`` are half A, the rest half B.  Scans with the same
    points, whose keys tie, keep their order in ``points`` (the reader's, sorted by path).

    Parameters
    ----------
    points : sequence of (n_i, 3) arrays
        The scans' points (``RealScan.points``), one per row of ``labels``.
    labels : (S,) int
    seed : int

    Returns
    -------
    half_a, half_b : int64 arrays
        Rows of ``labels``, class by class (in ``np.unique`` order), each class's rows in key order.
    """
    labels = np.asarray(labels)
    keys = np.asarray([scan_key(p, seed) for p in points], dtype=np.uint64)
    a, b = [], []
    for c in np.unique(labels):
        rows = np.flatnonzero(labels == c)
        rows = rows[np.argsort(keys[rows], kind="stable")]
        a += rows[: len(rows) // 2].tolist()
        b += rows[len(rows) // 2 :].tolist()
    return np.asarray(a, np.int64), np.asarray(b, np.int64)


def real_clouds(scans, names: list[str], label_map: dict[str, str], n_points: int, seed: int, *,
                keep_scale: bool = False) -> tuple[NDArray[np.float32], NDArray[np.int64], list[str]]:  # fmt: skip
    """Real scans as clouds of ``n_points`` (random subset, or all plus repeats) and label indices.

    Labels are renamed with ``label_map`` (then lower-cased when that matches a class); scans
    of labels outside ``names`` are left out (logged).  Each scan's subset is drawn with
    ``seed`` and its own :func:`scan_key`, so that it depends on its points only, not on where
    the reader found it.

    Returns
    -------
    points : (S, n_points, 3) float32; labels : (S,) int64; sources : list of str

    Raises
    ------
    InvalidInputError
        No scan has a label among ``names``.
    """
    index = {n: i for i, n in enumerate(names)}
    pts, labels, sources, dropped = [], [], [], {}
    for s in scans:
        label = real_label(s.label, index, label_map)
        if label not in index:
            dropped[s.label] = dropped.get(s.label, 0) + 1
            continue
        rng = np.random.default_rng([seed, 0x2EA1, scan_key(s.points)])
        p = resample(np.asarray(s.points, np.float32)[None], n_points, rng)[0].astype(np.float64)
        if keep_scale:
            p = p * float(np.max(s.extent_m))
        pts.append(p)
        labels.append(index[label])
        sources.append(s.source)
    if dropped:
        log.warning("real scans left out (label not a training class %s): %s", names, dropped)
    if not pts:
        raise InvalidInputError(f"no real scan has a label among the training classes {names}; use --label-map")
    arr = np.stack(pts)
    if keep_scale:
        lo, hi = arr.min(axis=1, keepdims=True), arr.max(axis=1, keepdims=True)
        out = ((arr - (lo + hi) / 2) / KEEP_SCALE_UNIT_M).astype(np.float32)
    else:
        out = normalize_batch(arr)
    return out, np.asarray(labels, np.int64), sources
