"""``scan``'s beam options and surface optics: one path from the command line to any pulsed scanner's beam.

Every beam option sets one field of the sensor's :class:`~zbuf_occlude.sensors.beam.Beam`
(:data:`BEAM_OPTIONS`), through :func:`~zbuf_occlude.sensors.kinds.with_beam`, whatever scans the
beam: a spinning LiDAR, an airborne scanner, a ray table (a preset, a sensor file or
``--ray-table``).  A depth camera has no beam and refuses them, and ``--footprint-cast``, naming
the option.
:func:`with_return_physics` applies them and checks ``--reflectance-table`` and
``--transmittance`` against the sensor; :func:`surface_optics` turns the last two into the
keywords of :func:`~zbuf_occlude.sensors.scan.scan` and
:func:`~zbuf_occlude.sensors.scan.scan_airborne` for any scene: a scene file's, or the one a
scan of a mesh stands the mesh in (the ground, the object, then any occluders).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

from zbuf_occlude.cli.options import count, real, shown
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam import RETURN_MODES
from zbuf_occlude.sensors.echoes import ECHO_RULES
from zbuf_occlude.sensors.beam import footprint_changes

__all__ = [
    "BEAM_OPTIONS", "MAX_TRANSMITTANCE_CLASSES", "add_beam_arguments", "beam_changes", "check_max_returns", "check_transmittance",
    "scene_optics_of", "surface_optics", "with_return_physics",
]  # fmt: skip

#: Each beam option's ``args`` attribute and the :class:`~zbuf_occlude.sensors.beam.Beam` field it sets.
#: ``--footprint`` (a switch: :data:`~zbuf_occlude.sensors.footprint.FOOTPRINT_RAYS` sub-rays) and
#: ``--divergence`` are crop options too (:data:`~zbuf_occlude.cli.crops.CROP_OPTIONS`: ``farm
#: --sensor-footprint``); the others are ``scan``'s.
BEAM_OPTIONS = {
    "footprint": "footprint_rays", "divergence": "divergence_deg", "max_returns": "max_returns", "return_mode": "return_mode",
    "range_resolution": "range_resolution_m", "power_noise": "power_noise", "echo_separation": "echo_separation_m",
    "min_echo_reflectance": "min_echo_reflectance", "echo_rule": "echo_rule",
}  # fmt: skip
#: How each of them is written on the command line where the namespace does not say (crop options record the name typed).
_OPTION_FLAGS = {dest: "--" + dest.replace("_", "-") for dest in BEAM_OPTIONS}


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


def add_beam_arguments(group) -> None:
    """Add ``--return-mode`` and ``--echo-rule`` to ``group`` (a parser or an argument group of ``scan``'s; its other beam
    options sit beside it)."""
    group.add_argument(
        "--return-mode", choices=RETURN_MODES, default=None,
        help="which echoes of a pulse the receiver records: all (up to --max-returns, in range order), strongest or last "
        "(one, as Velodyne's single-return modes), dual (the last and the strongest, Velodyne's dual mode); all but 'all' "
        "need --range-resolution (default: the sensor's, 'all' for presets)",
    )  # fmt: skip
    group.add_argument(
        "--echo-rule", choices=ECHO_RULES, default=None,
        help="with resolved echoes (--max-returns above 1 or --return-mode): how a pulse's sub-ray hits merge into echoes: "
        "chain (a new echo at a gap of --range-resolution after the previous hit) or waveform (one echo per peak of the pulse's "
        "summed waveform, split where it dips: returns per pulse that do not drift with the sub-ray count) "
        "(default: the sensor's, chain for presets)",
    )  # fmt: skip


def _flag(args: argparse.Namespace, dest: str) -> str:
    """The option of ``dest`` as the user typed it (``--footprint`` or ``--sensor-footprint``)."""
    from zbuf_occlude.cli.crops import FLAGS

    crop_names = {"footprint": "footprint", "divergence": "divergence_deg"}
    typed = getattr(args, FLAGS, {}).get(crop_names.get(dest, ""))
    return typed or _OPTION_FLAGS[dest]


def _given(args: argparse.Namespace) -> dict[str, object]:
    """The beam options given (not None and not False: every option's default is None, ``--footprint``'s False), by dest."""
    return {dest: v for dest in BEAM_OPTIONS if (v := getattr(args, dest, None)) is not None and v is not False}


def beam_changes(sensor, args: argparse.Namespace) -> dict[str, object]:
    """The :class:`~zbuf_occlude.sensors.beam.Beam` fields the beam options of ``args`` change on ``sensor``'s beam.

    ``--footprint`` gives :data:`~zbuf_occlude.sensors.footprint.FOOTPRINT_RAYS` sub-rays in the
    beam's divergence cone (``--divergence DEG``, else the sensor's) where the beam fires fewer
    (:func:`~zbuf_occlude.sensors.beam.footprint_changes`); without it the sensor's own
    ``footprint_rays`` stay (a sensor file's K above 1 is a footprint for ``--echo-separation``).
    ``--return-mode strongest`` or ``last`` record one return per pulse, ``dual`` two, so they set
    ``max_returns`` where ``--max-returns`` is not given.  Resolved echoes (``max_returns`` above 1
    or a return mode other than ``all``) need a range resolution, ``--range-resolution``'s or the
    sensor's; the sensor's echo separation then gives way to it, and one return per pulse drops the
    sensor's range resolution.

    Raises
    ------
    InvalidInputError
        Naming the option as typed and its value: any of them, or ``scan --footprint-cast``, for a
        sensor without a beam (a depth camera); ``--footprint`` for a beam without a divergence (naming ``--divergence``);
        ``--echo-separation`` without a footprint or with resolved echoes; ``--range-resolution``
        with one return per pulse; resolved echoes without a range resolution; ``--max-returns``
        that contradicts ``--return-mode``; ``--echo-rule waveform`` with one return per pulse.
    """
    from zbuf_occlude.sensors.kinds import kind_of

    given = _given(args)
    cast = getattr(args, "footprint_cast", None)  # scan's --footprint-cast: None unless given
    kind = kind_of(sensor)
    if not kind.pulsed and (given or cast is not None):
        names = ", ".join([*(_flag(args, dest) for dest in given), *(["--footprint-cast"] if cast is not None else [])])
        raise InvalidInputError(f"{names}: {args.sensor} is a {kind.title}, which has no beam to change (a pulsed LiDAR has one)")
    if not given:
        return {}
    beam = sensor.beam
    changes: dict[str, object] = footprint_changes(
        beam, footprint="footprint" in given, divergence_deg=given.get("divergence"), names=(_flag(args, "footprint"), _flag(args, "divergence")),
        sensor=str(args.sensor),
    )  # fmt: skip
    mode = given.get("return_mode", beam.return_mode)
    wanted = {"strongest": 1, "last": 1, "dual": 2}.get(str(mode))
    if "return_mode" in given:
        changes["return_mode"] = mode
        if "max_returns" in given and wanted is not None and given["max_returns"] != wanted:
            raise InvalidInputError(f"--return-mode {mode} records {wanted} return{'s' * (wanted > 1)} per pulse; "
                                    f"--max-returns {given['max_returns']} contradicts it")  # fmt: skip
        if wanted is not None:
            changes["max_returns"] = wanted
        elif "max_returns" not in given and beam.return_mode != "all":
            changes["max_returns"] = 1  # 'all' after a Velodyne mode: one return unless --max-returns says more
    if "max_returns" in given:
        changes["max_returns"] = int(given["max_returns"])
    if "echo_rule" in given:
        changes["echo_rule"] = given["echo_rule"]
    for dest in ("range_resolution", "power_noise", "echo_separation", "min_echo_reflectance"):
        if dest in given:
            changes[BEAM_OPTIONS[dest]] = float(given[dest])
    _check_echoes(beam, changes, given, args)
    return changes


def _check_echoes(beam, changes: dict, given: dict, args: argparse.Namespace) -> None:
    """The rules that tie the footprint, the returns and the range resolution together, said in the options' words;
    ``changes`` gains the drops that follow (the sensor's echo separation or range resolution)."""
    rays = changes.get("footprint_rays", beam.footprint_rays)
    returns = changes.get("max_returns", beam.max_returns)
    mode = changes.get("return_mode", beam.return_mode)
    resolves = returns > 1 or mode != "all"
    resolution = changes.get("range_resolution_m", beam.range_resolution_m)
    what = f"--max-returns {returns}" if mode == "all" else f"--return-mode {mode}"
    separation = given.get("echo_separation")
    if separation and rays == 1:
        raise InvalidInputError(
            f"--echo-separation {separation:g} needs {_flag(args, 'footprint')} (mixed pixels come from a wide footprint)"
        )
    if separation and resolves:
        raise InvalidInputError(
            f"--echo-separation {separation:g} merges echoes into one return; with {what} give --range-resolution instead"
        )
    if resolves and not resolution > 0:
        raise InvalidInputError(f"{what} needs --range-resolution M (metres: the least range between two returns)")
    if given.get("echo_rule", "chain") != "chain" and not resolves:
        raise InvalidInputError(f"--echo-rule {given['echo_rule']} tells resolved echoes apart: it needs --max-returns above 1 "
                                "or --return-mode strongest, last or dual")  # fmt: skip
    if "range_resolution" in given and not resolves:
        raise InvalidInputError(f"--range-resolution {given['range_resolution']:g} separates several returns per pulse: it needs "
                                "--max-returns above 1 or --return-mode strongest, last or dual")  # fmt: skip
    if resolves and beam.echo_separation_m > 0:
        changes["echo_separation_m"] = 0.0  # resolved echoes are kept apart by the range resolution, not merged
    if not resolves and beam.range_resolution_m > 0:
        changes["range_resolution_m"] = 0.0  # one return per pulse: nothing to resolve


def with_return_physics(sensor, args: argparse.Namespace):
    """``sensor`` with its beam changed by the beam options (:func:`beam_changes`, applied by
    :func:`~zbuf_occlude.sensors.kinds.with_beam`), and ``--reflectance-table`` and ``--transmittance``
    checked against it (:func:`surface_optics` applies them, to a scene file or a mesh's scene, for
    any pulsed scanner).

    Raises
    ------
    InvalidInputError
        As :func:`beam_changes`; a change the beam refuses (naming the options given); and
        ``--reflectance-table`` or ``--transmittance`` for a sensor without a beam, ``--reflectance-table``
        with ``--reflectivity`` (one ρ for the object, or its material's), ``--transmittance`` above 0
        without several returns per pulse or with ``--backend zbuffer`` (one face per pixel), each naming the value.
    """
    from zbuf_occlude.sensors.kinds import kind_of, with_beam

    changes = beam_changes(sensor, args)
    out = sensor
    if changes:
        try:
            out = with_beam(sensor, **changes)
        except InvalidInputError as exc:
            names = ", ".join(_flag(args, dest) for dest in _given(args))
            raise InvalidInputError(f"{names}: {exc}") from None
    table, tau = getattr(args, "reflectance_table", False), getattr(args, "transmittance", None)
    given = " and ".join(f for f, v in (("--reflectance-table", table), (f"--transmittance {_shown_tau(tau)}", tau is not None)) if v)
    if not given:
        return out
    kind = kind_of(out)
    if not kind.pulsed:
        raise InvalidInputError(f"{given} model the surfaces a pulsed LiDAR's beam meets; {args.sensor} is a {kind.title}")
    if table and getattr(args, "reflectivity", None) is not None:
        from zbuf_occlude.cli.crops import FLAGS

        flag = getattr(args, FLAGS, {}).get("reflectivity", "--reflectivity")
        raise InvalidInputError(f"--reflectance-table gives each surface its material's reflectivity; {flag} gives the object one: "
                                "give one of them")  # fmt: skip
    opaque = tau is None or (not isinstance(tau, (str, dict)) and tau == 0) or (isinstance(tau, dict) and not any(tau.values()))
    if not opaque and not out.beam.resolves_echoes:
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
    """The ``reflectivity`` and ``transmittance`` keywords of :func:`~zbuf_occlude.sensors.scan.scan` and
    :func:`~zbuf_occlude.sensors.scan.scan_airborne` from ``--reflectance-table`` and ``--transmittance``
    (none given: no keyword, the scan as without them).

    ``scene`` is a :class:`~zbuf_occlude.sensors.scene.ScanScene`: a scene file's, or the one a
    scan of a mesh stands the mesh in (:func:`~zbuf_occlude.sensors.crops.object_crop`: the ground,
    the object, then any occluders, which reflect and transmit as the object does).  One
    ``--transmittance`` number applies to every object, not the ground; ``CLASS=VALUE`` pairs to
    the objects of those classes (a mesh's class: its file name without suffix).

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


def scene_optics_of(args: argparse.Namespace) -> Callable[[object], dict] | None:
    """:func:`surface_optics` of ``args`` as a function of the scene, for a scan that builds its scene per
    sample (:func:`~zbuf_occlude.sensors.crops.object_crops`' ``optics``); None where neither option is given."""
    if not getattr(args, "reflectance_table", False) and getattr(args, "transmittance", None) is None:
        return None
    return lambda scene: surface_optics(args, scene)
