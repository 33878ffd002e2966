"""The sim-to-real table (Markdown) and the figure of example clouds, real beside each training set."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from zbuf_occlude.io.encodings import png_bytes
from zbuf_occlude.io.owned import OwnedFolder

__all__ = ["table_md", "plot_examples"]


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
