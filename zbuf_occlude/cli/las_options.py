"""``--crs``, ``--origin``, ``--class-map`` and ``--gps-start``: the survey fields of the LAS/LAZ files a command writes.

:func:`add_las_arguments` adds the options; each is checked while the command line is parsed
(:class:`~zbuf_occlude.cli.options.Checked`: a class map file is read and checked then, before
anything is scanned), and a refused value is one line naming the option and the value, exit
status 2.  :func:`las_keywords` turns them into the keywords of
:meth:`~zbuf_occlude.sensors.scan_data.Scan.to_las_bytes`.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

from zbuf_occlude.cli.options import GIVEN, Checked, real, shown
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.request import LAS_FORMATS
from zbuf_occlude.sensors.scan_data import GPS_START_S

__all__ = [
    "LAS_FORMATS", "LAS_OPTIONS", "add_las_arguments", "check_class_map_option", "check_crs_option", "check_gps_start_option",
    "check_origin_option", "las_keywords",
]  # fmt: skip

#: The options of :func:`add_las_arguments`: ``args`` attribute → option.
LAS_OPTIONS = {"crs": "--crs", "class_map": "--class-map", "gps_start_s": "--gps-start", "origin_m": "--origin"}


def check_crs_option(text: str, option: str) -> str:
    """``--crs EPSG:N`` or ``EPSG:H+V``: the EPSG code of a projected CRS in metres, or of one compound with a vertical CRS in
    metres, that PROJ knows (:func:`~zbuf_occlude.io.las_crs.epsg_crs`), as ``EPSG:N`` or ``EPSG:H+V``.

    Raises
    ------
    InvalidInputError
        Naming the option and the value: not ``EPSG:N`` or ``EPSG:H+V``, unknown, of another kind (geographic, geocentric,
        vertical alone) or not in metres.
    BackendUnavailable
        pyproj is not installed (the ``crs`` extra).
    """
    from zbuf_occlude.io.las_crs import epsg_crs

    if not text.strip().upper().startswith("EPSG:"):
        raise InvalidInputError(f"{option} must be an EPSG code, EPSG:N (EPSG:2154), got {shown(text)}")
    try:
        epsg_crs(text)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{option} {shown(text)}: {exc}") from None
    return "EPSG:" + "+".join(str(int(code)) for code in text.strip()[5:].split("+"))


def check_gps_start_option(text: str, option: str) -> float:
    """``--gps-start S``: a number >= 0 of seconds at which float64 GPS times keep
    :data:`~zbuf_occlude.sensors.scan_data.GPS_TIME_RESOLUTION_S` (the library's rule,
    :func:`~zbuf_occlude.sensors.scan_data.check_gps_start`; each scan's own times are checked again before it is written).

    Raises
    ------
    InvalidInputError
        Naming the option and the value: not a finite number >= 0, or a start whose float64 steps
        are coarser than the resolution (the message gives the step and the latest start that keeps it).
    """
    from zbuf_occlude.sensors.scan_data import check_gps_start

    return check_gps_start(real(0.0, unit="seconds")(text, option), name=option)


def check_class_map_option(text: str, option: str) -> dict[str, int]:
    """``--class-map FILE``: the class map the file holds (:func:`~zbuf_occlude.sensors.scene.las_classes.load_class_map`).

    Raises
    ------
    InvalidInputError
        Naming the option, the file and the key.
    """
    from zbuf_occlude.sensors.scene.las_classes import load_class_map

    try:
        return load_class_map(text)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{option} {exc}") from None


def check_origin_option(text: str, option: str) -> tuple[float, ...]:
    """``--origin E,N[,H]``: the world frame's origin in the file's coordinates, metres
    (:func:`~zbuf_occlude.sensors.scan_data.las_origin`'s rule).

    Raises
    ------
    InvalidInputError
        Not 2 or 3 comma-separated finite numbers within the bound, naming ``option``.
    """
    from zbuf_occlude.sensors.scan_data import las_origin

    try:
        values = [float(p) for p in text.split(",")]
    except ValueError:
        raise InvalidInputError(f"{option} must be E,N or E,N,H in metres, got {shown(text)}") from None
    return tuple(las_origin(values, option).tolist())


def add_las_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--crs``, ``--origin``, ``--class-map`` and ``--gps-start`` (docs/guide/las_fields.md) to ``parser``."""
    g = parser.add_argument_group(
        "LAS/LAZ fields (--format las or laz)",
        "ASPRS classes, object ids and class names, flight lines, intensity counts and adjusted standard GPS time are "
        "always written (docs/guide/las_fields.md); these options set the rest",
    )
    g.add_argument(
        "--crs", metavar="EPSG:N", action=Checked, check=check_crs_option, default=None,
        help="the coordinate reference system of the points, written as a WKT VLR: the EPSG code of a projected CRS in metres "
        "(EPSG:32633), or of one compound with a vertical CRS in metres (EPSG:2154+5720, EPSG:7415); geographic, geocentric, "
        "vertical-only and feet CRSs are refused (the points are metres on a plane, written unconverted); needs --frame world "
        "(airborne scans are) and pyproj (the crs extra) (default: none)",
    )  # fmt: skip
    g.add_argument(
        "--origin", metavar="E,N[,H]", dest="origin_m", action=Checked, check=check_origin_option, default=None,
        help="where the scene's origin lies in the file's coordinates, metres (a CRS's easting, northing and height, "
        "e.g. --crs EPSG:2154 --origin 652000,6862000,35): every point and the trajectory are written at their world "
        "position plus it; needs --frame world (airborne scans are) (default: the scene's own coordinates)",
    )  # fmt: skip
    g.add_argument(
        "--class-map", metavar="FILE", action=Checked, check=check_class_map_option, default=None,
        help='a .json object of class name to ASPRS code ({"car": 1, "oak_tree": 5}) that overrides the rule (ground 2, '
        "vegetation 3/4/5 by height, building 6, others 1) for the names it holds",
    )  # fmt: skip
    g.add_argument(
        "--gps-start", metavar="S", dest="gps_start_s", action=Checked, check=check_gps_start_option, default=GPS_START_S,
        help="adjusted standard GPS time (GPS seconds - 1e9) of the scan's time 0, by default 2026-01-01T00:00:00 UTC; every "
        "time written must stay >= 0 and below about 8.6e9 s, where float64 times (as LAS stores them) are still 1 µs apart "
        "or less (default: %(default)s)",
    )  # fmt: skip


def las_keywords(args: argparse.Namespace, formats: Sequence[str]) -> dict[str, Any]:
    """The keywords of :meth:`~zbuf_occlude.sensors.scan_data.Scan.to_las_bytes` from the options of :func:`add_las_arguments`
    (the scan's request checks them against its frame).

    Parameters
    ----------
    formats : sequence of str
        The formats the command writes.

    Raises
    ------
    InvalidInputError
        An option given while no LAS/LAZ file is written.
    """
    given = getattr(args, GIVEN, frozenset())
    if not set(formats) & set(LAS_FORMATS):
        for attr, option in LAS_OPTIONS.items():
            if attr in given:
                raise InvalidInputError(f"{option} fills LAS/LAZ files: it needs --format las or laz, not {', '.join(formats)}")
    return {"crs": args.crs, "class_map": args.class_map, "gps_start_s": args.gps_start_s, "origin_m": args.origin_m}
