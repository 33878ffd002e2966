"""``fit-sensor``'s engine: a sensor fitted to the user's real scans, read, fitted and written as a sensor file.

What the input is chooses the fit (:func:`fit_sensor`):

* LAS/LAZ scans (a ``.las``/``.laz`` file, or a folder of them: tiles or crops of one survey;
  :func:`las_inputs`): the return model (:func:`fit_sensor_to_las`,
  :func:`~zbuf_occlude.sensors.fit.fit_return_model`) applied to the sensor's beam
  (:mod:`.fitted_beam`);
* a folder of real object scans (any format :func:`~zbuf_occlude.real_scans.datasets.load_real_scans`
  detects; points in metres, z up; :func:`fit_sensor_to_scans`), where the sensor to start from
  chooses the fit:

  - a spinning LiDAR (``hdl32e``, ...): :func:`~zbuf_occlude.sensors.fit.fit_lidar` on the scans in
    the sensor's frame (sensor at the origin), and, per class of at least
    :data:`~zbuf_occlude.sensors.fit.MIN_PLACEMENT_SCANS` scans, the crops' sensor distances and
    object heights (:func:`~zbuf_occlude.sensors.fit.crop_placement_json`; :func:`fit_to_scans`);
  - an airborne scanner (``dales-q1560``, ``riegl-q1560``, or a file of ``"kind": "airborne"``):
    :func:`~zbuf_occlude.sensors.fit.fit_airborne` on the crops as they lie (no sensor position).

  A spinning LiDAR's fit may be followed by a :class:`Refine` step, run on the same scans before
  anything is written, whose sensor is written instead (``fit-sensor --meshes``: the detection of
  partial echoes, fitted by :mod:`zbuf_occlude.sensors.fit.partial_echo_meshes`, which this package
  does not import).

Writes the sensor JSON (which ``scan``, ``farm --sensor`` and ``experiment sim2real --sensor``
read) and a Markdown table of the estimates beside it, both through the output layer
(:class:`~zbuf_occlude.io.owned.OwnedFolder` on their folder: atomic, recorded, and replacing
only files a run of ours wrote; checked before any scan is read, so that a refusal writes
nothing).  The JSON is strict (no ``NaN``, which strict readers refuse): an estimate the scans do
not tell is ``null``, and the table says it was not measured and why.  Errors name the
arguments as a caller's ``names`` map them (``fit-sensor`` maps ``altitude_m`` to ``--altitude``, ...; an argument the
map leaves out is named as itself).
"""

from __future__ import annotations

import json
import os
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zbuf_occlude.errors import InvalidInputError, OutputError
from zbuf_occlude.sensors.checks import namer
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.sensors.fit.airborne import AirborneFit, fit_airborne
from zbuf_occlude.sensors.fit.lidar import BOOTSTRAP, LidarFit, fit_lidar
from zbuf_occlude.sensors.kinds import capabilities
from zbuf_occlude.sensors.fit.return_model import ReturnModelFit, fit_return_model, merge_scans
from zbuf_occlude.sensors.fit.returns import VEGETATION_CLASSES
from zbuf_occlude.sensors.fit.scans import MIN_PLACEMENT_SCANS, crop_placement_json
from zbuf_occlude.sensors.kinds import sensor_from_name, sensor_to_json

__all__ = [
    "LAS_EXTENSIONS",
    "FittedSensor",
    "LasFit",
    "Refine",
    "Refinement",
    "class_statistics",
    "fit_sensor",
    "fit_sensor_to_las",
    "fit_sensor_to_scans",
    "fit_to_scans",
    "las_inputs",
]

#: What ``fit-sensor`` reads as LAS/LAZ scans (the return model's fit) rather than object scans.
LAS_EXTENSIONS = (".las", ".laz")
#: A callable told each step before it runs (the command line prints it).
Say = Callable[[str], object]
#: A caller's word for each argument, for messages (``{"altitude_m": "--altitude"}``); an argument left out is named as itself.
Names = Mapping[str, str]


