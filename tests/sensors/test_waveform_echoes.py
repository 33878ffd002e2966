"""Echoes told apart on the pulse's waveform (``echo_rule="waveform"``, :mod:`zbuf_occlude.sensors.beam.waveform`).

Analytic cases: two equal reflections are told apart exactly when more than the range resolution
ΔR apart; a weak run of hits between two reflections does not join them (where the chain rule
does), and so the echoes of a footprint across a crown's side wall do not change with the sub-ray
count K.  Laws: hits within ΔR make one echo; groups ΔR apart resolve independently; the echoes
do not depend on the rows' order, on a common scale of the energies, or on scaling ranges and ΔR
together.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude.sensors.beam.echo_energy as echo_model
import zbuf_occlude.sensors.beam.waveform as waveform
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.beam.echoes import hit_energy, resolve_echoes
from zbuf_occlude.sensors.beam.footprint import footprint_offsets, subray_directions

RESOLUTION = 0.75  # ΔR of a 5 ns pulse, metres


def _echoes(r, e, rule="waveform", pulse=None, resolution=RESOLUTION, surface=None, max_returns=15):
    r, e = np.asarray(r, float), np.asarray(e, float)
    pulse = np.zeros(len(r), np.int64) if pulse is None else np.asarray(pulse, np.int64)
    surface = np.zeros(len(r), np.int64) if surface is None else np.asarray(surface, np.int64)
    return resolve_echoes(pulse, r, e, surface, range_resolution_m=resolution, detection_threshold=0.0, max_returns=max_returns,
                          echo_rule=rule)  # fmt: skip


@pytest.mark.parametrize("range_m", [5.0, 1500.0])
@pytest.mark.parametrize(("gap", "told_apart"), [(0.3, False), (0.6, False), (0.69, False), (0.81, True), (0.9, True), (1.2, True)])
def test_two_equal_reflections_are_told_apart_when_more_than_the_resolution_apart(range_m, gap, told_apart):
    ranges = [range_m, range_m + gap]
    energy = hit_energy(0.5, 0.3, 1.0, np.array(ranges))
    echoes = _echoes(ranges, energy)
    assert len(echoes) == (2 if told_apart else 1)
    if told_apart:
        np.testing.assert_array_equal(echoes.range_m, ranges)  # one hit each: its range bit for bit
    else:
        assert echoes.energy[0] == pytest.approx(energy.sum(), rel=1e-12)
        assert ranges[0] < echoes.range_m[0] < ranges[1]


def test_a_weak_run_between_two_reflections_does_not_join_them_where_the_chain_rule_does():
    # a strong reflection at 10 m and at 13 m, a weak hit every 0.5 m between (a crown's side wall across the footprint)
    r = np.r_[10.0, np.arange(10.5, 13.0, 0.5), 13.0]
    e = np.r_[1.0, np.full(5, 0.05), 1.0]
    chain, wave = _echoes(r, e, "chain"), _echoes(r, e)
    assert len(chain) == 1 and chain.energy[0] == pytest.approx(e.sum())
    assert len(wave) == 2
    assert wave.energy.sum() == pytest.approx(e.sum())  # every hit in one echo or the other
    assert 10.0 <= wave.range_m[0] < 11.0 and 12.0 < wave.range_m[1] <= 13.0
    # hits strong enough to fill the dip make one peak: no dip, one echo
    assert len(_echoes([10.0, 10.6, 11.2], [1.0, 2.0, 1.0])) == 1
    assert len(_echoes([10.0, 10.6, 11.2], [1.0, 0.1, 1.0])) == 2


@pytest.mark.parametrize(
    ("ranges", "energies", "expected"),
    [
        ([10.23, 10.9, 11.5], [0.3, 0.3, 0.32], 1),  # two peaks 0.6 m apart: one echo
        ([10.35, 10.82, 11.37, 12.23, 12.38], [0.84, 0.75, 0.97, 0.51, 0.48], 2),  # a ripple beside the first peak
    ],
)
def test_peaks_nearer_than_the_resolution_are_one_echo(ranges, energies, expected):
    """The waveform dips between these peaks, but they lie less than ΔR apart: the weaker is a ripple of the stronger."""
    echoes = _echoes(ranges, energies)
    assert len(echoes) == expected
    assert echoes.energy.sum() == pytest.approx(sum(energies))


def test_a_dip_shallower_than_the_prominence_does_not_tell_peaks_apart(monkeypatch):
    """Three equal reflections 0.74 m apart: the waveform dips by about 3 % between two peaks over ΔR apart; a receiver
    needs a deeper dip (PROMINENCE 0.05) to re-arm, one that takes any dip splits them.  With a weaker middle
    reflection the dip is deep enough either way."""
    ranges, deep, shallow = [10.0, 10.74, 11.48], [1.0, 0.6, 1.0], [1.0, 1.0, 1.0]
    assert waveform.PROMINENCE == 0.05
    assert len(_echoes(ranges, shallow)) == 1 and len(_echoes(ranges, deep)) == 2
    monkeypatch.setattr(waveform, "PROMINENCE", 0.0)
    assert len(_echoes(ranges, shallow)) == 2 and len(_echoes(ranges, deep)) == 2


def _crown_side_pulse(k: int, range_m: float = 40.0, depth_m: float = 3.0):
    """One pulse's hits across a crown's side: sub-rays left of the footprint's centre strip hit a canopy top at
    ``range_m``, those right of it a lower layer ``depth_m`` behind, those in the strip (a fifth of the footprint's
    width) a wall between, met at grazing incidence (|cos θ| 0.1)."""
    offsets, weights = footprint_offsets(k, 1.0)
    d = subray_directions([[0.0, 0.0, -1.0]], offsets)[0]
    half = math.tan(math.radians(0.5))
    x = d[:, 0] / -d[:, 2] / half  # across the footprint, −1 to 1
    strip = 0.2
    r = np.where(x < -strip, range_m, np.where(x > strip, range_m + depth_m, range_m + depth_m * (x + strip) / (2 * strip)))
    cos = np.where(np.abs(x) <= strip, 0.1, 1.0)
    return r, hit_energy(weights, 0.5, cos, r)


def _strong(echoes, total, least=0.05):
    """The echoes that carry at least ``least`` of the pulse's energy ``total``: (ranges, shares)."""
    strong = echoes.energy >= least * total
    return echoes.range_m[strong], echoes.energy[strong] / total


