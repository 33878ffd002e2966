"""``experiment sim2real``: train on clouds made from meshes only, score on real scans.

:func:`run_sim2real` runs a :class:`~zbuf_occlude.experiments.sim2real.config.Sim2RealConfig` (every setting,
checked once) in three stages: :func:`prepare_sets` (the real scans, their fixed halves, the meshes the
sensor sees and, with ``fit_sensor``, the sensor and crops fitted to the first half), :func:`run_seed`
(each training set of one seed, trained and scored on the held-out half, the mesh-only sets also on
every scan) and :func:`write_outputs` (the files of :mod:`.outputs`, the summary of :mod:`.report`).
Every setting is written to ``settings.json`` before the first real scan is scored; a rerun with the
same settings resumes from ``runs.jsonl``, one with others is refused.  The protocol and what it can
show: docs/results/sim2real.md; the question is Sryamkin et al. 2023, Table 3B, "Test 3".
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.sim2real.config import FAMILIES_SEED, FITTED_SHAPES, WIDTH_SHAPES, Sim2RealConfig
from zbuf_occlude.experiments.sim2real.data import SetRecipe, build_sets, check_lidar_meshes
from zbuf_occlude.experiments.sim2real.outputs import (
    ALL_SCANS,
    REAL_TO_REAL,
    SIM2REAL_OUTPUTS,
    append_run,
    confusion_name,
    load_runs,
    set_folder,
)
from zbuf_occlude.experiments.sim2real.families import family_heights, family_meshes, fit_families
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes, split_whole_meshes
from zbuf_occlude.sensors.fit.class_placement import CropPlacement, fit_mesh_shapes
from zbuf_occlude.experiments.sim2real.real import real_clouds, real_halves, real_scan_rows
from zbuf_occlude.experiments.table3.common import CHECKPOINT_FILES
from zbuf_occlude.io.json_files import read_json_file
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.learn.data import CloudSet, split_validation
from zbuf_occlude.learn.metrics import classification_report
from zbuf_occlude.mesh.families.fitted import FamiliesFit
from zbuf_occlude.mesh.sizes import SizeRange
from zbuf_occlude.sensors.request import kept_returns

__all__ = ["Sim2RealSets", "run_sim2real", "prepare_sets", "run_seed", "write_outputs"]

log = logging.getLogger(__name__)

#: Seed of the fixed stratified half split of the real scans (:func:`~zbuf_occlude.experiments.sim2real.real.real_halves`), the same for every run.
_REAL_SPLIT_SEED = 20_231
#: How the halves are drawn, as ``settings.json`` records it (a run split otherwise is another run).
_REAL_SPLIT_BY = "content: each class's scans ordered by SHA-256 of the seed and their points, first half A"
#: Keys of ``settings.json`` that say when or how a setting was chosen, not what it is: a rerun
#: does not compare them (the same elevations given as an option or derived from the sensor make the same run).
_NOTES = ("fixed_at", "occluded_elevation_from")
_MISSING = object()


def _fit_sensor(scans: list, base, labels: np.ndarray, names: list[str]):
    """:func:`~zbuf_occlude.experiments.sensor_fit.fit_to_scans` on ``scans`` (``labels`` index
    ``names``), every class's crop placement included.

    Returns the fitted Lidar, the crops' placement per class (``{class: {"distance_m": (lo_m, hi_m),
    "hidden_below_m": (lo_m, hi_m), "across_sight_width_m": (lo_m, hi_m), "across_sight_profile": (K values)}}``: the sensor's
    distances, the objects' hidden bottoms, their widths and their outline over the height),
    ``{class: SizeRange}`` (heights: the top return above the ground) and the sensor's JSON with the fit and the ``crops`` block.
    """
    from zbuf_occlude.experiments.sensor_fit import fit_to_scans
    from zbuf_occlude.sensors.kinds import capabilities

    if not capabilities(base).spins:
        raise InvalidInputError(f"--fit-sensor fits a spinning LiDAR: --sensor must name one, got {base.name!r}")
    try:
        fit, spec = fit_to_scans(scans, base, [names[int(y)] for y in labels], every_class=True)
    except InvalidInputError as exc:
        raise InvalidInputError(f"--fit-sensor: {exc}") from None
    crops = spec["fit"]["crops"]
    keys = ("distance_m", "hidden_below_m", "across_sight_width_m", "across_sight_profile")
    placement = {k: {key: tuple(float(v) for v in crops[key][k]) for key in keys} for k in crops["distance_m"]}
    sizes = {k: SizeRange("height", max(float(lo), 0.05), max(float(hi), 0.05)) for k, (lo, hi) in crops["object_height_m"].items()}
    return fit.sensor, placement, sizes, spec


def _score(pred: np.ndarray, labels: np.ndarray, names: list[str]) -> dict:
    from zbuf_occlude.real_scans.datasets import car_scores_from_labels

    rep = classification_report(labels, pred, names)
    row = {"overall_accuracy": rep["overall_accuracy"], "mean_class_accuracy": rep["mean_class_accuracy"],
           **{f"acc_{n}": rep["per_class"][n] for n in names}, "confusion": rep["confusion"].tolist()}  # fmt: skip
    if "car" in names:
        car = car_scores_from_labels([names[i] for i in labels], [names[i] for i in pred], model_classes=names,
                                     car_classes=("car",))  # fmt: skip
        c = car["per_class"][0] if car["per_class"] else {}
        row.update(car_precision=c.get("precision", float("nan")), car_recall=c.get("recall", float("nan")),
                   car_f1=c.get("f1", float("nan")))  # fmt: skip
    return row


@dataclass(frozen=True)
class Sim2RealSets:
    """What :func:`prepare_sets` finds and fits before any training: every seed's material.

    Attributes
    ----------
    names : list of str
        The classes, sorted (label ``i`` is ``names[i]``).
    meshes : list of MeshEntry
        The meshes the sensor (and the fitted sensor) sees; ``skipped`` those it does not, ``[name, reason]``.
    real_points : (R, n_points, 3) float32; real_labels : (R,) int64; sources : list of str
        The real scans as clouds, their classes and their files.
    half_a, half_b : (about R/2,) int64
        The fixed stratified halves of the real scans, rows of ``real_labels`` in the order
        :func:`~zbuf_occlude.experiments.sim2real.real.real_halves` gives: real→real trains on
        ``half_a``, every row is scored on ``half_b``; with ``fit_sensor``, ``half_a`` is the fit half.
    fitted, fitted_placement, fitted_sizes, fit_json
        With ``fit_sensor``: the fitted Lidar, the crops' placement per class and shape per mesh
        (:class:`~zbuf_occlude.sensors.fit.class_placement.CropPlacement`), the heights
        per class and the sensor's JSON; None otherwise.
    families_fit : FamiliesFit or None
        With ``fit_families``: the families fitted to the first half
        (:func:`~zbuf_occlude.experiments.sim2real.families.fit_families`), whose objects
        ``meshes`` holds (named ``families/CLASS/FAMILY_K``).
    heights : dict of str to SizeRange or None
        With ``family_heights``: the first half's heights of the classes a family writes to
        (:func:`~zbuf_occlude.experiments.sim2real.families.family_heights`), which :meth:`sizes` puts over ``config.sizes``.
    """

    names: list
    meshes: list
    skipped: list
    real_points: np.ndarray
    real_labels: np.ndarray
    sources: list
    half_a: np.ndarray
    half_b: np.ndarray
    fitted: object = None
    fitted_placement: CropPlacement | None = None
    fitted_sizes: dict | None = None
    fit_json: dict | None = None
    families_fit: FamiliesFit | None = None
    heights: dict | None = None

    def sizes(self, base: Mapping[str, SizeRange]) -> dict[str, SizeRange]:
        """The classes' sizes of every mesh-only set: ``base`` (``config.sizes``) with :attr:`heights` over it."""
        return {**base, **(self.heights or {})}


