"""``zbuf-occlude fit-sensor``: a sensor fitted to real object scans, or its return model to LAS/LAZ scans.

Parses the options and calls :func:`zbuf_occlude.sensors.fit.engine.fit_sensor`, which reads, fits and writes; with
``--meshes``, the fit of the partial echoes runs in it (:func:`zbuf_occlude.sensors.fit.partial_echo_meshes.partial_echo_refine`)."""

from __future__ import annotations

import argparse

from zbuf_occlude.cli.options import Checked, count, real, resamples, seed, shown
from zbuf_occlude.defaults import DEFAULT_SEED
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.scene import UP_CHOICES
from zbuf_occlude.sensors.checks import MAX_RANGE_M
from zbuf_occlude.sensors.fit.engine import LAS_EXTENSIONS
from zbuf_occlude.sensors.fit.lidar import MAX_BOOTSTRAP
from zbuf_occlude.sensors.kinds import preset_names

__all__ = ["add_fit_sensor_parser", "cmd_fit_sensor", "DEFAULT_CROPS_PER_MESH", "LAS_EXTENSIONS", "MAX_BOOTSTRAP"]

#: ``--crops-per-mesh``'s default: crops of each mesh at each threshold of the partial echoes' fit (fit_threshold.py's too).
DEFAULT_CROPS_PER_MESH = 4


def _classes(text: str, option: str) -> tuple[int, ...]:
    """``--classes C,C,...``: ASPRS class codes 0 to 255 (``none``: no class set)."""
    if text.strip().lower() == "none":
        return ()
    codes = [c.strip() for c in text.split(",")]
    if not codes or len(codes) > 256 or not all(c.isascii() and c.isdigit() and int(c) <= 255 for c in codes):
        raise InvalidInputError(f"{option} must be ASPRS class codes 0 to 255, C,C,... (or none), got {shown(text)}")
    return tuple(int(c) for c in codes)


def _altitude(text: str, option: str) -> float:
    """``--altitude M``: metres above the ground, > 0 and at most a sensor's largest range (:data:`~zbuf_occlude.sensors.checks.MAX_RANGE_M`)."""
    value = real(0.0, above=True, unit="metres")(text, option)
    if value > MAX_RANGE_M:
        raise InvalidInputError(f"{option} must be at most {MAX_RANGE_M:g} metres (a sensor's largest range), got {shown(text)}")
    return value


def _refine(args: argparse.Namespace, say):
    """``--meshes`` and its options: the partial echoes' fit (:func:`~zbuf_occlude.sensors.fit.partial_echo_meshes.partial_echo_refine`),
    checked before any scan is read; None without ``--meshes`` (its options then refused, naming them)."""
    if args.meshes is None:
        given = [flag for flag, value in (("--crops-per-mesh", args.crops_per_mesh), ("--up-map", args.up_map), ("--sizes", args.sizes),
                                          ("--up", args.up)) if value is not None]  # fmt: skip
        if given:
            raise InvalidInputError(f"{', '.join(given)}: for the partial echoes' fit, which --meshes FOLDER asks for")
        return None
    from zbuf_occlude.cli.sim2real import parse_up_map
    from zbuf_occlude.sensors.fit.partial_echo_meshes import partial_echo_refine
    from zbuf_occlude.mesh.sizes import parse_sizes

    up_map = parse_up_map(args.up_map)
    crops = DEFAULT_CROPS_PER_MESH if args.crops_per_mesh is None else args.crops_per_mesh
    return partial_echo_refine(args.meshes, crops_per_mesh=crops, seed=args.seed, up=args.up or "auto", up_map=up_map,
                               sizes=parse_sizes(args.sizes), say=say, names=FIT_SENSOR_OPTIONS)  # fmt: skip


#: ``fit-sensor``'s option of each argument of :func:`~zbuf_occlude.sensors.fit.engine.fit_sensor` and of the partial echoes'
#: fit (:func:`~zbuf_occlude.sensors.fit.partial_echo_meshes.partial_echo_refine`), for their messages.
FIT_SENSOR_OPTIONS = {"out": "--out", "sensor": "--sensor", "altitude_m": "--altitude", "classes": "--classes", "bootstrap": "--bootstrap",
                      "divergence_shares": "--divergence-shares", "meshes": "--meshes", "sizes": "--sizes"}  # fmt: skip


def cmd_fit_sensor(args: argparse.Namespace) -> int:
    from zbuf_occlude.sensors.fit.engine import LasFit, fit_sensor

    def say(line: str) -> None:
        print(line, flush=True)

    las = LasFit(altitude_m=args.altitude, classes=args.classes, bootstrap=args.bootstrap, divergence_shares=args.divergence_shares)
    result = fit_sensor(args.real, args.sensor, args.out, seed=args.seed, las=las, refine=_refine(args, say), say=say,
                        names=FIT_SENSOR_OPTIONS)  # fmt: skip
    print(result.table, end="")
    print(f"wrote {result.json_path} (use it as --sensor {result.json_path}), {result.markdown_path}")
    return 0


