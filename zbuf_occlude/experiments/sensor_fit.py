"""``zbuf-occlude fit-sensor``: a sensor fitted to a folder of the user's real object scans.

Reads the scans with :func:`zbuf_occlude.real_scans.datasets.load_real_scans` (any real-scan
format it detects; each scan's points in metres, z up, as the file gives them).  The ``sensor``
to start from chooses the fit:

* a spinning LiDAR (``hdl32e``, ...): :func:`zbuf_occlude.sensors.fit.fit_lidar` on the scans in
  the sensor's frame (sensor at the origin), and, per class of at least
  :data:`~zbuf_occlude.sensors.fit.MIN_PLACEMENT_SCANS` scans, the crops' sensor distances and
  object heights (:func:`zbuf_occlude.sensors.fit.crop_placement_json`);
* an airborne scanner (``dales-q1560``, ``riegl-q1560``, or a file of ``"kind": "airborne"``):
  :func:`zbuf_occlude.sensors.fit.fit_airborne` on the crops as they lie (no sensor position).

Writes the sensor JSON (which ``scan``, ``farm --sensor`` and ``experiment sim2real --sensor``
read) and a Markdown table of the estimates beside it, both through the output layer
(:class:`~zbuf_occlude.io.owned.OwnedFolder` on their folder: atomic, recorded, and replacing
only files a run of ours wrote).  The JSON is strict (no
``NaN``, which strict readers refuse): an estimate the scans do not tell is ``null``, and the table
says it was not measured and why.
"""

from __future__ import annotations

import json
import os
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from zbuf_occlude.errors import InvalidInputError, OutputError
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.sensors.airborne import AirborneScanner
from zbuf_occlude.sensors.fit import BOOTSTRAP, MIN_PLACEMENT_SCANS, AirborneFit, LidarFit, crop_placement_json, fit_airborne, fit_lidar
from zbuf_occlude.sensors.lidar import Lidar
from zbuf_occlude.sensors.fit.lidar import sensor_kind
from zbuf_occlude.sensors.kinds import sensor_from_name

__all__ = ["fit_to_scans", "fit_sensor_to_scans"]


def _strict_json(spec: dict) -> str:
    """``spec`` as strict JSON text (numpy scalars as numbers); a NaN left in it is our bug, so it raises ValueError."""
    return json.dumps(spec, indent=1, default=float, allow_nan=False) + "\n"


def fit_to_scans(scans: Sequence, base: Lidar, labels: Sequence[str], *, seed: int = 0,
                 every_class: bool = False) -> tuple[LidarFit, dict]:  # fmt: skip
    """``base`` fitted to the sensor-frame points of ``scans``, and its JSON with the crops' placement per class.

    Parameters
    ----------
    scans : sequence of RealScan
        Each with ``points_sensor_m (N, 3) float64`` (sensor at the origin, z up, metres) and ``source``.
    base : Lidar
    labels : sequence of str
        One class name per scan.
    seed : int
        Seeds the bootstrap (:func:`~zbuf_occlude.sensors.fit.fit_lidar`).
    every_class : bool
        Every class must have :data:`~zbuf_occlude.sensors.fit.MIN_PLACEMENT_SCANS` scans for its ``fit.crops`` entry (an error
        names the one that has fewer); False: such classes are left out of ``fit.crops``.

    Returns
    -------
    fit : LidarFit
    spec : dict
        ``fit.to_json()`` with ``spec["fit"]["crops"]`` (:func:`~zbuf_occlude.sensors.fit.crop_placement_json`)
        when a class has enough scans.

    Raises
    ------
    InvalidInputError
        A scan without sensor-frame points (naming it and how many such scans there are), what
        :func:`~zbuf_occlude.sensors.fit.fit_lidar` refuses, or, with ``every_class``, a class
        with too few scans.
    """
    missing = [s.source for s in scans if s.points_sensor_m is None or len(s.points_sensor_m) == 0]
    if missing:
        raise InvalidInputError(f"{missing[0]}: no sensor-frame points to fit a sensor to ({len(missing)} such scans; the "
                                "fit needs the scans' coordinates with the sensor at the origin)")  # fmt: skip
    clouds = [np.asarray(s.points_sensor_m, dtype=np.float64) for s in scans]
    fit = fit_lidar(clouds, base, seed=seed)
    spec = fit.to_json()
    counts = Counter(labels)
    rows = [i for i, y in enumerate(labels) if every_class or counts[y] >= MIN_PLACEMENT_SCANS]
    if rows:
        spec["fit"]["crops"] = crop_placement_json([clouds[i] for i in rows], [labels[i] for i in rows])
    return fit, spec


