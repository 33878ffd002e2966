"""Command-line interface ``zbuf-occlude`` (also ``python -m zbuf_occlude``).

Thin: parse arguments, call the library, print.  Every option is checked while the command line
is parsed (:mod:`zbuf_occlude.cli.options`: counts against their caps, seeds, reals, pose lists,
output folders), before any work.  A :class:`ZbufOccludeError` is printed on one line and the
exit status is 2; running out of memory (a ``MemoryError`` anywhere) is one line naming the
command, what it was doing and the file when known, exit status 1; a closed pipe on stdout
exits 141 quietly and an unwritable or missing stdout (``>&-``) is one line, exit 1
(:func:`main`); any other exception is a bug and shows a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import logging
import os
import signal
import sys
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from zbuf_occlude._version import __version__
from zbuf_occlude.cli.first_run import say_if_cold
from zbuf_occlude.cli.options import Checked, Parser, count, counted, given_params, out_folder, poses, real, seed
from zbuf_occlude.defaults import DEFAULT_DENSE_POINTS, DEFAULT_METHOD, DEFAULT_RESOLUTION, DEFAULT_SEED, DEFAULT_VIEWS
from zbuf_occlude.errors import InvalidInputError, ZbufOccludeError
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS, camera_on_sphere, view_schedule
from zbuf_occlude.io.atomic import write_csv
from zbuf_occlude.io.clouds import FORMATS
from zbuf_occlude.mesh.formats import EXTENSIONS_TEXT
from zbuf_occlude.mesh.inputs.kinds import plan_nouns
from zbuf_occlude.resources import check_memory, estimate_job_memory
from zbuf_occlude.visibility.metrics import agreement
from zbuf_occlude.visibility.registry import (
    available_methods,
    check_runnable,
    method_info,
    resolution_option,
    unavailable_reason,
    visible_mask,
)

__all__ = ["SAMPLE_MESHES", "build_parser", "main"]

log = logging.getLogger("zbuf_occlude")

#: Real ModelNet meshes shipped with a checkout (see data/samples/SOURCE.md).
SAMPLE_MESHES = Path(__file__).resolve().parents[2] / "data" / "samples"


def _default_paths(paths: list[str]) -> list[str]:
    if paths:
        return paths
    if not SAMPLE_MESHES.is_dir():
        raise InvalidInputError(
            f"no PATH given and there are no sample meshes at {SAMPLE_MESHES} (only a checkout of the repository "
            "ships data/samples; an installed wheel has none): pass mesh files or folders"
        )
    return [str(SAMPLE_MESHES)]


# -- generate ------------------------------------------------------------------------------
def cmd_generate(args: argparse.Namespace) -> int:
    """``generate`` runs on the farm's engine (:mod:`zbuf_occlude.farm.generate`)."""
    import shlex

    from zbuf_occlude.cli.farm import GIVEN_PARAMS
    from zbuf_occlude.farm import FarmParams
    from zbuf_occlude.farm.generate import generate

    if args.protocol != "paper":  # the field's recipes (zbuf_occlude.protocols) have their own writers
        from zbuf_occlude.cli.protocols import run_protocol_command

        return run_protocol_command(args, _default_paths(args.paths))
    if args.severity is not None:
        raise InvalidInputError(f"--severity {args.severity} needs --protocol modelnet40-c-occlusion or modelnet40-c-lidar")
    params = FarmParams(
        views=args.views, samples_per_view=args.samples_per_view, n_points=args.points, dense_points=args.dense_points,
        resolution=args.resolution, seed=args.seed, radius=args.radius, storage=args.format, method=args.method,
        up=args.up,
    )  # fmt: skip
    paths = _default_paths(args.paths)
    # generate's engine (farm.run_farm) checks the options, the memory, --out and the GL before loading a mesh
    t0 = time.perf_counter()
    summary, objects = generate(
        paths, args.out, params=params, overwrite=args.overwrite, progress=not args.no_progress, isolate=True,
        command=shlex.join(["zbuf-occlude", *sys.argv[1:]]) if sys.argv else None, class_from=args.class_from,
        set_params=given_params(args, GIVEN_PARAMS),
    )  # fmt: skip
    elapsed = time.perf_counter() - t0
    nouns = plan_nouns(objects)  # "meshes", "clouds" (point-set inputs), or "objects" for both
    print(
        f"{counted(summary.done, *nouns)} done, {summary.failed} failed, {counted(summary.samples, 'sample')} "
        f"({counted(summary.resumed, *nouns)} from an earlier run) in {elapsed:.1f} s -> {args.out}"
    )
    source = {o.name: o.source for o in objects}
    for name, err in summary.failures:
        print(f"FAILED {source.get(name, name)}: {err}", file=sys.stderr)
    for path, reason in summary.skipped:
        print(f"SKIPPED {path}: {reason}", file=sys.stderr)
    return summary.exit_status


