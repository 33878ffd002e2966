"""Training data: occluded clouds from a farm data set, complete clouds from meshes, augmentation.

Everything here is numpy (no torch): a :class:`CloudSet` is the in-memory arrays a training
run needs, ``points (B, N, 3) float32`` normalised per cloud like the paper (bounding-box
centre at 0, maximum extent 1, z up; :func:`zbuf_occlude.real_scans.datasets.normalize_points`),
``labels (B,) int64``, ``elevation_deg (B,) float64`` (NaN for complete clouds) and
``object_index (B,) int64`` (which mesh each cloud came from).
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError

__all__ = [
    "CloudSet",
    "normalize_batch",
    "resample",
    "from_occluded",
    "from_meshes",
    "augment",
    "split_validation",
    "balanced_epoch_rows",
]

log = logging.getLogger(__name__)

#: Augmentation of Sryamkin et al. 2023 (rotation, scaling, jitter) with PointNet's values
#: (Qi et al. 2017, §5.1: rotation about the up axis, Gaussian jitter σ = 0.01 clipped
#: at 0.05) and PointNet++'s scaling range [0.8, 1.25] (Qi et al. NeurIPS 2017).
SCALE_RANGE = (0.8, 1.25)
JITTER_SIGMA, JITTER_CLIP = 0.01, 0.05
#: Per-axis factors of the ``aspect`` augmentation: DGCNN's anisotropic scaling range (Wang et al.,
#: ACM TOG 2019; its ``data.py``, ``translate_pointcloud``: ``uniform(2/3, 3/2, size=3)``), without
#: its translation (every cloud here is centred on its bounding box, the real ones too).
ASPECT_RANGE = (2.0 / 3.0, 3.0 / 2.0)
#: Share of the clouds the ``partial`` augmentation makes partial (the others pass unchanged).
PARTIAL_SHARE = 0.5
#: Most of a cloud's height the ``partial`` augmentation cuts from its bottom, as a real object segmented from a scan
#: loses its lowest returns to the ground filter or to what stands in front.  No published figure: read on the fit
#: half of LiDARNet's scans, where the far bushes' lowest return lies 1.3 m below the sensor against 1.8 m for the
#: near ones', on crowns 2-3 m tall.
PARTIAL_CUT_MAX = 0.3
#: Largest share of a cloud's points the ``partial`` augmentation drops at random: PointNet++'s random input dropout
#: (Qi et al., NeurIPS 2017; its ``provider.py``, ``random_point_dropout``: ``max_dropout_ratio=0.875``).
PARTIAL_DROPOUT_MAX = 0.875


@dataclass
class CloudSet:
    """Clouds, labels and where they came from (module docstring for shapes)."""

    points: NDArray[np.float32]
    labels: NDArray[np.int64]
    elevation_deg: NDArray[np.float64]
    object_index: NDArray[np.int64]

    def __len__(self) -> int:
        return len(self.labels)

    def subset(self, rows: NDArray[np.integer]) -> CloudSet:
        return CloudSet(self.points[rows], self.labels[rows], self.elevation_deg[rows], self.object_index[rows])

    @staticmethod
    def concat(sets: Sequence[CloudSet]) -> CloudSet:
        return CloudSet(*(np.concatenate([getattr(s, f) for s in sets]) for f in
                          ("points", "labels", "elevation_deg", "object_index")))  # fmt: skip


def normalize_batch(points: NDArray[np.floating]) -> NDArray[np.float32]:
    """``(B, N, 3)``: each cloud's bounding box centred on 0 with maximum extent 1."""
    p = np.asarray(points, dtype=np.float64)
    lo, hi = p.min(axis=1, keepdims=True), p.max(axis=1, keepdims=True)
    extent = np.maximum((hi - lo).max(axis=2, keepdims=True), 1e-12)
    return ((p - (lo + hi) / 2) / extent).astype(np.float32)


def resample(points: NDArray[np.float32], n: int, rng: np.random.Generator) -> NDArray[np.float32]:
    """``(B, M, 3)`` → ``(B, n, 3)``: a random subset without replacement when ``n <= M``,
    else every point plus ``n − M`` repeats."""
    b, m, _ = points.shape
    if n == m:
        return points
    if n < m:
        idx = np.argsort(rng.random((b, m)), axis=1)[:, :n]
    else:
        idx = np.concatenate([np.tile(np.arange(m), (b, 1)), rng.integers(0, m, (b, n - m))], axis=1)
    return np.take_along_axis(points, idx[..., None], axis=1)


