"""``zbuf-occlude verify DIR``: the argparse face of :func:`~zbuf_occlude.dataset.verify.verify_dataset`."""

from __future__ import annotations

import argparse

from zbuf_occlude.dataset.verify import verify_dataset

__all__ = ["add_verify_parser"]


def cmd_verify(args: argparse.Namespace) -> int:
    """Print every problem (exit 1) or a one-line summary (exit 0)."""
    import sys

    report = verify_dataset(args.path, progress=not args.no_progress)
    for problem in report.problems:
        print(f"PROBLEM {problem}", file=sys.stderr)
    if not report.ok:
        n = len(report.problems)
        print(f"{report.path}: {n} problem{'s' if n != 1 else ''} found; do not use this data set as it is", file=sys.stderr)
        return 1
    print(report.summary())
    return 0


def add_verify_parser(sub: argparse._SubParsersAction) -> None:
    """``zbuf-occlude verify DIR``."""
    p = sub.add_parser(
        "verify",
        help="check a data set (schema, paths, checksums) before using it",
        description="Check a data set folder: its card, manifest and class names against their schema, every path "
        "inside the folder, every file's SHA-256, every shard's datasets. Exit 0 when clean, 1 naming every problem.",
    )
    p.add_argument("path", metavar="DIR", help="the data set folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (or, when stderr is a file, no progress lines)")
    p.set_defaults(func=cmd_verify)
