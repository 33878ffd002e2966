"""Where a sim2real run's mesh-only models err on the FIT half of the real scans, and what those scans look like.

usage: python docs/results/families/fit_half_errors.py RUN [SET]   (from the repository root, ../shared beside it)
  RUN  a folder of `experiment sim2real ... --fit-sensor --validate-on fit-half` runs, one folder per model, each
       with its settings.json and checkpoints (docs/results/families/sim2real_count24 keeps the tables; the
       checkpoints stay where the run was made)
  SET  the training set whose checkpoints are read (default lidar)

Only the fit half is read: the half that fitted the sensor and the families and chose every best epoch.  The
scored half, which the results pages report, is never predicted here.  The real scans, their classes and their
halves are the run's own (its settings.json: ``real``, ``classes``, ``points``, ``label_map``, ``real_split``).  For
every model and seed it predicts the fit half with the set's best checkpoint and prints the confusion summed over
seeds; then, over all models and seeds, the real poles taken for pedestrians in at least 8 of the runs, those taken
in fewer, those never taken, and the real pedestrians: their points, height (m), width across the line of sight
(m, :func:`~zbuf_occlude.sensors.fit.across_sight_width`), height / width as the families fit measures it
(:func:`~zbuf_occlude.experiments.realism_stats.shape_stats`), the median of their points' horizontal range (m,
the sensor frame), and per tenth of the height the share of their points and their width across the line of sight
over the scan's (:func:`~zbuf_occlude.sensors.fit.width_profile`).
"""

from __future__ import annotations

import collections
import json
import sys
from pathlib import Path

import numpy as np

from zbuf_occlude.experiments.realism_stats import shape_stats
from zbuf_occlude.experiments.sim2real.outputs import set_folder
from zbuf_occlude.experiments.sim2real.real import real_clouds, real_halves, real_scan_rows
from zbuf_occlude.learn.training import load_model, predict
from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.sensors.fit import across_sight_width, width_profile

MODELS = ("pointnet", "voxnet", "3dmfv")
POLE, PERSON = "pole", "pedestrian"


def crop_stats(points: np.ndarray) -> dict:
    """One real crop (sensor at the origin, z up, metres): what the page's table shows of it."""
    shape = shape_stats(points)
    return {"points": len(points), "height": shape["height_m"], "width": across_sight_width(points),
            "ratio": shape["height_to_width"], "range": float(np.linalg.norm(np.median(points[:, :2], axis=0))),
            "shares": shape["height_shares"], "widths": width_profile(points)}  # fmt: skip


def main() -> None:
    run, kind = Path(sys.argv[1]), sys.argv[2] if len(sys.argv) > 2 else "lidar"
    models = [m for m in MODELS if (run / m / "settings.json").is_file()]
    settings = json.loads((run / models[0] / "settings.json").read_text(encoding="utf-8"))
    names, label_map = settings["classes"], settings["label_map"]
    scans = load_real_scans(settings["real"])
    clouds, labels, _ = real_clouds(scans, names, label_map, settings["points"], 0, keep_scale=settings["keep_scale"])
    kept = real_scan_rows(scans, names, label_map)
    fit_half, _ = real_halves([scans[i].points for i in kept], labels, settings["real_split"]["seed"])
    stats = [crop_stats(np.asarray(scans[kept[i]].points_sensor_m, np.float64)) for i in fit_half]
    pole, person = names.index(POLE), names.index(PERSON)
    taken = collections.Counter()
    runs = 0
    for model in models:
        confusion = np.zeros((len(names), len(names)), int)
        for best in sorted((run / model / "checkpoints" / set_folder(kind)).glob("seed*/best.pt")):
            net, _ = load_model(best)
            pred, _ = predict(net, clouds[fit_half])
            np.add.at(confusion, (labels[fit_half], pred), 1)
            taken.update(np.flatnonzero((labels[fit_half] == pole) & (pred == person)).tolist())
            runs += 1
        print(f"\n{model}: fit-half confusion summed over seeds (rows: true {', '.join(names)}; columns: predicted)\n{confusion}")
    poles, people = np.flatnonzero(labels[fit_half] == pole), np.flatnonzero(labels[fit_half] == person)
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
        widths = " ".join(f"{v:.2f}" for v in np.nanmedian([stats[j]["widths"] for j in rows], axis=0))
        print(f"{name} ({len(rows)}): {cells}\n  % of points per tenth: {shares}\n  width per tenth / the crop's width: {widths}")


if __name__ == "__main__":
    main()
