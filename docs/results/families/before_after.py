"""Shape statistics of the families before and after the fit, against the real LiDARNet crops, as Markdown.

usage: python docs/results/families/before_after.py FOLDER
  FOLDER  the realism_classes_SET_CLASS.csv tables of two compare.sh runs with SIZING=class (the second with
          FIT=fitted_families.json), copied in as before_realism_classes_... and after_realism_classes_...
          (docs/results/families/fitted)

Prints one table per class: the real crops, the street meshes, each family before and after the fit: crops, median
points per crop, height, width, height / width, the median normalised height, the outline share and the profile
distance to the real crops (the share of points in another tenth of the height).
"""

import csv
import sys
from pathlib import Path

import numpy as np

SHARES = [f"share_{a:g}_{b:g}" for a, b in zip(np.round(np.arange(0, 1, 0.1), 1), np.round(np.arange(0.1, 1.01, 0.1), 1))]
COLUMNS = ("crops", "n_points", "height_m", "width_m", "height_to_width", "median_normalised_height", "outline_share")


def table(path: Path) -> dict[str, dict]:
    with open(path, encoding="utf-8") as fh:
        return {r["set"]: r for r in csv.DictReader(fh)}


def shares(row: dict) -> np.ndarray:
    return np.array([float(row[k]) for k in SHARES])


def main() -> None:
    folder = Path(sys.argv[1])
    for cls, family in (("pole", "trunk"), ("bush", "shrub")):
        street = table(folder / f"before_realism_classes_street_{cls}.csv")
        real = street["real"]
        rows = [("real (LiDARNet)", real), ("street meshes", street["generated"]),
                (f"{family}, before the fit", table(folder / f"before_realism_classes_{family}_{cls}.csv")["generated"]),
                (f"{family}, fitted", table(folder / f"after_realism_classes_{family}-fitted_{cls}.csv")["generated"])]  # fmt: skip
        print(f"\n**{cls}**\n")
        print("| set | crops | median points | height, m | width, m | height / width | median normalised height | outline share | "
              "% of points per tenth, bottom to top | profile distance to real |")  # fmt: skip
        print("|---|---|---|---|---|---|---|---|---|---|")
        for name, r in rows:
            d = 0.5 * float(np.abs(shares(r) - shares(real)).sum())
            cells = [f"{float(r[c]):.3g}" if c != "crops" else r[c] for c in COLUMNS]
            profile = " ".join(f"{100 * v:.0f}" for v in shares(r))
            print(f"| {name} | {' | '.join(cells)} | {profile} | {'—' if r is real else f'{d:.3f}'} |")


if __name__ == "__main__":
    main()
