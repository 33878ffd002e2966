"""Are roofs what keeps Autzen's intensity ratio low?  Planar points in its high vegetation, measured.

    .venv/bin/python docs/results/returns/canopy/roofs.py ../shared/data/als_returns/autzen_trim.laz \
        > docs/results/returns/canopy/roofs.txt

Autzen's class 1 is classed by height as ``experiment returns`` classes it
(:func:`~zbuf_occlude.experiments.canopy.classes_by_height`).  Its high vegetation (class 5) then
holds whatever stands 1.5 m above the ground, roofs too.  A roof is a plane at the scale of a few
points; a crown is not.  For each class-5 point: the covariance of its ``K`` nearest points in 3D
(metres; scipy's k-d tree) and its *surface variation* λ₃ / (λ₁ + λ₂ + λ₃), the smallest
eigenvalue's share (Pauly, Gross & Kobbelt 2002, "Efficient simplification of point-sampled
surfaces"; 0 on a plane, 1/3 for an isotropic scatter).  The histogram of log₁₀ of it is printed;
the points below the trough between its two modes are taken as roofs, their returns and
intensities are printed, and ``return_statistics`` is given with them moved to class 6
(building) and without, and each class's median intensities.  Geometry alone picks the roofs: neither return numbers nor intensities
enter the rule.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from zbuf_occlude.experiments.canopy import classes_by_height, heights_above_ground
from zbuf_occlude.io.las import read_las
from zbuf_occlude.sensors.fit.returns import return_statistics

#: Neighbours of a point's covariance: a few metres of Autzen's ~2.5 first returns per m².
K = 12
#: log₁₀ surface variation below which a point is on a plane: the histogram's trough (printed).
LOG_TROUGH = -2.75
ROWS = ("multi_return_points_classes_3_4_5", "intensity_single_classes_3_4_5", "intensity_first_of_several_classes_3_4_5",
        "intensity_ratio_classes_3_4_5")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("autzen", help="autzen_trim.laz")
    path = parser.parse_args().autzen
    las = read_las(path)
    las = classes_by_height(las, heights_above_ground(las))
    points = las.points * las.metres_per_unit
    high = np.flatnonzero(las.classification == 5)
    _, nearest = cKDTree(points).query(points[high], k=K)
    neighbourhoods = points[nearest]  # (M, K, 3)
    centred = neighbourhoods - neighbourhoods.mean(axis=1, keepdims=True)
    eigen = np.linalg.eigvalsh(np.einsum("mki,mkj->mij", centred, centred) / K)
    log_variation = np.log10(np.maximum(eigen[:, 0] / eigen.sum(axis=1), 1e-6))
    print(f"{path}: {len(high):,} points of class 5 (class 1 classed by height), K = {K}")
    counts, edges = np.histogram(log_variation, bins=np.arange(-6.0, 0.01, 0.25))
    print("log10 surface variation: points")
    for left, n in zip(edges, counts, strict=False):
        if n:
            print(f"  [{left:+.2f}, {left + 0.25:+.2f}): {n:6,d} {'#' * int(np.ceil(60 * n / counts.max()))}")
    planar = log_variation < LOG_TROUGH
    singles = las.number_of_returns[high] == 1
    print(f"planar (log10 < {LOG_TROUGH}): {planar.sum():,} points, {planar.mean():.1%} of class 5")
    for name, mask in (("planar", planar), ("the rest", ~planar)):
        print(f"  {name}: single returns {singles[mask].mean():.1%}; median intensity of single returns "
              f"{np.median(las.intensity[high][mask & singles]):.0f}")  # fmt: skip
    first_of_several = (las.return_number == 1) & (las.number_of_returns > 1)
    print("median intensity by class (classes by height), single returns / first of several:")
    for code in (2, 4, 5):
        mask = las.classification == code
        single, first = las.intensity[mask & (las.number_of_returns == 1)], las.intensity[mask & first_of_several]
        print(f"  class {code}: {mask.sum():,} points, from multi-return pulses {np.mean(las.number_of_returns[mask] > 1):.1%}; "
              f"{np.median(single):.0f} ({len(single):,}) / {np.median(first) if len(first) else float('nan'):.0f} ({len(first):,})")  # fmt: skip
    classes = las.classification.copy()
    classes[high[planar]] = 6
    for label, scan in (("class 5 as classed by height", las), ("planar points moved to class 6", replace(las, classification=classes))):
        stats = return_statistics(scan)
        print(f"return_statistics, {label}:")
        for row in ROWS:
            print(f"  {row}: {stats.estimates[row].value:.4g}")


if __name__ == "__main__":
    main()
