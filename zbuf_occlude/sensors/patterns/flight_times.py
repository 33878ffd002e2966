"""A flight plan in time: the lines of an airborne survey flown one after another, and the trajectory that flies them.

A real block's lines are minutes apart: the aircraft flies a line, turns, and flies the next.  Line ``i`` of a plan
(its ``line_id``, :meth:`~zbuf_occlude.sensors.patterns.airborne.AirborneScanner.flight_lines`) starts at

``T_i = i · (L / v + turn_s)``

seconds after the first, L the length each line is flown (:func:`line_length_m`), v the ground speed and ``turn_s``
the time between one line's end and the next line's start (the turn and the run-in; ``AirborneScanner.turn_s``).  Along
its line the aircraft is at ``−L/2`` (in the line's frame, x along track) at ``T_i`` and at ``+L/2`` at ``T_i + L/v``, so
every time of a scan is ≥ 0 and a later line's times all follow an earlier line's.  The turns are not modelled: the
flight's poses (:func:`flown_poses`) hold the straight, level lines, and between two lines whose headings differ by a
quarter turn or more, one pose half way in time, position and heading (a :class:`~zbuf_occlude.sensors.platform.Trajectory`
of them turns the short way between samples).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["TURN_S", "flown_poses", "line_length_m", "line_start_s"]

#: Seconds between the end of one flight line and the start of the next: a fixed-wing survey aircraft's procedure turn
#: and run-in take a few minutes (an ASSUMPTION: two minutes, a 180° turn at a standard rate of 3°/s plus the run-in).
TURN_S = 120.0
#: Seconds between the trajectory's samples along a line (its two ends are always samples).
SAMPLE_STEP_S = 1.0


def line_length_m(center_xy, half_size_m: float) -> float:
    """How far each line of a plan is flown over a scan of the square ``center_xy ± half_size_m`` (metres, world frame,
    the plan centred on the origin): ``2 (|c| + √2 r)``, the diameter of the disc about the plan centre that holds the
    square, so that every line, at any heading or offset, is flown across the whole square."""
    cx, cy = (float(v) for v in center_xy)
    return 2.0 * (math.hypot(cx, cy) + math.sqrt(2.0) * float(half_size_m))


def line_start_s(line_id, length_m: float, speed_mps: float, turn_s: float) -> NDArray[np.float64]:
    """Start times ``T_i = i · (L / v + turn_s)`` of lines ``line_id`` (int or array), seconds (module docstring)."""
    return np.asarray(line_id, dtype=np.float64) * (float(length_m) / float(speed_mps) + float(turn_s))


def flown_poses(lines, length_m: float, altitude_m: float, speed_mps: float, turn_s: float) -> tuple[NDArray[np.float64], ...]:
    """The aircraft's poses flying ``lines`` (:class:`~zbuf_occlude.sensors.patterns.airborne.FlightLine`, in flight
    order) one after another (module docstring): samples every :data:`SAMPLE_STEP_S` along each line and at its two
    ends, at ``altitude_m``, the sensor frame's x along the line, y to its left, z up.

    Returns
    -------
    time_s : (T,) float64
        On the scan's clock (line 0 starts at 0), strictly increasing.
    position_m : (T, 3) float64
        World frame, metres.
    rotation : (T, 3, 3) float64
        Sensor → world: a :class:`~zbuf_occlude.sensors.platform.Trajectory`'s samples.
    """
    duration = float(length_m) / float(speed_mps)
    times, positions, rotations = [], [], []
    previous = None
    for line in lines:
        along, across = line.axes()
        start = float(line_start_s(line.line_id, length_m, speed_mps, turn_s))
        steps = np.unique(np.append(np.arange(0.0, duration, SAMPLE_STEP_S), duration))
        xy = (line.offset_m * across)[None, :] + (speed_mps * steps - length_m / 2.0)[:, None] * along[None, :]
        if previous is not None and abs(_turn_deg(previous[2], line.heading_deg)) >= 90.0:  # a half-way pose: turn the short way
            t0, p0, h0 = previous
            times.append([(t0 + start) / 2.0])
            positions.append([[(p0[0] + xy[0, 0]) / 2.0, (p0[1] + xy[0, 1]) / 2.0, altitude_m]])
            rotations.append(_heading_rotation(h0 + _turn_deg(h0, line.heading_deg) / 2.0)[None])
        rotation = _heading_rotation(line.heading_deg)
        times.append(start + steps)
        positions.append(np.column_stack([xy, np.full(len(steps), float(altitude_m))]))
        rotations.append(np.repeat(rotation[None], len(steps), axis=0))
        previous = (start + duration, xy[-1], line.heading_deg)
    return np.concatenate(times), np.concatenate(positions), np.concatenate(rotations)


def _heading_rotation(heading_deg: float) -> NDArray[np.float64]:
    """(3, 3) float64: sensor → world for level flight at ``heading_deg`` (x along it, y to its left, z up)."""
    phi = math.radians(heading_deg)
    return np.array([[math.cos(phi), -math.sin(phi), 0.0], [math.sin(phi), math.cos(phi), 0.0], [0.0, 0.0, 1.0]])


def _turn_deg(from_deg: float, to_deg: float) -> float:
    """The signed turn from one heading to another the short way, degrees in (−180, 180]."""
    d = (to_deg - from_deg) % 360.0
    return d - 360.0 if d > 180.0 else d
