"""The sample index of a data set: which object, pose, sample and shard row each item is (pure functions).

:class:`~zbuf_occlude.dataset.reader.OccludedDataset` serves its samples in the order the shards hold
them: object after object, each pose-major, then by sample index (:mod:`zbuf_occlude.dataset.layout`).
From each object's samples per pose and which of its rows the pose filters keep, :func:`sample_index`
builds the four arrays that map an item to its place; nothing here reads a file.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError

__all__ = ["PoseFilter", "PoseFilters", "SampleIndex", "POSE_MATCH_ATOL_DEG", "pose_mask", "samples_per_pose", "sample_index"]

#: Degrees: a pose matches a requested elevation/azimuth within this (poses are stored
#: as the exact floats of the schedule, so this only absorbs decimal round trips).
POSE_MATCH_ATOL_DEG = 1e-6

#: A filter on one angle (degrees): a value, values, or a predicate; ``None`` keeps every pose.
PoseFilter = float | Iterable[float] | Callable[[float], bool] | None


def samples_per_pose(n_visible: NDArray[np.integer], samples_per_view: int) -> NDArray[np.int64]:
    """``(P,) int64``: samples stored per pose (none where nothing is visible)."""
    return np.where(np.asarray(n_visible) > 0, int(samples_per_view), 0).astype(np.int64)


def pose_mask(values: NDArray[np.float64], spec: PoseFilter, name: str) -> NDArray[np.bool_]:
    """``(len(values),) bool``: which angles (degrees) ``spec`` keeps.

    A number or numbers keep the angles within :data:`POSE_MATCH_ATOL_DEG` of one of them; a
    predicate keeps those it is true of; ``None`` keeps all.

    Raises
    ------
    InvalidInputError
        ``spec`` is neither a predicate nor finite numbers (``name`` says which filter).
    """
    if spec is None:
        return np.ones(len(values), dtype=bool)
    if callable(spec):
        return np.array([bool(spec(float(v))) for v in values], dtype=bool)
    wanted = np.atleast_1d(np.asarray(spec, dtype=np.float64))
    if wanted.ndim != 1 or not np.all(np.isfinite(wanted)):
        raise InvalidInputError(f"{name} must be a number, a sequence of numbers or a predicate, got {spec!r}")
    return np.isclose(values[:, None], wanted[None, :], rtol=0.0, atol=POSE_MATCH_ATOL_DEG).any(axis=1)


@dataclass(frozen=True)
class PoseFilters:
    """The reader's ``elevation_deg`` and ``azimuth_deg`` filters (:data:`PoseFilter` each, degrees)."""

    elevation_deg: PoseFilter = None
    azimuth_deg: PoseFilter = None

    @property
    def active(self) -> bool:
        """Whether either filter is given."""
        return self.elevation_deg is not None or self.azimuth_deg is not None

    def mask(self, elevation_deg: NDArray[np.float64], azimuth_deg: NDArray[np.float64]) -> NDArray[np.bool_]:
        """``(N,) bool``: which of ``N`` sensor directions (degrees, seen from the object) both filters keep.

        Raises
        ------
        InvalidInputError
            A filter of the wrong kind (:func:`pose_mask`).
        """
        return pose_mask(elevation_deg, self.elevation_deg, "elevation_deg") & pose_mask(azimuth_deg, self.azimuth_deg, "azimuth_deg")

    def __str__(self) -> str:
        return f"elevation_deg={self.elevation_deg!r}, azimuth_deg={self.azimuth_deg!r}"


@dataclass(frozen=True)
class SampleIndex:
    """Where each item of a data set lies.

    Attributes
    ----------
    obj, pose, sample, row : (N,) int64
        Per item: the object (its position in the list given to :func:`sample_index`), the pose
        (for ``farm --sensor``, the scan), the sample index within the pose, and the row of the
        object's shard (or of its list of sample files).
    n_unfiltered : int
        Items before the keep masks were applied.
    """

    obj: NDArray[np.int64]
    pose: NDArray[np.int64]
    sample: NDArray[np.int64]
    row: NDArray[np.int64]
    n_unfiltered: int

    def __len__(self) -> int:
        return len(self.obj)


def sample_index(rows_per_pose: Sequence[ArrayLike], keep: Sequence[NDArray[np.bool_] | None] | None = None) -> SampleIndex:
    """The index of the samples of several objects, pose-major within each object.

    Parameters
    ----------
    rows_per_pose : sequence of (P_k,) int
        Per object, the samples each of its poses stores (:func:`samples_per_pose`).
    keep : sequence of (B_k,) bool or None, optional
        Per object, which of its ``B_k = sum(rows_per_pose[k])`` rows to keep (``None``: all).

    Returns
    -------
    SampleIndex
        Object ``k``'s kept rows, in order, after those of objects ``0 .. k-1``.

    Raises
    ------
    ValueError
        A keep mask of another length than its object's rows.
    """
    parts: list[tuple[NDArray[np.int64], ...]] = []
    n_unfiltered = 0
    for k, spp in enumerate(rows_per_pose):
        spp = np.asarray(spp, dtype=np.int64)
        pose = np.repeat(np.arange(len(spp), dtype=np.int64), spp)
        sample = np.arange(len(pose), dtype=np.int64) - np.repeat(np.cumsum(spp) - spp, spp)
        mask = None if keep is None else keep[k]
        mask = np.ones(len(pose), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        if mask.shape != pose.shape:
            raise ValueError(f"object {k}: keep mask of shape {mask.shape} for {len(pose)} rows")
        n_unfiltered += len(pose)
        parts.append((np.full(int(mask.sum()), k, dtype=np.int64), pose[mask], sample[mask], np.flatnonzero(mask)))
    obj, pose, sample, row = (
        np.concatenate([p[i] for p in parts]).astype(np.int64) if parts else np.zeros(0, dtype=np.int64) for i in range(4)
    )
    return SampleIndex(obj, pose, sample, row, n_unfiltered)
