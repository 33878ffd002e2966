"""The share of a sub-ray's energy that reaches each of its hits through the surfaces before it, and comes back.

Where a scan casts every hit along a sub-ray (surfaces that transmit: foliage as a gap fraction, a
mesh fence, a pane), :func:`~zbuf_occlude.sensors.beam.echo_energy.echo_returns` weighs each hit's energy
(:func:`~zbuf_occlude.sensors.beam.echoes.hit_energy`) by :func:`attenuate_along_subray` before resolving echoes.
A surface whose gaps are places, not a share of every sub-ray's energy (a crown's foliage: leaves and the
holes between them), is a mosaic of cells that are leaf or gap (:func:`gap_cells_open`): a sub-ray that meets
a leaf cell is stopped there and returns its echo, one that meets a gap goes on whole and returns none.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.hit_rows import hit_columns, rank_in_run, sorted_order

__all__ = ["GAP_CELL_SALT", "attenuate_along_subray", "gap_cells_open"]

#: Mixed into the cells' hash: the one pattern of leaf and gap cells of every scan (a tree at one place shows
#: the same gaps to every pulse and every scan, as a real one does).
GAP_CELL_SALT = 0x5EED_F011A6E5


def attenuate_along_subray(
    subray: ArrayLike,
    range_m: ArrayLike,
    surface: ArrayLike,
    surface_transmittance: ArrayLike,
) -> NDArray[np.float64]:
    """(M,) float64: the share of a sub-ray's energy that reaches each of its hits and comes back.

    Where a scan casts all hits along a sub-ray (not only the first), a hit's energy
    (:func:`hit_energy`) is multiplied by this factor: the product of the transmittances of the
    surfaces hit strictly nearer along the same sub-ray.  The first hit gets 1; behind an opaque
    surface (transmittance 0) a hit gets 0, so it returns nothing.  Hits at the same range of
    one sub-ray (a ray through a shared edge) do not shade each other.

    Parameters
    ----------
    subray : (M,) int
        Sub-ray id of each hit (unique over all pulses, e.g. ``pulse · K + k``).
    range_m : (M,) float
        Range of each hit along its sub-ray, metres, finite and ≥ 0; rows in any order.
    surface : (M,) int
        Surface id of each hit, an index into ``surface_transmittance``.
    surface_transmittance : (S,) float
        Round-trip transmittance of each surface, in [0, 1]: the share of the energy arriving
        at it that goes on and whose reflection comes back through it.  A gap fraction ``g``
        (a leafy layer, a mesh fence: the return passes through the same gaps) is ``g``; a
        pane that transmits ``T`` each way is ``T²``.  Each hit counts once, so a closed thin
        mesh (a leaf as a box) is crossed twice.

    Returns
    -------
    (M,) float64
        In [0, 1], in the order of the input rows.

    Raises
    ------
    InvalidInputError
        Arrays not 1-D of one length, ids not integers, ranges negative or not finite, a
        surface id outside ``surface_transmittance``, a transmittance outside [0, 1].
    """
    try:
        t = np.asarray(surface_transmittance, dtype=np.float64)
    except (TypeError, ValueError):
        t = np.full(1, np.nan)
    if t.ndim != 1 or not np.all((t >= 0) & (t <= 1)):
        raise InvalidInputError(f"surface_transmittance must be a (S,) array of values in [0, 1], got shape {t.shape}")
    cols = hit_columns(subray=subray, range_m=range_m, surface=surface)
    ids = cols["surface"]
    if ids.size and (ids.min() < 0 or ids.max() >= len(t)):
        raise InvalidInputError(f"surface ids must lie in [0, {len(t)}) to index surface_transmittance, got {ids.min()}..{ids.max()}")
    order = sorted_order(cols["range_m"], cols["subray"])
    ray, r, tr = cols["subray"][order], cols["range_m"][order], t[ids[order]]
    # products over the nearer hits of each sub-ray as sums over earlier rows: of log t for
    # the partial surfaces, and a count of the opaque ones (log 0 would poison the sums)
    opaque = np.concatenate([[0], np.cumsum(tr == 0)])
    log_t = np.concatenate([[0.0], np.cumsum(np.log(np.where(tr > 0, tr, 1.0)))])
    index = np.arange(len(ray))
    ray_start = index - rank_in_run(ray)
    tie_start = index - rank_in_run(ray, r)
    # sums over the rows of the sub-ray nearer than the first row of this hit's range
    n_opaque = opaque[tie_start] - opaque[ray_start]
    log_sum = log_t[tie_start] - log_t[ray_start]
    factor = np.where(n_opaque > 0, 0.0, np.exp(log_sum))
    out = np.empty(len(order))
    out[order] = factor
    return out


def _unit_hash(cells: NDArray[np.int64], salt: int) -> NDArray[np.float64]:
    """(M,) float64 in [0, 1): a uniform number per integer cell ``cells`` (M, 3), the same for the same cell.

    The cell's three indices are mixed by odd 64-bit multipliers and the finaliser of MurmurHash3 (``fmix64``,
    Appleby 2011), in wrapping uint64 arithmetic: the top 53 bits make the number.
    """
    c = cells.astype(np.uint64)  # two's complement: negative indices wrap, distinct cells stay distinct
    h = np.uint64(salt) ^ (c[:, 0] * np.uint64(0x9E3779B97F4A7C15))
    h = (h ^ (c[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F))) * np.uint64(0xFF51AFD7ED558CCD)
    h = (h ^ (c[:, 2] * np.uint64(0x165667B19E3779F9))) * np.uint64(0xC4CEB9FE1A85EC53)
    h ^= h >> np.uint64(33)
    h *= np.uint64(0xFF51AFD7ED558CCD)
    h ^= h >> np.uint64(33)
    h *= np.uint64(0xC4CEB9FE1A85EC53)
    h ^= h >> np.uint64(33)
    return (h >> np.uint64(11)).astype(np.float64) * 2.0**-53


def gap_cells_open(points: ArrayLike, gap_fraction: ArrayLike, cell_m: float, *, salt: int = GAP_CELL_SALT) -> NDArray[np.bool_]:
    """(M,) bool: whether each hit point lies in a gap of its surface, not on a leaf.

    Space is cut into cubes of side ``cell_m`` (the world frame's grid); each cube is a gap with
    probability ``gap_fraction`` and a leaf otherwise, drawn once from the cube's own hash, so every sub-ray,
    pulse and scan that meets a cube finds it the same.  A surface's share of gaps is then its gap fraction
    (the law the tests check), and the gaps are clumped at ``cell_m``: the sub-rays of one footprint that
    fall in one cell pass or stop together, so a pulse goes on through a crown whole, in part or not at all,
    as the returns of a real canopy show, where a gap fraction taken as a share of every sub-ray's energy
    sends a weak echo through behind every crown hit.  The leaves are the clumps of foliage that gap-fraction
    models of canopies describe (J. M. Chen, J. Cihlar 1995, "Plant canopy gap-size analysis theory for
    improving optical measurements of leaf-area index", Appl. Opt. 34(27), 6211–6222: gaps between clumps,
    not only between leaves).

    Parameters
    ----------
    points : (M, 3) float
        Hit points, world frame, metres, finite.
    gap_fraction : (M,) float
        Each hit's surface's gap fraction (its round-trip transmittance), in [0, 1].
    cell_m : float
        Side of a cell, metres, > 0.
    salt : int
        Mixed into the hash: another salt, another pattern of the same law.

    Returns
    -------
    (M,) bool
        True where the point's cell is a gap.

    Raises
    ------
    InvalidInputError
        Points not (M, 3) finite, gap fractions not (M,) in [0, 1], ``cell_m`` not a finite number > 0.
    """
    x = np.asarray(points, dtype=np.float64)
    g = np.asarray(gap_fraction, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3 or not np.isfinite(x).all():
        raise InvalidInputError(f"points must be a finite (M, 3) array, got shape {x.shape}")
    if g.shape != (len(x),) or not np.all((g >= 0) & (g <= 1)):
        raise InvalidInputError(f"gap_fraction must be ({len(x)},) values in [0, 1], got shape {g.shape}")
    if not (isinstance(cell_m, (int, float)) and np.isfinite(cell_m) and cell_m > 0):
        raise InvalidInputError(f"cell_m must be a finite number > 0, got {cell_m!r:.40}")
    cells = np.floor(x / float(cell_m)).astype(np.int64)
    return _unit_hash(cells, salt) < g
