"""Per-pulse return statistics: pulses built by hand give exactly their figures; the shared real scans give SOURCE.md's."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.io.las import LasPoints, read_las
from zbuf_occlude.sensors.fit.las_pulses import MAX_AMBIGUOUS_SHARE, las_pulses
from zbuf_occlude.sensors.fit.returns import return_statistics

#: The real airborne scans (research-only, next to the repository; skipped when absent).
ALS_RETURNS = Path(os.environ.get("ZBUF_OCCLUDE_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data")) / "als_returns"
needs_shared = pytest.mark.skipif(not ALS_RETURNS.is_dir(), reason="../shared/data/als_returns not present")


def _scan(pulses: list[tuple[int, list[tuple[int, float, int, int]]]], *, unit_m: float = 1.0, shuffle: int | None = 0) -> LasPoints:
    """Pulse ``i`` at x = i, GPS time i ms: ``(number_of_returns, [(return_number, z, intensity, class), ...])``."""
    rows = [(i, count, *ret) for i, (count, returns) in enumerate(pulses) for ret in returns]
    i, count, number, z, intensity, cls = (np.array(c) for c in zip(*rows, strict=True))
    order = np.random.default_rng(shuffle).permutation(len(rows)) if shuffle is not None else np.arange(len(rows))
    return LasPoints(
        points=np.stack([i, np.zeros(len(i)), z], axis=1)[order].astype(float), intensity=intensity[order], return_number=number[order],
        number_of_returns=count[order], gps_time=i[order] * 1e-3, scan_angle_deg=np.zeros(len(i)), classification=cls[order],
        point_source_id=np.zeros(len(i)), scanner_channel=np.zeros(len(i)), linear_unit_m=unit_m,
    )  # fmt: skip


#: 4 single returns on ground; two 2-return pulses (gaps 1 and 3) and a 3-return one (gaps 0.5, 2) in trees; a thinned pulse.
HAND = [
    *[(1, [(1, 0.0, v, 2)]) for v in (100, 120, 140, 160)],
    (2, [(1, 10.0, 50, 5), (2, 9.0, 30, 2)]),
    (2, [(1, 10.0, 70, 5), (2, 7.0, 30, 2)]),
    (3, [(1, 12.0, 60, 5), (2, 11.5, 20, 5), (3, 9.5, 10, 2)]),
    (2, [(1, 8.0, 80, 5)]),
]


def test_pulses_built_by_hand_give_exactly_their_figures() -> None:
    stats = return_statistics(_scan(HAND), classes=(2, 5))
    e = {k: v.value for k, v in stats.estimates.items()}
    assert (stats.n_points, stats.n_pulses, stats.n_complete_pulses) == (12, 8, 7)
    assert [e[f"returns_{k}"] for k in ("1", "2", "3", "4", "5+")] == pytest.approx([4 / 7, 2 / 7, 1 / 7, 0, 0])
    assert e["multi_return_points"] == pytest.approx(8 / 12)
    assert e["multi_return_points_class_2"] == pytest.approx(3 / 7) and e["multi_return_points_class_5"] == 1.0
    assert (e["gap_min"], e["gap_p05"], e["gap_median"], e["gap_count"]) == pytest.approx((0.5, np.percentile([0.5, 1, 2, 3], 5), 1.5, 4))
    assert (e["intensity_single"], e["intensity_first_of_several"], e["intensity_ratio"]) == (130.0, 65.0, 0.5)
    assert e["intensity_ratio_classes_2_5"] == 0.5 and e["multi_return_points_classes_2_5"] == pytest.approx(8 / 12)
    assert stats.estimates["returns_2"].std == pytest.approx(math.sqrt(2 / 7 * 5 / 7 / 7))  # binomial
    assert stats.estimates["returns_2"].method.startswith("binomial")
    assert stats.estimates["gap_median"].method == "bootstrap over pulses (200, seed 0)" and stats.gap_unit == "m"


def test_gaps_follow_the_files_unit_and_the_class_set_may_be_absent() -> None:
    in_feet = return_statistics(_scan(HAND, unit_m=0.3048), classes=(5,))
    assert in_feet.estimates["gap_min"].value == pytest.approx(0.5 * 0.3048) and in_feet.gap_unit == "m"
    assert math.isnan(in_feet.estimates["intensity_single_classes_5"].value)  # no single return on class 5
    unknown = return_statistics(_scan(HAND, unit_m=math.nan), classes=None)
    assert unknown.gap_unit == "coordinate unit" and unknown.estimates["gap_min"].value == 0.5
    assert not any("classes" in name for name in unknown.estimates)


def test_the_figures_do_not_depend_on_the_order_of_the_points_and_the_seed_fixes_the_spread() -> None:
    a, b = return_statistics(_scan(HAND, shuffle=1)), return_statistics(_scan(HAND, shuffle=None))
    assert a.to_json() == b.to_json()
    c = return_statistics(_scan(HAND, shuffle=1), seed=5)
    assert {k: v.value for k, v in c.estimates.items() if math.isfinite(v.value)} == {
        k: v.value for k, v in a.estimates.items() if math.isfinite(v.value)
    }


#: Single pulses beside the two inconsistent ones, so that their 5 points are within MAX_AMBIGUOUS_SHARE of the scan's.
SINGLES = 600


def test_an_incomplete_or_inconsistent_pulse_is_not_complete_and_has_no_gaps() -> None:
    pulses = [
        (2, [(1, 0.0, 10, 1), (1, 1.0, 10, 1)]),  # return 1 twice
        (2, [(1, 0.0, 10, 1), (2, 1.0, 10, 1), (2, 2.0, 10, 1)]),  # three points for two returns
        (3, [(1, 0.0, 10, 1), (2, 1.0, 10, 1), (3, 2.0, 10, 1)]),
        *[(1, [(1, 0.0, 10, 1)])] * SINGLES,
    ]
    stats = return_statistics(_scan(pulses))
    assert stats.n_complete_pulses == 1 + SINGLES and stats.estimates["returns_3"].value == 1 / (1 + SINGLES)
    # 1->2 and 2->3 in the third pulse; the second holds return 2 twice: not one pulse's returns, no gap
    assert stats.estimates["gap_count"].value == 2


@st.composite
def _pulse_lists(draw):
    pulses, expected = [], {"complete": [], "pairs": 0}
    for _ in range(draw(st.integers(1, 25))):
        count = draw(st.integers(1, 7))
        kept = sorted(draw(st.sets(st.integers(1, count), min_size=1)))
        cls = draw(st.sampled_from([1, 2, 5]))
        pulses.append((count, [(r, float(-r), draw(st.integers(0, 65535)), cls) for r in kept]))
        if len(kept) == count:
            expected["complete"].append(count)
        expected["pairs"] += sum(1 for r in kept if r + 1 in kept)
    return pulses, expected


@settings(max_examples=60, deadline=None)
@given(_pulse_lists())
def test_laws_shares_sum_to_one_and_points_and_pulses_add_up(case) -> None:
    pulses, expected = case
    stats = return_statistics(_scan(pulses), bootstrap=2)
    e = stats.estimates
    assert stats.n_points == sum(len(r) for _, r in pulses) and stats.n_pulses == len(pulses)
    assert stats.n_complete_pulses == len(expected["complete"])
    shares = [e[k].value for k in ("returns_1", "returns_2", "returns_3", "returns_4", "returns_5+")]
    if expected["complete"]:
        assert sum(shares) == pytest.approx(1.0, abs=1e-12)
        assert shares[4] == pytest.approx(np.mean(np.array(expected["complete"]) >= 5))
    else:
        assert all(math.isnan(s) for s in shares)
    multi = [count > 1 for count, returns in pulses for _ in returns]
    assert e["multi_return_points"].value == pytest.approx(np.mean(multi))
    assert e["gap_count"].value == expected["pairs"]
    if expected["pairs"]:
        assert e["gap_min"].value == 1.0  # consecutive returns are 1 apart in z
    json.dumps(stats.to_json(), allow_nan=False)


@st.composite
def _pulses_some_twice(draw):
    """Pulses of 1 to 4 returns, some with a return number repeated (a duplicated point, or two pulses of one time), the
    rest whole; what a grouping by time must find: the pulses holding a repeat, and the gaps of the others."""
    pulses, repeated, pairs = [], [], 0
    for i in range(draw(st.integers(1, 30))):
        count = draw(st.integers(1, 4))
        returns = [(r, float(-r), 10, 1) for r in range(1, count + 1)]
        if draw(st.booleans()) and draw(st.booleans()):
            returns.append(returns[draw(st.integers(0, count - 1))])
            repeated.append(i)
        else:
            pairs += count - 1
        pulses.append((count, returns))
    return pulses, repeated, pairs


@settings(max_examples=60, deadline=None)
@given(_pulses_some_twice(), st.integers(0, 2**32 - 1))
def test_law_a_pulse_holding_a_return_number_twice_is_ambiguous_and_gives_no_gap(case, shuffle) -> None:
    pulses, repeated, pairs = case
    scan = _scan(pulses, shuffle=shuffle)  # the order of the points in the file changes nothing
    found = las_pulses(scan)
    assert np.flatnonzero(found.ambiguous).tolist() == repeated and not (found.complete & found.ambiguous).any()
    assert int(found.pairs(scan.return_number).sum()) == pairs
    in_repeated = sum(len(pulses[i][1]) for i in repeated)
    if in_repeated > MAX_AMBIGUOUS_SHARE * len(scan):
        with pytest.raises(InvalidInputError, match="its GPS times do not identify pulses"):
            return_statistics(scan, bootstrap=2)
    else:
        assert return_statistics(scan, bootstrap=2).estimates["gap_count"].value == pairs


def test_wrong_kinds_and_scans_without_times_are_refused() -> None:
    scan = _scan(HAND)
    with pytest.raises(ArgumentTypeError, match="las must be a LasPoints"):
        return_statistics("scan.laz")  # type: ignore[arg-type]
    with pytest.raises(ArgumentTypeError, match="classes must be a sequence"):
        return_statistics(scan, classes=5)  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError, match="classes must be ASPRS class codes"):
        return_statistics(scan, classes=(5, 300))
    with pytest.raises(InvalidInputError, match="bootstrap must be >= 2"):
        return_statistics(scan, bootstrap=1)
    with pytest.raises(InvalidInputError, match="seed must be a non-negative integer"):
        return_statistics(scan, seed=0.5)  # type: ignore[arg-type]
    no_time = LasPoints(**{f: getattr(scan, f) for f in LasPoints._DTYPES}, points=scan.points, has_gps_time=False, point_format_id=2)
    with pytest.raises(InvalidInputError, match="point format 2 has no GPS time"):
        return_statistics(no_time)


def test_markdown_and_json() -> None:
    stats = return_statistics(_scan(HAND), classes=(5,))
    table = stats.markdown()
    assert table.startswith("12 points, 8 pulses, 7 complete; class set 5")
    assert "| returns_1 | 57.14 ± 19 | % | 7 | binomial, over 7 complete pulses |" in table
    assert "| intensity_single_classes_5 | not measured |" in table and "| gap_count | 4 |" in table
    out = json.loads(json.dumps(stats.to_json(), allow_nan=False))
    assert out["estimates"]["intensity_single_classes_5"]["value"] is None and out["n_complete_pulses"] == 7


# -- the shared real scans: SOURCE.md's figures ----------------------------------------------------------------------------


@needs_shared
def test_the_ign_sample_gives_the_figures_of_source_md() -> None:
    stats = return_statistics(read_las(ALS_RETURNS / "ign_lidarhd_sample.laz"), classes=(5,))
    e = {k: v.value for k, v in stats.estimates.items()}
    assert (stats.n_pulses, stats.n_complete_pulses) == (32_231, 30_722)
    assert [round(100 * e[f"returns_{k}"], 2) for k in "1234"] == [84.89, 12.56, 2.31, 0.24]
    assert round(100 * e["multi_return_points"], 1) == 31.0 and round(100 * e["multi_return_points_class_5"], 1) == 64.9
    assert round(100 * e["multi_return_points_class_2"], 1) == 13.5 and round(100 * e["multi_return_points_class_1"], 1) == 49.6
    assert (round(e["gap_min"], 2), round(e["gap_p05"], 2), round(e["gap_median"], 2), e["gap_count"]) == (0.82, 0.97, 2.46, 5574)
    assert (e["intensity_first_of_several_classes_5"], e["intensity_single_classes_5"]) == (76.0, 145.0)


@needs_shared
def test_autzen_gives_the_figures_of_source_md() -> None:
    stats = return_statistics(read_las(ALS_RETURNS / "autzen_trim.laz"))
    e = {k: v.value for k, v in stats.estimates.items()}
    assert (stats.n_pulses, stats.n_complete_pulses) == (99_331, 99_162)
    assert [round(100 * e[f"returns_{k}"], 1) for k in "1234"] == [91.0, 7.4, 1.5, 0.1]
    assert round(100 * e["multi_return_points"], 1) == 18.0
    assert round(100 * e["multi_return_points_class_2"], 1) == 9.1 and round(100 * e["multi_return_points_class_1"], 1) == 20.7
    assert e["gap_min"] == pytest.approx(6.93 * 0.3048, abs=0.01)  # the file is in international feet
