"""``experiment sim2real``: classifiers trained only on clouds made from meshes, tested on real scans.

The question of Sryamkin et al. 2023, Table 3B "Test 3" (do occluded training clouds teach a
classifier to recognise real, partial scans?), asked on real data with the protocol of
:mod:`zbuf_occlude.experiments.sim2real_data`:

* four training sets from the same meshes, the same number of clouds per class and points
  per cloud (``complete``, ``occluded``, ``lidar``, ``lidar+complete``);
* validation (early stopping, best epoch) on clouds of the same kind made from **held-out
  whole meshes**; no real scan is used for training, validation or any setting, and every
  setting is written to ``settings.json`` before the first real scan is scored;
* ``seeds`` repetitions, each redrawing the mesh split, the clouds and the initialisation;
  mean ± standard deviation over seeds and an exact one-sided permutation test of each set
  against ``complete`` (:mod:`zbuf_occlude.learn.stats`);
* context rows: chance (``1/K``) and ``real→real`` (a fixed stratified half of the real scans
  trains, 10 % of that half validates, the other half tests);
* with ``fit_sensor``, a sensor fitted to the real scans (:func:`zbuf_occlude.sensors.fit.fit_lidar`):
  the real scans are split once into the same fixed stratified halves as ``real→real``'s (a seed
  of its own, independent of the run's seeds; the split uses the class indices and the scans'
  order only), the sensor is fitted on the first half (the half ``real→real`` trains on), and
  so are, per class, the crops' sensor distances, the objects' heights (their visible
  heights in the scans), their hidden bottoms and their widths across the line of sight
  (:func:`zbuf_occlude.sensors.fit.crop_placement_json`);
  both are written to ``fitted_sensor.json``; three more training sets are made,
  :data:`~zbuf_occlude.experiments.sim2real_data.FITTED` (the fitted sensor, the ``lidar`` set's
  placements and sizes), :data:`~zbuf_occlude.experiments.sim2real_data.FITTED_PLACED` (the
  fitted sensor, distances, heights and bottoms; with ``fitted_shape``, each mesh also stretched
  to the widths, :func:`zbuf_occlude.sensors.fit.fit_width_scale`, or partly hidden to them,
  :func:`zbuf_occlude.sensors.fit.fit_visible_across_sight`, and/or warped to the class's
  outline over the height, :func:`zbuf_occlude.sensors.fit.fit_width_profile`) and
  :data:`~zbuf_occlude.experiments.sim2real_data.POOLED` (the three LiDAR sets in one), and
  **every row is scored on the other half only**; the fitted sets are also tested against ``lidar``.  ``real_split.csv`` lists each scan's half;
* with ``validate_on="fit-half"`` (needs ``fit_sensor``), the mesh-only sets are validated on the
  real scans of the fit half instead of held-out meshes (best epoch and early stopping), and train
  on every mesh: the fit half is already what the sensor was fitted to, the scored half stays
  unseen, and a small mesh library no longer loses a fifth of its meshes to validation; a row
  :data:`CHOSEN_ON_FIT_HALF` takes, per seed, the set with the best fit-half score (a choice of
  training set made without the scored half) and is tested against complete and real→real.

Every run trains with one recipe (``recipe``, :data:`zbuf_occlude.learn.training.RECIPES`):
``stable`` (class-balanced sampling, best epoch by validation mean class accuracy, warm-up,
gradient clipping) keeps a seed from losing a small class of an imbalanced set (real→real);
``plain`` is the models' own loop.

Outputs in ``out``: ``settings.json``, (``fitted_sensor.json``, ``real_split.csv``), ``runs.jsonl`` (one line per training run, what a
rerun resumes from), ``results.csv`` (one row per run), ``summary.csv`` (mean ± std per
training set), ``confusion_<set>.csv`` (summed over seeds), ``table.md``, ``run.json``.
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.sim2real_data import (
    FITTED_SETS,
    GROUND_ELEVATION_DEG,
    KEEP_SCALE_UNIT_M,
    LIDAR_PLACEMENT,
    MIN_RETURNS,
    TRAINING_SETS,
    build_sets,
    check_lidar_meshes,
    fit_mesh_shapes,
    find_class_meshes,
    real_clouds,
    real_scan_rows,
    split_whole_meshes,
)  # fmt: skip
from zbuf_occlude.io.atomic import write_csv, write_text
from zbuf_occlude.io.json_files import loads_json, read_json_file
from zbuf_occlude.learn.data import CloudSet, split_validation
from zbuf_occlude.learn.metrics import classification_report
from zbuf_occlude.learn.stats import mean_std, permutation_p
from zbuf_occlude.mesh.sizes import CLASS_SIZES_M, SizeRange

__all__ = ["Sim2RealScale", "SIM2REAL_SCALES", "REAL_TO_REAL", "SIM2REAL_RECIPE", "VALIDATION_CHOICES", "FITTED_SHAPES", "CHOSEN_ON_FIT_HALF",
           "run_sim2real", "summarise"]

log = logging.getLogger(__name__)

#: Name of the real→real context row.
REAL_TO_REAL = "real→real"
#: Seed of the fixed stratified half split of the real scans (real→real), the same for every run.
_REAL_SPLIT_SEED = 20_231
#: The training recipe of every run (:data:`zbuf_occlude.learn.training.RECIPES`; module docstring).
SIM2REAL_RECIPE = "stable"
#: What the mesh-only sets validate on: clouds of held-out whole meshes, or the real scans of the fit half.
VALIDATION_CHOICES = ("meshes", "fit-half")
#: What ``fitted_shape`` may give the fitted+placed set's meshes, and the fitted crop keywords each uses
#: (``widen`` is ``widths`` with every stretch below 1 raised to 1; ``occlude`` meets the widths with a
#: side occluder instead of a stretch).
FITTED_SHAPES = {"widths": "across_sight_width_m", "widen": "across_sight_width_m", "occlude": "across_sight_width_m",
                 "outline": "across_sight_profile"}  # fmt: skip
#: The shapes that meet the widths, of which a run takes one, and how each meets them
#: (:data:`~zbuf_occlude.experiments.sim2real_data.WIDTH_BY`).
_WIDTH_SHAPES = {"widths": "stretch", "widen": "widen", "occlude": "occluder"}
#: Name of the row that takes, per seed, the mesh-only set with the best fit-half validation score.
CHOSEN_ON_FIT_HALF = "chosen on fit half"


@dataclass(frozen=True)
class Sim2RealScale:
    """Sizes of a run: points per cloud, training clouds per class, validation clouds per class
    (from held-out meshes), epochs, early-stopping patience, model width, 3DmFV grid, the
    ``occluded`` set's dense points and z-buffer resolution, and the share of meshes held out."""

    points: int
    per_class: int
    val_per_class: int
    epochs: int
    patience: int
    width: dict
    fv_grid: int
    dense_points: int
    resolution: int
    val_mesh_fraction: float


