"""Two sim2real runs of the same models, set by set, and each set against real→real.

    python docs/results/sensor_fit/compare.py docs/results/sensor_fit/sim2real docs/results/sensor_fit/sim2real_realval [LO-HI]

Each argument holds one folder per model with the ``runs.jsonl`` of ``experiment sim2real``;
``LO-HI`` keeps seeds LO to HI of both (default: every seed each has).
Prints, per model and training set, mean class accuracy (mean ± std over seeds) in each run,
the difference (second − first) with both one-sided exact permutation p-values, then the second
run's sets against its real→real row (difference and p that real→real is above), then each
set's validation mean class accuracy in both runs (with ``--validate-on fit-half``: on the fit
half, the score its settings are chosen by).  The set chosen
per seed on the fit half is in each run's own table (``experiment sim2real --validate-on fit-half``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from zbuf_occlude.learn.stats import mean_std, permutation_p

MODELS = ("pointnet", "voxnet", "3dmfv")


def scores(folder: Path, seeds: tuple[int, int], key: str) -> dict[str, list[float]]:
    """``{training set: [key per seed, in seed order]}`` over ``seeds`` (lo, hi)."""
    out: dict[str, list[tuple[int, float]]] = {}
    for line in (folder / "runs.jsonl").read_text(encoding="utf-8").splitlines():
        r = json.loads(line)
        if seeds[0] <= r["seed"] <= seeds[1]:
            out.setdefault(r["train_set"], []).append((r["seed"], r[key]))
    return {k: [v for _, v in sorted(rows)] for k, rows in out.items()}


def pm(values: list[float]) -> str:
    m, s = mean_std(values)
    return f"{m:.3f} ± {s:.3f}"


def mean(values: list[float]) -> float:
    return sum(values) / len(values)


def pairs(key: str):
    """``(model, training set, first run's values, second's)`` of ``key`` for every mesh-only set both runs hold."""
    for model in MODELS:
        if (second / model / "runs.jsonl").is_file():
            a, b = scores(first / model, SEEDS, key), scores(second / model, SEEDS, key)
            yield from ((model, kind, a[kind], b[kind]) for kind in b if kind in a and kind != "real→real")


first, second = Path(sys.argv[1]), Path(sys.argv[2])
SEEDS = tuple(int(v) for v in sys.argv[3].split("-")) if len(sys.argv) > 3 else (0, 10**9)
print("| model | training set | first | second | Δ | p (second above) | p (first above) |\n|---|---|---|---|---|---|---|")
for model, kind, a, b in pairs("mean_class_accuracy"):
    print(f"| {model} | {kind} | {pm(a)} | {pm(b)} | {mean(b) - mean(a):+.3f} | {permutation_p(b, a):.3g} | {permutation_p(a, b):.3g} |")
print("\n| model | training set | mean class acc. | real→real | Δ | p (real→real above) |\n|---|---|---|---|---|---|")
for model in MODELS:
    if not (second / model / "runs.jsonl").is_file():
        continue
    b = scores(second / model, SEEDS, "mean_class_accuracy")
    ref = b["real→real"]
    for kind, v in b.items():
        if kind != "real→real":
            print(f"| {model} | {kind} | {pm(v)} | {pm(ref)} | {mean(v) - mean(ref):+.3f} | {permutation_p(ref, v):.3g} |")
print("\n| model | training set | validation, first | validation, second | Δ |\n|---|---|---|---|---|")
for model, kind, a, b in pairs("best_val_mean_class_accuracy"):
    print(f"| {model} | {kind} | {pm(a)} | {pm(b)} | {mean(b) - mean(a):+.3f} |")
