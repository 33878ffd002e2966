"""The pulses a scan pattern fires: where each leaves from, where it points, when, and its labels.

A scan pattern (:class:`~zbuf_occlude.sensors.patterns.spinning.Lidar`'s rings, an airborne scanner's lines,
a :class:`~zbuf_occlude.sensors.patterns.ray_table.RayTable`'s rows) makes :class:`Pulses`; the one
pipeline (:func:`zbuf_occlude.sensors.scan.fire_pulses`, behind :func:`~zbuf_occlude.sensors.scan.scan` and
:func:`~zbuf_occlude.sensors.scan.scan_airborne`) casts them with the scanner's beam and turns the
echoes into a :class:`~zbuf_occlude.sensors.scan_data.Scan`, whatever made them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["Pulses"]


@dataclass
class Pulses:
    """P pulses, in firing order.

    Attributes
    ----------
    directions_sensor : (P, 3) float64
        Unit beam axes in the sensor frame at each pulse's firing time (LiDAR: x forward, y left,
        z up); an airborne scanner, which has no one sensor frame, gives the world directions.
    directions : (P, 3) float64
        The same axes in the world frame.
    origins : (3,) or (P, 3) float64
        Where the pulses leave, world frame, metres: one point for a scanner that stands still
        during the sweep, else one per pulse (a moving platform).
    rotation : (3, 3) float64 or None
        Sensor → world rotation of a scanner standing still (with ``origins`` (3,)); None for a
        moving one.
    pulse_id, time_s : (P,) int64, (P,) float64
        Each pulse's id (unique in the scan) and firing time, seconds.
    scan_angle_deg : (P,) float32
        The LAS scan angle: a spinning scanner's beam elevation, an airborne one's across-track
        angle (ASPRS LAS 1.4's sign).
    ring : (P,) int64 or None
        The spinning scanner's beam (row of ``elevations_deg``).
    per_pulse_meta : dict of str to (P,) arrays
        Labels the scan's ``meta`` carries per point (an airborne flight line's ``line_id``).
    meta : dict
        Values for the scan's ``meta`` (phases, shifts, ray counts).
    default_reflectivity : float or None
        ρ the detection threshold is applied with where the scan is given no reflectivity (an
        airborne scanner's: 1), or None (no radiometric detection
        without reflectivities).
    rotations : (P, 3, 3) float64 or None
        A moving scanner's sensor → world rotation at each pulse, where its points can be given in
        the sensor frame of their time; None otherwise.
    has_sensor_frame : bool
        Whether the scan's points can be given in a sensor frame (False: an airborne scan, whose
        pulses' frames follow the aircraft along several lines).
    home_m : (3,) float64 or None
        The scan's ``sensor_position`` (world frame) where no return is kept; None: where the first pulse leaves
        (:meth:`home`).
    """

    directions_sensor: NDArray[np.float64]
    directions: NDArray[np.float64]
    origins: NDArray[np.float64]
    rotation: NDArray[np.float64] | None
    pulse_id: NDArray[np.int64]
    time_s: NDArray[np.float64]
    scan_angle_deg: NDArray[np.float32]
    ring: NDArray[np.int64] | None = None
    per_pulse_meta: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
    default_reflectivity: float | None = None
    rotations: NDArray[np.float64] | None = None
    has_sensor_frame: bool = True
    home_m: NDArray[np.float64] | None = None

    def __len__(self) -> int:
        return len(self.directions)

    def home(self) -> NDArray[np.float64]:
        """(3,) float64: :attr:`home_m`, or where the first pulse leaves (the world origin without pulses)."""
        if self.home_m is not None:
            return self.home_m
        return self.origins if self.origins.ndim == 1 else self.origins[0] if len(self.origins) else np.zeros(3)

    @property
    def static(self) -> bool:
        """Whether every pulse leaves from one point with one attitude (a scanner standing still)."""
        return self.rotation is not None


def placed(directions_sensor: NDArray[np.float64], time_s: NDArray[np.float64], platform) -> tuple[NDArray[np.float64], ...]:
    """``(directions, origins, rotation, rotations, time_s)`` of pulses fired along ``directions_sensor (P, 3)`` at
    ``time_s (P,)`` seconds from the sweep's start, by a scanner on ``platform``.

    ``platform`` is a (4, 4) sensor → world pose (the scanner stands still: one origin, one
    rotation, times as given) or a :class:`~zbuf_occlude.sensors.platform.Trajectory` (each
    pulse gets the pose at ``start_s + time_s``, and that time; a trajectory of one pose stands
    still).  ``rotation`` is the one (3, 3) rotation of a scanner standing still, else None;
    ``rotations`` (P, 3, 3) each pulse's on a moving one, else None.
    """
    if isinstance(platform, np.ndarray):
        rot, origin = platform[:3, :3], platform[:3, 3]
        return directions_sensor @ rot.T, origin, rot, None, time_s
    t = platform.start_s + time_s
    if platform.is_static:
        pose = platform.pose_at(platform.start_s)
        rot, origin = pose[:3, :3], pose[:3, 3]
        return directions_sensor @ rot.T, origin, rot, None, t
    rotations, origins = platform.poses_at(t)
    return np.einsum("pij,pj->pi", rotations, directions_sensor), origins, None, rotations, t
