"""The bias of the default footprint cast on the ``lidar`` set's crops: adaptive against exact, per class.

    .venv/bin/python docs/results/returns_realism/adaptive_bias.py ../shared/data/street_objects \
        --out docs/results/returns_realism/adaptive_bias

``scan``'s default cast, ``footprint="auto"``, is the adaptive footprint wherever a beam resolves a
footprint's echoes (:mod:`zbuf_occlude.sensors.beam.adaptive_cast`): a pulse's sub-rays are cast
only where its centre ray and its neighbouring pulses do not show one plane filling the
footprint.  Its one error is the echo of a surface inside the cone that none of those rays
meets.  This script scans the ``lidar`` set's crops of every mesh (``measure.sim_crops``:
``experiment sim2real``'s placements, meshes and rule) twice with each sensor, ``"exact"`` then
``"auto"``, on the same draws, and compares them crop by crop: points, outline points (points that
end a run of their ring's scan line, :func:`~zbuf_occlude.experiments.realism.outline_mask`),
returns 2 and later, and the crops whose points differ at all.  The sensors are those of the
sim2real runs with returns: ``--returns 2`` on the HDL-32E preset and the sensor file
``fit/hdl32e_footprint.json`` (the strongest echo of a 7-ray footprint).  The CPU time of each
cast is the sum over its crops (the two casts run one after the other, sensor by sensor, so a
load change hits them alike only roughly: the benchmark ``benchmarks/bench_returns.py`` times
them interleaved).

Writes ``by_class.csv`` and ``by_class.md`` to ``--out``, with the load average and the times.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from measure import CLASSES, per_crop, sim_crops  # noqa: E402

from zbuf_occlude.sensors.request import kept_returns  # noqa: E402
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes  # noqa: E402
from zbuf_occlude.io.atomic import write_csv, write_text  # noqa: E402
from zbuf_occlude.sensors import Lidar  # noqa: E402
from zbuf_occlude.sensors.kinds import sensor_from_name  # noqa: E402

log = logging.getLogger("adaptive_bias")
HERE = Path(__file__).resolve().parent
#: The sensors compared: a name and a function of nothing (each is made once).
SENSORS = (
    ("--returns 2", lambda: kept_returns(Lidar.preset("hdl32e"), 2)),
    ("hdl32e_footprint.json", lambda: sensor_from_name(str(HERE / "fit" / "hdl32e_footprint.json"))),
)


def compare(exact: list[dict], fast: list[dict], cls: str) -> dict:
    """One class's paired crops of the two casts: medians, sums and the crops that differ."""
    a = {(c["mesh"], c["crop"]): c for c in exact if c["class"] == cls}
    b = {(c["mesh"], c["crop"]): c for c in fast if c["class"] == cls}
    keys = sorted(set(a) & set(b))
    sa, sb = [per_crop(a[k]) for k in keys], [per_crop(b[k]) for k in keys]
    points_a, points_b = np.array([s["n_points"] for s in sa]), np.array([s["n_points"] for s in sb])
    differ = [k for k in keys if len(a[k]["points_m"]) != len(b[k]["points_m"]) or not np.array_equal(a[k]["points_m"], b[k]["points_m"])]
    later_a = sum(s["return_2plus"] for s in sa)
    later_b = sum(s["return_2plus"] for s in sb)
    return {
        "class": cls, "paired_crops": len(keys), "crops_only_exact": len(set(a) - set(b)), "crops_only_auto": len(set(b) - set(a)),
        "crops_with_other_points": len(differ), "points_exact": int(points_a.sum()), "points_auto": int(points_b.sum()),
        "points_difference": int(points_b.sum() - points_a.sum()),
        "largest_crop_difference": int(np.abs(points_b - points_a).max()) if len(keys) else 0,
        "outline_points_exact": int(sum(s["outline_points"] for s in sa)), "outline_points_auto": int(sum(s["outline_points"] for s in sb)),
        "returns_2plus_exact": int(later_a), "returns_2plus_auto": int(later_b),
    }  # fmt: skip


def markdown(rows: list[dict], times: dict) -> str:
    head = ("| sensor | class | paired crops | crops with other points | points exact → auto | largest difference in a crop | "
            "outline points exact → auto | returns 2+ exact → auto |\n|---|---|---|---|---|---|---|---|\n")  # fmt: skip
    body = "".join(
        f"| {r['sensor']} | {r['class']} | {r['paired_crops']} | {r['crops_with_other_points']} | {r['points_exact']:,} → "
        f"{r['points_auto']:,} ({r['points_difference']:+,}) | {r['largest_crop_difference']} | {r['outline_points_exact']:,} → "
        f"{r['outline_points_auto']:,} | {r['returns_2plus_exact']:,} → {r['returns_2plus_auto']:,} |\n"
        for r in rows
    )
    cpu = "".join(
        f"* {name}: exact {t['exact']:.0f} s, auto {t['auto']:.0f} s CPU ({t['exact'] / t['auto']:.2f}×)\n" for name, t in times.items()
    )
    return head + body + "\nCPU time of the crops (each cast once, one after the other):\n\n" + cpu


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("meshes", help="class folders of meshes (street_objects)")
    ap.add_argument("--out", required=True, help="folder for by_class.csv and by_class.md")
    ap.add_argument("--crops", type=int, default=4, help="crops per mesh (default %(default)s)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--up-map", default="bush/openglforest__*=+y", help="GLOB=AXIS,... as experiment sim2real's (default %(default)s)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    t0, load0 = time.perf_counter(), os.getloadavg()
    up_map = dict(pair.split("=", 1) for pair in args.up_map.split(",") if pair)
    meshes = find_class_meshes(args.meshes, up_map=up_map, classes=list(CLASSES))
    rows, times = [], {}
    for name, make in SENSORS:
        sensor, crops, times[name] = make(), {}, {}
        for cast in ("exact", "auto"):
            cpu = time.process_time()
            crops[cast] = sim_crops(meshes, sensor, args.crops, args.seed, footprint=cast)
            times[name][cast] = time.process_time() - cpu
            log.info("%s, %s: %d crops in %.0f s CPU", name, cast, len(crops[cast]), times[name][cast])
        rows += [{"sensor": name, **compare(crops["exact"], crops["auto"], cls)} for cls in CLASSES]
    os.makedirs(args.out, exist_ok=True)
    write_csv(os.path.join(args.out, "by_class.csv"), rows)
    wall, load1 = time.perf_counter() - t0, os.getloadavg()
    note = (f"{len(meshes)} meshes, {args.crops} crops per mesh, seed {args.seed}; {wall:.0f} s wall; load average "
            f"{load0[0]:.2f} → {load1[0]:.2f} (1 min)\n\n")  # fmt: skip
    write_text(os.path.join(args.out, "by_class.md"), note + markdown(rows, times))
    print(note + markdown(rows, times))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
