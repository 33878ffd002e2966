"""A scan request: what one scan command asks of a sensor, checked once, in the library's words.

``scan``, ``farm --sensor`` and ``experiment sim2real`` ask for the same things: a sensor, changes to
its beam, how its footprint is cast, which ray caster, which frame, which surface optics, which
platform.  A :class:`ScanRequest` holds them and checks every rule that ties them together here,
once.  Its refusals name each field through the caller's ``names`` (a field → option map: ``scan``
maps ``max_returns`` to ``--max-returns``), so that a command never restates a rule and the library
never spells an option; a field the map leaves out is named as the field.

The rules themselves live beside what they govern and are only called from here: the beam's returns
(:func:`~zbuf_occlude.sensors.beam.fields.check_returns`), its footprint (:func:`~zbuf_occlude.sensors.beam.fields.footprint_changes`)
and the adaptive cast (:func:`~zbuf_occlude.sensors.beam.adaptive_cast.check_footprint_cast`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field

from zbuf_occlude.defaults import MAX_SAMPLES
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.file_errors import value_kind
from zbuf_occlude.sensors.checks import count, namer
from zbuf_occlude.sensors.raycast.embree import BACKENDS
from zbuf_occlude.sensors.beam.fields import MODE_RETURNS, RETURN_FIELDS, check_returns, footprint_changes
from zbuf_occlude.sensors.beam.echo_energy import check_transmittance_cast
from zbuf_occlude.sensors.kinds import SensorKind, capabilities, sensor_from_name, with_beam
from zbuf_occlude.sensors.scan_data import FRAMES, check_las_frame, las_origin

__all__ = ["BEAM_REQUEST_FIELDS", "KEPT_RETURNS", "LAS_FORMATS", "RETURNS_RANGE_RESOLUTION_M", "SCAN_FORMATS", "TRAINING_RETURNS",
           "ScanRequest", "beam_changes", "check_kept_returns", "kept_returns"]  # fmt: skip

#: The beam changes a request may ask for: :class:`~zbuf_occlude.sensors.beam.fields.Beam` fields, and
#: ``footprint`` (a switch: :data:`~zbuf_occlude.sensors.beam.footprint.FOOTPRINT_RAYS` sub-rays in the beam's cone).
BEAM_REQUEST_FIELDS = (
    "footprint", "divergence_deg", "max_returns", "return_mode", "range_resolution_m", "power_noise", "echo_separation_m",
    "min_echo_reflectance", "echo_rule",
)  # fmt: skip
#: The formats whose points a LAS file classifies by height.
LAS_FORMATS = ("las", "laz")
#: The files a scan writes (:func:`~zbuf_occlude.sensors.scan_files.save_scan`).
SCAN_FORMATS = ("npz", "ply", *LAS_FORMATS)


def beam_changes(beam, given: Mapping[str, object], *, sensor: str, names: Mapping[str, str | None] | None = None) -> dict:
    """The :class:`~zbuf_occlude.sensors.beam.fields.Beam` fields that the beam changes ``given`` (fields of :data:`BEAM_REQUEST_FIELDS`) make.

    ``footprint`` gives :data:`~zbuf_occlude.sensors.beam.footprint.FOOTPRINT_RAYS` sub-rays in the
    beam's divergence cone (``divergence_deg``, else the beam's) where the beam fires fewer
    (:func:`~zbuf_occlude.sensors.beam.fields.footprint_changes`).  ``return_mode`` "strongest" or "last"
    records one return per pulse, "dual" two, so it sets ``max_returns`` where that is not given
    ("all" after a Velodyne mode: one return unless ``max_returns`` says more).  Resolved echoes
    keep echoes apart by the range resolution, so the beam's own echo separation gives way; one
    return per pulse drops the beam's own range resolution.  What is then asked for is checked
    by :func:`~zbuf_occlude.sensors.beam.fields.check_returns`, naming the fields as ``names`` maps them.

    Raises
    ------
    InvalidInputError
        What :func:`~zbuf_occlude.sensors.beam.fields.footprint_changes` and
        :func:`~zbuf_occlude.sensors.beam.fields.check_returns` refuse.
    """
    n = namer(names)
    changes: dict[str, object] = footprint_changes(
        beam, footprint=bool(given.get("footprint")), divergence_deg=given.get("divergence_deg"),
        names=(n("footprint"), n("divergence_deg")), sensor=sensor,
    )  # fmt: skip
    if "return_mode" in given:
        changes["return_mode"] = mode = given["return_mode"]
        wanted = MODE_RETURNS.get(str(mode))
        if wanted is not None and "max_returns" not in given:
            changes["max_returns"] = wanted
        elif "max_returns" not in given and beam.return_mode != "all":
            changes["max_returns"] = 1
    for name in ("max_returns", "echo_rule", "range_resolution_m", "power_noise", "echo_separation_m", "min_echo_reflectance"):
        if name in given:
            changes[name] = given[name]
    values = {name: changes.get(name, getattr(beam, name)) for name in RETURN_FIELDS}
    resolves = values["max_returns"] > 1 or values["return_mode"] != "all"
    if resolves and "echo_separation_m" not in given and beam.echo_separation_m > 0:
        changes["echo_separation_m"] = values["echo_separation_m"] = 0.0  # resolved echoes are kept apart, not merged
    if not resolves and "range_resolution_m" not in given and beam.range_resolution_m > 0:
        changes["range_resolution_m"] = values["range_resolution_m"] = 0.0  # one return per pulse: nothing to resolve
    check_returns(values, {**(names or {}), "footprint_rays": n("footprint")})
    return changes


#: What a training cloud keeps of each pulse's returns, besides a count (:func:`kept_returns`): ``"strongest"`` (one return,
#: the count 1), ``"first"`` or ``"last"`` (one, the receiver's first or last echo), ``"all"`` (what the device records).
KEPT_RETURNS = ("strongest", "first", "last", "all")
#: What ``farm --sensor`` and ``experiment sim2real`` keep unless asked otherwise: one return per pulse, the strongest.  Measured
#: on the real scans the project has (LiDARNet's HDL-32E crops, whose device records one return, the strongest): no training set
#: of several returns per pulse scored better on them, and two models leaned worse (the results page "sim2real", "With several
#: returns per pulse").  ``scan`` writes what the device records.
TRAINING_RETURNS = 1
#: Least range between two returns of one pulse, metres, where returns are resolved for a sensor whose beam gives none: half the
#: pulse length ``c·τ/2`` of a 5 ns pulse (an ASSUMPTION: the Velodyne HDL-32E data sheet 97-0038 and manual 63-9113 give no
#: pulse length; the value of the sensors guide).
RETURNS_RANGE_RESOLUTION_M = 0.75


#: The fields whose option :func:`kept_returns` may name in a refusal: what to keep, and the divergence a footprint needs.
_KEPT_RETURNS_FIELDS = ("returns", "divergence_deg")


def check_kept_returns(value: object, name: str = "returns") -> int | str:
    """``value`` as :func:`kept_returns` takes it: a whole number 1..15 (LAS's return numbers) or one of :data:`KEPT_RETURNS`,
    ``"strongest"`` as 1 (one value for one rule: settings read back compare equal).

    Raises
    ------
    InvalidInputError
        Anything else, naming ``name`` and the value (a caller's option, never a user's file).
    """
    from zbuf_occlude.sensors.beam.echoes import MAX_RETURNS

    if isinstance(value, str) and value in KEPT_RETURNS:
        return 1 if value == "strongest" else value
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_RETURNS:  # its kind, not its value: a card's
        raise InvalidInputError(f"{name} must be a whole number from 1 to {MAX_RETURNS} (returns per pulse) or one of "
                                f"{', '.join(KEPT_RETURNS)}, got {value_kind(value)}")  # fmt: skip
    return value


def kept_returns(sensor, returns: int | str = TRAINING_RETURNS, *, names: Mapping[str, str | None] | None = None):
    """``sensor`` whose beam records what a training cloud keeps of each pulse: the one rule of ``farm --sensor`` and ``experiment sim2real``.

    ``returns``:

    ``1`` or ``"strongest"``
        One return per pulse: ``sensor`` itself where its beam records one (a single-return mode included), else its beam
        with ``max_returns`` 1, the footprint's strongest surface (``strongest_echo``).
    ``"first"``, ``"last"``
        One return per pulse, the receiver's first (nearest) or last echo: ``sensor`` itself where its beam fires one ray
        and records one return (its one return is both), else its beam with that ``return_mode`` and its range resolution
        (or :data:`RETURNS_RANGE_RESOLUTION_M`).
    ``"all"``
        ``sensor`` itself: every return its device records.
    N above 1
        The multi-return model: up to N returns per pulse in range order, each pulse's footprint cast as the beam's own
        sub-rays (or :data:`~zbuf_occlude.sensors.beam.footprint.FOOTPRINT_RAYS` over its divergence), its echoes resolved
        by its range resolution (or :data:`RETURNS_RANGE_RESOLUTION_M`).

    Every change is made by :func:`beam_changes`, the rule of ``scan``'s beam options, naming the fields as ``names`` maps
    them (``names["returns"]``: the caller's option for ``returns``).  :class:`ScanRequest` calls it for its ``returns``.

    Raises
    ------
    InvalidInputError
        ``returns`` not one of those (:func:`check_kept_returns`); N above 1 for a beam without a divergence (no footprint
        to sample); a sensor without a beam (a depth camera).
    """
    names = {
        "footprint": "a footprint",
        "footprint_rays": "a footprint",
        "divergence_deg": "a sensor file's divergence_deg",
        **(names or {}),
    }
    n = namer(names)
    returns = check_kept_returns(returns, n("returns"))
    beam = sensor.beam
    if returns == "all":
        return sensor
    if returns == 1:
        given = {"max_returns": 1, "return_mode": "all"} if beam.max_returns > 1 else {}
    elif returns in ("first", "last"):
        if beam.footprint_rays == 1 and not beam.resolves_echoes:
            return sensor
        resolution = beam.range_resolution_m if beam.range_resolution_m > 0 else RETURNS_RANGE_RESOLUTION_M
        given = {"return_mode": returns, "range_resolution_m": resolution, "max_returns": 1}
    else:
        resolution = beam.range_resolution_m if beam.range_resolution_m > 0 else RETURNS_RANGE_RESOLUTION_M
        given = {"max_returns": returns, "return_mode": "all", "range_resolution_m": resolution, "footprint": beam.footprint_rays == 1,
                 "echo_separation_m": 0.0}  # fmt: skip
    if not given:
        return sensor
    try:
        changes = beam_changes(beam, given, sensor=str(getattr(sensor, "name", "the sensor")), names=names)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{n('returns')} {returns}: {exc}") from None
    return with_beam(sensor, **changes) if changes else sensor


@dataclass(frozen=True)
class ScanRequest:
    """A scan's sensor, beam changes, cast, frame, surface optics and platform, checked together on construction.

    Parameters
    ----------
    sensor : Lidar, RayTable, AirborneScanner, DepthCamera, str or PathLike
        The sensor, or its name: a preset, a sensor file or a ray table file, read by
        :func:`~zbuf_occlude.sensors.kinds.sensor_from_name`.
    beam : mapping of str to value
        Beam changes by field (:data:`BEAM_REQUEST_FIELDS`), applied by :func:`beam_changes` and
        :func:`~zbuf_occlude.sensors.kinds.with_beam`.
    footprint_cast : {"auto", "exact", "adaptive"} or None
        How a footprint whose echoes are resolved is cast
        (:func:`~zbuf_occlude.sensors.beam.adaptive_cast.check_footprint_cast`); None: not asked ("auto").
    backend : {"embree", "zbuffer"}
    frame : {"sensor", "world"} or None
        The frame of the points; None: "sensor", or "world" for a scanner that flies (it has no one sensor frame).
    reflectance_table : bool
        The surfaces reflect as their materials' table gives at the beam's wavelength.
    transmittance : "table", float, mapping of class to float, or None
        The share of each sub-ray that goes on through an object (:mod:`~zbuf_occlude.sensors.scene.materials`).
    reflectivity : object
        The object's own reflectivity where the caller gives one (checked against ``reflectance_table``).
    trajectory : Trajectory, str, PathLike or None
        A platform moving during the sweeps (:mod:`~zbuf_occlude.sensors.platform`), or its CSV file
        (:func:`~zbuf_occlude.sensors.platform.load_trajectory`).
    samples : int
        Sweeps scanned one after another (a trajectory must last them).
    formats : tuple of str
        The output's file formats (``"las"`` and ``"laz"``: :data:`LAS_FORMATS`).
    returns : int, str or None
        What the scanner keeps of each pulse's returns (:func:`kept_returns`: 1 or "strongest", "first", "last", "all", N),
        applied before the beam changes; None: what the device records.  Held as None where the sensor records that
        already (a spinning preset's one return), so a request that changes nothing equals one that asks nothing.
    las : mapping of str to value
        The LAS/LAZ files' keywords of :meth:`~zbuf_occlude.sensors.scan_data.Scan.to_las_bytes` (``crs``, ``class_map``,
        ``gps_start_s``, ``origin_m``: held checked, as 3 numbers).
    names : mapping of str to str
        The caller's name of each field, for messages (module docstring); ``"sensor"`` how it named the sensor.

    Attributes
    ----------
    scanner
        ``sensor`` with the beam changes applied.
    kind : SensorKind
        What the scanner can do (:func:`~zbuf_occlude.sensors.kinds.capabilities`), asked once.
    cast : str
        ``footprint_cast`` checked ("auto" where not asked).

    Raises
    ------
    InvalidInputError
        Naming the fields as ``names`` maps them: what :func:`~zbuf_occlude.sensors.kinds.sensor_from_name` and
        :func:`~zbuf_occlude.sensors.platform.load_trajectory` refuse of a sensor or a trajectory given by name; an unknown backend or format, sweeps that are not a whole
        number from 1 to :data:`~zbuf_occlude.defaults.MAX_SAMPLES`; beam changes, a footprint cast, returns or surface optics
        for a sensor without a beam (a depth camera); what :func:`kept_returns`, :func:`beam_changes` and the beam refuse; the
        reflectance table with the object's own reflectivity; a transmittance above 0 without
        resolved echoes or with the z-buffer; returns asked of a beam of one ray onto opaque
        surfaces (each pulse has one return: nothing to resolve); the sensor frame for a scanner that
        flies; a CRS for LAS files in the sensor frame; a trajectory for a scanner without a platform of its own, with the
        z-buffer (one point of view), shorter than the sweeps, or in the sensor frame with a LAS format; a footprint cast that does not apply.
    """

    sensor: object
    beam: Mapping[str, object] = field(default_factory=dict)
    footprint_cast: str | None = None
    backend: str = "embree"
    frame: str | None = None
    reflectance_table: bool = False
    transmittance: object = None
    reflectivity: object = None
    trajectory: object = None
    samples: int = 1
    formats: tuple[str, ...] = ("npz",)
    returns: int | str | None = None
    las: Mapping[str, object] = field(default_factory=dict)
    names: Mapping[str, str | None] = field(default_factory=dict)
    scanner: object = field(init=False, repr=False, compare=False)
    kind: SensorKind = field(init=False, repr=False, compare=False)
    cast: str = field(init=False, compare=False)

    def name_of(self, name: str) -> str:
        """How the caller calls the field ``name`` in a message: its option in :attr:`names` (``--max-returns``), else
        ``name`` (:func:`~zbuf_occlude.sensors.checks.namer`)."""
        return namer(self.names)(name)

    def __post_init__(self) -> None:
        n = self.name_of
        if isinstance(self.sensor, (str, os.PathLike)):
            object.__setattr__(self, "sensor", sensor_from_name(self.sensor))
        if isinstance(self.trajectory, (str, os.PathLike)):
            from zbuf_occlude.sensors.platform import load_trajectory

            object.__setattr__(self, "trajectory", load_trajectory(self.trajectory))
        label = self.names.get("sensor") or getattr(self.sensor, "name", "the sensor")
        kind = capabilities(self.sensor)
        object.__setattr__(self, "kind", kind)
        given = {f: v for f, v in self.beam.items() if v is not None and v is not False}
        unknown = sorted(set(given) - set(BEAM_REQUEST_FIELDS))
        if unknown:
            raise InvalidInputError(
                f"a scan request changes no beam field {unknown[0]!r:.40}; the fields: {', '.join(BEAM_REQUEST_FIELDS)}"
            )
        if not kind.pulsed and (given or self.footprint_cast is not None or self.returns is not None):
            asked = [n(f) for f in (*given, *(("footprint_cast",) if self.footprint_cast is not None else ()),
                                    *(("returns",) if self.returns is not None else ()))]  # fmt: skip
            raise InvalidInputError(f"{', '.join(asked)}: {label} is a {kind.title}, which has no beam to change (a pulsed LiDAR has one)")
        self._check_values()
        scanner = self.sensor
        if self.returns is not None:  # what a pulse's record keeps, then the beam changes on it
            returns = check_kept_returns(self.returns, n("returns"))
            # the caller's words for what kept_returns can ask of it (the footprint it casts is its own: "a footprint")
            scanner = kept_returns(self.sensor, returns, names={f: self.names[f] for f in _KEPT_RETURNS_FIELDS if self.names.get(f)})
            object.__setattr__(self, "returns", None if scanner is self.sensor else returns)
        if given:
            changes = beam_changes(scanner.beam, given, sensor=str(label), names=self.names)
            try:
                scanner = with_beam(scanner, **changes) if changes else scanner
            except InvalidInputError as exc:
                raise InvalidInputError(f"{', '.join(n(f) for f in given)}: {exc}") from None
        object.__setattr__(self, "scanner", scanner)
        self._check_optics(kind, label)
        object.__setattr__(self, "frame", self._frame(kind, label))
        self._check_trajectory(kind)
        if set(self.formats) & set(LAS_FORMATS):
            moving = self.trajectory is not None and not self.trajectory.is_static
            check_las_frame(self.frame, moving=moving, crs=self.las.get("crs"), origin_m=self.las.get("origin_m"), names=self.names)
            if self.las.get("origin_m") is not None:  # checked once: the files and the trajectory beside them add it as it is
                object.__setattr__(self, "las", {**self.las, "origin_m": tuple(las_origin(self.las["origin_m"], n("origin_m")).tolist())})
        cast = "auto" if self.footprint_cast is None else self.footprint_cast
        if kind.pulsed:
            from zbuf_occlude.sensors.beam.adaptive_cast import check_footprint_cast

            cast = check_footprint_cast(cast, scanner.beam, self.backend, sensor=str(label), names=self.names)
        object.__setattr__(self, "cast", cast)

    def _check_values(self) -> None:
        """The backend, the formats and the sweeps, each alone."""
        n = self.name_of
        if not isinstance(self.backend, str) or self.backend not in BACKENDS:
            raise InvalidInputError(f"{n('backend')} must be one of {', '.join(BACKENDS)}, got {self.backend!r:.40}")
        unknown = [f for f in self.formats if f not in SCAN_FORMATS] if isinstance(self.formats, tuple) else [self.formats]
        if unknown or not self.formats:
            raise InvalidInputError(f"{n('format')} must be a tuple of {', '.join(SCAN_FORMATS)}, got {self.formats!r:.60}")
        object.__setattr__(self, "samples", count(self.samples, n("samples"), low=1, high=MAX_SAMPLES))

    def _check_optics(self, kind, label) -> None:
        """The surface optics against the sensor and the cast (class docstring)."""
        n, tau = self.name_of, self.transmittance
        shown = f"{n('transmittance')} {_shown_tau(tau)}"
        asked = [f for f, v in ((n("reflectance_table"), self.reflectance_table), (shown, tau is not None)) if v]
        opaque = tau is None or (not isinstance(tau, (str, Mapping)) and tau == 0) or (isinstance(tau, Mapping) and not any(tau.values()))
        if asked and not kind.pulsed:
            raise InvalidInputError(f"{' and '.join(asked)} model the surfaces a pulsed LiDAR's beam meets; {label} is a {kind.title}")
        if not kind.pulsed:
            return
        beam = self.scanner.beam
        if self.reflectance_table and self.reflectivity is not None:
            raise InvalidInputError(f"{n('reflectance_table')} gives each surface its material's reflectivity; {n('reflectivity')} gives "
                                    "the object one: give one of them")  # fmt: skip
        if not opaque:
            check_transmittance_cast(_shown_tau(tau), resolves_echoes=beam.resolves_echoes, backend=self.backend, names=self.names)
        # returns asked of one opaque ray would change nothing (a sensor file's own stay as the device has them; a scanner
        # that flies takes its materials' transmittance where none is asked: scan_airborne's "auto")
        asked_returns = any(self.beam.get(f) is not None for f in ("max_returns", "return_mode"))
        if asked_returns and beam.resolves_echoes and beam.footprint_rays == 1 and opaque and not kind.flies:
            what = f"{n('max_returns')} {beam.max_returns}" if beam.return_mode == "all" else f"{n('return_mode')} {beam.return_mode}"
            raise InvalidInputError(f"{what} resolves the echoes of a footprint or of surfaces the beam goes through; {label} fires one "
                                    f"ray a pulse onto opaque surfaces, so each pulse has one return: give {n('footprint_rays')} "
                                    f"(or {n('transmittance')} above 0)")  # fmt: skip

    def _frame(self, kind, label) -> str:
        """The frame: as asked, else "sensor", or "world" for a scanner that flies (which refuses "sensor")."""
        n = self.name_of
        if self.frame is not None and self.frame not in FRAMES:
            raise InvalidInputError(f"{n('frame')} must be one of {', '.join(FRAMES)}, got {self.frame!r:.40}")
        if not kind.flies:
            return self.frame or "sensor"
        if self.frame == "sensor":
            raise InvalidInputError(f"{n('frame')} sensor: {label} flies along its lines, so its points have no one sensor frame; "
                                    f"they are written in the world frame ({n('frame')} world)")  # fmt: skip
        return "world"

    def _check_trajectory(self, kind) -> None:
        """A trajectory against the sensor, the sweeps and the output (class docstring)."""
        if self.trajectory is None:
            return
        n, traj = self.name_of, self.trajectory
        what = n("trajectory")
        if not kind.pulsed or kind.flies:
            raise InvalidInputError(f"{what}: a {kind.title} {'flies its own plan' if kind.flies else 'takes one pose'}")
        if not traj.is_static and self.backend != "embree":
            raise InvalidInputError(f"{what}: {n('backend')} {self.backend:.40} renders from one point, and a moving scanner's pulses "
                                    f"leave from many: use {n('backend')} embree")  # fmt: skip
        needed = self.samples * self.scanner.sweep_s
        if not traj.is_static and traj.duration_s + 1e-9 < needed:
            raise InvalidInputError(f"{what} lasts {traj.duration_s:g} s, and {n('samples')} {self.samples} sweeps of "
                                    f"{self.scanner.name} take {needed:g} s: give fewer samples or a longer trajectory")  # fmt: skip

    def surface_optics(self, scene) -> dict:
        """The ``reflectivity`` and ``transmittance`` keywords of :func:`~zbuf_occlude.sensors.scan.scan` and
        :func:`~zbuf_occlude.sensors.scan.scan_airborne` for ``scene`` (none asked: no keyword, the scan as without them).

        ``scene`` is a :class:`~zbuf_occlude.sensors.scene.objects.ScanScene`: a scene file's, or the one a
        scan of a mesh stands the mesh in (:func:`~zbuf_occlude.sensors.crops.object_crop`: the ground,
        the object, then any occluders, which reflect and transmit as the object does).  One
        transmittance number applies to every object, not the ground; class → value pairs to the
        objects of those classes (a mesh's class: its file name without suffix).

        Raises
        ------
        InvalidInputError
            A transmittance class that no object of the scene has, naming it.
        """
        from zbuf_occlude.sensors.scene.materials import per_class

        out: dict = {}
        if self.reflectance_table:
            out["reflectivity"] = "table"
        tau = self.transmittance
        if isinstance(tau, Mapping):
            try:
                out["transmittance"] = per_class(scene.build(), dict(tau))
            except InvalidInputError as exc:
                raise InvalidInputError(f"{self.name_of('transmittance')} {_shown_tau(tau)}: {exc}") from None
        elif isinstance(tau, str):
            out["transmittance"] = tau
        elif tau is not None:  # every object, not the ground
            out["transmittance"] = [0.0] + [tau] * (len(scene.build().objects))
        return out

    def scene_optics(self):
        """:meth:`surface_optics` as a function of the scene, for a scan that builds its scene per sample
        (:func:`~zbuf_occlude.sensors.crops.object_crops`' ``optics``); None where no optics are asked."""
        if not self.reflectance_table and self.transmittance is None:
            return None
        return self.surface_optics


def _shown_tau(tau) -> str:
    """A transmittance as a user writes it, for messages."""
    if isinstance(tau, Mapping):
        return ",".join(f"{k}={v:g}" for k, v in tau.items())
    return tau if isinstance(tau, str) else f"{tau:g}" if tau is not None else ""