def test_the_echoes_of_a_footprint_across_a_crown_side_do_not_change_with_the_sub_ray_count():
    for k in (19, 37, 76, 152, 304, 608):
        r, e = _crown_side_pulse(k)
        ranges, _ = _strong(_echoes(r, e), e.sum())
        # the top and the layer below, at every K (the wall's own weak echoes, 2 % of the energy or less, aside)
        np.testing.assert_allclose(ranges, [40.0, 43.0], atol=0.05)
        chain = _echoes(r, e, "chain")
        # the chain rule: once the wall's hits lie closer than ΔR to each other, they join the two into one echo
        assert len(chain) == (1 if k >= 152 else 3)


def test_the_shares_of_echo_energy_converge_with_k():
    """The energy of the strong echoes of the crown-side pulse tends to a limit as K grows: within 1 % of the pulse's
    energy from K = 76 to K = 608 (the wall's weak echoes take the rest)."""
    shares = [_strong(_echoes(r, e), e.sum())[1] for r, e in map(_crown_side_pulse, (76, 152, 304, 608))]
    for share in shares[1:]:
        np.testing.assert_allclose(share, shares[0], atol=0.01)


_ranges = st.floats(0.0, 1.0 - 1e-9, allow_nan=False)  # hits ΔR apart (to rounding) are two echoes, as in the chain rule
_energies = st.floats(1e-6, 1.0, allow_nan=False)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(_ranges, _energies), min_size=1, max_size=30), st.floats(1.0, 3000.0))
def test_hits_within_the_resolution_are_one_echo(hits, start):
    """Where every hit's pulse is live, the waveform's slope is one sinusoid of half-period ΔR: one peak at most."""
    # (hits exactly ΔR apart start a new echo by the gap rule; their sum is flat between them)
    r = start + RESOLUTION * np.array([h[0] for h in hits])
    e = np.array([h[1] for h in hits])
    echoes = _echoes(r, e)
    assert len(echoes) == 1
    assert echoes.energy[0] == pytest.approx(e.sum(), rel=1e-12)


