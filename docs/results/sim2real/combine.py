"""The table of docs/results/sim2real.md from the runs' summary.csv files (one folder per model).

python docs/results/sim2real/combine.py docs/results/sim2real/pointnet docs/results/sim2real/voxnet
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path


def cell(row: dict, key: str) -> str:
    m, s = row.get(f"{key}_mean", ""), row.get(f"{key}_std", "")
    return f"{float(m):.3f} ± {float(s):.3f}" if m not in ("", "nan") else ""


print(
    "| model | training set | mean class acc. | Δ vs complete | p vs complete | overall acc. | car F1 | "
    "acc. bush | acc. car | acc. pedestrian | acc. pole |"
)
print("|---|---|---|---|---|---|---|---|---|---|---|")
for folder in map(Path, sys.argv[1:]):
    model = json.loads((folder / "settings.json").read_text())["model"]
    with open(folder / "summary.csv", encoding="utf-8") as fh:
        for r in csv.DictReader(fh):
            p = r.get("p_vs_complete", "")
            d = r.get("diff_vs_complete", "")
            name = r["train_set"]
            print(
                f"| {model} | {name} | {cell(r, 'mean_class_accuracy')} | "
                f"{'' if name in ('complete', 'chance') or d in ('', 'nan') else f'{float(d):+.3f}'} | "
                f"{'' if p in ('', 'nan') else f'{float(p):.3f}'} | {cell(r, 'overall_accuracy')} | {cell(r, 'car_f1')} | "
                + " | ".join(cell(r, f"acc_{c}") for c in ("bush", "car", "pedestrian", "pole"))
                + " |"
            )
