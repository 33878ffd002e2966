"""Shape statistics of the families before and after the fit, against the real LiDARNet crops, as Markdown.

usage: python docs/results/families/before_after.py FOLDER
  FOLDER  the realism_classes_SET_CLASS.csv tables of two compare.sh runs with SIZING=class (the second with
          FIT=fitted_families.json), copied in as before_realism_classes_... and after_realism_classes_...
          (docs/results/families/fitted)

Prints one table per class whose street table is in FOLDER: the real crops, the street meshes, each family whose tables
are in FOLDER before and after the fit: crops, median points per crop, height, width, height / width, the plan
elongation (a dash in tables made before it was measured), the median normalised height, the outline share and the
profile distance to the real crops (the share of points in another tenth of the height).
"""

import csv
import sys
from pathlib import Path

import numpy as np

SHARES = [f"share_{a:g}_{b:g}" for a, b in zip(np.round(np.arange(0, 1, 0.1), 1), np.round(np.arange(0.1, 1.01, 0.1), 1))]
COLUMNS = ("crops", "n_points", "height_m", "width_m", "height_to_width", "plan_elongation", "median_normalised_height", "outline_share")


def table(path: Path) -> dict[str, dict]:
    with open(path, encoding="utf-8") as fh:
        return {r["set"]: r for r in csv.DictReader(fh)}


def shares(row: dict) -> np.ndarray:
    return np.array([float(row[k]) for k in SHARES])


def families_of(folder: Path, cls: str) -> list[str]:
    """The families whose before-the-fit table of ``cls`` is in ``folder``, by name."""
    prefix, suffix = "before_realism_classes_", f"_{cls}.csv"
    return sorted(p.name[len(prefix) : -len(suffix)] for p in folder.glob(f"{prefix}*{suffix}") if p.name != f"{prefix}street{suffix}")


def cell(row: dict, column: str) -> str:
    """One column of a row; a column the table lacks (``plan_elongation``, before it was measured) as a dash."""
    value = row.get(column, "")
    return "—" if value in ("", None) else row[column] if column == "crops" else f"{float(value):.3g}"


def main() -> None:
    folder = Path(sys.argv[1])
    for cls in ("pole", "bush"):
        if not (folder / f"before_realism_classes_street_{cls}.csv").is_file():
            continue
        street = table(folder / f"before_realism_classes_street_{cls}.csv")
        real = street["real"]
        rows = [("real (LiDARNet)", real), ("street meshes", street["generated"])]
        for family in families_of(folder, cls):
            rows += [(f"{family}, before the fit", table(folder / f"before_realism_classes_{family}_{cls}.csv")["generated"]),
                     (f"{family}, fitted", table(folder / f"after_realism_classes_{family}-fitted_{cls}.csv")["generated"])]  # fmt: skip
        print(f"\n**{cls}**\n")
        print("| set | crops | median points | height, m | width, m | height / width | plan elongation | median normalised height | "
              "outline share | % of points per tenth, bottom to top | profile distance to real |")  # fmt: skip
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for name, r in rows:
            d = 0.5 * float(np.abs(shares(r) - shares(real)).sum())
            profile = " ".join(f"{100 * v:.0f}" for v in shares(r))
            print(f"| {name} | {' | '.join(cell(r, c) for c in COLUMNS)} | {profile} | {'—' if r is real else f'{d:.3f}'} |")


if __name__ == "__main__":
    main()
