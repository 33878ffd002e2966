"""``zbuf-occlude elevation-profile``: the argparse face of :func:`~zbuf_occlude.experiments.elevation_profile.elevation_profile`."""

from __future__ import annotations

import argparse
from typing import Any

from zbuf_occlude.cli.options import Checked, count, elevations, seed
from zbuf_occlude.defaults import DEFAULT_METHOD, DEFAULT_RESOLUTION, MAX_VIEWS
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.elevation_profile import (
    DEFAULT_AZIMUTHS,
    DEFAULT_ELEVATIONS,
    DEFAULT_PROFILE_POINTS,
    elevation_profile,
)
from zbuf_occlude.mesh.formats import EXTENSIONS_TEXT

__all__ = ["add_profile_parser"]


def _cli_profile(args: argparse.Namespace) -> int:
    import sys

    elevations_deg = args.elevations or DEFAULT_ELEVATIONS  # a given list was checked while parsing
    if len(elevations_deg) * args.azimuths > MAX_VIEWS:
        raise InvalidInputError(
            f"--elevations ({len(elevations_deg)}) times --azimuths ({args.azimuths}) is {len(elevations_deg) * args.azimuths:,} poses, "
            f"more than the {MAX_VIEWS:,} accepted (MAX_VIEWS)"
        )
    png = elevation_profile(
        args.mesh,
        args.out,
        method=args.method,
        points=args.dense_points,
        elevations=elevations_deg,
        azimuths=args.azimuths,
        resolution=args.resolution,
        seed=args.seed,
        progress=not args.no_progress,
    )
    sys.stdout.write(f"{png}\n{png.with_suffix('.csv')}\n")  # the command's output
    return 0


def add_profile_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``elevation-profile`` subcommand to an argparse ``subparsers``; ``func`` returns an exit code."""
    p = subparsers.add_parser(
        "elevation-profile",
        help="projected visible area vs camera elevation (Fig. 12 of the paper)",
        description=(
            "Projected area of the visible surface onto the x-y, y-z and x-z planes as a function of camera "
            "elevation (-90..90 degrees), averaged over azimuths. Writes a PNG and a CSV."
        ),
    )
    p.add_argument("mesh", help=f"mesh file ({EXTENSIONS_TEXT})")
    p.add_argument("--out", default="elevation_profile.png", help="PNG path or folder (default: %(default)s)")
    p.add_argument("--method", default=DEFAULT_METHOD, help="HSR method (default: %(default)s)")
    p.add_argument(
        "--dense-points", action=Checked, check=count("MAX_POINTS"), default=DEFAULT_PROFILE_POINTS,
        help="points sampled on the surface (default: %(default)s)",
    )  # fmt: skip
    p.add_argument("--elevations", action=Checked, check=elevations, default="", help="comma-separated degrees (default: -90..90 step 10)")
    p.add_argument(
        "--azimuths", action=Checked, check=count("MAX_VIEWS"), default=DEFAULT_AZIMUTHS,
        help="azimuths averaged per elevation (default: %(default)s)",
    )  # fmt: skip
    p.add_argument(
        "--resolution", action=Checked, check=count("MAX_RESOLUTION"), default=DEFAULT_RESOLUTION,
        help="image size in pixels (default: %(default)s)",
    )  # fmt: skip
    p.add_argument("--seed", action=Checked, check=seed, default=0, help="sampling seed (default: %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cli_profile)
    return p
