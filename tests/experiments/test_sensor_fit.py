"""``fit-sensor`` (experiments/sensor_fit.py): what it writes when the crops do not tell every estimate."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import aerial_slab_crops

from zbuf_occlude.experiments.sensor_fit import fit_sensor_to_scans
from zbuf_occlude.sensors.kinds import sensor_from_name

#: Where aerial crops lie in a user's files: projected coordinates (UTM-like eastings and northings, metres).
_UTM_OFFSET = np.array([480_000.0, 5_400_000.0, 120.0])


def _strict_loads(text: str):
    """``json.loads`` that refuses ``NaN``, ``Infinity`` and ``-Infinity``, as strict JSON readers do."""

    def refuse(constant: str):
        raise ValueError(f"not JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def fitted_without_a_scan_angle(tmp_path_factory):
    """``fit-sensor --sensor dales-q1560`` on flat slabs under the plan centre: a top, no wall, so no crop tells a scan angle."""
    root = aerial_slab_crops(tmp_path_factory.mktemp("crops"), offset=_UTM_OFFSET)
    out = root.parent / f"{root.name}-fitted.json"
    fit, json_path, md_path = fit_sensor_to_scans(root, "dales-q1560", out)
    assert math.isnan(fit.estimates["max_scan_angle_deg"].value)  # the case at hand: nothing to tell the angle by
    return fit, json_path, md_path


def test_an_unmeasured_scan_angle_is_written_as_null_in_strict_json(fitted_without_a_scan_angle) -> None:
    fit, json_path, _ = fitted_without_a_scan_angle
    spec = _strict_loads(json_path.read_text())
    estimates = spec["fit"]["estimates"]
    for key in ("max_scan_angle_deg", "median_incidence_deg"):
        assert estimates[key]["value"] is None and estimates[key]["std"] is None, key
    assert estimates["density_m2"]["value"] == pytest.approx(fit.estimates["density_m2"].value)  # measured: a number
    assert sensor_from_name(json_path) == fit.sensor  # the file still loads as the fitted sensor


def test_the_table_says_an_unmeasured_scan_angle_was_not_measured(fitted_without_a_scan_angle) -> None:
    fit, _, md_path = fitted_without_a_scan_angle
    rows = {line.split("|")[1].strip(): line for line in md_path.read_text().splitlines() if line.startswith("| ")}
    for key in ("max_scan_angle_deg", "median_incidence_deg"):
        assert "not measured (no crop tells the scan angle)" in rows[key], rows[key]
    assert "nan" not in md_path.read_text().lower() and "not measured" in fit.markdown()
    assert " ± " in rows["density_m2"]  # measured values keep value ± std
