"""The paper's two experiments as functions: Table 3A (accuracy vs elevation) and Table 3B (augmentation).

Sryamkin et al. 2023, §4.4, Table 3.  Data are rendered with the farm
(:func:`zbuf_occlude.run_farm`, compact storage) and read back with
:class:`zbuf_occlude.OccludedDataset`; each experiment writes ``results.csv``,
``table.md`` (our numbers beside the paper's), ``run.json`` (parameters, wall times) and
plots into its output folder.  Both take their settings as one
:class:`~zbuf_occlude.experiments.table3_config.Table3Config`, checked when it is made.

Every file goes through the output layer (:class:`~zbuf_occlude.io.owned.OwnedFolder`): the
output folder is held for the run, each name it writes (:data:`ELEVATION_OUTPUTS`,
:data:`AUGMENTATION_OUTPUTS`, :data:`COMBINED_OUTPUTS`) is checked before any work, and a file
is replaced only if a run of ours wrote it and it is unchanged since.  The data folder (``--data``,
default ``OUT/data``) is held apart while its own files are written (:data:`DATA_OUTPUTS`); the
farm's data set inside it (``dataset/``) is the farm's.
"""

from __future__ import annotations

import json
import logging
import os
import re
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from zbuf_occlude.defaults import DEFAULT_METHOD
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.machine import machine_description
from zbuf_occlude.experiments.paper import MODELNET8, PAPER_3A, PAPER_3B, TEST_ELEVATIONS, TRAIN_ELEVATIONS
from zbuf_occlude.experiments.table3_config import AUGMENTATION_MODEL, ELEVATION_MODEL, SCALES, Scale, Table3Config
from zbuf_occlude.experiments.table3_report import confusion_rows, plot_augmentation, plot_elevation, table_3a, table_3b
from zbuf_occlude.io.json_files import read_json_file
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.io.regular_files import read_regular_file
from zbuf_occlude.io.tables import read_csv_rows
from zbuf_occlude.learn.data import CloudSet, dedupe_meshes, from_meshes, from_occluded, split_validation
from zbuf_occlude.learn.metrics import accuracy_by_elevation, classification_report
from zbuf_occlude.visibility.registry import method_info

__all__ = [
    "SCALES", "Scale", "Table3Config", "plan_meshes", "run_elevation", "run_augmentation", "combine_elevation", "CHECKPOINT_FILES",
    "AUGMENTATION_SETS", "ELEVATION_OUTPUTS", "AUGMENTATION_OUTPUTS", "COMBINED_OUTPUTS", "DATA_OUTPUTS",
]  # fmt: skip

log = logging.getLogger(__name__)

#: The files of one training run, :data:`zbuf_occlude.learn.training.CHECKPOINT_FILES` (named here:
#: importing learn.training imports torch, which importing this module must not).
CHECKPOINT_FILES = ("last.pt", "best.pt", "history.json")
#: Table 3B's training sets: occluded (C1), complete (C2), both (C3); each trains in ``checkpoints/<set>/``.
AUGMENTATION_SETS = ("C1", "C2", "C3")
#: Every file ``experiment elevation`` writes in ``--out`` (:func:`run_elevation`).
ELEVATION_OUTPUTS = (
    "results.csv", "per_class.csv", "confusion.csv", "accuracy_vs_elevation.png", "run.json", "table.md",
    *(f"checkpoints/{name}" for name in CHECKPOINT_FILES),
)  # fmt: skip
#: Every file ``experiment augmentation`` writes in ``--out`` (:func:`run_augmentation`; ``test3.csv``
#: only with real scans).
AUGMENTATION_OUTPUTS = (
    "results.csv", "test3.csv", "augmentation.png", "run.json", "table.md",
    *(f"checkpoints/{s}/{name}" for s in AUGMENTATION_SETS for name in CHECKPOINT_FILES),
)  # fmt: skip
#: Every file :func:`combine_elevation` writes in its ``out``.
COMBINED_OUTPUTS = ("results.csv", "table.md", "accuracy_vs_elevation.png")
#: The files the experiments write in their data folder, beside the farm's data set ``dataset/``:
#: the farm's list of meshes and the cache of Fig. 12's curve.
DATA_OUTPUTS = ("meshes.txt", "visible_area.csv")


