"""One seed's mesh-only training set of a sim2real run, beside the FIT half of its real scans, per class.

usage: python docs/results/families/set_shapes.py SET -- experiment sim2real ARGS...   (from the repository root)
  SET   the training set to build: lidar, fitted, fitted+placed (the sets of `experiment sim2real --sets`)
  ARGS  the run's own arguments, as docs/results/sensor_fit/sim2real_realval/run.sh gives them

Builds seed 0's SET exactly as the run does (its sensor fit, families and placements; nothing is trained) and
prints, per class, for the fit half's real clouds and for the set's clouds as the classifiers get them (256 points,
normalised): how many clouds, their height / width and plan elongation as the families fit measures them (10th /
50th / 90th percentile; :func:`~zbuf_occlude.experiments.realism_stats.shape_stats`), the median number of distinct points among the 256 (a
crop of fewer returns is padded with repeats), and the mean share of points per tenth of the height.  The scored
half is never read.
"""

from __future__ import annotations

import sys

import numpy as np

from zbuf_occlude.cli.main import build_parser
from zbuf_occlude.cli.sim2real import sim2real_config
from zbuf_occlude.experiments.realism_stats import shape_stats
from zbuf_occlude.experiments.sim2real import run as sim2real_run


PERCENTILES = (10, 50, 90)


def main() -> None:
    kind, argv = sys.argv[1], sys.argv[sys.argv.index("--") + 1 :]
    config = sim2real_config(build_parser().parse_args(argv))
    sets = sim2real_run.prepare_sets(config, say=print)
    # the run's own recipe of one seed's sets, validated on the fit half (every mesh trains)
    built = sim2real_run._build_seed_sets(config, sets, 0, sets.meshes, [], {}, progress=False)["train"][kind]
    fit_half = (sets.real_points[sets.half_a], sets.real_labels[sets.half_a])
    for k, name in enumerate(sets.names):
        for tag, (clouds, labels) in (("real, fit half", fit_half), (kind, (built.points, built.labels))):
            shapes = [shape_stats(c) for c in clouds[labels == k]]
            ratio, plan = ([s[key] for s in shapes] for key in ("height_to_width", "plan_elongation"))
            distinct = np.median([len(np.unique(c, axis=0)) for c in clouds[labels == k]])
            shares = 100 * np.mean([s["height_shares"] for s in shapes], axis=0)
            print(f"{name:10s} {tag:15s} {len(shapes):3d} clouds; height / width {' / '.join(f'{v:.2f}' for v in np.nanpercentile(ratio, PERCENTILES))}; "
                  f"plan elongation {' / '.join(f'{v:.2f}' for v in np.nanpercentile(plan, PERCENTILES))}; distinct points {distinct:.0f}; "
                  f"% per tenth {' '.join(f'{v:.0f}' for v in shares)}")  # fmt: skip


if __name__ == "__main__":
    main()
