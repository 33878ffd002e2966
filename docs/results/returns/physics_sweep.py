"""The returns experiment's targets against the physics of partial echoes: detection, foliage transmittance, sub-rays.

    python docs/results/returns/physics_sweep.py MESH_FOLDER REAL_LAZ OUT_CSV [--ks K,K] [--echo-rule RULE]
        [--transmittances T,T] [--min-echo-reflectances R,R] > physics_sweep.md

The scanner and plot of ``experiment returns`` (the IGN sample's fitted return model, the trees
spaced for the tile's tree cover, two pooled flight lines), and per setting: the partial-echo
threshold ``min_echo_reflectance`` (Beam: an echo's energy × range², its apparent reflectance,
beside the fitted absolute ``detection_threshold``), the foliage's round-trip transmittance (every
mesh; the ground opaque) and the sub-ray count K.  Per setting the divergence is fitted as the
experiment fits it (the simulated vegetation multi-return share against the tile's, over
:data:`DIVERGENCES_MRAD`, ``divergence_from_shares``), then the 13 IGN targets are compared at it
(``returns_comparison.comparison_rows``).  Where the share stays above the tile's at every
divergence swept, the smallest divergence is compared; below it at every one, the largest.
Each setting is compared at the data sheet's divergence too (0.25 mrad: the experiment's second set
of rows).  ``--echo-rule`` is the simulated receiver's (``Beam.echo_rule``: chain by default).
No value is chosen here: the sweep shows what each setting does.
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np

from zbuf_occlude.experiments.returns import IGN_ALTITUDE_M, IGN_DIVERGENCE_DEG, pulse_subset, simulate
from zbuf_occlude.experiments.tree_cover import tree_cover
from zbuf_occlude.experiments.returns_comparison import comparison_rows
from zbuf_occlude.experiments.returns_report import ReturnsSettings, ign_plot, simulated_model
from zbuf_occlude.io.atomic import write_csv
from zbuf_occlude.io.las import read_las
from zbuf_occlude.sensors.fit.divergence import divergence_from_shares
from zbuf_occlude.sensors.fit.return_model import fit_return_model
from zbuf_occlude.sensors.fit.returns import VEGETATION_CLASSES, return_statistics
from zbuf_occlude.sensors.kinds import with_beam

K_VALUES = (19, 37, 76)
MIN_ECHO_REFLECTANCES = (0.0, 0.05, 0.1)
TRANSMITTANCES = (0.0, 0.1, 0.2, 0.3)
DIVERGENCES_MRAD = (0.125, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0)
BOOTSTRAP = 100
SHARE = "multi_return_points_classes_3_4_5"


def _scan(plot, model, divergence_mrad: float, k: int, mer: float, t: float, settings: ReturnsSettings):
    scene, vegetation, centre, half = plot
    scanner = with_beam(model.scanner(math.degrees(divergence_mrad * 1e-3), k), min_echo_reflectance=mer)
    transmittance = (0.0,) + (t,) * len(vegetation) if t > 0 else None
    return simulate(scene, scanner, vegetation, center_xy=centre, half_size_m=half, seeds=settings.seeds, bootstrap=BOOTSTRAP,
                    reflectivity=model.reflectivity, transmittance=transmittance)  # fmt: skip


def _fitted(shares: list[tuple[float, float]], real_share) -> tuple[float, float, str]:
    """The divergence (mrad) where the curve meets the real share, ± sd, and how it was reached."""
    x = np.array(DIVERGENCES_MRAD)
    y = np.maximum.accumulate(np.array([s for s, _ in shares]))
    if real_share.value <= y[0]:
        return float(x[0]), math.nan, "above at every divergence"
    if real_share.value >= y[-1]:
        return float(x[-1]), math.nan, "below at every divergence"
    fit = divergence_from_shares(np.degrees(x * 1e-3), y, real_share, np.array([sd for _, sd in shares]))
    return math.radians(fit.value) * 1e3, math.radians(fit.std) * 1e3, "fitted"


def main(mesh_root: str, real_path: str, out_csv: str, ks: tuple[int, ...] = K_VALUES, echo_rule: str = "chain",
         transmittances=TRANSMITTANCES, mers=MIN_ECHO_REFLECTANCES) -> None:  # fmt: skip
    load_start, cpu_start, wall_start = os.getloadavg(), time.process_time(), time.perf_counter()
    las = read_las(real_path)
    real = {"all": return_statistics(las, bootstrap=BOOTSTRAP)}
    for side in ("vegetation", "ground"):
        real[side] = return_statistics(pulse_subset(las, side), bootstrap=BOOTSTRAP)
    settings = ReturnsSettings()
    plot = ign_plot(mesh_root, settings, tree_cover=tree_cover(las, bootstrap=BOOTSTRAP).value)
    model = simulated_model(fit_return_model(las, altitude_m=IGN_ALTITUDE_M, bootstrap=BOOTSTRAP), plot[0], True, echo_rule)
    sheet_mrad = math.radians(IGN_DIVERGENCE_DEG) * 1e3
    rows = []
    print(
        "| foliage transmittance | min_echo_reflectance | K | divergence (mrad) | vegetation pulses with 1 / 2 / 3 / 4 returns (%) | "
        "vegetation points from multi-return pulses (%) | ground points from multi-return pulses (%) | smallest gap (m) | "
        f"median gap (m) | intensity first-of-several / single | IGN targets passed | at the data sheet's {sheet_mrad:g} mrad |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for t in transmittances:
        for mer in mers:
            for k in ks:
                shares = []
                for d in DIVERGENCES_MRAD:
                    e = _scan(plot, model, d, k, mer, t, settings).statistics["all"].estimates[SHARE]
                    shares.append((e.value, e.std))
                divergence, sd, how = _fitted(shares, real["all"].estimates[SHARE])
                result = _scan(plot, model, divergence, k, mer, t, settings)
                compared = comparison_rows(real, result.statistics, real_classes=VEGETATION_CLASSES,
                                           range_resolution_m=model.range_resolution_m, label="IGN")  # fmt: skip
                figures = {r["figure"]: r["simulated"] for r in compared}
                sheet = comparison_rows(real, _scan(plot, model, sheet_mrad, k, mer, t, settings).statistics, real_classes=VEGETATION_CLASSES,
                                        range_resolution_m=model.range_resolution_m, label="IGN, data sheet")  # fmt: skip
                veg = result.statistics["vegetation"].estimates
                rows.append({
                    "transmittance": t, "min_echo_reflectance": mer, "K": k, "divergence_mrad": divergence, "divergence_sd_mrad": sd,
                    "divergence_fit": how, **{f"share_at_{d:g}_mrad": s for d, (s, _) in zip(DIVERGENCES_MRAD, shares)},
                    **{f"returns_{n}": veg[f"returns_{n}"].value for n in (1, 2, 3, 4)},
                    "multi_return_share": figures["vegetation points from multi-return pulses"],
                    "ground_multi_return_share": figures["ground points from multi-return pulses"],
                    "gap_min_m": figures["smallest gap (m)"], "gap_median_m": figures["median gap (m)"],
                    "intensity_ratio": figures["intensity first-of-several / single, vegetation"],
                    "tree_cover": tree_cover(result.las, bootstrap=BOOTSTRAP).value,
                    "passes": sum(r["verdict"] == "PASS" for r in compared), "targets": len(compared), "echo_rule": echo_rule,
                    "sheet_passes": sum(r["verdict"] == "PASS" for r in sheet),
                    "sheet_fails": "; ".join(r["figure"] for r in sheet if r["verdict"] == "FAIL"),
                    "fails": "; ".join(r["figure"] for r in compared if r["verdict"] == "FAIL"),
                })  # fmt: skip
                r = rows[-1]
                print(f"| {t:g} | {mer:g} | {k} | {divergence:.3g} ({how}) | "
                      f"{' / '.join(format(100 * r['returns_' + str(n)], '.1f') for n in (1, 2, 3, 4))} | {100 * r['multi_return_share']:.1f} | "
                      f"{100 * r['ground_multi_return_share']:.1f} | {r['gap_min_m']:.3g} | {r['gap_median_m']:.3g} | "
                      f"{r['intensity_ratio']:.3g} | {r['passes']}/{r['targets']} | {r['sheet_passes']}/{len(sheet)} |", flush=True)  # fmt: skip
    write_csv(out_csv, rows)
    print(f"\nload average {', '.join(f'{v:.2f}' for v in load_start)} at the start, "
          f"{', '.join(f'{v:.2f}' for v in os.getloadavg())} at the end; {time.perf_counter() - wall_start:.0f} s, "
          f"{time.process_time() - cpu_start:.0f} CPU seconds")  # fmt: skip


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("meshes")
    ap.add_argument("real")
    ap.add_argument("out_csv")
    ap.add_argument("--ks", default=",".join(map(str, K_VALUES)))
    ap.add_argument("--echo-rule", default="chain", choices=("chain", "waveform"))
    ap.add_argument("--transmittances", default=",".join(map(str, TRANSMITTANCES)))
    ap.add_argument("--min-echo-reflectances", default=",".join(map(str, MIN_ECHO_REFLECTANCES)))
    a = ap.parse_args()
    floats = lambda text: tuple(float(v) for v in text.split(","))  # noqa: E731
    main(a.meshes, a.real, a.out_csv, ks=tuple(int(v) for v in a.ks.split(",")), echo_rule=a.echo_rule,
         transmittances=floats(a.transmittances), mers=floats(a.min_echo_reflectances))  # fmt: skip