def fit_sensor_to_scans(real: str | os.PathLike, sensor: str, out: str | os.PathLike, *, seed: int = 0, dataset: str = "auto",
                        say: Callable[[str], object] | None = None) -> tuple[LidarFit | AirborneFit, Path, Path]:  # fmt: skip
    """Fit ``sensor`` (a preset name or JSON file: a spinning LiDAR or an airborne scanner) to the scans under ``real``.

    Parameters
    ----------
    real : path
        The real scans (:func:`~zbuf_occlude.real_scans.datasets.load_real_scans`, ``dataset``).
    sensor : str
        The sensor to start from; its kind chooses the fit (module docstring).
    out : path
        The fitted sensor's ``.json`` file; the table goes to the same name with ``.md``.
    seed : int
        Seeds the bootstrap.
    say : callable, optional
        Called with a one-line description of each step before it runs (what is read, how many
        scans of which classes, what is fitted to them); the command line prints them.

    Returns
    -------
    fit : LidarFit or AirborneFit
    json_path, markdown_path : Path

    Raises
    ------
    InvalidInputError
        ``out`` does not end in ``.json``; an unknown sensor or one that is neither kind (both
        before any scan is read); unreadable scans; what the fit refuses (spinning: scans not in a
        spinning sensor's frame, such as airborne crops, in one line), each naming the cause.
    OutputError
        ``out`` is a folder, or its folder cannot be made or written.
    UnsafePathError
        ``out`` or the ``.md`` beside it exists and was not written by a run of ours, or was
        changed since (checked before any scan is read; nothing is written).
    DatasetBusy
        Another live process holds the folder of ``out``.
    """
    out = Path(out)
    if out.suffix.lower() != ".json":
        raise InvalidInputError(f"--out {out}: the fitted sensor is written as a .json file")
    if out.is_dir():
        raise OutputError(f"--out {out} is a folder; name the file to write")
    base = sensor_from_name(sensor)
    if sensor_kind(base) not in ("lidar", "airborne"):
        raise InvalidInputError(f"--sensor {sensor}: fit-sensor fits a spinning LiDAR or an airborne scanner, not a {type(base).__name__}")
    md = out.with_suffix(".md")
    names = (out.name, md.name)
    with OwnedFolder(out.parent, files=names, what="the fitted sensor") as folder:
        folder.check_writable(names)  # both before any scan is read: a refusal writes nothing
        fit = _fit_into(folder, real, base, out.name, md.name, seed=seed, dataset=dataset, say=say or (lambda _: None))
    return fit, out, md


def _fit_into(folder: OwnedFolder, real: str | os.PathLike, base: Lidar | AirborneScanner, json_name: str, md_name: str, *, seed: int,
              dataset: str, say: Callable[[str], object]) -> LidarFit | AirborneFit:  # fmt: skip
    """:func:`fit_sensor_to_scans` once the folder of its files is held: fit, write ``json_name`` and ``md_name``."""
    say(f"reading the real scans under {real} ...")
    scans = load_real_scans(real, dataset=dataset)
    counts = Counter(s.label for s in scans)
    airborne = sensor_kind(base) == "airborne"
    kind = "an airborne scanner" if airborne else "a spinning LiDAR"
    say(f"read {len(scans)} scans of {len(counts)} class{'' if len(counts) == 1 else 'es'} ({', '.join(f'{k}: {n}' for k, n in sorted(counts.items()))}); "
        f"fitting {kind}, {base.name}, with {BOOTSTRAP} bootstrap resamples ...")  # fmt: skip
    if airborne:
        missing = [s.source for s in scans if s.points_sensor_m is None]
        if missing:
            raise InvalidInputError(f"{missing[0]}: no points in metres to fit a scanner to ({len(missing)} such scans)")
        fit = fit_airborne([s.points_sensor_m for s in scans], base, seed=seed)
        folder.write_text(json_name, _strict_json(fit.to_json()))
        folder.write_text(md_name, f"# {fit.sensor.name}: fitted to {fit.n_crops} crops under {Path(real).name}\n\n{fit.markdown()}")
        return fit
    fit, spec = fit_to_scans(scans, base, [s.label for s in scans], seed=seed)
    crops = spec["fit"].get("crops")
    folder.write_text(json_name, _strict_json(spec))
    text = f"# {fit.sensor.name}: fitted to {fit.n_scans} scans under {Path(real).name}\n\n{fit.markdown()}"
    if crops is not None:
        lo_q, hi_q = crops["quantiles"]
        text += (f"\nPer class, {lo_q:g}th to {hi_q:g}th percentile over its scans: the sensor's horizontal distance to the "
                 "returns' centroid (crops' `distance_m`), the top return's and the lowest return's heights above the "
                 f"ground (crops' `object_height_m` and `hidden_below_m`; the ground {crops['sensor_height_m']:.2f} m below "
                 "the sensor), and the width across the line of sight (crops' `across_sight_width_m`):\n\n"
                 "| class | scans | distance, m | top return, m | lowest return, m | width, m |\n|---|---|---|---|---|---|\n")  # fmt: skip
        for k, (lo, hi) in crops["distance_m"].items():
            h_lo, h_hi = crops["object_height_m"][k]
            b_lo, b_hi = crops["hidden_below_m"][k]
            w_lo, w_hi = crops["across_sight_width_m"][k]
            text += f"| {k} | {counts[k]} | {lo:.1f}–{hi:.1f} | {h_lo:.2f}–{h_hi:.2f} | {b_lo:.2f}–{b_hi:.2f} | {w_lo:.2f}–{w_hi:.2f} |\n"
        profiles = crops["across_sight_profile"]
        bins = len(next(iter(profiles.values())))
        text += ("\nThe outline over the height (crops' `across_sight_profile`): per class, the median over its scans of the "
                 f"width in {bins} bins of relative height (bottom to top), over the scan's width:\n\n"
                 "| class | " + " | ".join(f"{b / bins:.3g}–{(b + 1) / bins:.3g}" for b in range(bins)) + " |\n|---|" + "---|" * bins + "\n")  # fmt: skip
        for k, values in profiles.items():
            text += f"| {k} | " + " | ".join(f"{v:.2f}" for v in values) + " |\n"
    folder.write_text(md_name, text)
    return fit