def _owned(folder: str | os.PathLike, names: Sequence[str], what: str, *, option: str = "--out") -> OwnedFolder:
    """``folder`` held for a run that writes exactly the files ``names`` (and the folders they lie in)."""
    subfolders = sorted({str(Path(n).parent) for n in names} - {"."})
    return OwnedFolder(folder, files=names, subfolders=subfolders, what=what, option=option)


def _write_mesh_list(data_dir: Path, text: str) -> Path:
    """Write the farm's list of meshes, ``data_dir/meshes.txt``, through the data folder's layer.

    A list an earlier version wrote (no ledger then) is taken as ours when it holds exactly this
    run's meshes, so that a data folder shared across models is reused as before.
    """
    data = text.encode("utf-8")
    with _owned(data_dir, DATA_OUTPUTS, "the experiment's data folder", option="--data") as folder:
        path = folder.root / "meshes.txt"
        if (folder.recorded("meshes.txt") is None and path.is_file() and not path.is_symlink() and path.stat().st_size == len(data)
                and read_regular_file(path, max_bytes=len(data), within=folder.root) == data):  # fmt: skip
            folder.adopt(["meshes.txt"])
        return folder.write_text("meshes.txt", text)


def _number_rows(path: Path, within: Path, *, text: Sequence[str] = ()) -> list[dict]:
    """The rows of a CSV table of ours (:func:`~zbuf_occlude.io.tables.read_csv_rows`, held inside
    ``within``), every column but those in ``text`` a float.

    Raises
    ------
    InvalidInputError
        The file cannot be read (a FIFO, past the cap, not CSV), or holds a value that is not a
        number; the message names it.
    UnsafePathError
        It leads outside ``within``.
    """
    rows = read_csv_rows(path, within=within)
    try:
        return [{k: (v if k in text else float(v)) for k, v in r.items()} for r in rows]
    except (TypeError, ValueError) as exc:  # a short or long row, a word where a number belongs
        raise InvalidInputError(f"{path}: not a table of ours, a value is not a number ({exc})") from None


def _natural(text: str) -> list:
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", text)]


def plan_meshes(root: str | os.PathLike, classes: Sequence[str] | None = None) -> list[dict]:
    """Meshes under ``root`` (ModelNet layout), content duplicates dropped, sorted.

    Returns
    -------
    list of dict
        ``path`` (absolute), ``class_name``, ``split`` (ModelNet's folder), ``name``.

    Raises
    ------
    InvalidInputError
        Nothing found, or an unknown class.
    """
    from zbuf_occlude.mesh.inputs import discover_objects

    objs = discover_objects(root, classes=list(classes) if classes else None)
    by_path = {Path(o.source).resolve(): o for o in objs}
    kept, dropped = dedupe_meshes(sorted(by_path, key=lambda p: _natural(str(p))))
    for dup, orig in dropped:
        log.warning("dropping %s: same mesh as %s", dup, orig)
    rows = [{"path": str(p), "class_name": by_path[p].class_name, "split": by_path[p].split, "name": by_path[p].name}
            for p in kept]  # fmt: skip
    rows.sort(key=lambda r: _natural(r["name"]))
    return rows


def _render(meshes: list[dict], data_dir: Path, views: str, config: Table3Config, progress: bool) -> Path:
    """Farm the meshes (compact storage) into ``data_dir`` (resumes; reuses a finished run)."""
    from zbuf_occlude.farm import FarmParams, RunOptions, run_farm

    list_file = _write_mesh_list(data_dir, "".join(f"{m['path']} {m['class_name']} {m['split']}\n" for m in meshes))
    scale = config.scale_values
    params = FarmParams(views=views, samples_per_view=scale.samples_per_view, n_points=config.n_points,
                        dense_points=scale.dense_points, resolution=scale.resolution, seed=config.seed,
                        storage="compact", method=config.method)  # fmt: skip
    run_farm(list_file, data_dir / "dataset", params, RunOptions(progress=progress))
    return data_dir / "dataset"


