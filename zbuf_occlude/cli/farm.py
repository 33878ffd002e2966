"""The ``farm`` and ``farm-merge`` subcommands (called from :mod:`zbuf_occlude.cli.main`)."""

from __future__ import annotations

import argparse
import logging
import shlex
import sys

from zbuf_occlude.cli.crops import add_crop_arguments, crop_settings, given_crop_options
from zbuf_occlude.cli.options import Checked, count, given_params, out_folder, poses, real, seed
from zbuf_occlude.cli.scan_request import returns_per_pulse
from zbuf_occlude.dataset.layout import STORAGE_MODES
from zbuf_occlude.defaults import DEFAULT_DENSE_POINTS as GENERATE_DENSE_POINTS
from zbuf_occlude.defaults import (
    DEFAULT_FARM_DENSE_POINTS,
    DEFAULT_FARM_RESOLUTION,
    DEFAULT_FARM_VIEWS,
    DEFAULT_METHOD,
    DEFAULT_N_POINTS,
    DEFAULT_SAMPLES_PER_VIEW,
    DEFAULT_SEED,
    MAX_WORKERS,
)
from zbuf_occlude.defaults import DEFAULT_RESOLUTION as GENERATE_RESOLUTION
from zbuf_occlude.defaults import DEFAULT_VIEWS as GENERATE_VIEWS
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.farm.config import FarmParams, usable_cpus
from zbuf_occlude.farm.sensor_params import FARM_CROP_DISTRIBUTIONS, SensorCropParams
from zbuf_occlude.farm.shards import parse_shard
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS
from zbuf_occlude.mesh.paths import SPLITS
from zbuf_occlude.mesh.formats import EXTENSIONS_TEXT
from zbuf_occlude.mesh.inputs.kinds import DEFAULT_POINT_SET_POINTS, POINT_SET_METHOD, POINT_SET_VISIBLE_SHARE
from zbuf_occlude.mesh.scene import UP_CHOICES
from zbuf_occlude.sensors.beam.adaptive_cast import FOOTPRINT_MODES
from zbuf_occlude.sensors.kinds import SENSOR_KINDS
from zbuf_occlude.sensors.request import TRAINING_RETURNS

log = logging.getLogger(__name__)

#: Help shared by ``generate``, ``validate`` and ``farm`` (:mod:`zbuf_occlude.cli.main` imports them).
VIEWS_HELP = "poses: grid25 (5x5 grid) | paper100 (the paper's 100) | fibonacci:N | EL:AZ,EL:AZ,... in degrees"
RADIUS_HELP = "camera distance from the object's centre, object units (the normalised object's largest extent is 1)"
UP_HELP = (
    "the meshes' up axis, turned to +z; auto: per file, +y for ShapeNetCore paths (SYNSET/MODEL_ID/...), "
    "+y for glTF (as stored when trimesh wrote it), COLLADA's <up_axis>, OBJ by its exporter, else as stored; "
    "the axis used goes into each record and the card (default: %(default)s)"
)
CLASS_FROM_HELP = (
    "N: take each mesh's class from the N-th folder above it (1: the folder holding it) instead of the detected "
    "layout's; needed where the layout's classes look wrong (all one class, or folders such as 'models')"
)
#: ``farm --sensor``'s presets, by kind, for its help.
_PRESETS = "; ".join(f"{k.name}: {', '.join(sorted(k.presets))}" for k in SENSOR_KINDS if k.pulsed)  # the farm scans with pulses
#: ``--class-from N``'s check (a folder level, no cap): ``mesh.layouts`` says the same of a bad value.
CLASS_FROM = count(None, hint="1: the folder holding each file")


#: What the CLI says of point-set inputs (``generate`` and ``farm``).
POINT_SETS_HELP = (
    "Point-set files are taken too (PointNet-layout HDF5 such as modelnet40_ply_hdf5_2048, read +y up; .npy and "
    ".ply without faces, read as stored, +z up; --up overrides): each cloud is one object, its visibility decided "
    f"from its points alone ({POINT_SET_METHOD}); see docs/guide/inputs.md"
)
#: Why point sets take fewer points per sample by default.
POINT_SETS_POINTS_WHY = f"about {round(100 * POINT_SET_VISIBLE_SHARE)} %% of a cloud is visible per pose"  # %%: argparse's
#: What the help of an option that point sets refuse adds.
NOT_FOR_POINT_SETS = "meshes only: refused for point sets"
#: ``FarmParams`` field -> ``args`` attribute of the options a point-set run refuses or defaults itself.
GIVEN_PARAMS = {"n_points": "points", "dense_points": "dense_points", "density": "density", "resolution": "resolution"}


