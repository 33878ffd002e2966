"""Per class: how wide the fitted+placed crops show across the line of sight, and how many returns they hold,
whole and with a side occluder fitted to the class's widths (`--fitted-shape occlude`), against the fit half's
real scans (the sensor fitted as `--fit-sensor` does).

    python docs/results/sensor_fit/occluded_by_class.py ../shared/data   (from the repository root)

12 crops per mesh, one seed; medians and quartiles over the class's crops and scans (which stand at different
ranges: the realism tables compare counts at matched range).
"""

import sys

from fit_half import widths_table
from zbuf_occlude.sensors.fit import fit_visible_across_sight


def share_per_mesh(shares, meshes):
    def cells(c):
        s = [shares[m.name] for m in meshes if m.class_name == c]
        return [f"{min(lo for lo, _ in s):.2f}–{max(hi for _, hi in s):.2f}", f"{sum(lo < 1.0 for lo, _ in s)} of {len(s)}"]

    return ["visible share per mesh", "meshes hidden in part"], cells


widths_table(sys.argv[1], fit_visible_across_sight, "visible_across_sight", ("whole", "occluded"), share_per_mesh)