# -- Table 3A ------------------------------------------------------------------------------
def _visible_area_curve(meshes: list[dict], data_dir: Path, scale: Scale, method: str, progress: bool) -> list[dict]:
    """Fig. 12: projected visible areas per elevation, averaged over the meshes (cached in data_dir)."""
    from zbuf_occlude.experiments.elevation_profile import profile_table
    from zbuf_occlude.io.progress import progress as progress_bar
    from zbuf_occlude.mesh.load import load_mesh

    cache = data_dir / "visible_area.csv"
    if os.path.lexists(cache):  # a FIFO or a link out of the data folder is refused, not skipped
        return _number_rows(cache, data_dir)
    # Fig. 12's areas need a sharp visible set: an occupancy-grid method (the paper's HSR for
    # the data) would blur them, so those fall back to the default method.
    info = method_info(method)
    profile_method = DEFAULT_METHOD if (info.takes_grid or info.grid_of) else method
    per_mesh = []
    for m in progress_bar(meshes, desc="table3 visible area", unit="mesh", enabled=progress):
        rows = profile_table(load_mesh(m["path"]), method=profile_method,
                             points=scale.profile_points, azimuths=scale.profile_azimuths,
                             resolution=scale.resolution, progress=False)  # fmt: skip
        per_mesh.append(rows)
    keys = [k for k in per_mesh[0][0] if k.startswith("area_") and not k.endswith("_std")]
    out = []
    for i, row in enumerate(per_mesh[0]):
        r = {"elevation_deg": row["elevation_deg"]}
        for k in keys:
            r[k] = float(np.mean([pm[i][k] for pm in per_mesh]))
        out.append(r)
    with _owned(data_dir, DATA_OUTPUTS, "the experiment's data folder", option="--data") as folder:
        folder.write_csv(cache.name, out)
    return out


def run_elevation(
    root: str | os.PathLike,
    out: str | os.PathLike,
    config: Table3Config | None = None,
    *,
    data_dir: str | os.PathLike | None = None,
    profile: bool = True,
    progress: bool = True,
) -> dict:
    """Table 3A: train on elevations ±90, ±70, ±50, ±20 of paper100, test on ±80, ±60, ±40, ±30, ±10, 0.

    The same objects are seen in training and test, from unseen viewpoints (the paper's protocol).

    Parameters
    ----------
    root : path
        Mesh tree (ModelNet layout); content duplicates are dropped.
    out : path
        Output folder: ``results.csv`` (accuracy per test elevation, ours and the paper's),
        ``table.md``, ``per_class.csv``, ``confusion.csv``, ``run.json``, ``accuracy_vs_elevation.png``,
        ``checkpoints/`` (:data:`ELEVATION_OUTPUTS`, each checked before any work).
    config : Table3Config, optional
        Model, scale, epochs, points per cloud, HSR method, classes, seed, device and threads
        (:class:`~zbuf_occlude.experiments.table3_config.Table3Config`, checked when made);
        default: its defaults with the model :data:`~zbuf_occlude.experiments.table3_config.ELEVATION_MODEL`.
    data_dir : path, optional
        Where the farm's data set goes (default ``out/data``); share it between models.
    profile : bool
        Compute Fig. 12's visible-area curve for the plot's second axis.

    Returns
    -------
    dict
        The run summary written to ``run.json``.

    Raises
    ------
    UnsafePathError
        A file of :data:`ELEVATION_OUTPUTS` in ``out`` was not written by a run of ours, or was
        changed since (checked before any work; nothing is written).
    DatasetBusy
        Another live process holds ``out``.
    """
    t_start = time.perf_counter()
    config = config if config is not None else Table3Config(ELEVATION_MODEL)
    with _owned(out, ELEVATION_OUTPUTS, "the elevation run (Table 3A)") as folder:
        folder.check_writable(ELEVATION_OUTPUTS)  # every file before any work: a refusal writes nothing
        return _elevation_into(folder, root, t_start, config, data_dir=data_dir, profile=profile, progress=progress)


