"""``zbuf-occlude scan`` and ``zbuf-occlude realism``: options beside their engines.

``cli.build_parser`` calls :func:`add_scan_parser` and :func:`add_realism_parser`.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from zbuf_occlude.cli.crops import FLAGS, CropSettings, add_crop_arguments, crop_settings, given_crop_options
from zbuf_occlude.cli.options import Checked, count, counted, interval, out_folder, parse_interval, real, seed, shown
from zbuf_occlude.defaults import DEFAULT_SEED
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.mesh.formats import EXTENSIONS_TEXT
from zbuf_occlude.mesh.sizes import DIMENSIONS, SizeRange, size_interval
from zbuf_occlude.sensors.footprint import FOOTPRINT_RAYS
from zbuf_occlude.sensors.placement import CropDistributions
from zbuf_occlude.sensors.presets import preset_names, sensor_from_name

__all__ = ["add_scan_parser", "add_realism_parser", "add_parser", "parse_interval"]

log = logging.getLogger(__name__)


#: A mesh whose height is below this share of its largest side is flat in z: stood on the ground it
#: lies in the ground plane, where a scan cannot tell it from the ground (scan refuses it).
FLAT_SHARE = 1e-6

#: Unit primitives ``scan`` takes instead of a mesh file (stretch them with ``--extents``).
PRIMITIVES = {
    "cylinder": {"cylinder": {"radius_m": 0.5, "height_m": 1.0, "sections": 48}},
    "box": {"box_m": [1.0, 1.0, 1.0]},
}


def _outline(text: str | None) -> tuple[float, ...] | None:
    """``--outline V,V,...``: two or more widths over the scan's width, bottom to top (:func:`~zbuf_occlude.sensors.scene.check_width_profile`)."""
    from zbuf_occlude.sensors.scene import check_width_profile

    if text is None:
        return None
    try:
        return check_width_profile(text.split(","))
    except InvalidInputError:
        raise InvalidInputError(f"--outline must be 2 or more numbers > 0, V,V,..., bottom to top, got {text!r}") from None


def check_outside(dist, extents=None) -> None:
    """Refuse a ``--distance`` that may put the sensor inside the object.

    The object's footprint centre lies ``distance_m`` from the sensor and its largest
    horizontal dimension is up to ``size_m`` (or the X/Y ``extents_m``) high end, or, given the
    mesh's ``extents (3,)``, its larger horizontal side scaled so, times the ``width_scale``
    high end where it stretches the object and the largest ``width_profile`` factor above 1
    where it warps it; a distance below half of that may stand the sensor
    inside it (every ray starts inside).

    Raises
    ------
    InvalidInputError
        Naming ``--distance`` and the smallest distance allowed.
    """
    if dist.extents_m is not None:
        sizes = [dist.extents_m[0][1], dist.extents_m[1][1]]
    else:
        e = None if extents is None else np.asarray(extents, dtype=np.float64)
        sizes = [dist.size_m[1] * (1.0 if e is None or not e.max() > 0 else float(e[:2].max() / e.max()))]
    if dist.width_scale is not None:
        sizes = [v * dist.width_scale[1] for v in sizes]
    if dist.width_profile is not None:
        sizes = [v * max(1.0, *dist.width_profile) for v in sizes]
    half = max(sizes) / 2
    if dist.distance_m[0] < half:
        raise InvalidInputError(
            f"--distance {dist.distance_m[0]:g} m may put the sensor inside the object (up to {max(sizes):g} m across): "
            f"use a distance of at least {half:g} m"
        )


def _max_returns(text: str, option: str) -> int:
    """``--max-returns N``: a whole number from 1 to :data:`~zbuf_occlude.sensors.echoes.MAX_RETURNS` (LAS's return numbers)."""
    from zbuf_occlude.sensors.echoes import MAX_RETURNS

    n = count(None)(text, option)
    if n > MAX_RETURNS:
        raise InvalidInputError(f"{option} must be at most {MAX_RETURNS} (a LAS return number's range), got {shown(text)}")
    return n


#: Most ``CLASS=VALUE`` pairs ``--transmittance`` takes (a scene file holds at most this many objects' classes).
MAX_TRANSMITTANCE_CLASSES = 256


def _transmittance(text: str, option: str):
    """``--transmittance``: ``table``, one number in [0, 1] (every object, not the ground), or ``CLASS=VALUE,...``.

    Returns "table", a float, or a dict of class name → float.

    Raises
    ------
    InvalidInputError
        Naming the option and the value: a number outside [0, 1] or not finite, a pair without a
        class or a value, a class given twice, more than :data:`MAX_TRANSMITTANCE_CLASSES` pairs.
    """
    text = text.strip()
    if text.lower() == "table":
        return "table"

    def fraction(value: str, what: str) -> float:
        v = real(0.0)(value, option)
        if v > 1.0:
            raise InvalidInputError(f"{option} must be a transmittance in [0, 1], got {shown(what)}")
        return v

    if "=" not in text:
        return fraction(text, text)
    pairs = text.split(",")
    if len(pairs) > MAX_TRANSMITTANCE_CLASSES:
        raise InvalidInputError(f"{option} takes at most {MAX_TRANSMITTANCE_CLASSES} CLASS=VALUE pairs, got {len(pairs):,}")
    out: dict[str, float] = {}
    for pair in pairs:
        name, _, value = (part.strip() for part in pair.partition("="))
        if not name or not value:
            raise InvalidInputError(f"{option} must be table, a number in [0, 1], or CLASS=VALUE,... (bush=0.3,tree=0.3), got {shown(pair)}")
        if name.lower() in out:
            raise InvalidInputError(f"{option} gives the class {shown(name)} twice")
        out[name.lower()] = fraction(value, pair)
    return out


