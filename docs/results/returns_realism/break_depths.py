"""Where real and simulated scan lines break: the range step across each break of a ring's run, per class at 5-10 m.

    .venv/bin/python docs/results/returns_realism/break_depths.py ../shared/data/street_objects \
        ../shared/data/lidarnet_v2_partial --out docs/results/returns_realism/ray_drop

A break is a gap between neighbours along a ring wider than 1.5 azimuth steps
(:func:`~zbuf_occlude.experiments.realism_stats.scan_line_runs`, whose runs come ordered by ring,
then azimuth about the cloud's centroid).  Its depth is the difference in range between the last
point before it and the first after it.  A break at an outline (the line leaves the object and
comes back on a part farther or nearer) is deep; a missed pulse on a surface is shallow.  On the
real fit half (as ``ray_drop.py`` splits it) and on the ``lidar`` set's crops with the returns
runs' sensor file, before and after the fitted ray drop on crowns (``--foliage-dropout``).
Written to ``--out/break_depths.md``.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from measure import CLASSES, fit_half_scans, sim_crops  # noqa: E402

from zbuf_occlude.experiments.partial_echo_crops import MATCHED_RANGE_M  # noqa: E402
from zbuf_occlude.experiments.realism_stats import ring_labels, scan_line_runs  # noqa: E402
from zbuf_occlude.experiments.sim2real.meshes import find_class_meshes  # noqa: E402
from zbuf_occlude.io.atomic import write_text  # noqa: E402
from zbuf_occlude.sensors.kinds import sensor_from_name, with_beam  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def break_depths(p: np.ndarray) -> np.ndarray:
    """The range step (m) across each break of ``p``'s ring runs, in scan_line_runs' order of points."""
    ring, length = scan_line_runs(p)
    centre = p.mean(axis=0)
    azimuth = (np.degrees(np.arctan2(p[:, 1], p[:, 0]) - math.atan2(centre[1], centre[0])) + 180.0) % 360.0 - 180.0
    order = np.lexsort((azimuth, ring_labels(p)))  # by ring, then azimuth: the runs' order
    assert length.sum() == len(p)
    r = np.linalg.norm(p[order], axis=1)
    ends = np.cumsum(length)[:-1]  # first point of each run after the first
    same_ring = ring[1:] == ring[:-1]
    return np.abs(r[ends[same_ring]] - r[ends[same_ring] - 1])


def rows(name: str, clouds: list[tuple[str, np.ndarray]]) -> list[str]:
    out = []
    for c in CLASSES:
        near = [p for k, p in clouds if k == c and MATCHED_RANGE_M[0] <= np.linalg.norm(p.mean(axis=0)) < MATCHED_RANGE_M[1]]
        d = np.concatenate([break_depths(p) for p in near]) if near else np.zeros(0)
        cells = [
            f"{len(d) / max(len(near), 1):.1f}",
            f"{np.median(d):.2f}" if len(d) else "–",
            f"{np.mean(d < 0.1):.2f}" if len(d) else "–",
        ]
        out.append(f"| {c} | {name} | {len(near)} | " + " | ".join(cells) + " |")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("meshes")
    ap.add_argument("real")
    ap.add_argument("--out", required=True)
    ap.add_argument("--sensor", default=os.path.join(HERE, "fit", "hdl32e_footprint.json"))
    ap.add_argument("--foliage-dropout", type=float, default=0.073, help="the fitted ray drop (ray_drop.md; default %(default)s)")
    ap.add_argument("--crops", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    t0, load0 = time.perf_counter(), os.getloadavg()
    real = fit_half_scans(args.real)
    lines = [
        "| class | set | scans at 5-10 m | breaks a scan | median depth of a break, m | share under 0.1 m |",
        "|---|---|---|---|---|---|",
    ]
    lines += rows("real (fit half)", [(s.label, s.points_sensor_m) for s in real])
    meshes = find_class_meshes(args.meshes, up_map={"bush/openglforest__*": "+y"}, classes=list(CLASSES))
    sensor = sensor_from_name(args.sensor)
    for name, s in (
        ("simulated", sensor),
        (f"simulated, foliage_dropout {args.foliage_dropout:g}", with_beam(sensor, foliage_dropout=args.foliage_dropout)),
    ):
        lines += rows(name, [(c["class"], c["points_m"]) for c in sim_crops(meshes, s, args.crops, args.seed)])
    lines.sort(key=lambda row: row.split("|")[1] if row.startswith("| ") and not row.startswith("| class") else "")
    lines += ["", f"{args.crops} crops a mesh, seed {args.seed}; wall {time.perf_counter() - t0:.0f} s, load average {load0[0]:.1f} → "
              f"{os.getloadavg()[0]:.1f}."]  # fmt: skip
    os.makedirs(args.out, exist_ok=True)
    write_text(os.path.join(args.out, "break_depths.md"), "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