def _kinds(config: Sim2RealConfig) -> tuple[str, ...]:
    """The mesh-only training sets of a run, in report order."""
    return config.training_sets


def _owned(out: str | os.PathLike, config: Sim2RealConfig) -> OwnedFolder:
    """``out`` as a run of ``config`` holds it: :data:`SIM2REAL_OUTPUTS`, in the checkpoint folders of its sets and seeds."""
    seeds = range(int(config.seeds))
    folders = [f"checkpoints/{set_folder(kind)}/seed{seed}" for kind in (*_kinds(config), REAL_TO_REAL) for seed in seeds]
    return OwnedFolder(out, names=SIM2REAL_OUTPUTS, subfolders=["checkpoints", *folders], what="the sim2real run")


def _writes(config: Sim2RealConfig) -> list[str]:
    """The files a run of ``config`` writes: those of :data:`SIM2REAL_FILES` (``settings.json`` is
    compared when it is there) and the checkpoints of each set and seed."""
    kinds = (*_kinds(config), REAL_TO_REAL)
    checkpoints = [f"checkpoints/{set_folder(kind)}/seed{seed}/{name}" for kind in kinds for seed in range(int(config.seeds))
                   for name in CHECKPOINT_FILES]  # fmt: skip
    return ["real_split.csv", "runs.jsonl", "results.csv", "summary.csv", "run.json", "table.md",
            *(["fitted_sensor.json"] if config.fit_sensor else []), *(["fitted_families.json"] if config.fit_families else []),
            *(confusion_name(kind) for kind in kinds), *checkpoints]  # fmt: skip


