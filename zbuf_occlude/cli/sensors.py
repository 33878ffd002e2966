"""``zbuf-occlude scan`` and ``zbuf-occlude realism``: options beside their engines.

``cli.build_parser`` calls :func:`add_scan_parser` and :func:`add_realism_parser`; scan's return physics
options are :mod:`zbuf_occlude.cli.return_physics`'s, ``fit-sensor`` is :mod:`zbuf_occlude.cli.fit_sensor`.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from zbuf_occlude.cli.crops import add_crop_arguments, crop_settings, given_crop_options
from zbuf_occlude.cli.las_options import add_las_arguments, las_keywords
from zbuf_occlude.cli.options import Checked, count, counted, interval, out_folder, parse_interval, seed
from zbuf_occlude.cli.return_physics import add_return_physics_arguments
from zbuf_occlude.cli.scan_request import scan_request
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.ray_tables import RAY_TABLE_SUFFIXES
from zbuf_occlude.mesh.formats import EXTENSIONS_TEXT
from zbuf_occlude.mesh.sizes import DIMENSIONS
from zbuf_occlude.sensors.kinds import SENSOR_KINDS, preset_names
from zbuf_occlude.sensors.placement import CropDistributions, ObjectPlacement
from zbuf_occlude.sensors.scan_files import run_scan

__all__ = ["add_scan_parser", "SCAN_CROP_DISTRIBUTIONS"]

log = logging.getLogger(__name__)


#: ``scan``'s placement when no option changes it: a car (4.5 m) 10 m ahead of a LiDAR on a car roof.
SCAN_CROP_DISTRIBUTIONS = CropDistributions(distance_m=10.0, height_m=1.8, size_m=4.5, azimuth_deg=0.0, yaw_deg=0.0)
#: ``scan``'s own option of each other :class:`~zbuf_occlude.sensors.placement.CropDistributions` and
#: :class:`~zbuf_occlude.sensors.placement.ObjectPlacement` field it sets, for messages (the crop options of
#: :mod:`zbuf_occlude.cli.crops` name theirs).
SCAN_OPTION_NAMES = {
    "azimuth_deg": "--azimuth", "yaw_deg": "--yaw", "extents_m": "--extents", "ground_reflectivity": "--ground-reflectivity",
    "up": "--up", "size_of": "--size-of", "width_profile": "--outline", "occlude": "--occlude",
}  # fmt: skip
#: What ``scan`` adds to the help of a crop option.
SCAN_NOTES = {
    "distance_m": "at least half the object's size; an airborne scanner flies over the object, distance · sin(azimuth) "
    "across track from its plan's centre",
    "size_m": "see --size-of",
    **{field: "with --crop" for field in ("ground_margin_m", "hidden_below_m", "across_sight_width_m")},
}


#: ``scan``'s sensor when neither ``--sensor`` nor ``--ray-table`` names one.
SCAN_SENSOR = "hdl32e"


def _sensor_name(args: argparse.Namespace) -> str:
    """The name of the sensor ``scan`` fires: ``--sensor``'s (:data:`SCAN_SENSOR` by default), or the file of
    ``--ray-table`` (read by :func:`~zbuf_occlude.sensors.kinds.sensor_from_name` with the request)."""
    if args.ray_table is None:
        return args.sensor or SCAN_SENSOR
    if args.sensor is not None:
        raise InvalidInputError(f"--ray-table {args.ray_table} is the sensor: give --ray-table or --sensor {args.sensor}, not both")
    if Path(args.ray_table).suffix.lower() not in RAY_TABLE_SUFFIXES:
        raise InvalidInputError(f"--ray-table must be a {' or '.join(RAY_TABLE_SUFFIXES)} file, got {args.ray_table!r:.80}")
    return args.ray_table


def _placement(args: argparse.Namespace) -> ObjectPlacement:
    """How ``scan`` stands a mesh on the ground: the crop options, ``--azimuth``, ``--yaw``, ``--extents``, ``--size-of``,
    ``--up``, ``--across-sight-width``, ``--outline`` and ``--occlude``, as the library's
    :class:`~zbuf_occlude.sensors.placement.ObjectPlacement` (which checks them, naming the options as typed).  The
    options that shape the object's crop alone are refused without ``--crop``."""
    if not args.crop:
        for flag, option in given_crop_options(args, in_crop=True):
            raise InvalidInputError(f"{flag} {option.in_crop}: it needs --crop")
        if args.outline is not None:
            raise InvalidInputError("--outline gives the object's crops the outline of real scans: it needs --crop")
    extents, round_xy = None, False
    if args.extents:
        parts = args.extents.split(",")
        if len(parts) != 3:
            raise InvalidInputError(f"--extents must be X,Y,Z in metres (each N or LO:HI; Y may be '='), got {args.extents!r}")
        round_xy = parts[1].strip() == "="
        extents = tuple(parse_interval(parts[0] if i == 1 and round_xy else v, "--extents") for i, v in enumerate(parts))
    crops = crop_settings(args, SCAN_CROP_DISTRIBUTIONS, azimuth_deg=parse_interval(args.azimuth, "--azimuth"),
                          yaw_deg=parse_interval(args.yaw, "--yaw"), extents_m=extents, round_xy=round_xy,
                          ground_reflectivity=args.ground_reflectivity)  # fmt: skip
    outline = None if args.outline is None else tuple(args.outline.split(","))
    return ObjectPlacement(crops.distributions, up=args.up, size_of=args.size_of, across_sight_width_m=crops.across_sight_width_m,
                           width_profile=outline, occlude=args.occlude, names=crops.names)  # fmt: skip


