"""Tables (Markdown, ours beside the paper's), rows of a confusion matrix, and plots of the Table 3 experiments.

Nothing here writes a file: the plots are returned as the bytes of a PNG
(:func:`zbuf_occlude.io.encodings.png_bytes`), and :mod:`zbuf_occlude.experiments.table3` writes
every file through its output folder (:meth:`zbuf_occlude.io.owned.OwnedFolder.write_bytes`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from zbuf_occlude.experiments.paper import PAPER_3A, PAPER_3B_MEAN_F1, TEST_ELEVATIONS
from zbuf_occlude.io.encodings import png_bytes

__all__ = ["table_3a", "table_3b", "plot_elevation", "plot_augmentation", "confusion_rows"]


def _fmt(x: float) -> str:
    return "" if x is None or not np.isfinite(x) else f"{100 * x:.1f}"


def confusion_rows(cm: np.ndarray, names: Sequence[str]) -> list[dict]:
    """The rows of ``confusion.csv``: one per true class, a column per predicted class (``cm``: (K, K) counts)."""
    return [{"true\\pred": n, **{m: int(v) for m, v in zip(names, row)}} for n, row in zip(names, cm)]


def table_3a(rows_by_model: dict, summaries: dict) -> str:
    lines = ["| model | " + " | ".join(f"{e:+.0f}°" for e in TEST_ELEVATIONS) + " | overall | mean class |",
             "|---|" + "---|" * (len(TEST_ELEVATIONS) + 2)]  # fmt: skip
    for model, rows in rows_by_model.items():
        ours = {r["elevation_deg"]: r["accuracy"] for r in rows}
        s = summaries.get(model, {})
        lines.append(f"| {model} (ours) | " + " | ".join(_fmt(ours.get(e, float("nan"))) for e in TEST_ELEVATIONS)
                     + f" | {_fmt(s.get('overall_accuracy', float('nan')))} | {_fmt(s.get('mean_class_accuracy', float('nan')))} |")  # fmt: skip
        lines.append(f"| {model} (paper) | " + " | ".join(f"{v:.1f}" for v in PAPER_3A[model])
                     + f" | {np.mean(PAPER_3A[model]):.1f}¹ | |")  # fmt: skip
    lines.append("")
    lines.append("¹ unweighted mean of the paper's per-elevation values (the paper gives no overall figure).")
    return "\n".join(lines) + "\n"


def plot_elevation(rows_by_model: dict, curve: list[dict] | None) -> bytes:
    """Accuracy vs elevation per model, ours and the paper's, with Fig. 12's curve when given: the bytes of a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.8))
    for model, rows in rows_by_model.items():
        el = [r["elevation_deg"] for r in rows]
        line = ax.plot(el, [100 * r["accuracy"] for r in rows], marker="o", label=f"{model} (ours)")[0]
        ax.plot(TEST_ELEVATIONS, PAPER_3A[model], ls="--", marker="x", color=line.get_color(), alpha=0.6,
                label=f"{model} (paper)")  # fmt: skip
    ax.set(xlabel="camera elevation (degrees)", ylabel="overall accuracy (%)", ylim=(0, 100),
           title="Accuracy vs camera elevation (Table 3A protocol)")  # fmt: skip
    ax.set_xticks(range(-90, 91, 30))
    ax.grid(True, alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    if curve:
        ax2 = ax.twinx()
        el = [r["elevation_deg"] for r in curve]
        for key, style in (("area_xy", ":"), ("area_yz", "-."), ("area_xz", (0, (1, 3)))):
            h = ax2.plot(el, [r[key] for r in curve], color="grey", ls=style, label=f"visible {key[5:]} area (Fig. 12)")[0]
            handles.append(h)
            labels.append(h.get_label())
        ax2.set_ylabel("projected visible area, mean over meshes (object units²)")
    ax.legend(handles, labels, fontsize=7, loc="lower left")
    fig.tight_layout()
    try:
        return png_bytes(fig, dpi=120)
    finally:
        plt.close(fig)


def table_3b(rows: list[dict], test3: list[dict], model: str) -> str:
    lines = ["| training set | Test 1 ours | Test 1 paper | Test 2 ours | Test 2 paper |", "|---|---|---|---|---|"]
    for name in ("C1", "C2", "C3"):
        r = {x["test"]: x for x in rows if x["train_set"] == name}
        lines.append(f"| {name} | {_fmt(r['Test1']['overall_accuracy'])} | {_fmt(r['Test1']['paper_accuracy'])} | "
                     f"{_fmt(r['Test2']['overall_accuracy'])} | {_fmt(r['Test2']['paper_accuracy'])} |")  # fmt: skip
    if test3:
        lines += ["", "Test 3 (real scans):", ""]
        keys = [k for k in test3[0] if k != "train_set"]
        lines.append("| training set | " + " | ".join(keys) + " |")
        lines.append("|---|" + "---|" * len(keys))
        for r in test3:
            vals = [f"{v:.3f}" if isinstance(v, float) else str(v) for v in (r.get(k, "") for k in keys)]
            lines.append(f"| {r['train_set']} | " + " | ".join(vals) + " |")
        if model == "3dmfv":
            lines.append("")
            lines.append("Paper (3DmFV, 1,024 points, SUO): car / 4wd accuracy C1 88.6 / 66.7, C2 36.4 / 42.9, "
                         f"C3 76.1 / 81.0; mean F1 over six car types {PAPER_3B_MEAN_F1}.")  # fmt: skip
    return "\n".join(lines) + "\n"


def plot_augmentation(rows: list[dict], model: str) -> bytes:
    """Accuracy per training set and test set, ours beside the paper's: the bytes of a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2))
    x = np.arange(3)
    for k, (test, off) in enumerate((("Test1", -0.3), ("Test2", 0.1))):
        ours = [next(r["overall_accuracy"] for r in rows if r["train_set"] == c and r["test"] == test) for c in ("C1", "C2", "C3")]
        paper = [next(r["paper_accuracy"] for r in rows if r["train_set"] == c and r["test"] == test) for c in ("C1", "C2", "C3")]
        ax.bar(x + off, 100 * np.array(ours), 0.2, label=f"{test} ours", color=f"C{k}")
        ax.bar(x + off + 0.2, 100 * np.array(paper), 0.2, label=f"{test} paper", color=f"C{k}", alpha=0.4)
    ax.set_xticks(x, ["C1 occluded", "C2 complete", "C3 both"])
    ax.set(ylabel="overall accuracy (%)", ylim=(0, 100), title=f"{model}: training set vs test set (Table 3B protocol)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    try:
        return png_bytes(fig, dpi=120)
    finally:
        plt.close(fig)
