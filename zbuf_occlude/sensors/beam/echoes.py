"""Echoes of laser pulses: the sub-ray hits of each pulse resolved into discrete returns.

A pulse is cast as sub-rays (:mod:`zbuf_occlude.sensors.beam.footprint`); every hit of every sub-ray is one row here,
with its pulse, range, received energy (:func:`hit_energy`) and surface.  A receiver sees the
sum of the hits' reflected pulses along time (range) and reports one return per peak it can tell
apart (:func:`resolve_echoes`):

* **Merging** (``echo_rule``, one of :data:`ECHO_RULES`).  ``"chain"``: within a pulse, hits
  sorted by range, a new echo starts at a hit that lies at least ``range_resolution_m`` beyond
  the hit before it; nearer hits merge into the current echo.  A reflected pulse is ``c·τ``
  long, so two reflections less than ``c·τ/2`` apart in range overlap into one peak of the
  waveform, and a chain of overlapping reflections (a slanted surface across the footprint)
  stays one widened peak; two echoes are told apart when they are at least ``c·τ/2`` apart
  (Baltsavias 1999, "Airborne laser scanning: basic relations and formulas", ISPRS J.
  Photogramm. 54(2–3), 199–214).  So consecutive echoes' ranges are always at least
  ``range_resolution_m`` apart.  But a weak run of hits between two strong reflections chains
  them into one echo, and the more sub-rays, the more such runs: the returns per pulse drift
  with K.  ``"waveform"``: the echoes are the peaks of the pulse's summed waveform, told apart
  where it dips (:mod:`zbuf_occlude.sensors.beam.waveform`); a weak run between two strong reflections leaves a dip.
* **An echo** has the energy-weighted mean range of its hits (the centroid of the merged
  peak), the sum of their energies, and the surface that gives it the most energy.
* **Detection.**  Echoes with energy below ``detection_threshold`` are not detected, nor those
  whose apparent reflectance, energy times range squared, lies below ``min_echo_reflectance``
  (a threshold relative to the full-footprint echo at the echo's range: :class:`Beam
  <zbuf_occlude.sensors.beam.fields.Beam>`).
* **Returns kept.**  At most ``max_returns`` per pulse: the first ones in range order.  A
  discrete-return receiver triggers on the echoes as they arrive and stops recording after
  its last slot; later, possibly stronger echoes are lost (returns are numbered 1..n in that
  arrival order: ASPRS LAS Specification 1.4 R15, 2019, "Return Number").  Echoes below the
  threshold take no slot.  (Some receivers keep other sets, e.g. Velodyne's dual mode keeps
  the strongest and the last; those are not modelled.)

Energies follow the LiDAR range equation for an extended Lambertian target (Kashani et al.
2015, "A review of LIDAR radiometric processing: from ad hoc intensity correction to rigorous
radiometric calibration", Sensors 15(11), 28099–28128, Eq. 4): received power ∝
``ρ cos θ / R²`` times the share of the beam that meets the surface, constants dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.sensors.checks import count, real, text
from zbuf_occlude.sensors.beam.hit_rows import group_starts, hit_columns, rank_in_run, sorted_order
from zbuf_occlude.sensors.beam.waveform import waveform_echo_starts

__all__ = [
    "ECHO_RULES",
    "MAX_POWER_NOISE",
    "MAX_RETURNS",
    "MIN_RANGE_M",
    "Echoes",
    "hit_energy",
    "number_returns",
    "resolve_echoes",
]

#: How a pulse's hits merge into echoes (:func:`resolve_echoes`' ``echo_rule``; module docstring).
ECHO_RULES = ("chain", "waveform")

#: Most returns per pulse: LAS 1.4 point formats 6–10 store the return number in 4 bits.
MAX_RETURNS = 15

#: Largest ``power_noise``, the σ of the natural log of a firing's received power (a beam's, and
#: ``scan``'s option): every hit of a firing is scaled by ``exp(σ z)``, z ~ N(0, 1).  The most a
#: real return's power fluctuates is fully developed speckle (negative exponential power, whose log
#: has σ = π/√6 ≈ 1.28: Goodman, "Speckle Phenomena in Optics", 2007, ch. 3) seen through saturated
#: turbulence (negative exponential irradiance again: Andrews & Phillips, "Laser Beam Propagation
#: through Random Media", 2nd ed., 2005, ch. 9): the product of the two has a log of σ = π/√3 ≈
#: 1.81, which 2 bounds.  Beyond it the noise, not the range equation, sets the intensities (at
#: σ = 50 one standard draw scales a power by e^±50 ≈ 10^±22: every return detected is at its
#: device's top count), and ``exp(σ z)`` overflows float64 once σ z > 709.
MAX_POWER_NOISE = 2.0

#: Ranges are clamped to at least this in :func:`hit_energy`, metres: a hit at the sensor's
#: centre gets a finite energy (the clamp :func:`~zbuf_occlude.sensors.scan.scan` applies).
MIN_RANGE_M = 1e-9


@dataclass(frozen=True)
class Echoes:
    """Discrete returns of many pulses, sorted by pulse, then by range (return number).

    Attributes
    ----------
    pulse : (E,) int64
        Pulse id of each return (as given to :func:`resolve_echoes`).
    range_m : (E,) float64
        Energy-weighted mean range of the echo's hits, metres; a one-hit echo keeps its hit's
        range bit for bit.
    energy : (E,) float64
        Sum of the hits' energies (units of :func:`hit_energy`, m⁻²).
    surface : (E,) int64
        The surface id that contributes the most energy to the echo (ties: the lower id).
    hit : (E,) int64
        Row of the input of the strongest hit of that surface in the echo (ties: the nearer,
        then the earlier row): where to look up the face, normal or sub-ray of the return.
    return_number : (E,) uint8
        1..n within the pulse, in range order.
    number_of_returns : (E,) uint8
        n, the returns the pulse kept, on every return of the pulse.
    """

    pulse: NDArray[np.int64]
    range_m: NDArray[np.float64]
    energy: NDArray[np.float64]
    surface: NDArray[np.int64]
    hit: NDArray[np.int64]
    return_number: NDArray[np.uint8]
    number_of_returns: NDArray[np.uint8]

    def __len__(self) -> int:
        return len(self.pulse)


def hit_energy(
    weight: ArrayLike,
    reflectance: ArrayLike,
    cos_incidence: ArrayLike,
    range_m: ArrayLike,
) -> NDArray[np.float64]:
    """Energy a sub-ray's hit sends back: ``reflectance · cos_incidence · weight / R²``.

    The LiDAR range equation for an extended Lambertian target (Kashani et al. 2015, Sensors
    15(11), Eq. 4), up to the constant of the sensor (pulse energy, aperture, efficiencies):
    a surface of reflectance ρ, met at incidence θ and range R by the share ``weight`` of the
    beam, returns power ∝ ``ρ cos θ weight / R²``.  The beam's radiometric threshold
    (:attr:`Beam.detection_threshold <zbuf_occlude.sensors.beam.fields.Beam.detection_threshold>`,
    m⁻²) is in the same units.

    Parameters
    ----------
    weight : float or (M,) float
        Share of the pulse's energy the sub-ray carries (:func:`~zbuf_occlude.sensors.beam.footprint.footprint_offsets`).
    reflectance : float or (M,) float
        Lambertian reflectance ρ of the surface hit, at the scanner's wavelength, in [0, 1].
    cos_incidence : float or (M,) float
        ``|cos θ|`` between the sub-ray and the surface normal.
    range_m : float or (M,) float
        Range of the hit, metres; clamped to :data:`MIN_RANGE_M`.

    Returns
    -------
    (M,) float64 (the broadcast shape of the inputs)
        Computed as ``(ρ · cos θ) · weight / max(R, MIN_RANGE_M)²``: with weight 1, the bits
        of :func:`~zbuf_occlude.sensors.scan.scan`'s one-ray received power.
    """
    rho = np.asarray(reflectance, dtype=np.float64)
    cos = np.asarray(cos_incidence, dtype=np.float64)
    r = np.maximum(np.asarray(range_m, dtype=np.float64), MIN_RANGE_M)
    return rho * cos * np.asarray(weight, dtype=np.float64) / r**2


def number_returns(pulse: NDArray) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """``return_number`` and ``number_of_returns`` (N,) uint8 of returns of pulse rows ``pulse`` (N,).

    ``pulse`` is sorted (each pulse's returns together, in range order): the returns of one pulse
    are numbered 1..n and each carries n.  The one numbering of :func:`resolve_echoes` and of
    the scans (:func:`~zbuf_occlude.sensors.scan.return_numbers`, after dropout).
    """
    pulse = np.asarray(pulse)
    starts = group_starts(pulse)
    n_returns = np.diff(starts, append=len(pulse))
    rank = np.arange(len(pulse)) - np.repeat(starts, n_returns)
    return (rank + 1).astype(np.uint8), np.repeat(n_returns, n_returns).astype(np.uint8)


#: :func:`_pulse_range_order` sorts each pulse's rows in one (pulses, most hits of a pulse)
#: table when it holds at most this many cells per row given (padding included): a scan's
#: pulses have a few hits each; one pulse with many more sorts all rows at once instead.
_MOST_CELLS_PER_ROW = 4


def _pulse_range_order(p: NDArray, r: NDArray) -> NDArray[np.int64]:
    """``np.lexsort((r, p))``: the rows by pulse, then range, ties in row order.

    Rows already by pulse (a scan gives them so) are sorted pulse by pulse: each pulse's
    ranges one row of a table padded with inf (the ranges are finite), sorted along the rows by
    a stable sort, instead of a sort of all the ranges and another of all the pulses.
    """
    n = len(p)
    if n > 1 and np.all(p[1:] >= p[:-1]):
        starts = group_starts(p)
        counts = np.diff(starts, append=n)
        width = int(counts.max())
        if len(starts) * width <= _MOST_CELLS_PER_ROW * n:
            table = np.full((len(starts), width), np.inf)
            # row i of pulse j (from its first row starts[j]) goes to cell j · width + i − starts[j]
            table.reshape(-1)[np.arange(n) + np.repeat(np.arange(len(starts)) * width - starts, counts)] = r
            column = np.argsort(table, axis=1, kind="stable")
            # the padding's columns (from the pulse's count on) are dropped wherever they sort
            return (starts[:, None] + column)[column < counts[:, None]]
    return sorted_order(r, p)


def _hit_order(p: NDArray, r: NDArray, e: NDArray, s: NDArray) -> tuple[NDArray[np.int64], ...]:
    """The rows sorted by pulse, range, energy, surface: by the first two, then the runs of one
    pulse at one range (common: sub-rays mirrored about a plane's slope hit it at one range) by
    the other two (rows equal on all four are interchangeable).

    Returns the order and the four columns in it."""
    order = _pulse_range_order(p, r)
    po, ro = p[order], r[order]
    tie = (po[1:] == po[:-1]) & (ro[1:] == ro[:-1])
    if tie.any():
        # tie[i]: rows i and i + 1 tie; a link with a tied link before or after it is in a longer run
        before = np.concatenate([[False], tie[:-1]])
        after = np.concatenate([tie[1:], [False]])
        # runs of two rows (mirror-image sub-rays hitting a plane at one range): swapped where
        # the second is lower by (energy, surface), as the stable sort of the pair would
        pair = np.flatnonzero(tie & ~before & ~after)
        a, b = order[pair], order[pair + 1]
        swap = (e[b] < e[a]) | ((e[b] == e[a]) & (s[b] < s[a]))
        order[pair[swap]], order[pair[swap] + 1] = b[swap], a[swap]
        ro[pair[swap]], ro[pair[swap] + 1] = r[b[swap]], r[a[swap]]  # (-0 ties with 0)
        longer = tie & (before | after)  # links of runs of three rows or more
        if longer.any():
            tied = np.zeros(len(order), bool)
            tied[:-1] |= longer
            tied[1:] |= longer
            rows = np.flatnonzero(tied)
            run = np.cumsum(~np.concatenate([[False], tie])[rows])  # the runs, in order
            order[rows] = order[rows][np.lexsort((s[order[rows]], e[order[rows]], run))]
            ro[rows] = r[order[rows]]
    return order, po, ro, e[order], s[order]


def _first_max(values: NDArray, starts: NDArray[np.int64], group: NDArray[np.int64]) -> NDArray[np.int64]:
    """Per group (rows ``starts[g]`` to the next start, ``group`` the group of each row): the
    first row holding the group's greatest value."""
    at_max = np.flatnonzero(values == np.maximum.reduceat(values, starts)[group])
    return at_max[group_starts(group[at_max])]


def _dominant_surface(
    echo: NDArray[np.int64],
    starts: NDArray[np.int64],
    s: NDArray[np.int64],
    e: NDArray[np.float64],
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Per echo (rows sorted by echo, then range; ``starts`` the first row of each echo): the
    surface with the most energy (ties: the lower id) and the index of that surface's strongest
    row (ties: the nearer, then the first).

    An echo of one surface needs no grouping: that surface, and its first row of the greatest
    energy.  Only the echoes of several surfaces (a footprint across an edge) go through
    :func:`_dominant_surface_of_mixed`, which gives the one-surface echoes the same answer.
    """
    surface = s[starts]
    hit = _first_max(e, starts, echo)
    mixed = np.zeros(len(starts), bool)
    mixed[echo[1:][(s[1:] != s[:-1]) & (echo[1:] == echo[:-1])]] = True
    if mixed.any():
        rows = np.flatnonzero(mixed[echo])
        sub = echo[rows]
        sub_surface, sub_hit = _dominant_surface_of_mixed(_rank_of_runs(sub), s[rows], e[rows])
        surface[mixed], hit[mixed] = sub_surface, rows[sub_hit]
    return surface, hit


def _rank_of_runs(key: NDArray) -> NDArray[np.int64]:
    """(n,) int64: the runs of equal sorted ``key`` numbered 0, 1, 2 ... in order."""
    new = np.ones(len(key), bool)
    new[1:] = key[1:] != key[:-1]
    return np.cumsum(new) - 1


def _dominant_surface_of_mixed(
    echo: NDArray[np.int64],
    s: NDArray[np.int64],
    e: NDArray[np.float64],
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """:func:`_dominant_surface` for any echoes (``echo`` numbered 0, 1, ... in row order) by
    grouping each echo's rows by surface."""
    lowest, span = int(s.min()), int(s.max()) - int(s.min()) + 1
    if (int(echo[-1]) + 1) * span < 2**62:  # one integer key (echo, surface)
        by_surface = np.argsort(echo * span + (s - lowest), kind="stable")
    else:
        by_surface = sorted_order(s, echo)
    # stable sorts: an (echo, surface) group keeps its rows in range order
    starts = group_starts(echo[by_surface], s[by_surface])
    total = np.add.reduceat(e[by_surface], starts)
    g_echo, g_surface = echo[by_surface][starts], s[by_surface][starts]
    # groups in (echo, surface) order: the first at the echo's greatest total has the lower id
    surface = g_surface[_first_max(total, group_starts(g_echo), g_echo)]
    # the rows of that surface, in (echo, range) order: the first at the greatest energy
    mine = np.flatnonzero(s == surface[echo])
    return surface, mine[_first_max(e[mine], group_starts(echo[mine]), echo[mine])]


def _detected(energy: NDArray, range_m: NDArray, threshold: float, relative: float) -> NDArray[np.bool_]:
    """The receiver's detection of echoes of ``energy`` at ``range_m``: the absolute threshold, then the relative one."""
    detected = energy >= threshold
    if relative > 0:
        detected &= energy * np.maximum(range_m, MIN_RANGE_M) ** 2 >= relative
    return detected


def _single_hits(p: NDArray, r: NDArray, e: NDArray, s: NDArray, threshold: float, relative: float) -> Echoes:
    """:func:`resolve_echoes` of rows with one hit a pulse, pulses ascending: each hit is its pulse's one echo
    (the general path's result, bit for bit, without its sorts and merging)."""
    kept = np.flatnonzero(_detected(e, r, threshold, relative))
    ones = np.ones(len(kept), np.uint8)
    return Echoes(pulse=p[kept], range_m=r[kept], energy=e[kept], surface=s[kept], hit=kept, return_number=ones, number_of_returns=ones)


def resolve_echoes(
    pulse: ArrayLike,
    range_m: ArrayLike,
    energy: ArrayLike,
    surface: ArrayLike,
    *,
    range_resolution_m: float,
    detection_threshold: float,
    max_returns: int,
    min_echo_reflectance: float = 0.0,
    echo_rule: str = "chain",
) -> Echoes:
    """Resolve the sub-ray hits of many pulses into discrete returns (rules: module docstring).

    Parameters
    ----------
    pulse : (M,) int
        Pulse id of each hit; any integers, rows of one pulse in any order.
    range_m : (M,) float
        Range of each hit along its sub-ray, metres, finite and ≥ 0.
    energy : (M,) float
        Energy each hit sends back (:func:`hit_energy`), finite and ≥ 0.
    surface : (M,) int
        Surface id of each hit (an object id, a class, or a face: what the returns should name).
    range_resolution_m : float
        Least range between two echoes the receiver tells apart, metres, > 0: half the pulse
        length, ``c·τ/2`` (a 5 ns pulse: 0.75 m).  Hits less than this beyond the previous
        hit of their pulse merge into its echo.
    detection_threshold : float
        Least echo energy detected, ≥ 0, in the units of ``energy``
        (:attr:`Beam.detection_threshold <zbuf_occlude.sensors.beam.fields.Beam.detection_threshold>`
        with :func:`hit_energy`); 0 keeps every echo.
    max_returns : int
        Most returns per pulse, 1 to :data:`MAX_RETURNS`; the first ones in range order are kept.
    min_echo_reflectance : float
        Least apparent reflectance of a detected echo, in [0, 1]: its energy times the square of
        its range (with :func:`hit_energy`'s energies, ``ρ · |cos θ|`` times the share of the pulse
        its hits carry; :attr:`Beam.min_echo_reflectance
        <zbuf_occlude.sensors.beam.fields.Beam.min_echo_reflectance>`).  Scaling every range and the
        range resolution by ``c`` and every energy by ``1/c²`` detects the same echoes (with
        ``detection_threshold`` 0, ranges above :data:`MIN_RANGE_M`).  0 keeps every echo.
    echo_rule : {"chain", "waveform"}
        How hits merge into echoes (module docstring): a new echo at a gap of
        ``range_resolution_m`` after the previous hit, or at each dip of the pulse's waveform
        (:func:`~zbuf_occlude.sensors.beam.waveform.waveform_echo_starts`).  Either way a pulse's echoes are its hits
        split into runs in range order.

    Returns
    -------
    Echoes
        Sorted by pulse, then range.  Pulses without a detected echo have none.  The result
        does not depend on the order of the rows (beyond which of identical rows ``hit`` names).

    Raises
    ------
    InvalidInputError
        Arrays not 1-D of one length, integer ids not integers, ranges or energies negative or
        not finite; a resolution ≤ 0, a negative threshold, a ``min_echo_reflectance`` outside
        [0, 1], ``max_returns`` outside 1..:data:`MAX_RETURNS`, or an ``echo_rule`` not in
        :data:`ECHO_RULES`, each naming the value.

    Notes
    -----
    O(M log M), no loop over pulses: rows given by pulse (a scan's) are sorted pulse by pulse,
    others by sorts of all rows; only the echoes of several surfaces are grouped by surface.
    """
    resolution = real(range_resolution_m, "range_resolution_m", low=0.0, low_open=True)
    threshold = real(detection_threshold, "detection_threshold", low=0.0)
    relative = real(min_echo_reflectance, "min_echo_reflectance", low=0.0, high=1.0)
    keep_n = count(max_returns, "max_returns", low=1, high=MAX_RETURNS)
    rule = text(echo_rule, "echo_rule", choices=ECHO_RULES)
    cols = hit_columns(pulse=pulse, range_m=range_m, energy=energy, surface=surface)
    if len(cols["pulse"]) == 0:
        ids, counts = np.zeros(0, np.int64), np.zeros(0, np.uint8)
        return Echoes(ids, np.zeros(0), np.zeros(0), ids, ids, counts, counts)
    p = cols["pulse"]
    if np.all(p[1:] > p[:-1]):  # one hit a pulse, in pulse order (an adaptive scan's plane echoes): each hit its echo
        return _single_hits(p, cols["range_m"], cols["energy"], cols["surface"], threshold, relative)
    # one order for any input order: rows equal on all four keys are interchangeable
    order, p, r, e, s = _hit_order(cols["pulse"], cols["range_m"], cols["energy"], cols["surface"])
    if rule == "waveform":
        new = waveform_echo_starts(p, r, e, resolution)
    else:  # a new echo: a new pulse, or a gap of at least the resolution after the previous hit
        new = np.ones(len(p), bool)
        new[1:] = (p[1:] != p[:-1]) | (np.diff(r) >= resolution)
    starts = np.flatnonzero(new)
    echo = np.cumsum(new) - 1  # (M,) echo of each sorted hit
    n_hits = np.diff(starts, append=len(p))
    first, last = r[starts], r[starts + n_hits - 1]
    total = np.add.reduceat(e, starts)
    # the weighted mean as the first hit plus a weighted offset (no cancellation), clipped to
    # the hits' span against rounding; an echo of zero energy: the plain mean; one hit: its range
    offset = r - first[echo]
    weighted = np.zeros(len(starts))
    np.divide(np.add.reduceat(e * offset, starts), total, out=weighted, where=total > 0)
    mean = np.where(total > 0, weighted, np.add.reduceat(offset, starts) / n_hits)
    echo_range = np.where(n_hits == 1, first, np.clip(first + mean, first, last))
    echo_surface, echo_hit = _dominant_surface(echo, starts, s, e)
    # detection, then the first max_returns detected echoes of each pulse
    detected = np.flatnonzero(_detected(total, echo_range, threshold, relative))
    rank = rank_in_run(p[starts][detected])
    kept = detected[rank < keep_n]
    kept_pulse = p[starts][kept]
    return_number, number_of_returns = number_returns(kept_pulse)
    return Echoes(
        pulse=kept_pulse,
        range_m=echo_range[kept],
        energy=total[kept],
        surface=echo_surface[kept],
        hit=order[echo_hit[kept]],
        return_number=return_number,
        number_of_returns=number_of_returns,
    )
