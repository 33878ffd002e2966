"""Tables 1A and 1B of Sryamkin et al. 2023, reproduced from the comparison's rows."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from zbuf_occlude.experiments.compare.results import summarise

__all__ = ["table_1a", "table_1b", "PAPER_TABLE_1A_REDUCTION", "PAPER_TABLE_1B_REDUCTION"]

#: Sryamkin et al. 2023, Table 1A: ``paper-pruned`` vs ``paper-exact`` time reduction,
#: percent (reported ≈55 %, rows from 54 to 59 %).
PAPER_TABLE_1A_REDUCTION = (54.0, 59.0)
#: Sryamkin et al. 2023, Table 1B: OG_32 / OG_64 vs exact time reduction at 50k-100k
#: points, percent.
PAPER_TABLE_1B_REDUCTION = (98.5, 99.8)


def _reduction(t_new: float, t_old: float) -> float:
    return 100.0 * (1.0 - t_new / t_old) if t_old > 0 else math.nan


def table_1a(rows: Sequence[dict[str, Any]], exact: str = "paper-exact", pruned: str = "paper-pruned") -> str:
    """Markdown: Table 1A of Sryamkin et al. 2023 reproduced, per mesh and point count.

    ``paper-exact`` vs ``paper-pruned`` mean time per view and the reduction, beside the
    paper's reported reduction, plus each method's agreement with the oracle.
    """
    s = summarise(rows, by=("mesh", "n_faces", "n_points", "method"))
    keys = sorted({k[:3] for k in s}, key=lambda k: (-int(k[1]), k[2]))
    lo, hi = PAPER_TABLE_1A_REDUCTION
    lines = [
        f"| mesh (faces) | points | views | {exact} (s) | {pruned} (s) | reduction (ours) | reduction (paper) | "
        f"{pruned} accuracy | {pruned} false hidden |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for mesh, faces, n in keys:
        e, p = s.get((mesh, faces, n, exact)), s.get((mesh, faces, n, pruned))
        if not e or not p:
            continue
        lines.append(
            f"| {mesh} ({faces}) | {n:,} | {e['views']} | {e['time_s']:.3g} | {p['time_s']:.3g} | "
            f"{_reduction(p['time_s'], e['time_s']):.1f} % | ≈55 % ({lo:g}–{hi:g} %) | {p['accuracy']:.4f} | "
            f"{p['false_hidden_rate']:.4f} |"
        )
    return "\n".join(lines) + "\n"


def table_1b(
    rows: Sequence[dict[str, Any]],
    exact: str = "paper-exact",
    methods: Sequence[str] = ("og32", "og64", "zbuffer", "oracle"),
) -> str:
    """Markdown: Table 1B of Sryamkin et al. 2023 reproduced, with the z-buffer and agreement added.

    Per mesh and point count: mean time per view of ``exact`` and of each of ``methods``,
    the reduction relative to ``exact``, and each method's accuracy against the oracle
    (which the paper did not report).
    """
    s = summarise(rows, by=("mesh", "n_faces", "n_points", "method"))
    keys = sorted({k[:3] for k in s}, key=lambda k: (-int(k[1]), k[2]))
    lo, hi = PAPER_TABLE_1B_REDUCTION
    head = f"| mesh (faces) | points | views | {exact} (s) | " + " | ".join(f"{m} (s) / reduction / accuracy" for m in methods)
    lines = [head + " | paper: OG_32/OG_64 reduction |", "|---|---:|---:|---:|" + "---:|" * len(methods) + "---:|"]
    for mesh, faces, n in keys:
        e = s.get((mesh, faces, n, exact))
        if not e:
            continue
        cells = []
        for m in methods:
            x = s.get((mesh, faces, n, m))
            cells.append("–" if not x else f"{x['time_s']:.3g} / {_reduction(x['time_s'], e['time_s']):.1f} % / {x['accuracy']:.4f}")
        paper = f"{lo:g}–{hi:g} %" if n >= 50_000 else "–"
        lines.append(f"| {mesh} ({faces}) | {n:,} | {e['views']} | {e['time_s']:.3g} | " + " | ".join(cells) + f" | {paper} |")
    return "\n".join(lines) + "\n"
