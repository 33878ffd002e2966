"""``zbuf-occlude realism``: generated against real clouds, per statistic and per class (:mod:`zbuf_occlude.experiments.realism`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from zbuf_occlude.cli.options import Checked, count, out_folder

__all__ = ["add_realism_parser"]


def cmd_realism(args: argparse.Namespace) -> int:
    from zbuf_occlude.experiments.realism import class_table, markdown_table, realism_report

    out_folder(args.out, "--out")  # the default's check; a given --out was checked while parsing
    print(f"reading {args.generated} and {args.real} ...", flush=True)
    rows, table = realism_report(args.generated, args.real, args.out, min_points=args.min_points, figure=not args.no_figure,
                                 ground_in_crops=args.ground_in_crops, airborne=args.airborne)  # fmt: skip
    print(markdown_table(rows) + "\n" + class_table(table), end="")
    print(f"wrote {Path(args.out) / 'realism.md'}, realism.csv, realism_classes.csv" + ("" if args.no_figure else ", realism.png"))
    return 0


def add_realism_parser(sub) -> argparse.ArgumentParser:
    """Add ``realism`` to the subparsers ``sub``."""
    p = sub.add_parser(
        "realism", help="generated vs real clouds: ring spacing, count-vs-range, spacing, extent; per class points, height/width, vertical profile",
        description="Compare statistics of generated scans with real LiDAR clouds and write realism.md, realism.csv, "
        "realism_classes.csv and a figure to --out.  Per class (the class folders both sets share, or all clouds pooled): "
        "points per crop, height over width, and how the points spread over the height (the median height above the "
        "crop's bottom and the share in each tenth of its height; a simulated pole that is a tall shaft where real crops "
        "show a squat top differs there).  --airborne compares aerial crops by these alone.",
    )  # fmt: skip
    p.add_argument(
        "generated",
        metavar="GENERATED",
        help="scan .npz files or a folder of them (in class folders, GENERATED/CLASS/*.npz, for the per-class table), or LiDARNet CSVs",
    )
    p.add_argument(
        "real", metavar="REAL", help="real scans: class folders of point-cloud files (aerial crops, ...), LiDARNet v2 CSVs, or scan .npz"
    )
    p.add_argument(
        "--out",
        action=Checked,
        check=out_folder,
        default="realism",
        help="folder for realism.md, realism.csv, realism_classes.csv, realism.png (default: %(default)s)",
    )
    p.add_argument(
        "--min-points",
        action=Checked,
        check=count("MAX_POINTS", lowest=0),
        default=1,
        help="ignore clouds with fewer points (default: %(default)s)",
    )
    p.add_argument(
        "--ground-in-crops", action="store_true",
        help="a generated scan file holding one object (a crop made with scan --crop --ground-margin) counts its ground "
        "returns as part of it, as a real crop holds them (default: ground returns never count)",
    )  # fmt: skip
    p.add_argument(
        "--airborne", action="store_true",
        help="the clouds are aerial crops (no sensor position in the files): compare per class only (rings and ranges "
        "need a sensor at the origin); the figure shows the height profiles",
    )  # fmt: skip
    p.add_argument("--no-figure", action="store_true", help="do not draw realism.png")
    p.set_defaults(func=cmd_realism)
    return p