def _with_return_physics(sensor, args: argparse.Namespace):
    """``sensor`` with the return physics options applied (:func:`_return_physics`), and
    ``--reflectance-table`` and ``--transmittance`` checked against it (:func:`_surface_optics` applies them).

    Raises
    ------
    InvalidInputError
        As :func:`_return_physics`; and ``--reflectance-table`` or ``--transmittance`` for a scan
        of a mesh file (they give each object of a scene file its own value), for a sensor other
        than a spinning LiDAR or ray table; ``--transmittance`` above 0 without several returns per
        pulse or with ``--backend zbuffer`` (one face per pixel), each naming the value.
    """
    out = _return_physics(sensor, args)
    table, tau = getattr(args, "reflectance_table", False), getattr(args, "transmittance", None)
    given = " and ".join(f for f, v in (("--reflectance-table", table), (f"--transmittance {_shown_tau(tau)}", tau is not None)) if v)
    if not given:
        return out
    from zbuf_occlude.sensors.lidar import Lidar
    from zbuf_occlude.sensors.ray_table import RayTable

    if Path(args.mesh_or_scene).suffix.lower() not in (".json", ".yaml", ".yml"):
        raise InvalidInputError(f"{given} give each object of a scene file its own value: scan a scene .json/.yaml "
                                f"({args.mesh_or_scene} is a mesh; its crops take --reflectivity)")  # fmt: skip
    if not isinstance(out, (Lidar, RayTable)):
        raise InvalidInputError(f"{given} model spinning LiDARs and ray tables; {args.sensor} is not one")
    opaque = tau is None or (not isinstance(tau, (str, dict)) and tau == 0) or (isinstance(tau, dict) and not any(tau.values()))
    if not opaque and not out.multi_return:
        raise InvalidInputError(f"--transmittance {_shown_tau(tau)} gives hits behind a surface, which only several returns per pulse "
                                "resolve: give --max-returns above 1 (and --footprint)")  # fmt: skip
    if not opaque and getattr(args, "backend", "embree") != "embree":
        raise InvalidInputError(f"--transmittance {_shown_tau(tau)} needs every hit along each sub-ray, which --backend {args.backend} "
                                "cannot give (one face per pixel): use --backend embree")  # fmt: skip
    return out


def _shown_tau(tau) -> str:
    """``--transmittance``'s parsed value as the user wrote it, for messages."""
    if isinstance(tau, dict):
        return ",".join(f"{k}={v:g}" for k, v in tau.items())
    return tau if isinstance(tau, str) else f"{tau:g}" if tau is not None else ""


def _surface_optics(args: argparse.Namespace, scene) -> dict:
    """``scan``'s ``reflectivity`` and ``transmittance`` keywords from ``--reflectance-table`` and
    ``--transmittance`` for a :class:`~zbuf_occlude.sensors.scene.ScanScene` (none given: no keyword,
    the scan as without them).

    Raises
    ------
    InvalidInputError
        A ``--transmittance CLASS=VALUE`` class that no object of the scene has, naming it.
    """
    from zbuf_occlude.sensors.reflectance import per_class

    out: dict = {}
    if getattr(args, "reflectance_table", False):
        out["reflectivity"] = "table"
    tau = getattr(args, "transmittance", None)
    if isinstance(tau, dict):
        try:
            out["transmittance"] = per_class(scene.build(), tau)
        except InvalidInputError as exc:
            raise InvalidInputError(f"--transmittance {_shown_tau(tau)}: {exc}") from None
    elif isinstance(tau, str):
        out["transmittance"] = tau
    elif tau is not None:  # every object, not the ground
        out["transmittance"] = [0.0] + [tau] * (len(scene.build().objects))
    return out