SIM2REAL_SCALES = {
    "quick": Sim2RealScale(points=256, per_class=100, val_per_class=25, epochs=20, patience=6,
                           width={"pointnet": 0.25, "voxnet": 0.5, "3dmfv": 0.25}, fv_grid=5, dense_points=8192,
                           resolution=512, val_mesh_fraction=0.2),
    "paper": Sim2RealScale(points=1024, per_class=1000, val_per_class=200, epochs=100, patience=20,
                           width={"pointnet": 1.0, "voxnet": 1.0, "3dmfv": 1.0}, fv_grid=8, dense_points=100_000,
                           resolution=1024, val_mesh_fraction=0.2),
}  # fmt: skip


def _sensor(name_or_sensor):
    from zbuf_occlude.sensors.airborne import AirborneScanner
    from zbuf_occlude.sensors.lidar import Lidar
    from zbuf_occlude.sensors.presets import sensor_from_name

    if isinstance(name_or_sensor, (Lidar, AirborneScanner)):
        return name_or_sensor
    sensor = sensor_from_name(str(name_or_sensor))
    if not isinstance(sensor, (Lidar, AirborneScanner)):
        raise InvalidInputError(f"--sensor {name_or_sensor}: the lidar training set needs a LiDAR or an airborne scanner")
    return sensor


