"""Table 3A, accuracy against elevation: :func:`run_elevation` (``experiment elevation``) and :func:`combine_elevation`.

Sryamkin et al. 2023, §4.4, Table 3A and Fig. 12.  The data are rendered with the farm (compact
storage, :func:`~zbuf_occlude.experiments.table3.common.render_meshes`) and read back with
:class:`zbuf_occlude.OccludedDataset`.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from zbuf_occlude.defaults import DEFAULT_METHOD
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.machine import machine_description
from zbuf_occlude.learn.reproducible import arithmetic_record
from zbuf_occlude.experiments.paper import PAPER_3A, TEST_ELEVATIONS, TRAIN_ELEVATIONS
from zbuf_occlude.experiments.table3.common import (
    COMBINED_OUTPUTS,
    DATA_OUTPUTS,
    ELEVATION_OUTPUTS,
    number_rows,
    owned_folder,
    plan_meshes,
    render_meshes,
)
from zbuf_occlude.experiments.table3.config import ELEVATION_MODEL, Scale, Table3Config
from zbuf_occlude.experiments.table3.report import confusion_rows, plot_elevation, table_3a
from zbuf_occlude.io.json_files import read_json_file
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.learn.data import from_occluded, split_validation
from zbuf_occlude.learn.metrics import accuracy_by_elevation, classification_report
from zbuf_occlude.visibility.registry import method_info

__all__ = ["run_elevation", "combine_elevation"]


def _visible_area_curve(meshes: list[dict], data_dir: Path, scale: Scale, method: str, progress: bool) -> list[dict]:
    """Fig. 12: projected visible areas per elevation, averaged over the meshes (cached in data_dir)."""
    from zbuf_occlude.experiments.elevation_profile import profile_table
    from zbuf_occlude.io.progress import progress as progress_bar
    from zbuf_occlude.mesh.load import load_mesh

    cache = data_dir / "visible_area.csv"
    if os.path.lexists(cache):  # a FIFO or a link out of the data folder is refused, not skipped
        return number_rows(cache, data_dir)
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
    with owned_folder(data_dir, DATA_OUTPUTS, "the experiment's data folder", option="--data") as folder:
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
        (:class:`~zbuf_occlude.experiments.table3.config.Table3Config`, checked when made);
        default: its defaults with the model :data:`~zbuf_occlude.experiments.table3.config.ELEVATION_MODEL`.
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
    with owned_folder(out, ELEVATION_OUTPUTS, "the elevation run (Table 3A)") as folder:
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
    ds_path = render_meshes(meshes, data_dir, "paper100", config, progress)
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
        "history": result.history, "machine": machine_description(), "cpu_arithmetic": arithmetic_record(),
        "wall_s": {"render": t_render, "train": t_train, "test": t_test, "total": time.perf_counter() - t_start},
        "train_samples_per_s": result.samples_per_second,
    }  # fmt: skip
    folder.write_text("run.json", json.dumps(summary, indent=1, default=float))
    folder.write_text("table.md", table_3a({model: rows}, {model: summary}))
    return summary


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
    with owned_folder(out, COMBINED_OUTPUTS, "the combined elevation table") as folder:
        folder.check_writable(COMBINED_OUTPUTS)  # every file before any run is read: a refusal writes nothing
        return _combine_into(folder, run_dirs)


def _combine_into(folder: OwnedFolder, run_dirs: Sequence[str | os.PathLike]) -> Path:
    """:func:`combine_elevation` once its ``out`` is held; each run's files are read inside its folder."""
    rows_by_model, summaries, all_rows, curve = {}, {}, [], None
    for d in map(Path, run_dirs):
        summary = read_json_file(d / "run.json", within=d)
        if not isinstance(summary, dict) or not isinstance(summary.get("model"), str):
            raise InvalidInputError(f"{d / 'run.json'} is not the run.json of an elevation run (it names no model)")
        rows = number_rows(d / "results.csv", d, text=("model",))
        rows_by_model[summary["model"]] = rows
        summaries[summary["model"]] = summary
        all_rows += rows
        data_dirs = [d / "data"]
        if isinstance(summary.get("data_dir"), str) and summary["data_dir"]:
            data_dirs.append(Path(summary["data_dir"]))
        for data_dir in data_dirs:
            if curve is None and os.path.lexists(data_dir / "visible_area.csv"):
                curve = number_rows(data_dir / "visible_area.csv", data_dir)
    folder.write_csv("results.csv", all_rows)
    folder.write_text("table.md", table_3a(rows_by_model, summaries))
    folder.write_bytes("accuracy_vs_elevation.png", plot_elevation(rows_by_model, curve))
    return folder.root