def _return_physics(sensor, args: argparse.Namespace):
    """``sensor`` with ``--footprint``, ``--power-noise``, ``--echo-separation``, ``--max-returns`` and
    ``--range-resolution`` applied: all five to a spinning LiDAR, the last two to an airborne
    scanner (its footprint is the sensor file's ``footprint_rays``).

    ``--footprint`` gives :data:`~zbuf_occlude.sensors.footprint.FOOTPRINT_RAYS` sub-rays; without it the sensor's own ``footprint_rays`` stay (a sensor
    file's K above 1 is a footprint for ``--echo-separation``).  ``--max-returns`` above 1 needs a
    range resolution, from ``--range-resolution`` or the sensor's.

    Raises
    ------
    InvalidInputError
        Naming the option and its value: one of them for a depth camera, ``--footprint``,
        ``--power-noise`` or ``--echo-separation`` for an airborne scanner,
        ``--echo-separation`` without a footprint or with several returns, ``--range-resolution``
        with one return per pulse, ``--max-returns`` above 1 without a range resolution.
    """
    from zbuf_occlude.sensors.airborne import AirborneScanner
    from zbuf_occlude.sensors.lidar import Lidar

    given = [f for f, v in (("--footprint", args.footprint), ("--power-noise", args.power_noise), ("--echo-separation", args.echo_separation),
                            ("--max-returns", args.max_returns), ("--range-resolution", args.range_resolution)) if v]  # fmt: skip
    if not given:
        return sensor
    airborne = isinstance(sensor, AirborneScanner) and not (args.footprint or args.power_noise or args.echo_separation)
    if not (isinstance(sensor, Lidar) or airborne):
        raise InvalidInputError(f"--footprint, --power-noise, --echo-separation, --max-returns and --range-resolution model spinning LiDARs; "
                                f"{args.sensor} is not one (given: {', '.join(given)})")  # fmt: skip
    if airborne and args.max_returns == 1 and sensor.footprint_rays > 1:
        raise InvalidInputError(f"--max-returns 1: {args.sensor} has a footprint of {sensor.footprint_rays} sub-rays, which an airborne scanner "
                                "resolves into several returns; give --max-returns above 1")  # fmt: skip
    rays = FOOTPRINT_RAYS if args.footprint else sensor.footprint_rays
    max_returns = args.max_returns or sensor.max_returns
    resolution = args.range_resolution or sensor.range_resolution_m
    if args.echo_separation and rays == 1:
        raise InvalidInputError(f"--echo-separation {args.echo_separation:g} needs --footprint (mixed pixels come from a wide footprint)")
    if max_returns > 1 and args.echo_separation:
        raise InvalidInputError(f"--echo-separation {args.echo_separation:g} merges echoes into one return; with --max-returns {max_returns} "
                                "give --range-resolution instead")  # fmt: skip
    if max_returns > 1 and not resolution > 0:
        raise InvalidInputError(f"--max-returns {max_returns} needs --range-resolution M (metres: the least range between two returns)")
    if args.range_resolution and max_returns == 1:
        raise InvalidInputError(f"--range-resolution {args.range_resolution:g} separates several returns per pulse: it needs --max-returns above 1")
    if airborne:
        return sensor.with_(max_returns=max_returns, range_resolution_m=resolution if max_returns > 1 else sensor.range_resolution_m)
    return sensor.with_(footprint_rays=rays, power_noise=args.power_noise, echo_separation_m=args.echo_separation or sensor.echo_separation_m,
                        max_returns=max_returns, range_resolution_m=resolution if max_returns > 1 else sensor.range_resolution_m)  # fmt: skip


#: ``scan``'s placement when no option changes it: a car (4.5 m) 10 m ahead of a LiDAR on a car roof.
SCAN_CROP_DISTRIBUTIONS = CropDistributions(distance_m=10.0, height_m=1.8, size_m=4.5, azimuth_deg=0.0, yaw_deg=0.0)
#: ``scan``'s own option of each other :class:`~zbuf_occlude.sensors.placement.CropDistributions` field it sets, for
#: messages (the crop options of :mod:`zbuf_occlude.cli.crops` name theirs).
SCAN_OPTION_NAMES = {"azimuth_deg": "--azimuth", "yaw_deg": "--yaw", "extents_m": "--extents", "ground_reflectivity": "--ground-reflectivity"}
#: What ``scan`` adds to the help of a crop option.
SCAN_NOTES = {
    "distance_m": "at least half the object's size; an airborne scanner flies over the object, distance · sin(azimuth) "
    "across track from its plan's centre",
    "size_m": "see --size-of",
    **{field: "with --crop" for field in ("ground_margin_m", "hidden_below_m", "across_sight_width_m")},
}


def _largest_side(crops: CropSettings, size_of: str, mesh) -> CropSettings:
    """``crops`` with its size the interval of the object's largest side, metres: ``--size-of`` a mesh's height or length converted."""
    if size_of == "max":
        return crops
    if isinstance(mesh, dict):
        raise InvalidInputError(f"--size-of {size_of} measures a mesh file; a primitive takes --size (its largest dimension) or --extents")
    return crops.with_fields(size_m=size_interval(mesh.extents, SizeRange(size_of, *crops.distributions.size_m)))


#: ``scan``'s sensor when neither ``--sensor`` nor ``--ray-table`` names one.
SCAN_SENSOR = "hdl32e"


def _scan_sensor(args: argparse.Namespace):
    """The sensor ``scan`` fires: ``--sensor``'s (:data:`SCAN_SENSOR` by default) with the return physics options, or the
    :class:`~zbuf_occlude.sensors.ray_table.RayTable` of ``--ray-table FILE``.

    Raises
    ------
    InvalidInputError
        ``--ray-table`` with ``--sensor`` (one sensor per scan) or with a return physics option (they model LiDAR
        presets and sensor files), or a file :func:`~zbuf_occlude.sensors.ray_table.load_ray_table` refuses.
    """
    if args.ray_table is None:
        args.sensor = args.sensor or SCAN_SENSOR
        return _with_return_physics(sensor_from_name(args.sensor), args)
    from zbuf_occlude.sensors.ray_table import load_ray_table

    if args.sensor is not None:
        raise InvalidInputError(f"--ray-table {args.ray_table} is the sensor: give --ray-table or --sensor {args.sensor}, not both")
    table = load_ray_table(args.ray_table)
    args.sensor = args.ray_table  # what the return physics options' messages name
    return _with_return_physics(table, args)


