"""Width over height: per class, how wide the scans show across the line of sight in 8 bins of relative height
(0 = the lowest return, 1 = the top), as a fraction of the scan's vertical extent; the median over the scans.
Real fit-half scans against the crops realism.sh wrote for one tag, and per mesh.

    python docs/results/sensor_fit/width_profile.py ../shared/data runs/realism train pedestrian pole
"""

import collections
import subprocess
import sys
from pathlib import Path

import numpy as np

from fit_half import recorded_fit_half
from zbuf_occlude.experiments.sim2real.real import real_clouds, real_scan_rows
from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.sensors.scan_data import read_scan_npz

BINS = 8


def profile(p: np.ndarray) -> np.ndarray:
    """(BINS,) width across the line of sight per relative-height bin, over the vertical extent (NaN: under 2 returns)."""
    c = p[:, :2].mean(axis=0)
    across = p[:, :2] @ (np.array([-c[1], c[0]]) / np.linalg.norm(c))
    extent = max(float(np.ptp(p[:, 2])), 1e-9)
    k = np.minimum(((p[:, 2] - p[:, 2].min()) / extent * BINS).astype(int), BINS - 1)
    return np.array([np.ptp(across[k == b]) if (k == b).sum() >= 2 else np.nan for b in range(BINS)]) / extent


data, realism_out, tag, *classes = sys.argv[1:]
scans = load_real_scans(f"{data}/lidarnet_v2_partial")
names = ["bush", "car", "pedestrian", "pole"]
_, labels, _ = real_clouds(scans, names, {}, 256, 0)
fit_half = recorded_fit_half(labels)
kept = real_scan_rows(scans, names, {})
# the meshes in realism.sh's order (its shell's glob), which numbers their scan folders from 1
LIST = 'for m in "$1"/*.{glb,gltf,dae,obj} "$1"/*/*.{glb,gltf,dae,obj}; do [ -f "$m" ] && echo "$m"; done; true'
meshes = {cls: subprocess.run(["bash", "-c", LIST, "-", f"{data}/street_objects/{cls}"], capture_output=True, text=True, check=True).stdout.split("\n")
          for cls in classes}  # fmt: skip
fmt = lambda v: " | ".join(f"{x:.2f}" for x in np.nanmedian(np.array(v), axis=0))  # noqa: E731
print("| class | scans | " + " | ".join(f"{b / BINS:.3g}–{(b + 1) / BINS:.3g}" for b in range(BINS)) + " |")
print("|---|---|" + "---|" * BINS)
for cls in classes:
    real = [profile(np.asarray(scans[kept[i]].points_sensor_m, np.float64)) for i in fit_half if names[labels[i]] == cls]
    print(f"| {cls} | real | {fmt(real)} |")
    by_mesh = collections.defaultdict(list)
    for path in sorted((Path(realism_out) / f"scans_{tag}_{cls}").glob("*/*.npz")):
        by_mesh[int(path.parent.name)].append(profile(read_scan_npz(path).points.astype(np.float64)))
    print(f"| {cls} | {tag} | {fmt([p for v in by_mesh.values() for p in v])} |")
    for i, v in sorted(by_mesh.items()):  # realism.sh numbers the meshes from 1 in this order
        print(f"| {cls} | {Path(meshes[cls][i - 1]).name} | {fmt(v)} |")
