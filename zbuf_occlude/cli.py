"""Command-line interface ``zbuf-occlude`` (also ``python -m zbuf_occlude``).

Thin: parse arguments, call the library, print.  A :class:`ZbufOccludeError` is printed on
one line and the exit status is non-zero; any other exception is a bug and shows a traceback.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ._version import __version__
from .cameras import DEFAULT_RADIUS, camera_on_sphere, view_schedule
from .defaults import DEFAULT_DENSE_POINTS, DEFAULT_METHOD, DEFAULT_RESOLUTION, DEFAULT_VIEWS
from .errors import InvalidInputError, ZbufOccludeError
from .io import FORMATS, write_csv
from .mesh import load_mesh, scan_meshes
from .metrics import agreement
from .resources import MemoryEstimate, check_memory, estimate_job_memory
from .sampling import check_seed, sample_surface
from .visibility.registry import available_methods, get_method, method_info, visible_mask

__all__ = ["main", "build_parser", "SAMPLE_MESHES"]

log = logging.getLogger("zbuf_occlude")

#: Real ModelNet meshes shipped with a checkout (see data/samples/SOURCE.md).
SAMPLE_MESHES = Path(__file__).resolve().parents[1] / "data" / "samples"


def _default_paths(paths: list[str]) -> list[str]:
    if paths:
        return paths
    if not SAMPLE_MESHES.is_dir():
        raise InvalidInputError("no PATH given and the shipped sample meshes (data/samples) are not here; pass mesh files or folders")
    return [str(SAMPLE_MESHES)]


def _progress(iterable, **kwargs):
    from tqdm.auto import tqdm

    return tqdm(iterable, disable=None, **kwargs)


# -- generate ------------------------------------------------------------------------------
def cmd_generate(args: argparse.Namespace) -> int:
    """``generate`` runs on the farm's engine (:mod:`zbuf_occlude.farm.generate`)."""
    import shlex

    from .farm import FarmParams
    from .farm.generate import generate

    if args.protocol != "paper":  # the field's recipes (zbuf_occlude.protocols) have their own writers
        from .protocols.cli import run_protocol_command

        return run_protocol_command(args, _default_paths(args.paths))
    if args.severity is not None:
        raise InvalidInputError(f"--severity {args.severity} needs --protocol modelnet40-c-occlusion or modelnet40-c-lidar")
    params = FarmParams(
        views=args.views, samples_per_view=args.samples_per_view, n_points=args.points, dense_points=args.dense_points,
        resolution=args.resolution, seed=args.seed, radius=args.radius, storage=args.format, method=args.method,
    )  # fmt: skip
    paths = _default_paths(args.paths)
    # generate's engine (farm.run_farm) checks the options, the memory, --out and the GL before loading a mesh
    t0 = time.perf_counter()
    summary, objects = generate(
        paths, args.out, params=params, overwrite=args.overwrite, progress=True,
        command=shlex.join(["zbuf-occlude", *sys.argv[1:]]) if sys.argv else None,
    )  # fmt: skip
    elapsed = time.perf_counter() - t0
    print(
        f"{summary.done} meshes done, {summary.failed} failed, {summary.samples} samples "
        f"({summary.resumed} meshes from an earlier run) in {elapsed:.1f} s -> {args.out}"
    )
    source = {o.name: o.source for o in objects}
    for name, err in summary.failures:
        print(f"FAILED {source.get(name, name)}: {err}", file=sys.stderr)
    for path, reason in summary.skipped:
        print(f"SKIPPED {path}: {reason}", file=sys.stderr)
    return summary.exit_status


# -- validate ----------------------------------------------------------------------------------
def _check_at_least(args: argparse.Namespace, **lowest: int) -> None:
    """Usage errors name the option: ``--points must be an integer >= 1, got 0``."""
    for name, low in lowest.items():
        value = getattr(args, name)
        if value < low:
            raise InvalidInputError(f"--{name.replace('_', '-')} must be an integer >= {low}, got {value}")