def cmd_scan(args: argparse.Namespace) -> int:
    sensor = _scan_sensor(args)
    if not args.crop:
        for flag, option in given_crop_options(args, in_crop=True):
            raise InvalidInputError(f"{flag} {option.in_crop}: it needs --crop")
        if args.outline is not None:
            raise InvalidInputError("--outline gives the object's crops the outline of real scans: it needs --crop")
    if args.occlude and args.across_sight_width is None:
        width = getattr(args, FLAGS)["across_sight_width_m"]
        raise InvalidInputError(f"--occlude meets {width} with a side occluder: it needs {width}")
    formats = ("npz", "ply") if args.format == "both" else (args.format,)
    # a refused run's empty --out is removed by cli.main
    with OwnedFolder(args.out, names=[SCAN_FILE_NAMES], what="the scan") as folder:
        return _scan_into(folder, args, sensor, formats)


#: The files ``scan`` writes in ``--out``: ``<stem>_<sensor>_sNNN.npz|ply|las|laz``.
SCAN_FILE_NAMES = r"[^/]+_s\d{3,}\.(npz|ply|las|laz)"


def _save(folder: OwnedFolder, s, stem: str, formats: Sequence[str]) -> list[Path]:
    """Write scan ``s`` as ``<stem>.<fmt>`` for each format, through the owned folder."""
    files = []
    for fmt in formats:
        if fmt in ("las", "laz"):  # LAS 1.4 point format 6, encoded in memory
            folder.write_bytes(f"{stem}.{fmt}", s.to_las_bytes(compress=fmt == "laz"))
        else:
            with folder.write(f"{stem}.{fmt}") as tmp:
                getattr(s, f"to_{fmt}")(tmp)
        files.append(folder.root / f"{stem}.{fmt}")
    return files


def _scan_into(folder: OwnedFolder, args: argparse.Namespace, sensor, formats: Sequence[str]) -> int:
    """:func:`cmd_scan` once ``--out`` is held."""
    from zbuf_occlude.io.progress import progress as progress_bar
    from zbuf_occlude.sensors.airborne import AirborneScanner
    from zbuf_occlude.sensors.crops import object_crops
    from zbuf_occlude.sensors.lidar import Lidar
    from zbuf_occlude.sensors.ray_table import RayTable
    from zbuf_occlude.sensors.scan import look_at_pose, scan
    from zbuf_occlude.sensors.scene import GROUND_ID, load_scene

    out = folder.root
    src = Path(args.mesh_or_scene)
    written, empty = [], 0
    if src.suffix.lower() in (".json", ".yaml", ".yml"):
        if args.crop:
            raise InvalidInputError(f"--crop keeps one mesh's returns; {src.name} is a scene file, scanned whole")
        scene = load_scene(src)
        if isinstance(sensor, (Lidar, RayTable)):
            pose = scene.default_sensor_pose()
        else:  # a camera looks at the first object from the sensor position
            target = scene.build().local_to_world[1][:3, 3] if scene.objects else np.array([1.0, 0.0, scene.ground_z_m])
            pose = look_at_pose(scene.default_sensor_pose()[:3, 3], target + [0, 0, 0.5])
        for k in progress_bar(range(args.samples), desc="scan", unit="scan", enabled=not args.no_progress):
            if isinstance(sensor, AirborneScanner):  # a flight over the scene's ground (world frame)
                from zbuf_occlude.sensors.airborne import scan_airborne

                s = scan_airborne(scene, sensor, (0.0, 0.0), scene.ground_half_extent_m, seed=args.seed + k)
            else:
                s = scan(scene, sensor, pose, seed=args.seed + k, backend=args.backend, frame=args.frame, **_surface_optics(args, scene))
            written += _save(folder, s, f"{src.stem}_{sensor.name}_s{k:03d}", formats)
    else:
        if not isinstance(sensor, (Lidar, RayTable, AirborneScanner)):
            raise InvalidInputError("scan of a mesh file places a LiDAR; use a scene file for depth cameras")
        extents, round_xy = None, False
        if args.extents and args.size_of != "max":
            raise InvalidInputError(f"--size-of {args.size_of} says what --size measures; --extents gives every side instead")
        if args.extents:
            parts = args.extents.split(",")
            if len(parts) != 3:
                raise InvalidInputError(f"--extents must be X,Y,Z in metres (each N or LO:HI; Y may be '='), got {args.extents!r}")
            round_xy = parts[1].strip() == "="
            extents = tuple(parse_interval(parts[0] if i == 1 and round_xy else v, "--extents") for i, v in enumerate(parts))
        mesh = PRIMITIVES.get(str(src)) if not src.exists() else None
        if mesh is None:
            from zbuf_occlude.mesh.load import load_mesh

            mesh = load_mesh(src, up=args.up)  # once, not per sample
            if not mesh.extents[2] > FLAT_SHARE * mesh.extents.max():
                raise InvalidInputError(
                    f"{src}: flat in z (no height once its up axis is turned to +z, --up {args.up}): stood on the ground it lies "
                    "in the ground plane, where no scan can tell it from the ground; give --up the axis it should stand along "
                    "(e.g. --up +y), or give it a thickness"
                )
        crops = crop_settings(args, SCAN_CROP_DISTRIBUTIONS, azimuth_deg=parse_interval(args.azimuth, "--azimuth"),
                              yaw_deg=parse_interval(args.yaw, "--yaw"), extents_m=extents, round_xy=round_xy,
                              ground_reflectivity=args.ground_reflectivity)  # fmt: skip
        dist = _largest_side(crops, args.size_of, mesh).distributions
        if crops.across_sight_width_m is not None or args.outline is not None:
            from zbuf_occlude.sensors.fit import fit_object_shape

            dist = replace(dist, **fit_object_shape(mesh, sensor, dist, crops.across_sight_width_m, _outline(args.outline), occlude=args.occlude,
                                                    seed=args.seed, name=str(src)))  # fmt: skip
            log.info("%s: width_scale %s, visible_across_sight %s, width_profile %s", src.name, dist.width_scale, dist.visible_across_sight,
                     dist.width_profile)  # fmt: skip
        if not isinstance(sensor, AirborneScanner):  # an aircraft flies its altitude above the object
            check_outside(dist, None if isinstance(mesh, dict) else mesh.extents)
        # the farm's loop and seeds: one seed gives the crops farm --sensor gives a folder holding this file
        crops = object_crops(mesh, sensor, dist, name=src.stem, n_samples=args.samples, seed=args.seed, backend=args.backend, frame=args.frame)
        for k, crop, _ in progress_bar(crops, total=args.samples, desc="scan", unit="scan", enabled=not args.no_progress):
            placement = crop.placement
            s = crop.scan if args.crop else crop.full
            s.meta.update(placement.to_dict())
            stem = f"{src.stem}_{sensor.name}_s{k:03d}"
            files = _save(folder, s, stem, formats)
            written += files
            returns = int(np.count_nonzero(crop.scan.object_id != GROUND_ID))
            if returns == 0:
                empty += 1
                print(f"EMPTY {files[0]}: no return of the object (edge-on, below the sensor's beams or beyond its range at "
                      f"{placement.distance_m:.2f} m)", file=sys.stderr)  # fmt: skip
            log.info("%s: %d returns of the object at %.2f m", stem, returns, placement.distance_m)
    print(f"wrote {counted(len(written), 'file')} to {out}" + (f"; {empty} of {counted(args.samples, 'scan')} hold no return of the object" if empty else ""))
    return 1 if empty else 0


