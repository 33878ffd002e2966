"""Fitted estimates as JSON (sensors/fit/lidar.py): a quantity nothing measured is ``null``, not ``NaN``."""

from __future__ import annotations

import json
import math

from zbuf_occlude.sensors.fit import Estimate, LidarFit
from zbuf_occlude.sensors.patterns.spinning import lidar_preset


def _strict_loads(text: str):
    """``json.loads`` that refuses ``NaN``, ``Infinity`` and ``-Infinity``, as strict JSON readers do."""

    def refuse(constant: str):
        raise ValueError(f"not JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def test_a_spinning_fit_with_unmeasured_estimates_writes_null() -> None:
    sensor = lidar_preset("hdl32e")
    fit = LidarFit(sensor, sensor, {"dropout": Estimate(math.nan, math.nan, 0, "too few scans"),
                                    "range_noise_m": Estimate(0.02, math.nan, 1, "one scan", "m")}, 1)  # fmt: skip
    spec = _strict_loads(json.dumps(fit.to_json(), allow_nan=False))
    assert spec["fit"]["estimates"]["dropout"]["value"] is None and spec["fit"]["estimates"]["range_noise_m"] == {
        "value": 0.02, "std": None, "n": 1, "method": "one scan", "unit": "m", "set_in_sensor": False}  # fmt: skip
    assert "nan" not in fit.markdown().lower()
