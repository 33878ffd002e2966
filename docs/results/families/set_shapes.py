"""One seed's mesh-only training set of a sim2real run, beside the FIT half of its real scans, per class.

usage: python docs/results/families/set_shapes.py SET -- experiment sim2real ARGS...   (from the repository root)
  SET   the training set to build: lidar, fitted, fitted+placed (the sets of `experiment sim2real --sets`)
  ARGS  the run's own arguments, as docs/results/sensor_fit/sim2real_realval/run.sh gives them

Builds seed 0's SET exactly as the run does (its sensor fit, families and placements; nothing is trained) and
prints, per class, for the fit half's real clouds and for the set's clouds as the classifiers get them (256 points,
normalised): how many clouds, their height / width (10th / 50th / 90th percentile), the median number of distinct
points among the 256 (a crop of fewer returns is padded with repeats), and per tenth of the height the mean share of
points and the median width (the larger horizontal extent) over the height.  The scored half is never read.
"""

from __future__ import annotations

import sys

import numpy as np

from zbuf_occlude.cli.main import build_parser
from zbuf_occlude.cli.sim2real import sim2real_config
from zbuf_occlude.experiments.sim2real import run as sim2real_run


def cloud_stats(points: np.ndarray) -> tuple:
    z = points[:, 2]
    height = float(np.ptp(z))
    tenth = np.minimum(((z - z.min()) / max(height, 1e-9) * 10).astype(int), 9)
    xy = points[:, :2]
    widths = [max(np.ptp(xy[tenth == k, 0]), np.ptp(xy[tenth == k, 1])) if (tenth == k).sum() > 1 else 0.0 for k in range(10)]
    distinct = len(np.unique(points, axis=0))
    return np.bincount(tenth, minlength=10) / len(points), np.asarray(widths) / height, height / max(np.ptp(xy, axis=0)), distinct


def main() -> None:
    kind, argv = sys.argv[1], sys.argv[sys.argv.index("--") + 1 :]
    config = sim2real_config(build_parser().parse_args(argv))
    sets = sim2real_run.prepare_sets(config, say=print)
    # the run's own recipe of one seed's sets, validated on the fit half (every mesh trains)
    built = sim2real_run._build_seed_sets(config, sets, 0, sets.meshes, [], {}, progress=False)["train"][kind]
    fit_half = (sets.real_points[sets.half_a], sets.real_labels[sets.half_a])
    for k, name in enumerate(sets.names):
        for tag, (clouds, labels) in (("real, fit half", fit_half), (kind, (built.points, built.labels))):
            rows = [cloud_stats(np.asarray(c, np.float64)) for c in clouds[labels == k]]
            ratio = np.array([r[2] for r in rows])
            print(f"{name:10s} {tag:15s} {len(rows):3d} clouds; height / width {np.percentile(ratio, 10):.2f} / {np.median(ratio):.2f} / "
                  f"{np.percentile(ratio, 90):.2f}; distinct points {np.median([r[3] for r in rows]):.0f}\n"
                  f"  % per tenth {' '.join(f'{v:.0f}' for v in 100 * np.mean([r[0] for r in rows], axis=0))}; "
                  f"width / height per tenth {' '.join(f'{v:.2f}' for v in np.median([r[1] for r in rows], axis=0))}")  # fmt: skip


if __name__ == "__main__":
    main()