def from_occluded(dataset, n_points: int | None = None, seed: int = 0) -> CloudSet:
    """Every sample of a :class:`zbuf_occlude.OccludedDataset` (dense or compact storage).

    Parameters
    ----------
    dataset : OccludedDataset
        Already filtered (split, classes, elevations).
    n_points : int, optional
        Points per cloud (default: the data set's); fewer are drawn at random.
    seed : int

    Raises
    ------
    InvalidInputError
        The selection is empty.
    """
    if len(dataset) == 0:
        raise InvalidInputError(f"no samples selected in {dataset!r}")
    data, labels = dataset.to_arrays()
    meta = [dataset.metadata(i) for i in range(len(dataset))]
    elevation = np.array([m["elevation_deg"] for m in meta], dtype=np.float64)
    obj = np.array([m["object_index"] for m in meta], dtype=np.int64)
    if n_points is not None and n_points != data.shape[1]:
        data = resample(data, n_points, np.random.default_rng(seed))
    return CloudSet(normalize_batch(data), labels.astype(np.int64), elevation, obj)


def from_meshes(
    paths: Sequence[str | os.PathLike],
    labels: Sequence[int],
    n_points: int,
    per_mesh: int = 1,
    seed: int = 0,
    object_index: Sequence[int] | None = None,
) -> CloudSet:
    """Complete clouds: each mesh sampled uniformly (Algorithms 1–2), ``per_mesh`` times (the paper's C2 / Test 1).

    Parameters
    ----------
    paths : sequence of path
        Mesh files (:func:`zbuf_occlude.load_mesh` normalises them).
    labels : sequence of int
    n_points : int
        Points per cloud.
    per_mesh : int
        Independent clouds per mesh.
    seed : int
        Cloud ``j`` of mesh ``i`` uses seed ``(seed, i, j)``.
    object_index : sequence of int, optional
        Stored as ``object_index`` (default 0..len-1).
    """
    from zbuf_occlude.geometry.sampling import sample_surface
    from zbuf_occlude.mesh.load import load_mesh

    if len(paths) != len(labels):
        raise InvalidInputError(f"{len(paths)} meshes but {len(labels)} labels")
    clouds, ys, objs = [], [], []
    for i, (path, label) in enumerate(zip(paths, labels)):
        mesh = load_mesh(path)
        for j in range(per_mesh):
            pts, _ = sample_surface(mesh, count=n_points, seed=np.random.default_rng([seed, i, j]))
            clouds.append(pts)
            ys.append(label)
            objs.append(object_index[i] if object_index is not None else i)
    n = len(clouds)
    return CloudSet(normalize_batch(np.stack(clouds)), np.asarray(ys, dtype=np.int64),
                    np.full(n, np.nan), np.asarray(objs, dtype=np.int64))  # fmt: skip


def augment(points: NDArray[np.float32], rng: np.random.Generator, *, rotate: bool = True,
            scale: bool = True, jitter: bool = True, aspect: bool = False, partial: bool = False) -> NDArray[np.float32]:  # fmt: skip
    """Random rotation about the up (z) axis, isotropic scaling and Gaussian jitter, per cloud;
    with ``aspect``, random proportions too; with ``partial``, partial objects too.

    Parameters
    ----------
    points : (B, N, 3) float32
        Normalised clouds.
    rng : numpy Generator
    rotate, scale, jitter : bool
        Each step on or off.
    aspect : bool
        Stretch x, y and z by independent factors ``U(2/3, 3/2)`` (:data:`ASPECT_RANGE`), after
        the rotation, and re-normalise: the proportions change (a post as thick as a trunk, a
        tree as low as a shrub), the size is the isotropic scaling's alone.  Off by default,
        so that the draws of runs without it are unchanged.
    partial : bool
        Before the other steps, make :data:`PARTIAL_SHARE` of the clouds partial, as far and half-hidden real
        objects are: cut a share ``U(0, 0.3)`` of the cloud's height from its bottom (:data:`PARTIAL_CUT_MAX`), drop
        a share ``U(0, 0.875)`` of the points left at random (:data:`PARTIAL_DROPOUT_MAX`, at least one kept), and
        fill the cloud up again with repeats of the points kept (as a sparse real crop is), re-normalised.  Off by
        default, so that the draws of runs without it are unchanged.

    Returns
    -------
    (B, N, 3) float32
        Rotated (and stretched) clouds are re-normalised to max extent 1 before scaling by
        ``U(0.8, 1.25)``; jitter ``N(0, 0.01²)`` clipped to ±0.05 (object units).
    """
    b, n, _ = points.shape
    out = np.asarray(points, dtype=np.float32)
    if partial:
        out = _partial(out, rng)
    if rotate:
        theta = rng.uniform(0.0, 2 * np.pi, b)
        c, s = np.cos(theta), np.sin(theta)
        rot = np.zeros((b, 3, 3), dtype=np.float32)
        rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = c, -s, s, c, 1.0
        out = normalize_batch(np.einsum("bij,bnj->bni", rot, out))
    if aspect:
        out = normalize_batch(out * rng.uniform(*ASPECT_RANGE, (b, 1, 3)).astype(np.float32))
    if scale:
        out = out * rng.uniform(*SCALE_RANGE, (b, 1, 1)).astype(np.float32)
    if jitter:
        out = out + np.clip(rng.normal(0.0, JITTER_SIGMA, out.shape), -JITTER_CLIP, JITTER_CLIP).astype(np.float32)
    return out.astype(np.float32, copy=False)


