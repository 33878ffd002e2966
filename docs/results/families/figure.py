"""Figures of compare.sh's runs: per class, real against the street meshes and each family.

usage: python docs/results/families/figure.py OUT KEEP   (OUT: compare.sh's output folder; KEEP: where it copied the tables)

Writes KEEP/shape_CLASS.png (pole, bush, pedestrian: the classes compare.sh ran) from the realism_classes_SET_CLASS.csv tables (each row as
`zbuf-occlude realism` wrote it: the mean share of points per tenth of the height, the median points per crop
in each range bin, the median height / width), and KEEP/crops.png: side views of the first crop of the
first four objects of each simulated set (OUT/scans; the real crops are not drawn: LiDARNet v2 is not
redistributable).
"""

import csv
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from zbuf_occlude.sensors.scan_data import read_scan_npz  # noqa: E402
from zbuf_occlude.sensors.scene.objects import GROUND_ID  # noqa: E402

out, keep = Path(sys.argv[1]), Path(sys.argv[2])
SETS = {
    "pole": ["street", "trunk", "utility_pole", "street_light", "sign_post"],
    "bush": ["street", "shrub", "hedge"],
    "pedestrian": ["street", "pedestrian"],
}
BINS = ["5-10", "10-15", "15-20", "20-25"]


def rows(set_name: str, cls: str) -> dict[str, dict]:
    with open(keep / f"realism_classes_{set_name}_{cls}.csv") as fh:
        return {r["set"]: r for r in csv.DictReader(fh)}


SETS = {cls: [s for s in sets if (keep / f"realism_classes_{s}_{cls}.csv").exists()] for cls, sets in SETS.items()}  # FAMILIES= runs fewer
SETS = {cls: sets for cls, sets in SETS.items() if sets}
for cls, sets in SETS.items():
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(13, 3.8))
    curves = {"real (LiDARNet)": rows(sets[0], cls)["real"]} | {
        f"{s} meshes" if s == "street" else s: rows(s, cls)["generated"] for s in sets
    }
    for i, (name, r) in enumerate(curves.items()):
        style = {"color": "k", "lw": 2.5} if i == 0 else {"lw": 1.5}
        shares = [100 * float(v) for k, v in r.items() if k.startswith("share_")]
        a.plot(shares, (np.arange(10) + 0.5) / 10, marker="o", ms=3, label=name, **style)
        counts = [float(r[f"n_points_by_range_{bn}_m"]) if r[f"n_points_by_range_{bn}_m"] not in ("", "nan") else np.nan for bn in BINS]
        b.plot(range(len(BINS)), counts, marker="o", label=name, **style)
        c.bar(i, float(r["height_to_width"]), color="k" if i == 0 else f"C{i - 1}")
    a.set(xlabel="% of points (mean over crops)", ylabel="height above the crop's bottom, share", title=f"{cls}: vertical profile")
    b.set(
        xticks=range(len(BINS)),
        xticklabels=[f"{bn} m" for bn in BINS],
        yscale="log",
        ylabel="median points per crop",
        title="points per crop by range",
    )
    c.set(xticks=range(len(curves)), xticklabels=list(curves), ylabel="median height / width", title="height / width")
    c.tick_params(axis="x", rotation=30)
    a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(keep / f"shape_{cls}.png", dpi=80)
    plt.close(fig)

panels = [(f"{s}_{cls}", f"street {cls}" if s == "street" else s) for cls, sets in SETS.items() for s in sets]
fig, axes = plt.subplots(len(panels), 4, figsize=(8, 2.1 * len(panels)))
for row, (folder, name) in zip(axes, panels):
    for k, ax in enumerate(row):
        files = sorted((out / "scans" / folder).glob(f"*/{k + 1}/*.npz"))
        ax.set_xticks([]), ax.set_yticks([])
        if not files:
            continue
        s = read_scan_npz(files[0])
        p = s.points.astype(np.float64) @ np.asarray(s.sensor_to_world, dtype=np.float64)[:3, :3].T
        p = p[s.object_id != GROUND_ID]
        if len(p) == 0:
            continue
        # side view across the line of sight: horizontal axis perpendicular to the sensor-object direction
        d = p[:, :2].mean(axis=0)
        u = np.array([-d[1], d[0]]) / np.linalg.norm(d)
        x = p[:, :2] @ u
        ax.scatter(x - x.mean(), p[:, 2] - p[:, 2].min(), s=1, c="C0")
        ax.set_aspect("equal")
        ax.set_title(f"{name} {k + 1}: {len(p)} pts, {np.linalg.norm(d):.0f} m", fontsize=7)
fig.tight_layout()
fig.savefig(keep / "crops.png", dpi=70)
