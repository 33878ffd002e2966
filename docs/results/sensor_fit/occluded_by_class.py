"""Per class: how wide the fitted+placed crops show across the line of sight, and how many returns they hold,
whole and with a side occluder fitted to the class's widths (`--fitted-shape occlude`), against the fit half's
real scans (the sensor fitted as `--fit-sensor` does).

    python docs/results/sensor_fit/occluded_by_class.py ../shared/data   (from the repository root)

12 crops per mesh, one seed; medians and quartiles over the class's crops and scans (which stand at different
ranges: the realism tables compare counts at matched range).
"""

import collections
import sys
from dataclasses import replace

import numpy as np

from fit_half import load_fit_half
from zbuf_occlude.experiments.sim2real_data import LIDAR_PLACEMENT
from zbuf_occlude.mesh.sizes import size_interval
from zbuf_occlude.sensors.crops import CropDistributions, draw_placement, object_crop
from zbuf_occlude.sensors.fit import across_sight_width, fit_visible_across_sight

f = load_fit_half(sys.argv[1])
scans, kept, names, real_y, fit_half, fitted, placement, sizes, meshes = (f.scans, f.kept, f.names, f.real_y, f.fit_half, f.fitted,
                                                                           f.placement, f.sizes, f.meshes)  # fmt: skip
stats = {"real": collections.defaultdict(list), "whole": collections.defaultdict(list), "occluded": collections.defaultdict(list)}
for i in fit_half:
    p = np.asarray(scans[kept[i]].points_sensor_m, np.float64)
    stats["real"][names[real_y[i]]].append((across_sight_width(p), len(p)))
rng = np.random.default_rng(1)
shares = {}
for m in meshes:
    keywords = dict(placement[m.class_name])
    width_m = keywords.pop("across_sight_width_m")
    keywords.pop("across_sight_profile", None)  # the outline: profile_by_class.py
    dist = CropDistributions(size_m=size_interval(m.mesh.extents, sizes[m.class_name]), **{**LIDAR_PLACEMENT, **keywords})
    shares[m.name] = fit_visible_across_sight(m.mesh, fitted, dist, width_m)
    for tag, d in (("whole", dist), ("occluded", replace(dist, visible_across_sight=shares[m.name]))):
        for k in range(12):
            c = object_crop(m.mesh, fitted, draw_placement(d, rng), seed=k).scan.points
            if len(c) >= 30:  # sim2real's MIN_RETURNS
                stats[tag][m.class_name].append((across_sight_width(c), len(c)))
q = lambda v: f"{np.median(v):.2f} ({np.percentile(v, 25):.2f}–{np.percentile(v, 75):.2f})"  # noqa: E731
print("| class | fitted width, m | real: width, m | returns | whole: width, m | returns | occluded: width, m | returns | visible share per mesh | meshes hidden in part |")
print("|---|---|---|---|---|---|---|---|---|---|")
for c in names:
    cells = [f"{placement[c]['across_sight_width_m'][0]:.2f}–{placement[c]['across_sight_width_m'][1]:.2f}"]
    for tag in stats:
        v = np.array(stats[tag][c])
        cells += [q(v[:, 0]), f"{np.median(v[:, 1]):.0f}"]
    s = [shares[m.name] for m in meshes if m.class_name == c]
    cells += [f"{min(lo for lo, _ in s):.2f}–{max(hi for _, hi in s):.2f}", f"{sum(lo < 1.0 for lo, _ in s)} of {len(s)}"]
    print(f"| {c} | " + " | ".join(cells) + " |")
