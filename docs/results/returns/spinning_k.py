"""Sub-rays per pulse for a spinning LiDAR: returns per pulse on trees and bushes, and the cost, against K.

    python docs/results/returns/spinning_k.py MESH_FOLDER OUT_CSV > spinning_k.md

The Velodyne HDL-32E preset (its data-sheet divergence, ``Lidar.preset("hdl32e")``) with several
returns per pulse (4, range resolution 0.75 m: a 5 ns pulse) scans the eight meshes of
street_objects/bush at their real sizes (experiments.returns.PLOT_TREES), standing 10, 15 and 20 m
from the sensor around it, on flat ground; no reflectance and no threshold: every echo returns, so
the smallest partial echoes count (the case that needs the most sub-rays).  Per K: the shares of
the pulses meeting a mesh with 1, 2, 3 and 4 returns (object_pulse_shares: a bootstrap over
those pulses), and the cost of the scan per pulse (median of interleaved rounds, the order of
the K rotated each round), against K = 1 with the multi-return model on and against today's
scan (one ray, one return).  The recommended K: returns_comparison.recommend_k, the airborne sweep's
rule (the smallest K whose four shares lie within 1.96 combined sd of the largest K's).
"""

from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

from zbuf_occlude.experiments.returns import PLOT_TREES, object_pulse_shares
from zbuf_occlude.experiments.returns_comparison import recommend_k
from zbuf_occlude.io.atomic import write_csv
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.sensors import Lidar, scan, with_beam
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject

K_VALUES = (1, 7, 19, 37, 61)
DISTANCES_M = (10.0, 15.0, 20.0)
ROUNDS = 3
BOOTSTRAP = 200


def scene(mesh_root: str) -> ScanScene:
    rng = np.random.default_rng(0)
    objects = []
    for i, tree in enumerate(PLOT_TREES):
        azimuth = math.radians(45.0 * i)
        distance = DISTANCES_M[i % len(DISTANCES_M)]
        objects.append(SceneObject(load_mesh(f"{mesh_root}/{tree.file}", up=tree.up), class_name="vegetation",
                                   position_m=(distance * math.cos(azimuth), distance * math.sin(azimuth)),
                                   yaw_deg=float(rng.uniform(0.0, 360.0)), size_m=tree.size_m))  # fmt: skip
    return ScanScene(objects=objects, ground=True, ground_half_extent_m=40.0)


def sensor(k: int | None) -> Lidar:
    if k is None:  # today's scan: one ray, one return
        return Lidar.preset("hdl32e")
    return with_beam(Lidar.preset("hdl32e"), footprint_rays=k, max_returns=4, range_resolution_m=0.75)


def main(mesh_root: str, out_csv: str) -> None:
    load_start, cpu_start = os.getloadavg(), time.process_time()
    plot = scene(mesh_root)
    ids = list(range(1, len(plot.objects) + 1))
    rows = {}
    for k in K_VALUES:
        shares, n = object_pulse_shares(scan(plot, sensor(k), seed=0, footprint="exact"), ids, seed=0, bootstrap=BOOTSTRAP)
        rows[k] = {"K": k, "pulses_on_meshes": n} | {f"returns_{j}": shares[f"returns_{j}"][0] for j in (1, 2, 3, 4)} | {
            f"returns_{j}_sd": shares[f"returns_{j}"][1] for j in (1, 2, 3, 4)}  # fmt: skip
    times: dict = {k: [] for k in (None, *K_VALUES)}
    order = [None, *K_VALUES]
    for r in range(ROUNDS):
        for k in order[r % len(order) :] + order[: r % len(order)]:  # rotated: each K in another place each round
            lidar = sensor(k)
            start = time.perf_counter()
            s = scan(plot, lidar, seed=r, footprint="exact")
            times[k].append((time.perf_counter() - start) / s.meta["n_rays"])
    pulses = len(sensor(1).rays()[0])
    median = {k: float(np.median(v)) for k, v in times.items()}
    for k, row in rows.items():
        row["us_per_pulse"] = median[k] * 1e6
        row["cost_vs_K1"] = median[k] / median[1]
        row["cost_vs_today"] = median[k] / median[None]
    best = recommend_k(list(rows.values()))
    load_end = os.getloadavg()
    print(f"HDL-32E, {pulses:,} pulses a revolution; {len(plot.objects)} meshes at {', '.join(f'{d:g}' for d in DISTANCES_M)} m; "
          f"today's scan {median[None] * 1e6:.2f} µs per pulse\n")  # fmt: skip
    print(
        "| K | pulses on the meshes with 1 / 2 / 3 / 4 returns (%, ± sd) | pulses on the meshes | µs per pulse | cost / K = 1 | cost / today's scan |"
    )
    print("|---|---|---|---|---|---|")
    for k, row in rows.items():
        shares = " / ".join(f"{100 * row[f'returns_{j}']:.1f} ± {100 * row[f'returns_{j}_sd']:.1f}" for j in (1, 2, 3, 4))
        mark = " **(recommended)**" if k == best else ""
        print(
            f"| {k}{mark} | {shares} | {row['pulses_on_meshes']:,} | {row['us_per_pulse']:.2f} | {row['cost_vs_K1']:.1f}× | {row['cost_vs_today']:.1f}× |"
        )
    print(f"\nrecommended K {best}; load average {', '.join(f'{v:.2f}' for v in load_start)} at the start, "
          f"{', '.join(f'{v:.2f}' for v in load_end)} at the end; {time.process_time() - cpu_start:.0f} CPU seconds")  # fmt: skip
    write_csv(out_csv, list(rows.values()))


if __name__ == "__main__":
    main(*sys.argv[1:3])
