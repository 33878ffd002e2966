"""Leaves inside a crown: the foliage that a tree mesh's hull or leaf cards leave out.

A tree mesh made for a game or a simulator models its crown as a closed hull or a few leaf
cards: an opaque surface that a laser pulse either hits or misses.  A real crown is leaves
scattered through a volume, smaller than an airborne footprint, through which a pulse passes in
part and returns echoes from several depths.  :func:`add_foliage` fills the crown's volume with
such leaves: square leaves of side ``leaf_side_m`` whose centres are uniform (a Poisson process)
in the region inside the mesh's convex hull and within ``shell_m`` of its surface, as many as
make the **leaf area density** (LAD, one-sided leaf area per crown volume, m²/m³), their normals
uniform on the sphere (the *spherical* leaf angle distribution).  The mesh's own faces stay as
they are (unless ``keep_surface=False``): the hull or cards are the crown's dense outer foliage, the
leaves its sparse interior.

Such leaves are the discrete form of the turbid medium of canopy radiative transfer: a ray
passes a depth ``L`` of foliage with probability ``exp(−G · LAD · L)``, ``G = 0.5`` the mean
projection of a spherical distribution's leaves (J. Ross 1981, *The radiation regime and
architecture of plant stands*; T. Nilson 1971, "A theoretical analysis of the frequency of gaps
in plant stands", Agric. Meteorol. 8, 25–38), the medium that HELIOS++ scans as voxels of leaves
(Winiwarter et al. 2022, "Virtual laser scanning with HELIOS++", Remote Sens. Environ. 269,
112772).  The density is the user's: the returns experiment's is chosen on a real tile (its
results page lists the runs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.file_errors import value_kind
from zbuf_occlude.sensors.checks import count, mapping, real

if TYPE_CHECKING:
    import trimesh

__all__ = [
    "FOLIAGE_KEYS",
    "LEAF_MATERIAL",
    "MAX_LEAVES",
    "MIN_LEAF_SIDE_M",
    "Foliage",
    "add_foliage",
    "crown_region_volume",
    "in_metres",
    "leaf_quads",
]

#: Most leaves one call adds (two triangles each): a crown asking for more is refused, naming the count.
MAX_LEAVES = 2_000_000
#: Smallest leaf side, metres (a conifer's needle cluster is larger): below it the count of leaves
#: is refused as :data:`MAX_LEAVES` refuses it, before anything is drawn.
MIN_LEAF_SIDE_M = 1e-3
#: The material name of the leaves a scene object grows (:class:`~zbuf_occlude.sensors.scene.objects.SceneObject`'s
#: ``foliage``): foliage's reflectance, opaque (:data:`~zbuf_occlude.sensors.scene.materials.MATERIALS`).
LEAF_MATERIAL = "grown_leaf"
#: Keys of a scene file's ``foliage`` (:class:`Foliage`'s fields).
FOLIAGE_KEYS = ("leaf_area_density", "leaf_side_m", "shell_m", "keep_surface", "seed")
#: Uniform points drawn in the mesh's bounding box to measure the crown region's volume.
_VOLUME_SAMPLES = 400_000
#: Points of the mesh's surface per shell width, each way: the k-d tree's distances to the surface
#: exceed the true ones by at most about ``shell_m / _SURFACE_PER_SHELL``.
_SURFACE_PER_SHELL = 5
_MAX_SURFACE_SAMPLES = 500_000


class _CrownRegion:
    """Inside the convex hull of ``vertices`` and within ``shell_m`` of the surface sampled by ``surface``."""

    def __init__(self, vertices: NDArray, surface: NDArray, shell_m: float) -> None:
        from scipy.spatial import ConvexHull, Delaunay, QhullError, cKDTree

        try:  # the hull's tetrahedra: a point is inside the hull iff inside one of them
            self.hull = Delaunay(vertices[ConvexHull(vertices).vertices])
        except QhullError:  # flat or degenerate: no volume to fill
            raise InvalidInputError("the mesh encloses no volume for leaves (its convex hull is flat or degenerate)") from None
        self.tree, self.shell = cKDTree(surface), shell_m
        self.lo, self.hi = vertices.min(0), vertices.max(0)

    def contains(self, points: NDArray) -> NDArray[np.bool_]:
        inside = self.hull.find_simplex(points) >= 0
        near = np.zeros(len(points), bool)
        if inside.any():
            d, _ = self.tree.query(points[inside], distance_upper_bound=self.shell)
            near[np.flatnonzero(inside)] = np.isfinite(d)
        return near

    def uniform(self, n: int, rng: np.random.Generator) -> NDArray:
        return rng.uniform(self.lo, self.hi, (n, 3))


def _region(mesh: trimesh.Trimesh, shell_m: float, rng: np.random.Generator) -> _CrownRegion:
    import trimesh

    if not isinstance(mesh, trimesh.Trimesh):
        raise InvalidInputError(f"foliage needs a trimesh.Trimesh, got {type(mesh).__name__}")
    area = float(mesh.area)
    if not (area > 0):
        raise InvalidInputError("the mesh has no surface area to grow leaves around")
    spacing = shell_m / _SURFACE_PER_SHELL
    n_surface = int(np.clip(area / spacing**2, 1_000, _MAX_SURFACE_SAMPLES))
    surface, _ = trimesh.sample.sample_surface(mesh, n_surface, seed=int(rng.integers(2**31)))
    return _CrownRegion(np.asarray(mesh.vertices, np.float64), np.asarray(surface, np.float64), shell_m)


def in_metres(mesh: trimesh.Trimesh, size_m: float) -> trimesh.Trimesh:
    """``mesh`` scaled about its bounding box's lowest corner so that its largest dimension is ``size_m`` metres
    (a new mesh, not processed).

    Raises
    ------
    InvalidInputError
        A size not > 0, or a mesh with no extent.
    """
    import trimesh

    size = real(size_m, "size_m", low=0.0, low_open=True)
    vertices = np.asarray(mesh.vertices, np.float64)
    extent = float(np.ptp(vertices, axis=0).max()) if len(vertices) else 0.0
    if not extent > 0:
        raise InvalidInputError("the mesh has no extent to scale")
    return trimesh.Trimesh((vertices - vertices.min(0)) * (size / extent), np.asarray(mesh.faces), process=False)


def crown_region_volume(mesh: trimesh.Trimesh, *, shell_m: float = 1.0, seed: int = 0) -> float:
    """Volume of the region :func:`add_foliage` fills, m³ (the mesh in metres): Monte Carlo over the bounding box.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        In metres.
    shell_m : float
        As :func:`add_foliage`'s.
    seed : int
        Draws the samples.

    Returns
    -------
    float
        The box's volume times the share of :data:`_VOLUME_SAMPLES` uniform points in the region
        (relative standard error ``sqrt((1 − p) / (p · n))``, below 1 % where the region fills a
        fifth of the box).

    Raises
    ------
    InvalidInputError
        Not a ``trimesh.Trimesh``, a shell not > 0, or a mesh with no area or a flat hull.
    """
    shell = real(shell_m, "shell_m", low=0.0, low_open=True)
    rng = np.random.default_rng(seed)
    region = _region(mesh, shell, rng)
    return _volume(region, rng)


def _volume(region: _CrownRegion, rng: np.random.Generator) -> float:
    box = float(np.prod(region.hi - region.lo))
    return box * float(region.contains(region.uniform(_VOLUME_SAMPLES, rng)).mean())


def leaf_quads(centres: NDArray, normals: NDArray, side_m: float, rng: np.random.Generator) -> tuple[NDArray, NDArray]:
    """Square leaves: ``centres (N, 3)`` and unit ``normals (N, 3)`` float64, side ``side_m`` metres, each turned
    by a uniform angle about its normal.

    Returns
    -------
    vertices : (4N, 3) float64
        Four corners a leaf, in order around it.
    faces : (2N, 3) int64
        Two triangles a leaf, wound counter-clockwise seen from its normal.
    """
    n = len(centres)
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(normals, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(normals, u)
    turn = rng.uniform(0.0, 2.0 * math.pi, (n, 1))
    a, b = np.cos(turn) * u + np.sin(turn) * v, -np.sin(turn) * u + np.cos(turn) * v
    h = side_m / 2.0
    corners = np.stack([centres - h * a - h * b, centres + h * a - h * b, centres + h * a + h * b, centres - h * a + h * b], axis=1)
    base = 4 * np.arange(n, dtype=np.int64)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]]).reshape(2, n, 3).transpose(1, 0, 2).reshape(-1, 3)
    return corners.reshape(-1, 3), faces


@dataclass(frozen=True)
class Foliage:
    """Leaves for a scene object's crown: :func:`add_foliage`'s settings (a scene file's ``foliage``).

    Attributes
    ----------
    leaf_area_density : float
        One-sided leaf area per m³ of the crown region, m²/m³, ≥ 0 (0: no leaves).
    leaf_side_m : float
        Side of a square leaf, metres, ≥ :data:`MIN_LEAF_SIDE_M` (default 0.1, a broadleaf's).
    shell_m : float
        Depth of the crown region under the mesh's surface, metres, > 0 (default 1).
    keep_surface : bool
        True (default): the mesh's faces stay (leaf cards, a hull with gaps); False: the leaves
        alone, for a closed hull that would hide them (:func:`add_foliage`'s).
    seed : int
        Draws the leaves, ≥ 0.

    Raises
    ------
    InvalidInputError
        A field out of range or of a wrong type, naming it.
    """

    leaf_area_density: float
    leaf_side_m: float = 0.1
    shell_m: float = 1.0
    keep_surface: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "leaf_area_density", real(self.leaf_area_density, "leaf_area_density", low=0.0))
        object.__setattr__(self, "leaf_side_m", real(self.leaf_side_m, "leaf_side_m", low=MIN_LEAF_SIDE_M))
        object.__setattr__(self, "shell_m", real(self.shell_m, "shell_m", low=0.0, low_open=True))
        if not isinstance(self.keep_surface, bool):
            raise InvalidInputError(f"keep_surface must be true or false, got {value_kind(self.keep_surface)}")
        object.__setattr__(self, "seed", count(self.seed, "seed", low=0, high=2**63 - 1))

    @classmethod
    def of(cls, value: Any) -> Foliage:
        """``value`` as a :class:`Foliage`: itself, or a mapping of :data:`FOLIAGE_KEYS` (a scene file's; ``leaf_area_density`` required).

        Raises
        ------
        InvalidInputError
            Neither, an unknown or missing key, or a bad value, naming it.
        """
        if isinstance(value, cls):
            return value
        return cls(**mapping(value, "foliage", FOLIAGE_KEYS, required=("leaf_area_density",)))

    def grow(self, mesh: trimesh.Trimesh, *, max_leaves: int | None = None) -> trimesh.Trimesh:
        """:func:`add_foliage` of ``mesh`` (in metres) with these settings."""
        return add_foliage(mesh, leaf_area_density=self.leaf_area_density, leaf_side_m=self.leaf_side_m, shell_m=self.shell_m,
                           keep_surface=self.keep_surface, seed=self.seed, max_leaves=max_leaves)  # fmt: skip


def add_foliage(mesh: trimesh.Trimesh, *, leaf_area_density: float, leaf_side_m: float = 0.1, shell_m: float = 1.0,
                keep_surface: bool = True, seed: int = 0, max_leaves: int | None = None) -> trimesh.Trimesh:  # fmt: skip
    """The mesh with leaves filling its crown (module docstring).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A tree, z up, **in metres** (scale it to its real size first: the density is per m³).
    leaf_area_density : float
        One-sided leaf area per volume of the region, m²/m³, ≥ 0; 0 returns ``mesh`` itself.
    leaf_side_m : float
        Side of a square leaf, metres, ≥ :data:`MIN_LEAF_SIDE_M` (0.1: a broadleaf's; a leaf smaller
        than the footprint covers part of it, as a real one does).
    shell_m : float
        The region's depth under the mesh's surface, metres, > 0: leaves lie inside the convex
        hull and within this distance of the surface (distances to the nearest of the surface's
        sampled points), so that the space inside a whole tree's hull far from its crown (under
        it, beside the trunk) stays empty.  Leaves also grow within this distance of a trunk:
        give the crown alone where that matters.
    keep_surface : bool
        True (default): the mesh's faces stay, as the crown's dense outer foliage (leaf cards, or
        a hull with gaps); leaves under a closed hull are hidden by it from outside.  False: the
        leaves alone (a closed crown hull replaced by the leaves it bounds).
    seed : int
        Draws the leaves; the same seed gives the same mesh.
    max_leaves : int, optional
        Most leaves, 0 to :data:`MAX_LEAVES` (None, the default: :data:`MAX_LEAVES`); more are
        refused before any is drawn (a scene passes what its triangle cap leaves).

    Returns
    -------
    trimesh.Trimesh
        The mesh's vertices and faces first, unchanged (``keep_surface``), then ``2 · n`` triangles of ``n =
        round(LAD · V / leaf_side_m²)`` leaves (``V``: :func:`crown_region_volume` with the same
        seed), not processed (no merging or reordering).

    Raises
    ------
    InvalidInputError
        Not a ``trimesh.Trimesh``; a density < 0, a side below :data:`MIN_LEAF_SIDE_M`, a shell not > 0, a mesh with
        no area or a flat hull, or more than ``max_leaves`` leaves, each naming the value.
    """
    import trimesh

    lad = real(leaf_area_density, "leaf_area_density", low=0.0)
    side, shell = real(leaf_side_m, "leaf_side_m", low=MIN_LEAF_SIDE_M), real(shell_m, "shell_m", low=0.0, low_open=True)
    if lad == 0:
        return mesh
    limit = MAX_LEAVES if max_leaves is None else count(max_leaves, "max_leaves", low=0, high=MAX_LEAVES)
    rng = np.random.default_rng(seed)
    region = _region(mesh, shell, rng)
    volume = _volume(region, rng)
    wanted = lad * volume / side**2  # inf for a density near the float's limit: refused as too many
    if not wanted < limit + 0.5:
        room = "" if limit == MAX_LEAVES else f" here (what the scene's triangle cap leaves; {MAX_LEAVES:,} a crown)"
        raise InvalidInputError(
            f"leaf_area_density and leaf_side_m ask for more than {limit:,} leaves in this crown{room}: lower the density or "
            "enlarge the leaves"
        )
    n = round(wanted)
    share = volume / float(np.prod(region.hi - region.lo)) if volume > 0 else 1.0
    parts, found = [], 0
    while found < n:  # rejection sampling in the box, in batches of at most _VOLUME_SAMPLES points
        draw = region.uniform(min(_VOLUME_SAMPLES, max(1_000, math.ceil(1.5 * (n - found) / share))), rng)
        parts.append(draw[region.contains(draw)])
        found += len(parts[-1])
    centres = np.concatenate(parts)[:n] if parts else np.zeros((0, 3))
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    vertices, faces = leaf_quads(centres, normals, side, rng)
    if not keep_surface:
        return trimesh.Trimesh(vertices, faces, process=False)
    base = np.asarray(mesh.vertices, np.float64)
    return trimesh.Trimesh(
        np.concatenate([base, vertices]), np.concatenate([np.asarray(mesh.faces, np.int64), faces + len(base)]), process=False
    )
