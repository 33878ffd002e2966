"""Uniform random points on a triangle mesh (Sryamkin et al. 2023, §3.4, Algorithms 1 and 2).

Sryamkin, Msallam, Klestov, "A method to create real-like point clouds for 3D object
classification", 2023.  §3.4 samples the surface uniformly in two steps:

* Algorithm 1 (how many points per face): with ``s`` points per unit area, face ``f``
  of area ``A_f`` gets ``floor(A_f · s)`` points plus one more with probability equal
  to the fractional part of ``A_f · s`` (stochastic rounding), so the expected count is
  exactly ``A_f · s``.  :func:`sample_faces` ``(density=s)``.
* Algorithm 2 (where in the face): two uniforms ``r1, r2`` in [0, 1); if
  ``r1 + r2 > 1`` they are folded back to ``1 − r1, 1 − r2``; the point is
  ``v0 + r1 (v1 − v0) + r2 (v2 − v0)``, i.e. barycentric ``(1 − r1 − r2, r1, r2)``.

For a fixed number of points (``count=N``) faces are drawn i.i.d. with probability
proportional to their area and Algorithm 2 places the point in the face.

Samples are returned as ``(face_index, barycentric)`` so that callers can rebuild
points, normals or colours exactly (:func:`points_from_barycentric`).  Every function
takes an explicit ``seed``; the same seed gives the same bytes.
"""

from __future__ import annotations

import math
import numbers
import os
import reprlib
from typing import TYPE_CHECKING, TypeAlias

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.defaults import MAX_SEED
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.arguments import check_mesh
from zbuf_occlude.resources import BYTES_PER_DENSE_POINT, check_memory

if TYPE_CHECKING:  # imported where a mesh is looked at: check_seed's users (the farm's options) need no trimesh
    import trimesh

__all__ = [
    "sample_faces",
    "points_from_barycentric",
    "sample_surface",
    "triangles_of",
    "check_seed",
    "SeedLike",
]

#: What the ``seed`` argument accepts: an int (or None for OS entropy), or a Generator
#: that is used, and advanced, as is.
SeedLike = int | np.random.Generator | None

#: A mesh, or its triangles as a (F, 3, 3) array of corner coordinates.
MeshOrTriangles: TypeAlias = "trimesh.Trimesh | ArrayLike"


