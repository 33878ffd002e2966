"""The sim-to-real table (Markdown) and the figure of example clouds, real beside each training set."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from zbuf_occlude.experiments.sim2real.data import FITTED_SETS, OCCLUDED_POINTS
from zbuf_occlude.experiments.sim2real.outputs import ALL_SCANS, CHOSEN_ON_FIT_HALF, EVERY_SET, MESH_SETS, REAL_TO_REAL
from zbuf_occlude.io.encodings import png_bytes
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.learn.stats import mean_std, permutation_p

__all__ = ["summarise", "table_md", "plot_examples"]


def _pm(row: dict, key: str) -> str:
    m, s = row.get(f"{key}_mean", float("nan")), row.get(f"{key}_std", float("nan"))
    if m is None or not np.isfinite(m):
        return ""
    return f"{m:.3f} ± {s:.3f}" if np.isfinite(s) else f"{m:.3f}"


def _p(x) -> str:
    return "" if x is None or not np.isfinite(x) else f"{x:.3g}"


def table_md(rows: list[dict], settings: dict) -> str:
    """One row per training set (then real→real and chance): mean class accuracy on the held-out
    half first, mean ± std over seeds, the difference from ``complete`` and its one-sided
    permutation p; mean class accuracy on every scan (the mesh-only sets); then overall
    accuracy, the paper's car precision / recall / F1, and per-class accuracy (held-out half)."""
    names = settings["classes"]
    head = (["training set", "seeds", "mean class acc.", "Δ vs complete", "p vs complete", "mean class acc., all scans",
             "overall acc.", "car precision", "car recall", "car F1"] + [f"acc. {n}" for n in names])  # fmt: skip
    lines = [f"model **{settings['model']}**, {settings['points']} points, scale {settings['scale']}, "
             f"sensor {settings['sensor']}, {'metric scale kept' if settings['keep_scale'] else 'normalised (max extent 1)'}",
             "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]  # fmt: skip
    for r in rows:
        diff = r.get("diff_vs_complete", float("nan"))
        cells = [r["train_set"], str(r.get("n_seeds", "")), _pm(r, "mean_class_accuracy"),
                 "" if r["train_set"] in ("complete", "chance") or not np.isfinite(diff) else f"{diff:+.3f}",
                 _p(r.get("p_vs_complete", float("nan"))), _pm(r, "all_scans_mean_class_accuracy"), _pm(r, "overall_accuracy"),
                 _pm(r, "car_precision"),
                 _pm(r, "car_recall"), _pm(r, "car_f1")] + [_pm(r, f"acc_{n}") for n in names]  # fmt: skip
        lines.append("| " + " | ".join(cells) + " |")
    for r in rows:
        if "p_vs_lidar" in r:
            lines += ["", (f"{r['train_set']} vs lidar: Δ {r['diff_vs_lidar']:+.3f} mean class accuracy, one-sided p "
                           f"{_p(r['p_vs_lidar'])} ({r['train_set']} above lidar), {_p(r['p_lidar_above'])} (lidar above {r['train_set']})")]  # fmt: skip
    for r in rows:
        if "p_vs_occluded" in r:
            lines += ["", (f"{r['train_set']} vs occluded (visibility from the points alone vs from the mesh): Δ {r['diff_vs_occluded']:+.3f} "
                           f"mean class accuracy, one-sided p {_p(r['p_vs_occluded'])} ({r['train_set']} above occluded), "
                           f"{_p(r['p_occluded_above'])} (occluded above {r['train_set']})")]  # fmt: skip
    for r in rows:
        if "chosen_sets" in r:
            lines += ["", (f"{r['train_set']}: per seed, the mesh-only set with the best fit-half validation score "
                           f"({r['chosen_sets']}); Δ {r['diff_vs_real_to_real']:+.3f} mean class accuracy against real→real, "
                           f"one-sided p {_p(r['p_real_to_real_above'])} (real→real above)")]  # fmt: skip
    if "real_split" in settings:
        scored, every = sum(settings["real_split"]["scored_scans"].values()), sum(settings["real_scans"].values())
        lines += ["", (f"Every row is scored on the held-out half of the real scans ({scored} of {every} scans; the other half is "
                       f"the one real→real trains on); the column 'all scans' scores the mesh-only sets on all {every} "
                       "(not real→real, which trained on half of them).")]  # fmt: skip
    if settings.get("fit_sensor"):
        fs = settings["fit_sensor"]
        lines += ["", (f"The sensor was fitted on the half real→real trains on ({sum(fs['fit_scans'].values())} scans), which the "
                       "'all scans' column includes.")]  # fmt: skip
        if settings.get("validate_on") == "fit-half":
            lines += ["", ("The mesh-only sets trained on every mesh and chose their best epoch (and stopped early) on the "
                           "fit half's real scans, never on the scored half.")]  # fmt: skip
    return "\n".join(lines) + "\n"


def plot_examples(path: str | Path, rows: dict[str, dict[str, np.ndarray]], title: str = "") -> Path:
    """A grid of 3-D scatter plots: one row per ``{row label: {column label: (n, 3) cloud}}``,
    the same view and limits for each (normalised clouds, max extent 1), written as the PNG ``path``
    through the output layer (:meth:`~zbuf_occlude.io.owned.OwnedFolder.write_bytes` into its folder,
    held for this one name: an existing file of that name is replaced only if a run of ours wrote it
    and it is unchanged since).

    Needs matplotlib (the ``learn`` or ``plot`` extra).

    Raises
    ------
    UnsafePathError
        ``path`` exists and was not written by a run of ours, was changed since, or is a folder
        or a link.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n_rows, n_cols = len(rows), max(len(r) for r in rows.values())
    fig = plt.figure(figsize=(2.6 * n_cols, 2.7 * n_rows))
    for i, (row_label, clouds) in enumerate(rows.items()):
        for j, (label, pts) in enumerate(clouds.items()):
            ax = fig.add_subplot(n_rows, n_cols, i * n_cols + j + 1, projection="3d")
            p = np.asarray(pts, dtype=np.float64)
            ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=1.5, c=p[:, 2], cmap="viridis")
            ax.set_title(f"{row_label}: {label}", fontsize=8)
            ax.set_box_aspect((1, 1, 1))
            lim = 0.55
            ax.set_xlim(-lim, lim), ax.set_ylim(-lim, lim), ax.set_zlim(-lim, lim)
            ax.view_init(elev=15, azim=-60)
            ax.set_xticks([]), ax.set_yticks([]), ax.set_zticks([])
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    try:
        data = png_bytes(fig, dpi=100)
    finally:
        plt.close(fig)
    with OwnedFolder(path.parent, files=[path.name], what=f"the file {path.name}", option="path") as folder:
        return folder.write_bytes(path.name, data)


def summarise(runs: list[dict], names: list[str], *, chosen_on_fit_half: bool = False) -> list[dict]:
    """Per training set: mean ± std over seeds of every score (on the held-out half, and on every
    scan, :data:`ALL_SCANS`, NaN for real→real), and the one-sided permutation p of its mean class
    accuracy on the held-out half against ``complete``; then the chance row (``1/K``).

    The rows of :data:`~zbuf_occlude.experiments.sim2real.data.FITTED_SETS` also hold their
    difference from ``lidar`` (``diff_vs_lidar``) and both one-sided p-values: ``p_vs_lidar``
    (the fitted set above lidar) and ``p_lidar_above`` (lidar above it); the
    :data:`~zbuf_occlude.experiments.sim2real.data.OCCLUDED_POINTS` row likewise against
    ``occluded`` (``diff_vs_occluded``, ``p_vs_occluded``, ``p_occluded_above``).

    With ``chosen_on_fit_half`` (runs validated on the fit half's real scans), a
    :data:`CHOSEN_ON_FIT_HALF` row follows real→real: per seed, the mesh-only run with the best
    ``best_val_mean_class_accuracy`` (ties: the lower ``best_val_loss``, then the first in the
    sets' order), its scores as above,
    the chosen sets (``chosen_sets``, in seed order), and its difference from real→real
    (``diff_vs_real_to_real``) with the one-sided p that real→real is above (``p_real_to_real_above``)."""
    keys = ["mean_class_accuracy", "overall_accuracy", "car_precision", "car_recall", "car_f1",
            *[f"acc_{n}" for n in names], *ALL_SCANS]  # fmt: skip
    ref = [r["mean_class_accuracy"] for r in runs if r["train_set"] == "complete"]
    lidar = [r["mean_class_accuracy"] for r in runs if r["train_set"] == "lidar"]
    occluded = [r["mean_class_accuracy"] for r in runs if r["train_set"] == "occluded"]
    rows = []
    for kind in EVERY_SET:
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
        if kind == OCCLUDED_POINTS and occluded:
            row["diff_vs_occluded"] = row["mean_class_accuracy_mean"] - float(np.mean(occluded))
            row["p_vs_occluded"], row["p_occluded_above"] = permutation_p(mca, occluded), permutation_p(occluded, mca)
        rows.append(row)
    if chosen_on_fit_half:
        rows += _chosen_row(runs, keys, ref)
    k = len(names)
    rows.append({"train_set": "chance", "n_seeds": 0, "mean_class_accuracy_mean": 1.0 / k, "mean_class_accuracy_std": 0.0,
                 "overall_accuracy_mean": 1.0 / k, "overall_accuracy_std": 0.0,
                 **{f"{key}_{stat}": (1.0 / k if stat == "mean" else 0.0) for key in ALL_SCANS for stat in ("mean", "std")}})  # fmt: skip
    return rows


def _validation_rank(run: dict) -> tuple[float, float]:
    """How well a run did on its validation scans, larger is better: the mean class accuracy, then
    (accuracy often ties at 1.0 on a small fit half) the lower validation loss; a run recorded
    without a loss ranks below one with a loss."""
    loss = run.get("best_val_loss")
    return run["best_val_mean_class_accuracy"], -loss if loss is not None and math.isfinite(loss) else -math.inf


def _chosen_row(runs: list[dict], keys: list[str], ref: list[float]) -> list[dict]:
    """The :data:`CHOSEN_ON_FIT_HALF` row of :func:`summarise` (none when no seed has a mesh-only run)."""
    order = {k: i for i, k in enumerate(MESH_SETS)}
    chosen = []
    for seed in sorted({r["seed"] for r in runs}):
        mine = [r for r in runs if r["seed"] == seed and r["train_set"] in order]
        if mine:
            chosen.append(max(sorted(mine, key=lambda r: order[r["train_set"]]), key=_validation_rank))
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