def cmd_scan(args: argparse.Namespace) -> int:
    sensor = _sensor_name(args)
    placement = _placement(args)
    formats = ("npz", "ply") if args.format == "both" else (args.format,)
    request = scan_request(args, sensor, backend=args.backend, frame=args.frame, trajectory=args.trajectory, samples=args.samples,
                           formats=formats, las=las_keywords(args, formats))  # fmt: skip
    written, empty, folder = 0, 0, None  # a refused run's empty --out is removed by cli.main
    for done in run_scan(request, args.mesh_or_scene, args.out, placement, seed=args.seed, crop=args.crop, progress=not args.no_progress):
        written, folder = written + len(done.files), done.files[0].parent
        if done.object_returns == 0:
            empty += 1
            print(f"EMPTY {done.files[0]}: no return of the object (edge-on, below the sensor's beams or beyond its range at "
                  f"{done.distance_m:.2f} m)", file=sys.stderr)  # fmt: skip
        if done.object_returns is not None:
            log.info("%s: %d returns of the object at %.2f m", done.files[0].stem, done.object_returns, done.distance_m)
    print(
        f"wrote {counted(written, 'file')} to {folder}"
        + (f"; {empty} of {counted(request.samples, 'scan')} hold no return of the object" if empty else "")
    )
    return 1 if empty else 0