# -- command line (called from zbuf_occlude.cli.main) -------------------------------------------------
def _farm_command(args: argparse.Namespace) -> int:
    if args.density is not None and args.dense_points is not None:
        raise InvalidInputError("give either --density or --dense-points, not both")
    params = FarmParams(
        views=args.views,
        samples_per_view=args.samples_per_view,
        n_points=args.points,
        dense_points=args.dense_points if args.dense_points is not None else DEFAULT_FARM_DENSE_POINTS,
        density=args.density,
        resolution=args.resolution,
        seed=args.seed,
        radius=args.radius,
        storage=args.storage,
        method=args.method,
        up=args.up,
        **_sensor_params(args),
    )
    from zbuf_occlude.farm.config import RunOptions
    from zbuf_occlude.farm.run import run_farm  # meshes, visibility and the GL: imported when the command runs

    options = RunOptions(
        classes=args.classes,
        per_class=args.per_class,
        splits=args.splits,
        class_from=args.class_from,
        workers=args.workers,
        shard=parse_shard(args.shard) if args.shard else (0, 1),
        scheduler=args.scheduler,
        dask_local=args.dask_local,
        overwrite=args.overwrite,
        progress=not args.no_progress,
        isolate=True,  # a SIGTERM stops the run at once, even inside a long native call
        command=shlex.join(["zbuf-occlude", *sys.argv[1:]]) if sys.argv else None,
        set_params=given_params(args, GIVEN_PARAMS),
    )
    summary = run_farm(args.root, args.out, params, options)
    print(summary.format())
    return summary.exit_status


def _sensor_params(args: argparse.Namespace) -> dict:
    """``{"sensor": SensorCropParams}`` of ``--sensor`` and the crop options (``{}`` without ``--sensor``)."""
    if args.sensor is None:
        for flag, _ in given_crop_options(args):
            raise InvalidInputError(f"{flag} needs --sensor")
        for flag, value in (("--sensor-footprint-cast", args.sensor_footprint_cast), ("--sensor-returns", args.sensor_returns)):
            if value is not None:
                raise InvalidInputError(f"{flag} needs --sensor")
        return {}
    crops = crop_settings(args, FARM_CROP_DISTRIBUTIONS)
    returns = TRAINING_RETURNS if args.sensor_returns is None else args.sensor_returns
    return {"sensor": SensorCropParams(args.sensor, crops.distributions, footprint=crops.footprint,
                                       across_sight_width_m=crops.across_sight_width_m, divergence_deg=crops.divergence_deg,
                                       footprint_cast=args.sensor_footprint_cast or "auto", returns=returns, option_names=crops.names)}  # fmt: skip


def _merge_command(args: argparse.Namespace) -> int:
    from zbuf_occlude.farm.run import merge_farm

    summary = merge_farm(args.inputs, args.out, progress=not args.no_progress)
    print(summary.format())
    return summary.exit_status  # 1: objects failed, or the tasks skipped inputs


