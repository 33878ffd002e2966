"""The ``zbuf-occlude compare`` command: the argparse face of :func:`~zbuf_occlude.experiments.compare.job.run_compare`."""

from __future__ import annotations

import argparse
from typing import Any

from zbuf_occlude.cli.options import Checked, count, count_list, out_folder, poses, real, seed
from zbuf_occlude.defaults import DEFAULT_RESOLUTION, DEFAULT_VIEWS
from zbuf_occlude.experiments.compare.config import DEFAULT_METHODS, DEFAULT_POINTS, DEFAULT_REFERENCE, CompareConfig
from zbuf_occlude.experiments.compare.job import run_compare
from zbuf_occlude.mesh.formats import EXTENSIONS_TEXT

__all__ = ["add_compare_parser"]


#: The flag of each CompareConfig field, named in its messages.
COMPARE_OPTIONS = {
    "methods": "--methods", "points": "--dense-points", "views": "--views", "resolution": "--resolution", "seed": "--seed",
    "reference": "--reference", "resolution_sweep": "--resolution-sweep", "grid_sweep": "--grid-sweep",
    "sweep_points": "--sweep-points", "method_budget_s": "--method-budget",
}  # fmt: skip


def _cli_compare(args: argparse.Namespace) -> int:
    import shlex
    import sys

    out_folder(args.out, "--out")  # the default's check; a given --out was checked while parsing
    config = CompareConfig(
        methods=args.methods, points=args.dense_points, views=args.views, resolution=args.resolution, seed=args.seed,
        reference=args.reference, resolution_sweep=args.resolution_sweep, grid_sweep=args.grid_sweep,
        sweep_points=args.sweep_points, memory=args.memory, method_budget_s=args.method_budget, option_names=COMPARE_OPTIONS,
    )  # fmt: skip
    command = "zbuf-occlude " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    report = run_compare(args.paths, args.out, config, progress=not args.no_progress, command=command)
    sys.stdout.write(f"{report}\n")  # the command's output: where the report went
    return 0


def add_compare_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``compare`` subcommand to an argparse ``subparsers``; ``func`` returns an exit code."""
    p = subparsers.add_parser(
        "compare",
        help="time every HSR method and score it against the exact oracle",
        description=(
            "For every mesh x point count x camera pose x method: wall time per view and agreement with "
            "the oracle (accuracy, false-visible and false-hidden rates, IoU, Chamfer distance). Writes "
            "results.csv, report.md and PNG plots into --out."
        ),
    )
    p.add_argument("paths", nargs="+", help=f"mesh files ({EXTENSIONS_TEXT}) or folders (searched recursively)")
    p.add_argument("--methods", default=",".join(DEFAULT_METHODS), help="comma-separated methods (default: %(default)s)")
    p.add_argument(
        "--dense-points", action=Checked, check=count_list("MAX_POINTS"), default=",".join(str(n) for n in DEFAULT_POINTS),
        help="points sampled on each mesh, one run per count, comma-separated (default: %(default)s)",
    )  # fmt: skip
    p.add_argument(
        "--views", action=Checked, check=poses, default=DEFAULT_VIEWS,
        help="pose schedule: grid25, paper100, fibonacci:N or EL:AZ,... (default: %(default)s)",
    )  # fmt: skip
    p.add_argument(
        "--resolution", action=Checked, check=count("MAX_RESOLUTION"), default=DEFAULT_RESOLUTION,
        help="z-buffer resolution in pixels (default: %(default)s)",
    )  # fmt: skip
    p.add_argument("--out", action=Checked, check=out_folder, default="compare_out", help="output folder (default: %(default)s)")
    p.add_argument("--seed", action=Checked, check=seed, default=0, help="sampling seed (default: %(default)s)")
    p.add_argument("--reference", default=DEFAULT_REFERENCE, help="method that defines the truth (default: %(default)s)")
    p.add_argument(
        "--resolution-sweep", action=Checked, check=count_list("MAX_RESOLUTION", empty=True), default="",
        help="e.g. 128,256,512,1024,2048: agreement vs resolution",
    )  # fmt: skip
    p.add_argument(
        "--grid-sweep", action=Checked, check=count_list("MAX_GRID", empty=True), default="",
        help="e.g. 16,32,64,128: agreement vs occupancy-grid size",
    )  # fmt: skip
    p.add_argument(
        "--sweep-points", action=Checked, check=count("MAX_POINTS"), default=None,
        help="point count of the sweeps (default: smallest --points)",
    )  # fmt: skip
    p.add_argument("--memory", action="store_true", help="also record peak traced memory per method")
    p.add_argument(
        "--method-budget", action=Checked, check=real(0.0, above=True), default=None,
        help="seconds per view after which a method is skipped at larger point counts",
    )  # fmt: skip
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cli_compare)
    return p
