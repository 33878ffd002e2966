"""Tree cover: how much of the ground the crowns cover, on a real LAS tile and on a simulated plot.

How many ground returns come from pulses that passed through a crown first depends on how much of
the ground the crowns cover.  :func:`tree_cover` measures it on a LAS file (the share of square
cells whose highest return is vegetation rather than ground), :func:`plot_cover` on a plot of
meshes the same way with vertical rays, and :func:`spacing_for_cover` spaces the plot's trees
(:func:`~.returns.plot_scene`) so that its cover equals the real tile's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.returns import GROUND_CLASS, plot_scene
from zbuf_occlude.io.las import LasPoints
from zbuf_occlude.sensors.checks import count, real
from zbuf_occlude.sensors.fit import Estimate
from zbuf_occlude.sensors.fit.returns import VEGETATION_CLASSES
from zbuf_occlude.sensors.scene.objects import ScanScene

__all__ = [
    "COVER_STEPS", "COVER_TOLERANCE", "MAX_COVER_CELLS_ACROSS", "MAX_COVER_RAYS", "TREE_COVER_BLOCK_M", "TREE_COVER_CELL_M",
    "TREE_COVER_MIN_PULSES", "CellTops", "cell_tops", "plot_cover", "spacing_for_cover", "tree_cover", "vertical_tops",
]  # fmt: skip

#: Side of the square cells on which :func:`tree_cover` tells a covered cell from open ground,
#: metres: a canopy height model's usual cell, and about the distance between the IGN sample's
#: pulses (about 20 first returns per m² where its strips are whole).
TREE_COVER_CELL_M = 1.0
#: Least first returns (pulses) in a cell for :func:`tree_cover` to count it: the IGN sample is thinned
#: into strips whose edges hold one or two pulses a cell, too few to tell what is highest there.
TREE_COVER_MIN_PULSES = 5
#: Side of the blocks of cells that :func:`tree_cover`'s bootstrap draws, metres: neighbouring cells
#: lie under the same crowns and are not independent draws (a crown is up to about 10 m across).
TREE_COVER_BLOCK_M = 10.0
#: :func:`spacing_for_cover` stops when the plot's cover is this close to the target (a share; the
#: IGN sample's cover has a standard deviation of about 0.02).
COVER_TOLERANCE = 0.002
#: Bisection steps of :func:`spacing_for_cover` at most (each builds the plot and casts its rays).
COVER_STEPS = 30
#: Most rays :func:`plot_cover` casts (its cells times the rays per cell; about 100 bytes each while cast):
#: the experiment's plot casts about 25,000, a plot of 30 m trees 36 m apart about 400,000.
MAX_COVER_RAYS = 4_000_000
#: Largest plot side over cell side :func:`tree_cover` grids (beyond it the cells' indices lose precision).
MAX_COVER_CELLS_ACROSS = 2**31


def _cell_cover(xy: NDArray[np.float64], top_is_vegetation: NDArray[np.bool_], block_m: float, *, seed: int,
                bootstrap: int, what: str) -> Estimate:  # fmt: skip
    """The share of cells (one row each: ``xy`` a corner, metres) that are vegetation, ± a bootstrap over ``block_m`` blocks."""
    from zbuf_occlude.sensors.fit.returns import pulse_bootstrap

    if len(xy) == 0:
        raise InvalidInputError(f"tree_cover: {what}")
    blocks = np.floor((xy - xy.min(axis=0)) / block_m).astype(np.int64)
    _, block = np.unique(blocks, axis=0, return_inverse=True)
    block = block.reshape(-1)
    hits = top_is_vegetation.astype(np.float64)

    def share(w: NDArray[np.float64] | None) -> float:
        if w is None:
            return float(hits.mean())
        cell_w = w[block]
        return float(np.dot(cell_w, hits) / cell_w.sum()) if cell_w.sum() > 0 else math.nan

    value, std = pulse_bootstrap(int(block.max()) + 1, {"cover": share}, seed=seed, bootstrap=bootstrap)["cover"]
    return Estimate(value, std, len(xy), f"bootstrap over {block_m:g} m blocks of cells", "share")


def tree_cover(las: LasPoints, *, classes: Sequence[int] = VEGETATION_CLASSES, cell_m: float = TREE_COVER_CELL_M,
               min_pulses: int = TREE_COVER_MIN_PULSES, block_m: float = TREE_COVER_BLOCK_M, seed: int = 0,
               bootstrap: int = 200) -> Estimate:  # fmt: skip
    """The share of a scan's ground under crowns: of the square cells whose highest return is on
    vegetation (``classes``) or on the ground (class 2), those whose highest return is on vegetation.

    A cell counts when it holds at least ``min_pulses`` first returns (one per pulse); a cell whose
    highest return is of another class (a building, a bridge, noise) does not count.  The same
    measure on a real tile and on a simulated scan read back from LAS, at about the same density
    of pulses, compares their tree cover like with like.

    Parameters
    ----------
    las : LasPoints
        The scan with classes, x and y in a projected reference system (cut into cells of metres:
        :attr:`~zbuf_occlude.io.las.LasPoints.metres_per_unit` turns a file in feet into metres).
    classes : sequence of int
        The vegetation classes (ASPRS 3, 4 and 5 by default).
    cell_m : float
        Side of the cells, metres (:data:`TREE_COVER_CELL_M`); the grid starts at the scan's least x and y.
    min_pulses : int
        Least first returns in a counted cell (:data:`TREE_COVER_MIN_PULSES`).
    block_m : float
        Side of the blocks of cells the bootstrap draws whole, metres (:data:`TREE_COVER_BLOCK_M`).
    seed, bootstrap : int
        Of the bootstrap (:func:`~zbuf_occlude.sensors.fit.returns.pulse_bootstrap`).

    Returns
    -------
    Estimate
        ``value``: the share, 0 to 1; ``std``: its standard deviation over the resamples of
        blocks; ``n``: the cells counted; unit ``"share"``.

    Raises
    ------
    InvalidInputError
        ``cell_m`` or ``block_m`` not a finite number > 0, ``min_pulses`` not a whole number >= 1,
        a scan more than :data:`MAX_COVER_CELLS_ACROSS` cells across, no cell counted, or a seed or
        bootstrap the bootstrap refuses.
    """
    block_m = real(block_m, "block_m", low=0.0, low_open=True)
    tops = cell_tops(las, classes=classes, cell_m=cell_m, min_pulses=min_pulses)
    return _cell_cover(tops.corners_m[tops.counted], tops.vegetation[tops.counted], block_m, seed=seed, bootstrap=bootstrap,
                       what=f"no cell of {tops.cell_m:g} m holds {tops.min_pulses} pulses and a highest return on vegetation or the ground")  # fmt: skip


@dataclass(frozen=True)
class CellTops:
    """The highest return of each square cell of a scan (:func:`cell_tops`); ``C`` cells hold a return.

    Attributes
    ----------
    corners_m : (C, 2) float64
        Each cell's corner, metres from the scan's least x and y.
    highest : (C,) int64
        The row of the scan's points that is the cell's highest return.
    vegetation : (C,) bool
        That return is on vegetation.
    counted : (C,) bool
        The cell holds ``min_pulses`` first returns or more and its highest return is vegetation or the ground.
    cell_m : float
    min_pulses : int
    """

    corners_m: NDArray[np.float64]
    highest: NDArray[np.int64]
    vegetation: NDArray[np.bool_]
    counted: NDArray[np.bool_]
    cell_m: float
    min_pulses: int


def cell_tops(las: LasPoints, *, classes: Sequence[int] = VEGETATION_CLASSES, cell_m: float = TREE_COVER_CELL_M,
              min_pulses: int = TREE_COVER_MIN_PULSES) -> CellTops:  # fmt: skip
    """The highest return of each ``cell_m`` square cell of ``las`` and whether the cell counts, as :func:`tree_cover` counts cells.

    x and y are in metres (:attr:`~zbuf_occlude.io.las.LasPoints.metres_per_unit`: a file in feet
    is cut into cells of ``cell_m`` metres too); the grid starts at the scan's least x and y.

    Raises
    ------
    InvalidInputError
        ``cell_m`` not a finite number > 0, ``min_pulses`` not a whole number >= 1, no point, or a
        scan more than :data:`MAX_COVER_CELLS_ACROSS` cells across.
    """
    cell_m = real(cell_m, "cell_m", low=0.0, low_open=True)
    min_pulses = count(min_pulses, "min_pulses", low=1, high=2**31)
    xy = las.points[:, :2] * las.metres_per_unit
    if len(xy) == 0:
        raise InvalidInputError("tree_cover: the scan holds no point")
    offset = xy.min(axis=0)
    if float(np.max(xy.max(axis=0) - offset)) / cell_m >= MAX_COVER_CELLS_ACROSS:
        raise InvalidInputError(f"tree_cover: the scan is more than {MAX_COVER_CELLS_ACROSS:,} cells of {cell_m:g} m across")
    cells, cell = np.unique(np.floor((xy - offset) / cell_m).astype(np.int64), axis=0, return_inverse=True)
    cell = cell.reshape(-1)
    order = np.lexsort((las.points[:, 2], cell))  # by cell, then height: each cell's last row is its highest return
    highest = order[np.r_[np.flatnonzero(np.diff(cell[order])), len(order) - 1]]
    top = las.classification[highest]
    pulses = np.bincount(cell, weights=las.return_number == 1, minlength=len(cells))
    vegetation = np.isin(top, np.asarray(classes, np.int64))
    counted = (pulses >= min_pulses) & (vegetation | (top == GROUND_CLASS))
    return CellTops(cells * cell_m, highest.astype(np.int64), vegetation, counted, cell_m, min_pulses)


def plot_cover(scene: ScanScene, center_xy, half_size_m: float, vegetation_ids: Sequence[int], *, cell_m: float = TREE_COVER_CELL_M,
               rays_per_cell: int, seed: int = 0) -> float:  # fmt: skip
    """The tree cover of a scene as :func:`tree_cover` measures a scan, from vertical rays.

    The square ``center_xy ± half_size_m`` is cut into cells of ``cell_m``; each cell casts
    ``rays_per_cell`` vertical rays down from above the scene at uniformly drawn points; the
    cell's highest hit is on vegetation (``vegetation_ids``), on the ground (object 0) or on
    something else (not counted), like a scan's highest return in a cell.

    Parameters
    ----------
    scene : ScanScene
        World frame, metres, z up.
    center_xy : (float, float)
        Centre of the square, metres.
    half_size_m : float
        Half its side, metres (> 0).
    vegetation_ids : sequence of int
        The objects that are vegetation.
    cell_m : float
        Side of the cells, metres.
    rays_per_cell : int
        Vertical rays per cell (the scan's pulses per cell: pooled flight lines times pulses per
        m² times ``cell_m``²).
    seed : int
        Draws the rays' points.

    Returns
    -------
    float
        The share of counted cells whose highest hit is vegetation, 0 to 1; NaN where no cell
        counts (the square off the ground).

    Raises
    ------
    InvalidInputError
        A size not finite > 0, ``rays_per_cell`` below 1, more than :data:`MAX_COVER_RAYS` rays.
    """
    first, _ = vertical_tops(scene, center_xy, half_size_m, cell_m=cell_m, rays_per_cell=rays_per_cell, seed=seed)
    vegetation = np.isin(first, np.asarray(vegetation_ids, np.int64))
    counted = vegetation | (first == 0)
    return float(vegetation[counted].mean()) if counted.any() else math.nan


def vertical_tops(scene: ScanScene, center_xy, half_size_m: float, *, cell_m: float, rays_per_cell: int,
                  seed: int = 0) -> tuple[NDArray[np.int64], NDArray[np.float64]]:  # fmt: skip
    """The highest hit of each cell of a square of a scene, from vertical rays (:func:`plot_cover`'s cells and rays).

    Returns
    -------
    object_id : (C,) int64
        The object of each cell's highest hit (0 the ground), -1 where no ray hits; ``C`` is the
        number of cells, row by row.
    z_m : (C,) float64
        That hit's height, metres (world z); NaN where no ray hits.

    Raises
    ------
    InvalidInputError
        A size not finite > 0, ``rays_per_cell`` below 1, more than :data:`MAX_COVER_RAYS` rays.
    """
    from zbuf_occlude.sensors.raycast.embree import cast_embree

    half_size_m = real(half_size_m, "half_size_m", low=0.0, low_open=True)
    cell_m = real(cell_m, "cell_m", low=0.0, low_open=True)
    rays_per_cell = count(rays_per_cell, "rays_per_cell", low=1, high=MAX_COVER_RAYS)
    across = max(1, round(2.0 * half_size_m / cell_m))
    if across * across * rays_per_cell > MAX_COVER_RAYS:
        raise InvalidInputError(f"plot_cover: {across}² cells × {rays_per_cell} rays is more than {MAX_COVER_RAYS:,} rays")
    built = scene.build()
    rng = np.random.default_rng(seed)
    corner = np.asarray(center_xy, np.float64) - half_size_m
    ij = np.stack(np.meshgrid(np.arange(across), np.arange(across), indexing="ij"), axis=-1).reshape(-1, 2)
    xy = corner + (np.repeat(ij, rays_per_cell, axis=0) + rng.random((len(ij) * rays_per_cell, 2))) * (2.0 * half_size_m / across)
    top = float(built.mesh.vertices[:, 2].max()) + 1.0
    origins = np.column_stack([xy, np.full(len(xy), top)])
    face, t = cast_embree(built.mesh, origins, np.broadcast_to([0.0, 0.0, -1.0], origins.shape))
    hit = np.where(face >= 0, built.face_object[np.maximum(face, 0)], -1).reshape(-1, rays_per_cell)
    t = t.reshape(-1, rays_per_cell)
    nearest = np.argmin(t, axis=1)
    rows = np.arange(len(hit))
    first = hit[rows, nearest].astype(np.int64)
    return first, np.where(first >= 0, top - t[rows, nearest], np.nan)


def spacing_for_cover(meshes: Sequence, sizes_m: Sequence[float], cover: float, *, center_xy=(0.0, 0.0), cell_m: float = TREE_COVER_CELL_M,
                      rays_per_cell: int, seed: int = 0) -> float:  # fmt: skip
    """The spacing of :func:`plot_scene`'s grid whose square of ground has the tree cover ``cover``.

    The plot's square is the grid's (``ceil(sqrt(n))`` cells of the spacing a side), its cover
    :func:`plot_cover`'s; the spacing is bracketed from the largest size (crowns about touching)
    by doubling or halving it, then found by bisection on its logarithm, to within
    :data:`COVER_TOLERANCE` or after :data:`COVER_STEPS` steps, the closest found (the cover of a
    plot of few cells moves in steps as the spacing grows).  Crowns closer than their width overlap
    (a closed canopy), as they do in a forest.

    Parameters
    ----------
    meshes, sizes_m
        As :func:`plot_scene`'s.
    cover : float
        The tree cover wanted, in (0, 1) (:func:`tree_cover` of a real tile).
    center_xy, seed
        As :func:`plot_scene`'s (the yaws; the rays' points too).
    cell_m, rays_per_cell
        As :func:`plot_cover`'s.

    Returns
    -------
    float
        The spacing, metres.

    Raises
    ------
    InvalidInputError
        A cover outside (0, 1), one the meshes cannot give within :data:`COVER_STEPS` doublings or
        halvings of the spacing, or a plot too large for :func:`plot_cover` on the way.
    """
    cover = real(cover, "cover", low=0.0, high=1.0, low_open=True, high_open=True)
    side = math.ceil(math.sqrt(len(meshes))) if len(meshes) else 1

    def cover_at(spacing: float) -> float:
        scene, vegetation = plot_scene(meshes, sizes_m, spacing_m=spacing, center_xy=center_xy, seed=seed)
        return plot_cover(scene, center_xy, side * spacing / 2.0, vegetation, cell_m=cell_m, rays_per_cell=rays_per_cell, seed=seed)

    largest = max((float(v) for v in sizes_m), default=0.0)
    # bracket the cover: from the largest size apart (crowns about touching), double or halve the spacing
    start = math.log(largest if largest > 0 else 1.0)
    at_start = cover_at(math.exp(start))
    step = math.log(2.0) if at_start > cover else -math.log(2.0)
    low = high = start
    for _ in range(COVER_STEPS):
        if (at_start > cover) == (cover_at(math.exp(high + step)) > cover):
            high += step
            continue
        low, high = sorted((high, high + step))
        break
    else:
        raise InvalidInputError(f"spacing_for_cover: a tree cover of {cover:.3g} is out of these meshes' reach "
                                f"({at_start:.3g} with them {math.exp(start):.3g} m apart, the same {COVER_STEPS} doublings further)")  # fmt: skip
    best = (abs(at_start - cover), start)
    for _ in range(COVER_STEPS):
        middle = (low + high) / 2.0
        got = cover_at(math.exp(middle))
        best = min(best, (abs(got - cover), middle))
        if best[0] <= COVER_TOLERANCE:
            break
        low, high = (middle, high) if got > cover else (low, middle)
    return math.exp(best[1])