# -- validate ----------------------------------------------------------------------------------
def _check_validate_memory(points: int, resolution: int) -> None:
    """``validate`` holds a dense cloud of ``--dense-points`` per mesh and one image of ``--resolution``."""
    check_memory(estimate_job_memory(dense_points=points, resolution=resolution))


def cmd_validate(args: argparse.Namespace) -> int:
    from zbuf_occlude.geometry.sampling import sample_surface
    from zbuf_occlude.mesh.inputs.discovery import scan_meshes
    from zbuf_occlude.mesh.load import load_mesh  # trimesh (and scipy): imported by the commands that load meshes

    # the counts, --seed and --views were checked when the command line was parsed (cli.options)
    from zbuf_occlude.farm.checks import check_radius

    check_radius(args.radius, args.resolution)
    poses = view_schedule(args.views)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    for m in methods:
        check_runnable(m)  # unknown names and missing extras fail here, before any output
    if any(method_info(m).takes_resolution for m in methods):
        from zbuf_occlude.render.context import check_image_size

        check_image_size(args.resolution, name="--resolution")
    _check_validate_memory(args.dense_points, args.resolution)
    meshes, skipped = scan_meshes(_default_paths(args.paths))
    for item in skipped:
        print(f"SKIPPED {item}", file=sys.stderr)
    rows: list[dict] = []
    failed = len(skipped)
    header = f"{'mesh':32s} {'el':>6s} {'az':>6s} {'method':18s} {'agree%':>8s} {'f-vis%':>7s} {'f-hid%':>7s} {'ms':>8s} {'oracle ms':>9s}"
    print(header)
    options = {m: resolution_option(m, args.resolution) for m in methods}
    for path, name in meshes:
        try:
            mesh = load_mesh(path)
        except ZbufOccludeError as exc:
            failed += 1
            print(f"FAILED {path}: {exc}", file=sys.stderr)
            continue
        points, face_index = sample_surface(mesh, count=args.dense_points, seed=args.seed)
        for el, az in poses:
            camera = camera_on_sphere(el, az, args.radius, resolution=args.resolution)
            t = time.perf_counter()
            truth = visible_mask(mesh, points, camera, "oracle", face_index=face_index)
            oracle_ms = 1e3 * (time.perf_counter() - t)
            for method in methods:
                t = time.perf_counter()
                pred = visible_mask(mesh, points, camera, method, face_index=face_index, **options[method])
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
    from zbuf_occlude.render.context import context_info, create_context

    info = context_info(create_context(args.gl))
    print(f"zbuf_occlude {__version__}")
    for key, value in info.items():
        print(f"GL {key:8s} {value}")
    missing = {m: unavailable_reason(m) for m in available_methods()}
    print(f"methods     {', '.join(m for m, why in missing.items() if why is None)}")
    not_here = [m for m, why in missing.items() if why is not None]
    if not_here:  # listed apart: `--method` with one of them fails here
        print(f"not here    {', '.join(not_here)} (their extras are not installed)")
    return 0


# -- parser ------------------------------------------------------------------------------------------
#: The paths' help of generate and validate: a wheel ships no sample meshes (only a checkout has data/samples).
PATHS_HELP = (
    f"mesh files ({EXTENSIONS_TEXT}) or folders, searched recursively; classes and splits come from "
    "the folder's layout (ModelNet, ShapeNetCore, CLASS/NAME; see docs/guide/inputs.md) "
    "(default: the sample meshes in a checkout's data/samples; an installed wheel has none: pass PATH)"
)


