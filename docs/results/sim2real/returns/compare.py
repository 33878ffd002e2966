"""The with/without-returns table of docs/results/sim2real.md from two runs' runs.jsonl (the same model, seeds and settings
but ``--returns``), seed by seed: the same seed draws the same mesh split, complete and occluded clouds and initialisation
in both, so only the LiDAR sets differ, and the difference is paired by seed.

    python docs/results/sim2real/returns/compare.py docs/results/sim2real/returns/voxnet_noreturns docs/results/sim2real/returns/voxnet_returns
"""

from __future__ import annotations

import itertools
import json
import sys
from pathlib import Path

import numpy as np


def runs(folder: Path) -> dict[tuple[str, int], dict]:
    rows = [json.loads(line) for line in (folder / "runs.jsonl").read_text(encoding="utf-8").splitlines() if line.strip()]
    return {(r["train_set"], int(r["seed"])): r for r in rows}


def sign_flip_p(d: np.ndarray) -> float:
    """One-sided exact paired permutation p of mean(d) <= the observed mean (returns worse), over the 2^n sign flips."""
    flips = np.array(list(itertools.product((1.0, -1.0), repeat=len(d))))
    return float(np.mean((flips * d).mean(axis=1) <= d.mean() + 1e-12))


def ms(v: np.ndarray) -> str:
    return f"{v.mean():.3f} ± {v.std(ddof=1):.3f}"


without, with_ = runs(Path(sys.argv[1])), runs(Path(sys.argv[2]))
sets = list(dict.fromkeys(k[0] for k in without))
CLASSES = ("bush", "car", "pedestrian", "pole")
print(
    "| training set | seeds | mean class acc., one return | with returns | Δ (paired by seed) | seeds up / down | p (worse) | "
    + " | ".join(f"Δ acc. {c}" for c in CLASSES)
    + " |"
)
print("|---|---|---|---|---|---|---|" + "---|" * len(CLASSES))
per_class = []
for s in sets:
    seeds = sorted(k[1] for k in without if k[0] == s and (s, k[1]) in with_)

    def pair(m: str, s: str = s, seeds: list = seeds) -> tuple[np.ndarray, np.ndarray]:
        return (np.array([without[(s, i)][m] for i in seeds], float), np.array([with_[(s, i)][m] for i in seeds], float))

    a, b = pair("mean_class_accuracy")
    d = b - a
    if np.array_equal(a, b) and all(np.array_equal(*pair(f"acc_{c}")) for c in CLASSES):
        print(f"| {s} | {len(seeds)} | {ms(a)} | {ms(b)} | identical (same clouds) | 0 / 0 |  |" + " |" * len(CLASSES))
        continue
    deltas = [pair(f"acc_{c}") for c in CLASSES]
    print(
        f"| {s} | {len(seeds)} | {ms(a)} | {ms(b)} | {d.mean():+.3f} ± {d.std(ddof=1):.3f} | {(d > 0).sum()} / {(d < 0).sum()} | "
        f"{sign_flip_p(d):.3f} | " + " | ".join(f"{(y - x).mean():+.3f}" for x, y in deltas) + " |"
    )
    per_class.append((s, deltas))
print()
print("| training set | returns | " + " | ".join(f"acc. {c}" for c in CLASSES) + " |")
print("|---|---|" + "---|" * len(CLASSES))
for s, deltas in per_class:
    print(f"| {s} | one | " + " | ".join(ms(x) for x, _ in deltas) + " |")
    print(f"| {s} | several | " + " | ".join(ms(y) for _, y in deltas) + " |")
