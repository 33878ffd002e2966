"""The share of a sub-ray's energy that reaches each of its hits through the surfaces before it, and comes back.

Where a scan casts every hit along a sub-ray (surfaces that transmit: foliage as a gap fraction, a
mesh fence, a pane), :func:`~zbuf_occlude.sensors.beam.echo_energy.echo_returns` weighs each hit's energy
(:func:`~zbuf_occlude.sensors.beam.echoes.hit_energy`) by :func:`attenuate_along_subray` before resolving echoes.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.hit_rows import hit_columns, rank_in_run, sorted_order

__all__ = ["attenuate_along_subray"]


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
