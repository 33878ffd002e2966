"""Per class: how wide the fitted+placed crops show across the line of sight, and how many returns they hold,
without and with the width stretch (or, with `occlude`, whole and with a side occluder fitted to the class's
widths, `--fitted-shape occlude`), against the fit half's real scans (the sensor fitted as `--fit-sensor` does).

    python docs/results/sensor_fit/widths_by_class.py ../shared/data [occlude]   (from the repository root)

12 crops per mesh, one seed; medians and quartiles over the class's crops and scans (which stand at different
ranges: the realism tables compare counts at matched range).
"""

import sys

from fit_half import widths_table
from zbuf_occlude.sensors.fit import fit_visible_across_sight, fit_width_scale


def per_mesh(fits, meshes):
    def cells(c):
        s = [fits[m.name] for m in meshes if m.class_name == c]
        span = f"{min(lo for lo, _ in s):.2f}–{max(hi for _, hi in s):.2f}"
        return [span, f"{sum(lo < 1.0 for lo, _ in s)} of {len(s)}"] if occlude else [span]

    return (["visible share per mesh", "meshes hidden in part"] if occlude else ["stretch per mesh"]), cells


occlude = sys.argv[2:] == ["occlude"]
if occlude:
    widths_table(sys.argv[1], fit_visible_across_sight, "visible_across_sight", ("whole", "occluded"), per_mesh)
else:
    widths_table(sys.argv[1], fit_width_scale, "width_scale", ("unstretched", "stretched"), per_mesh)
