"""Fit the HDL-32E's detection of partial echoes (``Beam.min_echo_reflectance``) on the fit half of the real scans.

    .venv/bin/python docs/results/returns_realism/fit_threshold.py ../shared/data/street_objects \
        ../shared/data/lidarnet_v2_partial --out docs/results/returns_realism/fit

The real LiDARNet v2 HDL-32E scans are split as ``experiment sim2real`` splits them
(``real_halves`` with its seed): the **fit half** (what real→real trains on and ``--fit-sensor``
fits to) is used here; the scored half is not read beyond the split.  On the fit half:

1. the HDL-32E preset is fitted as ``experiment sim2real --fit-sensor`` fits it
   (``sensor_fit.fit_to_scans``: firing rate, range noise, dropout and its growth with range);
2. the ``lidar`` set's crops of every mesh (``sensors.fit.mesh_crops.mesh_crops``: sim2real's placements and rule)
   are scanned by the fitted sensor with a 7-sub-ray footprint over the data sheet's 0.16°
   divergence and Velodyne's strongest-return mode (the mode the real set was recorded in: its
   points share no direction with another point; ``sensors.fit.partial_echo_meshes.partial_echo_sensor``), at each
   threshold of ``fit.partial_echoes.FIT_GRID``;
3. ``fit_min_echo_reflectance`` matches the median outline share per class (``realism.outline_share``)
   of the crops whose centroid lies 5-10 m away, simulated against real.

Steps 2 and 3 are the fit ``fit-sensor --meshes`` runs (``sensors.fit.partial_echo_meshes.fit_partial_echoes_to_meshes``).

Then, at the fitted threshold (to 0.05), the footprint's convergence: the same crops at K = 7
and K = 28 (4×), paired, per class: median points and outline share.  Writes ``fit.md``,
``fit.json`` and ``hdl32e_footprint.json`` (the sensor file of the ``on`` runs of
``experiment sim2real``: the preset, not the fitted sensor, with the footprint, the return mode
and the fitted threshold) into ``--out``.
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
from measure import CLASSES, per_crop, sim_crops  # noqa: E402

from zbuf_occlude.sensors.fit.mesh_crops import MATCHED_RANGE_M  # noqa: E402
from zbuf_occlude.sensors.fit.partial_echo_meshes import fit_partial_echoes_to_meshes, partial_echo_sensor  # noqa: E402
from zbuf_occlude.experiments.sensor_fit import fit_to_scans  # noqa: E402
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes  # noqa: E402
from zbuf_occlude.experiments.sim2real.real import real_halves, real_scan_rows  # noqa: E402
from zbuf_occlude.experiments.sim2real.run import _REAL_SPLIT_SEED  # noqa: E402
from zbuf_occlude.io.atomic import write_text  # noqa: E402
from zbuf_occlude.real_scans.datasets import load_real_scans  # noqa: E402
from zbuf_occlude.sensors import Lidar  # noqa: E402
from zbuf_occlude.sensors.kinds import sensor_to_json, with_beam  # noqa: E402

log = logging.getLogger("fit_threshold")
#: The step the "on" runs' threshold is rounded to (fit-sensor --meshes writes the threshold as fitted).
ON_STEP = 0.05


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("meshes")
    ap.add_argument("real")
    ap.add_argument("--out", required=True)
    ap.add_argument("--crops", type=int, default=4, help="crops per mesh (default %(default)s)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--up-map", default="bush/openglforest__*=+y")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    t0, load0 = time.perf_counter(), os.getloadavg()
    up_map = dict(pair.split("=", 1) for pair in args.up_map.split(",") if pair)

    scans = load_real_scans(args.real)  # as experiment sim2real --real reads this folder
    names = sorted(CLASSES)
    kept = real_scan_rows(scans, names, {})
    labels = np.array([names.index(scans[i].label) for i in kept])
    fit_half, _ = real_halves([scans[i].points for i in kept], labels, _REAL_SPLIT_SEED)
    fit_scans = [scans[kept[i]] for i in fit_half]
    log.info("%d real scans kept, %d in the fit half", len(kept), len(fit_scans))
    fitted, _ = fit_to_scans(fit_scans, Lidar.preset("hdl32e"), [names[labels[i]] for i in fit_half], every_class=True)
    sensor = fitted.sensor
    b = sensor.beam
    log.info("fitted: dropout %.4f + %.5f/m, range noise %.4f m, firing %.0f Hz", b.dropout, b.dropout_range_per_m, b.range_noise_m,
             sensor.firing_rate_hz)  # fmt: skip
    meshes = find_class_meshes(args.meshes, up_map=up_map, classes=list(CLASSES))
    result = fit_partial_echoes_to_meshes(fit_scans, sensor, meshes, crops_per_mesh=args.crops, seed=args.seed, bootstrap=200, say=log.info)
    fit = result.fit
    tau = round(fit.estimate.value / ON_STEP) * ON_STEP

    # convergence of the footprint at the fitted threshold: K and 4K, paired crops
    conv = {}
    for k in (7, 28):
        crops = sim_crops(meshes, with_beam(partial_echo_sensor(sensor, tau), footprint_rays=k), args.crops, args.seed)
        conv[k] = {(c["mesh"], c["crop"]): (c["class"], per_crop(c)) for c in crops}
    lines = ["| class | paired crops | points at K = 28 / K = 7 (median, ± se) | outline share K = 28 − K = 7 (median, ± se) |",
             "|---|---|---|---|"]  # fmt: skip
    for c in names:
        both = [key for key in conv[7] if key in conv[28] and conv[7][key][0] == c]
        ratio = np.array([conv[28][key][1]["n_points"] / conv[7][key][1]["n_points"] for key in both])
        diff = np.array([conv[28][key][1]["outline_share"] - conv[7][key][1]["outline_share"] for key in both])
        se = lambda v: 1.2533 * np.std(v, ddof=1) / np.sqrt(len(v)) if len(v) > 1 else np.nan  # noqa: E731  (se of a median)
        lines.append(f"| {c} | {len(both)} | {np.median(ratio):.3f} ± {se(ratio):.3f} | {np.median(diff):+.4f} ± {se(diff):.4f} |")

    os.makedirs(args.out, exist_ok=True)
    on = partial_echo_sensor(Lidar.preset("hdl32e"), tau)
    spec = sensor_to_json(on)
    write_text(os.path.join(args.out, "hdl32e_footprint.json"), json.dumps(spec, indent=2) + "\n")
    wall, load1 = time.perf_counter() - t0, os.getloadavg()
    report = (
        f"Fit half: {len(fit_scans)} real scans; fitted dropout {b.dropout:.4f} + {b.dropout_range_per_m:.5f}/m, "
        f"range noise {b.range_noise_m:.4f} m.  Crops per mesh {args.crops}, seed {args.seed}; outline shares of crops "
        f"{MATCHED_RANGE_M[0]:g}-{MATCHED_RANGE_M[1]:g} m away.\n\n"
        + fit.markdown()
        + f"\nthreshold of the on runs (to 0.05): {tau:.2f}\n\nConvergence at it, K = 28 against K = 7 (the same crops):\n\n"
        + "\n".join(lines)
        + f"\n\n{time.process_time():.0f} s CPU, {wall:.0f} s wall; load average {load0[0]:.1f}, {load0[1]:.1f}, {load0[2]:.1f} → "
        f"{load1[0]:.1f}, {load1[1]:.1f}, {load1[2]:.1f}\n"
    )
    write_text(os.path.join(args.out, "fit.md"), report)
    write_text(os.path.join(args.out, "fit.json"), json.dumps({"estimate": fit.estimate.to_json(), "grid": fit.grid, "real": fit.real,
                                                              "simulated": fit.simulated, "objective": fit.objective,
                                                              "threshold_of_on_runs": tau}, indent=2) + "\n")  # fmt: skip
    print(report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