@dataclass(frozen=True)
class LasFit:
    """The options of a fit to LAS/LAZ scans (:func:`fit_sensor_to_las`); None: their defaults.

    Attributes
    ----------
    altitude_m : float, optional
        Flying height above the ground, metres (default: an airborne sensor's altitude; a spinning LiDAR needs it).
    classes : sequence of int, optional
        The class set of the return statistics (default :data:`~zbuf_occlude.sensors.fit.VEGETATION_CLASSES`).
    bootstrap : int, optional
        Resamples of the bootstrap over pulses (default :data:`~zbuf_occlude.sensors.fit.BOOTSTRAP`).
    divergence_shares : path, optional
        A table of simulated multi-return shares (:func:`~zbuf_occlude.sensors.fit.divergence_curve`): the divergence is
        fitted by inverting it.  Read before the scans.
    """

    altitude_m: float | None = None
    classes: Sequence[int] | None = None
    bootstrap: int | None = None
    divergence_shares: str | os.PathLike | None = None

    def given(self) -> list[str]:
        """The options set, by name."""
        return [name for name in ("altitude_m", "classes", "bootstrap", "divergence_shares") if getattr(self, name) is not None]


@dataclass(frozen=True)
class Refinement:
    """What a step after a spinning LiDAR's fit (:class:`Refine`) changes in what :func:`fit_sensor_to_scans` writes.

    Attributes
    ----------
    sensor : Lidar
        Written in place of the fit's sensor.
    fit_json : dict
        Strict-JSON entries added to the file's ``"fit"`` block.
    markdown : str
        Appended to the ``.md`` table and to :attr:`FittedSensor.table`.
    result : object
        The step's own result (:attr:`FittedSensor.refinement`).
    """

    sensor: Any
    fit_json: dict
    markdown: str
    result: Any = None


@dataclass(frozen=True)
class Refine:
    """A step run after a spinning LiDAR's fit to object scans and before anything is written: it fits more of the sensor
    (``fit-sensor --meshes``: the detection of partial echoes, :func:`~zbuf_occlude.sensors.fit.partial_echo_meshes.partial_echo_refine`).

    Attributes
    ----------
    option : str
        The command's option that asks for it, named where the input cannot take it (LAS/LAZ scans, a sensor that is
        not a spinning LiDAR), before any scan is read.
    run : callable
        ``run(fit, scans) -> Refinement``: ``fit`` the :class:`~zbuf_occlude.sensors.fit.LidarFit`, ``scans`` the
        :class:`~zbuf_occlude.real_scans.records.RealScan` list it was fitted to.
    """

    option: str
    run: Callable[[LidarFit, Sequence[Any]], Refinement]


@dataclass(frozen=True)
class FittedSensor:
    """What :func:`fit_sensor` fitted and wrote.

    Attributes
    ----------
    fit : LidarFit, AirborneFit or ReturnModelFit
    sensor : Lidar or AirborneScanner
        The fitted sensor, as the JSON file reads back.
    json_path, markdown_path : Path
    table : str
        The Markdown table of the estimates (what the command prints).
    refinement : object or None
        What a :class:`Refine` step returned as its result (:attr:`Refinement.result`); None without one.
    """

    fit: LidarFit | AirborneFit | ReturnModelFit
    sensor: Any
    json_path: Path
    markdown_path: Path
    table: str
    refinement: Any = None


def _strict_json(spec: dict) -> str:
    """``spec`` as strict JSON text (numpy scalars as numbers); a NaN left in it is our bug, so it raises ValueError."""
    return json.dumps(spec, indent=1, default=float, allow_nan=False) + "\n"


def _quiet(_: str) -> None:
    """A ``say`` that says nothing."""


def las_inputs(real: str | os.PathLike) -> list[Path] | None:
    """The LAS/LAZ files ``fit-sensor REAL`` fits the return model to: ``REAL`` itself when it is named ``.las``/``.laz``,
    or the ``.las``/``.laz`` files directly inside the folder ``REAL`` (sorted by name); None when it names neither."""
    path = Path(real)
    if path.suffix.lower() in LAS_EXTENSIONS and not path.is_dir():
        return [path]  # missing or damaged: read_las says so, naming it
    if path.is_dir():
        found = sorted(p for p in path.iterdir() if p.suffix.lower() in LAS_EXTENSIONS and not p.is_dir())
        return found or None
    return None


