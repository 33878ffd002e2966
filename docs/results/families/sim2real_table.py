"""The fitted families' sim2real runs against the same protocol without them, as Markdown.

usage: python docs/results/families/sim2real_table.py FAMILIES_RUN [BASE_RUN [BASE_NAME]]
  FAMILIES_RUN  one folder per model with the runs.jsonl of
                experiment sim2real ... --fit-families --sets lidar,pooled (docs/results/families/sim2real)
  BASE_RUN      the run to compare with, where it was run: by default the same command without
                --fit-families (the street meshes alone)
  BASE_NAME     what the table calls BASE_RUN (default "street meshes alone")

Prints a table per model: each set's mean class accuracy on the scored half (mean ± std over seeds), its
difference from the same run's real→real with the one-sided exact permutation p that real→real is above,
and, where BASE_RUN holds the model, the same set in BASE_RUN over the seeds both runs hold, with the difference
(FAMILIES_RUN − BASE_RUN) and the p that FAMILIES_RUN's set is above.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from zbuf_occlude.learn.stats import mean_std, permutation_p

MODELS = ("pointnet", "voxnet", "3dmfv")
SETS = ("lidar", "fitted+placed", "pooled")


def scores(folder: Path) -> dict[str, dict[int, float]]:
    """``{set: {seed: mean class accuracy on the scored half}}`` of one run (empty when it has none)."""
    out: dict[str, dict[int, float]] = {}
    path = folder / "runs.jsonl"
    for line in path.read_text(encoding="utf-8").splitlines() if path.is_file() else []:
        r = json.loads(line)
        out.setdefault(r["train_set"], {})[r["seed"]] = r["mean_class_accuracy"]
    return out


def pm(values: list[float]) -> str:
    m, s = mean_std(values)
    return f"{m:.3f} ± {s:.3f}"


def mean(values: list[float]) -> float:
    return sum(values) / len(values)


def main() -> None:
    run = Path(sys.argv[1])
    street = Path(sys.argv[2]) if len(sys.argv) > 2 else None
    base_name = sys.argv[3] if len(sys.argv) > 3 else "street meshes alone"
    for model in MODELS:
        ours = scores(run / model)
        if not ours:
            continue
        seeds = sorted(set.intersection(*(set(v) for v in ours.values())))
        base = scores(street / model) if street else {}
        sets = [k for k in SETS if k in ours]  # a run of --sets lidar has no pooled rows
        shared = sorted(set(seeds).intersection(*(set(base.get(k, {})) for k in (*sets, "real→real")))) if base else []
        print(f"\n### {model}: seeds {seeds[0]}-{seeds[-1]}\n")
        print(f"| set | with the fitted families | Δ vs real→real (p real→real above) | {base_name}, seeds both hold | "
              f"difference (p the first above) |")  # fmt: skip
        print("|---|---|---|---|---|")
        real = [ours["real→real"][s] for s in seeds]
        for kind in sets:
            v = [ours[kind][s] for s in seeds]
            cells = ["", ""]
            if shared:
                o, b = [ours[kind][s] for s in shared], [base[kind][s] for s in shared]
                cells = [f"{pm(b)} ({len(shared)} seeds)", f"{mean(o) - mean(b):+.3f} (p {permutation_p(o, b):.3g})"]
            print(f"| {kind} | {pm(v)} | {mean(v) - mean(real):+.3f} (p {permutation_p(real, v):.3g}) | {cells[0]} | {cells[1]} |")
        street_real = f"{pm([base['real→real'][s] for s in shared])} ({len(shared)} seeds)" if shared else ""
        print(f"| real→real | {pm(real)} | | {street_real} | |")


if __name__ == "__main__":
    main()
