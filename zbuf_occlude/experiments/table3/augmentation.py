"""Table 3B, augmentation: :func:`run_augmentation` (``experiment augmentation``), trained on occluded,
complete or both kinds of clouds and tested on complete, occluded and real clouds.

Sryamkin et al. 2023, §4.4, Table 3B.
"""

from __future__ import annotations

import json
import logging
import os
import time
from pathlib import Path

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.machine import machine_description
from zbuf_occlude.learn.reproducible import arithmetic_record
from zbuf_occlude.experiments.paper import MODELNET8, PAPER_3B
from zbuf_occlude.experiments.table3.common import AUGMENTATION_OUTPUTS, AUGMENTATION_SETS, owned_folder, plan_meshes, render_meshes
from zbuf_occlude.experiments.table3.config import AUGMENTATION_MODEL, Table3Config
from zbuf_occlude.experiments.table3.report import plot_augmentation, table_3b
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.learn.data import CloudSet, from_meshes, from_occluded, split_validation
from zbuf_occlude.learn.metrics import classification_report

__all__ = ["run_augmentation"]

log = logging.getLogger(__name__)


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
        (:class:`~zbuf_occlude.experiments.table3.config.Table3Config`, checked when made);
        default: its defaults with the model :data:`~zbuf_occlude.experiments.table3.config.AUGMENTATION_MODEL`.
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
    with owned_folder(out, AUGMENTATION_OUTPUTS, "the augmentation run (Table 3B)") as folder:
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
    ds_path = render_meshes(meshes, data_dir, "grid25", config, progress)
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
        "machine": machine_description(), "cpu_arithmetic": arithmetic_record(), "real_scans": str(real_scans) if real_scans else None,
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