def add_scan_parser(sub) -> argparse.ArgumentParser:
    """Add ``scan`` to the subparsers ``sub``."""
    from zbuf_occlude.mesh.scene import UP_CHOICES

    names = preset_names()
    p = sub.add_parser(
        "scan", help="LiDAR / depth-camera scan of a mesh on the ground, or of a scene file",
        description="Stand a mesh on a ground plane at --distance from a simulated LiDAR and scan it (or fly an airborne "
        "scanner over it, or scan a scene file with any sensor); writes one point cloud per sample to --out.  A mesh "
        "flat in z (a single square, no height) is refused: on the ground it lies in the ground plane.  The exit "
        "status is 1 when a scan of a mesh holds no return of the object (each such file is named on stderr: seen "
        "edge-on, below the beams or out of range).",
    )  # fmt: skip
    p.add_argument("mesh_or_scene", metavar="MESH_OR_SCENE", help=f"mesh file ({EXTENSIONS_TEXT}; stood on the ground), 'cylinder' or 'box' (unit primitives), or a scene .json/.yaml")
    p.add_argument(
        "--sensor", default=None,
        help=f"a spinning LiDAR ({', '.join(names['lidar'])}), an airborne scanner ({', '.join(names['airborne'])}), a depth "
        f"camera ({', '.join(names['depth_camera'])}), or a sensor .json (fit-sensor writes one) (default: {SCAN_SENSOR})",
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
    r = p.add_argument_group("return physics (LiDAR)", "with --reflectivity and --footprint above")
    r.add_argument("--ground-reflectivity", action=Checked, check=real(0.0), default=0.15, help="the ground's reflectivity with --reflectivity (default: %(default)s)")
    r.add_argument("--power-noise", action=Checked, check=real(0.0), default=0.0, help="sigma of ln(received power) per firing; 0: a sharp threshold (default: %(default)s)")
    r.add_argument(
        "--echo-separation", metavar="M", action=Checked, check=real(0.0, unit="metres"), default=0.0,
        help="with --footprint: echoes within M metres of the strongest merge into one return at their energy-weighted "
        "range (mixed pixels at shallow depth edges; half the pulse length, ~0.75 m for 5 ns) (default: 0, never)",
    )  # fmt: skip
    r.add_argument("--max-returns", metavar="N", action=Checked, check=_max_returns, default=None,
                   help="with --footprint (or a sensor file's footprint, airborne scanners too): up to N returns per pulse (1..15), the "
                        "footprint's echoes resolved by --range-resolution, each with its return number, number of returns and "
                        "intensity (default: the sensor's, 1 for presets)")  # fmt: skip
    r.add_argument("--range-resolution", metavar="M", action=Checked, check=real(0.0, above=True, unit="metres"), default=None,
                   help="with --max-returns above 1: echoes closer than M metres merge into one return (half the pulse length, "
                        "~0.75 m for 5 ns) (default: the sensor's)")  # fmt: skip
    r.add_argument("--reflectance-table", action="store_true",
                   help="a scene file's surfaces reflect as the cited table gives their material at 905 nm (by each object's "
                        "material or class: leaves, bark, car paint, glass, metal, ...; the ground asphalt), and returns must clear "
                        "the sensor's radiometric threshold")  # fmt: skip
    r.add_argument("--transmittance", metavar="SPEC", action=Checked, check=_transmittance, default=None,
                   help="with --max-returns above 1, a scene file: the share of each sub-ray that goes on through an object's "
                        "surface and comes back, in [0, 1] (a leafy crown's gap fraction); table (foliage 0.3 from the reflectance "
                        "table), one number (every object), or CLASS=VALUE,... (bush=0.3,tree=0.3) (default: 0, opaque)")  # fmt: skip
    p.add_argument("--azimuth", action=Checked, check=interval, default="0", help="direction of the object from the sensor, degrees (N or LO:HI) (default: %(default)s)")
    p.add_argument("--yaw", action=Checked, check=interval, default="0", help="the object's heading, degrees (N or LO:HI) (default: %(default)s)")
    p.add_argument("--samples", action=Checked, check=count("MAX_SAMPLES"), default=1, help="scans, each with its own draws (default: %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (or, when stderr is a file, no progress lines)")
    p.add_argument("--crop", action="store_true", help="write only the object's returns; default: the object and the ground in the object's azimuth sector (±5°)")
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
        "--frame", choices=("sensor", "world"), default="sensor",
        help="frame of the written points: sensor (LiDAR at the origin, x forward, z up; cameras: OpenCV) or "
        "world (the scene's frame) (default: %(default)s)",
    )  # fmt: skip
    p.add_argument("--format", choices=("npz", "ply", "both", "las", "laz"), default="npz",
                   help="file format of each scan: npz, ply, both (npz and ply), or LAS 1.4 / LAZ with return number, intensity, "
                        "GPS time and scan angle per point (default: %(default)s)")
    p.add_argument(
        "--backend", choices=("embree", "zbuffer"), default="embree",
        help="ray casting: embree (exact, CPU) or zbuffer (OpenGL depth images) (default: %(default)s)",
    )  # fmt: skip
    p.add_argument("--seed", action=Checked, check=seed, default=0, help="seed of the placement draws and the sensor noise; one seed gives the crops farm --sensor gives "
                   "the file in a folder of meshes (default: %(default)s)")
    p.add_argument("--up", choices=UP_CHOICES, default="auto", help="a mesh file's up axis, turned to +z; auto: by its path and format, as in generate and farm "
                   "(ShapeNetCore paths and glTF +y, ...) (default: %(default)s)")
    p.add_argument("--out", required=True, action=Checked, check=out_folder, help="output folder")
    p.set_defaults(func=cmd_scan)
    return p


