"""``zbuf-occlude experiment elevation|augmentation``: Table 3A and 3B of Sryamkin et al. 2023.

The parser is added without importing torch; torch is imported when a command runs.
"""

from __future__ import annotations

import argparse
from typing import Any

from zbuf_occlude.cli.options import Checked, check_device, count, out_folder, seed
from zbuf_occlude.cli.sim2real import THREADS_HELP, parse_pairs, print_table
from zbuf_occlude.defaults import DEFAULT_METHOD
from zbuf_occlude.experiments.table3.config import AUGMENTATION_MODEL, ELEVATION_MODEL, SCALES, Table3Config
from zbuf_occlude.mesh.formats import EXTENSIONS_TEXT

__all__ = ["add_parser"]


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "root", help=f"mesh tree in ModelNet's layout, CLASS/SPLIT/NAME.ext with files {EXTENSIONS_TEXT}; duplicate meshes are dropped"
    )
    p.add_argument(
        "--out", required=True, action=Checked, check=out_folder, help="output folder (results.csv, table.md, run.json, plots, checkpoints)"
    )
    p.add_argument(
        "--scale",
        choices=tuple(SCALES),
        default="quick",
        help="quick: fits a 2-core CPU; paper: the paper's sizes (ModelNet40 and a GPU) (default: %(default)s)",
    )
    p.add_argument("--epochs", action=Checked, check=count("MAX_EPOCHS"), help="override the scale's epoch count")
    p.add_argument("--points", action=Checked, check=count("MAX_POINTS"), help="points per cloud (override the scale's)")
    p.add_argument("--method", default=DEFAULT_METHOD, help="HSR method of the farm (default: %(default)s; og32/og64 are the paper's)")
    p.add_argument("--classes", help="comma-separated class names to keep")
    p.add_argument(
        "--data", action=Checked, check=out_folder, help="folder for the farm's data set (default OUT/data); reuse it across models"
    )
    p.add_argument(
        "--seed", action=Checked, check=seed, default=0, help="seed of the data set, the splits and the training (default: %(default)s)"
    )
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu", help="torch device of the training (default: %(default)s)")
    p.add_argument("--threads", action=Checked, check=count("MAX_WORKERS"), help=THREADS_HELP)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


#: The flag of each Table3Config field, named in its messages.
TABLE3_OPTIONS = {name: f"--{name}" for name in ("model", "scale", "epochs", "points", "method", "classes", "seed", "device", "threads")}


def _run(args: argparse.Namespace) -> int:
    # before anything imports torch: its CPU arithmetic is chosen at import (learn.reproducible)
    from zbuf_occlude.learn.reproducible import pin_cpu_arithmetic, training_threads

    pin_cpu_arithmetic()
    # the counts, --seed and --out were checked while parsing (cli.options); the device before any rendering
    check_device(args.device)
    from zbuf_occlude.experiments.table3 import run_augmentation, run_elevation

    classes = [c.strip() for c in args.classes.split(",")] if args.classes else None
    config = Table3Config(model=args.model, scale=args.scale, epochs=args.epochs, points=args.points, method=args.method,
                          classes=classes, seed=args.seed, device=args.device, threads=training_threads(args.threads), option_names=TABLE3_OPTIONS)  # fmt: skip
    progress = not args.no_progress
    if args.experiment == "elevation":
        summary = run_elevation(args.root, args.out, config, data_dir=args.data, profile=not args.no_profile, progress=progress)
    else:
        summary = run_augmentation(args.root, args.out, config, data_dir=args.data, real_scans=args.real_scans,
                                   label_map=parse_pairs(args.label_map, "--label-map"), progress=progress)  # fmt: skip
    return print_table(args.out, summary)


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``experiment`` (with ``elevation`` and ``augmentation``) to an argparse ``subparsers``."""
    p = subparsers.add_parser(
        "experiment", help="train PointNet/VoxNet/3DmFV on generated clouds (Table 3 of the paper)",
        description="Reproduce the paper's classification experiments: build the occluded data set with the farm, "
        "train a classifier and write the table (needs the learn extra: torch).",
    )  # fmt: skip
    sub = p.add_subparsers(dest="experiment", required=True)
    e = sub.add_parser(
        "elevation", help="Table 3A: train on elevations ±90,±70,±50,±20, test on ±80..0",
        description="Table 3A: train on clouds seen from elevations ±90, ±70, ±50, ±20 degrees and test on ±80..0.",
    )  # fmt: skip
    _common(e)
    e.add_argument("--model", choices=("pointnet", "voxnet", "3dmfv"), default=ELEVATION_MODEL, help="classifier (default: %(default)s)")
    e.add_argument("--no-profile", action="store_true", help="skip Fig. 12's visible-area curve in the plot")
    e.set_defaults(func=_run)
    a = sub.add_parser(
        "augmentation", help="Table 3B: C1 occluded / C2 complete / C3 both x Test 1/2 (/3 real scans)",
        description="Table 3B: train on occluded (C1), complete (C2) or both (C3) clouds and test on each "
        "(and on real scans with --real-scans).",
    )  # fmt: skip
    _common(a)
    a.add_argument("--model", choices=("voxnet", "3dmfv", "pointnet"), default=AUGMENTATION_MODEL, help="classifier (default: %(default)s)")
    a.add_argument("--real-scans", help="Test 3: SUO objects/ folder or LiDARNet v2 folder")
    a.add_argument("--label-map", help="rename real labels, REAL=MODEL,... (e.g. Car=car,4wd=car)")
    a.set_defaults(func=_run)
    from zbuf_occlude.cli.sim2real import add_sim2real_parser

    add_sim2real_parser(sub)
    from zbuf_occlude.cli.returns import add_returns_parser

    add_returns_parser(sub)
    return p
