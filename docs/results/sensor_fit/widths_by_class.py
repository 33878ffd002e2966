"""Per class: how wide the fitted+placed crops show across the line of sight, and how many returns they hold,
without and with the width stretch, against the fit half's real scans (the sensor fitted as `--fit-sensor` does).

    python docs/results/sensor_fit/widths_by_class.py ../shared/data   (from the repository root)

12 crops per mesh, one seed; medians and quartiles over the class's crops and scans (which stand at different
ranges: the realism tables compare counts at matched range).
"""

import sys

from fit_half import widths_table
from zbuf_occlude.sensors.fit import fit_width_scale


def stretch_per_mesh(scales, meshes):
    def cells(c):
        s = [scales[m.name] for m in meshes if m.class_name == c]
        return [f"{min(lo for lo, _ in s):.2f}–{max(hi for _, hi in s):.2f}"]

    return ["stretch per mesh"], cells


widths_table(sys.argv[1], fit_width_scale, "width_scale", ("unstretched", "stretched"), stretch_per_mesh)
