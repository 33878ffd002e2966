"""``scan``'s return physics options: a LiDAR's footprint, echoes and returns per pulse, and the surface optics of a scene file.

:func:`with_return_physics` applies ``--footprint``, ``--power-noise``, ``--echo-separation``,
``--max-returns`` and ``--range-resolution`` to the sensor and checks ``--reflectance-table`` and
``--transmittance`` against it; :func:`surface_optics` turns the last two into the keywords of
:func:`zbuf_occlude.sensors.scan`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from zbuf_occlude.cli.options import count, real, shown
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.footprint import FOOTPRINT_RAYS

__all__ = ["MAX_TRANSMITTANCE_CLASSES", "check_max_returns", "check_transmittance", "with_return_physics", "surface_optics"]


def check_max_returns(text: str, option: str) -> int:
    """``--max-returns N``: a whole number from 1 to :data:`~zbuf_occlude.sensors.echoes.MAX_RETURNS` (LAS's return numbers)."""
    from zbuf_occlude.sensors.echoes import MAX_RETURNS

    n = count(None)(text, option)
    if n > MAX_RETURNS:
        raise InvalidInputError(f"{option} must be at most {MAX_RETURNS} (a LAS return number's range), got {shown(text)}")
    return n


#: Most ``CLASS=VALUE`` pairs ``--transmittance`` takes (a scene file holds at most this many objects' classes).
MAX_TRANSMITTANCE_CLASSES = 256


def check_transmittance(text: str, option: str):
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
            raise InvalidInputError(
                f"{option} must be table, a number in [0, 1], or CLASS=VALUE,... (bush=0.3,tree=0.3), got {shown(pair)}"
            )
        if name.lower() in out:
            raise InvalidInputError(f"{option} gives the class {shown(name)} twice")
        out[name.lower()] = fraction(value, pair)
    return out


def with_return_physics(sensor, args: argparse.Namespace):
    """``sensor`` with the return physics options applied (:func:`_return_physics`), and
    ``--reflectance-table`` and ``--transmittance`` checked against it (:func:`surface_optics` applies them).

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


def surface_optics(args: argparse.Namespace, scene) -> dict:
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
        raise InvalidInputError(
            f"--range-resolution {args.range_resolution:g} separates several returns per pulse: it needs --max-returns above 1"
        )
    if airborne:
        return sensor.with_(max_returns=max_returns, range_resolution_m=resolution if max_returns > 1 else sensor.range_resolution_m)
    return sensor.with_(footprint_rays=rays, power_noise=args.power_noise, echo_separation_m=args.echo_separation or sensor.echo_separation_m,
                        max_returns=max_returns, range_resolution_m=resolution if max_returns > 1 else sensor.range_resolution_m)  # fmt: skip