def _elevation_into(folder: OwnedFolder, root: str | os.PathLike, t_start: float, config: Table3Config, *,
                    data_dir: str | os.PathLike | None, profile: bool, progress: bool) -> dict:  # fmt: skip
    """:func:`run_elevation` once ``--out`` is held."""
    from zbuf_occlude.learn.training import predict, train

    sc, n_points, model, seed = config.scale_values, config.n_points, config.model, config.seed
    out = folder.root
    data_dir = Path(data_dir) if data_dir else out / "data"
    meshes = plan_meshes(root, config.classes)
    t0 = time.perf_counter()
    ds_path = _render(meshes, data_dir, "paper100", config, progress)
    t_render = time.perf_counter() - t0
    from zbuf_occlude.dataset.reader import OccludedDataset

    train_ds = OccludedDataset(ds_path, elevation_deg=TRAIN_ELEVATIONS)
    test_ds = OccludedDataset(ds_path, elevation_deg=TEST_ELEVATIONS)
    names = train_ds.shape_names
    full = from_occluded(train_ds, n_points, seed)
    test = from_occluded(test_ds, n_points, seed + 1)
    tr_rows, val_rows = split_validation(len(full), sc.val_fraction, seed, labels=full.labels)
    train_config = config.train_config()
    t0 = time.perf_counter()
    result = train(full.subset(tr_rows), len(names), train_config, val_set=full.subset(val_rows), checkpoint_dir=out / "checkpoints",
                   checkpoint_writer=lambda name, data: folder.write_bytes(f"checkpoints/{name}", data), progress=progress)  # fmt: skip
    t_train = time.perf_counter() - t0
    t0 = time.perf_counter()
    pred, _ = predict(result.model, test.points, batch_size=train_config.batch_size, device=train_config.device)
    t_test = time.perf_counter() - t0
    report = classification_report(test.labels, pred, names)
    by_el = accuracy_by_elevation(test.labels, pred, test.elevation_deg)
    paper = dict(zip(TEST_ELEVATIONS, PAPER_3A[model]))
    rows = [{"model": model, "elevation_deg": r["elevation_deg"], "n_test": r["n"], "accuracy": r["accuracy"],
             "paper_accuracy": paper.get(r["elevation_deg"], float("nan")) / 100} for r in by_el]  # fmt: skip
    folder.write_csv("results.csv", rows)
    folder.write_csv("per_class.csv", [{"class": k, "accuracy": v} for k, v in report["per_class"].items()])
    folder.write_csv("confusion.csv", confusion_rows(report["confusion"], names))
    curve = _visible_area_curve(meshes, data_dir, sc, config.method, progress) if profile else None
    folder.write_bytes("accuracy_vs_elevation.png", plot_elevation({model: rows}, curve))
    summary = {
        "experiment": "elevation (Table 3A)", "model": model, "scale": config.scale, "root": str(root),
        "data_dir": str(data_dir),
        "meshes": len(meshes), "classes": names, "points": n_points, "method": config.method,
        "n_train": len(tr_rows), "n_val": len(val_rows), "n_test": len(test),
        "overall_accuracy": report["overall_accuracy"], "mean_class_accuracy": report["mean_class_accuracy"],
        "best_epoch": result.best_epoch, "epochs_run": len(result.history), "config": train_config.to_dict(),
        "history": result.history, "machine": machine_description(),
        "wall_s": {"render": t_render, "train": t_train, "test": t_test, "total": time.perf_counter() - t_start},
        "train_samples_per_s": result.samples_per_second,
    }  # fmt: skip
    folder.write_text("run.json", json.dumps(summary, indent=1, default=float))
    folder.write_text("table.md", table_3a({model: rows}, {model: summary}))
    return summary


# -- Table 3B ------------------------------------------------------------------------------
def _split_3b(meshes: list[dict]) -> list[dict]:
    """ModelNet's own split; a class without a test mesh gives its last train mesh to test
    (if it has two or more), a class with a single mesh is dropped (nothing to test on)."""
    out = []
    by_class: dict[str, list[dict]] = {}
    for m in meshes:
        by_class.setdefault(m["class_name"], []).append(m)
    for cls, ms in sorted(by_class.items()):
        if len(ms) < 2:
            log.warning("augmentation: class %s has one mesh; dropped (it cannot be both trained and tested)", cls)
            continue
        ms = [dict(m) for m in ms]
        if not any(m["split"] == "test" for m in ms):
            ms[-1]["split"] = "test"
        if not any(m["split"] == "train" for m in ms):
            ms[0]["split"] = "train"
        out.extend(ms)
    return out