def _partial(points: NDArray[np.float32], rng: np.random.Generator) -> NDArray[np.float32]:
    """:func:`augment`'s ``partial`` step on ``(B, N, 3)`` normalised clouds (z up)."""
    b, n, _ = points.shape
    chosen = rng.random(b) < PARTIAL_SHARE
    cut = rng.uniform(0.0, PARTIAL_CUT_MAX, b)
    kept_share = 1.0 - rng.uniform(0.0, PARTIAL_DROPOUT_MAX, b)
    order = rng.random((b, n))
    out = points.copy()
    for i in np.flatnonzero(chosen):
        z = points[i, :, 2]
        above = np.flatnonzero(z >= z.min() + cut[i] * (z.max() - z.min()))  # never empty: the top point stays
        kept = above[np.argsort(order[i, above], kind="stable")[: max(1, math.ceil(kept_share[i] * len(above)))]]
        out[i] = normalize_batch(resample(points[i, kept][None], n, rng))[0]  # every point kept, then repeats
    return out


def split_validation(n: int, fraction: float, seed: int, groups: NDArray[np.integer] | None = None,
                     labels: NDArray[np.integer] | None = None) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # fmt: skip
    """Deterministic train/validation split of ``n`` rows.

    With ``labels``, stratified: about ``fraction`` of each class's rows (at least one when
    a class has ≥ 2 rows) go to validation.  ``groups`` is accepted for API symmetry (rows
    of one object may fall on both sides: the paper validates on samples, not objects).

    Returns
    -------
    train_rows, val_rows : int64 arrays, sorted
    """
    if not 0.0 <= fraction < 1.0:
        raise InvalidInputError(f"validation fraction must be in [0, 1), got {fraction}")
    rng = np.random.default_rng([seed, 7])
    if fraction == 0.0 or n < 2:
        return np.arange(n, dtype=np.int64), np.zeros(0, dtype=np.int64)
    labels = np.zeros(n, dtype=np.int64) if labels is None else np.asarray(labels)
    val = []
    for c in np.unique(labels):
        rows = np.flatnonzero(labels == c)
        k = int(round(fraction * len(rows)))
        if len(rows) >= 2:
            k = min(max(k, 1), len(rows) - 1)
        else:
            k = 0
        val.extend(rng.permutation(rows)[:k].tolist())
    val_rows = np.sort(np.asarray(val, dtype=np.int64))
    train_rows = np.setdiff1d(np.arange(n, dtype=np.int64), val_rows)
    return train_rows, val_rows


def balanced_epoch_rows(labels: NDArray[np.integer], rng: np.random.Generator) -> NDArray[np.int64]:
    """One epoch's rows with every class equally often: class-balanced sampling.

    Each of the ``K`` classes present in ``labels`` gives ``len(labels) // K`` rows (so an epoch
    is about as long as the data set), taken from a fresh permutation of that class's rows,
    which is repeated as often as needed (a small class's rows are seen several times, a large
    class's a subset of them, each row at most once more than any other row of its class); the
    rows are then shuffled.  This is the "class-aware sampling" of Shen et al., ECCV 2016
    ("Relay backpropagation"), the usual remedy when a minority class is lost to the majority.

    Parameters
    ----------
    labels : (n,) int
        Class index of every row.
    rng : numpy Generator

    Returns
    -------
    (K * (n // K),) int64
        Row indices into ``labels``, in random order; exactly ``n // K`` of every class.
    """
    labels = np.asarray(labels)
    classes = np.unique(labels)
    if len(classes) == 0:
        return np.zeros(0, dtype=np.int64)
    per_class = max(len(labels) // len(classes), 1)
    rows = []
    for c in classes:
        own = np.flatnonzero(labels == c)
        reps = -(-per_class // len(own))  # ceil
        rows.append(np.concatenate([rng.permutation(own) for _ in range(reps)])[:per_class])
    return rng.permutation(np.concatenate(rows)).astype(np.int64)
