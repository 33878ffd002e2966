"""Echoes of laser pulses: analytic footprints on plates, the receiver's rules, and properties of any input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.attenuation import attenuate_along_subray
from zbuf_occlude.sensors.beam.echoes import (
    MAX_RETURNS,
    hit_energy,
    resolve_echoes,
)
from zbuf_occlude.sensors.beam.footprint import footprint_offsets, subray_directions

R = 20.0  # range of the near plate, metres
RESOLUTION = 0.75  # c·τ/2 of a 5 ns pulse, metres


def _plates(
    gap: float,
    *,
    profile: str = "gaussian",
    reflectance=(0.6, 0.3),
    k: int = 19,
    divergence_deg: float = 2.0,
):
    """One pulse along +x on two plates normal to it: plate A (y >= 0) at x = R, plate B (y < 0) at
    x = R + gap; each takes the sub-rays on its side (half the footprint).  Returns the hits
    ``(range, energy, surface)``, the sub-ray weights and which sub-rays hit A."""
    offsets, weights = footprint_offsets(k, divergence_deg, profile=profile)
    rays = subray_directions(np.array([[1.0, 0.0, 0.0]]), offsets)[0]
    on_a = rays[:, 1] >= 0
    plate_x = np.where(on_a, R, R + gap)
    range_m = plate_x / rays[:, 0]  # along each sub-ray to its plate
    energy = hit_energy(weights, np.where(on_a, reflectance[0], reflectance[1]), rays[:, 0], range_m)
    return range_m, energy, np.where(on_a, 1, 2), weights, on_a


def _resolve(range_m, energy, surface, pulse=None, **kw):
    pulse = np.zeros(len(range_m), np.int64) if pulse is None else pulse
    args = {
        "range_resolution_m": RESOLUTION,
        "detection_threshold": 0.0,
        "max_returns": 5,
    } | kw
    return resolve_echoes(
        pulse,
        np.asarray(range_m, float),
        np.asarray(energy, float),
        np.asarray(surface, np.int64),
        **args,
    )


@pytest.mark.parametrize("profile", ["tophat", "gaussian"])
def test_two_plates_a_resolvable_gap_apart_give_two_returns(profile: str) -> None:
    gap = 2.0
    range_m, energy, surface, weights, on_a = _plates(gap, profile=profile)
    assert 0 < on_a.sum() < len(on_a)  # both plates in the footprint
    echoes = _resolve(range_m, energy, surface)
    assert len(echoes) == 2
    # the sub-rays are within 1° of the axis: ranges R / cos θ differ from R by < R θ² / 2
    assert echoes.range_m == pytest.approx([R, R + gap], abs=R * math.radians(1.0) ** 2)
    # energies: ρ × the footprint share on each plate / R² (cos θ ≈ 1 to the same order)
    expected = np.array([0.6 * weights[on_a].sum() / R**2, 0.3 * weights[~on_a].sum() / (R + gap) ** 2])
    assert echoes.energy == pytest.approx(expected, rel=1e-3)
    assert echoes.energy == pytest.approx([energy[on_a].sum(), energy[~on_a].sum()], rel=1e-14)
    assert echoes.range_m[1] - echoes.range_m[0] >= RESOLUTION
    assert echoes.surface.tolist() == [1, 2] and echoes.pulse.tolist() == [0, 0]
    assert echoes.return_number.tolist() == [
        1,
        2,
    ] and echoes.number_of_returns.tolist() == [2, 2]
    assert echoes.return_number.dtype == echoes.number_of_returns.dtype == np.uint8
    assert on_a[echoes.hit[0]] and not on_a[echoes.hit[1]]  # each return names a hit of its plate


def test_two_plates_closer_than_the_resolution_give_one_return_at_the_energy_weighted_range() -> None:
    gap = 0.3
    range_m, energy, surface, _, on_a = _plates(gap)
    echoes = _resolve(range_m, energy, surface)
    assert len(echoes) == 1 and echoes.return_number.tolist() == [1] and echoes.number_of_returns.tolist() == [1]
    assert echoes.range_m[0] == pytest.approx(np.sum(energy * range_m) / np.sum(energy), rel=1e-14)
    assert R < echoes.range_m[0] < R + gap  # a mixed return, on neither plate
    assert echoes.energy[0] == pytest.approx(energy.sum(), rel=1e-14)
    stronger = 1 if energy[on_a].sum() > energy[~on_a].sum() else 2
    assert echoes.surface.tolist() == [stronger]


def test_the_gap_is_measured_from_the_previous_hit_so_a_chain_of_close_hits_is_one_echo() -> None:
    # a slanted surface across the footprint: hits 0.5 m apart over 3 m, one smooth peak
    chain = np.arange(7) * 0.5 + R
    echoes = _resolve(chain, np.ones(7), np.zeros(7))
    assert len(echoes) == 1 and echoes.range_m[0] == pytest.approx(R + 1.5)
    # exactly the resolution apart: told apart
    echoes = _resolve([R, R + RESOLUTION], [1.0, 1.0], [0, 0])
    assert echoes.return_number.tolist() == [1, 2]


def test_an_echo_below_the_threshold_is_dropped_and_the_others_renumbered() -> None:
    range_m = [10.0, 12.0, 14.0]
    energy = [1e-2, 1e-4, 1e-2]
    echoes = _resolve(range_m, energy, [1, 2, 3], detection_threshold=1e-3)
    assert echoes.range_m.tolist() == [10.0, 14.0] and echoes.surface.tolist() == [1, 3]
    assert echoes.return_number.tolist() == [
        1,
        2,
    ] and echoes.number_of_returns.tolist() == [2, 2]
    # an echo exactly at the threshold is detected
    assert len(_resolve(range_m, energy, [1, 2, 3], detection_threshold=1e-4)) == 3
    # a weak hit that merges into a strong echo is not lost: the echo's sum counts
    echoes = _resolve([10.0, 10.1], [9e-4, 2e-4], [1, 2], detection_threshold=1e-3)
    assert len(echoes) == 1 and echoes.energy[0] == pytest.approx(1.1e-3)


def test_at_most_max_returns_are_kept_the_first_in_range_order() -> None:
    rng = np.random.default_rng(3)
    range_m = 10.0 + 2.0 * np.arange(7)
    energy = np.arange(1.0, 8.0)  # the far ones are the strongest
    rows = rng.permutation(7)
    echoes = _resolve(range_m[rows], energy[rows], np.arange(7)[rows], max_returns=5)
    assert echoes.range_m.tolist() == range_m[:5].tolist()
    assert echoes.surface.tolist() == [0, 1, 2, 3, 4]
    assert echoes.return_number.tolist() == [1, 2, 3, 4, 5] and echoes.number_of_returns.tolist() == [5] * 5
    # an undetected echo takes no slot
    echoes = _resolve(
        range_m,
        np.where(np.arange(7) == 1, 0.5, energy),
        np.arange(7),
        max_returns=5,
        detection_threshold=0.9,
    )
    assert echoes.surface.tolist() == [0, 2, 3, 4, 5]


def test_one_hit_per_pulse_gives_the_hits_themselves_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    n = 500
    range_m = rng.uniform(0.5, 120.0, n) * rng.choice([1.0, 1 + 1e-12, math.pi], n)
    energy = rng.uniform(0.0, 1.0, n) ** 8  # zeros' neighbours and tiny values too
    energy[:5] = 0.0
    surface = rng.integers(0, 9, n)
    pulse = rng.permutation(n) * 3 - 700  # any ids, any order
    echoes = _resolve(range_m, energy, surface, pulse=pulse, max_returns=1)
    order = np.argsort(pulse)
    assert np.array_equal(echoes.pulse, pulse[order])
    assert np.array_equal(echoes.range_m, range_m[order])  # not (e r) / e: the range itself
    assert np.array_equal(echoes.energy, energy[order])
    assert np.array_equal(echoes.surface, surface[order]) and np.array_equal(echoes.hit, order)
    assert np.all(echoes.return_number == 1) and np.all(echoes.number_of_returns == 1)


def test_rows_at_one_range_are_summed_in_one_order_whatever_their_input_order() -> None:
    # (1 + ε) + ε rounds to 1, (ε + ε) + 1 does not: a sum must not follow the input order
    energy = np.array([1.0, 2.0**-53, 2.0**-53])
    sums = {_resolve(np.full(3, R), energy[rows], np.zeros(3)).energy[0] for rows in ([0, 1, 2], [1, 2, 0], [2, 0, 1])}
    assert len(sums) == 1


def test_surface_ids_of_any_size_name_the_returns() -> None:
    # face indices or packed ids: too wide to pack with the echo into one sort key
    range_m, energy, surface, _, _ = _plates(2.0)
    huge = np.where(surface == 1, 2**62, -(2**62))
    small, large = _resolve(range_m, energy, surface), _resolve(range_m, energy, huge)
    assert large.surface.tolist() == [2**62, -(2**62)]
    assert np.array_equal(large.hit, small.hit) and np.array_equal(large.range_m, small.range_m)


def test_hit_energy_is_the_range_equation_and_scans_one_ray_power_bit_for_bit() -> None:
    rng = np.random.default_rng(1)
    rho, cos, t = (
        rng.uniform(0, 1, 200),
        rng.uniform(0, 1, 200),
        rng.uniform(0.5, 100, 200),
    )
    assert np.array_equal(hit_energy(1.0, rho, cos, t), rho * np.abs(cos) / np.maximum(t, 1e-9) ** 2)
    assert hit_energy(0.25, 0.5, 0.8, 2.0) == pytest.approx(0.25 * 0.5 * 0.8 / 4.0)
    assert hit_energy(1.0, 1.0, 1.0, 10.0) / hit_energy(1.0, 1.0, 1.0, 20.0) == pytest.approx(4.0)
    assert np.isfinite(hit_energy(1.0, 1.0, 1.0, 0.0))


def test_opaque_surfaces_pass_nothing_and_partial_ones_their_transmittance() -> None:
    subray = np.array([4, 4, 4, 9, 9, 9, 9])
    range_m = np.array([3.0, 1.0, 2.0, 5.0, 6.0, 6.0, 7.0])
    surface = np.array([0, 1, 1, 0, 1, 2, 1])
    opaque = attenuate_along_subray(subray, range_m, surface, np.zeros(3))
    assert opaque.tolist() == [0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    t = np.array([0.0, 0.5, 0.25])
    factor = attenuate_along_subray(subray, range_m, surface, t)
    # sub-ray 4: 1.0 (s1), 2.0 (s1), 3.0 (s0); sub-ray 9: 5.0 (s0 opaque) then nothing
    assert factor.tolist() == [0.25, 1.0, 0.5, 1.0, 0.0, 0.0, 0.0]
    factor = attenuate_along_subray(subray[3:], range_m[3:], np.array([1, 1, 2, 1]), t)
    assert factor == pytest.approx([1.0, 0.5, 0.5, 0.5 * 0.5 * 0.25])  # equal ranges do not shade each other
    with pytest.raises(InvalidInputError, match="surface ids"):
        attenuate_along_subray(subray, range_m, surface, np.zeros(2))
    with pytest.raises(InvalidInputError, match="surface_transmittance"):
        attenuate_along_subray(subray, range_m, surface, [0.0, 1.5, 0.0])
    with pytest.raises(InvalidInputError, match="surface_transmittance"):
        attenuate_along_subray(subray, range_m, surface, "glass")


def test_bad_inputs_are_refused_naming_them() -> None:
    good = {"range_resolution_m": 1.0, "detection_threshold": 0.0, "max_returns": 5}
    one = (np.zeros(2, np.int64), np.ones(2), np.ones(2), np.zeros(2, np.int64))
    for name, value, match in [("range_resolution_m", 0.0, "range_resolution_m"), ("detection_threshold", -1.0, "detection_threshold"),
                               ("max_returns", MAX_RETURNS + 1, "max_returns"), ("max_returns", 0, "max_returns")]:  # fmt: skip
        with pytest.raises(InvalidInputError, match=match):
            resolve_echoes(*one, **(good | {name: value}))
    with pytest.raises(InvalidInputError, match="one length"):
        resolve_echoes(np.zeros(3, np.int64), *one[1:], **good)
    with pytest.raises(InvalidInputError, match="pulse must be an integer"):
        resolve_echoes(np.zeros(2), *one[1:], **good)
    with pytest.raises(InvalidInputError, match="energy must be finite"):
        resolve_echoes(one[0], one[1], np.array([1.0, -1.0]), one[3], **good)
    with pytest.raises(InvalidInputError, match="range_m must be finite"):
        resolve_echoes(one[0], np.array([1.0, np.nan]), *one[2:], **good)
    assert len(resolve_echoes(*(a[:0] for a in one), **good)) == 0


# -- properties over any hits -----------------------------------------------------------------


def _reference(pulse, range_m, energy, surface, resolution, threshold, max_returns):
    """The rules written as plain loops: (pulse, range, energy, surface, hits) per kept echo."""
    out = []
    for p in sorted(set(pulse.tolist())):
        rows = sorted(np.flatnonzero(pulse == p), key=lambda i: range_m[i])
        groups, last = [], None
        for i in rows:
            if last is None or range_m[i] - last >= resolution:
                groups.append([])
            groups[-1].append(i)
            last = range_m[i]
        kept = [g for g in groups if energy[g].sum() >= threshold][:max_returns]
        for g in kept:
            per_surface = {}
            for i in g:
                per_surface[surface[i]] = per_surface.get(surface[i], 0.0) + energy[i]
            best = min(per_surface, key=lambda s: (-per_surface[s], s))
            e = energy[g].sum()
            r = np.sum(energy[g] * range_m[g]) / e if e > 0 else np.mean(range_m[g])
            out.append((p, r, e, best, g, len(kept)))
    return out


@st.composite
def hits(draw, max_per_pulse: int = MAX_RETURNS):
    n = draw(st.integers(0, 40))
    pulse = np.array(draw(st.lists(st.integers(-3, 4), min_size=n, max_size=n)), np.int64)
    keep = np.ones(n, bool)
    for p in np.unique(pulse):  # at most max_per_pulse hits per pulse
        keep[np.flatnonzero(pulse == p)[max_per_pulse:]] = False
    pulse = pulse[keep]
    n = len(pulse)
    # ranges on a coarse grid too, so that ties and gaps of exactly the resolution occur
    ranges = st.one_of(
        st.floats(0.0, 60.0, allow_nan=False),
        st.integers(0, 120).map(lambda i: i * 0.25),
    )
    range_m = np.array(draw(st.lists(ranges, min_size=n, max_size=n)), np.float64)
    energies = st.one_of(st.just(0.0), st.floats(1e-12, 10.0), st.sampled_from([0.5, 1.0]))
    energy = np.array(draw(st.lists(energies, min_size=n, max_size=n)), np.float64)
    surface = np.array(draw(st.lists(st.integers(0, 4), min_size=n, max_size=n)), np.int64)
    return pulse, range_m, energy, surface


rules = st.tuples(
    st.sampled_from([0.25, 0.5, 1.0, 3.0]) | st.floats(0.01, 10.0),
    st.sampled_from([0.0, 0.5, 1.0, 2.0]),
    st.integers(1, MAX_RETURNS),
)


@settings(max_examples=300, deadline=None)
@given(hits(), rules)
def test_echoes_follow_the_rules_for_any_hits(data, rule) -> None:
    pulse, range_m, energy, surface = data
    resolution, threshold, max_returns = rule
    echoes = resolve_echoes(
        pulse,
        range_m,
        energy,
        surface,
        range_resolution_m=resolution,
        detection_threshold=threshold,
        max_returns=max_returns,
    )
    expected = _reference(pulse, range_m, energy, surface, resolution, threshold, max_returns)
    assert len(echoes) == len(expected)
    for i, (p, r, e, best, group, n) in enumerate(expected):
        assert echoes.pulse[i] == p and echoes.surface[i] == best and echoes.number_of_returns[i] == n
        assert echoes.energy[i] == pytest.approx(e, rel=1e-12, abs=1e-300)
        assert echoes.range_m[i] == pytest.approx(r, rel=1e-12, abs=1e-12)
        assert range_m[group].min() <= echoes.range_m[i] <= range_m[group].max()  # within its hits
        assert echoes.hit[i] in group and surface[echoes.hit[i]] == best
        # the named hit: the strongest of that surface in the echo, the nearest on a tie
        candidates = [j for j in group if surface[j] == best]
        strongest = max(energy[candidates])
        assert energy[echoes.hit[i]] == strongest
        assert range_m[echoes.hit[i]] == min(range_m[j] for j in candidates if energy[j] == strongest)
    for p in np.unique(echoes.pulse):
        mine = echoes.pulse == p
        n = mine.sum()
        assert np.all(echoes.number_of_returns[mine] == n)  # the same on every return of a pulse
        assert echoes.return_number[mine].tolist() == list(range(1, n + 1))  # 1..n, no gap
        assert np.all(np.diff(echoes.range_m[mine]) >= resolution)  # returns a resolution apart, at least
    assert np.all(np.diff(echoes.pulse) >= 0)


@settings(max_examples=200, deadline=None)
@given(hits(), st.floats(0.01, 10.0), st.randoms(use_true_random=False))
def test_energy_is_conserved_and_the_order_of_rows_does_not_matter(data, resolution, random) -> None:
    pulse, range_m, energy, surface = data
    rules = {
        "range_resolution_m": resolution,
        "detection_threshold": 0.0,
        "max_returns": MAX_RETURNS,
    }
    echoes = resolve_echoes(pulse, range_m, energy, surface, **rules)
    for p in np.unique(pulse):  # threshold 0 and room for every echo: all the energy comes back
        assert echoes.energy[echoes.pulse == p].sum() == pytest.approx(energy[pulse == p].sum(), rel=1e-12, abs=1e-300)
    assert set(echoes.pulse.tolist()) == set(pulse.tolist())
    rows = np.array(random.sample(range(len(pulse)), len(pulse)), np.int64)
    again = resolve_echoes(pulse[rows], range_m[rows], energy[rows], surface[rows], **rules)
    for field in (
        "pulse",
        "range_m",
        "energy",
        "surface",
        "return_number",
        "number_of_returns",
    ):
        assert np.array_equal(getattr(again, field), getattr(echoes, field)), field  # bit for bit
    for column in (
        pulse,
        range_m,
        energy,
        surface,
    ):  # the hit named: the same row, or one just like it
        assert np.array_equal(column[rows][again.hit], column[echoes.hit])


@settings(max_examples=200, deadline=None)
@given(hits(), st.lists(st.sampled_from([0.0, 0.25, 0.5, 1.0]), min_size=5, max_size=5))
def test_attenuation_is_the_product_of_the_transmittances_nearer_along_the_subray(data, transmittance) -> None:
    subray, range_m, _, surface = data
    t = np.array(transmittance)
    factor = attenuate_along_subray(subray, range_m, surface, t)
    for i in range(len(subray)):
        nearer = (subray == subray[i]) & (range_m < range_m[i])
        assert factor[i] == pytest.approx(np.prod(t[surface[nearer]]), rel=1e-12, abs=0)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(2, 60), seed=st.integers(0, 2**32 - 1), relative=st.sampled_from([0.0, 0.05]), rule=st.sampled_from(["chain", "waveform"])
)
def test_one_hit_a_pulse_gives_the_general_paths_echoes(n, seed, relative, rule) -> None:
    # rows of one hit each in pulse order take the short path; the same rows shuffled take the general one
    rng = np.random.default_rng(seed)
    pulse = np.cumsum(rng.integers(1, 4, n))
    r, e, s = rng.uniform(0.5, 80.0, n), rng.uniform(0.0, 2e-3, n), rng.integers(0, 5, n)
    rules = {"range_resolution_m": 0.5, "detection_threshold": 1e-4, "max_returns": 2, "min_echo_reflectance": relative, "echo_rule": rule}
    fast = resolve_echoes(pulse, r, e, s, **rules)
    shuffle = rng.permutation(n)
    if np.all(np.diff(shuffle) > 0):
        shuffle = shuffle[::-1]  # never in pulse order
    general = resolve_echoes(pulse[shuffle], r[shuffle], e[shuffle], s[shuffle], **rules)
    for name in ("pulse", "range_m", "energy", "surface", "return_number", "number_of_returns"):
        a, b = getattr(fast, name), getattr(general, name)
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), name
    assert np.array_equal(fast.hit, shuffle[general.hit])
    assert np.all(fast.return_number == 1) and len(fast) == int(np.sum((e >= 1e-4) & (e * r**2 >= relative)))