def run_augmentation(
    root: str | os.PathLike,
    out: str | os.PathLike,
    config: Table3Config | None = None,
    *,
    data_dir: str | os.PathLike | None = None,
    real_scans: str | os.PathLike | None = None,
    label_map: dict[str, str] | None = None,
    progress: bool = True,
) -> dict:
    """Table 3B: training sets C1 (occluded), C2 (complete), C3 (both) × Test 1 (complete test
    meshes), Test 2 (occluded clouds of the test meshes) and, with ``real_scans``, Test 3.

    Poses: grid25 (elevations ±80, ±40, 0 × azimuths 0, 72, 144, 216, 288).  C2 and Test 1
    draw ``complete_per_mesh`` uniform clouds per mesh (``quick``: 25, as many as C1 has
    occluded clouds per mesh; ``paper``: 1).  Validation: a stratified ``val_fraction`` of
    each training set's samples.  ``classes`` defaults to ModelNet8 when all eight classes
    are under ``root``, else every class with two or more meshes.

    Test 3 (``real_scans``): each scan (:func:`zbuf_occlude.real_scans.datasets.load_real_scans`)
    is resampled to ``points`` and classified; labels are renamed with ``label_map``
    (default: SUO car types → ``car``); :func:`zbuf_occlude.real_scans.datasets.car_scores`
    gives per-class accuracy, TP/FP/F1 and the mean F1 when the model has a ``car`` class,
    otherwise only the distribution of predictions is reported.

    Writes :data:`AUGMENTATION_OUTPUTS` in ``out`` (``test3.csv`` only with ``real_scans``), each
    checked before any work.

    Parameters
    ----------
    root : path
        Mesh tree (ModelNet layout); content duplicates are dropped.
    out : path
        Output folder.
    config : Table3Config, optional
        Model, scale, epochs, points per cloud, HSR method, classes, seed, device and threads
        (:class:`~zbuf_occlude.experiments.table3_config.Table3Config`, checked when made);
        default: its defaults with the model :data:`~zbuf_occlude.experiments.table3_config.AUGMENTATION_MODEL`.
    data_dir : path, optional
        Where the farm's data set goes (default ``out/data``).
    real_scans : path, optional
        Test 3's scans: an SUO ``objects/`` folder or a LiDARNet v2 folder.
    label_map : dict, optional
        Real label → model class (default: SUO car types → ``car``).
    progress : bool
        Progress bars.

    Returns
    -------
    dict
        The run summary written to ``run.json``.

    Raises
    ------
    InvalidInputError
        Fewer than two classes with two meshes each.
    UnsafePathError
        A file it writes in ``out`` was not written by a run of ours, or was changed since
        (checked before any work; nothing is written).
    DatasetBusy
        Another live process holds ``out``.
    """
    t_start = time.perf_counter()
    config = config if config is not None else Table3Config(AUGMENTATION_MODEL)
    writes = [n for n in AUGMENTATION_OUTPUTS if real_scans or n != "test3.csv"]
    with _owned(out, AUGMENTATION_OUTPUTS, "the augmentation run (Table 3B)") as folder:
        folder.check_writable(writes)  # every file before any work: a refusal writes nothing
        return _augmentation_into(folder, root, t_start, config, data_dir=data_dir, real_scans=real_scans, label_map=label_map,
                                  progress=progress)  # fmt: skip


