"""The comparison's Markdown report and PNG plots, written with ``results.csv`` through the output layer.

:func:`compare_folder` holds the output folder (:class:`~zbuf_occlude.io.owned.OwnedFolder`: every
file atomic and recorded, a file replaced only if a run of ours wrote it and it is unchanged since);
:func:`write_results_into` writes into it, :func:`write_results` does both.
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from zbuf_occlude._version import install_hint
from zbuf_occlude.experiments.compare.results import summarise, write_csv
from zbuf_occlude.io.encodings import png_bytes
from zbuf_occlude.io.owned import OwnedFolder

__all__ = ["write_results", "write_results_into", "compare_folder", "compare_writes", "format_or_dash", "method_order", "COMPARE_OUTPUTS"]

log = logging.getLogger(__name__)

#: The report's default name.
REPORT_NAME = "report.md"
#: The plots, one per kind of row: time vs points, and one per sweep that has rows.
TIME_PLOT = "time_vs_points.png"
SWEEP_PLOTS = {"resolution": "agreement_vs_resolution.png", "grid": "agreement_vs_grid.png"}
#: Every file ``compare`` writes in ``--out``: the rows, the report and the plots (a sweep's plot only with
#: that sweep; no plot without matplotlib).  :func:`write_results` with another ``report_name`` writes that one instead.
COMPARE_OUTPUTS = ("results.csv", REPORT_NAME, TIME_PLOT, *SWEEP_PLOTS.values())


def format_or_dash(value: float, spec: str) -> str:
    """``format(value, spec)``, or an en dash for a missing or NaN value."""
    return "–" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, spec)


def method_order(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Method names in the order they first appear in ``rows`` (the mesh-failure marker ``*`` left out)."""
    return list(dict.fromkeys(r["method"] for r in rows if r.get("method") not in ("", "*")))