def run_sim2real(config: Sim2RealConfig, out: str | os.PathLike, *, device: str = "cpu", threads: int | None = None,
                 progress: bool = True, say: Callable[[str], None] | None = None) -> dict:  # fmt: skip
    """Train on each synthetic training set and on real scans, ``config.seeds`` times; score on the real scans.

    Three stages: :func:`prepare_sets` (the scans, meshes and fitted sensor every seed uses; then
    every setting is fixed in ``settings.json``, before any real scan is scored), :func:`run_seed`
    per seed, :func:`write_outputs`.

    Parameters
    ----------
    config : Sim2RealConfig
        What is run (checked when it was made).
    out : path
        Output folder (module docstring); a rerun resumes from ``runs.jsonl`` when the
        settings are unchanged, and is refused otherwise.
    device : {"cpu", "cuda"}; threads : int, optional; progress : bool
        How the training runs (torch device and CPU threads, progress bars); the settings do not
        depend on them, the last bits of the results do (the thread count and the CPU arithmetic,
        :mod:`zbuf_occlude.learn.reproducible`: ``run.json`` records them as ``cpu_arithmetic``).
    say : callable, optional
        Takes one line per stage of :func:`prepare_sets` (what it reads, the fit before and after it);
        default: the module's log at INFO level.

    Returns
    -------
    dict
        The ``run.json`` summary.

    Raises
    ------
    InvalidInputError
        Unusable meshes or scans (with ``fit_sensor``: scans without sensor-frame points, or an
        airborne ``sensor``), or an ``out`` made with other settings.
    UnsafePathError
        A file it writes in ``out`` was not written by a run of ours, or was changed since
        (checked before any work; in a run of an earlier version, once its settings match).
    DatasetBusy
        Another live process holds ``out``.
    """
    t_start = time.perf_counter()
    with _owned(out, config) as folder:
        # every file before any work, unless out holds an earlier version's run (no ledger): its
        # files are taken as ours once its settings match, and checked then, still before training
        settings_path = folder.root / "settings.json"
        if not os.path.lexists(settings_path) or folder.recorded("settings.json") is not None:
            folder.check_writable(_writes(config))
        sets = prepare_sets(config, say=say)
        settings = _fix_settings(config, sets, folder)
        folder.check_writable(_writes(config))
        done = load_runs(folder.root / "runs.jsonl")
        for seed in range(int(config.seeds)):
            run_seed(config, sets, seed, done, folder, device=device, threads=threads, progress=progress)
        return write_outputs(config, sets, settings, done, folder, wall_s=time.perf_counter() - t_start)