def _augmentation_into(folder: OwnedFolder, root: str | os.PathLike, t_start: float, config: Table3Config, *,
                       data_dir: str | os.PathLike | None, real_scans: str | os.PathLike | None, label_map: dict[str, str] | None,
                       progress: bool) -> dict:  # fmt: skip
    """:func:`run_augmentation` once ``--out`` is held."""
    from zbuf_occlude.dataset.reader import OccludedDataset
    from zbuf_occlude.learn.training import predict, train

    sc, n_points, model, seed = config.scale_values, config.n_points, config.model, config.seed
    out = folder.root
    data_dir = Path(data_dir) if data_dir else out / "data"
    meshes = plan_meshes(root, config.classes)
    if config.classes is None and set(MODELNET8) <= {m["class_name"] for m in meshes}:
        meshes = [m for m in meshes if m["class_name"] in MODELNET8]
    meshes = _split_3b(meshes)
    if len({m["class_name"] for m in meshes}) < 2:
        raise InvalidInputError(f"augmentation needs two classes with two meshes each under {root}")
    t0 = time.perf_counter()
    ds_path = _render(meshes, data_dir, "grid25", config, progress)
    t_render = time.perf_counter() - t0
    tr_ds, te_ds = OccludedDataset(ds_path, split="train"), OccludedDataset(ds_path, split="test")
    names = tr_ds.shape_names
    label = {c: i for i, c in enumerate(names)}
    c1 = from_occluded(tr_ds, n_points, seed)
    test2 = from_occluded(te_ds, n_points, seed + 1)
    train_meshes = [m for m in meshes if m["split"] == "train"]
    test_meshes = [m for m in meshes if m["split"] == "test"]
    c2 = from_meshes([m["path"] for m in train_meshes], [label[m["class_name"]] for m in train_meshes], n_points,
                     per_mesh=sc.complete_per_mesh, seed=seed)  # fmt: skip
    test1 = from_meshes([m["path"] for m in test_meshes], [label[m["class_name"]] for m in test_meshes], n_points,
                        per_mesh=max(1, sc.complete_per_mesh // 2), seed=seed + 1)  # fmt: skip
    scans = _load_scans(real_scans, n_points, seed) if real_scans else None
    sets = dict(zip(AUGMENTATION_SETS, (c1, c2, CloudSet.concat([c1, c2]))))
    rows, test3, timings, summaries = [], [], {}, {}
    train_config = config.train_config()
    for name, data in sets.items():
        tr_rows, val_rows = split_validation(len(data), sc.val_fraction, seed, labels=data.labels)
        t0 = time.perf_counter()
        ckpt = f"checkpoints/{name}"
        res = train(data.subset(tr_rows), len(names), train_config, val_set=data.subset(val_rows), checkpoint_dir=out / ckpt,
                    checkpoint_writer=lambda file, blob, ckpt=ckpt: folder.write_bytes(f"{ckpt}/{file}", blob), progress=progress)  # fmt: skip
        timings[f"train_{name}"] = time.perf_counter() - t0
        summaries[name] = {"best_epoch": res.best_epoch, "epochs_run": len(res.history), "n_train": len(tr_rows),
                           "n_val": len(val_rows), "history": res.history}  # fmt: skip
        for test_name, test in (("Test1", test1), ("Test2", test2)):
            pred, _ = predict(res.model, test.points, batch_size=train_config.batch_size, device=train_config.device)
            rep = classification_report(test.labels, pred, names)
            paper = PAPER_3B.get(model, {}).get(name, (float("nan"),) * 2)[0 if test_name == "Test1" else 1]
            rows.append({"model": model, "train_set": name, "test": test_name, "n_test": rep["n"],
                         "overall_accuracy": rep["overall_accuracy"], "mean_class_accuracy": rep["mean_class_accuracy"],
                         "paper_accuracy": paper / 100})  # fmt: skip
        if scans is not None:
            test3.extend(_test3(res.model, scans, names, name, train_config, label_map))
    folder.write_csv("results.csv", rows)
    if test3:
        folder.write_csv("test3.csv", test3)
    folder.write_bytes("augmentation.png", plot_augmentation(rows, model))
    summary = {
        "experiment": "augmentation (Table 3B)", "model": model, "scale": config.scale, "root": str(root),
        "classes": names, "train_meshes": [m["name"] for m in train_meshes],
        "test_meshes": [m["name"] for m in test_meshes], "points": n_points, "method": config.method,
        "n": {"C1": len(c1), "C2": len(c2), "Test1": len(test1), "Test2": len(test2),
              "Test3": len(scans[0]) if scans else 0},
        "training": summaries, "config": train_config.to_dict(),
        "machine": machine_description(), "real_scans": str(real_scans) if real_scans else None,
        "wall_s": {"render": t_render, **timings, "total": time.perf_counter() - t_start},
    }  # fmt: skip
    folder.write_text("run.json", json.dumps(summary, indent=1, default=float))
    folder.write_text("table.md", table_3b(rows, test3, model))
    return summary


def _load_scans(path, n_points: int, seed: int):
    from zbuf_occlude.learn.data import normalize_batch, resample
    from zbuf_occlude.real_scans.datasets import load_real_scans

    scans = load_real_scans(path)
    rng = np.random.default_rng([seed, 3])
    clouds = np.stack([resample(s.points[None], n_points, rng)[0] for s in scans])
    return normalize_batch(clouds), [s.label for s in scans]


def _test3(model, scans, names, train_set: str, config, label_map) -> list[dict]:
    from zbuf_occlude.learn.training import predict
    from zbuf_occlude.real_scans.datasets import SUO_CAR_CLASSES, car_scores_from_labels

    points, labels = scans
    pred, _ = predict(model, points, batch_size=config.batch_size, device=config.device)
    predicted = [names[i] for i in pred]
    lm = dict(label_map or {})
    rows = []
    if "car" in names:
        res = car_scores_from_labels(labels, predicted, model_classes=names, label_map=lm,
                                     car_classes=tuple(SUO_CAR_CLASSES) + ("car",))  # fmt: skip
        for r in res["per_class"]:
            rows.append({"train_set": train_set, **r, "mean_f1": res["mean_f1"]})
    else:  # no car class in the model: report what each real class is taken for
        real = [lm.get(t, t) for t in labels]
        for cls in sorted(set(real)):
            sel = [p for t, p in zip(real, predicted) if t == cls]
            counts = {n: sel.count(n) for n in names}
            top = max(counts, key=counts.get)
            rows.append({"train_set": train_set, "class": cls, "n": len(sel), "most_predicted": top,
                         "share": counts[top] / len(sel), **{f"pred_{n}": c for n, c in counts.items()}})  # fmt: skip
    return rows


def combine_elevation(run_dirs: Sequence[str | os.PathLike], out: str | os.PathLike) -> Path:
    """Join the ``experiment elevation`` runs of several models: ``results.csv``, ``table.md`` and
    ``accuracy_vs_elevation.png`` (all models, Fig. 12's curve from the first run's data folder) in ``out``
    (:data:`COMBINED_OUTPUTS`, each checked before any run is read).

    Raises
    ------
    UnsafePathError
        A file it writes in ``out`` was not written by a run of ours, or was changed since; or a
        run's ``run.json``, ``results.csv`` or ``data/visible_area.csv`` is a link that leads out
        of the folder it was named from.
    InvalidInputError
        A run's file is missing, not a regular file (a FIFO), larger than its cap, or not a file
        of ours (a ``run.json`` without a model, a value that is not a number); the message names it.
    DatasetBusy
        Another live process holds ``out``.
    """
    with _owned(out, COMBINED_OUTPUTS, "the combined elevation table") as folder:
        folder.check_writable(COMBINED_OUTPUTS)  # every file before any run is read: a refusal writes nothing
        return _combine_into(folder, run_dirs)


def _combine_into(folder: OwnedFolder, run_dirs: Sequence[str | os.PathLike]) -> Path:
    """:func:`combine_elevation` once its ``out`` is held; each run's files are read inside its folder."""
    rows_by_model, summaries, all_rows, curve = {}, {}, [], None
    for d in map(Path, run_dirs):
        summary = read_json_file(d / "run.json", within=d)
        if not isinstance(summary, dict) or not isinstance(summary.get("model"), str):
            raise InvalidInputError(f"{d / 'run.json'} is not the run.json of an elevation run (it names no model)")
        rows = _number_rows(d / "results.csv", d, text=("model",))
        rows_by_model[summary["model"]] = rows
        summaries[summary["model"]] = summary
        all_rows += rows
        data_dirs = [d / "data"]
        if isinstance(summary.get("data_dir"), str) and summary["data_dir"]:
            data_dirs.append(Path(summary["data_dir"]))
        for data_dir in data_dirs:
            if curve is None and os.path.lexists(data_dir / "visible_area.csv"):
                curve = _number_rows(data_dir / "visible_area.csv", data_dir)
    folder.write_csv("results.csv", all_rows)
    folder.write_text("table.md", table_3a(rows_by_model, summaries))
    folder.write_bytes("accuracy_vs_elevation.png", plot_elevation(rows_by_model, curve))
    return folder.root