#: Other names ``--format`` takes: ``hdf5``, the format's own name, is ``h5``, its files' extension.
FORMAT_ALIASES = {"hdf5": "h5"}


def _format(text: str) -> str:
    """``--format``'s value: an alias of :data:`FORMAT_ALIASES` as the name it stands for (argparse checks the choice)."""
    return FORMAT_ALIASES.get(text, text)


def _add_paths(p: argparse.ArgumentParser) -> None:
    p.add_argument("paths", nargs="*", metavar="PATH", help=PATHS_HELP)


def build_parser() -> argparse.ArgumentParser:
    """The ``zbuf-occlude`` argument parser with every subcommand."""
    from zbuf_occlude.cli.farm import (
        CLASS_FROM, CLASS_FROM_HELP, NOT_FOR_POINT_SETS, POINT_SETS_HELP, POINT_SETS_POINTS_WHY, RADIUS_HELP, UP_HELP, VIEWS_HELP,
    )  # fmt: skip
    from zbuf_occlude.mesh.inputs.kinds import DEFAULT_POINT_SET_POINTS
    from zbuf_occlude.defaults import DEFAULT_FARM_DENSE_POINTS, DEFAULT_FARM_RESOLUTION
    from zbuf_occlude.defaults import DEFAULT_FARM_VIEWS as FARM_VIEWS
    from zbuf_occlude.farm.config import GENERATE_DEFAULTS as gd  # generate's defaults, taken from zbuf_occlude.defaults
    from zbuf_occlude.mesh.scene import UP_CHOICES

    parser = Parser(prog="zbuf-occlude", description="Real-like occluded point clouds from meshes (headless z-buffer HSR).")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True)

    g = sub.add_parser(
        "generate", help="occluded point clouds from a few meshes or point-set files",
        description="Render each mesh from each pose, keep the points the camera sees, and write samples of "
        "--points points to --out; point-set files (PointNet HDF5, .npy, .ply without faces) are seen from "
        "their points alone. Run it again to resume; `farm` builds large data sets.",
    )  # fmt: skip
    g.add_argument("paths", nargs="*", metavar="PATH", help=f"{PATHS_HELP}. {POINT_SETS_HELP}")
    g.add_argument("--out", required=True, action=Checked, check=out_folder, help="output folder (created; must not be a file)")
    g.add_argument("--views", action=Checked, check=poses, help=f"{VIEWS_HELP} (default: {gd.views}; the farm's: {FARM_VIEWS})")
    g.add_argument(
        "--points", action=Checked, check=count("MAX_POINTS"),
        help=f"points per sample (default: {gd.n_points}; point sets: {DEFAULT_POINT_SET_POINTS}, {POINT_SETS_POINTS_WHY})",
    )  # fmt: skip
    g.add_argument(
        "--samples-per-view", action=Checked, check=count("MAX_SAMPLES"),
        help=f"random samples drawn per pose (default: {gd.samples_per_view})",
    )  # fmt: skip
    g.add_argument(
        "--dense-points", action=Checked, check=count("MAX_POINTS"),
        help=f"dense cloud sampled once per mesh, drawn from per pose (default: {gd.dense_points}; the farm's: {DEFAULT_FARM_DENSE_POINTS}; {NOT_FOR_POINT_SETS})",
    )  # fmt: skip
    g.add_argument(
        "--resolution", action=Checked, check=count("MAX_RESOLUTION"),
        help=f"z-buffer image size, pixels (default: {gd.resolution}; the farm's: {DEFAULT_FARM_RESOLUTION}; {NOT_FOR_POINT_SETS})",
    )  # fmt: skip
    g.add_argument("--radius", action=Checked, check=real(), default=gd.radius, help=f"{RADIUS_HELP} (default: %(default)s)")
    g.add_argument(
        "--seed", action=Checked, check=seed, default=gd.seed,
        help="global seed: the same seed and options give the same samples (default: %(default)s)",
    )  # fmt: skip
    g.add_argument(
        "--format", type=_format, choices=FORMATS, metavar=f"{{{','.join([*FORMATS, *FORMAT_ALIASES])}}}",
        help=f"npz or ply: one file per sample; h5 (or hdf5): PointNet's layout (default: {gd.storage})",
    )  # fmt: skip
    g.add_argument("--method", help=f"visibility method (see `zbuf-occlude info`) (default: {gd.method})")
    g.add_argument("--class-from", action=Checked, check=CLASS_FROM, metavar="N", help=CLASS_FROM_HELP)
    g.add_argument("--up", choices=UP_CHOICES, default="auto", help=UP_HELP)
    g.add_argument("--overwrite", action="store_true", help="start over (needed to change options in an existing --out)")
    g.add_argument("--no-progress", action="store_true", help="no progress bar (or, when stderr is a file, no progress lines)")
    from zbuf_occlude.cli.protocols import add_protocol_arguments

    add_protocol_arguments(g)
    g.set_defaults(
        func=cmd_generate, views=gd.views, points=gd.n_points, resolution=gd.resolution,
        samples_per_view=gd.samples_per_view, dense_points=gd.dense_points, format=gd.storage, method=gd.method,
    )  # fmt: skip

    v = sub.add_parser(
        "validate", help="agreement of visibility methods with the exact oracle, per mesh and pose",
        description="Sample --points points on each mesh, decide their visibility per pose with each of --methods "
        "and with the exact oracle, and print the agreement (false-visible, false-hidden) and the time per view.",
    )  # fmt: skip
    _add_paths(v)
    v.add_argument(
        "--methods", default=DEFAULT_METHOD, help="comma-separated methods to score (see `zbuf-occlude info`) (default: %(default)s)"
    )
    v.add_argument("--views", action=Checked, check=poses, default=DEFAULT_VIEWS, help=f"{VIEWS_HELP} (default: %(default)s)")
    v.add_argument(
        "--dense-points", action=Checked, check=count("MAX_POINTS"), default=DEFAULT_DENSE_POINTS,
        help="points sampled on each mesh's surface, scored per pose (default: %(default)s)",
    )  # fmt: skip
    v.add_argument(
        "--resolution", action=Checked, check=count("MAX_RESOLUTION"), default=DEFAULT_RESOLUTION,
        help="z-buffer image size of the image-space methods, pixels (default: %(default)s)",
    )  # fmt: skip
    v.add_argument("--radius", action=Checked, check=real(), default=DEFAULT_RADIUS, help=f"{RADIUS_HELP} (default: %(default)s)")
    v.add_argument("--seed", action=Checked, check=seed, default=DEFAULT_SEED, help="seed of the surface sampling (default: %(default)s)")
    v.add_argument("--csv", help="also write the rows to this CSV file")
    v.set_defaults(func=cmd_validate)

    i = sub.add_parser(
        "info", help="the OpenGL context and the visibility methods available here",
        description="Make an OpenGL context as the other commands do, print its renderer and version, "
        "and list the visibility methods that can run here.",
    )  # fmt: skip
    i.add_argument("--gl", help="egl | osmesa | an order such as osmesa,egl (default: $ZBUF_OCCLUDE_GL or egl,osmesa)")
    i.set_defaults(func=cmd_info)

    # Subcommands whose options live beside their engines.
    from zbuf_occlude.cli.compare import add_compare_parser
    from zbuf_occlude.cli.contact_sheet import add_contact_sheet_parser
    from zbuf_occlude.cli.elevation_profile import add_profile_parser
    from zbuf_occlude.cli.farm import add_farm_merge_parser, add_farm_parser

    for add in (add_compare_parser, add_profile_parser, add_farm_parser, add_farm_merge_parser, add_contact_sheet_parser):
        add(sub)
    from zbuf_occlude.cli.learn import add_parser as add_experiment_parser  # zbuf-occlude experiment; torch only when it runs
    from zbuf_occlude.cli.fit_sensor import add_fit_sensor_parser
    from zbuf_occlude.cli.realism import add_realism_parser
    from zbuf_occlude.cli.sensors import add_scan_parser
    from zbuf_occlude.cli.verify import add_verify_parser  # zbuf-occlude verify DIR: schema, paths, checksums of a data set
    from zbuf_occlude.cli.export import add_export_parser  # zbuf-occlude export DATASET --to TARGET
    from zbuf_occlude.cli.families import add_families_parser  # zbuf-occlude families FAMILY --count N --out DIR

    for add in (add_scan_parser, add_realism_parser, add_fit_sensor_parser, add_experiment_parser, add_verify_parser, add_export_parser,
                add_families_parser):  # fmt: skip
        add(sub)
    return parser


