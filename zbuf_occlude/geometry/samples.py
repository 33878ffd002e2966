"""Samples of a dense cloud: seeds, draws and the sample record, the same bytes for every writer and reader.

Every random draw has its own generator derived from ``(seed, object_key, pose_index,
sample_index)`` with :class:`numpy.random.SeedSequence` (Sryamkin et al. 2023, §3.4 draws a
fixed-size sample from the visible points), so results are identical whatever the order, the
worker count or the sharding.  Pure numpy: the writers (``io``, ``dataset``, the farm) and
readers that rebuild samples from stored visibility masks share these functions.

**Top-up.**  A pose that sees fewer than ``n_points`` of the dense cloud would give samples
padded with repeats.  :func:`top_up` instead draws more surface points on the faces the pose
sees (those holding at least one of its visible dense points), area-weighted with
:func:`~zbuf_occlude.geometry.sampling.sample_faces` (Algorithms 1-2), keeps those the same
visibility method finds visible, and stops when the pose has ``n_points`` distinct visible
points, after :data:`TOPUP_MAX_ROUNDS` rounds or :data:`TOPUP_MAX_CANDIDATES_FACTOR` ·
``n_points`` candidates.  A pose's *pool* is its visible dense points followed by its top-up
points; the samples are drawn from the pool (:func:`pool_index`, :func:`pose_samples`), so they
repeat points only when the visible surface is truly too small.  Poses that see enough dense
points draw no top-up and give the same samples as without it.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.sampling import check_seed, points_from_barycentric, sample_faces

__all__ = [
    "OccludedCloud", "ObjectProvenance", "object_key", "derive_rng", "sample_rng", "topup_rng", "draw_sample", "pose_samples",
    "count_padded", "TopUp", "top_up", "pool_index", "pool_take", "DENSE_STREAM", "DRAW_STREAM", "PROTOCOL_STREAM", "TOPUP_STREAM",
    "TOPUP_MAX_ROUNDS", "TOPUP_MAX_CANDIDATES_FACTOR", "TOPUP_MARGIN",
]  # fmt: skip

#: Stream tags keep the generators of one object independent, one tag per use: the dense cloud (0),
#: the sample draws (1), the protocols' own draws (2, :mod:`zbuf_occlude.protocols`) and the top-up
#: candidates (3).
DENSE_STREAM, DRAW_STREAM, PROTOCOL_STREAM, TOPUP_STREAM = 0, 1, 2, 3

#: Rounds of candidates :func:`top_up` draws at most for one pose.  Each round is sized from the
#: fraction of candidates found visible so far, so one or two rounds usually suffice; the bound
#: keeps a pose whose visible surface is tiny from looping.
TOPUP_MAX_ROUNDS = 4
#: At most this many times ``n_points`` candidates per pose, over all rounds: the work of a
#: top-up is bounded by that of testing ``8 · n_points`` points once.
TOPUP_MAX_CANDIDATES_FACTOR = 8
#: A round draws this many times the candidates expected to give the missing points (a
#: margin for the spread of the visible fraction, so a second round is rarely needed).
TOPUP_MARGIN = 1.25


@dataclass(frozen=True)
class ObjectProvenance:
    """Where an object comes from: what each of its samples copies (:class:`OccludedCloud`'s fields of the same names).

    Attributes
    ----------
    label : int
        Class index (−1 if unknown).
    class_name : str
        Class name (``""`` if unknown).
    source : str
        The source mesh or point-set file (``""`` if none).
    split : str
        The data-set split of the source (``"train"``, ``"test"``; ``""`` if unknown).
    """

    label: int = -1
    class_name: str = ""
    source: str = ""
    split: str = ""


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
        Distinct visible points the pose offered the sample: its visible dense points plus
        its top-up points (module docstring).  If ``n_visible < n``, the sample holds every
        one of them once plus repeats drawn at random (``padded``).
    n_topped_up : int
        How many of the ``n_visible`` points were drawn by :func:`top_up` (0 when the pose
        saw at least ``n`` dense points).
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
    n_topped_up: int = 0

    @property
    def padded(self) -> bool:
        """True if fewer distinct visible points (top-up included) were available than the sample holds (repeats added)."""
        return self.n_visible < len(self.points)

    @property
    def provenance(self) -> ObjectProvenance:
        """The sample's ``label``, ``class_name``, ``source`` and ``split``, as one value."""
        return ObjectProvenance(self.label, self.class_name, self.source, self.split)


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


def topup_rng(seed: int, key: int, pose_index: int, round_index: int) -> np.random.Generator:
    """The generator of one round of a pose's top-up candidates: ``(seed, key, TOPUP_STREAM, pose_index, round_index)``.

    Its own stream: a top-up never moves the draws of :func:`sample_rng`.
    """
    return derive_rng(seed, key, TOPUP_STREAM, pose_index, round_index)


def draw_sample(visible_index: NDArray[np.int64], n_points: int, rng: np.random.Generator) -> tuple[NDArray[np.int64], int]:
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


def pool_index(visible_index: NDArray[np.int64], n_dense: int, n_topped_up: int) -> NDArray[np.int64]:
    """A pose's pool of distinct visible points as indices: its visible dense points, then its top-up points.

    Parameters
    ----------
    visible_index : (V,) int64
        Indices of the pose's visible points in the dense cloud.
    n_dense : int
        Points in the dense cloud ``M``.
    n_topped_up : int
        The pose's top-up points ``T``; top-up point ``j`` has index ``M + j``.

    Returns
    -------
    pool : (V + T,) int64
        ``visible_index`` itself when ``T == 0`` (the draws are then those without top-up).
    """
    if not n_topped_up:
        return visible_index
    return np.concatenate([np.asarray(visible_index, dtype=np.int64), int(n_dense) + np.arange(int(n_topped_up), dtype=np.int64)])


def pool_take(dense: NDArray, topped_up: NDArray | None, chosen: NDArray[np.int64]) -> NDArray:
    """Rows of ``dense`` (index < M) or of ``topped_up`` (index M + j) for pool indices ``chosen``.

    Parameters
    ----------
    dense : (M, ...) array
        Per dense point: coordinates, face indices...
    topped_up : (T, ...) array or None
        The same per top-up point of the pose (None or empty: none).
    chosen : (n,) int64
        Pool indices (:func:`pool_index`, :func:`pose_samples`).

    Returns
    -------
    rows : (n, ...) array of ``dense``'s dtype
    """
    n_dense = len(dense)
    if topped_up is None or len(topped_up) == 0:
        return dense[chosen]
    out = np.empty((len(chosen), *dense.shape[1:]), dtype=dense.dtype)
    from_dense = chosen < n_dense
    out[from_dense] = dense[chosen[from_dense]]
    out[~from_dense] = topped_up[chosen[~from_dense] - n_dense]
    return out


def pose_samples(
    visible_index: NDArray[np.int64],
    n_points: int,
    *,
    seed: int,
    key: int,
    pose_index: int,
    sample_indices: Iterable[int],
    n_dense: int = 0,
    n_topped_up: int = 0,
) -> list[NDArray[np.int64]]:
    """The samples of one pose: for each sample index, ``n_points`` pool indices, drawn by
    :func:`draw_sample` with :func:`sample_rng` from :func:`pool_index`.

    The one place samples are drawn, for the writers and for readers that rebuild samples
    from stored visibility masks and top-up points, so both give the same bytes.

    Parameters
    ----------
    visible_index : (V,) int64
        The pose's visible dense points.
    n_dense, n_topped_up : int
        Dense cloud size and the pose's top-up points (module docstring); without top-up the
        indices are into the dense cloud.

    Returns
    -------
    chosen : list of (n_points,) int64
        One per sample index; empty if nothing is visible.  Index ``i < n_dense`` is dense
        point ``i``, ``n_dense + j`` is top-up point ``j`` (:func:`pool_take`).
    """
    if len(visible_index) == 0:
        return []
    pool = pool_index(visible_index, n_dense, n_topped_up)
    return [draw_sample(pool, n_points, sample_rng(seed, key, pose_index, s))[0] for s in sample_indices]


@dataclass
class TopUp:
    """The top-up points of one pose (:func:`top_up`).

    Attributes
    ----------
    points : (T, 3) float64
        Visible surface points, the mesh's frame (object units).
    face_index : (T,) int64
        Face of the mesh each lies on.
    candidates : int
        Candidates drawn and tested (at most ``TOPUP_MAX_CANDIDATES_FACTOR · n_points``).
    rounds : int
        Rounds drawn (at most :data:`TOPUP_MAX_ROUNDS`).
    """

    points: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    face_index: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    candidates: int = 0
    rounds: int = 0

    def __len__(self) -> int:
        return len(self.face_index)


#: ``test(points (k, 3) float64, face_index (k,) int64) -> (k,) bool``: the pose's visibility
#: method applied to candidate points.
VisibilityTest = Callable[[NDArray[np.float64], NDArray[np.int64]], NDArray[np.bool_]]


def top_up(
    triangles: NDArray[np.float64],
    seen_faces: NDArray[np.int64],
    n_missing: int,
    test: VisibilityTest,
    *,
    seed: int,
    key: int,
    pose_index: int,
    n_points: int,
    visible_fraction: float,
    max_rounds: int = TOPUP_MAX_ROUNDS,
    max_candidates_factor: int = TOPUP_MAX_CANDIDATES_FACTOR,
) -> TopUp:
    """More visible surface points for a pose that sees fewer than ``n_points`` dense points.

    Per round ``r`` (generator :func:`topup_rng` ``(seed, key, pose_index, r)``): draw
    candidates on ``seen_faces`` area-weighted (:func:`~zbuf_occlude.geometry.sampling.sample_faces`,
    Sryamkin et al. 2023, §3.4, Algorithms 1-2: uniform on those faces), keep those ``test``
    finds visible, and stop once ``n_missing`` are kept.  A round draws
    ``ceil(TOPUP_MARGIN · missing / f)`` candidates, ``f`` the fraction found visible so far
    (before the first round ``visible_fraction``; never below ``1 / max_candidates_factor``),
    within what remains of the ``max_candidates_factor · n_points`` candidates.  Kept points are
    uniform over the visible part of the seen faces, as the visible dense points are.  The last
    round may keep more than ``n_missing`` (all are kept: more distinct points to draw from).

    Parameters
    ----------
    triangles : (F, 3, 3) float64
        The mesh's triangles (:func:`~zbuf_occlude.geometry.sampling.triangles_of`).
    seen_faces : (S,) int64
        Faces holding at least one visible dense point of the pose.
    n_missing : int
        ``n_points`` minus the pose's visible dense points.
    test : callable
        ``test(points (k, 3) float64, face_index (k,) int64) -> (k,) bool``: the visibility
        method of the pose's dense points, from the same camera.
    seed, key, pose_index : int
        Seed the rounds (:func:`topup_rng`).
    n_points : int
        Points per sample (bounds the candidates).
    visible_fraction : float
        Expected fraction of candidates visible: the pose's visible dense points over the dense
        points on ``seen_faces``.
    max_rounds, max_candidates_factor : int
        The bounds (:data:`TOPUP_MAX_ROUNDS`, :data:`TOPUP_MAX_CANDIDATES_FACTOR`).

    Returns
    -------
    TopUp
        Empty when ``n_missing <= 0``, nothing is seen, or the seen faces have no area.

    Raises
    ------
    InvalidInputError
        ``test`` returned a mask of another length.
    """
    seen_faces = np.asarray(seen_faces, dtype=np.int64)
    if n_missing <= 0 or len(seen_faces) == 0:
        return TopUp()
    seen_triangles = triangles[seen_faces]
    cross = np.cross(seen_triangles[:, 1] - seen_triangles[:, 0], seen_triangles[:, 2] - seen_triangles[:, 0])
    if not np.any(cross != 0.0):  # only zero-area faces: nothing to sample
        return TopUp()
    budget = int(max_candidates_factor) * int(n_points)
    floor = 1.0 / int(max_candidates_factor)
    fraction = max(float(visible_fraction), floor)
    kept_points: list[NDArray[np.float64]] = []
    kept_faces: list[NDArray[np.int64]] = []
    kept = drawn = rounds = 0
    while rounds < max_rounds and kept < n_missing and drawn < budget:
        count = min(budget - drawn, math.ceil(TOPUP_MARGIN * (n_missing - kept) / fraction))
        local, barycentric = sample_faces(seen_triangles, count, seed=topup_rng(seed, key, pose_index, rounds))
        face_index = seen_faces[local]
        points = points_from_barycentric(triangles, face_index, barycentric)
        visible = np.asarray(test(points, face_index), dtype=bool)
        if visible.shape != (count,):
            raise InvalidInputError(f"the visibility test returned a mask of shape {visible.shape} for {count} candidates")
        kept_points.append(points[visible])
        kept_faces.append(face_index[visible])
        kept += int(visible.sum())
        drawn += count
        rounds += 1
        fraction = max(max(kept, 1) / drawn, floor)
    return TopUp(np.concatenate(kept_points), np.concatenate(kept_faces), drawn, rounds)


def count_padded(n_visible: Sequence[int] | NDArray[np.integer], n_points: int, samples_per_view: int) -> int:
    """How many samples of an object were padded with repeats (:func:`draw_sample`).

    Parameters
    ----------
    n_visible : (P,) int
        Distinct visible points per pose, top-up included (a record's ``n_visible``).
    n_points, samples_per_view : int
        Points per sample; samples drawn per pose (a pose that sees nothing has none).

    Returns
    -------
    int
        ``samples_per_view`` times the number of poses with ``0 < n_visible < n_points``.
    """
    nv = np.asarray(n_visible, dtype=np.int64)
    return int(np.count_nonzero((nv > 0) & (nv < int(n_points)))) * int(samples_per_view)
