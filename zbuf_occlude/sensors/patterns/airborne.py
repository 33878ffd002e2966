"""Airborne laser scanners (ALS): an aircraft flies a straight line and a mirror sweeps the beam across it.

World frame: metres, z up, the ground at ``z = 0``; the aircraft flies along +x over the line
``y = 0`` at ``altitude_m``, at ``speed_mps``.  The mirror sweeps the beam across track (in the
y–z plane) over ``swath_deg``, ``line_rate_hz`` lines per second, firing ``pulse_rate_hz``
pulses per second:

``linear``
    a rotating polygon mirror: every line sweeps the same way, in equal angle steps (parallel
    lines; RIEGL's LMS-Q and VQ series).
``oscillating``
    a swinging mirror: lines alternate direction (a zig-zag on the ground; modelled with a
    constant angular speed, i.e. without the slow-down at the turning points of a real mirror).

On flat ground the pattern gives, at across-track angle θ, ``ρ(θ) = PRR · cos²θ / (S · h · v)``
points per m² (S: the swath in radians, h: altitude, v: speed), and over the whole swath
``PRR / (v · W)`` with ``W = 2 h tan(S/2)`` (:attr:`AirborneScanner.density_m2`), the figure
flight plans quote (e.g. Baltsavias, "Airborne laser scanning: basic relations and formulas",
ISPRS J. Photogramm. 54, 1999, Eq. 17: mean point density = PRR / (v · swath width)).

Flight plans
------------
A survey flies several lines and merges their returns.  ``n_lines`` parallel lines per heading
in ``headings_deg`` (degrees counter-clockwise from +x; not a compass heading), ``s = W · (1 −
side_overlap)`` apart (:attr:`AirborneScanner.flight_line_spacing_m`; ``side_overlap``: the
fraction of a strip's width its neighbour covers again), centred on the plan centre (the world
origin) and shifted together across track by a lateral shift; every line starts at its own time
phase, and the lines are flown one after another, ``turn_s`` apart (:mod:`~zbuf_occlude.sensors.patterns.flight_times`).  Line ``j`` of heading ``h`` has the id ``h · n_lines + j``.  With the defaults
(``n_lines=1``, ``headings_deg=(0,)``) the plan is the single line above.

Overlapping strips add up: where the block is unbounded (at least ``W/2 − s`` inside its outer
lines' nadirs), every across-track interval one spacing ``s`` wide receives each column of
pulses of one line exactly once, so the mean density there is ``PRR / (v · s)`` per heading
(:attr:`AirborneScanner.survey_density_m2`; ``W / s = 1 / (1 − side_overlap)`` strips cover
a point on average).  This is Baltsavias' Eq. 17 with the swath width replaced by the line
spacing, the rule flight planners use for multi-strip density.

Returns
-------
The scanner's :class:`~zbuf_occlude.sensors.beam.fields.Beam` says what a pulse returns, as for every
pulsed sensor (:func:`~zbuf_occlude.sensors.scan.scan_airborne`, :func:`~zbuf_occlude.sensors.scan.fire_pulses`).
Each pulse is a cone of ``Beam.divergence_deg`` sampled by ``Beam.footprint_rays`` sub-rays
(:mod:`zbuf_occlude.sensors.beam.footprint`).  With ``Beam.max_returns`` above 1 their hits are resolved into up to
``max_returns`` returns by the one echo model (:func:`~zbuf_occlude.sensors.beam.echo_energy.echo_returns`:
energy ``w · ρ · |cos θ| / R²`` per sub-ray, echoes within ``range_resolution_m`` merged): a pulse
that meets a branch and the ground below records both.  With one return per pulse, a footprint
gives the pulse's strongest echo, and one ray its first hit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.fields import IDEAL_BEAM, Beam, check_beam
from zbuf_occlude.sensors.checks import (
    MAX_RANGE_M,
    MAX_SENSOR_RAYS,
    count,
    is_number,
    located,
    real,
    reals,
    replaced,
    sensor_name,
    text,
)
from zbuf_occlude.sensors.patterns.flight_times import TURN_S, flown_poses, line_length_m, line_start_s
from zbuf_occlude.sensors.pulses import Pulses

__all__ = ["AIRBORNE_IDEAL_BEAM", "MAX_FLIGHT_LINES", "AirborneScanner", "FlightLine"]

#: Scan patterns (module docstring).
PATTERNS = ("linear", "oscillating")
#: The beam of an airborne scanner given none: the ``ideal`` beam at the airborne wavelength, 1064 nm.
AIRBORNE_IDEAL_BEAM = IDEAL_BEAM.with_(wavelength_nm=1064.0)
#: Most flight lines one plan may hold (``n_lines · len(headings_deg)``): a sensor file is
#: untrusted input, and each line costs a pass over the scanned square.
MAX_FLIGHT_LINES = 256
#: Longest ``turn_s``, seconds: a day.
MAX_TURN_S = 86_400.0


@dataclass(frozen=True)
class FlightLine:
    """One line of a flight plan: a straight, level pass.

    Attributes
    ----------
    line_id : int
        ``heading index · n_lines + index in its block``.
    heading_deg : float
        Direction of flight, degrees counter-clockwise from +x.
    offset_m : float
        Signed distance of the line from the plan centre (the world origin), metres, along the
        left normal ``(−sin φ, cos φ)`` of the heading φ.
    """

    line_id: int
    heading_deg: float
    offset_m: float

    def axes(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The unit vectors ``(along, across)`` of the line in the world x–y plane."""
        phi = math.radians(self.heading_deg)
        return np.array([math.cos(phi), math.sin(phi)]), np.array([-math.sin(phi), math.cos(phi)])

    @property
    def is_reference(self) -> bool:
        """True for the single line of a plain scanner: along +x over ``y = 0`` (no transform)."""
        return self.heading_deg == 0.0 and self.offset_m == 0.0

    def to_line(self, xy) -> NDArray[np.float64]:
        """World ``(..., 2)`` x–y points in the line's frame (x along track, y across, metres)."""
        along, across = self.axes()
        rel = np.asarray(xy, dtype=np.float64) - self.offset_m * across
        return np.stack([rel @ along, rel @ across], axis=-1)