def _hit_lists(max_size=20):
    return st.lists(st.tuples(st.floats(0.0, 6.0, allow_nan=False), _energies), min_size=1, max_size=max_size)


@settings(max_examples=100, deadline=None)
@given(_hit_lists(), _hit_lists())
def test_groups_a_resolution_apart_resolve_independently(near, far):
    r_near = 20.0 + np.array([h[0] for h in near])
    r_far = r_near.max() + 1.001 * RESOLUTION + np.array([h[0] for h in far])  # (ΔR to rounding could fall short)
    e_near, e_far = np.array([h[1] for h in near]), np.array([h[1] for h in far])
    both = _echoes(np.r_[r_near, r_far], np.r_[e_near, e_far])
    alone = [_echoes(r_near, e_near), _echoes(r_far, e_far)]
    np.testing.assert_array_equal(both.range_m, np.r_[alone[0].range_m, alone[1].range_m])
    np.testing.assert_array_equal(both.energy, np.r_[alone[0].energy, alone[1].energy])


@settings(max_examples=100, deadline=None)
@given(_hit_lists(25), st.integers(-3, 3), st.integers(-20, 20), st.randoms(use_true_random=False))
def test_the_echoes_do_not_depend_on_row_order_or_scale(hits, range_power, energy_power, rnd):
    r = 30.0 + np.array([h[0] for h in hits])
    e = np.array([h[1] for h in hits])
    pulse = np.array([i % 2 for i in range(len(hits))], np.int64)  # two pulses, interleaved rows
    base = _echoes(r, e, pulse=pulse)
    order = list(range(len(hits)))
    rnd.shuffle(order)
    shuffled = _echoes(r[order], e[order], pulse=pulse[order])
    np.testing.assert_array_equal(shuffled.range_m, base.range_m)
    np.testing.assert_array_equal(shuffled.pulse, base.pulse)
    # ranges and ΔR scaled by a power of two (exact in binary), energies by another: the same echoes, scaled
    c, g = 2.0**range_power, 2.0**energy_power
    scaled = _echoes(r * c, e * g, pulse=pulse, resolution=RESOLUTION * c)
    np.testing.assert_array_equal(scaled.range_m, base.range_m * c)
    np.testing.assert_array_equal(scaled.energy, base.energy * g)
    np.testing.assert_array_equal(scaled.return_number, base.return_number)


def test_batches_of_segments_give_the_same_echoes(monkeypatch):
    rng = np.random.default_rng(5)
    pulse = np.repeat(np.arange(300), 12)
    r = 50.0 + rng.uniform(0.0, 5.0, len(pulse))
    e = rng.uniform(0.01, 1.0, len(pulse))
    whole = _echoes(r, e, pulse=pulse)
    assert len(whole) > 600  # most pulses hold several echoes
    monkeypatch.setattr(waveform, "_BATCH_PAIRS", 200)  # a few segments a batch
    batched = _echoes(r, e, pulse=pulse)
    for name in ("pulse", "range_m", "energy", "hit", "return_number"):
        np.testing.assert_array_equal(getattr(batched, name), getattr(whole, name))


def test_the_rules_agree_where_every_pulse_is_one_surface_or_far_apart_surfaces():
    rng = np.random.default_rng(2)
    pulse = np.repeat(np.arange(200), 7)
    layer = rng.integers(0, 3, len(pulse))  # up to three surfaces per pulse, 5 m apart, each within 0.7 ΔR
    r = 10.0 + 5.0 * layer + rng.uniform(0.0, 0.7 * RESOLUTION, len(pulse))
    e = rng.uniform(0.0, 1.0, len(pulse))
    chain, wave = _echoes(r, e, "chain", pulse=pulse), _echoes(r, e, pulse=pulse)
    for name in ("pulse", "range_m", "energy", "surface", "hit", "return_number", "number_of_returns"):
        np.testing.assert_array_equal(getattr(wave, name), getattr(chain, name))


