"""``zbuf-occlude fit-sensor``: a sensor fitted to real object scans, or its return model to LAS/LAZ scans."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from zbuf_occlude.cli.options import Checked, counted, real, resamples, seed, shown
from zbuf_occlude.defaults import DEFAULT_SEED
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.sensors.checks import MAX_RANGE_M
from zbuf_occlude.sensors.fit.lidar import MAX_BOOTSTRAP
from zbuf_occlude.sensors.kinds import preset_names, sensor_from_name

__all__ = ["add_fit_sensor_parser", "cmd_fit_sensor", "LAS_EXTENSIONS", "MAX_BOOTSTRAP"]


#: What ``fit-sensor`` reads as LAS/LAZ scans (the return model's fit) rather than object scans.
LAS_EXTENSIONS = (".las", ".laz")


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


def _altitude(text: str, option: str) -> float:
    """``--altitude M``: metres above the ground, > 0 and at most a sensor's largest range (:data:`~zbuf_occlude.sensors.checks.MAX_RANGE_M`)."""
    value = real(0.0, above=True, unit="metres")(text, option)
    if value > MAX_RANGE_M:
        raise InvalidInputError(f"{option} must be at most {MAX_RANGE_M:g} metres (a sensor's largest range), got {shown(text)}")
    return value


def _read_scans(files: Sequence[Path], real: str):
    """The LAS/LAZ ``files`` read (inside the folder ``real`` when it is one) and merged; one line naming a file that has no
    GPS time or no points, whose GPS times do not group its returns into pulses or that holds first returns only
    (:func:`~zbuf_occlude.sensors.fit.returns.check_pulses`), or what :func:`~zbuf_occlude.io.las.read_las` refuses."""
    from zbuf_occlude.defaults import MAX_POINTS
    from zbuf_occlude.io.las import read_las
    from zbuf_occlude.sensors.fit import merge_scans
    from zbuf_occlude.resources import check_memory
    from zbuf_occlude.sensors.fit.returns import BYTES_PER_POINT, check_pulses, check_return_pairs, las_pulses

    within = real if Path(real).is_dir() else None
    scans, total = [], 0
    for f in files:
        las = read_las(f, within=within, max_points=MAX_POINTS - total)
        if not las.has_gps_time:
            raise InvalidInputError(
                f"{f}: point format {las.point_format_id} has no GPS time: the returns of one pulse cannot be told apart"
            )
        if len(las) == 0:
            raise InvalidInputError(f"{f}: holds no points")
        check_memory(len(las) * BYTES_PER_POINT, option=f"the pulses of {f} ({len(las):,} points)", hint="fit a crop")
        pulses = las_pulses(las)
        check_pulses(las, pulses, name=str(f))  # times that group its returns into pulses
        check_return_pairs(las, pulses, name=str(f))  # not first returns alone
        scans.append(las)
        total += len(las)
    return merge_scans(scans, [str(f) for f in files])


def _fit_returns(args: argparse.Namespace, files: Sequence[Path]) -> int:
    """``fit-sensor`` on LAS/LAZ scans: the return model (:func:`~zbuf_occlude.sensors.fit.fit_return_model`) applied to
    ``--sensor``, written as a sensor JSON with the fit under ``"fit"`` and a Markdown table beside it."""
    import json

    from zbuf_occlude.sensors.fit import BOOTSTRAP, VEGETATION_CLASSES, fit_return_model
    from zbuf_occlude.sensors.fit.lidar import sensor_kind
    from zbuf_occlude.sensors.kinds import sensor_to_json

    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise InvalidInputError(f"--out {out}: the fitted sensor is written as a .json file")
    base = sensor_from_name(args.sensor)
    if sensor_kind(base) not in ("lidar", "airborne"):
        raise InvalidInputError(
            f"--sensor {args.sensor}: fit-sensor fits a spinning LiDAR or an airborne scanner, not a {type(base).__name__}"
        )
    altitude = args.altitude if args.altitude is not None else getattr(base, "altitude_m", None)
    if altitude is None:
        raise InvalidInputError(
            f"--sensor {args.sensor} is a spinning LiDAR: give --altitude M, the range to the ground in your scans, metres"
        )
    bootstrap = args.bootstrap or BOOTSTRAP
    curve: dict = {}
    if args.divergence_shares is not None:  # read first: a bad table is refused before the scans are
        from zbuf_occlude.io.tables import read_csv_rows
        from zbuf_occlude.sensors.fit import divergence_curve

        figure, divergences, shares, stds = divergence_curve(
            read_csv_rows(args.divergence_shares), f"--divergence-shares {args.divergence_shares}"
        )
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
        sensor, origin = fit.applied(base)
        spec = sensor_to_json(sensor)
        spec["fit"] = {"base": base.name, "files": [f.name for f in files], "beam": origin, "returns": fit.to_json()}
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

    fit, json_path, md_path = fit_sensor_to_scans(
        args.real, args.sensor, args.out, seed=args.seed, say=lambda line: print(line, flush=True)
    )
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
    p.set_defaults(func=cmd_fit_sensor)
    return p
