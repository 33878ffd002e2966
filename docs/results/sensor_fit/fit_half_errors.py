"""Where a training set's models err on the fit half (the real scans the sensor was fitted to and the
mesh-only sets validated on; never the scored half), from the best checkpoints a sim2real run kept.

    python docs/results/sensor_fit/fit_half_errors.py ../shared/data RUN_ROOT [SET]   (from the repository root)

RUN_ROOT holds MODEL/checkpoints/SET/seedK/best.pt for pointnet, voxnet and 3dmfv (the runs' --out folders);
SET defaults to fitted+placed. Prints each model's fit-half confusion summed over its seeds, then the scans
most of the runs get wrong, with their returns and extents (x, y, z in the scans' own frame, metres).
"""

import sys
from pathlib import Path

import numpy as np

from fit_half import recorded_fit_half
from zbuf_occlude.experiments.sim2real.real import real_clouds, real_scan_rows
from zbuf_occlude.learn.training import load_model, predict
from zbuf_occlude.real_scans import load_real_scans

data, root = sys.argv[1], Path(sys.argv[2])
kind = sys.argv[3] if len(sys.argv) > 3 else "fitted+placed"
scans = load_real_scans(f"{data}/lidarnet_v2_partial")
names = sorted(p.name for p in Path(f"{data}/street_objects").iterdir() if p.is_dir())
pts, y, _ = real_clouds(scans, names, {}, 256, 0)
half = recorded_fit_half(y)
kept = real_scan_rows(scans, names, {})
x, truth = pts[half], y[half]
preds = {}
print(f"| model | runs | {' | '.join(f'acc. {n}' for n in names)} | mean | errors (true → predicted, summed over the runs) |")
print("|---|---|" + "---|" * len(names) + "---|---|")
for model in ("pointnet", "voxnet", "3dmfv"):
    seeds = sorted((root / model / "checkpoints" / kind).glob("seed*/best.pt"))
    cm = np.zeros((len(names), len(names)), int)
    for path in seeds:
        net, _ = load_model(path)
        p, _ = predict(net, x)
        preds[(model, path.parent.name)] = p
        np.add.at(cm, (truth, p), 1)
    acc = np.diag(cm) / cm.sum(1)
    worst = sorted(
        ((cm[i, j], f"{names[i]} → {names[j]} {cm[i, j]}") for i in range(len(names)) for j in range(len(names)) if i != j), reverse=True
    )
    print(
        f"| {model} | {len(seeds)} | "
        + " | ".join(f"{a:.3f}" for a in acc)
        + f" | {acc.mean():.3f} | "
        + ", ".join(w for _, w in worst[:4])
        + " |"
    )
wrong = sum((p != truth).astype(int) for p in preds.values())
print("\n| scan | class | wrong in | called | returns | extent x, y, z, m |\n|---|---|---|---|---|---|")
for i in np.argsort(-wrong, kind="stable")[:20]:
    s = scans[kept[half[i]]]
    called = sorted({names[p[i]] for p in preds.values()} - {names[truth[i]]})
    ext = " × ".join(f"{v:.2f}" for v in np.asarray(s.extent_m))
    print(f"| {Path(s.source).name} | {names[truth[i]]} | {wrong[i]} of {len(preds)} | {', '.join(called)} | {len(s.points)} | {ext} |")