def prepare_sets(config: Sim2RealConfig, *, say: Callable[[str], None] | None = None) -> Sim2RealSets:
    """Load the real scans and the meshes, split the scans into their fixed halves and, with
    ``fit_sensor``, fit the sensor and the crops to the first half (:class:`Sim2RealSets`).

    ``say`` takes a line before each slow stage and after the fit (default: the log at INFO level).

    Raises
    ------
    InvalidInputError
        No usable classes, meshes or scans, or a fit that sees no mesh of a class.
    """
    from zbuf_occlude.real_scans.datasets import load_real_scans

    say = say or log.info
    # the lidar set's sensor; the fits take it with one return per pulse, as the real scans they are fitted to were recorded
    lidar, n_points, label_map = config.sensor, config.n_points, dict(config.label_map)
    one_return = kept_returns(config.given_sensor, 1)
    say(f"reading the real scans of {config.real}")
    scans = load_real_scans(config.real, **config.real_options)  # first: cheap, and classes="real" needs them
    wanted = _classes(config.classes, config.mesh_root, scans, label_map)
    say(f"{len(scans)} real scans; loading the meshes of {config.mesh_root} and trying each with {lidar.name}")
    meshes = find_class_meshes(config.mesh_root, up=config.up, up_map=config.up_map, classes=wanted)
    meshes, skipped = check_lidar_meshes(meshes, lidar, config.sizes, n_points, min_returns=int(config.min_returns))
    names = sorted({m.class_name for m in meshes})
    real_pts, real_y, sources = real_clouds(scans, names, label_map, n_points, 0, keep_scale=config.keep_scale)
    kept = real_scan_rows(scans, names, label_map)
    # real→real trains on half_a and every row is scored on half_b; with fit_sensor, half_a is the fit half
    half_a, half_b = real_halves([scans[i].points for i in kept], real_y, _REAL_SPLIT_SEED)
    sets = Sim2RealSets(names, meshes, skipped, real_pts, real_y, sources, half_a, half_b)
    if config.family_heights:  # the first half's heights, before the meshes are tried at them and the families fitted
        sets = _at_family_heights(config, sets, [scans[kept[i]] for i in half_a])
        meshes = sets.meshes
    sizes = sets.sizes(config.sizes)
    if config.fit_families:
        first_half = {c: [scans[kept[i]].points for i in half_a if real_y[i] == k] for k, c in enumerate(names)}
        say(f"fitting the procedural families to the first half's crops: {len(half_a)} scans")
        by_class = {c: [m for m in meshes if m.class_name == c] for c in names}
        family_fit = fit_families(first_half, one_return, sizes, seed=FAMILIES_SEED, meshes=by_class,
                                  fitted_on=f"the first half of {config.real}: {len(half_a)} scans")  # fmt: skip
        added, skipped_families = check_lidar_meshes(family_meshes(family_fit, config.family_count, FAMILIES_SEED), lidar,
                                                     sizes, n_points, min_returns=int(config.min_returns))  # fmt: skip
        kept_alone = sorted(family_fit.record["meshes_kept"])
        say(
            f"added {len(added)} objects of the families {', '.join(sorted(family_fit.counts(config.family_count))) or '(none)'}"
            + (f"; {', '.join(kept_alone)} kept their meshes alone (nearer the real crops than every family)" if kept_alone else "")
        )
        sets = replace(sets, meshes=meshes + added, skipped=sets.skipped + skipped_families, families_fit=family_fit)
        meshes = sets.meshes
    if not config.fit_sensor:
        return sets
    n_returns = sum(len(scans[kept[i]].points) for i in half_a)
    say(f"fitting {lidar.name} to the sensor-frame points of the fit half: {len(half_a)} scans, {n_returns} returns "
        "(the longest stage before training)")  # fmt: skip
    t0 = time.perf_counter()
    fitted, placement, fitted_sizes, fit_json = _fit_sensor([scans[kept[i]] for i in half_a], one_return, real_y[half_a], names)
    say(f"fitted {fitted.name} in {time.perf_counter() - t0:.0f} s; trying each mesh with it")
    meshes, skipped_fitted = check_lidar_meshes(meshes, fitted, sizes, n_points, min_returns=int(config.min_returns))
    placement = CropPlacement.from_keywords(_fitted_placement(config, placement))
    # each mesh's stretch and warp to its class's scans, fitted once for every seed (seed 0: the same every run)
    placement = placement.with_mesh_shapes(fit_mesh_shapes(meshes, fitted, fitted_sizes, placement))
    meshes, skipped_placed = check_lidar_meshes(meshes, fitted, fitted_sizes, n_points, min_returns=int(config.min_returns),
                                                placement=placement)  # fmt: skip
    if sorted({m.class_name for m in meshes}) != names:
        raise InvalidInputError(f"the fitted sensor sees no mesh of classes {sorted(set(names) - {m.class_name for m in meshes})}")
    return replace(sets, meshes=meshes, skipped=sets.skipped + skipped_fitted + skipped_placed, fitted=fitted, fitted_placement=placement,
                   fitted_sizes=fitted_sizes, fit_json=fit_json)  # fmt: skip


