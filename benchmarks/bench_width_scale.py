"""Cost of ``zbuf_occlude.sensors.fit.fit_width_scale`` per mesh, and of ``fit_object_shape`` with an outline or a side occluder beside it (not a test; prints a Markdown table).

Each mesh (a folder's mesh files, its class the folder above the file) is scaled to ``--height``,
placed ``--distance`` from an HDL-32E and stretched to ``--width`` across the line of sight: 16
crops at its own proportions (more while it shows no width), 16 at the stretch they ask for.
Wall time per mesh, the stretch found, and the total: what a ``sim2real --fit-sensor`` run spends
once on its meshes and ``farm --sensor-across-sight-width`` once per object.  With ``--outline``,
each mesh is then also fitted to that outline and stretched again under the warp
(``fit_object_shape``, what ``sim2real --fitted-shape widths,outline`` and ``scan --outline
--across-sight-width`` do), right after, so the two columns share the machine's load.  With
``--occlude``, each mesh is instead fitted the visible share that a side occluder leaves
(``fit_visible_across_sight``, what ``sim2real --fitted-shape occlude`` and ``scan --occlude`` do),
right after its width fit, and 16 of its crops are scanned with and without that occluder.

    python benchmarks/bench_width_scale.py data/samples
    python benchmarks/bench_width_scale.py ../shared/data/street_objects --height 1.5:3 --width 0.2:0.5 --outline 1.4,0.8,1,1,1.2,1.5,1.4,0.8
    python benchmarks/bench_width_scale.py ../shared/data/street_objects --height 1.5:3 --width 1.1:3.3 --occlude
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

from zbuf_occlude.mesh.formats import SUPPORTED_EXTENSIONS
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.mesh.sizes import SizeRange, size_interval
from zbuf_occlude.sensors.crops import object_crop
from zbuf_occlude.sensors.placement import CropDistributions, draw_placement
from zbuf_occlude.sensors.fit import fit_object_shape, fit_visible_across_sight, fit_width_scale
from zbuf_occlude.sensors.patterns.spinning import Lidar


def _interval(text: str) -> tuple[float, float]:
    lo, _, hi = text.partition(":")
    return float(lo), float(hi or lo)


def _rng(k: int) -> np.random.Generator:
    return np.random.default_rng([0x0CC1, k])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", type=Path, help="a folder of mesh files (searched recursively)")
    ap.add_argument("--height", type=_interval, default=(1.0, 2.0), help="object height, metres, LO:HI (default 1:2)")
    ap.add_argument("--distance", type=_interval, default=(4.0, 12.0), help="sensor distance, metres, LO:HI (default 4:12)")
    ap.add_argument("--width", type=_interval, default=(0.3, 0.6), help="across-sight width, metres, LO:HI (default 0.3:0.6)")
    ap.add_argument("--outline", type=lambda t: tuple(float(v) for v in t.split(",")), help="also time the fit to this outline, V,V,...")
    ap.add_argument("--occlude", action="store_true", help="also time the side occluder's fit, and 16 crops with and without it")
    args = ap.parse_args()
    if args.occlude and args.outline:
        ap.error("--occlude and --outline time different fits: give one")
    paths = sorted(p for p in args.root.rglob("*") if p.suffix.lower() in SUPPORTED_EXTENSIONS and p.is_file())
    sensor = Lidar.preset("hdl32e")
    print(
        f"# bench_width_scale: {len(paths)} meshes under {args.root}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f} at the start\n"
    )
    if args.occlude:
        print("| mesh | s | stretch | occluder fit, s | visible share | 16 crops whole, s | occluded, s |\n|---|---|---|---|---|---|---|")
    else:
        print("| mesh | s | stretch |" + (" with the outline, s | ratio |\n|---|---|---|---|---|" if args.outline else "\n|---|---|---|"))
    times, shaped, crops = [], [], []
    for path in paths:
        mesh = load_mesh(path)
        dist = CropDistributions(distance_m=args.distance, size_m=size_interval(mesh.extents, SizeRange("height", *args.height)))
        t0 = time.perf_counter()
        lo, hi = fit_width_scale(mesh, sensor, dist, args.width)
        times.append(time.perf_counter() - t0)
        row = f"| {path.relative_to(args.root)} | {times[-1]:.2f} | {lo:.2f}–{hi:.2f} |"
        if args.outline:
            t0 = time.perf_counter()
            fit_object_shape(mesh, sensor, dist, args.width, args.outline)
            shaped.append(time.perf_counter() - t0)
            row += f" {shaped[-1]:.2f} | {shaped[-1] / times[-1]:.2f} |"
        if args.occlude:
            t0 = time.perf_counter()
            share = fit_visible_across_sight(mesh, sensor, dist, args.width)
            shaped.append(time.perf_counter() - t0)
            pair = []
            for d in (dist, CropDistributions(distance_m=args.distance, size_m=dist.size_m, visible_across_sight=share)):
                t0 = time.perf_counter()
                for k in range(16):
                    object_crop(mesh, sensor, draw_placement(d, _rng(k)), seed=k)
                pair.append(time.perf_counter() - t0)
            crops.append(pair)
            row += f" {shaped[-1]:.2f} | {share[0]:.2f}–{share[1]:.2f} | {pair[0]:.2f} | {pair[1]:.2f} |"
        print(row, flush=True)
    print(
        f"\ntotal {sum(times):.1f} s, median {statistics.median(times):.2f} s, max {max(times):.2f} s per mesh; "
        f"load {os.getloadavg()[0]:.2f} at the end"
    )
    if crops:
        print(
            f"occluder fit: total {sum(shaped):.1f} s, median {statistics.median(shaped):.2f} s per mesh, median ratio to the "
            f"stretch's {statistics.median(b / a for a, b in zip(times, shaped)):.2f}; 16 crops: whole {sum(a for a, _ in crops):.1f} s, "
            f"occluded {sum(b for _, b in crops):.1f} s, median ratio {statistics.median(b / a for a, b in crops):.2f}"
        )
    elif shaped:
        print(
            f"with the outline: total {sum(shaped):.1f} s, median {statistics.median(shaped):.2f} s per mesh, "
            f"median ratio {statistics.median(b / a for a, b in zip(times, shaped)):.2f}"
        )


if __name__ == "__main__":
    main()
