"""Where a sim2real run's mesh-only models err on the FIT half of the real scans, and what those scans look like.

usage: python docs/results/families/fit_half_errors.py RUN [SET]   (from the repository root, ../shared beside it)
  RUN  a folder of `experiment sim2real ... --fit-sensor --validate-on fit-half` runs, one folder per model
       (docs/results/families/sim2real_count24 keeps the tables; the checkpoints stay where the run was made)
  SET  the training set whose checkpoints are read (default lidar)

Only the fit half is read: the half that fitted the sensor and the families and chose every best epoch.  The
scored half, which the results pages report, is never predicted here.  For every model and seed it predicts the
fit half with the set's best checkpoint and prints the confusion summed over seeds; then, over all models and
seeds, the real poles taken for pedestrians in at least 8 of the runs, those taken for pedestrians in fewer, those
never taken, and the real pedestrians: their points, height, width across the line of sight, height / width and
the median of their points' horizontal range (metres, the sensor frame), and per tenth of the height the share of
their points and their width across the line of sight over the height.
"""

from __future__ import annotations

import collections
import sys
from pathlib import Path

import numpy as np

from zbuf_occlude.experiments.sim2real.real import real_clouds, real_halves, real_scan_rows
from zbuf_occlude.learn.training import load_model, predict
from zbuf_occlude.real_scans.datasets import load_real_scans

MODELS = ("pointnet", "voxnet", "3dmfv")
NAMES = ["bush", "car", "pedestrian", "pole"]  # the LiDARNet runs' classes, sorted as the runs sort them
SPLIT_SEED = 20_231  # experiments/sim2real/run.py: _REAL_SPLIT_SEED, the fixed halves of every run


def crop_stats(points: np.ndarray) -> dict:
    """One real crop (sensor frame, z up, metres): its size and, per tenth of its height, share of points and width."""
    z = points[:, 2]
    height = float(np.ptp(z))
    tenth = np.minimum(((z - z.min()) / max(height, 1e-9) * 10).astype(int), 9)
    centre = np.median(points[:, :2], axis=0)
    sight = centre / np.linalg.norm(centre)
    across = points[:, :2] @ np.array([-sight[1], sight[0]])
    width = float(np.ptp(across))
    widths = [np.ptp(across[tenth == k]) if (tenth == k).sum() > 1 else 0.0 for k in range(10)]
    return {"points": len(points), "height": height, "width": width, "ratio": height / max(width, 1e-9),
            "range": float(np.linalg.norm(centre)), "shares": np.bincount(tenth, minlength=10) / len(points),
            "widths": np.asarray(widths) / max(height, 1e-9)}  # fmt: skip


def main() -> None:
    run, kind = Path(sys.argv[1]), sys.argv[2] if len(sys.argv) > 2 else "lidar"
    scans = load_real_scans("../shared/data/lidarnet_v2_partial")
    clouds, labels, _ = real_clouds(scans, NAMES, {}, 256, 0, keep_scale=False)
    kept = real_scan_rows(scans, NAMES, {})
    fit_half, _ = real_halves([scans[i].points for i in kept], labels, SPLIT_SEED)
    stats = [crop_stats(np.asarray(scans[kept[i]].points_sensor_m, np.float64)) for i in fit_half]
    taken = collections.Counter()
    runs = 0
    for model in MODELS:
        confusion = np.zeros((len(NAMES), len(NAMES)), int)
        for best in sorted((run / model / "checkpoints" / kind.replace("+", "_")).glob("seed*/best.pt")):
            net, _ = load_model(best)
            pred, _ = predict(net, clouds[fit_half])
            np.add.at(confusion, (labels[fit_half], pred), 1)
            taken.update(np.flatnonzero((labels[fit_half] == 3) & (pred == 2)).tolist())
            runs += 1
        print(f"\n{model}: fit-half confusion summed over seeds (rows: true {', '.join(NAMES)}; columns: predicted)\n{confusion}")
    poles, people = np.flatnonzero(labels[fit_half] == 3), np.flatnonzero(labels[fit_half] == 2)
    groups = {"poles taken for pedestrians in >= 8 runs": [j for j in poles if taken[j] >= 8],
              "poles taken in 1-7 runs": [j for j in poles if 0 < taken[j] < 8],
              "poles never taken": [j for j in poles if taken[j] == 0], "real pedestrians": list(people)}  # fmt: skip
    print(f"\nover {runs} runs; medians [10th, 90th percentile]")
    for name, rows in groups.items():
        if not rows:
            continue
        cells = " ".join(f"{k} {np.median([stats[j][k] for j in rows]):.2f} [{np.percentile([stats[j][k] for j in rows], 10):.2f}, "
                         f"{np.percentile([stats[j][k] for j in rows], 90):.2f}]" for k in ("points", "height", "width", "ratio", "range"))  # fmt: skip
        shares = " ".join(f"{v:.0f}" for v in 100 * np.mean([stats[j]["shares"] for j in rows], axis=0))
        widths = " ".join(f"{v:.2f}" for v in np.median([stats[j]["widths"] for j in rows], axis=0))
        print(f"{name} ({len(rows)}): {cells}\n  % of points per tenth: {shares}\n  width / height per tenth: {widths}")


if __name__ == "__main__":
    main()
