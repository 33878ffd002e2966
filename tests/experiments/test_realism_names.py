"""The realism report and its per-cloud statistics live in two modules; every name stays importable from both routes."""

from __future__ import annotations

import pytest

from zbuf_occlude.experiments import realism, realism_stats

#: The public names ``zbuf_occlude.experiments.realism`` offered when it held the statistics too; callers (scripts under
#: docs/results, the CLI, the tests) import them from there.
REALISM_NAMES = (
    "ObjectCloud", "read_object_clouds", "cloud_stats", "ring_spacings_deg", "fit_count_exponent",
    "compare_sets", "markdown_table", "realism_report", "RING_GAP_DEG", "HEIGHT_BINS", "RATIO_TARGET", "shape_stats",
    "compare_classes", "class_table", "REPORT_FILES", "ring_labels", "outline_mask", "outline_share", "scan_line_runs",
    "range_bin_medians", "class_summary", "OUTLINE_GAP_FACTOR", "SAME_AZIMUTH_DEG", "RANGE_BINS_M",
)  # fmt: skip


@pytest.mark.parametrize("name", REALISM_NAMES)
def test_every_public_name_is_still_importable_from_realism(name: str) -> None:
    assert name in realism.__all__ or name in realism_stats.__all__
    assert hasattr(realism, name)


@pytest.mark.parametrize("name", realism_stats.__all__)
def test_a_statistic_from_realism_is_the_same_object_as_from_realism_stats(name: str) -> None:
    assert getattr(realism, name) is getattr(realism_stats, name)


def test_each_name_is_documented_in_one_module() -> None:
    """A name in both ``__all__`` would be rendered twice on the API page."""
    assert not set(realism.__all__) & set(realism_stats.__all__)
    assert all(getattr(realism, name).__module__ == realism.__name__ for name in realism.__all__ if callable(getattr(realism, name)))