def fit_sensor(real: str | os.PathLike, sensor: str, out: str | os.PathLike, *, seed: int = 0, dataset: str = "auto",
               las: LasFit | None = None, refine: Refine | None = None, say: Say | None = None, names: Names | None = None) -> FittedSensor:  # fmt: skip
    """Fit ``sensor`` to the scans under ``real``: the return model to LAS/LAZ scans (:func:`fit_sensor_to_las`), else the
    sensor to object scans (:func:`fit_sensor_to_scans`); write its JSON file ``out`` and a ``.md`` table beside it.

    Parameters
    ----------
    real : path
        A ``.las``/``.laz`` file or a folder of them (:func:`las_inputs`), or a folder of object scans.
    sensor : str
        The preset or sensor JSON to start from (a spinning LiDAR or an airborne scanner).
    out : path
        The fitted sensor's ``.json`` file.
    seed : int
        Seeds the bootstrap.
    dataset : str
        The object scans' format (:func:`~zbuf_occlude.real_scans.datasets.load_real_scans`; ``"auto"`` detects it).
    las : LasFit, optional
        LAS/LAZ scans only (:func:`fit_sensor_to_las`); None: their defaults.
    refine : Refine, optional
        Object scans and a spinning LiDAR only (:func:`fit_sensor_to_scans`).
    say : callable, optional
        Told each step before it runs.
    names : mapping, optional
        The caller's word for each argument, in messages (module docstring).

    Returns
    -------
    FittedSensor

    Raises
    ------
    InvalidInputError
        A LAS/LAZ option given for object scans or ``refine`` for LAS/LAZ scans (naming the option), and what the fit of
        the input's kind refuses.
    OutputError, UnsafePathError, DatasetBusy
        As :func:`fit_sensor_to_scans` and :func:`fit_sensor_to_las`.
    """
    files = las_inputs(real)
    if files is not None and refine is not None:
        raise InvalidInputError(f"{refine.option}: fits a spinning LiDAR to object scans, and {real} holds LAS/LAZ scans")
    if files is not None:
        return fit_sensor_to_las(files, real, sensor, out, las=las, seed=seed, say=say, names=names)
    if given := ([] if las is None else las.given()):
        n = namer(names)
        raise InvalidInputError(
            f"{', '.join(map(n, given))}: for LAS/LAZ scans, and {real} is neither a .las/.laz file nor a folder of them"
        )
    return _fit_scans(real, sensor, out, seed=seed, dataset=dataset, refine=refine, say=say, names=names)


def _base_sensor(sensor: str, out: str | os.PathLike, refine: Refine | None = None, names: Names | None = None) -> tuple[Any, Path]:
    """The sensor to start from and the ``.json`` file to write, checked before anything is read."""
    out, n = Path(out), namer(names)
    if out.suffix.lower() != ".json":
        raise InvalidInputError(f"{n('out')} {out}: the fitted sensor is written as a .json file")
    if out.is_dir():
        raise OutputError(f"{n('out')} {out} is a folder; name the file to write")
    base = sensor_from_name(sensor)
    if refine is not None and not capabilities(base).spins:
        raise InvalidInputError(f"{refine.option}: fits a spinning LiDAR, and {n('sensor')} {sensor} is a {type(base).__name__}")
    if not capabilities(base).fits:
        raise InvalidInputError(
            f"{n('sensor')} {sensor}: fit-sensor fits a spinning LiDAR or an airborne scanner, not a {type(base).__name__}"
        )
    return base, out


