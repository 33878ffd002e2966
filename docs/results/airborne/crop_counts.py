"""Airborne crop point counts per class, for docs/results/airborne.md.

    python docs/results/airborne/crop_counts.py MESH_ROOT [CROPS_PER_MESH] [SENSOR,...] [SIZES] > counts.md

MESH_ROOT holds one folder per class (``car``, ``pedestrian``, ``bush``, ``pole``; e.g.
``../shared/data/street_objects``).  Every mesh is scanned ``CROPS_PER_MESH`` times (default 10)
by each sensor (default ``riegl-q1560,dales-q1560``) the way ``experiment sim2real --sensor``
makes its lidar set: real size drawn from the class table (``zbuf_occlude.mesh.sizes``, changed
by ``SIZES`` as ``--sizes``, e.g. ``pole=height:6-12``), the
placement of ``LIDAR_PLACEMENT``, the farm's per-object crop function, same seeds.  Crops with no
return count as 0 (the crop function leaves them out).  Prints a Markdown table per class and
sensor: crops, median, 10th–90th percentile, min–max returns, share of crops with at least
``MIN_RETURNS`` returns, and seconds per crop; then the median per mesh.
"""

from __future__ import annotations

import logging
import sys
import time

import numpy as np

from zbuf_occlude.sensors.fit.class_placement import MIN_RETURNS
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes
from zbuf_occlude.sensors.fit.class_placement import LIDAR_PLACEMENT
from zbuf_occlude.mesh.sizes import parse_sizes, size_interval
from zbuf_occlude.sensors.crops import lidar_object_samples
from zbuf_occlude.sensors.placement import CropDistributions
from zbuf_occlude.sensors.kinds import sensor_from_name

#: The one mesh of street_objects that breaks its format's up-axis convention (docs/results/sim2real.md).
UP_MAP = {"bush/openglforest__*": "+y"}


def main(argv: list[str]) -> None:
    logging.basicConfig(level=logging.WARNING)
    root = argv[0]
    per_mesh = int(argv[1]) if len(argv) > 1 else 10
    sensors = (argv[2] if len(argv) > 2 else "riegl-q1560,dales-q1560").split(",")
    sizes = parse_sizes(argv[3] if len(argv) > 3 else None)
    meshes = find_class_meshes(root, up_map=UP_MAP)
    print(
        f"{len(meshes)} meshes, {per_mesh} crops each, seed 0; sizes: "
        + ", ".join(f"{c} {s.dimension} {s.lo_m:g}–{s.hi_m:g} m" for c, s in sorted(sizes.items()))
        + "\n"
    )
    print(f"| class | sensor | crops | median | 10th–90th pct | min–max | ≥ {MIN_RETURNS} returns | s / crop |")
    print("|---|---|---|---|---|---|---|---|")
    per_mesh_median: dict[str, dict[str, float]] = {}
    for cls in sorted({m.class_name for m in meshes}):
        for name in sensors:
            sensor = sensor_from_name(name)
            counts, t0 = [], time.perf_counter()
            for entry in (m for m in meshes if m.class_name == cls):
                dist = CropDistributions(size_m=size_interval(entry.mesh.extents, sizes[cls]), **LIDAR_PLACEMENT)
                clouds = lidar_object_samples(entry.mesh, sensor, name=entry.name, n_samples=per_mesh, n_points=256,
                                              seed=0, distributions=dist, class_name=cls)  # fmt: skip
                mine = [c.n_visible for c in clouds] + [0] * (per_mesh - len(clouds))
                per_mesh_median.setdefault(entry.name, {})[sensor.name] = float(np.median(mine))
                counts += mine
            seconds = (time.perf_counter() - t0) / len(counts)
            c = np.asarray(counts)
            p10, p50, p90 = np.percentile(c, [10, 50, 90])
            print(
                f"| {cls} | {sensor.name} | {len(c)} | {p50:.0f} | {p10:.0f}–{p90:.0f} | {c.min()}–{c.max()} | "
                f"{np.mean(c >= MIN_RETURNS):.0%} | {seconds:.3f} |"
            )

    names = [sensor_from_name(name).name for name in sensors]
    print("\n| mesh | " + " | ".join(f"median, {n}" for n in names) + " |")
    print("|---|" + "---|" * len(names))
    for mesh, row in per_mesh_median.items():
        print(f"| {mesh} | " + " | ".join(f"{row[n]:.0f}" for n in names) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
