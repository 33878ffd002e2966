"""The LiDAR crop options of ``scan`` and ``farm --sensor``: one table, one path to the library's settings.

Both commands place an object on the ground in front of a simulated sensor and draw the
placement per scan (:class:`~zbuf_occlude.sensors.placement.CropDistributions`).  The options
that set it are the rows of :data:`CROP_OPTIONS`: :func:`add_crop_arguments` adds them to a
command's parser, :func:`crop_settings` turns what was parsed into the library's settings,
which check every value themselves (:class:`~zbuf_occlude.sensors.placement.CropDistributions`,
and the width a mesh is fitted to where it is used: :class:`~zbuf_occlude.sensors.placement.ObjectPlacement`,
:class:`~zbuf_occlude.farm.sensor_params.SensorCropParams`); a message names the option as it was typed.

Each option has two names that both commands take: ``--distance`` and ``--sensor-distance``,
``--hidden-below`` and ``--sensor-hidden-below``, ...  ``scan`` lists the short name first (it
has no other sensor), ``farm`` the ``--sensor-`` one (beside its z-buffer options).
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from zbuf_occlude.cli.options import Check, count, interval, parse_interval, real, shown
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.footprint import FOOTPRINT_RAYS, MAX_DIVERGENCE_DEG
from zbuf_occlude.sensors.placement import MAX_REDRAWS, CropDistributions

__all__ = [
    "BEAM_FIELDS", "CropOption", "CropSettings", "CROP_OPTIONS", "FLAGS", "add_crop_arguments", "check_divergence", "crop_settings",
    "given_crop_options",
]  # fmt: skip

#: The namespace attribute that holds, per setting, the option that names it in messages (the one typed).
FLAGS = "crop_flags"
#: The crop options that change the sensor's beam, not the placement (:func:`zbuf_occlude.cli.return_physics.beam_changes`).
BEAM_FIELDS = ("footprint", "divergence_deg")


def check_divergence(text: str, option: str) -> float:
    """``--divergence DEG``: a full angle in degrees, > 0 and at most :data:`~zbuf_occlude.sensors.beam.footprint.MAX_DIVERGENCE_DEG`."""
    value = real(0.0, above=True, unit="degrees")(text, option)
    if value > MAX_DIVERGENCE_DEG:
        raise InvalidInputError(f"{option} must be a full angle of at most {MAX_DIVERGENCE_DEG:g} degrees, got {shown(text)}")
    return value


@dataclass(frozen=True)
class CropOption:
    """One crop option: the setting it gives, its names, its check and its help.

    ``field`` is a :class:`CropDistributions` field, or a beam field (:data:`BEAM_FIELDS`: the
    ``footprint`` switch and ``divergence_deg``) or ``across_sight_width_m`` (the width a mesh is fitted to); ``name`` gives
    ``--NAME`` and ``--sensor-NAME``; ``check`` parses the text (None: a switch); ``unset`` says what
    holds when it is not given (where no default value does); ``in_crop``
    says what the option does to a crop, for options that mean nothing without one (``scan``
    without ``--crop`` refuses them).
    """

    field: str
    name: str
    metavar: str | None
    check: Check | None
    help: str
    unset: str = ""
    in_crop: str = ""

    @property
    def dest(self) -> str:
        return self.name.replace("-", "_")

    def flags(self, *, prefixed: bool) -> tuple[str, str]:
        """``("--sensor-NAME", "--NAME")`` with ``prefixed``, else the other way round."""
        short, long = f"--{self.name}", f"--sensor-{self.name}"
        return (long, short) if prefixed else (short, long)


#: Every crop option of ``scan`` and ``farm --sensor``, in the order ``--help`` lists them.
CROP_OPTIONS = (
    CropOption("distance_m", "distance", "LO:HI", interval, "horizontal distance from the sensor to the object's footprint centre, metres"),
    CropOption("height_m", "height", "LO:HI", interval, "sensor height above the ground, metres"),
    CropOption("size_m", "size", "LO:HI", interval, "the object's largest dimension, metres"),
    CropOption(
        "reflectivity", "reflectivity", "LO:HI", interval,
        "return physics: the object's Lambertian reflectivity; returns must clear the sensor's radiometric threshold "
        "rho*cos(incidence)*footprint/R^2", unset="every hit returns",
    ),
    CropOption("footprint", "footprint", None, None, f"return physics: {FOOTPRINT_RAYS} rays per firing inside the beam divergence cone, "
               "the strongest echo (with --max-returns above 1, scan: several returns); any pulsed sensor whose beam has a divergence"),
    CropOption("divergence_deg", "divergence", "DEG", check_divergence,
               "return physics: the beam's full-angle divergence, degrees in (0, 90], for --footprint (a sensor whose data "
               "sheet gives none, hdl64e)", unset="the sensor's"),
    CropOption(
        "ground_margin_m", "ground-margin", "M", real(0.0, unit="metres"),
        "also keep the ground returns under the object, inside its footprint grown by M metres, as a box segmentation "
        "of a street scan leaves them", unset="the object's returns only",
        in_crop="chooses the ground kept in a crop",
    ),
    CropOption(
        "hidden_below_m", "hidden-below", "LO:HI", interval,
        "hide the object's returns lower than this height above the ground, metres (a bottom hidden by parked cars or "
        "kerbs, or removed with the ground; fit-sensor fits it per class)", unset="nothing hidden",
        in_crop="hides the bottom of the object in a crop",
    ),
    CropOption(
        "across_sight_width_m", "across-sight-width", "LO:HI", interval,
        "stretch the object horizontally so that its crops are, at the median, this wide across the line of sight, "
        "metres (posts as thick as real trunks; a spinning LiDAR; fit-sensor fits it per class)", unset="the meshes' proportions",
        in_crop="makes the object's crops as wide as real scans",
    ),
    CropOption(
        "min_returns", "min-returns", "N", count("MAX_POINTS"),
        f"the fewest returns of the object a scan holds: a placement that gives fewer is drawn again, up to {MAX_REDRAWS} "
        "times, and a sample still short is left out and named (as experiment sim2real's --min-returns; an airborne "
        "scanner sees a few points of a thin object)", unset="every placement as drawn",
    ),
)  # fmt: skip


class _CropAction(argparse.Action):
    """Stores the checked value (True for a switch) and the option as typed, under :data:`FLAGS`."""

    def __init__(self, option_strings: list[str], dest: str, *, check: Check | None, field: str, **kwargs: Any) -> None:
        self.check, self.field = check, field
        super().__init__(option_strings, dest, nargs=0 if check is None else None, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        option = option_string or self.option_strings[0]
        setattr(namespace, self.dest, True if self.check is None else self.check(values, option))
        setattr(namespace, FLAGS, {**getattr(namespace, FLAGS, {}), self.field: option})


def _interval_text(value: tuple[float, float]) -> str:
    return f"{value[0]:g}" if value[0] == value[1] else f"{value[0]:g}:{value[1]:g}"


def add_crop_arguments(
    group: Any, base: CropDistributions, *, prefixed: bool, notes: Mapping[str, str] | None = None, names: Mapping[str, str] | None = None
) -> None:
    """Add every option of :data:`CROP_OPTIONS` to ``group`` (a parser or an argument group).

    ``base`` holds the command's defaults, shown in the help of the options that have one;
    ``prefixed`` lists ``--sensor-NAME`` first; ``notes`` adds a command's words to an option's
    help (by field); ``names`` gives the command's own options of the other
    :class:`CropDistributions` fields (``{"yaw_deg": "--yaw"}``), for messages.  Each option's
    value is None (False for a switch) when not given.
    """
    notes = notes or {}
    for o in CROP_OPTIONS:
        value = getattr(base, o.field, None)
        shown = _interval_text(value) if isinstance(value, tuple) else o.unset
        default = f" (default: {shown})" if shown else ""
        note = f"; {notes[o.field]}" if o.field in notes else ""
        group.add_argument(*o.flags(prefixed=prefixed), dest=o.dest, metavar=o.metavar, action=_CropAction, check=o.check,
                           field=o.field, default=False if o.check is None else None, help=f"{o.help}{note}{default}")  # fmt: skip
    flags = {**(names or {}), **{o.field: o.flags(prefixed=prefixed)[0] for o in CROP_OPTIONS}}
    group.set_defaults(**{FLAGS: flags})


def given_crop_options(args: argparse.Namespace, *, in_crop: bool = False) -> list[tuple[str, CropOption]]:
    """``(option as typed, its row)`` of every crop option given (``in_crop``: those that need a crop only)."""
    flags = getattr(args, FLAGS)
    return [(flags[o.field], o) for o in CROP_OPTIONS if getattr(args, o.dest) not in (None, False) and (o.in_crop or not in_crop)]


@dataclass(frozen=True)
class CropSettings:
    """What the crop options give: the placement's distributions, the beam's footprint and divergence, and the width fit.

    Attributes
    ----------
    distributions : CropDistributions
        Checked, its messages naming the options (:data:`FLAGS`).
    footprint : bool
        :data:`~zbuf_occlude.sensors.beam.footprint.FOOTPRINT_RAYS` rays per firing in the beam's divergence cone.
    divergence_deg : float or None
        The beam's full-angle divergence, degrees; None: the sensor's.
    across_sight_width_m : (lo, hi) or None
        Metres, as parsed: the library's value that takes it checks it
        (:func:`~zbuf_occlude.sensors.placement.check_across_sight_width`).
    names : dict of str to str
        The option that names each :class:`CropDistributions` field.
    """

    distributions: CropDistributions
    footprint: bool
    divergence_deg: float | None
    across_sight_width_m: tuple[float, float] | None
    names: Mapping[str, str]

    def with_fields(self, **fields: Any) -> CropSettings:
        """These settings with other :class:`CropDistributions` ``fields``, checked again (messages name the options)."""
        return replace(self, distributions=replace(self.distributions, **fields, option_names=self.names))


def crop_settings(args: argparse.Namespace, base: CropDistributions, **fields: Any) -> CropSettings:
    """The crop options of ``args`` over ``base``, with a command's own ``fields`` of :class:`CropDistributions`.

    Raises
    ------
    InvalidInputError
        A value the library refuses, naming the option as typed.
    """
    names = dict(getattr(args, FLAGS))
    for o in CROP_OPTIONS:
        text = getattr(args, o.dest)
        if o.field in (*BEAM_FIELDS, "across_sight_width_m") or text is None:
            continue
        fields[o.field] = parse_interval(text, names[o.field]) if o.check is interval else text
    distributions = replace(base, **fields, option_names=names)
    width = args.across_sight_width
    across = None if width is None else parse_interval(width, names["across_sight_width_m"])
    return CropSettings(distributions, bool(args.footprint), args.divergence, across, names)