def fit_to_scans(scans: Sequence, base: Any, labels: Sequence[str], *, seed: int = 0,
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
                        say: Say | None = None, names: Names | None = None) -> tuple[LidarFit | AirborneFit, Path, Path]:  # fmt: skip
    """Fit ``sensor`` (a preset name or JSON file: a spinning LiDAR or an airborne scanner) to the object scans under ``real``.

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
    names : mapping, optional
        The caller's word for each argument, in messages (module docstring).

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
    done = _fit_scans(real, sensor, out, seed=seed, dataset=dataset, say=say, names=names)
    return done.fit, done.json_path, done.markdown_path


def _fit_scans(real: str | os.PathLike, sensor: str, out: str | os.PathLike, *, seed: int, dataset: str, refine: Refine | None = None,
               say: Say | None, names: Names | None = None) -> FittedSensor:  # fmt: skip
    """:func:`fit_sensor_to_scans`, with the ``refine`` step of :func:`fit_sensor` where given."""
    base, out = _base_sensor(sensor, out, refine, names)
    md = out.with_suffix(".md")
    names = (out.name, md.name)
    with OwnedFolder(out.parent, files=names, what="the fitted sensor") as folder:
        folder.check_writable(names)  # both before any scan is read: a refusal writes nothing
        return _fit_scans_into(folder, real, base, out, md, seed=seed, dataset=dataset, refine=refine, say=say or _quiet)


def _fit_scans_into(folder: OwnedFolder, real: str | os.PathLike, base: Any, out: Path, md: Path, *, seed: int, dataset: str,
                    refine: Refine | None, say: Say) -> FittedSensor:  # fmt: skip
    """:func:`fit_sensor_to_scans` once the folder of its files is held: fit (and ``refine``), write ``out`` and ``md``."""
    json_name, md_name = out.name, md.name
    say(f"reading the real scans under {real} ...")
    scans = load_real_scans(real, dataset=dataset)
    counts = Counter(s.label for s in scans)
    airborne = capabilities(base).flies
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
        return FittedSensor(fit, fit.sensor, out, md, fit.markdown())
    fit, spec = fit_to_scans(scans, base, [s.label for s in scans], seed=seed)
    sensor, table, more = fit.sensor, fit.markdown(), None
    if refine is not None:  # before anything is written: a refusal writes nothing
        more = refine.run(fit, scans)
        sensor, table = more.sensor, table + more.markdown
        spec = {**sensor_to_json(sensor), "fit": {**spec["fit"], **more.fit_json}}
    folder.write_text(json_name, _strict_json(spec))
    text = f"# {fit.sensor.name}: fitted to {fit.n_scans} scans under {Path(real).name}\n\n{fit.markdown()}"
    text += _crops_markdown(spec["fit"].get("crops"), counts)
    folder.write_text(md_name, text + (more.markdown if more is not None else ""))
    return FittedSensor(fit, sensor, out, md, table, None if more is None else more.result)


def _crops_markdown(crops: dict | None, counts: Counter) -> str:
    """The crops' placement per class (:func:`~zbuf_occlude.sensors.fit.crop_placement_json`) as two tables; "" without."""
    if crops is None:
        return ""
    lo_q, hi_q = crops["quantiles"]
    text = (f"\nPer class, {lo_q:g}th to {hi_q:g}th percentile over its scans: the sensor's horizontal distance to the "
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
    return text


def _read_las_files(files: Sequence[Path], real: str | os.PathLike):
    """The LAS/LAZ ``files`` read (inside the folder ``real`` when it is one) and merged; one line naming a file that has no
    GPS time or no points, whose GPS times do not group its returns into pulses or that holds first returns only
    (:func:`~zbuf_occlude.sensors.fit.las_pulses.check_pulses`), or what :func:`~zbuf_occlude.io.las.read_las` refuses."""
    from zbuf_occlude.defaults import MAX_POINTS
    from zbuf_occlude.io.las import read_las
    from zbuf_occlude.resources import check_memory
    from zbuf_occlude.sensors.fit.las_pulses import check_pulses, check_return_pairs, las_pulses
    from zbuf_occlude.sensors.fit.returns import BYTES_PER_POINT

    within = real if Path(real).is_dir() else None
    scans, total = [], 0
    for f in files:
        las = read_las(f, within=within, max_points=MAX_POINTS - total)
        if not las.has_gps_time:
            raise InvalidInputError(
                f"{f}: point format {las.point_format_id} has no GPS time: the returns of one pulse cannot be told apart"
            )
        if len(las) == 0:
            raise InvalidInputError(f"{f}: holds no points")
        check_memory(len(las) * BYTES_PER_POINT, option=f"the pulses of {f} ({len(las):,} points)", hint="fit a crop")
        pulses = las_pulses(las)
        check_pulses(las, pulses, name=str(f))  # times that group its returns into pulses
        check_return_pairs(las, pulses, name=str(f))  # not first returns alone
        scans.append(las)
        total += len(las)
    return merge_scans(scans, [str(f) for f in files])


def class_statistics(las: Any, statistics: Any) -> dict[str, dict[str, Any]]:
    """Per ASPRS class of a scan: its points, the share of them from pulses of several returns (± its bootstrap's sd) and
    the median intensity of its returns that recorded one (counts; LAS 1.4 R15 §2.6: 0 means none recorded).

    Parameters
    ----------
    las : LasPoints
    statistics : ReturnStatistics
        The scan's return statistics (:func:`~zbuf_occlude.sensors.fit.return_statistics`), whose
        ``multi_return_points_class_<c>`` give the shares.

    Returns
    -------
    dict of str to dict
        Keyed by the class code as text, in increasing order: ``{"points": n, "multi_return_share": p,
        "multi_return_share_std": sd, "intensity_median": m}``, ``None`` where not measured; empty where the scan has no
        classes (every point of class 0, never classified).
    """
    codes, sizes = np.unique(las.classification, return_counts=True)
    if codes.tolist() in ([], [0]):
        return {}
    out = {}
    for c, n in zip(codes.tolist(), sizes.tolist(), strict=True):
        share = statistics.estimates[f"multi_return_points_class_{c}"].to_json()
        intensity = las.intensity[(las.classification == c) & (las.intensity > 0)]
        out[str(c)] = {"points": n, "multi_return_share": share["value"], "multi_return_share_std": share["std"],
                       "intensity_median": float(np.median(intensity)) if len(intensity) else None}  # fmt: skip
    return out


def fit_sensor_to_las(files: Sequence[Path], real: str | os.PathLike, sensor: str, out: str | os.PathLike, *, las: LasFit | None = None,
                      seed: int = 0, say: Say | None = None, names: Names | None = None) -> FittedSensor:  # fmt: skip
    """The return model fitted to LAS/LAZ scans (:func:`~zbuf_occlude.sensors.fit.fit_return_model`) and applied to
    ``sensor``'s beam (:meth:`~zbuf_occlude.sensors.fit.ReturnModelFit.applied`), written as a sensor JSON with the fit under
    ``"fit"`` (``"beam"``: what was fitted and what came from the data sheet; ``"returns"``: the fit; ``"classes"``, where the
    scans have classes: :func:`class_statistics`) and a table beside it.

    Parameters
    ----------
    files : sequence of Path
        The scans (:func:`las_inputs` of ``real``), merged (:func:`~zbuf_occlude.sensors.fit.merge_scans`).
    real : path
        What the user named: the files are read inside it when it is a folder.
    sensor : str
        The preset or sensor JSON to start from: a spinning LiDAR or an airborne scanner.
    out : path
        The ``.json`` file to write; the table goes to the same name with ``.md``.
    las : LasFit, optional
        The fit's options (the altitude, classes, bootstrap and table of shares); None: their defaults.
    seed : int
    say : callable, optional
        Told each step before it runs.
    names : mapping, optional
        The caller's word for each argument, in messages (module docstring).

    Returns
    -------
    FittedSensor

    Raises
    ------
    InvalidInputError
        ``out`` not ``.json``, a sensor of another kind, a spinning LiDAR without ``las.altitude_m``, a bad table of shares (all
        before any scan is read); what the reading (:func:`~zbuf_occlude.io.las.read_las`, pulses that GPS times do not
        tell, first returns only) and the fit refuse, naming the file.
    OutputError, UnsafePathError, DatasetBusy
        As :func:`fit_sensor_to_scans`.
    """
    say, options, n = say or _quiet, las or LasFit(), namer(names)
    base, out = _base_sensor(sensor, out, names=names)
    altitude = options.altitude_m if options.altitude_m is not None else getattr(base, "altitude_m", None)
    if altitude is None:
        raise InvalidInputError(f"{n('sensor')} {sensor} is a spinning LiDAR: give {n('altitude_m')} M, the range to the ground in your "
                                "scans, metres")  # fmt: skip
    bootstrap = BOOTSTRAP if options.bootstrap is None else options.bootstrap
    classes = options.classes
    curve: dict = {}
    if options.divergence_shares is not None:  # read first: a bad table is refused before the scans are
        from zbuf_occlude.io.tables import read_csv_rows
        from zbuf_occlude.sensors.fit.divergence import divergence_curve

        shares_file = options.divergence_shares
        figure, divergences, shares, stds = divergence_curve(read_csv_rows(shares_file), f"{n('divergence_shares')} {shares_file}")
        curve = {"divergence_shares": (divergences, shares, stds), "divergence_share": figure}
    md = out.with_suffix(".md")
    names = (out.name, md.name)
    with OwnedFolder(out.parent, files=names, what="the fitted sensor") as folder:
        folder.check_writable(names)  # before any scan is read: a refusal writes nothing
        say(f"reading {len(files)} LAS/LAZ file{'' if len(files) == 1 else 's'} from {real} ...")
        las = _read_las_files(files, real)
        say(f"read {len(las):,} points; fitting the return model to {base.name} at {altitude:g} m above the ground, "
            f"{bootstrap} bootstrap resamples ...")  # fmt: skip
        fit = fit_return_model(las, altitude_m=altitude, classes=VEGETATION_CLASSES if classes is None else classes,
                               seed=seed, bootstrap=bootstrap, **curve)  # fmt: skip
        fitted, origin = fit.applied(base)
        spec = sensor_to_json(fitted)
        spec["fit"] = {"base": base.name, "files": [f.name for f in files], "beam": origin, "returns": fit.to_json()}
        if classes_seen := class_statistics(las, fit.statistics):
            spec["fit"]["classes"] = classes_seen
        folder.write_text(out.name, _strict_json(spec))
        table = fit.markdown(fitted)
        folder.write_text(md.name, f"# {fitted.name}: the return model fitted to {', '.join(f.name for f in files)}\n\n{table}")
    return FittedSensor(fit, fitted, out, md, table)
