"""Command-line interface ``zbuf-occlude`` (also ``python -m zbuf_occlude``).

Thin: parse arguments, call the library, print.  A :class:`ZbufOccludeError` is printed on
one line and the exit status is non-zero; any other exception is a bug and shows a traceback.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from . import __version__
from .cameras import DEFAULT_RADIUS, camera_on_sphere, view_schedule
from .errors import InvalidInputError, ZbufOccludeError
from .io import FORMATS, read_h5_clouds, write_csv, write_h5, write_npz, write_ply, write_text
from .mesh import class_and_split, find_meshes, load_mesh
from .metrics import agreement
from .occlude import DEFAULT_DENSE_POINTS, dense_cloud, object_key, occlude_object
from .sampling import sample_surface
from .visibility.registry import available_methods, get_method, visible_mask

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
def _write_clouds(fmt: str, folder: Path, name: str, pose_index: int, clouds) -> list[Path]:
    stem = Path(name).name
    written = []
    for c in clouds:
        # e.g. chair_0001_v007_el+030_az045_s03.npz: the pose index keeps names unique,
        # the angles (rounded to whole degrees) keep them readable.
        base = f"{stem}_v{pose_index:03d}_el{c.elevation_deg:+04.0f}_az{c.azimuth_deg:03.0f}_s{c.sample_index:02d}"
        written.append(write_npz(folder / f"{base}.npz", c) if fmt == "npz" else write_ply(folder / f"{base}.ply", c))
    return written


def cmd_generate(args: argparse.Namespace) -> int:
    meshes = find_meshes(_default_paths(args.paths))
    poses = view_schedule(args.views)
    out = Path(args.out)
    class_names = sorted({class_and_split(p)[0] for p, _ in meshes})
    labels = {c: i for i, c in enumerate(class_names)}
    done_dir = out / ".done"
    failed: list[tuple[str, str]] = []
    n_written = 0
    t0 = time.perf_counter()
    bar = _progress(meshes, desc="meshes", unit="mesh")
    for path, name in bar:
        marker = done_dir / f"{_flat(name)}.done"
        if marker.exists() and not args.overwrite:
            continue  # finished in an earlier run
        try:
            mesh = load_mesh(path)
            cls, _ = class_and_split(path)
            dense = dense_cloud(mesh, object_key(name), seed=args.seed, count=args.dense_points)
            parts = []
            for pose_index, _, clouds in occlude_object(
                mesh, poses, key=object_key(name), n_points=args.points, samples_per_view=args.samples_per_view,
                seed=args.seed, dense=dense, method=args.method, resolution=args.resolution, radius=args.radius,
                label=labels[cls], class_name=cls, source=str(path),
            ):  # fmt: skip
                if args.format == "h5":
                    parts.extend(clouds)
                else:
                    n_written += len(_write_clouds(args.format, out / name, name, pose_index, clouds))
            if args.format == "h5":
                write_h5(out / ".parts" / f"{_flat(name)}.h5", parts, shape_names=class_names)
                n_written += len(parts)
            write_text(marker, f"{path}\n")
        except ZbufOccludeError as exc:
            failed.append((str(path), str(exc)))
            log.error("skipped %s: %s", path, exc)
        bar.set_postfix(samples=n_written, failed=len(failed))
    if args.format == "h5":
        _merge_h5_parts(out, meshes, class_names)
    elapsed = time.perf_counter() - t0
    print(f"{len(meshes) - len(failed)} meshes done, {len(failed)} failed, {n_written} samples written in {elapsed:.1f} s -> {out}")
    for path, err in failed:
        print(f"FAILED {path}: {err}", file=sys.stderr)
    return 1 if failed else 0


def _flat(name: str) -> str:
    # one file per mesh in .done/ and .parts/: the mesh's relative name, flattened
    return name.replace("/", "__")


def _merge_h5_parts(out: Path, meshes, class_names) -> None:
    parts = [out / ".parts" / f"{_flat(name)}.h5" for _, name in meshes]
    clouds = [c for p in parts if p.exists() for c in read_h5_clouds(p)]
    if clouds:
        write_h5(out / "occluded.h5", clouds, shape_names=class_names)


# -- validate ----------------------------------------------------------------------------------
def cmd_validate(args: argparse.Namespace) -> int:
    meshes = find_meshes(_default_paths(args.paths))
    poses = view_schedule(args.views)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    for m in methods:
        get_method(m)  # unknown names fail here, before any work
    rows: list[dict] = []
    failed = 0
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
def _add_common(p: argparse.ArgumentParser, *, points: int) -> None:
    p.add_argument("paths", nargs="*", metavar="PATH", help="mesh files or folders (recursive); default: the shipped sample meshes")
    p.add_argument("--views", default="grid25", help="paper100 | grid25 | fibonacci:N | EL:AZ,EL:AZ,... (degrees)")
    p.add_argument("--points", type=int, default=points, help="points per sample (generate) or sampled per mesh (validate)")
    p.add_argument("--resolution", type=int, default=1024, help="z-buffer image size, pixels")
    p.add_argument("--radius", type=float, default=DEFAULT_RADIUS, help="camera distance, object units (object max extent is 1)")
    p.add_argument("--seed", type=int, default=0)


def build_parser() -> argparse.ArgumentParser:
    """The ``zbuf-occlude`` argument parser with every subcommand."""
    parser = argparse.ArgumentParser(prog="zbuf-occlude", description="Real-like occluded point clouds from meshes (headless z-buffer HSR).")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True)

    g = sub.add_parser("generate", help="occluded point clouds from meshes")
    _add_common(g, points=2048)
    g.add_argument("--out", required=True, help="output folder")
    g.add_argument("--samples-per-view", type=int, default=10, help="random draws per pose")
    g.add_argument("--dense-points", type=int, default=DEFAULT_DENSE_POINTS, help="dense cloud per mesh, drawn from per pose")
    g.add_argument("--format", choices=FORMATS, default="npz")
    g.add_argument("--method", default="zbuffer", help="visibility method (see `zbuf-occlude info`)")
    g.add_argument("--overwrite", action="store_true", help="redo meshes finished by an earlier run")
    g.set_defaults(func=cmd_generate)

    v = sub.add_parser("validate", help="agreement of visibility methods with the exact oracle, per mesh and pose")
    _add_common(v, points=100_000)
    v.add_argument("--methods", default="zbuffer", help="comma-separated methods to score")
    v.add_argument("--csv", help="also write the rows to this CSV file")
    v.set_defaults(func=cmd_validate)

    i = sub.add_parser("info", help="the OpenGL context zbuf_occlude gets here")
    i.add_argument("--gl", help="egl | osmesa | an order such as osmesa,egl (default: $ZBUF_OCCLUDE_GL or egl,osmesa)")
    i.set_defaults(func=cmd_info)

    # Subcommands whose options live beside their engines.
    from .compare import add_compare_parser
    from .farm import add_farm_merge_parser, add_farm_parser
    from .profile import add_profile_parser

    for add in (add_compare_parser, add_profile_parser, add_farm_parser, add_farm_merge_parser):
        add(sub)
    from .learn.cli import add_parser as add_experiment_parser  # zbuf-occlude experiment; torch only when it runs

    add_experiment_parser(sub)
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
    except KeyboardInterrupt:
        print("zbuf-occlude: interrupted; run the same command again to resume", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