def cmd_realism(args: argparse.Namespace) -> int:
    from zbuf_occlude.experiments.realism import class_table, markdown_table, realism_report

    out_folder(args.out, "--out")  # the default's check; a given --out was checked while parsing
    print(f"reading {args.generated} and {args.real} ...", flush=True)
    rows, table = realism_report(args.generated, args.real, args.out, min_points=args.min_points, figure=not args.no_figure,
                                 ground_in_crops=args.ground_in_crops, airborne=args.airborne)  # fmt: skip
    print(markdown_table(rows) + "\n" + class_table(table), end="")
    print(f"wrote {Path(args.out) / 'realism.md'}, realism.csv, realism_classes.csv" + ("" if args.no_figure else ", realism.png"))
    return 0


def add_realism_parser(sub) -> argparse.ArgumentParser:
    """Add ``realism`` to the subparsers ``sub``."""
    p = sub.add_parser(
        "realism", help="generated vs real clouds: ring spacing, count-vs-range, spacing, extent; per class points, height/width, vertical profile",
        description="Compare statistics of generated scans with real LiDAR clouds and write realism.md, realism.csv, "
        "realism_classes.csv and a figure to --out.  Per class (the class folders both sets share, or all clouds pooled): "
        "points per crop, height over width, and how the points spread over the height (the median height above the "
        "crop's bottom and the share in each tenth of its height; a simulated pole that is a tall shaft where real crops "
        "show a squat top differs there).  --airborne compares aerial crops by these alone.",
    )  # fmt: skip
    p.add_argument("generated", metavar="GENERATED", help="scan .npz files or a folder of them (in class folders, GENERATED/CLASS/*.npz, for the per-class table), or LiDARNet CSVs")
    p.add_argument("real", metavar="REAL", help="real scans: class folders of point-cloud files (aerial crops, ...), LiDARNet v2 CSVs, or scan .npz")
    p.add_argument("--out", action=Checked, check=out_folder, default="realism", help="folder for realism.md, realism.csv, realism_classes.csv, realism.png (default: %(default)s)")
    p.add_argument("--min-points", action=Checked, check=count("MAX_POINTS", lowest=0), default=1, help="ignore clouds with fewer points (default: %(default)s)")
    p.add_argument(
        "--ground-in-crops", action="store_true",
        help="a generated scan file holding one object (a crop made with scan --crop --ground-margin) counts its ground "
        "returns as part of it, as a real crop holds them (default: ground returns never count)",
    )  # fmt: skip
    p.add_argument(
        "--airborne", action="store_true",
        help="the clouds are aerial crops (no sensor position in the files): compare per class only (rings and ranges "
        "need a sensor at the origin); the figure shows the height profiles",
    )  # fmt: skip
    p.add_argument("--no-figure", action="store_true", help="do not draw realism.png")
    p.set_defaults(func=cmd_realism)
    return p