def _markdown_report(rows: Sequence[dict[str, Any]], plots: dict[str, str], title: str, command: str | None) -> str:
    methods = method_order([r for r in rows if not r.get("sweep")])
    counts = sorted({int(r["n_points"]) for r in rows if r.get("n_points", "") != "" and not r.get("sweep")})
    meshes = list(dict.fromkeys(f"{r['mesh']} ({r['n_faces']} faces)" for r in rows if r.get("n_faces", "") != ""))
    main = summarise(rows)
    lines = [f"# {title}", ""]
    if command:
        lines += ["Produced by:", "", "```", command, "```", ""]
    n_views = len({(r["mesh"], r["view"]) for r in rows if r.get("view", "") != ""})
    lines += [
        f"Meshes: {', '.join(meshes) or '–'}; {n_views} mesh × view combinations.  Reference: exact oracle.",
        "Times are wall seconds per view (one `visible_mask` call) on this machine; agreement is the mean",
        "over meshes and views.  Rates are fractions of all points (accuracy = 1 − FV − FH).",
        "",
        "## Time per view (s)",
        "",
        "| method | " + " | ".join(f"{n:,} pts" for n in counts) + " |",
        "|---|" + "---:|" * len(counts),
    ]
    for m in methods:
        lines.append(f"| {m} | " + " | ".join(format_or_dash(main.get((m, n), {}).get("time_s", math.nan), ".4g") for n in counts) + " |")
    lines += [
        "",
        "## Agreement with the oracle",
        "",
        "| method | points | accuracy | false visible | false hidden | IoU | Chamfer | views |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for m in methods:
        for n in counts:
            s = main.get((m, n))
            if s:
                lines.append(
                    f"| {m} | {n:,} | {format_or_dash(s['accuracy'], '.4f')} | {format_or_dash(s['false_visible_rate'], '.4f')} | "
                    f"{format_or_dash(s['false_hidden_rate'], '.4f')} | {format_or_dash(s['iou'], '.4f')} | {format_or_dash(s['chamfer'], '.2e')} | {s['views']} |"
                )
    if any(r.get("peak_mib", "") != "" for r in rows):
        lines += ["", "## Peak traced memory (MiB, numpy/Python heap, first view)", "", "| method | points | peak MiB |", "|---|---:|---:|"]
        for (m, n), s in sorted(main.items(), key=lambda kv: (methods.index(kv[0][0]) if kv[0][0] in methods else 99, kv[0][1])):
            if not math.isnan(s["peak_mib"]):
                lines.append(f"| {m} | {n:,} | {s['peak_mib']:.1f} |")
    for sweep, label in (("resolution", "z-buffer resolution (px)"), ("grid", "occupancy-grid size (cells per axis)")):
        sw = summarise(rows, by=("method", "param"), sweep=sweep)
        if not sw:
            continue
        lines += [
            "",
            f"## Agreement vs {label}",
            "",
            f"| method | {sweep} | time (s) | accuracy | false visible | false hidden | IoU |",
            "|---|---:|---:|---:|---:|---:|---:|",
        ]
        for (m, p), s in sorted(sw.items()):
            lines.append(
                f"| {m} | {p} | {format_or_dash(s['time_s'], '.4g')} | {format_or_dash(s['accuracy'], '.4f')} | {format_or_dash(s['false_visible_rate'], '.4f')} | "
                f"{format_or_dash(s['false_hidden_rate'], '.4f')} | {format_or_dash(s['iou'], '.4f')} |"
            )
    errors = [r for r in rows if r.get("error")]
    if errors:
        lines += ["", "## Failures and skips", "", "| mesh | points | view | method | error |", "|---|---:|---:|---|---|"]
        seen = set()
        for r in errors:
            key = (r["mesh"], r.get("n_points"), r["method"], r["error"])
            if key in seen:
                continue
            seen.add(key)
            lines.append(f"| {r['mesh']} | {r.get('n_points', '')} | {r.get('view', '')} | {r['method']} | {r['error']} |")
    if plots:
        lines += ["", "## Plots", ""]
        lines += [f"![{k}]({v})" for k, v in plots.items()]
    return "\n".join(lines) + "\n"


def _save(fig: Any, folder: OwnedFolder, name: str) -> None:
    """Write ``fig`` as the PNG ``name`` in ``folder`` (:meth:`OwnedFolder.write_bytes`) and close it."""
    import matplotlib.pyplot as plt

    try:
        folder.write_bytes(name, png_bytes(fig, dpi=120))
    finally:
        plt.close(fig)


def _plots(rows: Sequence[dict[str, Any]], folder: OwnedFolder) -> dict[str, str]:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log.warning("matplotlib is not installed (%s): no PNG plots written", install_hint("plot"))
        return {}
    written: dict[str, str] = {}
    main = summarise(rows)
    methods = method_order([r for r in rows if not r.get("sweep")])
    fig, ax = plt.subplots(figsize=(7, 5))
    for m in methods:
        pts = sorted((n, s["time_s"]) for (mm, n), s in main.items() if mm == m and not math.isnan(s["time_s"]))
        if pts:
            ax.plot(*zip(*pts), marker="o", label=m)
    ax.set(xscale="log", yscale="log", xlabel="points", ylabel="wall time per view (s)", title="Time per view vs number of points")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    _save(fig, folder, TIME_PLOT)
    written["time per view vs points"] = TIME_PLOT
    for sweep, xlabel, fname in (
        ("resolution", "z-buffer resolution (px)", SWEEP_PLOTS["resolution"]),
        ("grid", "occupancy grid size (cells per axis)", SWEEP_PLOTS["grid"]),
    ):
        sw = summarise(rows, by=("method", "param"), sweep=sweep)
        if not sw:
            continue
        fig, ax = plt.subplots(figsize=(7, 5))
        for m in dict.fromkeys(k[0] for k in sw):
            series = sorted((p, s) for (mm, p), s in sw.items() if mm == m)
            x = [p for p, _ in series]
            line = ax.plot(x, [s["accuracy"] for _, s in series], marker="o", label=f"{m} accuracy")[0]
            ax.plot(x, [s["false_visible_rate"] for _, s in series], ls="--", color=line.get_color(), label=f"{m} false visible")
            ax.plot(x, [s["false_hidden_rate"] for _, s in series], ls=":", color=line.get_color(), label=f"{m} false hidden")
        ax.set(xscale="log", xlabel=xlabel, ylabel="fraction of points", title=f"Agreement with the oracle vs {sweep}")
        ax.set_xticks(sorted({k[1] for k in sw}))
        ax.get_xaxis().set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        _save(fig, folder, fname)
        written[f"agreement vs {sweep}"] = fname
    return written


def compare_folder(out: str | os.PathLike, *, report_name: str = REPORT_NAME) -> OwnedFolder:
    """``out`` as a comparison holds it (not yet entered): the files of :data:`COMPARE_OUTPUTS`, the report named ``report_name``."""
    names = compare_writes(report_name=report_name)  # every sweep's plot
    return OwnedFolder(out, files=names, what="the comparison")


def compare_writes(*, report_name: str = REPORT_NAME, sweeps: Sequence[str] = tuple(SWEEP_PLOTS)) -> list[str]:
    """The files a comparison with ``sweeps`` writes, to check before any work (:meth:`OwnedFolder.check_writable`)."""
    return ["results.csv", report_name, TIME_PLOT, *(SWEEP_PLOTS[s] for s in sweeps)]


def write_results_into(
    folder: OwnedFolder,
    rows: Sequence[dict[str, Any]],
    *,
    title: str = "HSR methods compared with the exact oracle",
    command: str | None = None,
    report_name: str = REPORT_NAME,
) -> Path:
    """Write ``results.csv``, the Markdown report and the PNG plots into a held :func:`compare_folder`.

    Returns
    -------
    Path
        The report's path.

    Raises
    ------
    UnsafePathError
        A file of a name it writes is there and was not written by a run of ours, or was changed since.
    OutputError
        A file cannot be written.
    """
    with folder.write("results.csv") as tmp:
        write_csv(rows, tmp, atomic=False)
    plots = _plots(rows, folder)
    return folder.write_text(report_name, _markdown_report(rows, plots, title, command))


def write_results(
    rows: Sequence[dict[str, Any]],
    out: str | os.PathLike,
    *,
    title: str = "HSR methods compared with the exact oracle",
    command: str | None = None,
    report_name: str = REPORT_NAME,
) -> Path:
    """Write ``results.csv``, the Markdown report and the PNG plots into ``out`` (:func:`compare_folder`,
    every file checked before the first is written).

    Returns
    -------
    Path
        The report's path.

    Raises
    ------
    OutputError
        When ``out`` cannot be created or written.
    UnsafePathError
        A file of a name it writes is in ``out`` and was not written by a run of ours, or was
        changed since (nothing is written).
    DatasetBusy
        Another live process holds ``out``.
    """
    with compare_folder(out, report_name=report_name) as folder:
        sweeps = [sweep for sweep in SWEEP_PLOTS if any(r.get("sweep") == sweep for r in rows)]
        folder.check_writable(compare_writes(report_name=report_name, sweeps=sweeps))
        return write_results_into(folder, rows, title=title, command=command, report_name=report_name)