def _fit_sensor(scans: list, base, labels: np.ndarray, names: list[str]):
    """:func:`~zbuf_occlude.experiments.sensor_fit.fit_to_scans` on ``scans`` (``labels`` index
    ``names``), every class's crop placement included.

    Returns the fitted Lidar, the crops' placement per class (``{class: {"distance_m": (lo_m, hi_m),
    "hidden_below_m": (lo_m, hi_m), "across_sight_width_m": (lo_m, hi_m), "across_sight_profile": (K values)}}``: the sensor's
    distances, the objects' hidden bottoms, their widths and their outline over the height),
    ``{class: SizeRange}`` (heights: the top return above the ground) and the sensor's JSON with the fit and the ``crops`` block.
    """
    from zbuf_occlude.experiments.sensor_fit import fit_to_scans
    from zbuf_occlude.sensors.lidar import Lidar

    if not isinstance(base, Lidar):
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


def _load_runs(path: Path) -> dict:
    done = {}
    if path.is_file():
        for line in path.read_text(encoding="utf-8").splitlines():
            if line.strip():
                r = loads_json(line, what=str(path))
                done[(r["train_set"], r["seed"])] = r
    return done


def _append_run(path: Path, done: dict, row: dict) -> None:
    done[(row["train_set"], row["seed"])] = row
    write_text(path, "".join(json.dumps(r, default=float) + "\n" for r in done.values()))