def _at_family_heights(config: Sim2RealConfig, sets: Sim2RealSets, first_half: list) -> Sim2RealSets:
    """``sets`` with the first half's heights (``first_half``: its RealScans, in ``sets.half_a``'s order) as the sizes of
    the classes a family writes to (:func:`~zbuf_occlude.experiments.sim2real.families.family_heights`), and the meshes
    the sensor still sees at them.

    Raises
    ------
    InvalidInputError
        The sensor sees no mesh of a class at its height.
    """
    labels = sets.real_labels[sets.half_a]
    heights = family_heights({c: [s.points_sensor_m for s, y in zip(first_half, labels) if y == k] for k, c in enumerate(sets.names)})
    sets = replace(sets, heights=heights)
    meshes, skipped = check_lidar_meshes(sets.meshes, config.sensor, sets.sizes(config.sizes), config.n_points,
                                         min_returns=int(config.min_returns))  # fmt: skip
    lost = sorted(set(sets.names) - {m.class_name for m in meshes})
    if lost:
        raise InvalidInputError(f"{config.sensor.name} sees no mesh of {', '.join(lost)} at the first half's heights")
    return replace(sets, meshes=meshes, skipped=sets.skipped + skipped)


def _fitted_placement(config: Sim2RealConfig, placement: dict[str, dict]) -> dict[str, dict]:
    """The fitted crop keywords per class that ``config.fitted_shape`` uses, and how the widths are met."""
    used = {FITTED_SHAPES[shape] for shape in config.fitted_shape}
    placement = {c: {k: v for k, v in kw.items() if k not in FITTED_SHAPES.values() or k in used} for c, kw in placement.items()}
    width_by = next((WIDTH_SHAPES[shape] for shape in config.fitted_shape if shape in WIDTH_SHAPES), None)
    if width_by is not None:
        placement = {c: {**kw, "across_sight_width_by": width_by} for c, kw in placement.items()}
    return placement