def test_a_segment_without_energy_is_one_echo():
    echoes = _echoes([10.0, 10.5, 11.0, 11.5], [0.0, 0.0, 0.0, 0.0])
    assert len(echoes) == 1 and echoes.energy[0] == 0.0


@pytest.mark.parametrize("rule", ["Waveform", "peak", "", 3, None])
def test_an_unknown_rule_is_refused_naming_it(rule):
    with pytest.raises(InvalidInputError, match="echo_rule"):
        _echoes([10.0], [1.0], rule)


def test_the_beam_takes_the_rule_only_where_echoes_are_resolved():
    beam = Beam(divergence_deg=0.2, footprint_rays=7, max_returns=3, range_resolution_m=0.75, echo_rule="waveform")
    assert beam.echo_rule == "waveform" and Beam().echo_rule == "chain"
    assert Beam(divergence_deg=0.2, footprint_rays=7, max_returns=1, return_mode="strongest", range_resolution_m=0.75,
                echo_rule="waveform").echo_rule == "waveform"  # fmt: skip
    with pytest.raises(InvalidInputError, match="echo_rule waveform tells resolved echoes apart"):
        Beam(divergence_deg=0.2, footprint_rays=7, echo_rule="waveform")
    for bad in ("gap", 1, True):
        with pytest.raises(InvalidInputError, match="echo_rule"):
            Beam(max_returns=2, range_resolution_m=0.75, echo_rule=bad)


@pytest.mark.parametrize("footprint", ["exact", "adaptive"])
def test_a_scan_resolves_its_echoes_with_the_beams_rule(monkeypatch, footprint):
    import trimesh

    import zbuf_occlude.sensors as S
    import zbuf_occlude.sensors.beam.adaptive_cast as adaptive
    from zbuf_occlude.sensors.kinds import with_beam
    from zbuf_occlude.sensors.patterns.spinning import Lidar

    rules = []

    def spy(*args, **kwargs):
        rules.append(kwargs.get("echo_rule"))
        return resolve_echoes(*args, **kwargs)

    monkeypatch.setattr(echo_model, "resolve_echoes", spy)
    monkeypatch.setattr(adaptive, "resolve_echoes", spy)
    lidar = with_beam(Lidar.preset("vlp16"), divergence_deg=0.3, footprint_rays=7, max_returns=3, range_resolution_m=0.75,
                      echo_rule="waveform")  # fmt: skip
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    box.apply_translation((6.0, 0.0, 0.0))
    scan = S.scan(box, lidar, np.zeros(3), seed=0, footprint=footprint)
    assert len(scan.points) > 0
    assert rules and set(rules) == {"waveform"}


@pytest.mark.parametrize("value", [["waveform"], "WAVEFORM", 1e300, None, {"rule": "waveform"}])
def test_a_sensor_file_with_a_bad_echo_rule_is_refused_naming_the_file(tmp_path, value):
    import json

    from zbuf_occlude.sensors.kinds import sensor_from_name

    path = tmp_path / "sensor.json"
    path.write_text(
        json.dumps({"kind": "lidar", "preset": "vlp16", "beam": {"echo_rule": value, "max_returns": 2, "range_resolution_m": 0.5}})
    )
    with pytest.raises(InvalidInputError, match=r"sensor\.json.*echo_rule must be one of 'chain', 'waveform'"):
        sensor_from_name(path)


def test_a_sensor_file_carries_the_rule(tmp_path):
    import json

    from zbuf_occlude.sensors.kinds import sensor_from_name, sensor_to_json

    path = tmp_path / "sensor.json"
    path.write_text(json.dumps({"kind": "lidar", "preset": "vlp16", "beam": {"echo_rule": "waveform", "max_returns": 2,
                                                                            "range_resolution_m": 0.5, "footprint_rays": 7}}))  # fmt: skip
    sensor = sensor_from_name(path)
    assert sensor.beam.echo_rule == "waveform"
    again = tmp_path / "again.json"
    again.write_text(json.dumps(sensor_to_json(sensor)))
    assert sensor_from_name(again) == sensor
