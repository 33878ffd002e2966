"""``zbuf-occlude fit-sensor``: a spinning LiDAR fitted to a folder of the user's real object scans.

Reads the scans with :func:`zbuf_occlude.real_scans.datasets.load_real_scans` (any real-scan
format it detects; the sensor-frame points), fits with :func:`zbuf_occlude.sensors.fit.fit_lidar`
(and, per class of at least 3 scans, the crops' sensor distances and object heights,
:func:`zbuf_occlude.sensors.fit.crop_placement_json`) and writes the sensor JSON (which ``scan``, ``farm --sensor`` and ``experiment sim2real
--sensor`` read) and a Markdown table of the estimates beside it, both atomically.
"""

from __future__ import annotations

import json
import os
from collections import Counter
from pathlib import Path

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.atomic import write_text
from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.sensors.fit import LidarFit, crop_placement_json, fit_lidar
from zbuf_occlude.sensors.presets import sensor_from_name

__all__ = ["fit_sensor_to_scans"]


def fit_sensor_to_scans(real: str | os.PathLike, sensor: str, out: str | os.PathLike, *, seed: int = 0,
                        dataset: str = "auto") -> tuple[LidarFit, Path, Path]:  # fmt: skip
    """Fit ``sensor`` (a spinning-LiDAR preset name or JSON file) to the scans under ``real``.

    Returns
    -------
    fit : LidarFit
    json_path, markdown_path : Path
        ``out`` (a ``.json`` file) and the same name with ``.md``.

    Raises
    ------
    InvalidInputError
        ``out`` does not end in ``.json``; an unknown or non-LiDAR sensor; unreadable scans or scans
        without a sensor frame (:func:`~zbuf_occlude.sensors.fit.fit_lidar`), each naming the cause.
    """
    out = Path(out)
    if out.suffix.lower() != ".json":
        raise InvalidInputError(f"--out {out}: the fitted sensor is written as a .json file")
    base = sensor_from_name(sensor)
    scans = load_real_scans(real, dataset=dataset)
    missing = [s.source for s in scans if s.points_sensor_m is None]
    if missing:
        raise InvalidInputError(f"{missing[0]}: no sensor-frame points to fit a sensor to ({len(missing)} such scans)")
    clouds = [s.points_sensor_m for s in scans]
    fit = fit_lidar(clouds, base, seed=seed)
    spec = fit.to_json()
    counts = Counter(s.label for s in scans)
    rows = [i for i, s in enumerate(scans) if counts[s.label] >= 3]
    crops = crop_placement_json([clouds[i] for i in rows], [scans[i].label for i in rows]) if rows else None
    if crops is not None:
        spec["fit"]["crops"] = crops
    md = out.with_suffix(".md")
    write_text(out, json.dumps(spec, indent=1, default=float) + "\n")
    text = f"# {fit.sensor.name}: fitted to {fit.n_scans} scans under {Path(real).name}\n\n{fit.markdown()}"
    if crops is not None:
        lo_q, hi_q = crops["quantiles"]
        text += (f"\nPer class, {lo_q:g}th to {hi_q:g}th percentile over its scans: the sensor's horizontal distance to the "
                 "returns' centroid (crops' `distance_m`) and the returns' vertical extent (the visible height):\n\n"
                 "| class | scans | distance, m | visible height, m |\n|---|---|---|---|\n")  # fmt: skip
        for k, (lo, hi) in crops["distance_m"].items():
            h_lo, h_hi = crops["object_height_m"][k]
            text += f"| {k} | {counts[k]} | {lo:.1f}–{hi:.1f} | {h_lo:.2f}–{h_hi:.2f} |\n"
    write_text(md, text)
    return fit, out, md