#: What ``fit-sensor`` reads as LAS/LAZ scans (the return model's fit) rather than object scans.
LAS_EXTENSIONS = (".las", ".laz")
#: Most resamples ``fit-sensor --bootstrap`` takes: each costs a pass over the scan's pulses.
MAX_BOOTSTRAP = 10_000


def _las_inputs(real: str) -> list[Path] | None:
    """The LAS/LAZ files ``fit-sensor REAL`` fits the return model to: ``REAL`` itself when it is named ``.las``/``.laz``,
    or the ``.las``/``.laz`` files directly inside the folder ``REAL`` (sorted by name); None when it names neither."""
    path = Path(real)
    if path.suffix.lower() in LAS_EXTENSIONS and not path.is_dir():
        return [path]  # missing or damaged: read_las says so, naming it
    if path.is_dir():
        found = sorted(p for p in path.iterdir() if p.suffix.lower() in LAS_EXTENSIONS and not p.is_dir())
        return found or None
    return None


def _classes(text: str, option: str) -> tuple[int, ...]:
    """``--classes C,C,...``: ASPRS class codes 0 to 255 (``none``: no class set)."""
    if text.strip().lower() == "none":
        return ()
    codes = [c.strip() for c in text.split(",")]
    if not codes or len(codes) > 256 or not all(c.isdigit() and int(c) <= 255 for c in codes):
        raise InvalidInputError(f"{option} must be ASPRS class codes 0 to 255, C,C,... (or none), got {shown(text)}")
    return tuple(int(c) for c in codes)


def _bootstrap(text: str, option: str) -> int:
    """``--bootstrap N``: resamples, 2 to :data:`MAX_BOOTSTRAP`."""
    n = count(None, lowest=2, hint="a spread needs two resamples")(text, option)
    if n > MAX_BOOTSTRAP:
        raise InvalidInputError(f"{option} must be at most {MAX_BOOTSTRAP:,}, got {shown(text)}")
    return n


def _read_scans(files: Sequence[Path], real: str):
    """The LAS/LAZ ``files`` read (inside the folder ``real`` when it is one) and merged; one line naming a file that has no
    GPS time or no points, or what :func:`~zbuf_occlude.io.las.read_las` refuses."""
    from zbuf_occlude.defaults import MAX_POINTS
    from zbuf_occlude.io.las import read_las
    from zbuf_occlude.sensors.fit import merge_scans

    within = real if Path(real).is_dir() else None
    scans, total = [], 0
    for f in files:
        las = read_las(f, within=within, max_points=MAX_POINTS - total)
        if not las.has_gps_time:
            raise InvalidInputError(f"{f}: point format {las.point_format_id} has no GPS time: the returns of one pulse cannot be told apart")
        if len(las) == 0:
            raise InvalidInputError(f"{f}: holds no points")
        scans.append(las)
        total += len(las)
    return merge_scans(scans, [str(f) for f in files])