def triangles_of(mesh_or_triangles: MeshOrTriangles) -> NDArray[np.float64]:
    """Corner coordinates of every face.

    Parameters
    ----------
    mesh_or_triangles : trimesh.Trimesh or (F, 3, 3) array_like
        A mesh, or triangles given by their corners ``[face, corner, xyz]``.

    Returns
    -------
    triangles : (F, 3, 3) float64
        ``triangles[f, k]`` is corner ``k`` of face ``f``, in the mesh's frame.

    Raises
    ------
    InvalidInputError
        On a wrong shape or NaN/inf coordinates.
    """
    import trimesh

    if isinstance(mesh_or_triangles, (str, bytes, os.PathLike)):
        check_mesh(mesh_or_triangles)  # a file name: load it first (the error says how)
    if isinstance(mesh_or_triangles, trimesh.Trimesh):
        vertices = np.asarray(mesh_or_triangles.vertices, dtype=np.float64)
        faces = np.asarray(mesh_or_triangles.faces, dtype=np.int64).reshape(-1, 3)
        triangles = vertices[faces] if len(faces) else np.zeros((0, 3, 3))
    else:
        try:
            triangles = np.asarray(mesh_or_triangles, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise InvalidInputError(f"triangles must be a (F, 3, 3) float array: {exc}") from exc
        if triangles.ndim != 3 or triangles.shape[1:] != (3, 3):
            raise InvalidInputError(f"triangles must have shape (F, 3, 3), got {triangles.shape}")
    if not np.isfinite(triangles).all():
        raise InvalidInputError("mesh or triangles contain NaN or inf coordinates")
    return triangles


def _areas(triangles: NDArray[np.float64]) -> NDArray[np.float64]:
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    return 0.5 * np.sqrt(np.einsum("ij,ij->i", cross, cross))


def _in_triangle(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    """(n, 3) float64 barycentric coordinates, uniform in the triangle (Algorithm 2)."""
    r = rng.random((n, 2))
    # Fold where 1 − r1 − r2 < 0, which is the paper's r1 + r2 > 1 but evaluated without
    # rounding: numpy's doubles are multiples of 2^-53 in [0, 1), so 1 − r1 and then
    # − r2 are exact, while r1 + r2 may round down to 1 and leave w0 = −2^-53.
    w0 = (1.0 - r[:, 0]) - r[:, 1]
    fold = w0 < 0.0
    r[fold] = 1.0 - r[fold]
    w0 = (1.0 - r[:, 0]) - r[:, 1]
    return np.column_stack([w0, r[:, 0], r[:, 1]])


def _check_count(count: object) -> int:
    if isinstance(count, (bool, np.bool_)) or not isinstance(count, numbers.Integral):
        raise InvalidInputError(f"count must be an integer, got {count!r}")
    if count < 0:
        raise InvalidInputError(f"count must be >= 0, got {count}")
    return int(count)


def check_seed(seed: object, *, name: str = "seed") -> SeedLike:
    """Validate a seed before any work: a non-negative int, None or a numpy Generator.

    numpy rejects negative seeds deep inside ``default_rng``/``SeedSequence`` with a bare
    ValueError; this names the argument (``name``, e.g. ``"--seed"`` for the CLI) and value.

    Parameters
    ----------
    seed : object
        What to check.
    name : str
        The argument or option named in the message.

    Returns
    -------
    seed : int, numpy.random.Generator or None
        ``seed`` itself, a numpy integer turned into an int.

    Raises
    ------
    InvalidInputError
        If ``seed`` is negative, above :data:`~zbuf_occlude.defaults.MAX_SEED`, a bool, or not an
        integer, None or Generator.
    """
    if seed is None or isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral):
        raise InvalidInputError(f"{name} must be a non-negative integer (or None, or a numpy Generator), got {reprlib.repr(seed)}")
    if seed < 0:
        raise InvalidInputError(f"{name} must be a non-negative integer, got {_integer_text(seed)}")
    if seed > MAX_SEED:
        raise InvalidInputError(
            f"{name} must be at most 2**63 - 1 = {MAX_SEED} (MAX_SEED: seeds are stored as int64), got {_integer_text(seed)}"
        )
    return int(seed)


#: Integers longer than this (in bits) are described by their number of digits in messages: Python
#: refuses to write an int of over 4,300 digits as text, and nobody reads one.
_SHOWN_INTEGER_BITS = 256


def _integer_text(value: numbers.Integral) -> str:
    """``value`` as text for a one-line message, or "an integer of about N digits" when it is huge."""
    bits = abs(int(value)).bit_length()
    if bits <= _SHOWN_INTEGER_BITS:
        return str(value)
    return f"{'-' if value < 0 else ''}an integer of about {int(bits * math.log10(2)) + 1:,} digits"


def _check_density(density: object) -> float:
    if isinstance(density, (bool, np.bool_)) or not isinstance(density, numbers.Real):
        raise InvalidInputError(f"density must be a real number of points per unit area, got {density!r}")
    if not (math.isfinite(density) and density > 0.0):
        raise InvalidInputError(f"density must be finite and > 0 points per unit area, got {density}")
    return float(density)


def sample_faces(
    mesh: MeshOrTriangles,
    count: int | None = None,
    *,
    density: float | None = None,
    seed: SeedLike = 0,
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Uniform random samples on the surface, as faces and barycentric coordinates.

    Sryamkin et al. 2023, §3.4: Algorithm 1 (points per face, ``density`` mode) and
    Algorithm 2 (uniform point in a triangle).  Give exactly one of ``count`` and
    ``density``.

    Parameters
    ----------
    mesh : trimesh.Trimesh or (F, 3, 3) array_like
        The surface (see :func:`triangles_of`).  Zero-area faces are never sampled.
    count : int, optional
        Exactly this many points; faces are drawn i.i.d. with probability
        ``A_f / sum(A)``.  Points are in draw order (not grouped by face), so any
        prefix is itself a uniform sample.
    density : float, optional
        Points per unit area, ``s`` of Algorithm 1: face ``f`` gets
        ``floor(A_f · s)`` points plus one with probability ``frac(A_f · s)``.  The
        total is random with mean ``sum(A) · s``.  Points are grouped by face, in face
        order.
    seed : int, numpy.random.Generator or None
        Source of randomness; ``numpy.random.default_rng(seed)``.  The same int gives
        the same bytes.  A Generator is advanced.  Checked by :func:`check_seed`.

    Returns
    -------
    face_index : (N,) int64
        Index of the face each sample lies on.
    barycentric : (N, 3) float64
        Weights of the face's corners ``(1 − r1 − r2, r1, r2)``, each >= 0, summing to 1.

    Raises
    ------
    InvalidInputError
        If ``seed`` is negative or not an integer/Generator/None, both or neither of
        ``count`` and ``density`` are given, ``count < 0``,
        ``density`` is not finite and > 0, the mesh has NaN/inf coordinates or zero
        total area, or ``density`` is so large that the point count overflows.
    InsufficientMemoryError
        (an InvalidInputError) The points would not fit in the memory available
        (:func:`zbuf_occlude.resources.check_memory`).
    """
    seed = check_seed(seed)
    if (count is None) == (density is None):
        raise InvalidInputError(
            f"give exactly one of count (points) and density (points per unit area), got count={count!r}, density={density!r}"
        )
    if count is not None:
        count = _check_count(count)
    else:
        density = _check_density(density)
    triangles = triangles_of(mesh)
    areas = _areas(triangles)
    # The total is the last entry of the cumulative table itself, so that a draw below
    # the total always falls inside the table.
    cumulative = np.cumsum(areas)
    total = float(cumulative[-1]) if len(cumulative) else 0.0
    if not total > 0.0:
        raise InvalidInputError(f"mesh has zero total area ({len(areas)} faces); there is no surface to sample")
    rng = np.random.default_rng(seed)

    if count is not None:
        check_memory(count * BYTES_PER_DENSE_POINT, option=f"count={count:,}", hint="sample fewer points")
        # Inverse-CDF draw of faces: u in [0, total) falls in face f when
        # cumulative[f-1] <= u < cumulative[f]; zero-area faces span an empty interval.
        u = rng.random(count) * total
        face_index = np.searchsorted(cumulative, u, side="right")
        # u * total can round up to total itself; clamp to the last face with area.
        last = int(np.flatnonzero(areas > 0.0)[-1])
        face_index = np.minimum(face_index, last).astype(np.int64)
    else:
        with np.errstate(over="ignore"):  # overflow is reported just below
            expected = areas * density
            total_expected = expected.sum()
        if not np.isfinite(total_expected):
            raise InvalidInputError(f"density {density} is too large: the expected point count overflows")
        check_memory(
            int(total_expected) * BYTES_PER_DENSE_POINT,
            option=f"density={density:g} ({int(total_expected):,} points expected)",
            hint="lower the density",
        )
        # Algorithm 1: stochastic rounding keeps the expected count of every face exact.
        whole = np.floor(expected)
        per_face = whole.astype(np.int64) + (rng.random(len(areas)) < expected - whole)
        face_index = np.repeat(np.arange(len(areas), dtype=np.int64), per_face)

    return face_index, _in_triangle(rng, len(face_index))


def points_from_barycentric(
    mesh_or_triangles: MeshOrTriangles,
    face_index: ArrayLike,
    barycentric: ArrayLike,
) -> NDArray[np.float64]:
    """Points from face indices and barycentric coordinates.

    ``point = b0 · v0 + b1 · v1 + b2 · v2`` for the corners ``v0, v1, v2`` of the face,
    which for ``b = (1 − r1 − r2, r1, r2)`` is ``v0 + r1 (v1 − v0) + r2 (v2 − v0)`` of
    Sryamkin et al. 2023, §3.4, Algorithm 2.

    Parameters
    ----------
    mesh_or_triangles : trimesh.Trimesh or (F, 3, 3) array_like
        The surface (see :func:`triangles_of`).
    face_index : (N,) int
        Face of each point, in [0, F).
    barycentric : (N, 3) float
        Weights of the face's corners.

    Returns
    -------
    points : (N, 3) float64
        In the mesh's frame.

    Raises
    ------
    InvalidInputError
        On wrong shapes or dtypes, indices out of range, or NaN/inf weights.
    """
    triangles = triangles_of(mesh_or_triangles)
    face_index = np.asarray(face_index)
    barycentric = np.asarray(barycentric, dtype=np.float64)
    if face_index.ndim != 1 or (face_index.size and not np.issubdtype(face_index.dtype, np.integer)):
        raise InvalidInputError(f"face_index must be a (N,) integer array, got {face_index.dtype} {face_index.shape}")
    if barycentric.shape != (len(face_index), 3):
        raise InvalidInputError(f"barycentric must have shape ({len(face_index)}, 3) to match face_index, got {barycentric.shape}")
    if not np.isfinite(barycentric).all():
        raise InvalidInputError("barycentric contains NaN or inf")
    face_index = face_index.astype(np.int64)
    if len(face_index) and (face_index.min() < 0 or face_index.max() >= len(triangles)):
        raise InvalidInputError(f"face_index spans [{face_index.min()}, {face_index.max()}] but the mesh has {len(triangles)} faces")
    corners = triangles[face_index]
    return np.einsum("nk,nkj->nj", barycentric, corners)


def sample_surface(
    mesh: MeshOrTriangles,
    count: int | None = None,
    *,
    density: float | None = None,
    seed: SeedLike = 0,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Uniform random points on the surface (Sryamkin et al. 2023, §3.4, Algorithms 1 and 2).

    :func:`sample_faces` followed by :func:`points_from_barycentric`; see the former
    for ``count``, ``density`` and ``seed``.

    Returns
    -------
    samples : (N, 3) float64
        Points on the surface, in the mesh's frame.  ``N == count`` in count mode.
    face_index : (N,) int64
        Index into ``mesh.faces`` of the face each point lies on.

    Raises
    ------
    InvalidInputError
        As :func:`sample_faces`.
    """
    face_index, barycentric = sample_faces(mesh, count, density=density, seed=seed)
    return points_from_barycentric(mesh, face_index, barycentric), face_index
