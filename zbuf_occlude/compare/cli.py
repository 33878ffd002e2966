"""The ``zbuf-occlude compare`` command: :func:`run_compare` and its argparse face."""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..defaults import DEFAULT_RESOLUTION
from ..mesh_formats import EXTENSIONS_TEXT
from .report import write_results
from .run import DEFAULT_METHODS, DEFAULT_POINTS, DEFAULT_REFERENCE, DEFAULT_VIEWS, compare, parse_int_list, parse_methods

__all__ = ["run_compare", "add_compare_parser"]


def run_compare(
    paths: Sequence[str | os.PathLike],
    methods: str | Sequence[str] = DEFAULT_METHODS,
    points: str | Sequence[int] = DEFAULT_POINTS,
    views: str = DEFAULT_VIEWS,
    resolution: int = DEFAULT_RESOLUTION,
    out: str | os.PathLike = "compare_out",
    seed: int = 0,
    *,
    reference: str = DEFAULT_REFERENCE,
    resolution_sweep: str | Sequence[int] = (),
    grid_sweep: str | Sequence[int] = (),
    sweep_points: int | None = None,
    memory: bool = False,
    method_budget_s: float | None = None,
    progress: bool = True,
    command: str | None = None,
) -> Path:
    """``zbuf-occlude compare``: run :func:`compare` and :func:`write_results`; return the report path.

    Parameters
    ----------
    paths : sequence of path
        Mesh files.
    methods : str or sequence of str
        Comma-separated method names (default: :data:`DEFAULT_METHODS`).
    points : str or sequence of int
        Point counts, e.g. ``"1000,10000,50k"``.
    views : str
        Pose schedule: ``grid25`` (default), ``paper100``, ``fibonacci:N`` or ``EL:AZ,...``.
    resolution : int
        Z-buffer image size, pixels.
    out : path
        Output folder: ``results.csv``, ``report.md``, ``*.png``.
    seed : int
        Sampling seed.
    reference : str
        Method defining the truth (default ``oracle``).
    resolution_sweep, grid_sweep : str or sequence of int
        E.g. ``"128,256,512,1024,2048"`` and ``"16,32,64,128"``; empty: no sweep.
    sweep_points : int, optional
        Point count of the sweeps (default: the smallest of ``points``).
    memory : bool
        Record peak traced memory per method.
    method_budget_s : float, optional
        Skip a method at larger point counts once one view took longer than this.
    progress : bool
        Progress bar.
    command : str, optional
        The command line, quoted in the report.

    Returns
    -------
    Path
        ``out/report.md``.

    Raises
    ------
    InvalidInputError
        Bad methods, counts or views.
    OutputError
        ``out`` not writable.
    """
    rows = compare(
        paths,
        parse_methods(methods),
        parse_int_list(points, "point counts"),
        views,
        int(resolution),
        int(seed),
        reference=reference,
        resolution_sweep=parse_int_list(resolution_sweep, "resolutions"),
        grid_sweep=parse_int_list(grid_sweep, "grid sizes"),
        sweep_points=sweep_points,
        memory=memory,
        method_budget_s=method_budget_s,
        progress=progress,
    )
    return write_results(rows, out, command=command)


def _cli_compare(args: argparse.Namespace) -> int:
    import shlex
    import sys

    report = run_compare(
        args.paths,
        args.methods,
        args.points,
        args.views,
        args.resolution,
        args.out,
        args.seed,
        reference=args.reference,
        resolution_sweep=args.resolution_sweep,
        grid_sweep=args.grid_sweep,
        sweep_points=args.sweep_points,
        memory=args.memory,
        method_budget_s=args.method_budget,
        progress=not args.no_progress,
        command="zbuf-occlude " + " ".join(shlex.quote(a) for a in sys.argv[1:]),
    )
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
    p.add_argument("--points", default=",".join(str(n) for n in DEFAULT_POINTS), help="point counts (default: %(default)s)")
    p.add_argument("--views", default=DEFAULT_VIEWS, help="pose schedule: grid25, paper100, fibonacci:N or EL:AZ,... (default: %(default)s)")
    p.add_argument("--resolution", type=int, default=DEFAULT_RESOLUTION, help="z-buffer resolution in pixels (default: %(default)s)")
    p.add_argument("--out", default="compare_out", help="output folder (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="sampling seed (default: %(default)s)")
    p.add_argument("--reference", default=DEFAULT_REFERENCE, help="method that defines the truth (default: %(default)s)")
    p.add_argument("--resolution-sweep", default="", help="e.g. 128,256,512,1024,2048: agreement vs resolution")
    p.add_argument("--grid-sweep", default="", help="e.g. 16,32,64,128: agreement vs occupancy-grid size")
    p.add_argument("--sweep-points", type=int, default=None, help="point count of the sweeps (default: smallest --points)")
    p.add_argument("--memory", action="store_true", help="also record peak traced memory per method")
    p.add_argument("--method-budget", type=float, default=None, help="seconds per view after which a method is skipped at larger point counts")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cli_compare)
    return p
