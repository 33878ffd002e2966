"""``zbuf-occlude contact-sheet``: the argparse face of :func:`~zbuf_occlude.experiments.contact_sheet.contact_sheet`."""

from __future__ import annotations

import argparse
from typing import Any

from zbuf_occlude.cli.options import Checked, count, seed, shown
from zbuf_occlude.defaults import DEFAULT_SEED
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.contact_sheet import (
    DEFAULT_DPI,
    DEFAULT_PER_CLASS,
    DEFAULT_POSES,
    MAX_DPI,
    contact_sheet,
)

__all__ = ["add_contact_sheet_parser"]


def _dpi(text: str, option: str) -> int:
    """Dots per inch, 1 to :data:`~zbuf_occlude.experiments.contact_sheet.MAX_DPI`."""
    value = count(None)(text, option)
    if value > MAX_DPI:
        raise InvalidInputError(f"{option} must be at most {MAX_DPI} (MAX_DPI), got {shown(text)}")
    return value


def _cli_contact_sheet(args: argparse.Namespace) -> int:
    sheet = contact_sheet(args.path, args.out, per_class=args.per_class, poses=args.poses, seed=args.seed, dpi=args.dpi)
    print(f"{sheet.shape[0]} rows ({sheet.source}) -> {sheet.path}")
    return 0


def add_contact_sheet_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``contact-sheet`` subcommand to an argparse ``subparsers``; ``func`` returns an exit code."""
    p = subparsers.add_parser(
        "contact-sheet",
        help="a PNG of a few samples per class: fixed view, camera view, complete cloud",
        description=(
            "Draw a grid of a data set's samples (a few objects per class, a few poses each) or of a scan folder's "
            "scans: each row shows the cloud from one fixed viewpoint, from the camera or sensor that made it, and "
            "the complete cloud when the data set keeps it (compact storage)."
        ),
    )
    p.add_argument("path", metavar="DATASET_OR_SCAN_FOLDER", help="--out folder of farm or generate, or of scan (.npz scans)")
    p.add_argument("--out", required=True, help="the PNG to write")
    p.add_argument(
        "--per-class", action=Checked, check=count(None), default=DEFAULT_PER_CLASS,
        help="objects per class (scan folders: scans per mesh, times --poses) (default: %(default)s)",
    )  # fmt: skip
    p.add_argument("--poses", action=Checked, check=count(None), default=DEFAULT_POSES, help="poses per object (default: %(default)s)")
    p.add_argument(
        "--seed", action=Checked, check=seed, default=DEFAULT_SEED, help="chooses the objects, poses and scans (default: %(default)s)"
    )
    p.add_argument("--dpi", action=Checked, check=_dpi, default=DEFAULT_DPI, help="pixels per inch of the PNG (default: %(default)s)")
    p.set_defaults(func=_cli_contact_sheet)
    return p
