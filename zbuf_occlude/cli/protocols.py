"""``zbuf-occlude generate --protocol NAME``: the options of the protocols and the command that runs them."""

from __future__ import annotations

import argparse
import sys
import time

from zbuf_occlude.cli.options import Checked, count, counted
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.protocols import PROTOCOL_NAMES, PROTOCOLS, get_protocol
from zbuf_occlude.protocols.base import ProtocolOptions, run_protocol
from zbuf_occlude.protocols.depth import DOWNSAMPLERS

__all__ = ["add_protocol_arguments", "run_protocol_command"]

_SEVERITY_PROTOCOLS = ("modelnet40-c-occlusion", "modelnet40-c-lidar")


def add_protocol_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--protocol`` and its options to ``generate``'s parser."""
    g = parser.add_argument_group("protocols (docs/guide/protocols.md)")
    g.add_argument(
        "--protocol", default="paper", choices=PROTOCOL_NAMES,
        help="paper: uniform samples of the visible surface (default); "
        + "; ".join(f"{p.name}: {p.summary}" for p in PROTOCOLS.values()),
    )  # fmt: skip
    g.add_argument("--severity", type=int, help="ModelNet40-C severity, 1..5 (modelnet40-c-* protocols)")
    g.add_argument("--downsample", default="random", choices=DOWNSAMPLERS, help="depth protocol: random or farthest-point down-sampling")
    g.add_argument("--normals", action="store_true", help="depth protocol: also write per-point face normals")
    g.add_argument("--camera-frame", action="store_true", help="depth protocol: also write camera-frame coordinates")
    g.add_argument(
        "--complete-points",
        action=Checked,
        check=count("MAX_POINTS", lowest=0),
        default=0,
        help="depth protocol: complete cloud beside the partial ones (pcn: default 16384)",
    )


def run_protocol_command(args: argparse.Namespace, paths: list[str]) -> int:
    """Run ``args.protocol`` (not ``paper``) over ``paths`` into ``args.out``; print a summary; the exit status.

    Raises
    ------
    InvalidInputError
        A bad option value (the message names it; the CLI exits 2).
    """
    protocol = get_protocol(args.protocol)
    if args.severity is not None and args.protocol not in _SEVERITY_PROTOCOLS:
        raise InvalidInputError(f"--severity {args.severity} applies only to {', '.join(_SEVERITY_PROTOCOLS)}")
    options = ProtocolOptions(
        severity=args.severity, seed=args.seed, views=args.views, resolution=args.resolution, radius=args.radius,
        n_points=args.points if args.protocol == "depth" else None, downsample=args.downsample, normals=args.normals,
        camera_frame=args.camera_frame, complete_points=args.complete_points, up=args.up,
    )  # fmt: skip
    t0 = time.perf_counter()
    run = run_protocol(protocol, paths, args.out, options, overwrite=args.overwrite, progress=not args.no_progress)
    print(
        f"{args.protocol}: {counted(run.done, 'mesh', 'meshes')} done, {run.resumed} from an earlier run, {len(run.failures)} failed "
        f"in {time.perf_counter() - t0:.1f} s -> {args.out}"
    )
    for path in run.files:
        print(f"  {path}")
    for source, err in run.failures:
        print(f"FAILED {source}: {err}", file=sys.stderr)
    return run.exit_status
