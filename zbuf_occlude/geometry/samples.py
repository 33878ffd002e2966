"""Samples of a dense cloud: seeds, draws and the sample record, the same bytes for every writer and reader.

Every random draw has its own generator derived from ``(seed, object_key, pose_index,
sample_index)`` with :class:`numpy.random.SeedSequence` (Sryamkin et al. 2023, §3.4 draws a
fixed-size sample from the visible points), so results are identical whatever the order, the
worker count or the sharding.  Pure numpy: the writers (``io``, ``dataset``, the farm) and
readers that rebuild samples from stored visibility masks share these functions.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.sampling import check_seed

__all__ = [
    "OccludedCloud", "object_key", "derive_rng", "sample_rng", "draw_sample", "pose_samples", "count_padded",
    "DENSE_STREAM", "DRAW_STREAM",
]  # fmt: skip

#: Stream tags keep the dense-sampling and the per-sample generators independent.
DENSE_STREAM, DRAW_STREAM = 0, 1


@dataclass
class OccludedCloud:
    """One occluded sample: a fixed-size point set seen from one pose.

    Attributes
    ----------
    points : (n, 3) float32
        World (object) frame, normalised mesh units.
    face_index : (n,) int64
        Face of the source mesh each point lies on.
    elevation_deg, azimuth_deg, radius : float
        The camera pose (degrees, degrees, object units).
    label : int
        Class index (−1 if unknown).
    class_name, source : str
        Class name and source mesh path.
    split : str
        The data-set split of the source mesh (``"train"``, ``"test"``; ``""`` if unknown).
    sample_index : int
        Which of the pose's random draws this is.
    n_visible : int
        Visible points in the dense cloud for this pose.  If ``n_visible < n``, the
        sample holds every visible point once plus repeats drawn at random (``padded``).
    """

    points: NDArray[np.float32]
    face_index: NDArray[np.int64]
    elevation_deg: float
    azimuth_deg: float
    radius: float
    label: int = -1
    class_name: str = ""
    source: str = ""
    sample_index: int = 0
    n_visible: int = 0
    split: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def padded(self) -> bool:
        """True if fewer points were visible than the sample holds (repeats added)."""
        return self.n_visible < len(self.points)


def object_key(name: str) -> int:
    """A stable 64-bit key of an object's name (BLAKE2b), for seeding.

    64 bits make a collision between two objects' seeds negligible even over all of
    ShapeNet (~5e-12 for 1e4 objects; a 32-bit CRC would give ~1 %).
    """
    # surrogateescape: a name from a non-UTF-8 file name (PEP 383) keys on its original
    # bytes; valid UTF-8 names give the same bytes, and so the same keys, as before.
    return int.from_bytes(hashlib.blake2b(name.encode("utf-8", "surrogateescape"), digest_size=8).digest(), "little")


def derive_rng(seed: int, *keys: int) -> np.random.Generator:
    """An independent generator for ``(seed, *keys)`` (``numpy.random.SeedSequence``).

    Raises InvalidInputError (:func:`~zbuf_occlude.geometry.sampling.check_seed`) for a negative seed.
    """
    if seed is None or isinstance(seed, np.random.Generator):
        raise InvalidInputError(f"seed must be a non-negative integer here (it is mixed with keys), got {seed!r}")
    return np.random.default_rng(np.random.SeedSequence([check_seed(seed), *(int(k) for k in keys)]))


def sample_rng(seed: int, key: int, pose_index: int, sample_index: int) -> np.random.Generator:
    """The generator of one sample's draw: ``(seed, key, pose_index, sample_index)``.

    Readers of compact data sets call it to redraw exactly the samples the farm drew.
    """
    return derive_rng(seed, key, DRAW_STREAM, pose_index, sample_index)


def draw_sample(
    visible_index: NDArray[np.int64], n_points: int, rng: np.random.Generator
) -> tuple[NDArray[np.int64], int]:
    """Draw ``n_points`` indices without replacement from ``visible_index``.

    If fewer are visible, all of them are taken once and the rest are repeats drawn
    uniformly at random (PointNet-style padding); the caller sees that from the returned
    count of visible points.

    Returns
    -------
    chosen : (n_points,) int64
        Indices into the dense cloud (empty if nothing is visible).
    n_visible : int
    """
    n_visible = len(visible_index)
    if n_visible == 0:
        return np.zeros(0, dtype=np.int64), 0
    if n_visible >= n_points:
        return rng.choice(visible_index, size=n_points, replace=False), n_visible
    extra = rng.choice(visible_index, size=n_points - n_visible, replace=True)
    return rng.permutation(np.concatenate([visible_index, extra])), n_visible


def pose_samples(
    visible_index: NDArray[np.int64],
    n_points: int,
    *,
    seed: int,
    key: int,
    pose_index: int,
    sample_indices: Iterable[int],
) -> list[NDArray[np.int64]]:
    """The samples of one pose: for each sample index, ``n_points`` indices into the dense
    cloud, drawn by :func:`draw_sample` with :func:`sample_rng`.

    The one place samples are drawn, for the writers and for readers that rebuild samples
    from stored visibility masks, so both give the same bytes.

    Returns
    -------
    chosen : list of (n_points,) int64
        One per sample index; empty if nothing is visible.
    """
    if len(visible_index) == 0:
        return []
    return [draw_sample(visible_index, n_points, sample_rng(seed, key, pose_index, s))[0] for s in sample_indices]


def count_padded(n_visible: Sequence[int] | NDArray[np.integer], n_points: int, samples_per_view: int) -> int:
    """How many samples of an object were padded with repeats (:func:`draw_sample`).

    Parameters
    ----------
    n_visible : (P,) int
        Visible points of the dense cloud per pose (a record's ``n_visible``).
    n_points, samples_per_view : int
        Points per sample; samples drawn per pose (a pose that sees nothing has none).

    Returns
    -------
    int
        ``samples_per_view`` times the number of poses with ``0 < n_visible < n_points``.
    """
    nv = np.asarray(n_visible, dtype=np.int64)
    return int(np.count_nonzero((nv > 0) & (nv < int(n_points)))) * int(samples_per_view)
