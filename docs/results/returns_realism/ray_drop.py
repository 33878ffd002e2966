"""Ray drop on vegetation: how many firings real HDL-32E scans lose per class, and the beam's ``foliage_dropout`` fitted from it.

    .venv/bin/python docs/results/returns_realism/ray_drop.py ../shared/data/street_objects \
        ../shared/data/lidarnet_v2_partial --out docs/results/returns_realism/ray_drop

The real LiDARNet v2 scans are split as ``experiment sim2real`` splits them; only the fit half is
read (the scored half is not read beyond the split).  The measure is ``fit-sensor``'s dropout
(:func:`~zbuf_occlude.sensors.fit.fit_lidar`: firings missing in gaps of at most 4 azimuth steps
along a ring's run over the object, pooled over scans, bootstrap over scans), per class, on the
real scans and on the ``lidar`` set's crops of the street_objects meshes
(:func:`~zbuf_occlude.sensors.fit.mesh_crops.mesh_crops`, sim2real's placements) scanned
with the sensor file of the returns runs (``--sensor``: a 7-ray footprint, the strongest echo).

The fit (:func:`~zbuf_occlude.sensors.fit.fit_foliage_dropout`): the real bushes keep
``1 − p_crown`` of their firings where the other classes (pooled) keep ``1 − p_solid``; the
simulated crops' geometry alone gives the same two figures.  A crown surface's ray drop ``f``
(:attr:`Beam.foliage_dropout <zbuf_occlude.sensors.beam.fields.Beam.foliage_dropout>`) multiplies the
simulated bushes' share by ``1 − f``, so ``f = 1 − S_real / S_sim`` with
``S = (1 − p_crown) / (1 − p_solid)``: the contrast between foliage and solid surfaces, not the
sensor's overall loss (``dropout``, which the preset leaves at 0).  Then the crops are scanned
again with ``f`` and each class's dropout, outline share and points per crop at 5–10 m are
written beside the real scans' (``ray_drop.md``), with the sensor file (``hdl32e_ray_drop.json``).

Where the scan lines of those clouds break (``break_depths.md``): per class at 5–10 m, the breaks
of a scan and their depths, the range step across each
(:func:`~zbuf_occlude.sensors.fit.scan_lines.break_depths_m`).  A break at an outline is deep;
a missed pulse on a surface leaves a shallow one.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from measure import CLASSES, fit_half_scans, per_crop, sim_crops  # noqa: E402

from zbuf_occlude.sensors.fit.mesh_crops import MATCHED_RANGE_M  # noqa: E402
from zbuf_occlude.experiments.realism_stats import break_depths_m  # noqa: E402
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes  # noqa: E402
from zbuf_occlude.io.atomic import write_text  # noqa: E402
from zbuf_occlude.sensors import Lidar  # noqa: E402
from zbuf_occlude.sensors.fit import Estimate, dropout_by_surface, fit_foliage_dropout, fit_lidar, is_crown_class  # noqa: E402
from zbuf_occlude.sensors.fit.ray_drop import CROWN, SOLID  # noqa: E402
from zbuf_occlude.sensors.kinds import sensor_from_name, sensor_to_json, with_beam  # noqa: E402

log = logging.getLogger("ray_drop")
HERE = os.path.dirname(os.path.abspath(__file__))


def rates(clouds_of: dict[str, list], base: Lidar) -> tuple[dict[str, dict[str, Estimate]], dict[str, Estimate]]:
    """fit-sensor's estimates per class (its ``dropout`` and ``dropout_range_per_m``), and the dropout of crowns and
    of solid classes pooled (:func:`dropout_by_surface`)."""
    per_class = {c: fit_lidar(clouds_of[c], base).estimates for c in CLASSES}
    groups = dropout_by_surface([p for c in CLASSES for p in clouds_of[c]], [c for c in CLASSES for _ in clouds_of[c]], base)
    return per_class, groups


def near(crops: list[dict]) -> dict[str, list[dict]]:
    """Per class: the crops (``class``, ``points_m``) whose centroid lies 5-10 m away, each with its :func:`per_crop` stats."""
    out = {c: [] for c in CLASSES}
    for x in crops:
        st = per_crop(x)
        if MATCHED_RANGE_M[0] <= st["range_m"] < MATCHED_RANGE_M[1]:
            out[x["class"]].append({**st, "break_depths_m": break_depths_m(x["points_m"])})
    return out


def near_cells(st: list[dict]) -> tuple[str, str]:
    """A class's cells of the two 5-10 m tables: outline share and points (crops); breaks a crop, their median
    depth and the share under 0.1 m (crops)."""
    d = np.concatenate([s["break_depths_m"] for s in st]) if st else np.zeros(0)
    if not st:
        return "nan, nan (0)", "0 | 0.0 | – | –"
    outline = f"{np.median([s['outline_share'] for s in st]):.3f}, {np.median([s['n_points'] for s in st]):.0f} ({len(st)})"
    depth = f"{np.median(d):.2f} | {np.mean(d < 0.1):.2f}" if len(d) else "– | –"
    return outline, f"{len(st)} | {len(d) / len(st):.1f} | {depth}"


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
    clouds = {"real": [{"class": s.label, "points_m": s.points_sensor_m} for s in real_scans]}
    sensor = sensor_from_name(args.sensor)
    meshes = find_class_meshes(args.meshes, up_map=up_map, classes=list(CLASSES))
    clouds["before"] = sim_crops(meshes, sensor, args.crops, args.seed)
    found = {k: rates({c: [x["points_m"] for x in v if x["class"] == c] for c in CLASSES}, base) for k, v in clouds.items()}
    est = fit_foliage_dropout(found["real"][1], found["before"][1])
    f, f_sd = round(est.value, 3), est.std
    log.info("foliage_dropout %.3f ± %.3f", f, f_sd)
    fitted = with_beam(sensor, foliage_dropout=f)
    clouds["after"] = sim_crops(meshes, fitted, args.crops, args.seed)
    found["after"] = rates({c: [x["points_m"] for x in clouds["after"] if x["class"] == c] for c in CLASSES}, base)
    scans = {k: {c: sum(x["class"] == c for x in v) for c in CLASSES} for k, v in clouds.items()}
    names = {"real": "real (fit half)", "before": "simulated, before", "after": f"simulated, foliage_dropout {f:g}"}
    at_5_10 = {k: near(v) for k, v in clouds.items()}

    def cell(k: str, c: str) -> str:
        e = found[k][0][c]["dropout"] if c in CLASSES else found[k][1][SOLID]
        n = scans[k][c] if c in CLASSES else sum(scans[k][x] for x in CLASSES if not is_crown_class(x))
        return f"{e.value:.4f} ± {e.std:.4f} ({n})"

    def contrast(k: str) -> float:
        return (1 - found[k][1][CROWN].value) / (1 - found[k][1][SOLID].value)

    lo, hi = MATCHED_RANGE_M
    lines = [f"# Ray drop on vegetation, fitted on the fit half ({len(real_scans)} real scans)", "",
             "fit-sensor's dropout (firings missing in gaps of at most 4 steps, pooled; ± bootstrap sd over scans), per class:", "",
             "| class | real: dropout (scans) | real: its growth per metre of range | simulated before | simulated after |",
             "|---|---|---|---|---|"]  # fmt: skip
    for c in (*CLASSES, SOLID):
        slope = found["real"][0][c]["dropout_range_per_m"] if c in CLASSES else None
        growth = f"{slope.value:+.4f} ± {slope.std:.4f}" if slope is not None else "–"
        label = c if c in CLASSES else "car, pedestrian, pole pooled"
        lines.append(f"| {label} | {cell('real', c)} | {growth} | {cell('before', c)} | {cell('after', c)} |")
    lines += ["", f"fitted `foliage_dropout` = 1 − S_real / S_sim = **{f:.3f} ± {f_sd:.3f}** "
              f"(S = (1 − p_crown) / (1 − p_solid): real {contrast('real'):.4f}, simulated {contrast('before'):.4f})", "",
              f"Crops whose centroid is {lo:g}-{hi:g} m away: median outline share and points per crop (crops).", "",
              "| class | " + " | ".join(names.values()) + " |", "|---|" + "---|" * len(names)]  # fmt: skip
    for c in CLASSES:
        lines.append(f"| {c} | " + " | ".join(near_cells(at_5_10[k][c])[0] for k in names) + " |")
    breaks = ["| class | set | scans at 5-10 m | breaks a scan | median depth of a break, m | share under 0.1 m |",
              "|---|---|---|---|---|---|"]  # fmt: skip
    breaks += [f"| {c} | {names[k]} | {near_cells(at_5_10[k][c])[1]} |" for c in CLASSES for k in names]
    wall, load1 = time.perf_counter() - t0, os.getloadavg()
    lines += ["", f"{args.crops} crops a mesh, seed {args.seed}; sensor `{os.path.relpath(args.sensor)}`; wall {wall:.0f} s, "
              f"load average {load0[0]:.1f} → {load1[0]:.1f}."]  # fmt: skip
    breaks += ["", f"{args.crops} crops a mesh, seed {args.seed}; made with ray_drop.md (wall {wall:.0f} s)."]
    os.makedirs(args.out, exist_ok=True)
    write_text(os.path.join(args.out, "ray_drop.md"), "\n".join(lines) + "\n")
    write_text(os.path.join(args.out, "break_depths.md"), "\n".join(breaks) + "\n")
    spec = sensor_to_json(fitted)
    spec["beam"]["source"] += f"; foliage_dropout {f:g} fitted to LiDARNet v2's fit half (docs/results/returns_realism/ray_drop.py)"
    write_text(os.path.join(args.out, "hdl32e_ray_drop.json"), json.dumps(spec, indent=2) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