def add_scan_parser(sub) -> argparse.ArgumentParser:
    """Add ``scan`` to the subparsers ``sub``."""
    from zbuf_occlude.mesh.scene import UP_CHOICES

    names = preset_names()
    kinds = ", ".join(f"{'an' if kind.title[0] in 'aeiou' else 'a'} {kind.title} ({', '.join(names[kind.name])})" for kind in SENSOR_KINDS)
    p = sub.add_parser(
        "scan", help="LiDAR / depth-camera scan of a mesh on the ground, or of a scene file",
        description="Stand a mesh on a ground plane at --distance from a simulated LiDAR and scan it (or fly an airborne "
        "scanner over it, or scan a scene file with any sensor); writes one point cloud per sample to --out.  A mesh "
        "flat in z (a single square, no height) is refused: on the ground it lies in the ground plane.  The exit "
        "status is 1 when a scan of a mesh holds no return of the object (each such file is named on stderr: seen "
        "edge-on, below the beams or out of range).",
    )  # fmt: skip
    p.add_argument(
        "mesh_or_scene",
        metavar="MESH_OR_SCENE",
        help=f"mesh file ({EXTENSIONS_TEXT}; stood on the ground), 'cylinder' or 'box' (unit primitives), or a scene .json/.yaml",
    )
    p.add_argument(
        "--sensor", default=None,
        help=f"{kinds}, a sensor .json (fit-sensor writes one), or a ray table file as --ray-table takes (default: {SCAN_SENSOR})",
    )  # fmt: skip
    t = p.add_argument_group("ray table (instead of --sensor)", "a LiDAR that fires along your own table of directions, one row per pulse")
    t.add_argument(
        "--ray-table", metavar="FILE",
        help="a .csv with the header time_s,azimuth_deg,elevation_deg (seconds; degrees in the LiDAR's frame: azimuth from x "
        "forward towards y left, elevation above the xy plane) or an (N, 3) .npy of those columns, time non-decreasing: each "
        "point gets its pulse's time (gps_time) and row (pulse_id); ranges 1-100 m, range noise 0.02 m",
    )  # fmt: skip
    c = p.add_argument_group(
        "placement and crops (as farm --sensor's)",
        "Where the object stands and what a crop keeps: a number N, or LO:HI drawn uniformly per scan. Each option "
        "has two names, scan's and farm's (--distance or --sensor-distance, ...).",
    )
    add_crop_arguments(c, SCAN_CROP_DISTRIBUTIONS, prefixed=False, names=SCAN_OPTION_NAMES, notes=SCAN_NOTES)
    p.add_argument(
        "--size-of", choices=DIMENSIONS, default="max",
        help="what --size measures: max (the largest dimension), height, or length (the larger horizontal side); the mesh keeps "
        "its proportions (default: %(default)s)",
    )  # fmt: skip
    p.add_argument(
        "--extents",
        help="X,Y,Z: stretch the mesh to these extents, metres, each N or LO:HI drawn per sample (instead of --size); "
        "Y '=' takes the drawn X (a round pole: --extents 0.1:0.4,=,3:9)",
    )
    add_return_physics_arguments(p)
    p.add_argument(
        "--azimuth",
        action=Checked,
        check=interval,
        default="0",
        help="direction of the object from the sensor, degrees (N or LO:HI) (default: %(default)s)",
    )
    p.add_argument(
        "--yaw", action=Checked, check=interval, default="0", help="the object's heading, degrees (N or LO:HI) (default: %(default)s)"
    )
    p.add_argument(
        "--samples", action=Checked, check=count("MAX_SAMPLES"), default=1, help="scans, each with its own draws (default: %(default)s)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar (or, when stderr is a file, no progress lines)")
    p.add_argument(
        "--crop",
        action="store_true",
        help="write only the object's returns; default: the object and the ground in the object's azimuth sector (±5°)",
    )
    p.add_argument(
        "--occlude", action="store_true",
        help="with --across-sight-width: instead of the stretch, hide one side of the object behind panels between it "
        "and the sensor, leaving as much of it in view as that width asks where it shows wider (a partial view)",
    )  # fmt: skip
    p.add_argument(
        "--outline", metavar="V,V,...",
        help="with --crop: warp the object so that its crops show this outline over the height: how wide they are in "
        "equal bins of their height, bottom to top, over their width (fit-sensor's across_sight_profile per class)",
    )  # fmt: skip
    p.add_argument(
        "--trajectory",
        metavar="CSV",
        default=None,
        help="a scene file's sensor moves along this trajectory during its sweeps (a CSV of time_s,x_m,y_m,z_m and "
        "roll_deg,pitch_deg,yaw_deg or qx,qy,qz,qw, the scene's frame): each point is fired from where the sensor is at its "
        "time, the motion distortion of a real sweep; sample k sweeps from the trajectory's start plus k sweeps",
    )
    p.add_argument(
        "--frame", choices=("sensor", "world"), default=None,
        help="frame of the written points: sensor (LiDAR at the origin, x forward, z up; cameras: OpenCV) or "
        "world (the scene's frame) (default: sensor; an airborne scanner's points are in the world frame)",
    )  # fmt: skip
    p.add_argument(
        "--format",
        choices=("npz", "ply", "both", "las", "laz"),
        default="npz",
        help="file format of each scan: npz, ply, both (npz and ply), or LAS 1.4 / LAZ with return number, intensity, "
        "GPS time and scan angle per point (default: %(default)s)",
    )
    p.add_argument(
        "--backend", choices=("embree", "zbuffer"), default="embree",
        help="ray casting: embree (exact, CPU) or zbuffer (OpenGL depth images) (default: %(default)s)",
    )  # fmt: skip
    p.add_argument(
        "--seed",
        action=Checked,
        check=seed,
        default=0,
        help="seed of the placement draws and the sensor noise; one seed gives the crops farm --sensor gives "
        "the file lying directly in its input folder (they key on the name without suffix) (default: %(default)s)",
    )
    p.add_argument(
        "--up",
        choices=UP_CHOICES,
        default="auto",
        help="a mesh file's up axis, turned to +z; auto: by its path and format, as in generate and farm "
        "(ShapeNetCore paths and glTF +y, ...) (default: %(default)s)",
    )
    add_las_arguments(p)
    p.add_argument("--out", required=True, action=Checked, check=out_folder, help="output folder")
    p.set_defaults(func=cmd_scan)
    return p
