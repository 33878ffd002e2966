"""The sweep tables of docs/results/returns.md from an ``experiment returns`` output folder.

    python docs/results/returns/tables.py OUT > tables.md

Prints the divergence sweep (the multi-return share on vegetation per divergence and K, and the
shares of returns per vegetation pulse), the fitted divergences and the sub-ray count table
(shares ± sd, cost per pulse relative to K = 1), read from OUT/divergence_sweep.csv,
OUT/k_sweep.csv and OUT/run.json.
"""

from __future__ import annotations

import sys

from zbuf_occlude.io.json_files import read_json_file
from zbuf_occlude.io.tables import read_csv_rows


def pct(row: dict, key: str) -> str:
    return f"{100 * float(row[key]):.1f} ± {100 * float(row[key + '_sd']):.1f}"


def main(out: str) -> None:
    run = read_json_file(f"{out}/run.json", within=out)
    sweep = read_csv_rows(f"{out}/divergence_sweep.csv", within=out)
    ign = [r for r in sweep if abs(float(r["resolution_m"]) - run["model"]["range_resolution_m"]) < 1e-3]
    autzen = [r for r in sweep if r not in ign]
    for name, rows in (("IGN sample's fitted range resolution", ign), ("Autzen's fitted range resolution", autzen)):
        if not rows:
            continue
        print(f"\n**{name}, {float(rows[0]['resolution_m']):.2f} m**\n")
        print(
            "| divergence (mrad) | K | vegetation points from multi-return pulses (%) | vegetation pulses with 1 / 2 / 3 / 4 returns (%) | vegetation pulses |"
        )
        print("|---|---|---|---|---|")
        for r in rows:
            shares = " / ".join(f"{100 * float(r[f'returns_{n}']):.1f}" for n in (1, 2, 3, 4))
            print(
                f"| {float(r['divergence_mrad']):.3g} | {r['K']} | {pct(r, 'multi_return_share')} | {shares} | {int(r['vegetation_pulses']):,} |"
            )
    print("\n| fit | K | divergence (mrad) | ± sd (mrad) |\n|---|---|---|---|")
    fits = [("IGN", f) for f in run["divergence_fits"]] + ([("Autzen", run["autzen_fit"])] if "autzen_fit" in run else [])
    for name, f in fits:
        print(f"| {name} | {f['K']} | {f['divergence_mrad']:.3f} | {f['sd_mrad']:.3f} |")
    print(
        "\n| K | vegetation pulses with 1 / 2 / 3 / 4 returns (%, ± sd) | vegetation points from multi-return pulses (%) | µs per pulse | cost / K = 1 |"
    )
    print("|---|---|---|---|---|")
    for r in read_csv_rows(f"{out}/k_sweep.csv", within=out):
        shares = " / ".join(pct(r, f"returns_{n}") for n in (1, 2, 3, 4))
        marker = " **(recommended)**" if int(r["K"]) == run["recommended_k"] else ""
        print(
            f"| {r['K']}{marker} | {shares} | {pct(r, 'multi_return_share')} | {float(r['seconds_per_mpulse']):.1f} | "
            f"{float(r['cost_vs_smallest_K']):.1f}× |"
        )


if __name__ == "__main__":
    main(sys.argv[1])
