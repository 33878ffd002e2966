"""The fitted families' sim2real runs against the street meshes alone and with the unfitted trunks and shrubs.

usage: python docs/results/families/sim2real_table.py FAMILIES_RUN [BASELINE_ROOT]
  FAMILIES_RUN   one folder per model with the runs.jsonl of
                 experiment sim2real ... --fit-families --sets lidar,pooled (docs/results/families/sim2real)
  BASELINE_ROOT  docs/results/sensor_fit (default): its sim2real_pooled10 (the street meshes) and
                 sim2real_procedural (with six trunks and six shrubs) runs, same protocol

Prints a Markdown table per model: each set's mean class accuracy over the seeds the runs share
(mean ± std), its difference from the same run's real→real with the one-sided exact permutation p
that real→real is above, and, for the families' lidar and pooled sets, the difference from the
same set of each baseline with the p that the families' set is above.  Seeds are those every run
holds (a 5-seed baseline limits the comparison to seeds 0-4 and says so).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from zbuf_occlude.learn.stats import mean_std, permutation_p

MODELS = ("pointnet", "voxnet", "3dmfv")
SETS = ("lidar", "pooled")


def scores(folder: Path) -> dict[str, dict[int, float]]:
    """``{set: {seed: mean class accuracy on the scored half}}`` of one run."""
    out: dict[str, dict[int, float]] = {}
    for line in (folder / "runs.jsonl").read_text(encoding="utf-8").splitlines():
        r = json.loads(line)
        out.setdefault(r["train_set"], {})[r["seed"]] = r["mean_class_accuracy"]
    return out


def pm(values: list[float]) -> str:
    m, s = mean_std(values)
    return f"{m:.3f} ± {s:.3f}"


def main() -> None:
    run = Path(sys.argv[1])
    base = Path(sys.argv[2]) if len(sys.argv) > 2 else Path("docs/results/sensor_fit")
    runs = {"street meshes": base / "sim2real_pooled10", "with trunks and shrubs": base / "sim2real_procedural", "with the fitted families": run}
    for model in MODELS:
        if not (run / model / "runs.jsonl").is_file():
            continue
        got = {name: scores(folder / model) for name, folder in runs.items()}
        seeds = sorted(set.intersection(*(set(s) for rows in got.values() for s in rows.values())))
        print(f"\n### {model} (seeds {seeds[0]}-{seeds[-1]}, {len(seeds)} each)\n")
        print("| meshes | set | mean class accuracy | Δ vs real→real (p real→real above) | Δ of the fitted families' set (p above) |")
        print("|---|---|---|---|---|")
        ours = got["with the fitted families"]
        for name, rows in got.items():
            real = [rows["real→real"][s] for s in seeds]
            for kind in SETS:
                v = [rows[kind][s] for s in seeds]
                d = sum(v) / len(v) - sum(real) / len(real)
                diff = ""
                if name != "with the fitted families":
                    o = [ours[kind][s] for s in seeds]
                    diff = f"{sum(o) / len(o) - sum(v) / len(v):+.3f} (p {permutation_p(o, v):.3g})"
                print(f"| {name} | {kind} | {pm(v)} | {d:+.3f} (p {permutation_p(real, v):.3g}) | {diff} |")
            print(f"| {name} | real→real | {pm(real)} | | |")


if __name__ == "__main__":
    main()
