"""The beam of a pulsed LiDAR: what one pulse is, and what its receiver records of it.

A scanner is a beam × a scan pattern × a platform.  The pattern says where and when pulses
leave (:mod:`zbuf_occlude.sensors.patterns.spinning`, :mod:`zbuf_occlude.sensors.patterns.airborne`, :mod:`zbuf_occlude.sensors.patterns.ray_table`), the platform where the scanner is at that time (:mod:`zbuf_occlude.sensors.platform`),
and the :class:`Beam` everything the device adds to a pulse's geometry: its footprint (a cone
of ``divergence_deg`` sampled by ``footprint_rays`` sub-rays, :mod:`zbuf_occlude.sensors.beam.footprint`), how its echoes
are resolved into returns (``max_returns``, ``range_resolution_m``, ``echo_rule``, ``return_mode``), which it
detects (``detection_threshold``, ``power_noise``), how it measures them (``range_noise_m``,
``dropout``, range limits) and how it writes their intensity (``intensity_scale``).  Every
field is checked here, once, whatever pattern fires the beam.

The beam named ``ideal`` (:data:`IDEAL_BEAM`) is one ray per pulse, its first hit, no noise,
no loss and no radiometry: the idealised scan, named as one.  A preset's beam carries its data
sheet (:mod:`zbuf_occlude.sensors.patterns.spinning`, :mod:`zbuf_occlude.sensors.patterns.airborne_presets`, :mod:`zbuf_occlude.sensors.patterns.ray_table`).

Units: the received energy of a sub-ray is ``w · ρ · |cos θ| / R²`` in m⁻² (``w`` the sub-ray's
share of the pulse, ρ the surface's reflectivity, θ the incidence, ``R`` the range;
:func:`~zbuf_occlude.sensors.beam.echoes.hit_energy`, the range equation of an extended Lambertian
target: Kashani et al. 2015, "A review of LIDAR radiometric processing", Sensors 15(11), Eq. 4).
``detection_threshold`` is in those units, ``intensity_scale`` in counts per unit of them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.checks import MAX_RANGE_M, count, located, namer, real, replaced, sensor_name, text, value_kind
from zbuf_occlude.sensors.beam.echoes import ECHO_RULES, MAX_POWER_NOISE, MAX_RETURNS
from zbuf_occlude.sensors.beam.footprint import (
    FOOTPRINT_RAYS,
    MAX_DIVERGENCE_DEG,
    MAX_SUBRAYS,
    PROFILES,
    footprint_offsets,
    subray_directions,
)

__all__ = [
    "Beam", "IDEAL_BEAM", "RETURN_MODES", "RETURN_FIELDS", "MODE_RETURNS", "MAX_INTENSITY_COUNTS", "check_beam", "check_returns",
    "footprint_changes", "intensity_counts", "INTENSITY_UNITS", "device_quantity",
]  # fmt: skip

#: How the receiver turns a pulse's resolved echoes into returns (``Beam.return_mode``):
#:
#: ``"all"``
#:     up to ``max_returns`` echoes, in range order (a full-waveform or discrete multi-return
#:     receiver: RIEGL, Leica, Optech); with ``max_returns`` 1, the pulse's one return (the
#:     centre ray's first hit, or with a footprint the strongest echo, merged within
#:     ``echo_separation_m``).
#: ``"first"``, ``"strongest"``, ``"last"``
#:     the pulse's first (nearest), strongest or last echo only (``max_returns`` 1): Velodyne's single-return
#:     modes are strongest and last (VLP-16 user manual 63-9243 Rev. D, "Return Modes"); Hesai's are first,
#:     strongest and last (PandarXT-16 user manual, §3.1.2.4, the tail's Return Mode field).
#: ``"dual"``
#:     the last and the strongest echo, or the last and the second strongest where they are one
#:     (Velodyne's dual-return mode; ``max_returns`` 2).
RETURN_MODES = ("all", "first", "strongest", "last", "dual")
#: Largest intensity a LAS file stores (unsigned 16 bits).
MAX_INTENSITY_COUNTS = 65_535
#: What a device writes as a return's intensity (``Beam.intensity_unit``), in counts of ``intensity_scale``:
#:
#: ``"energy"``
#:     the received energy E, m⁻², which falls as 1/R² (an airborne receiver's raw counts).
#: ``"reflectivity"``
#:     a calibrated reflectivity, E · R², the apparent reflectance ρ |cos θ| s of the echo (s: the share of the
#:     pulse's footprint it intercepts), independent of range and of the laser's power: what Velodyne, Ouster and
#:     Livox units report (the presets' sources).
INTENSITY_UNITS = ("energy", "reflectivity")


@dataclass(frozen=True)
class Beam:
    """A pulsed LiDAR's beam and receiver (module docstring).

    Parameters
    ----------
    name : str
        ``"ideal"`` or the device's name.
    source : str
        Data sheet (and page) the numbers come from; assumptions named as such.
    wavelength_nm : float
        Laser wavelength, nanometres (905 for most spinning LiDARs, 1064 or 1550 airborne); picks
        the column of material reflectances (:mod:`zbuf_occlude.sensors.scene.materials`).
    divergence_deg : float
        Full-angle beam divergence, degrees in [0, 90]; the cone the sub-rays sample.
    profile : {"tophat", "gaussian"}
        Energy across the footprint (:func:`~zbuf_occlude.sensors.beam.footprint.footprint_offsets`).
    footprint_rays : int
        K sub-rays per pulse, 1..:data:`~zbuf_occlude.sensors.beam.footprint.MAX_SUBRAYS`; above 1 needs a
        divergence > 0.  1: every pulse is its centre ray's first hit.
    max_returns : int
        Most returns recorded per pulse, 1..15 (LAS 1.4's return numbers).
    return_mode : str
        One of :data:`RETURN_MODES`.  ``"all"`` with ``max_returns`` above 1 is the multi-return
        model: the sub-rays' hits resolved into echoes (:func:`~zbuf_occlude.sensors.beam.echo_energy.echo_returns`).
    range_resolution_m : float
        Least range between two returns of one pulse, metres (half the pulse length, c·τ/2; a 5 ns
        pulse: 0.75 m).  Needed (> 0) when echoes are resolved (``max_returns`` above 1, or a
        return mode other than ``"all"``), refused otherwise.
    echo_rule : {"chain", "waveform"}
        How a pulse's sub-ray hits merge into echoes where echoes are resolved
        (:func:`~zbuf_occlude.sensors.beam.echoes.resolve_echoes`): ``"chain"`` (the default) starts a
        new echo at a gap of ``range_resolution_m`` after the previous hit; ``"waveform"`` at each
        dip of the pulse's summed waveform (:mod:`~zbuf_occlude.sensors.beam.waveform`), so that a weak
        run of hits between two reflections (a crown's side across the footprint) does not join
        them and the returns per pulse do not drift with ``footprint_rays``.  ``"waveform"`` needs
        echoes resolved (refused otherwise).
    echo_separation_m : float
        One return per pulse with a footprint (``"all"``, ``max_returns`` 1): echoes within this range
        of the strongest merge into one return at their energy-weighted range, the *mixed pixel*
        of Hebert & Krotkov (1992), Image and Vision Computing 10(3).  0: never merged.  Needs a
        footprint; refused when echoes are resolved.
    detection_threshold : float
        Least received energy detected, m⁻² (module docstring); applied where the scan is given
        surface reflectivities (an airborne scanner's: always, with ρ = 1 where none are given).
        0: every echo is detected.
    min_echo_reflectance : float
        Least *apparent reflectance* of a detected echo, in [0, 1]: its energy times its range
        squared, ``E · R²``, which is ``ρ · |cos θ| · s`` for surfaces of reflectance ρ met at
        incidence θ that intercept the share ``s`` of the pulse (ρ = 1 where the scan is given
        no reflectivities).  A threshold relative to the full-footprint echo at the echo's own
        range: what a receiver with sensitivity time control (gain growing as R², compressing
        the range equation's 1/R²; Skolnik, "Introduction to Radar Systems", 3rd ed., 2001, on
        sensitivity time control) compares against a fixed level.  So a partial echo at a silhouette (a sliver of
        the footprint on an object's edge) or a grazing hit is dropped alike at 5 m and at
        1,500 m, and since ``s`` is a share of the pulse's energy the rule does not change with
        the sub-ray count K (where :attr:`detection_threshold` alone detects ever thinner
        slivers as K grows).  Applied to every echo, with or without reflectivities, beside
        ``detection_threshold``.  0: no such threshold (the default).
    power_noise : float
        σ of the natural log of the received power per firing (detection is then
        ``Φ(ln(E / τ) / σ)``), in [0, :data:`~zbuf_occlude.sensors.beam.echoes.MAX_POWER_NOISE`]
        (2: above speckle through saturated turbulence, the most a return's power fluctuates);
        applied with the detection threshold, where reflectivities are given.  0: a sharp threshold.
    intensity_scale : float or None
        Counts per unit of received energy: a return's LAS intensity is
        ``min(round(E · intensity_scale), max_intensity)``.  None: no intensity model (with one
        return per pulse and no reflectivities the scan's intensity is 1.0, the idealised
        scan's; a beam that resolves echoes, or a scan given reflectivities, records the echo
        energies).
    max_intensity : int
        Largest count the device reports, 1..65535 (255 for an 8-bit reflectivity, Velodyne's).
    intensity_unit : {"energy", "reflectivity"}
        What the device writes (:data:`INTENSITY_UNITS`): ``"energy"`` (default) counts of the received energy,
        ``min(round(E · intensity_scale), max_intensity)``; ``"reflectivity"`` counts of its calibrated reflectivity,
        ``min(round(E · R² · intensity_scale), max_intensity)`` with R the return's range, so that
        ``intensity_scale`` is counts per unit reflectance (a Velodyne's 100: a white diffuse wall head-on reads 100
        at any range).
    range_noise_m : float
        σ of the Gaussian range error, metres.
    dropout : float
        Probability in [0, 1) that a return is lost, at range 0.
    dropout_range_per_m : float
        Growth of that probability per metre of range (:meth:`dropout_probability`).
    foliage_dropout : float
        Probability in [0, 1) that a return from a crown surface (a face of a material in
        :data:`~zbuf_occlude.sensors.scene.materials.CROWN_MATERIALS`: a mesh standing for leaves
        with gaps) is lost, besides ``dropout``: ray drop on vegetation, drawn independently per
        return.  Real HDL-32E scans of bushes miss about 14 % of their firings at every range
        where cars, pedestrians and poles miss 3–6 % (measured on LiDARNet v2: the results page
        "Returns against real scans: a spinning LiDAR"): a footprint on leaves often meets too
        little of them for an echo.  A crown mesh is a closed surface, so its footprints are
        whole; this is the loss it cannot give.  0: none (the default).
    min_range_m, max_range_m : float
        Returns measured nearer or farther are dropped, metres.

    Raises
    ------
    InvalidInputError
        Naming the field: a value that is not a number (``True``, ``"5"``) or not finite, out of
        its range, or a combination the receiver cannot have (each rule above).
    """

    name: str = "ideal"
    source: str = ""
    wavelength_nm: float = 905.0
    divergence_deg: float = 0.0
    profile: str = "tophat"
    footprint_rays: int = 1
    max_returns: int = 1
    return_mode: str = "all"
    range_resolution_m: float = 0.0
    echo_rule: str = "chain"
    echo_separation_m: float = 0.0
    detection_threshold: float = 0.0
    min_echo_reflectance: float = 0.0
    power_noise: float = 0.0
    intensity_scale: float | None = None
    max_intensity: int = MAX_INTENSITY_COUNTS
    intensity_unit: str = "energy"
    range_noise_m: float = 0.0
    dropout: float = 0.0
    dropout_range_per_m: float = 0.0
    foliage_dropout: float = 0.0
    min_range_m: float = 0.0
    max_range_m: float = MAX_RANGE_M

    def __post_init__(self) -> None:
        sensor_name(self.name, "beam name")
        with located("beam"):  # not by its name: a sensor file's name is one of its values, never quoted
            self._check()

    def _check(self) -> None:
        """Every field, numbers stored as floats and counts as ints (messages start with the field's name)."""
        at_least_0, ranges = {"low": 0.0}, {"low": 0.0, "high": MAX_RANGE_M}
        numbers = {
            "wavelength_nm": {"low": 200.0, "high": 20_000.0}, "divergence_deg": {"low": 0.0, "high": MAX_DIVERGENCE_DEG},
            "range_resolution_m": ranges, "echo_separation_m": ranges, "detection_threshold": at_least_0,
            "min_echo_reflectance": {"low": 0.0, "high": 1.0}, "power_noise": {"low": 0.0, "high": MAX_POWER_NOISE}, "range_noise_m": ranges, "dropout": {"low": 0.0, "high": 1.0, "high_open": True},
            "dropout_range_per_m": {}, "foliage_dropout": {"low": 0.0, "high": 1.0, "high_open": True}, "min_range_m": ranges, "max_range_m": {**ranges, "low_open": True},
        }  # fmt: skip
        for name, bounds in numbers.items():
            object.__setattr__(self, name, real(getattr(self, name), name, **bounds))
        if self.intensity_scale is not None:
            object.__setattr__(self, "intensity_scale", real(self.intensity_scale, "intensity_scale", low=0.0, low_open=True))
        text(self.source, "source")
        text(self.profile, "profile", choices=PROFILES)
        text(self.return_mode, "return_mode", choices=RETURN_MODES)
        text(self.echo_rule, "echo_rule", choices=ECHO_RULES)
        text(self.intensity_unit, "intensity_unit", choices=INTENSITY_UNITS)
        object.__setattr__(self, "footprint_rays", count(self.footprint_rays, "footprint_rays", low=1, high=MAX_SUBRAYS))
        object.__setattr__(self, "max_returns", count(self.max_returns, "max_returns", low=1, high=MAX_RETURNS))
        object.__setattr__(self, "max_intensity", count(self.max_intensity, "max_intensity", low=1, high=MAX_INTENSITY_COUNTS))
        if self.min_range_m >= self.max_range_m:
            raise InvalidInputError("min_range_m must be below max_range_m")
        self._check_returns()

    def _check_returns(self) -> None:
        """The rules that tie the footprint, the return mode and the range resolution together (:func:`check_returns`)."""
        check_returns({name: getattr(self, name) for name in RETURN_FIELDS})

    @property
    def resolves_echoes(self) -> bool:
        """Whether the pulse's hits are resolved into echoes (``max_returns`` above 1, or a Velodyne return mode)."""
        return self.max_returns > 1 or self.return_mode != "all"

    @property
    def resolves_footprint(self) -> bool:
        """Whether a pulse casts several sub-rays whose hits are resolved into echoes: the footprints
        whose sub-rays the adaptive footprint skips (:func:`~zbuf_occlude.sensors.beam.adaptive_cast.adaptive_footprint`)."""
        return self.footprint_rays > 1 and self.resolves_echoes

    @property
    def is_ideal(self) -> bool:
        """One ray, its first hit, no noise, no loss, no radiometry (:data:`IDEAL_BEAM`'s physics, any name and wavelength)."""
        return replace(self, name="ideal", source="", wavelength_nm=IDEAL_BEAM.wavelength_nm) == IDEAL_BEAM

    def with_(self, **changes) -> Beam:
        """A copy with some fields changed (``beam.with_(footprint_rays=19)``), checked again."""
        return replaced(self, **changes)

    def dropout_probability(self, range_m: ArrayLike) -> NDArray[np.float64]:
        """Probability that a return at ``range_m`` (metres, any shape) is lost, float64 of that shape:
        ``clip(dropout + dropout_range_per_m · range_m, 0, 0.95)``; exactly ``dropout`` when the slope is 0."""
        r = np.asarray(range_m, dtype=np.float64)
        if self.dropout_range_per_m == 0.0:
            return np.full(r.shape, float(self.dropout))
        return np.clip(self.dropout + self.dropout_range_per_m * r, 0.0, 0.95)

    def footprint_weights(self) -> NDArray[np.float64]:
        """(K,) float64: each sub-ray's share of the pulse's energy, summing to 1 (``profile``)."""
        if self.footprint_rays == 1:
            return np.ones(1)
        return footprint_offsets(self.footprint_rays, self.divergence_deg, profile=self.profile)[1]

    def footprint_directions(self, directions: ArrayLike) -> NDArray[np.float64]:
        """(N, K, 3) float64: the K = ``footprint_rays`` unit sub-rays of each beam axis ``directions (N, 3)``.

        Ray 0 is the centre (:func:`~zbuf_occlude.sensors.beam.footprint.subray_directions` of
        :func:`~zbuf_occlude.sensors.beam.footprint.footprint_offsets`).

        Raises
        ------
        InvalidInputError
            ``directions`` not finite.
        """
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        return subray_directions(d, footprint_offsets(self.footprint_rays, self.divergence_deg)[0])

    def intensity_counts(self, energy: ArrayLike, range_m: ArrayLike | None = None) -> NDArray[np.uint16]:
        """(N,) uint16 intensities the device writes for received energies ``energy (N,)`` m⁻² at ranges ``range_m (N,)``
        metres: :func:`intensity_counts` of :func:`device_quantity` with the beam's ``intensity_scale``, ``max_intensity``
        and ``intensity_unit``.

        Raises
        ------
        InvalidInputError
            The beam has no ``intensity_scale``; a reflectivity without ``range_m``.
        """
        if self.intensity_scale is None:
            raise InvalidInputError("the beam has no intensity_scale (counts per unit of received energy)")
        return intensity_counts(device_quantity(energy, range_m, self.intensity_unit), self.intensity_scale, self.max_intensity)


def device_quantity(energy: ArrayLike, range_m: ArrayLike | None, unit: str) -> NDArray[np.float64]:
    """(N,) float64: what a device of ``unit`` (:data:`INTENSITY_UNITS`) measures of echoes of received energy
    ``energy (N,)`` m⁻² at ranges ``range_m (N,)`` metres: the energy itself, or the calibrated reflectivity
    ``E · R²`` (unitless apparent reflectance).  The one rule of a beam's counts and of a scan's LAS file.

    Raises
    ------
    InvalidInputError
        An unknown unit; a reflectivity without ranges, or with ranges of another shape.
    """
    e = np.asarray(energy, dtype=np.float64)
    if text(unit, "intensity_unit", choices=INTENSITY_UNITS) == "energy":
        return e
    if range_m is None or np.shape(range_m) != e.shape:
        raise InvalidInputError(f"a calibrated reflectivity needs each return's range: {np.shape(e)} energies, ranges "
                                f"{'none' if range_m is None else np.shape(range_m)}")  # fmt: skip
    return e * np.square(np.asarray(range_m, dtype=np.float64))


def intensity_counts(energy: ArrayLike, scale: float, top: int = MAX_INTENSITY_COUNTS) -> NDArray[np.uint16]:
    """(N,) uint16 intensity counts of received energies ``energy (N,)`` m⁻²: ``min(rint(E · scale), top)``, 0 for
    an energy that is negative or not a number.  The one rule of a beam's counts and of a scan's LAS file."""
    e = np.nan_to_num(np.asarray(energy, dtype=np.float64), nan=0.0, posinf=np.inf)
    return np.minimum(np.rint(np.clip(e, 0.0, None) * float(scale)), int(top)).astype(np.uint16)


#: The :class:`Beam` fields :func:`check_returns` ties together.
RETURN_FIELDS = ("divergence_deg", "footprint_rays", "max_returns", "return_mode", "range_resolution_m", "echo_rule", "echo_separation_m")
#: A return mode other than ``"all"`` and the returns per pulse it records.
MODE_RETURNS = {"first": 1, "strongest": 1, "last": 1, "dual": 2}


def check_returns(values: Mapping[str, object], names: Mapping[str, str | None] | None = None) -> None:
    """The one statement of the rules that tie a beam's footprint, returns and range resolution together.

    ``values`` holds every field of :data:`RETURN_FIELDS` (a :class:`Beam`'s, or the beam a scan
    request asks for: :mod:`zbuf_occlude.sensors.request`).  Messages name each field as ``names``
    maps it (a command's option for it; a field it does not map: its own name), so that a command
    never restates a rule and the library never spells an option.  The rules: a footprint needs a
    divergence; a Velodyne return mode records its number of returns; resolved echoes (``max_returns``
    above 1 or a return mode other than ``"all"``) need a range resolution, and nothing else takes
    one; ``echo_rule`` "waveform" needs resolved echoes; echo merging (``echo_separation_m``) needs a
    footprint and one return per pulse.

    Raises
    ------
    InvalidInputError
        The first rule broken, naming the fields (as ``names`` maps them) and their values.
    """
    n = namer(names)
    k, m, mode, rule = values["footprint_rays"], values["max_returns"], values["return_mode"], values["echo_rule"]
    resolution, separation = values["range_resolution_m"], values["echo_separation_m"]
    resolves = m > 1 or mode != "all"
    what = f"{n('max_returns')} {m}" if mode == "all" else f"{n('return_mode')} {mode}"
    several = f"{n('max_returns')} above 1 or {n('return_mode')} first, strongest, last or dual"
    if k > 1 and not values["divergence_deg"] > 0:
        raise InvalidInputError(f"{n('footprint_rays')} above 1 needs {n('divergence_deg')} > 0")
    wanted = MODE_RETURNS.get(mode)
    if wanted is not None and m != wanted:
        raise InvalidInputError(f"{n('return_mode')} {mode} records {wanted} return{'s' * (wanted > 1)} per pulse; "
                                f"{n('max_returns')} {m} contradicts it")  # fmt: skip
    if resolves and not resolution > 0:
        raise InvalidInputError(f"{what} needs {n('range_resolution_m')} > 0 (metres: the least range between two returns, c·τ/2)")
    if not resolves and resolution > 0:
        raise InvalidInputError(f"{n('range_resolution_m')} {resolution:g} separates several returns per pulse: it needs {several} "
                                f"(one return per pulse merges echoes by {n('echo_separation_m')})")  # fmt: skip
    if rule != "chain" and not resolves:
        raise InvalidInputError(f"{n('echo_rule')} {rule} tells resolved echoes apart: it needs {several}")
    if separation > 0 and k == 1:
        raise InvalidInputError(f"{n('echo_separation_m')} {separation:g} needs {n('footprint_rays')} above 1 "
                                "(mixed pixels come from a wide footprint)")  # fmt: skip
    if separation > 0 and resolves:
        raise InvalidInputError(f"{n('echo_separation_m')} {separation:g} merges echoes into one return; with {what} give "
                                f"{n('range_resolution_m')} instead")  # fmt: skip


#: One ray per pulse, its first hit; no noise, loss or radiometry: the idealised scan.
IDEAL_BEAM = Beam()


def check_beam(beam: object) -> Beam:
    """``beam`` if it is a :class:`Beam` (a scanner's ``beam`` field).

    Raises
    ------
    InvalidInputError
        Anything else, naming its type.
    """
    if not isinstance(beam, Beam):
        raise InvalidInputError(f"beam must be a Beam (zbuf_occlude.sensors.beam.fields.Beam), got {value_kind(beam)}")
    return beam


def footprint_changes(beam: Beam, *, footprint: bool, divergence_deg: float | None, names: tuple[str, str], sensor: str) -> dict:
    """The beam fields a request for a footprint (``footprint``) and a divergence (``divergence_deg``) changes.

    The divergence as given; a footprint of :data:`~zbuf_occlude.sensors.beam.footprint.FOOTPRINT_RAYS`
    sub-rays where the beam fires fewer (a beam's own wider footprint stays: an airborne preset's
    19).  The one rule of ``scan --footprint --divergence`` and ``farm --sensor-footprint
    --sensor-divergence``; ``names`` are the two options as the command calls them, ``sensor`` the
    sensor's name, for messages.

    Raises
    ------
    InvalidInputError
        A footprint for a beam without a divergence (naming the divergence option), or a divergence
        for a beam that fires one ray a pulse with no footprint asked (naming the footprint option).
    """
    changes: dict = {}
    if divergence_deg is not None:
        changes["divergence_deg"] = float(divergence_deg)
    rays = beam.footprint_rays
    if footprint:
        if not changes.get("divergence_deg", beam.divergence_deg) > 0:
            raise InvalidInputError(
                f"{names[0]} samples the beam's divergence cone, and {sensor}'s beam ({beam.name}) has no divergence "
                f"(divergence_deg 0): give {names[1]} DEG, the full angle of its data sheet"
            )
        rays = max(rays, FOOTPRINT_RAYS)
        if rays != beam.footprint_rays:
            changes["footprint_rays"] = rays
    if divergence_deg is not None and rays == 1:
        raise InvalidInputError(
            f"{names[1]} {float(divergence_deg):g} widens a footprint's cone, and {sensor}'s beam fires one ray a pulse: give {names[0]} too"
        )
    return changes