def _stratified_half(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(_REAL_SPLIT_SEED)
    a = []
    for c in np.unique(labels):
        rows = rng.permutation(np.flatnonzero(labels == c))
        a.extend(rows[: len(rows) // 2].tolist())
    a = np.sort(np.asarray(a, np.int64))
    return a, np.setdiff1d(np.arange(len(labels)), a)


def run_sim2real(
    mesh_root: str | os.PathLike,
    real: str | os.PathLike,
    out: str | os.PathLike,
    *,
    model: str = "pointnet",
    sensor="hdl32e",
    scale: str = "quick",
    points: int | None = None,
    epochs: int | None = None,
    per_class: int | None = None,
    seeds: int = 5,
    keep_scale: bool = False,
    label_map: dict[str, str] | None = None,
    up: str = "auto",
    up_map: dict[str, str] | None = None,
    sizes: dict[str, SizeRange] | None = None,
    real_options: dict | None = None,
    min_returns: int = MIN_RETURNS,
    method: str = "auto",
    device: str = "cpu",
    threads: int | None = None,
    progress: bool = True,
    classes: str | list[str] | None = None,
    occluded_elevation_deg: tuple[float, float] = GROUND_ELEVATION_DEG,
    fit_sensor: bool = False,
    recipe: str = SIM2REAL_RECIPE,
    validate_on: str = "meshes",
    fitted_shape: tuple[str, ...] = (),
    aspect: bool = False,
) -> dict:
    """Train on each synthetic training set and on real scans, ``seeds`` times; score on the real scans.

    Parameters
    ----------
    mesh_root : path
        ``CLASS/.../mesh`` files (any format :func:`zbuf_occlude.load_mesh` reads).
    real : path
        Real scans (:func:`zbuf_occlude.real_scans.datasets.load_real_scans`; ``real_options`` are
        passed to it).
    out : path
        Output folder (module docstring); a rerun resumes from ``runs.jsonl`` when the
        settings are unchanged, and is refused otherwise.
    model : {"pointnet", "voxnet", "3dmfv"}
    sensor : str, Lidar or AirborneScanner
        Scanner of the ``lidar`` set: a preset name (:data:`zbuf_occlude.sensors.LIDAR_PRESETS`,
        :data:`zbuf_occlude.sensors.airborne.AIRBORNE_PRESETS`) or a sensor ``.json`` file.
    scale : {"quick", "paper"}; points, epochs, per_class : int, optional
        Override the scale's points per cloud, epochs and training clouds per class (the
        validation clouds per class follow in the scale's proportion).
    seeds : int
        Repetitions (≥ 2 for a standard deviation; 5 or more for a permutation test able to
        reach p < 0.05).
    keep_scale : bool
        Keep metres (centred, divided by :data:`KEEP_SCALE_UNIT_M`; augmentation off, random yaw
        drawn once per cloud) instead of the paper's normalisation.
    label_map : dict, optional
        Real label → class folder name (labels equal to a class up to case need none).
    up, up_map : mesh up axis and per-file overrides (:func:`find_class_meshes`).
    sizes : dict, optional
        Real sizes per class (default :data:`zbuf_occlude.mesh.sizes.CLASS_SIZES_M`).
    min_returns : int
        LiDAR crops with fewer returns are redrawn (:data:`~zbuf_occlude.experiments.sim2real_data.MIN_RETURNS`).
        Before any set is made, every mesh is tried once with the sensor; one that gives no
        such crop is skipped with a warning naming it (``settings.json``: ``meshes_skipped``).
    classes : "real", list of str, or None
        Class folders to train on: ``"real"``, those the real scans have (after
        ``label_map``; a real scan can then only be called a class it can be); a list, those;
        None, every class folder of ``mesh_root``.
    occluded_elevation_deg : (lo, hi)
        Camera elevations of the ``occluded`` set, degrees in [-90, 90], drawn uniformly
        (default :data:`~zbuf_occlude.experiments.sim2real_data.GROUND_ELEVATION_DEG`; an
        airborne sensor sees from above, e.g. ``(30, 80)``).
    fit_sensor : bool
        Fit ``sensor`` (a spinning LiDAR) to the sensor-frame points of the fixed first half of
        the real scans, and each class's crop distances and heights to the same scans, add the
        :data:`~zbuf_occlude.experiments.sim2real_data.FITTED_SETS`, and score every row on the
        other half only (module docstring).
    recipe : {"stable", "plain"}
        Training recipe (:data:`zbuf_occlude.learn.training.RECIPES`).
    validate_on : {"meshes", "fit-half"}
        What the mesh-only sets validate on (best epoch, early stopping): clouds of the same kind
        from held-out whole meshes, or, with ``fit_sensor``, the real scans of the fit half (the
        sets then train on every mesh; module docstring). real→real is the same either way.
    fitted_shape : tuple of str
        What the fitted+placed set changes in each mesh's shape (needs ``fit_sensor``; keys of
        :data:`FITTED_SHAPES`): ``"widths"``, a horizontal stretch to the class's widths across
        the line of sight, or ``"widen"``, the same stretch where it widens the mesh and none
        where it would narrow it (a narrow real width is often a partial view, not a thinner
        object), or ``"occlude"``, a side occluder that leaves in view as much of the mesh as
        the widths show where its crops are wider (a partial view; nothing hidden where they are
        narrower); ``"outline"``, a warp to its outline over the height, alone or with one of
        the three.  Empty (default): the meshes' own shapes.  Each is fitted per mesh once
        (:func:`fit_mesh_shapes`).
    aspect : bool
        Every run's augmentation also draws random proportions (x, y and z stretched by
        independent factors in [2/3, 3/2], DGCNN's range; :func:`zbuf_occlude.learn.data.augment`),
        real→real's too.  Not with ``keep_scale``, which turns augmentation off.

    Returns
    -------
    dict
        The ``run.json`` summary.

    Raises
    ------
    InvalidInputError
        Bad options (``validate_on="fit-half"`` without ``fit_sensor``, ``aspect`` with
        ``keep_scale``), unusable meshes or scans
        (with ``fit_sensor``: scans without sensor-frame points, or an airborne ``sensor``), or an
        ``out`` made with other settings.
    """
    from zbuf_occlude.experiments.table3 import _machine
    from zbuf_occlude.learn.training import (
        RECIPES,
        TrainConfig,
        predict,
        train,
    )
    from zbuf_occlude.real_scans.datasets import load_real_scans

    if scale not in SIM2REAL_SCALES:
        raise InvalidInputError(f"--scale must be one of {sorted(SIM2REAL_SCALES)}, got {scale!r}")
    if recipe not in RECIPES:
        raise InvalidInputError(f"--recipe must be one of {sorted(RECIPES)}, got {recipe!r}")
    if aspect and keep_scale:
        raise InvalidInputError("--augment aspect needs augmentation, which --keep-scale turns off")
    if int(seeds) < 1:
        raise InvalidInputError(f"--seeds must be >= 1, got {seeds}")
    if validate_on not in VALIDATION_CHOICES:
        raise InvalidInputError(f"--validate-on must be one of {', '.join(VALIDATION_CHOICES)}, got {validate_on!r}")
    if validate_on == "fit-half" and not fit_sensor:
        raise InvalidInputError("--validate-on fit-half needs --fit-sensor (which splits the real scans into the fit half and the scored half)")
    fitted_shape = tuple(fitted_shape)
    if unknown := [v for v in fitted_shape if v not in FITTED_SHAPES]:
        raise InvalidInputError(f"--fitted-shape must name {' and/or '.join(FITTED_SHAPES)}, got {', '.join(map(repr, unknown))}")
    if len(set(fitted_shape) & set(_WIDTH_SHAPES)) > 1:
        raise InvalidInputError(f"--fitted-shape takes one of {', '.join(_WIDTH_SHAPES)}, not both, got {','.join(fitted_shape)!r}")
    if fitted_shape and not fit_sensor:
        raise InvalidInputError("--fitted-shape needs --fit-sensor (it shapes the fitted+placed set's meshes)")
    real_val = validate_on == "fit-half"
    t_start = time.perf_counter()
    sc = SIM2REAL_SCALES[scale]
    if per_class:
        sc = replace(sc, per_class=int(per_class), val_per_class=max(1, round(int(per_class) * sc.val_per_class / sc.per_class)))
    n_points = int(points or sc.points)
    sizes = dict(sizes or CLASS_SIZES_M)
    lidar = _sensor(sensor)
    out = Path(out)
    elevation = _elevation_range(occluded_elevation_deg)
    scans = load_real_scans(real, **(real_options or {}))  # first: cheap, and --classes real needs them
    wanted = _classes(classes, mesh_root, scans, dict(label_map or {}))
    meshes = find_class_meshes(mesh_root, up=up, up_map=up_map, classes=wanted)
    meshes, skipped = check_lidar_meshes(meshes, lidar, sizes, n_points, min_returns=int(min_returns))
    names = sorted({m.class_name for m in meshes})
    real_pts, real_y, sources = real_clouds(scans, names, dict(label_map or {}), n_points, 0, keep_scale=keep_scale)
    half_a, half_b = _stratified_half(real_y)  # real→real trains on half_a; with fit_sensor, half_a is the fit half
    fitted, fitted_placement, fitted_sizes, fit_json = None, None, None, None
    if fit_sensor:
        kept = real_scan_rows(scans, names, dict(label_map or {}))
        fitted, fitted_placement, fitted_sizes, fit_json = _fit_sensor([scans[kept[i]] for i in half_a], lidar, real_y[half_a], names)
        meshes, skipped_fitted = check_lidar_meshes(meshes, fitted, sizes, n_points, min_returns=int(min_returns))
        used = {FITTED_SHAPES[shape] for shape in fitted_shape}
        fitted_placement = {c: {k: v for k, v in kw.items() if k not in FITTED_SHAPES.values() or k in used} for c, kw in fitted_placement.items()}
        width_by = next((_WIDTH_SHAPES[shape] for shape in fitted_shape if shape in _WIDTH_SHAPES), None)
        if width_by is not None:
            fitted_placement = {c: {**kw, "across_sight_width_by": width_by} for c, kw in fitted_placement.items()}
        # each mesh's stretch and warp to its class's scans, fitted once for every seed (seed 0: the same every run)
        fitted_placement = {**fitted_placement, **fit_mesh_shapes(meshes, fitted, fitted_sizes, fitted_placement)}
        meshes, skipped_placed = check_lidar_meshes(meshes, fitted, fitted_sizes, n_points, min_returns=int(min_returns),
                                                    placement=fitted_placement)  # fmt: skip
        skipped += skipped_fitted + skipped_placed
        if sorted({m.class_name for m in meshes}) != names:
            raise InvalidInputError(f"the fitted sensor sees no mesh of classes {sorted(set(names) - {m.class_name for m in meshes})}")
    kinds = (*TRAINING_SETS, *FITTED_SETS) if fit_sensor else TRAINING_SETS

    def config(seed: int) -> TrainConfig:
        return TrainConfig(model=model, epochs=int(epochs or sc.epochs), patience=sc.patience, width=sc.width[model],
                           fv_grid=sc.fv_grid, seed=seed, device=device, threads=threads, augment=not keep_scale,
                           aspect=bool(aspect), **RECIPES[recipe])  # fmt: skip

    settings = {
        "mesh_root": str(mesh_root), "real": str(real), "model": model, "sensor": lidar.name, "scale": scale,
        "scale_values": asdict(sc), "points": n_points, "seeds": int(seeds), "keep_scale": bool(keep_scale),
        "label_map": dict(label_map or {}), "up": up, "up_map": dict(up_map or {}), "classes": names,
        "sizes_m": {k: asdict(v) for k, v in sizes.items()}, "occluded_elevation_deg": list(elevation),
        "lidar_placement": LIDAR_PLACEMENT, "lidar_min_returns": int(min_returns), "keep_scale_unit_m": KEEP_SCALE_UNIT_M,
        "method": method, "train_config": config(0).identity(("seed", "device", "threads")),
        "meshes": {c: sum(m.class_name == c for m in meshes) for c in names},
        "mesh_up": {m.name: m.mesh.metadata["zbuf_occlude"].get("up_source") for m in meshes},
        "real_scans": {c: int((real_y == i).sum()) for i, c in enumerate(names)},
    }  # fmt: skip
    if skipped:  # only then: the settings of runs without a skipped mesh stay as they were (resume)
        settings["meshes_skipped"] = skipped
    if real_val:  # likewise: runs that validate on meshes keep their settings
        settings["validate_on"] = validate_on
    if fit_sensor:  # likewise: runs without it keep their settings
        settings["fit_sensor"] = {
            "split_seed": _REAL_SPLIT_SEED, "fitted_sensor": fit_json, "fitted_shape": list(fitted_shape),
            "fit_scans": {c: int((real_y[half_a] == i).sum()) for i, c in enumerate(names)},
            "scored_scans": {c: int((real_y[half_b] == i).sum()) for i, c in enumerate(names)},
        }  # fmt: skip
    out.mkdir(parents=True, exist_ok=True)
    settings_path = out / "settings.json"
    if settings_path.is_file():
        old = read_json_file(settings_path)
        if not isinstance(old, dict):
            raise InvalidInputError(f"{settings_path} is not a settings file of ours; choose another --out")
        old.pop("fixed_at", None)
        if old != json.loads(json.dumps(settings, default=float)):
            raise InvalidInputError(f"{out} holds a run with other settings ({settings_path}); choose another --out")
    else:
        # Every setting is fixed here, before any real scan is scored.
        write_text(settings_path, json.dumps({**settings, "fixed_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())},
                                             indent=1, default=float))  # fmt: skip
    if fit_sensor:
        write_text(out / "fitted_sensor.json", json.dumps(fit_json, indent=1, default=float))
        halves = {int(i): "fit" for i in half_a} | {int(i): "scored" for i in half_b}
        write_csv(out / "real_split.csv", [{"row": i, "source": src, "class": names[real_y[i]], "half": halves[i]}
                                           for i, src in enumerate(sources)])  # fmt: skip
    runs_path = out / "runs.jsonl"
    done = _load_runs(runs_path)
    # every row is scored on the other half when the sensor was fitted on the first one
    score_x, score_y = (real_pts[half_b], real_y[half_b]) if fit_sensor else (real_pts, real_y)
    common = dict(sensor=lidar, sizes=sizes, keep_scale=keep_scale, dense_points=sc.dense_points, min_returns=int(min_returns),
                  resolution=sc.resolution, method=method, elevation_deg=elevation)  # fmt: skip
    fit_half = CloudSet(real_pts[half_a], real_y[half_a], np.full(len(half_a), np.nan), half_a)
    for seed in range(int(seeds)):
        # validated on the fit half's real scans, the sets train on every mesh
        train_meshes, val_meshes = (meshes, []) if real_val else split_whole_meshes(meshes, sc.val_mesh_fraction, seed)
        sets: dict = {}
        for kind in (*kinds, REAL_TO_REAL):
            if (kind, seed) in done:
                continue
            t0 = time.perf_counter()
            if kind == REAL_TO_REAL:
                tr_rows, val_rows = split_validation(len(half_a), 0.1, seed, labels=real_y[half_a])
                tr, val = fit_half.subset(tr_rows), fit_half.subset(val_rows)
                test_x, test_y = real_pts[half_b], real_y[half_b]
            else:
                if not sets:  # the sets this seed still trains, at once (lidar+complete reuses two)
                    fits = {"fitted_sensor": fitted, "fitted_placement": fitted_placement, "fitted_sizes": fitted_sizes,
                            "kinds": [k for k in kinds if (k, seed) not in done]}  # fmt: skip
                    sets = {"train": build_sets(train_meshes, names, sc.per_class, n_points, seed, **fits, **common)}
                    if not real_val:
                        sets["val"] = build_sets(val_meshes, names, sc.val_per_class, n_points, seed + 10_000, **fits, **common)
                tr, val = sets["train"][kind], (fit_half if real_val else sets["val"][kind])
                test_x, test_y = score_x, score_y
            t_data = time.perf_counter() - t0
            cfg = config(seed)
            res = train(tr, len(names), cfg, val_set=val, checkpoint_dir=out / "checkpoints" / kind.replace("→", "_to_") / f"seed{seed}",
                        progress=progress)  # fmt: skip
            pred, _ = predict(res.model, test_x, batch_size=cfg.batch_size, device=cfg.device)
            row = {"train_set": kind, "seed": seed, "model": model, "n_train": len(tr), "n_val": len(val),
                   "n_test": len(test_y), "best_epoch": res.best_epoch, "epochs_run": len(res.history),
                   "best_val_accuracy": res.best_val_accuracy, "best_val_mean_class_accuracy": res.best_val_mean_class_accuracy,
                   "final_train_accuracy": res.history[-1]["train_accuracy"] if res.history else float("nan"),
                   "val_meshes": sorted(m.name for m in val_meshes) if kind != REAL_TO_REAL else [],
                   "data_s": t_data, "train_s": res.seconds, **_score(pred, test_y, names)}  # fmt: skip
            _append_run(runs_path, done, row)
            log.info("%s seed %d: mean class accuracy %.3f", kind, seed, row["mean_class_accuracy"])
    summary_rows = summarise(list(done.values()), names, chosen_on_fit_half=real_val)
    write_csv(out / "results.csv", [{k: v for k, v in r.items() if k not in ("confusion", "val_meshes")} for r in done.values()])
    write_csv(out / "summary.csv", summary_rows, fieldnames=list(dict.fromkeys(k for r in summary_rows for k in r)))
    for kind in (*kinds, REAL_TO_REAL):
        cms = [np.asarray(r["confusion"]) for r in done.values() if r["train_set"] == kind]
        if cms:
            write_csv(out / f"confusion_{kind.replace('→', '_to_').replace('+', '_')}.csv",
                      [{"true": n, **{f"pred_{m}": int(v) for m, v in zip(names, row)}} for n, row in zip(names, sum(cms))])  # fmt: skip
    from zbuf_occlude.experiments.sim2real_report import table_md

    summary = {"experiment": "sim2real", **settings, "machine": _machine(), "n_runs": len(done),
               "summary": summary_rows, "wall_s": {"total": time.perf_counter() - t_start,
                                                   "data": sum(r["data_s"] for r in done.values()),
                                                   "train": sum(r["train_s"] for r in done.values())}}  # fmt: skip
    write_text(out / "run.json", json.dumps(summary, indent=1, default=float))
    write_text(out / "table.md", table_md(summary_rows, settings))
    return summary


def _elevation_range(value) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InvalidInputError(f"--occluded-elevation must be LO:HI degrees, got {value!r}") from None
    if not (-90.0 <= lo <= hi <= 90.0):
        raise InvalidInputError(f"--occluded-elevation must be LO:HI with -90 <= LO <= HI <= 90 degrees, got {lo:g}:{hi:g}")
    return lo, hi


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


def summarise(runs: list[dict], names: list[str], *, chosen_on_fit_half: bool = False) -> list[dict]:
    """Per training set: mean ± std over seeds of every score, and the one-sided permutation p
    of its mean class accuracy against ``complete``; then the chance row (``1/K``).

    The rows of :data:`~zbuf_occlude.experiments.sim2real_data.FITTED_SETS` also hold their
    difference from ``lidar`` (``diff_vs_lidar``) and both one-sided p-values: ``p_vs_lidar``
    (the fitted set above lidar) and ``p_lidar_above`` (lidar above it).

    With ``chosen_on_fit_half`` (runs validated on the fit half's real scans), a
    :data:`CHOSEN_ON_FIT_HALF` row follows real→real: per seed, the mesh-only run with the best
    ``best_val_mean_class_accuracy`` (ties: the first in the sets' order), its scores as above,
    the chosen sets (``chosen_sets``, in seed order), and its difference from real→real
    (``diff_vs_real_to_real``) with the one-sided p that real→real is above (``p_real_to_real_above``)."""
    keys = ["mean_class_accuracy", "overall_accuracy", "car_precision", "car_recall", "car_f1",
            *[f"acc_{n}" for n in names]]  # fmt: skip
    ref = [r["mean_class_accuracy"] for r in runs if r["train_set"] == "complete"]
    lidar = [r["mean_class_accuracy"] for r in runs if r["train_set"] == "lidar"]
    rows = []
    for kind in (*TRAINING_SETS, *FITTED_SETS, REAL_TO_REAL):
        mine = [r for r in runs if r["train_set"] == kind]
        if not mine:
            continue
        row = {"train_set": kind, "n_seeds": len(mine)}
        for k in keys:
            if k in mine[0]:
                row[f"{k}_mean"], row[f"{k}_std"] = mean_std([r[k] for r in mine])
        mca = [r["mean_class_accuracy"] for r in mine]
        row["p_vs_complete"] = permutation_p(mca, ref) if kind not in ("complete", REAL_TO_REAL) and ref else float("nan")
        row["diff_vs_complete"] = (row["mean_class_accuracy_mean"] - float(np.mean(ref))) if ref else float("nan")
        if kind in FITTED_SETS and lidar:
            row["diff_vs_lidar"] = row["mean_class_accuracy_mean"] - float(np.mean(lidar))
            row["p_vs_lidar"], row["p_lidar_above"] = permutation_p(mca, lidar), permutation_p(lidar, mca)
        rows.append(row)
    if chosen_on_fit_half:
        rows += _chosen_row(runs, keys, ref)
    k = len(names)
    rows.append({"train_set": "chance", "n_seeds": 0, "mean_class_accuracy_mean": 1.0 / k, "mean_class_accuracy_std": 0.0,
                 "overall_accuracy_mean": 1.0 / k, "overall_accuracy_std": 0.0})  # fmt: skip
    return rows


def _chosen_row(runs: list[dict], keys: list[str], ref: list[float]) -> list[dict]:
    """The :data:`CHOSEN_ON_FIT_HALF` row of :func:`summarise` (none when no seed has a mesh-only run)."""
    order = {k: i for i, k in enumerate((*TRAINING_SETS, *FITTED_SETS))}
    chosen = []
    for seed in sorted({r["seed"] for r in runs}):
        mine = [r for r in runs if r["seed"] == seed and r["train_set"] in order]
        if mine:
            chosen.append(max(sorted(mine, key=lambda r: order[r["train_set"]]), key=lambda r: r["best_val_mean_class_accuracy"]))
    if not chosen:
        return []
    row = {"train_set": CHOSEN_ON_FIT_HALF, "n_seeds": len(chosen), "chosen_sets": " ".join(r["train_set"] for r in chosen)}
    for k in keys:
        if k in chosen[0]:
            row[f"{k}_mean"], row[f"{k}_std"] = mean_std([r[k] for r in chosen])
    mca = [r["mean_class_accuracy"] for r in chosen]
    row["p_vs_complete"] = permutation_p(mca, ref) if ref else float("nan")
    row["diff_vs_complete"] = (row["mean_class_accuracy_mean"] - float(np.mean(ref))) if ref else float("nan")
    real = [r["mean_class_accuracy"] for r in runs if r["train_set"] == REAL_TO_REAL]
    if real:
        row["diff_vs_real_to_real"] = row["mean_class_accuracy_mean"] - float(np.mean(real))
        row["p_real_to_real_above"] = permutation_p(real, mca)
    return [row]