def _fit_returns(args: argparse.Namespace, files: Sequence[Path]) -> int:
    """``fit-sensor`` on LAS/LAZ scans: the return model (:func:`~zbuf_occlude.sensors.fit.fit_return_model`) applied to
    ``--sensor``, written as a sensor JSON with the fit under ``"fit"`` and a Markdown table beside it."""
    import json

    from zbuf_occlude.sensors.airborne import AirborneScanner
    from zbuf_occlude.sensors.fit import BOOTSTRAP, VEGETATION_CLASSES, fit_return_model
    from zbuf_occlude.sensors.lidar import Lidar
    from zbuf_occlude.sensors.presets import sensor_to_json

    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise InvalidInputError(f"--out {out}: the fitted sensor is written as a .json file")
    base = sensor_from_name(args.sensor)
    if not isinstance(base, (Lidar, AirborneScanner)):
        raise InvalidInputError(f"--sensor {args.sensor}: fit-sensor fits a spinning LiDAR or an airborne scanner, not a {type(base).__name__}")
    altitude = args.altitude if args.altitude is not None else getattr(base, "altitude_m", None)
    if altitude is None:
        raise InvalidInputError(f"--sensor {args.sensor} is a spinning LiDAR: give --altitude M, the range to the ground in your scans, metres")
    bootstrap = args.bootstrap or BOOTSTRAP
    curve: dict = {}
    if args.divergence_shares is not None:  # read first: a bad table is refused before the scans are
        from zbuf_occlude.io.tables import read_csv_rows
        from zbuf_occlude.sensors.fit import divergence_curve

        figure, divergences, shares, stds = divergence_curve(read_csv_rows(args.divergence_shares), args.divergence_shares)
        curve = {"divergence_shares": (divergences, shares, stds), "divergence_share": figure}
    md = out.with_suffix(".md")
    names = (out.name, md.name)
    with OwnedFolder(out.parent, files=names, what="the fitted sensor") as folder:
        folder.check_writable(names)  # before any scan is read: a refusal writes nothing
        print(f"reading {counted(len(files), 'LAS/LAZ file')} from {args.real} ...", flush=True)
        las = _read_scans(files, args.real)
        print(f"read {len(las):,} points; fitting the return model to {base.name} at {altitude:g} m above the ground, "
              f"{bootstrap} bootstrap resamples ...", flush=True)  # fmt: skip
        fit = fit_return_model(las, altitude_m=altitude, classes=VEGETATION_CLASSES if args.classes is None else args.classes,
                               seed=args.seed, bootstrap=bootstrap, **curve)  # fmt: skip
        sensor = fit.apply(base)
        spec = sensor_to_json(sensor)
        spec["fit"] = {"base": base.name, "files": [f.name for f in files], "returns": fit.to_json()}
        folder.write_text(out.name, json.dumps(spec, indent=1, default=float, allow_nan=False) + "\n")
        table = fit.markdown(sensor)
        folder.write_text(md.name, f"# {sensor.name}: the return model fitted to {', '.join(f.name for f in files)}\n\n{table}")
    print(table, end="")
    print(f"wrote {out} (use it as --sensor {out}), {md}")
    return 0


def cmd_fit_sensor(args: argparse.Namespace) -> int:
    files = _las_inputs(args.real)
    if files is not None:
        return _fit_returns(args, files)
    given = [flag for flag, value in (("--altitude", args.altitude), ("--classes", args.classes), ("--bootstrap", args.bootstrap),
                                      ("--divergence-shares", args.divergence_shares)) if value is not None]  # fmt: skip
    if given:
        raise InvalidInputError(f"{', '.join(given)}: for LAS/LAZ scans, and {args.real} is neither a .las/.laz file nor a folder of them")
    from zbuf_occlude.experiments.sensor_fit import fit_sensor_to_scans

    fit, json_path, md_path = fit_sensor_to_scans(args.real, args.sensor, args.out, seed=args.seed, say=lambda line: print(line, flush=True))
    print(fit.markdown(), end="")
    print(f"wrote {json_path} (use it as --sensor {json_path}), {md_path}")
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
    p.add_argument("real", metavar="REAL_SCANS", help="folder of real object scans (class folders of point files, LiDARNet CSVs, or SUO), "
                   "or a .las/.laz scan or a folder of them (the return model)")
    p.add_argument(
        "--sensor", required=True,
        help=f"the preset or sensor JSON to start from: a spinning LiDAR ({', '.join(names['lidar'])}; its beam table is kept) "
        f"fits scans in the sensor's frame; an airborne scanner ({', '.join(names['airborne'])}) fits aerial crops",
    )  # fmt: skip
    p.add_argument("--out", required=True, help="the fitted sensor, a .json file (a .md table is written beside it)")
    p.add_argument("--seed", action=Checked, check=seed, default=DEFAULT_SEED, help="seed of the bootstrap (default: %(default)s)")
    r = p.add_argument_group("LAS/LAZ scans (the return model)")
    r.add_argument("--altitude", metavar="M", action=Checked, check=real(0.0, above=True, unit="metres"), default=None,
                   help="flying height above the ground, metres: a LAS file records no sensor position, and the intensity scale "
                        "and the detection threshold in energy depend on the range (default: the airborne --sensor's altitude; "
                        "IGN LiDAR HD flies about 1,500 m)")  # fmt: skip
    r.add_argument("--classes", metavar="C,C,...", action=Checked, check=_classes, default=None,
                   help="ASPRS classes of the class-set figures, or none (default: 3,4,5, vegetation); every class in the file "
                        "gets its own figures anyway")  # fmt: skip
    r.add_argument("--bootstrap", metavar="N", action=Checked, check=_bootstrap, default=None,
                   help=f"resamples of the bootstrap over pulses, 2 to {MAX_BOOTSTRAP:,} (default: {BOOTSTRAP})")
    r.add_argument("--divergence-shares", metavar="CSV", default=None,
                   help="the beam divergence fitted by simulation: a table with the header divergence_deg,<figure>[,std] (the "
                        "figure a return statistic, e.g. multi_return_points_class_5) of the share simulated at each divergence "
                        "(degrees, increasing), inverted at your scans' share (default: the divergence is not fitted)")  # fmt: skip
    p.set_defaults(func=cmd_fit_sensor)
    return p


def add_parser(sub) -> None:
    """Add ``scan``, ``realism`` and ``fit-sensor``."""
    add_scan_parser(sub)
    add_realism_parser(sub)
    add_fit_sensor_parser(sub)
