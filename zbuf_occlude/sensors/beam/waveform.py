"""Echoes told apart on a pulse's waveform: where a receiver that detects the waveform's peaks splits a pulse's hits.

A pulse's received waveform, along range, is the sum over its sub-ray hits of the echo of one
point reflector scaled by the hit's energy.  That echo is taken as a raised-cosine (Hann, cos²)
pulse whose full width at half maximum is the range resolution ΔR = c·τ/2::

    k(x) = cos²(π x / (2 ΔR))   for |x| < ΔR, else 0

the compact-support stand-in for the Gaussian of the same width that full-waveform processing
fits (Wagner et al. 2006, "Gaussian decomposition and calibration of a novel small-footprint
full-waveform digitising airborne laser scanner", ISPRS J. Photogramm. 60(2), 100–112).  The
receiver reports one echo per peak: two peaks are told apart where the waveform dips between
them (Sparrow's criterion: C. M. Sparrow 1916, "On spectroscopic resolving power", Astrophys. J.
44, 76–86) and their peaks lie at least ΔR apart (the least gap between two returns; a peak
nearer than that to a stronger one is a ripple of the same echo).  With this shape:

* hits within ΔR of each other make one peak: on an interval no longer than ΔR where every hit's
  pulse is live, the waveform's slope is one sinusoid of half-period ΔR, which changes sign at
  most once (two equal reflections ΔR apart sum to a flat top);
* a hit ΔR or more beyond the hit before it starts a new echo, as in the chain rule: just past
  the nearer hits the waveform falls (the farther hits' pulses are not yet live), and the two
  sides' peaks lie at least that gap apart.

So, for a pulse's hits sorted by range (:func:`waveform_echo_starts`), the chain rule's runs (each
hit less than ΔR beyond the one before: *chains*) are split further where their waveform dips: a chain that
spans more than ΔR is sampled every ΔR / :data:`SAMPLES_PER_RESOLUTION` (a digitiser; 1 ns is
0.15 m of range), its samples rounded to 2⁻³⁰ of the chain's largest (equal in exact arithmetic
stays equal), its peaks (local maxima, the middle of a flat run) nearer than ΔR to a stronger
neighbour, or parted from it by a dip shallower than :data:`PROMINENCE`, merged into it round
after round, and a new echo starts past each dip left between two peaks.

Unlike the chain rule, a weak run of hits between two strong reflections (a crown's side wall
across the footprint) does not join them: the sum still dips between the two, and the more
sub-rays, the more such runs the chain rule would join.  The echoes' ranges, energies and
surfaces are then the hits' as for the chain rule (:func:`~zbuf_occlude.sensors.beam.echoes.resolve_echoes`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["PROMINENCE", "SAMPLES_PER_RESOLUTION", "waveform_echo_starts"]

#: Samples of the waveform per range resolution ΔR (a digitiser's rate; 8 per 0.75 m is about 1.6 GS/s).
SAMPLES_PER_RESOLUTION = 8
#: Least depth of a dip that tells two peaks apart, as a share of the lower peak: a peak detector re-arms only once the
#: signal has fallen by a margin above its noise (an assumption, not a data sheet's figure; chosen among 0, 0.02, 0.05
#: and 0.1 on the IGN tile of ``experiment returns``, where 0.05 passes the most targets).  It keeps the shallow ripple
#: of a surface's sub-rays (a crown wall's, a slanted plane's) from counting as echoes; a footprint's sub-rays too sparse
#: for the surface's spread of ranges still give deeper dips (raise ``footprint_rays``).
PROMINENCE = 0.05
#: Samples are rounded to this share of their chain's largest before peaks and dips are found.
_QUANTUM = 2.0**-30
#: Most (hit, sample) pairs built at once: chains are taken in batches of about this many.
_BATCH_PAIRS = 1 << 22


def waveform_echo_starts(pulse: NDArray, range_m: NDArray, energy: NDArray, resolution_m: float) -> NDArray[np.bool_]:
    """Where each echo starts among a pulse's hits, told apart on the waveform (module docstring).

    Parameters
    ----------
    pulse : (M,) int64
        Pulse of each hit, sorted (a pulse's hits together).
    range_m : (M,) float64
        Range of each hit, metres, finite and ≥ 0, ascending within each pulse.
    energy : (M,) float64
        Each hit's energy (:func:`~zbuf_occlude.sensors.beam.echoes.hit_energy`), finite and ≥ 0.
    resolution_m : float
        The range resolution ΔR, metres, > 0: the echo's full width at half maximum.

    Returns
    -------
    (M,) bool
        True where a hit starts a new echo: the first hit of each pulse, a hit ΔR or more
        beyond the one before, or the first hit past a dip of the waveform.
    """
    n = len(pulse)
    new = np.ones(n, bool)
    if n < 2:
        return new
    new[1:] = (pulse[1:] != pulse[:-1]) | (np.diff(range_m) >= resolution_m)
    start = np.flatnonzero(new)
    stop = np.append(start[1:], n)
    span = range_m[stop - 1] - range_m[start]
    long = np.flatnonzero(span > resolution_m)  # the chains that may hold several peaks
    if len(long) == 0:
        return new
    step = resolution_m / SAMPLES_PER_RESOLUTION
    width = 2 * SAMPLES_PER_RESOLUTION + 1  # samples a hit's pulse can reach, from its floor sample on
    batch_start = 0
    hits = stop[long] - start[long]
    cumulative = np.cumsum(hits)
    while batch_start < len(long):
        room = cumulative[batch_start] - hits[batch_start] + max(_BATCH_PAIRS // width, int(hits[batch_start]))
        batch_stop = max(batch_start + 1, int(np.searchsorted(cumulative, room, side="right")))
        chains = long[batch_start:batch_stop]
        new |= _dips(start[chains], stop[chains], range_m, energy, span[chains], step, n)
        batch_start = batch_stop
    return new


def _dips(start, stop, range_m, energy, span, step, n) -> NDArray[np.bool_]:
    """(n,) bool: the hits of chains ``start[s]:stop[s]`` that follow a dip of their chain's sampled waveform."""
    s_per = SAMPLES_PER_RESOLUTION
    counts = stop - start
    rows = np.repeat(start - np.cumsum(np.append(0, counts[:-1])), counts) + np.arange(int(counts.sum()))
    chain = np.repeat(np.arange(len(start)), counts)
    # each chain's samples: x_j = first − ΔR + j · step, j = 0 .. n_samples − 1, zero at both ends
    n_samples = np.ceil(span / step).astype(np.int64) + 2 * s_per + 3
    offset = np.append(0, np.cumsum(n_samples)[:-1])
    u = (range_m[rows] - range_m[start][chain]) / step + s_per  # each hit in its chain's sample units
    base = np.floor(u).astype(np.int64)
    j = base[:, None] + np.arange(-s_per, s_per + 1)[None, :]  # (hits, 2·s_per + 1) samples around each hit
    x = np.abs(j - u[:, None])
    pulse_shape = np.where(x < s_per, np.cos(np.pi * x / (2 * s_per)) ** 2, 0.0)
    samples = np.bincount((j + offset[chain][:, None]).ravel(), weights=(pulse_shape * energy[rows][:, None]).ravel(),
                          minlength=int(n_samples.sum()))  # fmt: skip
    sample_chain = np.repeat(np.arange(len(start)), n_samples)
    top = np.maximum.reduceat(samples, offset)
    q = np.rint(np.divide(samples, top[sample_chain], out=np.zeros_like(samples), where=top[sample_chain] > 0) / _QUANTUM)
    # flat runs as one value (a flat run never spans two chains' live samples: each chain's samples end in zeros)
    run_start = np.flatnonzero(np.append(True, q[1:] != q[:-1]))
    run_stop = np.append(run_start[1:], len(q))
    level = q[run_start]
    inner = np.zeros(len(level), bool)
    inner[1:-1] = True
    peak = np.flatnonzero(inner & (level > np.roll(level, 1)) & (level > np.roll(level, -1)))
    low = np.flatnonzero(inner & (level < np.roll(level, 1)) & (level < np.roll(level, -1)))
    middle = (run_start + run_stop - 1) / 2.0  # each flat run's middle, global sample units
    # the one dip between each peak and the next (the flat runs alternate between peaks and dips), of one chain
    dip = low[np.minimum(np.searchsorted(low, peak[:-1]), len(low) - 1)] if len(peak) > 1 else np.zeros(0, np.int64)
    same = sample_chain[run_start[peak[1:]]] == sample_chain[run_start[peak[:-1]]]
    cut = middle[dip[_separate(middle[peak], level[peak], level[dip], same, s_per)]]
    # a hit starts a new echo where a cut lies between it and the hit before it (a hit on the cut: the earlier echo)
    passed = np.searchsorted(cut, u + offset[chain], side="left")
    follows = np.zeros(n, bool)
    later = np.flatnonzero(chain[1:] == chain[:-1]) + 1
    follows[rows[later]] = passed[later] != passed[later - 1]
    return follows


def _separate(position, height, dip_level, same, least) -> NDArray[np.bool_]:
    """Which dips between consecutive peaks (dip i, of level ``dip_level[i]``, between peaks i and i + 1; ``same[i]``: the
    two in one chain) stay, once every peak less than ``least`` from a stronger neighbour, or parted from it by a dip
    shallower than :data:`PROMINENCE`, has merged into it (the stronger of two such neighbours; of equal peaks the nearer
    survives), round after round."""
    alive = np.arange(len(position))
    between = np.arange(len(position) - 1)  # the dip between live peaks i and i + 1
    while len(alive) > 1:
        a, b = alive[:-1], alive[1:]
        shallow = dip_level[between] >= (1.0 - PROMINENCE) * np.minimum(height[a], height[b])
        close = np.flatnonzero((position[b] - position[a] < least) | shallow)  # peaks of two chains lie farther apart, dip 0
        if len(close) == 0:
            break
        # the weaker of each close pair merges into the other: the right one left (left ≥ right), or the left one right
        into_left = height[a[close]] >= height[b[close]]
        side = np.zeros(len(alive), np.int8)  # per live peak: −1 merges left, +1 right, 0 stays
        side[close[into_left] + 1] = -1
        pulled = np.zeros(len(alive), bool)
        pulled[close[into_left] + 1] = True
        right = close[~into_left]  # a peak that two stronger neighbours pull joins the stronger (the left on a tie)
        stronger = ~pulled[right] | (height[alive[right + 1]] > height[alive[right - 1]])
        side[right[stronger]] = 1
        gone = np.flatnonzero(side != 0)
        # each merge removes the dip between the peak and the one it joins
        between = np.delete(between, np.where(side[gone] < 0, gone - 1, gone))
        alive = np.delete(alive, gone)
    return between[same[between]]