@dataclass(frozen=True)
class AirborneScanner:
    """An airborne laser scanner on a straight, level flight line.

    Parameters
    ----------
    name : str
    swath_deg : float
        Full scan angle across track, degrees (0, 180).
    pulse_rate_hz : float
        Pulses per second (all channels together).
    line_rate_hz : float
        Scan lines per second.
    altitude_m, speed_mps : float
        Flying height above the ground, metres; ground speed, metres per second.
    pattern : {"linear", "oscillating"}
    beam : Beam
        The pulse and its receiver (:class:`~zbuf_occlude.sensors.beam.fields.Beam`): footprint, returns,
        detection, range noise and dropout.  Its ``detection_threshold`` (the value
        :func:`~zbuf_occlude.sensors.fit.fit_return_model` measures on a LAS file) applies with
        ρ = 1 where the scan is given no reflectivity.  Default: the ``ideal`` beam at 1064 nm.
    source : str
    n_lines : int
        Flight lines per heading, parallel (module docstring, *Flight plans*); 1: one line.
    side_overlap : float
        Fraction in [0, 1) of a strip's width that the next line's strip covers again; sets
        :attr:`flight_line_spacing_m`.  Unused with one line.
    headings_deg : tuple of float
        One block of ``n_lines`` lines per heading, degrees counter-clockwise from +x (two
        headings 90° apart: a cross-hatched survey).
    turn_s : float
        Seconds from the end of one flight line to the start of the next, > 0 (default
        :data:`~zbuf_occlude.sensors.patterns.flight_times.TURN_S`): the plan's lines are flown one
        after another (:mod:`~zbuf_occlude.sensors.patterns.flight_times`).

    Raises
    ------
    InvalidInputError
        Naming the field: a value that is not a number (``True``, ``"5"``), a non-positive or
        non-finite number, an altitude or noise beyond :data:`~zbuf_occlude.sensors.checks.MAX_RANGE_M`,
        a swath outside (0°, 180°), an unknown pattern, fewer than one pulse per line or more
        than :data:`~zbuf_occlude.sensors.checks.MAX_SENSOR_RAYS`, ``n_lines`` not an integer ≥ 1,
        ``side_overlap`` outside [0, 1), no heading or a non-finite one, more than
        :data:`MAX_FLIGHT_LINES` lines, a ``beam`` that is not a Beam, a name that cannot name files.
    """

    name: str
    swath_deg: float
    pulse_rate_hz: float
    line_rate_hz: float
    altitude_m: float
    speed_mps: float
    pattern: str = "linear"
    beam: Beam = AIRBORNE_IDEAL_BEAM
    source: str = ""
    n_lines: int = 1
    side_overlap: float = 0.0
    headings_deg: tuple[float, ...] = (0.0,)
    turn_s: float = TURN_S

    def __post_init__(self) -> None:
        sensor_name(self.name, "airborne scanner name")
        with located("airborne scanner"):  # not by its name: a sensor file's name is one of its values, never quoted
            self._check()

    def _check(self) -> None:
        """Check every field and store the numbers as floats (messages start with the field's name)."""
        positive = {"low": 0.0, "low_open": True}
        numbers = {
            "pulse_rate_hz": positive, "line_rate_hz": positive, "altitude_m": {**positive, "high": MAX_RANGE_M},
            "speed_mps": positive, "swath_deg": {**positive, "high": 180.0, "high_open": True},
            "side_overlap": {"low": 0.0, "high": 1.0, "high_open": True, "expected": "a fraction in [0, 1)"},
            "turn_s": {"low": 0.0, "low_open": True, "high": MAX_TURN_S},
        }  # fmt: skip
        for name, bounds in numbers.items():
            object.__setattr__(self, name, real(getattr(self, name), name, **bounds))
        text(self.pattern, "pattern", choices=PATTERNS)
        text(self.source, "source")
        per_line = self.pulse_rate_hz / self.line_rate_hz  # checked before pulses_per_line rounds it
        if not per_line <= MAX_SENSOR_RAYS or self.pulses_per_line < 1:
            raise InvalidInputError(
                f"pulse_rate_hz / line_rate_hz must give 1 to {MAX_SENSOR_RAYS:,} pulses per line, got "
                f"{'fewer than 1' if per_line <= MAX_SENSOR_RAYS else 'more'}"
            )
        object.__setattr__(self, "n_lines", count(self.n_lines, "n_lines", low=1, high=MAX_FLIGHT_LINES))
        headings = (self.headings_deg,) if is_number(self.headings_deg) else self.headings_deg
        headings = reals(headings, "headings_deg", max_length=MAX_FLIGHT_LINES, expected="one or more finite angles")
        object.__setattr__(self, "headings_deg", headings)
        if self.n_lines * len(self.headings_deg) > MAX_FLIGHT_LINES:
            raise InvalidInputError(
                f"{self.n_lines} lines x {len(self.headings_deg)} headings is more than {MAX_FLIGHT_LINES} flight lines"
            )
        check_beam(self.beam)

    @property
    def pulses_per_line(self) -> int:
        """Pulses fired during one scan line (``round(pulse_rate_hz / line_rate_hz)``)."""
        return int(round(self.pulse_rate_hz / self.line_rate_hz))  # noqa: RUF046 (numpy floats round to floats)

    @property
    def swath_width_m(self) -> float:
        """Width of the strip on flat ground, metres: ``2 h tan(swath/2)``."""
        return 2.0 * self.altitude_m * math.tan(math.radians(self.swath_deg) / 2.0)

    @property
    def line_spacing_m(self) -> float:
        """Distance between consecutive lines along track, metres (at one across-track position)."""
        return self.speed_mps / self.line_rate_hz

    @property
    def density_m2(self) -> float:
        """Mean point density over the strip on flat ground, points per m² (module docstring)."""
        return self.pulse_rate_hz / (self.speed_mps * self.swath_width_m)

    def density_at_m2(self, across_track_m: float) -> float:
        """Point density on flat ground at an across-track position, points per m²: ``PRR cos²θ / (S h v)``."""
        theta = math.atan2(across_track_m, self.altitude_m)
        return self.pulse_rate_hz * math.cos(theta) ** 2 / (math.radians(self.swath_deg) * self.altitude_m * self.speed_mps)

    @property
    def flight_line_spacing_m(self) -> float:
        """Distance between neighbouring parallel flight lines, metres: ``W · (1 − side_overlap)``."""
        return self.swath_width_m * (1.0 - self.side_overlap)

    @property
    def survey_density_m2(self) -> float:
        """Mean point density on flat ground where the plan's blocks are unbounded, points per m².

        ``len(headings_deg) · PRR / (v · s)`` with ``s`` the flight-line spacing, or the swath
        width for one line per heading (then :attr:`density_m2` per heading); module docstring.
        """
        spacing = self.flight_line_spacing_m if self.n_lines > 1 else self.swath_width_m
        return len(self.headings_deg) * self.pulse_rate_hz / (self.speed_mps * spacing)

    def _shifts(self, lateral_shift_m) -> NDArray[np.float64]:
        """(H,) float64: ``lateral_shift_m``, one finite value for every heading or one per heading, metres.

        Raises
        ------
        InvalidInputError
            Not finite numbers, or a list of another length than 1 or the headings', naming ``lateral_shift_m``.
        """
        one = is_number(lateral_shift_m)
        values = reals((lateral_shift_m,) if one else lateral_shift_m, "lateral_shift_m", lengths={1, len(self.headings_deg)})
        return np.broadcast_to(np.asarray(values, dtype=np.float64), (len(self.headings_deg),))

    def flight_lines(self, lateral_shift_m=0.0) -> list[FlightLine]:
        """The plan's lines (module docstring, *Flight plans*).

        Parameters
        ----------
        lateral_shift_m : float or sequence of float
            Shift of each heading's block across its lines, metres (one value for every block,
            or one per heading).

        Returns
        -------
        list of FlightLine
            ``n_lines · len(headings_deg)`` lines, ordered by line id.
        """
        shifts = self._shifts(lateral_shift_m)
        s = self.flight_line_spacing_m
        n = self.n_lines
        return [FlightLine(h * n + j, heading, (j - (n - 1) / 2.0) * s + float(shifts[h]) if n > 1 else float(shifts[h]))
                for h, heading in enumerate(self.headings_deg) for j in range(n)]  # fmt: skip

    def survey_density_at_m2(self, xy, lateral_shift_m=0.0) -> NDArray[np.float64]:
        """Point density of the whole plan on flat ground at world points ``xy``, points per m².

        The sum over the lines whose strip covers the point of :meth:`density_at_m2` at its
        across-track position (lines are unbounded along track).

        Parameters
        ----------
        xy : (2,) or (N, 2) float
            World x–y, metres.
        lateral_shift_m : float or sequence of float
            As :meth:`flight_lines`.

        Returns
        -------
        () or (N,) float64
        """
        pts = np.asarray(xy, dtype=np.float64)
        half = self.swath_width_m / 2.0
        total = np.zeros(pts.shape[:-1])
        for line in self.flight_lines(lateral_shift_m):
            y = line.to_line(pts)[..., 1]
            theta = np.arctan2(y, self.altitude_m)
            rho = self.pulse_rate_hz * np.cos(theta) ** 2 / (math.radians(self.swath_deg) * self.altitude_m * self.speed_mps)
            total = total + np.where(np.abs(y) <= half, rho, 0.0)
        return total

    def pulses(self, center_xy, half_size_m: float, rng: np.random.Generator, *, phase_s: float | None = None,
               lateral_shift_m=None) -> Pulses:  # fmt: skip
        """The plan's pulses over the square ``center_xy ± half_size_m`` (metres, world frame), every line's merged.

        Every line casts the pulses whose flat-ground footprint falls in the square of its own
        frame (:meth:`ground_rays`; for a line at another heading a rotated square, which still
        covers the disc of radius ``half_size_m``).

        Parameters
        ----------
        center_xy, half_size_m
            The square of flat ground whose pulses are cast, metres.
        rng : numpy.random.Generator
            Draws, in this order: one phase per line (when ``phase_s`` is None), then one shift per
            heading (plans of more than one line per heading, when ``lateral_shift_m`` is None).
        phase_s : float, optional
            Time of every line's first pulse, seconds; None: drawn per line, uniformly over one
            scan-line period.
        lateral_shift_m : float or sequence of float, optional
            Shift of each heading's block of lines across track, metres (:meth:`flight_lines`);
            None: drawn per heading, uniformly in ``±s/2`` (s: the flight-line spacing), for plans
            of more than one line per heading; 0 for one line (which then flies over ``y = 0``).

        Returns
        -------
        Pulses
            World frame, one origin per pulse (the aircraft's position); ``pulse_id`` the pulse's
            row among all the plan's pulses, line by line; ``time_s`` its firing time on the plan's
            clock (the lines flown one after another from 0 on, :mod:`~zbuf_occlude.sensors.patterns.flight_times`:
            line ``i`` at ``line_start_s[i]`` plus ``(x + L/2) / v`` for the aircraft at x along it); ``scan_angle_deg`` the
            across-track angle from nadir signed as ASPRS LAS 1.4 defines it (counter-clockwise
            seen from behind the aircraft is positive: the right, −y, side of a line flown along
            +x); per point in ``meta``: ``scan_angle_deg`` (the angle θ, +y side positive) and
            ``line_id``; the beam's detection threshold applies with ρ = 1 where no reflectivity
            is given; in ``meta`` also ``line_length_m`` (L), ``line_start_s`` (per line, by id) and
            ``flight``, the aircraft's poses on that clock (:func:`~zbuf_occlude.sensors.patterns.flight_times.flown_poses`:
            the samples of a :class:`~zbuf_occlude.sensors.platform.Trajectory`).

        Raises
        ------
        InvalidInputError
            A non-finite or non-positive square, a non-finite phase or shift, more than
            :data:`~zbuf_occlude.sensors.checks.MAX_SENSOR_RAYS` rays in all (counted line by
            line, sub-rays included, before the rays are cast).
        """
        scanner = self
        n_total = scanner.n_lines * len(scanner.headings_deg)
        # draw order: phases (one per line), then shifts (one per heading, plans of > 1 line per
        # heading only), then the pipeline's noise and dropout; a single line draws one phase
        if phase_s is None:
            phases = [float(rng.uniform(0.0, 1.0 / scanner.line_rate_hz)) for _ in range(n_total)]
        else:
            phases = [real(phase_s, "phase_s")] * n_total
        if lateral_shift_m is None:
            s = scanner.flight_line_spacing_m
            shifts = [float(rng.uniform(-s / 2.0, s / 2.0)) if scanner.n_lines > 1 else 0.0 for _ in scanner.headings_deg]
        else:
            shifts = scanner._shifts(lateral_shift_m).tolist()
        parts = []
        length = line_length_m(center_xy, half_size_m)
        starts = line_start_s(np.arange(n_total), length, scanner.speed_mps, scanner.turn_s)
        lines = scanner.flight_lines(shifts)
        for line in lines:
            if line.is_reference:
                o, d, a, ts = scanner.ground_rays(center_xy, half_size_m, phases[line.line_id], with_time=True)
            else:
                c = line.to_line(np.asarray(center_xy, dtype=np.float64).reshape(2))
                o, d, a, ts = scanner.ground_rays(c, half_size_m, phases[line.line_id], with_time=True)
                along, across = line.axes()
                o = np.column_stack([o[:, :1] * along + (line.offset_m + o[:, 1:2]) * across, o[:, 2]])
                d = np.column_stack([d[:, :1] * along + d[:, 1:2] * across, d[:, 2]])
            flown = starts[line.line_id] + length / (2.0 * scanner.speed_mps)
            parts.append((o, d, a, np.full(len(a), line.line_id, np.int32), ts + flown))  # on the plan's clock
            n_rays = sum(len(p[2]) for p in parts)
            if n_rays * scanner.beam.footprint_rays > MAX_SENSOR_RAYS:  # every line is bounded on its own; the plan's lines add up
                raise InvalidInputError(
                    f"airborne scanner: {n_rays:,} pulses{' of footprint_rays sub-rays each' if scanner.beam.footprint_rays > 1 else ''} "
                    f"by line {line.line_id} of {n_total} over the square {2 * float(half_size_m):g} m wide, more than {MAX_SENSOR_RAYS:,} rays; "
                    "scan a smaller square, fly fewer lines or take fewer footprint_rays"
                )
        if len(parts) == 1:
            origins, directions, angle, line_id, fired = parts[0]
        else:
            origins, directions, angle, line_id, fired = (np.concatenate(arrays) for arrays in zip(*parts))
        meta = {"phase_s": phases[0], "line_phase_s": tuple(phases), "lateral_shift_m": tuple(float(v) for v in shifts),
                "line_length_m": length, "line_start_s": tuple(starts.tolist()),
                "flight": flown_poses(lines, length, scanner.altitude_m, scanner.speed_mps, scanner.turn_s)}  # fmt: skip
        return Pulses(
            directions, directions, origins, None, pulse_id=np.arange(len(origins), dtype=np.int64), time_s=fired,
            scan_angle_deg=(-angle).astype(np.float32), per_pulse_meta={"scan_angle_deg": angle, "line_id": line_id}, meta=meta,
            default_reflectivity=1.0, has_sensor_frame=False, home_m=np.array([0.0, 0.0, scanner.altitude_m]),
        )  # fmt: skip

    def with_(self, **changes) -> AirborneScanner:
        """A copy with some fields changed."""
        return replaced(self, **changes)

    def ground_rays(
        self, center_xy, half_size_m: float, phase_s: float = 0.0, *, with_time: bool = False
    ) -> tuple[NDArray[np.float64], ...]:
        """The pulses whose flat-ground footprint falls in the square ``center ± half_size_m``.

        Parameters
        ----------
        center_xy : (2,) float
            Square centre, metres (x along track, y across track; the flight line is ``y = 0``).
        half_size_m : float
        phase_s : float
            Time of the first line's first pulse, seconds (a random phase moves the lines).

        Returns
        -------
        origins : (N, 3) float64
            Aircraft position at each pulse, world frame, metres.
        directions : (N, 3) float64
            Unit beam directions ``(0, sin θ, −cos θ)``.
        scan_angle_deg : (N,) float64
            θ, degrees (negative: −y side).
        time_s : (N,) float64
            Only ``with_time``: each pulse's firing time, seconds (the aircraft is at x = 0 at
            time 0; the first line starts at ``phase_s``).

        Raises
        ------
        InvalidInputError
            A non-finite centre or phase, a half size not > 0, or more than
            :data:`~zbuf_occlude.sensors.checks.MAX_SENSOR_RAYS` pulses (counted before any is made).
        """
        cx, cy = (float(v) for v in center_xy)
        r = float(half_size_m)
        if not (math.isfinite(cx) and math.isfinite(cy) and math.isfinite(r) and r > 0 and math.isfinite(phase_s)):
            raise InvalidInputError("ground_rays needs a finite centre, phase and half size > 0")
        m = self.pulses_per_line
        period = 1.0 / self.line_rate_hz
        s = math.radians(self.swath_deg)
        theta_grid = -s / 2.0 + s * (np.arange(m) + 0.5) / m
        ground_y = self.altitude_m * np.tan(theta_grid)
        columns = np.flatnonzero(np.abs(ground_y - cy) <= r)
        if len(columns) == 0:
            return (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)) + ((np.zeros(0),) if with_time else ())
        # lines whose pulses can land in [cx - r, cx + r] (a line spans speed · period along track)
        line_length = self.speed_mps * period
        n_k = 2.0 * r / line_length + 3.0 if line_length > 0 else math.inf
        if not len(columns) * n_k <= MAX_SENSOR_RAYS:  # before arange(k0, k1) allocates them
            raise InvalidInputError(
                f"airborne scanner: the square {2 * r:g} m wide takes about {len(columns) * n_k:.3g} pulses per line, "
                f"more than {MAX_SENSOR_RAYS:,}; scan a smaller square or a sparser scanner"
            )
        k0 = math.floor((cx - r - self.speed_mps * phase_s) / line_length) - 1
        k1 = math.ceil((cx + r - self.speed_mps * phase_s) / line_length) + 1
        k = np.arange(k0, k1 + 1)
        reverse = (k % 2 == 1) if self.pattern == "oscillating" else np.zeros(len(k), bool)
        slot = np.where(reverse[:, None], m - 1 - columns[None, :], columns[None, :])  # pulse index within its line
        t = phase_s + k[:, None] * period + slot / self.pulse_rate_hz
        x = self.speed_mps * t
        theta = np.broadcast_to(theta_grid[columns][None, :], x.shape)
        keep = np.abs(x - cx) <= r
        x, theta, t = x[keep], theta[keep], t[keep]
        origins = np.column_stack([x, np.zeros_like(x), np.full_like(x, self.altitude_m)])
        directions = np.column_stack([np.zeros_like(x), np.sin(theta), -np.cos(theta)])
        return (origins, directions, np.degrees(theta)) + ((t,) if with_time else ())