#: Exit status when standard output was closed by its reader (``| head``): 128 + SIGPIPE (13), what a
#: shell shows for a process that SIGPIPE ended (Python ignores SIGPIPE and gets EPIPE instead).
EXIT_CLOSED_STDOUT = 141

#: Local variables that hold the file a library function works on, looked up in the frames of a
#: ``MemoryError`` to name that file (the library's own name for it is ``path``).
_FILE_LOCALS = ("path", "mesh_path", "file_path", "filename")


def _out_of_memory(command: str, exc: MemoryError) -> str:
    """One line for a ``MemoryError``: the command, the innermost zbuf_occlude function and the file it worked on.

    The traceback's frames are read innermost first; the first function of the package names
    what was being done and the first ``path`` (or :data:`_FILE_LOCALS`) in those frames the file.
    """
    doing, file = None, None
    frames: list[TracebackType] = []
    tb = exc.__traceback__
    while tb is not None:
        frames.append(tb)
        tb = tb.tb_next
    for tb in reversed(frames):
        frame = tb.tb_frame
        module = frame.f_globals.get("__name__", "")
        if not module.startswith("zbuf_occlude"):
            continue
        if doing is None and not module.startswith("zbuf_occlude.cli"):
            doing = f"{module}.{frame.f_code.co_name}"
        if file is None:
            found = (frame.f_locals.get(name) for name in _FILE_LOCALS)
            file = next((os.fspath(v) for v in found if isinstance(v, (str, os.PathLike))), None)
    where = f"`{command}` ran out of memory"
    if doing:
        where += f" in {doing}"
    if file:
        where += f" on {file}"
    detail = " ".join(str(exc).split())  # numpy says what it could not allocate
    return f"{where}{f' ({detail})' if detail else ''}: free memory, or use smaller inputs or options"


