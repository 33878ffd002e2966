"""Where a pulse's second return lands on the lidar set's objects: points per crop, their layout along the object, what they hit.

usage: python docs/results/sim2real/returns/second_returns.py CROPS -- experiment sim2real ARGS...   (from the repository root)
  CROPS  crops per mesh (each mesh's first CROPS placements of seed 0)
  ARGS   the run's own arguments (docs/results/sensor_fit/sim2real_realval/run.sh's), with --returns N above 1

Loads the meshes, sizes and families as the run does (``prepare_sets``: nothing is trained, the scored half is never
read) and scans each mesh's first CROPS placements of seed 0 (the lidar set's placements: ``CropPlacement`` over
``LIDAR_PLACEMENT``) three times, from the same placements and scan seeds: with the run's sensor (``--returns N``),
with its footprint at one return per pulse (the strongest surface), and with the sensor as given at one return per
pulse (``kept_returns(sensor, 1)``, the default: the preset's one ray).  Per class it prints: the object's returns per
crop (median) with each; the share of the object's returns that are a pulse's second or later; of the
pulses whose first return is on the object, the share with a later return and where that return lands (the object
itself, the ground, nothing: the crop keeps the object's returns only, so a later return on the ground is lost to
the cloud); the median range gap between a pulse's first return and its later one on the object; and the share of
first and of later returns per fifth of the object's height (bottom to top).
"""

from __future__ import annotations

import sys
from collections import defaultdict

import numpy as np

from zbuf_occlude.cli.main import build_parser
from zbuf_occlude.cli.sim2real import sim2real_config
from zbuf_occlude.experiments.sim2real import run as sim2real_run
from zbuf_occlude.sensors.fit.class_placement import CropPlacement
from zbuf_occlude.sensors.crops import object_crops
from zbuf_occlude.sensors.request import kept_returns


def _pulses(crop) -> dict[str, float]:
    """One crop's figures: the object's returns, its later returns, and what the later returns of its pulses hit."""
    obj, full = crop.scan, crop.full
    first_on_object = np.unique(full.pulse_id[(full.return_number == 1) & (full.object_id == 1)])
    later = np.isin(full.pulse_id, first_on_object) & (full.return_number > 1)
    z = obj.points[:, 2]
    lo, hi = (z.min(), z.max()) if len(z) else (0.0, 1.0)
    fifth = np.minimum((5 * (z - lo) / max(hi - lo, 1e-9)).astype(int), 4)
    first_range = dict(zip(full.pulse_id[full.return_number == 1].tolist(), full.range_m[full.return_number == 1].tolist()))
    on_obj_later = later & (full.object_id == 1)
    gaps = [r - first_range[p] for p, r in zip(full.pulse_id[on_obj_later].tolist(), full.range_m[on_obj_later].tolist())]
    return {"returns": len(obj), "later": int(np.sum(obj.return_number > 1)), "pulses": len(first_on_object),
            "with_later": len(np.unique(full.pulse_id[later])), "later_on_object": int(on_obj_later.sum()),
            "later_on_ground": int(np.sum(later & (full.object_id == 0))), "gaps": gaps,
            "first_fifths": np.bincount(fifth[obj.return_number == 1], minlength=5),
            "later_fifths": np.bincount(fifth[obj.return_number > 1], minlength=5)}  # fmt: skip


def main() -> None:
    crops, argv = int(sys.argv[1]), sys.argv[sys.argv.index("--") + 1 :]
    config = sim2real_config(build_parser().parse_args(argv))
    if config.sensor.beam.max_returns < 2:
        raise SystemExit("give the run's --returns N with N above 1")
    sets = sim2real_run.prepare_sets(config, say=print)
    sizes, placement = sets.sizes(config.sizes), CropPlacement()
    one, footprint_one = kept_returns(config.given_sensor, 1), kept_returns(config.sensor, 1)
    print(f"sensor {config.sensor.name}: {config.sensor.beam.max_returns} returns a pulse, {config.sensor.beam.footprint_rays} sub-rays")
    rows: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for entry in sets.meshes:
        dist, _ = placement.crop_distributions(entry, sizes[entry.class_name])
        kw = {"name": entry.name, "n_samples": crops, "seed": 0, "class_name": entry.class_name, "frame": "sensor"}
        scans = (object_crops(entry.mesh, sensor, dist, **kw) for sensor in (config.sensor, footprint_one, one))
        for (_, several, _), (_, strongest, _), (_, single, _) in zip(*scans):
            got = _pulses(several)
            row = rows[entry.class_name]
            row["one"].append(len(single.scan))
            row["footprint_one"].append(len(strongest.scan))
            for key, value in got.items():
                row[key].append(value)
    for name in sets.names:
        r = rows[name]
        share = sum(r["later"]) / max(sum(r["returns"]), 1)
        pulses, with_later = sum(r["pulses"]), sum(r["with_later"])
        on_obj, on_ground = sum(r["later_on_object"]), sum(r["later_on_ground"])
        gaps = [g for gs in r["gaps"] for g in gs]
        first = np.sum(r["first_fifths"], axis=0)
        later = np.sum(r["later_fifths"], axis=0)
        print(f"{name:10s} {len(r['returns']):3d} crops; object returns per crop {np.median(r['one']):.0f} as given, "
              f"{np.median(r['footprint_one']):.0f} with the footprint at one a pulse, {np.median(r['returns']):.0f} with "
              f"{config.sensor.beam.max_returns}; later returns {100 * share:.1f} % of the "
              f"object's; pulses first on the object with a later return {100 * with_later / max(pulses, 1):.1f} %, the later "
              f"return on the object {on_obj}, on the ground {on_ground}, elsewhere {max(with_later - on_obj - on_ground, 0)}; "
              f"gap behind the first (object) {np.median(gaps) if gaps else float('nan'):.2f} m; "
              f"% of first returns per fifth {' '.join(f'{v:.0f}' for v in 100 * first / max(first.sum(), 1))}; "
              f"of later returns {' '.join(f'{v:.0f}' for v in 100 * later / max(later.sum(), 1))}")  # fmt: skip


if __name__ == "__main__":
    main()