def _fix_settings(config: Sim2RealConfig, sets: Sim2RealSets, out: OwnedFolder | str | os.PathLike) -> dict:
    """Every setting of the run (``config.identity()``, the sensor in full as ``sensor_spec``, the
    :func:`zbuf_occlude.sensors.kinds.sensor_to_json` of a preset or a file alike, and what
    :func:`prepare_sets` found), written to ``out/settings.json`` before any real scan is scored,
    or compared with the settings there; then ``fitted_sensor.json`` and ``real_split.csv``.

    ``out`` is the held folder of the run, or a path held for this call.  When the settings match
    those of a run made before the folder kept its ledger, that run's files are taken as ours
    (:meth:`~zbuf_occlude.io.owned.OwnedFolder.adopt`): it resumes.

    Raises
    ------
    InvalidInputError
        ``out`` holds a run with other settings, or a ``settings.json`` that is not ours.
    """
    if not isinstance(out, OwnedFolder):
        with _owned(out, config) as folder:
            return _fix_settings(config, sets, folder)
    from zbuf_occlude.sensors.kinds import sensor_to_json

    folder = out

    names, real_y = sets.names, sets.real_labels
    settings = {
        **config.identity(), "sensor_spec": sensor_to_json(config.sensor), "occluded_elevation_from": config.occluded_elevation_from,
        "classes": names, "meshes": {c: sum(m.class_name == c for m in sets.meshes) for c in names},
        "mesh_up": {m.name: m.mesh.metadata["zbuf_occlude"].get("up_source") for m in sets.meshes},
        "real_scans": {c: int((real_y == i).sum()) for i, c in enumerate(names)},
        "real_split": {"by": _REAL_SPLIT_BY, "seed": _REAL_SPLIT_SEED,
                       "scored_scans": {c: int((real_y[sets.half_b] == i).sum()) for i, c in enumerate(names)}},
    }  # fmt: skip
    if sets.skipped:  # only then: the settings of runs without a skipped mesh stay as they were (resume)
        settings["meshes_skipped"] = sets.skipped
    if config.fit_families:
        fit = sets.families_fit
        settings["fit_families"] = {**settings["fit_families"], "fitted_on": fit.record["fitted_on"],
                                    "chosen": {c: fit.record["classes"][c]["chosen"] for c in fit.classes},
                                    "meshes_kept": sorted(fit.record["meshes_kept"]),
                                    "objects": fit.counts(config.family_count),
                                    **({"heights_m": {c: [v.lo_m, v.hi_m] for c, v in sorted(sets.heights.items())}}
                                       if sets.heights is not None else {})}  # fmt: skip
    if config.fit_sensor:  # likewise: runs without it keep their settings
        settings["fit_sensor"] = {
            "split_seed": _REAL_SPLIT_SEED, "fitted_sensor": sets.fit_json, "fitted_shape": list(config.fitted_shape),
            "fit_scans": {c: int((real_y[sets.half_a] == i).sum()) for i, c in enumerate(names)},
            "scored_scans": {c: int((real_y[sets.half_b] == i).sum()) for i, c in enumerate(names)},
        }  # fmt: skip
    out = folder.root
    path = out / "settings.json"
    if path.is_file():
        old = read_json_file(path)
        if not isinstance(old, dict):
            raise InvalidInputError(f"{path} is not a settings file of ours; choose another --out")
        old, new = ({k: v for k, v in d.items() if k not in _NOTES} for d in (old, json.loads(json.dumps(settings, default=float))))
        if old != new:
            differ = sorted(k for k in old.keys() | new.keys() if old.get(k, _MISSING) != new.get(k, _MISSING))
            why = "" if "real_split" in old else "; it was made before every set was scored on the same held-out half of the scans"
            raise InvalidInputError(
                f"{out} holds a run with other settings ({path}: {', '.join(differ)} differ{why}); choose another --out"
            )
        if folder.recorded("settings.json") is None:  # a run of ours from before the ledger: its files are ours
            _adopt_earlier_run(folder)
    else:
        # Every setting is fixed here, before any real scan is scored.
        folder.write_text("settings.json", json.dumps({**settings, "fixed_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())},
                                                      indent=1, default=float))  # fmt: skip
    if config.fit_sensor:
        folder.write_text("fitted_sensor.json", json.dumps(sets.fit_json, indent=1, default=float))
    if config.fit_families:
        folder.write_text("fitted_families.json", json.dumps(sets.families_fit.record, indent=1))
    halves = {int(i): "fit" if config.fit_sensor else "train" for i in sets.half_a} | {int(i): "scored" for i in sets.half_b}
    folder.write_csv("real_split.csv", [{"row": i, "source": src, "class": names[real_y[i]], "half": halves[i]}
                                        for i, src in enumerate(sets.sources)])  # fmt: skip
    return settings


def _adopt_earlier_run(folder: OwnedFolder) -> None:
    """Record, as they are, the files of :data:`SIM2REAL_OUTPUTS` in ``folder``: those of a run whose
    ``settings.json`` matched this run's, made before the folder kept a ledger."""
    ours = []
    for below, dirs, files in os.walk(folder.root):  # links are not followed
        dirs[:] = [d for d in dirs if not d.startswith(".")]
        for name in files:
            rel = Path(below, name).relative_to(folder.root).as_posix()
            if any(rx.fullmatch(rel) for rx in folder.names):
                ours.append(rel)
    folder.adopt(sorted(ours))


def run_seed(config: Sim2RealConfig, sets: Sim2RealSets, seed: int, done: dict, folder: OwnedFolder, *, device: str = "cpu",
             threads: int | None = None, progress: bool = True) -> None:  # fmt: skip
    """Train and score every set of ``seed`` not in ``done`` (``{(train_set, seed): row}``), each
    row appended to ``runs.jsonl`` in the run's held folder and to ``done`` as soon as it is scored.

    The mesh-only sets still to train are made at once (``lidar+complete`` reuses two), on a
    whole-mesh split of the seed (or every mesh, validated on the fit half); real→real trains on
    the fit half (10 % of it validates); every row is scored on the other half, and the
    mesh-only sets on every real scan as well (:data:`ALL_SCANS`)."""
    real_val, half_a, half_b = config.validates_on_fit_half, sets.half_a, sets.half_b
    real_pts, real_y = sets.real_points, sets.real_labels
    sc = config.scale_values
    # validated on the fit half's real scans, the sets train on every mesh
    train_meshes, val_meshes = (sets.meshes, []) if real_val else split_whole_meshes(sets.meshes, sc.val_mesh_fraction, seed)
    fit_half = CloudSet(real_pts[half_a], real_y[half_a], np.full(len(half_a), np.nan), half_a)
    held_out, every_scan = (real_pts[half_b], real_y[half_b]), (real_pts, real_y)
    built: dict = {}
    for kind in (*_kinds(config), REAL_TO_REAL):
        if (kind, seed) in done:
            continue
        t0 = time.perf_counter()
        if kind == REAL_TO_REAL:
            tr_rows, val_rows = split_validation(len(half_a), 0.1, seed, labels=real_y[half_a])
            # not scored on every scan: half of them are its training scans
            tr, val, tests = fit_half.subset(tr_rows), fit_half.subset(val_rows), (held_out, None)
        else:
            if not built:  # the sets this seed still trains, at once
                built = _build_seed_sets(config, sets, seed, train_meshes, val_meshes, done, progress=progress)
            tr, val, tests = built["train"][kind], (fit_half if real_val else built["val"][kind]), (held_out, every_scan)
        made = {"val_meshes": sorted(m.name for m in val_meshes) if kind != REAL_TO_REAL else [], "data_s": time.perf_counter() - t0}
        row = _train_and_score(config, sets.names, kind, seed, (tr, val, tests), made, folder, device=device, threads=threads,
                               progress=progress)  # fmt: skip
        append_run(folder, done, row)
        log.info("%s seed %d: mean class accuracy %.3f", kind, seed, row["mean_class_accuracy"])


def _build_seed_sets(config: Sim2RealConfig, sets: Sim2RealSets, seed: int, train_meshes, val_meshes, done: dict, *,
                     progress: bool = False) -> dict:  # fmt: skip
    """``{"train": {kind: CloudSet}, "val": ...}``: the mesh-only sets of ``seed`` not yet in ``done``
    (no ``"val"`` when they validate on the fit half), with ``progress`` per set on stderr."""
    sc, n_points = config.scale_values, config.n_points
    kinds = _kinds(config)
    recipe = SetRecipe(sensor=config.sensor, sizes=sets.sizes(config.sizes), keep_scale=config.keep_scale, min_returns=int(config.min_returns),
                       dense_points=sc.dense_points, resolution=sc.resolution, method=config.method,
                       elevation_deg=config.occluded_elevation_deg, footprint=config.footprint_mode)  # fmt: skip
    options = dict(fitted_sensor=sets.fitted, fitted_placement=sets.fitted_placement, fitted_sizes=sets.fitted_sizes,
                   kinds=[k for k in kinds if (k, seed) not in done], progress=progress)  # fmt: skip
    built = {"train": build_sets(train_meshes, sets.names, sc.per_class, n_points, seed, recipe, **options)}
    if not config.validates_on_fit_half:
        built["val"] = build_sets(val_meshes, sets.names, sc.val_per_class, n_points, seed + 10_000, recipe, **options)
    return built


def _train_and_score(config: Sim2RealConfig, names: list[str], kind: str, seed: int, data: tuple, made: dict, folder: OwnedFolder, *,
                     device: str, threads: int | None, progress: bool) -> dict:  # fmt: skip
    """One training run of ``kind`` and ``seed`` on ``data`` ``(train CloudSet, validation CloudSet, (held_out, every_scan))``,
    each test ``(points, labels)``: its row of ``runs.jsonl``, with ``made`` (``val_meshes``, ``data_s``) before its times,
    the scores on ``held_out`` and those on ``every_scan`` (:data:`ALL_SCANS`; NaN where it is None)."""
    from zbuf_occlude.learn.training import predict, train

    tr, val, (test, every_scan) = data
    cfg = config.train_config(seed, device=device, threads=threads)
    checkpoints = f"checkpoints/{set_folder(kind)}/seed{seed}"
    res = train(tr, len(names), cfg, val_set=val, checkpoint_dir=folder.root / checkpoints,
                checkpoint_writer=lambda name, data: folder.write_bytes(f"{checkpoints}/{name}", data), progress=progress)  # fmt: skip
    test_x, test_y = test
    pred, _ = predict(res.model, test_x, batch_size=cfg.batch_size, device=cfg.device)
    all_scans = {key: float("nan") for key in ALL_SCANS} | {"n_test_all_scans": 0}
    if every_scan is not None:
        every = _score(predict(res.model, every_scan[0], batch_size=cfg.batch_size, device=cfg.device)[0], every_scan[1], names)
        all_scans = {key: every[score] for key, score in ALL_SCANS.items()} | {"n_test_all_scans": len(every_scan[1])}
    return {"train_set": kind, "seed": seed, "model": config.model, "n_train": len(tr), "n_val": len(val),
            "n_test": len(test_y), "best_epoch": res.best_epoch, "epochs_run": len(res.history),
            "best_epoch_by": cfg.select, "best_val_accuracy": res.best_val_accuracy,
            "best_val_mean_class_accuracy": res.best_val_mean_class_accuracy, "best_val_loss": res.best_val_loss,
            "final_train_accuracy": res.history[-1]["train_accuracy"] if res.history else float("nan"),
            **made, "train_s": res.seconds, **_score(pred, test_y, names), **all_scans}  # fmt: skip


def write_outputs(config: Sim2RealConfig, sets: Sim2RealSets, settings: dict, done: dict, folder: OwnedFolder, *, wall_s: float) -> dict:
    """Write ``results.csv``, ``summary.csv``, the ``confusion_<set>.csv`` files (summed over seeds),
    ``run.json`` and ``table.md`` from every run in ``done`` into the run's held folder; return the ``run.json`` summary."""
    from zbuf_occlude.experiments.sim2real.report import summarise, table_md
    from zbuf_occlude.experiments.machine import machine_description
    from zbuf_occlude.learn.reproducible import arithmetic_record

    names = sets.names
    summary_rows = summarise(list(done.values()), names, chosen_on_fit_half=config.validates_on_fit_half)
    folder.write_csv("results.csv", [{k: v for k, v in r.items() if k not in ("confusion", "val_meshes")} for r in done.values()])
    folder.write_csv("summary.csv", summary_rows, fieldnames=list(dict.fromkeys(k for r in summary_rows for k in r)))
    for kind in (*_kinds(config), REAL_TO_REAL):
        cms = [np.asarray(r["confusion"]) for r in done.values() if r["train_set"] == kind]
        if cms:
            folder.write_csv(confusion_name(kind),
                             [{"true": n, **{f"pred_{m}": int(v) for m, v in zip(names, row)}} for n, row in zip(names, sum(cms))])  # fmt: skip
    summary = {"experiment": "sim2real", **settings, "machine": machine_description(),
               "cpu_arithmetic": arithmetic_record(), "n_runs": len(done),
               "summary": summary_rows, "wall_s": {"total": wall_s,
                                                   "data": sum(r["data_s"] for r in done.values()),
                                                   "train": sum(r["train_s"] for r in done.values())}}  # fmt: skip
    folder.write_text("run.json", json.dumps(summary, indent=1, default=float))
    folder.write_text("table.md", table_md(summary_rows, settings))
    return summary


def _classes(classes, mesh_root, scans, label_map: dict[str, str]) -> list[str] | None:
    """The class folders to train on (``run_sim2real``'s ``classes``), None for all."""
    if classes is None:
        return None
    folders = sorted(d.name for d in Path(mesh_root).iterdir() if d.is_dir() and not d.name.startswith("."))
    if classes == "real":
        labels = {label_map.get(s.label, s.label) for s in scans}
        wanted = [c for c in folders if c in labels or c in {x.lower() for x in labels}]
        if len(wanted) < 2:
            raise InvalidInputError(
                f"--classes real: the real scans' labels {sorted(labels)} match {wanted or 'no'} class folders of "
                f"{mesh_root} ({folders}); two are needed: use --label-map REAL=CLASS"
            )
        return wanted
    wanted = list(classes)
    unknown = sorted(set(wanted) - set(folders))
    if unknown:
        raise InvalidInputError(f"--classes: no class folder {unknown} in {mesh_root} (it has {folders})")
    return wanted