def _check_validate_memory(points: int, resolution: int) -> None:
    """``validate`` holds a dense cloud of ``--points`` per mesh and one image of ``--resolution``."""
    est = estimate_job_memory(dense_points=points, resolution=resolution)
    check_memory(
        MemoryEstimate(
            {"--points": est.parts["--dense-points"], "--resolution": est.parts["--resolution"]},
            {"--points": points, "--resolution": resolution},
        )
    )


def cmd_validate(args: argparse.Namespace) -> int:
    _check_at_least(args, points=1, resolution=1)
    check_seed(args.seed, name="--seed")
    poses = view_schedule(args.views)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    for m in methods:
        get_method(m)  # unknown names fail here, before any work
    if any(method_info(m).takes_resolution for m in methods):
        from .render.context import check_image_size

        check_image_size(args.resolution, name="--resolution")
    _check_validate_memory(args.points, args.resolution)
    meshes, skipped = scan_meshes(_default_paths(args.paths))
    for item in skipped:
        print(f"SKIPPED {item}", file=sys.stderr)
    rows: list[dict] = []
    failed = len(skipped)
    header = f"{'mesh':32s} {'el':>6s} {'az':>6s} {'method':18s} {'agree%':>8s} {'f-vis%':>7s} {'f-hid%':>7s} {'ms':>8s} {'oracle ms':>9s}"
    print(header)
    for path, name in meshes:
        try:
            mesh = load_mesh(path)
        except ZbufOccludeError as exc:
            failed += 1
            print(f"FAILED {path}: {exc}", file=sys.stderr)
            continue
        points, face_index = sample_surface(mesh, count=args.points, seed=args.seed)
        for el, az in poses:
            camera = camera_on_sphere(el, az, args.radius, resolution=args.resolution)
            t = time.perf_counter()
            truth = visible_mask(mesh, points, camera, "oracle", face_index=face_index)
            oracle_ms = 1e3 * (time.perf_counter() - t)
            for method in methods:
                t = time.perf_counter()
                pred = visible_mask(mesh, points, camera, method, face_index=face_index, resolution=args.resolution)
                ms = 1e3 * (time.perf_counter() - t)
                a = agreement(pred, truth)
                rows.append({"mesh": name, "elevation_deg": el, "azimuth_deg": az, "method": method, "ms": ms, "oracle_ms": oracle_ms, **a})
                print(
                    f"{name[-32:]:32s} {el:6.1f} {az:6.1f} {method:18s} {100 * a['accuracy']:8.3f} "
                    f"{100 * a['false_visible']:7.3f} {100 * a['false_hidden']:7.3f} {ms:8.1f} {oracle_ms:9.1f}"
                )
    for method in methods:
        acc = [r["accuracy"] for r in rows if r["method"] == method]
        if acc:
            worst = min((r for r in rows if r["method"] == method), key=lambda r: r["accuracy"])
            print(
                f"{method}: mean agreement {100 * np.mean(acc):.3f} %, worst {100 * worst['accuracy']:.3f} % "
                f"({worst['mesh']} el={worst['elevation_deg']:g} az={worst['azimuth_deg']:g}), "
                f"median {np.median([r['ms'] for r in rows if r['method'] == method]):.1f} ms/view"
            )
    if args.csv and rows:
        write_csv(args.csv, rows)
    return 1 if failed else 0


# -- info -----------------------------------------------------------------------------------------
def cmd_info(args: argparse.Namespace) -> int:
    from .render.context import context_info, create_context

    info = context_info(create_context(args.gl))
    print(f"zbuf_occlude {__version__}")
    for key, value in info.items():
        print(f"GL {key:8s} {value}")
    print(f"methods     {', '.join(available_methods())}")
    return 0


