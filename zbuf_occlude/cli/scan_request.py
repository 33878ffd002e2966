"""``scan``'s beam options and surface optics: the options of a :class:`~zbuf_occlude.sensors.request.ScanRequest`.

Every beam option sets one field of the request (:data:`BEAM_OPTIONS`), whatever scans the beam:
a spinning LiDAR, an airborne scanner, a ray table (a preset, a sensor file or ``--ray-table``).
:func:`scan_request` builds the request from ``scan``'s arguments with :func:`option_names`, the
field → option map its refusals name the options by: the rules are the library's
(:mod:`zbuf_occlude.sensors.request`), said once.
"""

from __future__ import annotations

import argparse

from zbuf_occlude.cli.options import count, real, shown
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.request import ScanRequest

__all__ = [
    "BEAM_OPTIONS", "MAX_TRANSMITTANCE_CLASSES", "SCAN_OPTION_FIELDS", "check_max_returns",
    "check_transmittance", "option_names", "returns_per_pulse", "scan_request",
]  # fmt: skip

#: Each beam option's ``args`` attribute and the request's field it sets
#: (:data:`~zbuf_occlude.sensors.request.BEAM_REQUEST_FIELDS`).  ``--footprint`` and ``--divergence``
#: are crop options too (:data:`~zbuf_occlude.cli.crops.CROP_OPTIONS`: ``farm --sensor-footprint``);
#: the others are ``scan``'s.
BEAM_OPTIONS = {
    "footprint": "footprint", "divergence": "divergence_deg", "max_returns": "max_returns", "return_mode": "return_mode",
    "range_resolution": "range_resolution_m", "power_noise": "power_noise", "echo_separation": "echo_separation_m",
    "min_echo_reflectance": "min_echo_reflectance", "echo_rule": "echo_rule",
}  # fmt: skip
#: ``scan``'s option of each field of a :class:`~zbuf_occlude.sensors.request.ScanRequest` (and of the beam).
SCAN_OPTION_FIELDS = {
    **{field: "--" + dest.replace("_", "-") for dest, field in BEAM_OPTIONS.items()}, "footprint_rays": "--footprint",
    "footprint_cast": "--footprint-cast", "backend": "--backend", "frame": "--frame", "reflectance_table": "--reflectance-table",
    "transmittance": "--transmittance", "reflectivity": "--reflectivity", "trajectory": "--trajectory", "samples": "--samples",
    "format": "--format", "gps_start_s": "--gps-start", "crs": "--crs", "origin_m": "--origin", "crop": "--crop",
}  # fmt: skip
#: The crop options among them, by field, whose name ``scan`` records as typed (``--footprint`` or ``--sensor-footprint``).
_CROP_FIELDS = {"footprint": "footprint", "footprint_rays": "footprint", "divergence_deg": "divergence_deg", "reflectivity": "reflectivity"}


def check_max_returns(text: str, option: str) -> int:
    """``--max-returns N``: a whole number from 1 to :data:`~zbuf_occlude.sensors.beam.echoes.MAX_RETURNS` (LAS's return numbers)."""
    from zbuf_occlude.sensors.beam.echoes import MAX_RETURNS

    n = count(None)(text, option)
    if n > MAX_RETURNS:
        raise InvalidInputError(f"{option} must be at most {MAX_RETURNS} (a LAS return number's range), got {shown(text)}")
    return n


def returns_per_pulse(text: str, option: str) -> int | str:
    """``--returns WHICH``: a whole number of returns per pulse, or one of
    :data:`~zbuf_occlude.sensors.request.KEPT_RETURNS` (:func:`~zbuf_occlude.sensors.request.check_kept_returns`)."""
    from zbuf_occlude.sensors.beam.echoes import MAX_RETURNS
    from zbuf_occlude.sensors.request import KEPT_RETURNS, check_kept_returns

    word = text.strip().lower()
    try:
        return check_kept_returns(word if word in KEPT_RETURNS else count(None)(text, option), option)
    except InvalidInputError:
        raise InvalidInputError(
            f"{option} must be a whole number of returns per pulse (1 to {MAX_RETURNS}) or one of {', '.join(KEPT_RETURNS)}, "
            f"got {shown(text)}"
        ) from None


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


def option_names(args: argparse.Namespace, sensor: str | None = None) -> dict[str, str]:
    """The field → option map of ``args``: :data:`SCAN_OPTION_FIELDS` with the crop options as typed, and the sensor as
    named (``sensor``, else ``args.sensor``)."""
    from zbuf_occlude.cli.crops import FLAGS

    typed = getattr(args, FLAGS, {})
    names = {**SCAN_OPTION_FIELDS, **{f: typed[c] for f, c in _CROP_FIELDS.items() if typed.get(c)}}
    if getattr(args, "trajectory", None) is not None:
        names["trajectory"] = f"--trajectory {args.trajectory}"
    return {**names, "sensor": str(args.sensor if sensor is None else sensor)}


def scan_request(args: argparse.Namespace, sensor, **fields) -> ScanRequest:
    """The :class:`~zbuf_occlude.sensors.request.ScanRequest` of ``sensor`` (a sensor, or its name) and ``args``' beam options
    and surface optics (``fields``: the request's other fields), naming the options by :func:`option_names`.

    Raises
    ------
    InvalidInputError
        What the request refuses, naming the options as typed.
    """
    beam = {field: getattr(args, dest, None) for dest, field in BEAM_OPTIONS.items()}
    return ScanRequest(sensor, beam=beam, footprint_cast=getattr(args, "footprint_cast", None), reflectance_table=bool(getattr(args, "reflectance_table", False)),
                       transmittance=getattr(args, "transmittance", None), reflectivity=getattr(args, "reflectivity", None),
                       names=option_names(args, sensor if isinstance(sensor, str) else None), **fields)  # fmt: skip