def add_farm_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``farm`` subcommand to an ``argparse`` subparsers object (``func`` → exit status)."""
    p = subparsers.add_parser(
        "farm",
        help="build a whole occluded data set (parallel, resumable, sharded, Dask)",
        description="Render every mesh of ROOT from every pose and write a PointNet-style HDF5 data set to --out; "
        "point-set files in ROOT (PointNet HDF5, .npy, .ply without faces) are seen from their points alone. "
        "Run the same command again to resume; objects already finished are skipped.",
    )
    p.add_argument(
        "root",
        help=f"a folder of mesh files ({EXTENSIONS_TEXT}): ModelNet CLASS/SPLIT/NAME.off, ShapeNetCore v1/v2 with its "
        "taxonomy.json, CLASS/NAME.ext or CLASS_NNNN.ext files (the layout used goes into the card; see docs/guide/inputs.md); "
        f"or a list file of 'PATH LABEL [SPLIT]' lines. {POINT_SETS_HELP}",
    )
    p.add_argument("--out", required=True, action=Checked, check=out_folder, help="data set folder")
    sel = p.add_argument_group("selection")
    sel.add_argument("--classes", help="comma-separated class names (default: all)")
    sel.add_argument(
        "--per-class", action=Checked, check=count(None), help="first K meshes (by name) of each class and split (default: all)"
    )
    sel.add_argument("--splits", default=",".join(SPLITS), help="comma-separated splits (default: %(default)s)")
    sel.add_argument("--class-from", action=Checked, check=CLASS_FROM, metavar="N", help=CLASS_FROM_HELP)
    sel.add_argument("--up", choices=UP_CHOICES, default="auto", help=UP_HELP)
    r = p.add_argument_group("rendering")
    r.add_argument(
        "--views",
        action=Checked,
        check=poses,
        default=DEFAULT_FARM_VIEWS,
        help=f"{VIEWS_HELP} (default: %(default)s; generate's: {GENERATE_VIEWS})",
    )
    r.add_argument(
        "--samples-per-view",
        action=Checked,
        check=count("MAX_SAMPLES"),
        default=DEFAULT_SAMPLES_PER_VIEW,
        help="random samples drawn per pose (default: %(default)s)",
    )
    r.add_argument(
        "--points", action=Checked, check=count("MAX_POINTS"), default=DEFAULT_N_POINTS,
        help=f"points per sample (default: %(default)s; point sets: {DEFAULT_POINT_SET_POINTS}, {POINT_SETS_POINTS_WHY})",
    )  # fmt: skip
    dense = r.add_mutually_exclusive_group()
    dense.add_argument(
        "--dense-points",
        action=Checked,
        check=count("MAX_POINTS"),
        help=f"dense cloud per mesh, sampled once (default: {DEFAULT_FARM_DENSE_POINTS}; generate's: {GENERATE_DENSE_POINTS}; {NOT_FOR_POINT_SETS})",
    )
    dense.add_argument(
        "--density",
        action=Checked,
        check=real(0.0, above=True),
        help=f"dense cloud as points per unit area of the normalised mesh ({NOT_FOR_POINT_SETS})",
    )
    r.add_argument(
        "--resolution",
        action=Checked,
        check=count("MAX_RESOLUTION"),
        default=DEFAULT_FARM_RESOLUTION,
        help=f"z-buffer image size, pixels (default: %(default)s; generate's: {GENERATE_RESOLUTION}; {NOT_FOR_POINT_SETS})",
    )
    r.add_argument("--radius", action=Checked, check=real(), default=DEFAULT_RADIUS, help=f"{RADIUS_HELP} (default: %(default)s)")
    r.add_argument(
        "--seed",
        action=Checked,
        check=seed,
        default=DEFAULT_SEED,
        help="global seed: the same seed and options give the same data set (default: %(default)s)",
    )
    r.add_argument("--method", default=DEFAULT_METHOD, help="visibility method (see `zbuf-occlude info`) (default: %(default)s)")
    r.add_argument(
        "--storage",
        choices=STORAGE_MODES,
        default="dense",
        help="dense: PointNet HDF5; compact: dense cloud + visibility bits (default: %(default)s)",
    )
    s = p.add_argument_group(
        "LiDAR crops (--sensor)",
        "Instead of z-buffer poses, scan each object with a simulated sensor: --samples-per-view scans per object, "
        "each with its own placement, every quantity drawn uniformly and independently per scan: the "
        "horizontal distance (--sensor-distance), the sensor height above the ground (--sensor-height), the "
        "object's largest dimension (--sensor-size), its direction from the sensor and its heading (0-360 deg). "
        "The object stands on a ground plane; its returns (normalised mesh frame) are the rows of a dense "
        "shard, with the sensor's elevation/azimuth seen from the object and the placement per row. "
        "--views, --dense-points, --density, --resolution and --radius do not apply. The crop options are "
        "scan's, each with both its names (--sensor-distance or --distance, ...).",
    )
    s.add_argument(
        "--sensor",
        help=f"a preset ({_PRESETS}) or a sensor .json (fit-sensor writes one) (default: none, z-buffer poses)",
    )
    add_crop_arguments(s, FARM_CROP_DISTRIBUTIONS, prefixed=True)
    s.add_argument(
        "--sensor-footprint-cast", choices=FOOTPRINT_MODES, default=None,
        help="how a footprint whose echoes are resolved is cast: adaptive casts a pulse's whole footprint only where its centre "
        "ray and its neighbours do not show one plane filling it (the same returns but for a surface inside the cone none of them "
        "meets, a fraction of the cost); exact casts every sub-ray; auto is adaptive where the sensor resolves a footprint's "
        "echoes, else exact (default: auto)",
    )  # fmt: skip
    s.add_argument(
        "--sensor-returns", metavar="WHICH", action=Checked, check=returns_per_pulse, default=None,
        help="what each crop keeps of a pulse's returns, as experiment sim2real's --returns: 1 or strongest (default) one "
        "return per pulse, the footprint's strongest; first or last: the receiver's first or last echo; all: every return the "
        "sensor's device records (an airborne preset's several); N above 1: up to N per pulse, the footprint's echoes resolved "
        "(the card: sensor_returns, where it changes what the sensor records)",
    )  # fmt: skip
    ex = p.add_argument_group("execution")
    ex.add_argument(
        "--workers", action=Checked, check=count("MAX_WORKERS"), default=min(usable_cpus(), MAX_WORKERS),
        help=f"worker processes on this machine (default: %(default)s; the CPU cores this process may use, at most {MAX_WORKERS:,})",
    )  # fmt: skip
    ex.add_argument("--shard", help="I/N: render the I-th of N partitions (SLURM array, Kubernetes indexed job); then farm-merge")
    dask = ex.add_mutually_exclusive_group()
    dask.add_argument("--scheduler", help="Dask scheduler address tcp://HOST:PORT (out must be on a shared file system)")
    dask.add_argument(
        "--dask-local", action=Checked, check=count("MAX_WORKERS"), metavar="N", help="run on a local Dask cluster of N worker processes"
    )
    ex.add_argument("--overwrite", action="store_true", help="start over instead of resuming")
    ex.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_farm_command)
    return p


def add_farm_merge_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``farm-merge`` subcommand (``func`` → exit status)."""
    p = subparsers.add_parser(
        "farm-merge",
        help="join the outputs of `farm --shard I/N` tasks into one data set",
        description="Check that every object of the plan has a result, copy shards from other task folders, "
        "and write the manifest, file lists and data set card.",
    )
    p.add_argument("inputs", nargs="+", help="task output folders (one folder if all tasks shared --out)")
    p.add_argument("--out", action=Checked, check=out_folder, help="data set folder (default: the first input)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_merge_command)
    return p