# -- parser ------------------------------------------------------------------------------------------
def _add_common(p: argparse.ArgumentParser, *, points: int | None = None) -> None:
    p.add_argument("paths", nargs="*", metavar="PATH", help="mesh files or folders (recursive); default: the shipped sample meshes")
    p.add_argument("--views", default=DEFAULT_VIEWS, help="paper100 | grid25 | fibonacci:N | EL:AZ,EL:AZ,... (degrees)")
    p.add_argument("--points", type=int, default=points, help="points per sample (generate) or sampled per mesh (validate)")
    p.add_argument("--resolution", type=int, default=DEFAULT_RESOLUTION, help="z-buffer image size, pixels")
    p.add_argument("--radius", type=float, default=DEFAULT_RADIUS, help="camera distance, object units (object max extent is 1)")
    p.add_argument("--seed", type=int, default=0)


def build_parser() -> argparse.ArgumentParser:
    """The ``zbuf-occlude`` argument parser with every subcommand."""
    parser = argparse.ArgumentParser(prog="zbuf-occlude", description="Real-like occluded point clouds from meshes (headless z-buffer HSR).")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True)

    from .farm.generate import GENERATE_DEFAULTS as gd  # generate's defaults, taken from zbuf_occlude.defaults

    g = sub.add_parser("generate", help="occluded point clouds from meshes")
    _add_common(g)
    g.add_argument("--out", required=True, help="output folder")
    g.add_argument("--samples-per-view", type=int, help=f"random draws per pose (default: {gd.samples_per_view})")
    g.add_argument("--dense-points", type=int, help=f"dense cloud per mesh, drawn from per pose (default: {gd.dense_points})")
    g.add_argument("--format", choices=FORMATS, help=f"npz or ply: one file per sample; h5: PointNet's layout (default: {gd.storage})")
    g.add_argument("--method", help=f"visibility method (see `zbuf-occlude info`; default: {gd.method})")
    g.add_argument("--overwrite", action="store_true", help="start over (needed to change options in an existing --out)")
    from .protocols.cli import add_protocol_arguments

    add_protocol_arguments(g)
    g.set_defaults(
        func=cmd_generate, views=gd.views, points=gd.n_points, resolution=gd.resolution,
        samples_per_view=gd.samples_per_view, dense_points=gd.dense_points, format=gd.storage, method=gd.method,
    )  # fmt: skip

    v = sub.add_parser("validate", help="agreement of visibility methods with the exact oracle, per mesh and pose")
    _add_common(v, points=DEFAULT_DENSE_POINTS)
    v.add_argument("--methods", default=DEFAULT_METHOD, help="comma-separated methods to score")
    v.add_argument("--csv", help="also write the rows to this CSV file")
    v.set_defaults(func=cmd_validate)

    i = sub.add_parser("info", help="the OpenGL context zbuf_occlude gets here")
    i.add_argument("--gl", help="egl | osmesa | an order such as osmesa,egl (default: $ZBUF_OCCLUDE_GL or egl,osmesa)")
    i.set_defaults(func=cmd_info)

    # Subcommands whose options live beside their engines.
    from .compare import add_compare_parser
    from .farm import add_farm_merge_parser, add_farm_parser
    from .elevation_profile import add_profile_parser

    for add in (add_compare_parser, add_profile_parser, add_farm_parser, add_farm_merge_parser):
        add(sub)
    from .learn.cli import add_parser as add_experiment_parser  # zbuf-occlude experiment; torch only when it runs
    from .sensors.cli import add_realism_parser, add_scan_parser

    for add in (add_scan_parser, add_realism_parser, add_experiment_parser):
        add(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args) or 0)
    except ZbufOccludeError as exc:
        print(f"zbuf-occlude: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        # 130 after Ctrl-C (SIGINT), 143 after SIGTERM (farm.lifecycle.Terminated): 128 + the signal
        print("zbuf-occlude: interrupted; run the same command again to resume", file=sys.stderr)
        return 128 + getattr(exc, "signum", signal.SIGINT)


if __name__ == "__main__":
    sys.exit(main())
