"""Why do simulated HDL-32E object crops with the multi-return model look less like real scans?  Measured per class.

    .venv/bin/python docs/results/returns_realism/measure.py ../shared/data/street_objects \
        ../shared/data/lidarnet_v2_partial --out docs/results/returns_realism --up-map 'bush/openglforest__*=+y'

For each scanner variant of :data:`VARIANTS` (a name and a function of the HDL-32E preset), the
``lidar`` set's crops of every mesh (:func:`zbuf_occlude.sensors.fit.mesh_crops.mesh_crops`, which
``fit-sensor --meshes`` scans with too; ``experiment sim2real``'s code path: its mesh reader and
``--up-map`` rule, :func:`find_class_meshes`; its placements, :meth:`CropPlacement.crop_distributions`
over ``LIDAR_PLACEMENT`` and the class's real size from ``CLASS_SIZES_M``; its crops,
:func:`object_crops` with the mesh's name and the seed, which ``lidar_object_samples`` draws too;
its rule, crops with fewer than ``MIN_RETURNS`` returns dropped and the first ``--crops`` kept of
``crops + max(1, crops // 5)`` drawn).  Every variant sees the same placements (crop ``k`` of a mesh
is placed by the same draw), so per-crop ratios against variant ``a`` are paired.

The real scans are read as ``experiment sim2real --real`` reads this folder
(:func:`load_real_scans` with the command's defaults: LiDARNet v2 detected, y up turned to z up,
5 units per metre, byte-identical files dropped), in the sensor frame (``points_sensor_m``).

Per class and set, written to ``--out``: ``by_class.csv`` and ``by_class.md`` (crops; median points
per crop, range to the centroid and height; median points per crop in 5 m range bins; the count
exponent; the median outline share, overall and per range bin (:func:`outline_share`: points that
end a run of their ring's scan line); the share of points that are return 2 or later and of
points from pulses with two or more returns), ``paired.csv`` (per variant and class, the median
over paired crops of points and outline points against variant ``a``) and ``crops.csv`` (every crop, lengths to 0.1 mm).

Differences from a sim2real run, on purpose: only the first round of draws (a mesh with fewer
good crops keeps fewer, where sim2real draws more under another name), so that crop ``k`` of a
mesh has one placement in every variant; and every crop's returns, not ``n_points`` of them.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import fields

import numpy as np

from zbuf_occlude.sensors.fit.mesh_crops import MATCHED_RANGE_M, mesh_crops
from zbuf_occlude.sensors.fit.partial_echo_meshes import partial_echo_sensor
from zbuf_occlude.experiments.realism import RANGE_BINS_M, ObjectCloud, class_summary, outline_mask, range_bin_medians, scan_line_runs
from zbuf_occlude.sensors.request import kept_returns
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes
from zbuf_occlude.sensors.fit.class_placement import CropPlacement
from zbuf_occlude.io.atomic import write_csv, write_text
from zbuf_occlude.mesh.sizes import CLASS_SIZES_M
from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.sensors import Lidar
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.crops import lidar_object_samples
from zbuf_occlude.sensors.kinds import with_beam

CLASSES = ("bush", "car", "pedestrian", "pole")
#: How these pages' crops cast a footprint: every sub-ray, the model their figures were measured with
#: (``scan``'s default, "auto", casts the adaptive footprint; ``adaptive_bias.py`` measures the difference).
FOOTPRINT = "exact"


def _strongest_of_7(sensor: Lidar) -> Lidar:
    # the partial echoes' fit's beam: 7 sub-rays over the data sheet's divergence, the strongest return, 0.75 m resolution
    return partial_echo_sensor(sensor)


#: The scanner variants, each a name and a function of the HDL-32E preset; add rows to measure more.
VARIANTS: list[tuple[str, Callable[[Lidar], Lidar]]] = [
    ("a: preset, one ray", lambda s: s),
    ("b: --returns 2", lambda s: kept_returns(s, 2)),
    ("c: 7 rays, strongest", _strongest_of_7),
    # not a return model: the preset missing pulses at random (real scan lines break at 3-9 % of their gaps)
    ("a, dropout 0.05", lambda s: with_beam(s, dropout=0.05)),
]
#: Detection thresholds on an echo's apparent reflectance (ρ·|cos θ|·footprint share), over b and c,
#: where the beam has the field.
MIN_ECHO_REFLECTANCES = (0.1, 0.2, 0.3, 0.5)
if "min_echo_reflectance" in {f.name for f in fields(Beam)}:
    for _rho in MIN_ECHO_REFLECTANCES:
        VARIANTS.append((f"b, echo ρ ≥ {_rho:g}", lambda s, r=_rho: with_beam(kept_returns(s, 2), min_echo_reflectance=r)))
        VARIANTS.append((f"c, echo ρ ≥ {_rho:g}", lambda s, r=_rho: with_beam(_strongest_of_7(s), min_echo_reflectance=r)))

log = logging.getLogger("returns_realism")


def fit_half_scans(real_folder: str) -> list:
    """The real scans of ``real_folder`` that ``experiment sim2real`` fits to, split as it splits them (its
    ``real_split``); the scored half is not returned."""
    from zbuf_occlude.experiments.sim2real.real import real_halves, real_scan_rows
    from zbuf_occlude.experiments.sim2real.run import _REAL_SPLIT_SEED

    scans = load_real_scans(real_folder)  # as experiment sim2real --real reads this folder
    names = sorted(CLASSES)
    kept = real_scan_rows(scans, names, {})
    labels = np.array([names.index(scans[i].label) for i in kept])
    fit_half, _ = real_halves([scans[i].points for i in kept], labels, _REAL_SPLIT_SEED)
    return [scans[kept[i]] for i in fit_half]


def sim_crops(meshes, sensor: Lidar, crops: int, seed: int, footprint: str = FOOTPRINT) -> list[dict]:
    """The ``lidar`` set's crops of every mesh for ``sensor`` (module docstring; :func:`mesh_crops`, cast as ``footprint``): one dict per crop."""
    return [{"mesh": c.mesh, "class": c.class_name, "crop": c.crop, "points_m": c.points_m, "return_number": c.return_number,
             "number_of_returns": c.number_of_returns, "distance_m": c.distance_m} for c in mesh_crops(meshes, sensor, crops, seed, footprint=footprint)]  # fmt: skip


