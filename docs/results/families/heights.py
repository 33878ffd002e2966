"""How much of each family object its HDL-32E crops show: the object's size from its manifest against its crops' height.

usage: python docs/results/families/heights.py OUT   (OUT: compare.sh's output folder)

Prints a Markdown table, one row per family: objects, median height and largest horizontal extent of the
objects (the manifest's extent_m, metres), crops, median crop height (metres; z extent of the object's
returns) and median crop height over its object's height, and the share of crops showing less than half
of their object's height.  Families are scanned at their own size (compare.sh), so the manifest's height
is the scanned object's.
"""

import json
import sys
from pathlib import Path

import numpy as np

from zbuf_occlude.sensors.scan_data import read_scan_npz
from zbuf_occlude.sensors.scene.objects import GROUND_ID

out = Path(sys.argv[1])
print(
    "| family | objects | median object height, m | median object horizontal extent, m | crops | median crop height, m "
    "| median crop height / object height | crops showing < 1/2 of the height |"
)
print("|---|---|---|---|---|---|---|---|")
for manifest in sorted(out.glob("meshes/*/*.manifest.json")):
    doc = json.loads(manifest.read_text())
    height = {Path(f["path"]).stem: f["extent_m"][2] for f in doc["files"]}
    across = [max(f["extent_m"][:2]) for f in doc["files"]]
    crop_h, share = [], []
    for npz in sorted((out / "scans" / f"{doc['family']}_{doc['class']}").rglob("*.npz")):
        s = read_scan_npz(npz)
        z = (
            (s.points.astype(np.float64) @ np.asarray(s.sensor_to_world, dtype=np.float64)[:3, :3].T)[:, 2]
            if s.frame == "sensor"
            else s.points[:, 2]
        )
        z = z[s.object_id != GROUND_ID]
        if len(z) == 0:
            continue
        crop_h.append(float(np.ptp(z)))
        share.append(crop_h[-1] / height[npz.name.rsplit("_hdl32e_", 1)[0]])
    print(
        f"| {doc['family']} | {len(height)} | {np.median(list(height.values())):.2f} | {np.median(across):.2f} | {len(crop_h)} "
        f"| {np.median(crop_h):.2f} | {np.median(share):.2f} | {np.mean(np.array(share) < 0.5):.2f} |"
    )
