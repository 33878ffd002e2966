"""Real and simulated car crops by range: returns, rings, visible height, lowest and top return, width.

    python docs/results/sensor_fit/car_ranges.py ../shared/data runs/realism   (from the repository root)

The second argument is the OUT of realism.sh; its scans_{placed,hidden,occluded}_car folders are read where present.
Heights are z in the sensor's frame (z up, metres; the fitted ground lies 1.81 m below the sensor); medians per bin.
Then the slope of the real cars' lowest return over their distance (Theil-Sen, and least squares).
"""

import sys
from pathlib import Path

import numpy as np
from scipy.stats import theilslopes

from zbuf_occlude.experiments.realism import cloud_stats, read_object_clouds


def rows(name: str, clouds: list) -> None:
    stats = [cloud_stats(c) for c in clouds]
    r = np.array([s["range_m"] for s in stats])
    cols = {
        "returns": np.array([s["n_points"] for s in stats], np.float64),
        "rings": np.array([s["n_rings"] for s in stats], np.float64),
        "visible height": np.array([s["vertical_extent_m"] for s in stats]),
        "lowest z": np.array([c.points_m[:, 2].min() for c in clouds]),
        "top z": np.array([c.points_m[:, 2].max() for c in clouds]),
        "width": np.array([s["across_sight_width_m"] for s in stats]),
    }
    for lo, hi in ((3, 5), (5, 7), (7, 9)):
        k = (r >= lo) & (r < hi)
        if k.any():
            cells = [f"{np.median(v[k]):.0f}" if n in ("returns", "rings") else f"{np.median(v[k]):.2f}" for n, v in cols.items()]
            print(f"| {name} | {lo}–{hi} m | {int(k.sum())} | " + " | ".join(cells) + " |")


data, out = sys.argv[1], Path(sys.argv[2])
print("| crops | range | clouds | returns | rings | visible height, m | lowest z, m | top z, m | width, m |")
print("|---|---|---|---|---|---|---|---|---|")
real = read_object_clouds(Path(data) / "lidarnet_v2_partial" / "Car")
rows("real", real)
for tag in ("placed", "hidden", "occluded"):
    if (out / f"scans_{tag}_car").is_dir():
        rows(tag, read_object_clouds(out / f"scans_{tag}_car"))

bottom = np.array([c.points_m[:, 2].min() for c in real])
distance = np.array([np.hypot(*c.points_m[:, :2].mean(axis=0)) for c in real])
slope, _, lo, hi = theilslopes(bottom, distance)
print(
    f"\nreal cars' lowest return over distance: Theil-Sen {slope:.3f} m/m (95 % {lo:.3f} to {hi:.3f}), "
    f"least squares {np.polyfit(distance, bottom, 1)[0]:.3f} m/m, {len(real)} cars"
)