def check_same_crops(entry, sensor: Lidar, crops: int, seed: int, ours: list[dict]) -> None:
    """Our crops of ``entry`` have the returns that sim2real's ``lidar_object_samples`` counts for the same draws."""
    dist, _ = CropPlacement().crop_distributions(entry, CLASS_SIZES_M[entry.class_name])
    theirs = lidar_object_samples(entry.mesh, sensor, name=entry.name, n_samples=crops + max(1, crops // 5), n_points=64, seed=seed,
                                  distributions=dist, class_name=entry.class_name, footprint=FOOTPRINT)  # fmt: skip
    want = {c.sample_index: c.n_visible for c in theirs}
    got = {c["crop"]: len(c["points_m"]) for c in ours if c["mesh"] == entry.name}
    if any(want.get(k) != n for k, n in got.items()):
        raise SystemExit(f"{entry.name}: crops differ from lidar_object_samples': {got} against {want}")


def per_crop(c: dict) -> dict:
    """One crop's points, range to its centroid (m), height (m), outline, and its returns 2+ and points of
    multi-return pulses (NaN where the file records no return numbers: the real scans)."""
    p = c["points_m"]
    mask = outline_mask(p)
    run_ring, length = scan_line_runs(p)
    known = c.get("return_number") is not None
    return {"n_points": len(p), "range_m": float(np.linalg.norm(p.mean(axis=0))), "height_m": float(np.ptp(p[:, 2])),
            "outline_points": int(mask.sum()), "outline_share": float(mask.mean()), "rings": len(np.unique(run_ring)), "runs": len(length),
            "points_in_single_runs": int((length == 1).sum()),
            "return_2plus": int((c["return_number"] >= 2).sum()) if known else math.nan,
            "from_multi_return_pulse": int((c["number_of_returns"] >= 2).sum()) if known else math.nan}  # fmt: skip


def _bins() -> list[str]:
    return [f"{lo:g}-{hi:g}" for lo, hi in zip(RANGE_BINS_M[:-1], RANGE_BINS_M[1:])]


def summarise(name: str, cls: str, clouds: list[ObjectCloud], stats: list[dict]) -> dict:
    s = class_summary(clouds, by_range=True)
    ranges = np.array([st["range_m"] for st in stats])
    outline_by_range, _ = range_bin_medians(ranges, [st["outline_share"] for st in stats])
    n = sum(st["n_points"] for st in stats)
    row = {"class": cls, "set": name, "crops": s["crops"], "median_points": s["n_points"], "median_range_m": s["range_m"],
           "median_height_m": float(np.median([st["height_m"] for st in stats])), "count_exponent": s["count_exponent"],
           "median_outline_share": s["outline_share"]}  # fmt: skip
    for b, m, k in zip(_bins(), s["n_points_by_range"], s["crops_by_range"]):
        row[f"median_points_{b}_m"], row[f"crops_{b}_m"] = float(m), int(k)
    for b, m in zip(_bins(), outline_by_range):
        row[f"median_outline_share_{b}_m"] = float(m)
    row["share_return_2plus"] = sum(st["return_2plus"] for st in stats) / n
    row["share_from_multi_return_pulses"] = sum(st["from_multi_return_pulse"] for st in stats) / n
    # what the outline share is made of, at one range for both sets: rings, points per ring, how often a scan line breaks
    near = [st for st in stats if MATCHED_RANGE_M[0] <= st["range_m"] < MATCHED_RANGE_M[1]]
    rings, n_near = sum(st["rings"] for st in near), sum(st["n_points"] for st in near)
    row["matched_range_crops"] = len(near)
    row["matched_median_outline_share"] = float(np.median([st["outline_share"] for st in near])) if near else math.nan
    row["matched_median_rings"] = float(np.median([st["rings"] for st in near])) if near else math.nan
    row["matched_median_points_per_ring"] = float(np.median([st["n_points"] / st["rings"] for st in near])) if near else math.nan
    row["matched_median_runs_per_ring"] = float(np.median([st["runs"] / st["rings"] for st in near])) if near else math.nan
    row["matched_broken_gap_share"] = (sum(st["runs"] for st in near) - rings) / (n_near - rings) if n_near > rings else math.nan
    row["matched_share_in_single_point_runs"] = sum(st["points_in_single_runs"] for st in near) / n_near if n_near else math.nan
    return row


def _f(v, digits: int = 3) -> str:
    if isinstance(v, (int, np.integer)):
        return str(v)
    return "–" if not math.isfinite(v) else f"{v:.{digits}f}"


def markdown(rows: list[dict], paired: list[dict]) -> str:
    bins = _bins()
    head = ["class", "set", "crops", "median points", "median range, m", "median height, m",
            *(f"median points {b} m (crops)" for b in bins), "count exponent", "median outline share",
            *(f"outline share {b} m" for b in bins), "% return 2+", "% from 2+-return pulses"]  # fmt: skip
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in sorted(rows, key=lambda r: (r["class"], r["set"] != "real", r["set"])):
        cells = [r["class"], r["set"], str(r["crops"]), _f(r["median_points"], 0), _f(r["median_range_m"], 1), _f(r["median_height_m"], 2),
                 *(f"{_f(r[f'median_points_{b}_m'], 0)} ({r[f'crops_{b}_m']})" for b in bins), _f(r["count_exponent"], 2),
                 _f(r["median_outline_share"]), *(_f(r[f"median_outline_share_{b}_m"]) for b in bins),
                 _f(100 * r["share_return_2plus"], 1), _f(100 * r["share_from_multi_return_pulses"], 1)]  # fmt: skip
        lines.append("| " + " | ".join(cells) + " |")
    lo, hi = MATCHED_RANGE_M
    lines += ["", f"What the outline share is made of, crops whose centroid is {lo:g}-{hi:g} m away: rings per crop, points and runs "
              "per ring, the share of the gaps between neighbours along a ring that break it (wider than 1.5 azimuth steps), and the "
              "share of points alone in their run.", "",
              "| class | set | crops | median outline share | median rings | median points per ring | median runs per ring | "
              "% of gaps that break a ring | % of points in one-point runs |", "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in sorted(rows, key=lambda r: (r["class"], r["set"] != "real", r["set"])):
        lines.append(f"| {r['class']} | {r['set']} | {r['matched_range_crops']} | {_f(r['matched_median_outline_share'])} | "
                     f"{_f(r['matched_median_rings'], 0)} | {_f(r['matched_median_points_per_ring'], 1)} | "
                     f"{_f(r['matched_median_runs_per_ring'], 2)} | {_f(100 * r['matched_broken_gap_share'], 1)} | "
                     f"{_f(100 * r['matched_share_in_single_point_runs'], 1)} |")  # fmt: skip
    lines += ["", "Paired crops (the same placement), per variant against a: medians over the crops of each ratio.", "",
              "| class | variant | paired crops | points / a's | outline points / a's | outline share − a's |", "|---|---|---|---|---|---|"]  # fmt: skip
    for r in paired:
        lines.append(f"| {r['class']} | {r['set']} | {r['paired_crops']} | {_f(r['points_ratio'])} | {_f(r['outline_points_ratio'])} | "
                     f"{_f(r['outline_share_difference'])} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("meshes", help="class folders of meshes (street_objects)")
    ap.add_argument("real", help="LiDARNet v2 folder (lidarnet_v2_partial)")
    ap.add_argument("--out", required=True, help="folder for by_class.csv, by_class.md, paired.csv, crops.csv")
    ap.add_argument("--crops", type=int, default=4, help="crops per mesh (default %(default)s)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--up-map", default="bush/openglforest__*=+y", help="GLOB=AXIS,... as experiment sim2real's (default %(default)s)")
    ap.add_argument("--variants", default="", help="comma-separated variant letters or names to run (default: all)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    up_map = dict(pair.split("=", 1) for pair in args.up_map.split(",") if pair)
    wanted = [v for v in VARIANTS if not args.variants or any(v[0].startswith(w.strip()) for w in args.variants.split(","))]
    t0, load0 = time.perf_counter(), os.getloadavg()

    scans = load_real_scans(args.real)  # as experiment sim2real --real with its defaults (dataset auto, +z, m)
    real = [ObjectCloud(s.points_sensor_m, s.label, s.source) for s in scans if s.label in CLASSES]
    meshes = find_class_meshes(args.meshes, up_map=up_map, classes=list(CLASSES))
    log.info("%d real scans, %d meshes; variants: %s", len(real), len(meshes), [v[0] for v in wanted])

    rows, crop_rows, stats_of = [], [], {}
    for cls in CLASSES:
        clouds = [c for c in real if c.label == cls]
        stats = [per_crop({"points_m": c.points_m}) for c in clouds]
        rows.append(summarise("real", cls, clouds, stats))
    hdl32e = Lidar.preset("hdl32e")
    for name, make in wanted:
        sensor, t = make(hdl32e), time.perf_counter()
        crops = sim_crops(meshes, sensor, args.crops, args.seed)
        if name in (VARIANTS[0][0], VARIANTS[1][0]):
            check_same_crops(meshes[0], sensor, args.crops, args.seed, crops)
        log.info("%s: %d crops in %.0f s", name, len(crops), time.perf_counter() - t)
        for c in crops:
            st = per_crop(c)
            stats_of[(name, c["mesh"], c["crop"])] = st
            row = {"set": name, "class": c["class"], "mesh": c["mesh"], "crop": c["crop"], "distance_m": c["distance_m"], **st}
            crop_rows.append({k: round(v, 4) if isinstance(v, float) else v for k, v in row.items()})
        for cls in CLASSES:
            mine = [c for c in crops if c["class"] == cls]
            rows.append(summarise(name, cls, [ObjectCloud(c["points_m"], cls, c["mesh"]) for c in mine],
                                  [stats_of[(name, c["mesh"], c["crop"])] for c in mine]))  # fmt: skip
    paired = []
    base = VARIANTS[0][0]
    for name, _ in wanted:
        if name == base:
            continue
        for cls in CLASSES:
            keys = [(m, k) for (v, m, k) in stats_of if v == name and (base, m, k) in stats_of and m.startswith(cls + "/")]
            if not keys:
                continue
            a = [stats_of[(base, m, k)] for m, k in keys]
            b = [stats_of[(name, m, k)] for m, k in keys]
            paired.append({"class": cls, "set": name, "paired_crops": len(keys),
                           "points_ratio": float(np.median([y["n_points"] / x["n_points"] for x, y in zip(a, b)])),
                           "outline_points_ratio": float(np.median([y["outline_points"] / x["outline_points"] for x, y in zip(a, b)])),
                           "outline_share_difference": float(np.median([y["outline_share"] - x["outline_share"] for x, y in zip(a, b)]))})  # fmt: skip
    os.makedirs(args.out, exist_ok=True)
    write_csv(os.path.join(args.out, "by_class.csv"), rows)
    write_csv(os.path.join(args.out, "paired.csv"), paired)
    write_csv(os.path.join(args.out, "crops.csv"), crop_rows)
    wall, load1 = time.perf_counter() - t0, os.getloadavg()
    note = (f"{args.crops} crops per mesh, seed {args.seed}; {time.process_time():.0f} s CPU, {wall:.0f} s wall; "
            f"load average {load0[0]:.1f}, {load0[1]:.1f}, {load0[2]:.1f} → {load1[0]:.1f}, {load1[1]:.1f}, {load1[2]:.1f}\n\n")  # fmt: skip
    write_text(os.path.join(args.out, "by_class.md"), note + markdown(rows, paired))
    print(note + markdown(rows, paired))
    return 0


if __name__ == "__main__":
    sys.exit(main())
