"""The README's sensor figure: a simulated HDL-32E scan of a shipped mesh beside a real LiDARNet
v2 car of similar size and range (needs ../shared/data/lidarnet_v2_partial).

    python docs/sensors/make_figure.py [--real ../shared/data/lidarnet_v2_partial/Car/car12.csv]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import zbuf_occlude.sensors as S
from zbuf_occlude.experiments.realism import read_object_clouds
from zbuf_occlude.sensors.crops import object_crop
from zbuf_occlude.sensors.placement import Placement

ROOT = Path(__file__).resolve().parents[2]
MESH = ROOT / "data" / "samples" / "bed" / "train" / "bed_0001.off"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--real", default=str(ROOT.parent / "shared" / "data" / "lidarnet_v2_partial" / "Car"))
    ap.add_argument("--out", default=str(Path(__file__).with_name("scan_vs_lidarnet.png")))
    args = ap.parse_args()
    real_all = read_object_clouds(args.real)
    # A real car near 6.5 m with a typical point count.
    ranges = np.array([np.linalg.norm(c.points_m.mean(0)) for c in real_all])
    counts = np.array([len(c.points_m) for c in real_all])
    pick = int(np.argmin(np.abs(ranges - 6.5) + 0.002 * np.abs(counts - np.median(counts))))
    real = real_all[pick]
    centre = real.points_m.mean(0)
    az_deg = math.degrees(math.atan2(centre[1], centre[0]))
    dist = float(np.hypot(centre[0], centre[1]))
    placement = Placement(
        distance_m=dist, height_m=1.8, azimuth_deg=az_deg, yaw_deg=az_deg + 90.0 + 20.0, size_m=4.5, extents_m=(1.8, 4.5, 1.5)
    )
    sim = object_crop(str(MESH), S.Lidar.preset("hdl32e"), placement, seed=0).scan.points.astype(float)
    fig, ax = plt.subplots(2, 2, figsize=(11, 6.5))
    for col, (pts, title) in enumerate(((sim, f"simulated HDL-32E: {MESH.name} stretched to 4.5×1.8×1.5 m, {dist:.1f} m, {len(sim)} points"),
                                         (real.points_m, f"real LiDARNet v2 {Path(real.source).name}, {ranges[pick]:.1f} m, {len(real.points_m)} points"))):  # fmt: skip
        r = np.linalg.norm(pts, axis=1)
        az = np.degrees(np.arctan2(pts[:, 1], pts[:, 0]))
        el = np.degrees(np.arcsin(pts[:, 2] / r))
        ax[0, col].scatter(az, el, s=2, c=el, cmap="viridis")
        ax[0, col].set(xlabel="azimuth, deg", ylabel="elevation, deg", title=title)
        ax[0, col].title.set_fontsize(8)
        ax[1, col].scatter(pts[:, 0], pts[:, 1], s=2, c=el, cmap="viridis")
        ax[1, col].set(xlabel="x, m (sensor frame)", ylabel="y, m", aspect="equal")
    fig.tight_layout()
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
