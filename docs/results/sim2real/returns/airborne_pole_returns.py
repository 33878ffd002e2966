"""Returns a crop of the street poles from the air at one return a pulse, the first return and all returns.

usage: python docs/results/sim2real/returns/airborne_pole_returns.py   (from the repository root, ../shared beside it)

The poles of ``../shared/data/street_objects`` as ``experiment sim2real --sensor riegl-q1560`` loads and sizes them, each
at its first 4 placements of seed 0 (the lidar set's), scanned with ``kept_returns(riegl-q1560, WHICH)`` for WHICH 1,
"first" and "all" from the same placements; prints the crops and the median and mean returns a crop.  Output:
``airborne_pole_returns.txt``.
"""

from __future__ import annotations

import numpy as np

from zbuf_occlude.cli.main import build_parser
from zbuf_occlude.cli.sim2real import sim2real_config
from zbuf_occlude.experiments.sim2real import run as sim2real_run
from zbuf_occlude.sensors.fit.class_placement import CropPlacement
from zbuf_occlude.sensors.crops import object_crops
from zbuf_occlude.sensors.request import kept_returns

ARGV = ["experiment", "sim2real", "../shared/data/street_objects", "--real", "../shared/data/lidarnet_v2_partial", "--out", "unused",
        "--sensor", "riegl-q1560", "--up-map", "bush/openglforest__*=+y", "--returns", "all", "--min-returns", "5"]  # fmt: skip


def main() -> None:
    config = sim2real_config(build_parser().parse_args(ARGV))
    sets = sim2real_run.prepare_sets(config, say=lambda line: None)
    sizes = sets.sizes(config.sizes)
    counts: dict[object, list[int]] = {1: [], "first": [], "all": []}
    for entry in (m for m in sets.meshes if m.class_name == "pole"):
        dist, _ = CropPlacement().crop_distributions(entry, sizes["pole"])
        kw = {"name": entry.name, "n_samples": 4, "seed": 0, "class_name": "pole", "frame": "sensor"}
        for which, got in counts.items():
            got += [len(c.scan) for _, c, _ in object_crops(entry.mesh, kept_returns(config.given_sensor, which), dist, **kw)]
    for which, got in counts.items():
        print(f"{which}: {len(got)} crops, returns a crop median {np.median(got):g}, mean {np.mean(got):.2f}")


if __name__ == "__main__":
    main()