def _missing_folders(out: object) -> list[Path]:
    """``--out`` and those of its parents that do not exist yet, deepest first (none for a blank value)."""
    if not isinstance(out, str) or not out.strip():
        return []
    missing = []
    for folder in (Path(out), *Path(out).parents):
        if os.path.lexists(folder):
            break
        missing.append(folder)
    return missing


def _remove_if_empty(folders: list[Path]) -> None:
    """Remove the folders a refused run created, deepest first, if nothing was written in them
    (:func:`zbuf_occlude.io.deletes.remove_empty_tree`)."""
    from zbuf_occlude.io.deletes import remove_empty_tree

    for folder in folders:
        if not remove_empty_tree(folder) and folder.is_dir() and not folder.is_symlink():
            return


def parse_command_line(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> argparse.Namespace:
    """``parser.parse_args(argv)``, but an unknown option is refused by the sub-command it was given to:
    its usage, and the nearest of its options (``--veiws``: "did you mean --views?"), also when a
    required option is missing (a mistyped ``--otu`` is named, not only the missing ``--out``).
    Options are taken only as spelled (:class:`~zbuf_occlude.cli.options.Parser`): an abbreviation
    is refused, naming the options it starts (``--sample``: "did you mean --samples-per-view?").
    A command line asking for ``--help`` is parsed as it is, so that the help shows the required
    options as required.

    Raises
    ------
    SystemExit
        Exit 2, as argparse does, for any bad command line.
    """
    words = list(sys.argv[1:] if argv is None else argv)
    if any(word in ("-h", "--help") for word in words[: words.index("--") if "--" in words else None]):
        return parser.parse_args(argv)  # the help as it is: required options without brackets
    with _nothing_required(parser):  # a first look for unknown options, which argparse reports last
        args, extras = parser.parse_known_args(argv)
    if not extras:
        return parser.parse_args(argv)
    chosen = parser
    while True:  # down the sub-commands given (``experiment sim2real``)
        subs = [a for a in chosen._actions if isinstance(a, argparse._SubParsersAction)]
        name = getattr(args, subs[0].dest, None) if subs else None
        if name not in (subs[0].choices if subs else {}):
            break
        chosen = subs[0].choices[name]
    hints = []
    for extra in extras:
        if extra.startswith("-"):
            near = _nearest(extra.split("=", 1)[0], list(chosen._option_string_actions))
            hints += [f"did you mean {' or '.join(near)}?"] if near else []
    chosen.error(f"unrecognized arguments: {' '.join(extras)}" + (f" ({'; '.join(hints)})" if hints else ""))


#: Options named at most in a hint for an abbreviation (``--s``: ``--samples-per-view or --seed or ...``).
HINTED_OPTIONS = 3


def _nearest(typed: str, options: list[str]) -> list[str]:
    """The options ``typed`` may mean: those it abbreviates (``--sample``: ``--samples-per-view``), else the closest spelling."""
    import difflib

    longer = sorted(o for o in options if o.startswith(typed) and o != typed)
    return longer[:HINTED_OPTIONS] or difflib.get_close_matches(typed, options, n=1, cutoff=0.6)


@contextlib.contextmanager
def _nothing_required(parser: argparse.ArgumentParser):
    """Every argument (and group of exclusive ones) of ``parser`` and its sub-commands optional
    while the block runs."""
    actions, stack = [], [parser]
    while stack:
        p = stack.pop()
        for action in [*p._actions, *p._mutually_exclusive_groups]:
            actions.append((action, action.required))
            if isinstance(action, argparse._SubParsersAction):
                stack += list(dict.fromkeys(action.choices.values()))  # aliases name one parser
    try:
        for action, _ in actions:
            action.required = False
        yield
    finally:
        for action, required in actions:
            action.required = required


def _run(argv: Sequence[str] | None) -> int:
    """Parse ``argv`` and run its command; the exit status (see :func:`main`)."""
    created: list[Path] = []
    command = "zbuf-occlude"
    try:
        # inside the try: the options' checkers (cli.options) raise while the command line is parsed
        args = parse_command_line(build_parser(), argv)
        command = args.command
        logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
        created = _missing_folders(getattr(args, "out", None))
        say_if_cold(command)  # a first run's numba compile is a minute of silence otherwise
        return int(args.func(args) or 0)
    except ZbufOccludeError as exc:
        print(f"zbuf-occlude: error: {exc}", file=sys.stderr)
        _remove_if_empty(created)
        return 2
    except MemoryError as exc:
        # Readers turn a MemoryError into an error naming their file; anything else that runs
        # out of memory ends here, in one line, not with a traceback.
        print(f"zbuf-occlude: error: {_out_of_memory(command, exc)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        # 130 after Ctrl-C (SIGINT), 143 after SIGTERM (farm.lifecycle.Terminated): 128 + the signal
        print("zbuf-occlude: interrupted; run the same command again to resume", file=sys.stderr)
        return 128 + getattr(exc, "signum", signal.SIGINT)


class _NoStdout:
    """What stands for a missing ``sys.stdout`` (started with ``>&-``; pythonw): every write fails,
    so that a result the command cannot report is a failure, not a silent exit 0."""

    def write(self, text: str) -> int:
        raise OSError(errno.EBADF, "standard output is closed")

    def flush(self) -> None:
        pass


def _hold_fd(number: int) -> None:
    """Point a closed file descriptor (1 or 2) at ``os.devnull``, so that no file the command opens
    takes its number, where a library's or a child process's output would then be written."""
    try:
        os.fstat(number)
    except OSError:
        with contextlib.suppress(OSError):
            fd = os.open(os.devnull, os.O_WRONLY)
            if fd != number:
                os.dup2(fd, number)
                os.close(fd)


class _WatchedStdout:
    """``sys.stdout`` while a command runs: the same stream, keeping the first OSError a write raised.

    A reader that went away (``| head``: EPIPE) stops the command: the error propagates, as
    Python's documentation recommends.  Any other error (``> /dev/full``: ENOSPC) drops what is
    printed from then on and lets the command finish its files; :func:`main` says so at the end.
    Only stdout's own errors are kept: another file's OSError stays a bug with a traceback.
    """

    def __init__(self, stream: Any) -> None:
        self.stream = stream
        self.error: OSError | None = None

    def _failed(self, exc: OSError) -> None:
        self.error = exc
        if exc.errno == errno.EPIPE:
            raise exc

    def write(self, text: str) -> int:
        if self.error is None:
            try:
                return self.stream.write(text)
            except OSError as exc:
                self._failed(exc)
            except ValueError:  # a closed file object; any other ValueError (an encoding) stays a bug
                if not getattr(self.stream, "closed", False):
                    raise
                self._failed(OSError(errno.EBADF, "standard output is closed"))
        return len(text)  # stdout is lost: the text is dropped, the command goes on

    def writelines(self, lines: Iterable[str]) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        if self.error is None and not getattr(self.stream, "closed", False):  # a closed one: write says so
            try:
                self.stream.flush()
            except OSError as exc:
                self._failed(exc)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.stream, name)


def _stdout_lost(stdout: _WatchedStdout, status: int | None) -> int:
    """The exit status when stdout could not be written, after pointing stdout at ``os.devnull``
    (so that the interpreter's own flush at exit does not fail again with a traceback).

    A closed pipe exits :data:`EXIT_CLOSED_STDOUT` quietly; any other error is one line on
    stderr and exit 1 (or the command's own non-zero ``status``; None: it stopped there).
    """
    exc = stdout.error
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stdout.stream.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # a stdout without a file descriptor (tests, embedding)
        pass
    if exc is not None and exc.errno == errno.EPIPE:
        return EXIT_CLOSED_STDOUT
    done = "the command stopped there" if status is None else "the command finished its work; what it printed is lost"
    with contextlib.suppress(OSError):
        print(f"zbuf-occlude: error: could not write to standard output ({getattr(exc, 'strerror', None) or exc}); {done}", file=sys.stderr)
    return status or 1


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status.

    A usage error (an option refused while parsing, or any :class:`ZbufOccludeError`) is one line
    on stderr, exit 2.  A run refused with a usage error leaves no empty ``--out`` folder behind:
    the folders it created for ``--out`` are removed again when nothing was written in them.
    Standard output is watched and flushed here, not at exit, for every command: a reader that
    went away (``| head``) ends the command quietly with exit status 141; a stdout that cannot be
    written (``> /dev/full``), is closed or is missing (``>&-``: ``sys.stdout`` is None) lets the
    command finish, then is one line on stderr (when there is one) and exit 1.  A missing stderr
    (``2>&-``) loses the messages and progress, not the run.
    """
    original, original_err = sys.stdout, sys.stderr
    if original is None:
        _hold_fd(1)
    if original_err is None:  # stderr closed (2>&-): its messages are the user's to lose, the run goes on
        _hold_fd(2)
        sys.stderr = open(os.devnull, "w", encoding="utf-8")  # noqa: SIM115 - closed in the finally below
    stdout = sys.stdout = _WatchedStdout(_NoStdout() if original is None else original)
    try:
        try:
            status = _run(argv)
            with contextlib.suppress(OSError):
                stdout.flush()  # here, not at exit
        except SystemExit:  # argparse after --help, --version or a usage error; it ignores a failed write itself
            with contextlib.suppress(OSError):
                stdout.flush()
            if stdout.error is None:
                raise
            return _stdout_lost(stdout, 0)
        except OSError:
            if stdout.error is None:  # another file's error: a bug, shown with its traceback
                raise
            return _stdout_lost(stdout, None)
        return status if stdout.error is None else _stdout_lost(stdout, status)
    finally:
        if sys.stdout is stdout:
            sys.stdout = original
        if original_err is None:
            sys.stderr.close()
            sys.stderr = None


if __name__ == "__main__":
    sys.exit(main())
