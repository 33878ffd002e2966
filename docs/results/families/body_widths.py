"""How broad pedestrian crops are at their legs, chest and head, across the line of sight.

usage: python docs/results/families/body_widths.py NAME=FOLDER [NAME=FOLDER ...]

FOLDER: real scans or simulated crops, anything ``zbuf_occlude.real_scans.datasets.load_real_scans``
reads (sensor at the origin, z up, metres).  Per crop, the width across the line of sight (the
direction ``zbuf_occlude.sensors.fit.sight_coordinates`` gives, as ``realism`` measures) is the
5th-95th percentile spread of its points in a height band, with four points at least: the legs 0.15-0.45 m above the crop's lowest
return, the chest 0.3-0.6 m below its highest, the head its top 0.2 m; and the chest's spread along
the line of sight.  Prints a Markdown table: per folder, crops, then the 10th, 25th, 50th, 75th and
90th percentiles of each width over the crops, metres.
"""

import sys

import numpy as np

from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.sensors.fit import sight_coordinates


def _spread(values: np.ndarray, band: np.ndarray) -> float:
    return float(np.subtract(*np.percentile(values[band], [95, 5]))) if band.sum() >= 4 else np.nan


def widths(points: np.ndarray) -> tuple[float, float, float, float]:
    """Legs, chest and head across the line of sight, and the chest along it (metres)."""
    z = points[:, 2] - points[:, 2].min()
    top = z.max()
    along, across = sight_coordinates(points).T
    chest = (z > top - 0.6) & (z < top - 0.3)
    return _spread(across, (z > 0.15) & (z < 0.45)), _spread(across, chest), _spread(across, z > top - 0.2), _spread(along, chest)


print("| crops | n | legs across | chest across | head across | chest along |")
print("|---|---|---|---|---|---|")
for arg in sys.argv[1:]:
    name, folder = arg.split("=", 1)
    rows = np.array([widths(np.asarray(s.points_sensor_m, np.float64)) for s in load_real_scans(folder)])
    cells = [" ".join(f"{v:.2f}" for v in np.nanpercentile(column, (10, 25, 50, 75, 90))) for column in rows.T]
    print(f"| {name} | {len(rows)} | " + " | ".join(cells) + " |")