def add_fit_sensor_parser(sub) -> argparse.ArgumentParser:
    """Add ``fit-sensor`` to the subparsers ``sub``."""
    from zbuf_occlude.sensors.fit.lidar import BOOTSTRAP

    names = preset_names()
    p = sub.add_parser(
        "fit-sensor", help="fit a spinning LiDAR or an airborne scanner to your real object scans, or its return model to your LAS/LAZ scans",
        description="Estimate what the simulation can set from a folder of real segmented object scans (metres, z up), "
        "each with a bootstrap uncertainty, and write a sensor JSON that scan, farm --sensor and experiment sim2real "
        "--sensor take.  The --sensor to start from chooses the fit.  A spinning LiDAR: scans in the sensor's frame "
        "(sensor at the origin); azimuth step, range noise, dropout, and the ring spacing, count-vs-range law and "
        "ground returns.  An airborne scanner: aerial crops as they lie, no sensor position needed; point density, "
        "scan angle and swath, range noise (altitude and speed are the preset's; the flight plan puts scanned objects at "
        "the crops' scan angles).  Spinning fits refuse aerial crops in one line.  LAS/LAZ scans (a .las/.laz file, or a folder of them: tiles or "
        "crops of one survey) fit the return model instead: the range resolution, the most returns per pulse, the detection "
        "threshold and the intensity scale, per class too, beside the returns-per-pulse shares, gaps and intensities they "
        "rest on; the beam divergence cannot be told from the points: it stays the --sensor's, or is fitted to shares "
        "simulated at several divergences (--divergence-shares).",
    )  # fmt: skip
    p.add_argument(
        "real",
        metavar="REAL_SCANS",
        help="folder of real object scans (class folders of point files, LiDARNet CSVs, or SUO), "
        "or a .las/.laz scan or a folder of them (the return model)",
    )
    p.add_argument(
        "--sensor", required=True,
        help=f"the preset or sensor JSON to start from: a spinning LiDAR ({', '.join(names['lidar'])}; its beam table is kept) "
        f"fits scans in the sensor's frame; an airborne scanner ({', '.join(names['airborne'])}) fits aerial crops",
    )  # fmt: skip
    p.add_argument("--out", required=True, help="the fitted sensor, a .json file (a .md table is written beside it)")
    p.add_argument("--seed", action=Checked, check=seed, default=DEFAULT_SEED, help="seed of the bootstrap (default: %(default)s)")
    r = p.add_argument_group("LAS/LAZ scans (the return model)")
    r.add_argument("--altitude", metavar="M", action=Checked, check=_altitude, default=None,
                   help="flying height above the ground, metres: a LAS file records no sensor position, and the intensity scale "
                        "and the detection threshold in energy depend on the range (default: the airborne --sensor's altitude; "
                        "IGN LiDAR HD flies about 1,500 m)")  # fmt: skip
    r.add_argument("--classes", metavar="C,C,...", action=Checked, check=_classes, default=None,
                   help="ASPRS classes of the class-set figures, or none (default: 3,4,5, vegetation); every class in the file "
                        "gets its own figures anyway")  # fmt: skip
    r.add_argument(
        "--bootstrap",
        metavar="N",
        action=Checked,
        check=resamples,
        default=None,
        help=f"resamples of the bootstrap over pulses, 2 to {MAX_BOOTSTRAP:,} (default: {BOOTSTRAP})",
    )
    r.add_argument("--divergence-shares", metavar="CSV", default=None,
                   help="the beam divergence fitted by simulation: a table with the header divergence_deg,<figure>[,std] (the "
                        "figure a return statistic, e.g. multi_return_points_class_5) of the share simulated at each divergence "
                        "(degrees, increasing), inverted at your scans' share (default: the divergence is not fitted)")  # fmt: skip
    m = p.add_argument_group("the detection of partial echoes (a spinning LiDAR's object scans)")
    m.add_argument("--meshes", metavar="FOLDER", default=None,
                   help="also fit the beam's min_echo_reflectance, the weakest partial echo the receiver reports: meshes of your "
                        "scans' classes (one sub-folder per class, named as the scans' labels, as experiment sim2real reads them) "
                        "are scanned by the fitted sensor with a footprint over the --sensor's beam divergence and the strongest "
                        "return of each pulse (how your scans are assumed recorded), at each threshold of a grid, and the threshold "
                        "whose outline shares (scans 5-10 m away) meet your scans' is written into the sensor, with that beam")  # fmt: skip
    m.add_argument("--crops-per-mesh", metavar="N", action=Checked, check=count("MAX_SAMPLES"), default=None,
                   help=f"crops of each mesh at each threshold (default: {DEFAULT_CROPS_PER_MESH})")  # fmt: skip
    m.add_argument(
        "--up", choices=UP_CHOICES, default=None, help="up axis of the mesh files; auto: each format's convention (default: auto)"
    )
    m.add_argument("--up-map", metavar="GLOB=AXIS,...", default=None,
                   help="per-file up axis of the meshes, globs of paths relative to FOLDER (e.g. 'bush/openglforest__*=+y')")  # fmt: skip
    m.add_argument("--sizes", metavar="CLASS=DIM:LO-HI,...", default=None,
                   help="real sizes of the mesh classes, metres, over the defaults (car, pedestrian, pole, bush), as experiment "
                        "sim2real --sizes (e.g. chair=height:0.8-1.1)")  # fmt: skip
    p.set_defaults(func=cmd_fit_sensor)
    return p
