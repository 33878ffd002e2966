"""Ray drop on vegetation: how many firings real HDL-32E scans lose per class, and the beam's ``foliage_dropout`` fitted from it.

    .venv/bin/python docs/results/returns_realism/ray_drop.py ../shared/data/street_objects \
        ../shared/data/lidarnet_v2_partial --out docs/results/returns_realism/ray_drop

The real LiDARNet v2 scans are split as ``experiment sim2real`` splits them; only the fit half is
read (the scored half is not read beyond the split).  The measure is ``fit-sensor``'s dropout
(:func:`~zbuf_occlude.sensors.fit.fit_lidar`: firings missing in gaps of at most 4 azimuth steps
along a ring's run over the object, pooled over scans, bootstrap over scans), per class, on the
real scans and on the ``lidar`` set's crops of the street_objects meshes
(:func:`~zbuf_occlude.experiments.partial_echo_crops.mesh_crops`, sim2real's placements) scanned
with the sensor file of the returns runs (``--sensor``: a 7-ray footprint, the strongest echo).

The fit (:func:`~zbuf_occlude.sensors.fit.fit_foliage_dropout`): the real bushes keep
``1 − p_crown`` of their firings where the other classes (pooled) keep ``1 − p_solid``; the
simulated crops' geometry alone gives the same two figures.  A crown surface's ray drop ``f``
(:attr:`Beam.foliage_dropout <zbuf_occlude.sensors.beam.Beam.foliage_dropout>`) multiplies the
simulated bushes' share by ``1 − f``, so ``f = 1 − S_real / S_sim`` with
``S = (1 − p_crown) / (1 − p_solid)``: the contrast between foliage and solid surfaces, not the
sensor's overall loss (``dropout``, which the preset leaves at 0).  Then the crops are scanned
again with ``f`` and each class's dropout, outline share and points per crop at 5–10 m are
written beside the real scans' (``ray_drop.md``), with the sensor file (``hdl32e_ray_drop.json``).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from measure import CLASSES, fit_half_scans, per_crop, sim_crops  # noqa: E402

from zbuf_occlude.experiments.partial_echo_crops import MATCHED_RANGE_M  # noqa: E402
from zbuf_occlude.experiments.sim2real.meshes import find_class_meshes  # noqa: E402
from zbuf_occlude.io.atomic import write_text  # noqa: E402
from zbuf_occlude.sensors import Lidar  # noqa: E402
from zbuf_occlude.sensors.fit import Estimate, dropout_by_surface, fit_foliage_dropout, fit_lidar, is_crown_class  # noqa: E402
from zbuf_occlude.sensors.fit.ray_drop import CROWN, SOLID  # noqa: E402
from zbuf_occlude.sensors.kinds import sensor_from_name, sensor_to_json, with_beam  # noqa: E402

log = logging.getLogger("ray_drop")
HERE = os.path.dirname(os.path.abspath(__file__))


def dropout(clouds, base: Lidar, bootstrap: int = 200) -> tuple[float, float, int, float, float]:
    """fit-sensor's pooled dropout of ``clouds`` (sensor frame, metres): value, bootstrap sd, scans, and the slope of its
    law over range (per metre) with its sd."""
    est = fit_lidar(clouds, base, bootstrap=bootstrap).estimates
    e, slope = est["dropout"], est["dropout_range_per_m"]
    return e.value, e.std, len(clouds), slope.value, slope.std


def by_class(clouds_of: dict[str, list], base: Lidar) -> dict[str, tuple[float, float, int]]:
    """Per class and for crowns and solid classes pooled (:func:`dropout_by_surface`): dropout, its sd, scans."""
    out = {c: dropout(clouds_of[c], base) for c in CLASSES}
    groups = dropout_by_surface([p for c in CLASSES for p in clouds_of[c]], [c for c in CLASSES for _ in clouds_of[c]], base)
    out.update(
        {g: (e.value, e.std, sum(len(clouds_of[c]) for c in CLASSES if (g == CROWN) == is_crown_class(c))) for g, e in groups.items()}
    )
    return out


def _estimates(d: dict) -> dict[str, Estimate]:
    return {g: Estimate(d[g][0], d[g][1], d[g][2], "dropout") for g in (CROWN, SOLID)}


def near_stats(crops: list[dict]) -> dict[str, tuple[float, float, int]]:
    """Per class: median outline share and points per crop of the crops whose centroid lies 5-10 m away."""
    out = {}
    for c in CLASSES:
        st = [per_crop(x) for x in crops if x["class"] == c]
        st = [s for s in st if MATCHED_RANGE_M[0] <= s["range_m"] < MATCHED_RANGE_M[1]]
        out[c] = (float(np.median([s["outline_share"] for s in st])) if st else math.nan,
                  float(np.median([s["n_points"] for s in st])) if st else math.nan, len(st))  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("meshes")
    ap.add_argument("real")
    ap.add_argument("--out", required=True)
    ap.add_argument("--sensor", default=os.path.join(HERE, "fit", "hdl32e_footprint.json"), help="the returns runs' sensor file")
    ap.add_argument("--crops", type=int, default=8, help="crops per mesh (default %(default)s)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--up-map", default="bush/openglforest__*=+y")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    t0, load0 = time.perf_counter(), os.getloadavg()
    up_map = dict(pair.split("=", 1) for pair in args.up_map.split(",") if pair)
    base = Lidar.preset("hdl32e")

    real_scans = fit_half_scans(args.real)
    real_clouds = {c: [s.points_sensor_m for s in real_scans if s.label == c] for c in CLASSES}
    real = by_class(real_clouds, base)
    real_near = near_stats([{"class": s.label, "points_m": s.points_sensor_m} for s in real_scans])

    sensor = sensor_from_name(args.sensor)
    meshes = find_class_meshes(args.meshes, up_map=up_map, classes=list(CLASSES))
    before_crops = sim_crops(meshes, sensor, args.crops, args.seed)
    sim = by_class({c: [x["points_m"] for x in before_crops if x["class"] == c] for c in CLASSES}, base)
    est = fit_foliage_dropout(_estimates(real), _estimates(sim))
    f, f_sd = round(est.value, 3), est.std
    log.info("foliage_dropout %.3f ± %.3f", f, f_sd)
    fitted = with_beam(sensor, foliage_dropout=f)
    after_crops = sim_crops(meshes, fitted, args.crops, args.seed)
    after = by_class({c: [x["points_m"] for x in after_crops if x["class"] == c] for c in CLASSES}, base)
    near = {
        "real (fit half)": real_near,
        "simulated, before": near_stats(before_crops),
        f"simulated, foliage_dropout {f:g}": near_stats(after_crops),
    }

    lo, hi = MATCHED_RANGE_M
    lines = [f"# Ray drop on vegetation, fitted on the fit half ({len(real_scans)} real scans)", "",
             "fit-sensor's dropout (firings missing in gaps of at most 4 steps, pooled; ± bootstrap sd over scans), per class:", "",
             "| class | real: dropout (scans) | real: its growth per metre of range | simulated before | simulated after |",
             "|---|---|---|---|---|"]  # fmt: skip
    for c in (*CLASSES, SOLID):
        cells = [f"{d[c][0]:.4f} ± {d[c][1]:.4f} ({d[c][2]})" for d in (real, sim, after)]
        cells.insert(1, f"{real[c][3]:+.4f} ± {real[c][4]:.4f}" if len(real[c]) > 3 else "–")
        lines.append(f"| {c if c != 'solid' else 'car, pedestrian, pole pooled'} | " + " | ".join(cells) + " |")
    lines += ["", f"fitted `foliage_dropout` = 1 − S_real / S_sim = **{f:.3f} ± {f_sd:.3f}** "
              f"(S = (1 − p_crown) / (1 − p_solid): real {(1 - real[CROWN][0]) / (1 - real[SOLID][0]):.4f}, "
              f"simulated {(1 - sim[CROWN][0]) / (1 - sim[SOLID][0]):.4f})", "",
              f"Crops whose centroid is {lo:g}-{hi:g} m away: median outline share and points per crop (crops).", "",
              "| class | " + " | ".join(near) + " |", "|---|" + "---|" * len(near)]  # fmt: skip
    for c in CLASSES:
        lines.append(f"| {c} | " + " | ".join(f"{v[c][0]:.3f}, {v[c][1]:.0f} ({v[c][2]})" for v in near.values()) + " |")
    wall, load1 = time.perf_counter() - t0, os.getloadavg()
    lines += ["", f"{args.crops} crops a mesh, seed {args.seed}; sensor `{os.path.relpath(args.sensor)}`; wall {wall:.0f} s, "
              f"load average {load0[0]:.1f} → {load1[0]:.1f}."]  # fmt: skip
    os.makedirs(args.out, exist_ok=True)
    write_text(os.path.join(args.out, "ray_drop.md"), "\n".join(lines) + "\n")
    spec = sensor_to_json(fitted)
    spec["beam"]["source"] += f"; foliage_dropout {f:g} fitted to LiDARNet v2's fit half (docs/results/returns_realism/ray_drop.py)"
    write_text(os.path.join(args.out, "hdl32e_ray_drop.json"), json.dumps(spec, indent=2) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
