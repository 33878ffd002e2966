"""The airborne returns comparison over the street meshes' trees and over the procedural trees and shrubs, side by side.

usage: python docs/results/families/returns_table.py STREET.csv FAMILIES.csv
  STREET.csv, FAMILIES.csv  the comparison.csv of experiment returns with --plot street and with --plot families
                            (docs/results/families/returns/comparison_street.csv, comparison_families.csv)

Prints a Markdown table: per run (IGN with the fitted and with the data-sheet divergence; Autzen) and figure, the
real value, each plot's simulated value and verdict; then the PASS count of each plot.
"""

import csv
import sys
from pathlib import Path


def rows(path: Path) -> dict[tuple[str, str], dict]:
    with open(path, encoding="utf-8") as fh:
        return {(r["run"], r["figure"]): r for r in csv.DictReader(fh)}


def value(r: dict) -> str:
    v = float(r["simulated"])
    return f"{100 * v:.1f} %" if "pulses" in r["figure"] or "points" in r["figure"] else f"{v:.3g}"


def main() -> None:
    street, families = rows(Path(sys.argv[1])), rows(Path(sys.argv[2]))
    print("| run | figure | real | street meshes | procedural families | target |")
    print("|---|---|---|---|---|---|")
    for key, s in street.items():
        f = families[key]
        real = value({**s, "simulated": s["real"]})
        print(f"| {key[0]} | {key[1]} | {real} | {value(s)} {s['verdict']} | {value(f)} {f['verdict']} | {s['target']} |")
    for name, table in (("street meshes", street), ("procedural families", families)):
        passed = sum(r["verdict"] == "PASS" for r in table.values())
        print(f"\n{name}: {passed} of {len(table)} PASS", end="")
    print()


if __name__ == "__main__":
    main()
