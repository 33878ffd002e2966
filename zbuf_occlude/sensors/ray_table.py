"""A ray table as a sensor: one ``(time, azimuth, elevation)`` row per pulse, fired in order.

Non-repetitive scanners (Livox Avia, Mid-40 and Mid-70 rosettes, DJI Zenmuse L2) and hybrid
solid-state units fire along a pattern that no beam table and spin rate describe.  Their users
can give that pattern as a table (:mod:`zbuf_occlude.io.ray_tables` reads CSV and ``.npy``):
:class:`RayTable` scans like a :class:`~zbuf_occlude.sensors.lidar.Lidar` whose rays are the
table's rows, in the LiDAR's sensor frame and angle convention
(:func:`~zbuf_occlude.sensors.lidar.beam_directions`: x forward at azimuth 0°, y left at +90°,
z up at elevation +90°), with each point's time the table's time of its pulse.

:func:`rosette_table` makes a Livox-like rosette table, an approximation for trying the sensor
without a recorded pattern.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.ray_tables import read_ray_table
from zbuf_occlude.sensors.checks import MAX_RANGE_M, MAX_SENSOR_RAYS, count, located, real, reals, sensor_name, shown, text
from zbuf_occlude.sensors.footprint import check_resolved_footprint, footprint_offsets, subray_directions
from zbuf_occlude.sensors.lidar import Lidar, beam_directions

__all__ = ["ROSETTE_FOV_DEG", "ROSETTE_PRISM_HZ", "RayTable", "load_ray_table", "rosette_table"]

#: Circular field of view of the Livox Mid-40, full angle, degrees (Livox Mid-40 data sheet;
#: Liu et al. 2020, §II).
ROSETTE_FOV_DEG = 38.4
#: Rotation rates of the two prisms of :func:`rosette_table`, revolutions per second, opposite
#: signs (counter-rotating).  An ASSUMPTION: Livox does not publish its prisms' rates; these two
#: have the golden ratio as their ratio, so the pattern never repeats.
ROSETTE_PRISM_HZ = (100.0, -100.0 / ((1.0 + math.sqrt(5.0)) / 2.0))


@dataclass(frozen=True, eq=False)
class RayTable:
    """A LiDAR that fires along a table of directions, one row per pulse, each at its own time.

    Parameters
    ----------
    name : str
        User name (metadata; it names output files).
    time_s : (N,) float
        Firing time of each pulse, seconds, non-decreasing (any origin: a GPS week's seconds, or
        0 at the first pulse).  Each point of a scan carries its pulse's time, exactly
        (``Scan.gps_time``).
    azimuth_deg, elevation_deg : (N,) float
        Direction of each pulse in the sensor frame, degrees: azimuth from +x towards +y,
        elevation above the xy plane, in [−90°, 90°]
        (:func:`~zbuf_occlude.sensors.lidar.beam_directions`).
    min_range_m, max_range_m, range_noise_m, dropout : float
        As :class:`~zbuf_occlude.sensors.lidar.Lidar`'s (dropout: one probability at every range).
    beam_divergence_deg, footprint_rays, beam_profile, max_returns, range_resolution_m : float, int, str
        The footprint and multi-return model, as :class:`~zbuf_occlude.sensors.lidar.Lidar`'s;
        ``footprint_rays`` above 1 needs ``max_returns`` above 1 (a table's footprint is resolved
        into returns by :func:`~zbuf_occlude.sensors.echo_model.echo_returns`, as the airborne
        scanner's is).
    detection_reflectivity, detection_range_m, power_noise : float
        The radiometric detection threshold and power noise, as
        :class:`~zbuf_occlude.sensors.lidar.Lidar`'s (used when ``scan`` gets ``reflectivity``).
    source : str
        Where the table comes from (metadata).

    Attributes
    ----------
    time_s, azimuth_deg, elevation_deg : (N,) float64
        Read-only copies of the columns.

    Raises
    ------
    InvalidInputError
        Naming the field (``ray table 'avia': time_s[3] ...``): columns that are not 1-D arrays
        of real numbers (bools refused) or of different lengths; fewer than 1 or more than
        :data:`~zbuf_occlude.sensors.checks.MAX_SENSOR_RAYS` rows; a value that is not finite;
        a time below the one before it; an elevation outside [−90°, 90°]; the scalar fields as
        :class:`~zbuf_occlude.sensors.lidar.Lidar` refuses them; ``footprint_rays`` above 1
        with ``max_returns`` 1; a name that cannot name files.

    Notes
    -----
    Scanned by :func:`~zbuf_occlude.sensors.scan.scan`: each point's ``pulse_id`` is its row,
    ``gps_time`` its row's ``time_s``, ``scan_angle_deg`` its row's elevation (the spinning
    scanner's scan angle); ``ring`` is None.
    """

    name: str
    time_s: NDArray[np.float64]
    azimuth_deg: NDArray[np.float64]
    elevation_deg: NDArray[np.float64]
    min_range_m: float = 1.0
    max_range_m: float = 100.0
    range_noise_m: float = 0.02
    dropout: float = 0.0
    beam_divergence_deg: float = 0.0
    footprint_rays: int = 1
    beam_profile: str = "tophat"
    max_returns: int = 1
    range_resolution_m: float = 0.0
    detection_reflectivity: float = 0.8
    detection_range_m: float = 100.0
    power_noise: float = 0.0
    source: str = ""

    #: One return per pulse is the centre ray's first hit: no mixed-pixel merge (``Lidar.echo_separation_m`` 0).
    echo_separation_m = 0.0

    def __post_init__(self) -> None:
        sensor_name(self.name, "ray table name")
        with located(f"ray table {self.name!r}"):
            self._check_columns()
            self._check_model()

    def _check_columns(self) -> None:
        """The three columns: 1-D real numbers of one length, finite, time non-decreasing, elevations within ±90°."""
        columns = {}
        for name in ("time_s", "azimuth_deg", "elevation_deg"):
            value = getattr(self, name)
            n = len(value) if hasattr(value, "__len__") else -1
            if not 1 <= n <= MAX_SENSOR_RAYS:
                raise InvalidInputError(f"{name} must be a list of 1 to {MAX_SENSOR_RAYS:,} numbers (one per pulse), got {shown(value)}")
            a = np.asarray(value)
            if a.ndim != 1 or a.dtype.kind not in "fiu":
                raise InvalidInputError(f"{name} must be a 1-D array of real numbers, got shape {a.shape} dtype {a.dtype}")
            a = np.array(a, dtype=np.float64)  # a copy: the caller's array may change
            bad = np.flatnonzero(~np.isfinite(a))
            if len(bad):
                raise InvalidInputError(
                    f"{name}[{bad[0]}] must be a finite number, got {float(a[bad[0]])!r} ({len(bad):,} rows not finite)"
                )
            a.flags.writeable = False
            columns[name] = a
        lengths = {len(a) for a in columns.values()}
        if len(lengths) > 1:
            raise InvalidInputError(f"time_s, azimuth_deg and elevation_deg must have one length, got {[len(a) for a in columns.values()]}")
        back = np.flatnonzero(np.diff(columns["time_s"]) < 0)
        if len(back):
            i = back[0] + 1
            raise InvalidInputError(
                f"time_s must not decrease: time_s[{i}] = {float(columns['time_s'][i])!r} < time_s[{i - 1}] = {float(columns['time_s'][i - 1])!r}"
            )
        out = np.flatnonzero(np.abs(columns["elevation_deg"]) > 90.0)
        if len(out):
            raise InvalidInputError(f"elevation_deg[{out[0]}] must be in [-90, 90], got {float(columns['elevation_deg'][out[0]])!r}")
        for name, a in columns.items():
            object.__setattr__(self, name, a)

    def _check_model(self) -> None:
        """The range, noise, footprint and return fields, by :mod:`~zbuf_occlude.sensors.checks` as the LiDAR's."""
        positive, at_least_0, ranges = {"low": 0.0, "low_open": True}, {"low": 0.0}, {"high": MAX_RANGE_M}
        numbers = {
            "min_range_m": {**at_least_0, **ranges}, "max_range_m": {**positive, **ranges}, "range_noise_m": {**at_least_0, **ranges},
            "dropout": {"low": 0.0, "high": 1.0, "high_open": True}, "beam_divergence_deg": {**at_least_0, "high": 90.0},
            "range_resolution_m": {**at_least_0, **ranges}, "detection_reflectivity": positive,
            "detection_range_m": {**positive, **ranges}, "power_noise": at_least_0,
        }  # fmt: skip
        for name, bounds in numbers.items():
            object.__setattr__(self, name, real(getattr(self, name), name, **bounds))
        text(self.source, "source")
        if self.min_range_m >= self.max_range_m:
            raise InvalidInputError(f"need min_range_m < max_range_m, got {self.min_range_m} >= {self.max_range_m}")
        check_resolved_footprint(self, "a ray table's footprint")

    def __len__(self) -> int:
        """N, the table's rows (pulses)."""
        return len(self.time_s)

    @property
    def multi_return(self) -> bool:
        """Whether the multi-return model is on (``max_returns`` above 1)."""
        return self.max_returns > 1

    @property
    def detection_threshold(self) -> float:
        """τ = ``detection_reflectivity / detection_range_m²``, m⁻², as :attr:`Lidar.detection_threshold <zbuf_occlude.sensors.lidar.Lidar.detection_threshold>`."""
        return self.detection_reflectivity / self.detection_range_m**2

    def dropout_probability(self, range_m: ArrayLike) -> NDArray[np.float64]:
        """``dropout`` for every return, float64 of ``range_m``'s shape (no range dependence)."""
        return np.full(np.shape(range_m), float(self.dropout))

    def footprint_weights(self) -> NDArray[np.float64]:
        """(K,) float64: each sub-ray's share of the pulse's energy (:func:`~zbuf_occlude.sensors.footprint.footprint_offsets`)."""
        return footprint_offsets(self.footprint_rays, self.beam_divergence_deg, profile=self.beam_profile)[1]

    def footprint_directions(self, directions: ArrayLike) -> NDArray[np.float64]:
        """(N, K, 3) float64: the K = ``footprint_rays`` unit sub-rays of each pulse ``directions (N, 3)``, ray 0 the centre
        (:func:`~zbuf_occlude.sensors.footprint.subray_directions`, as the LiDAR's)."""
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        return subray_directions(d, footprint_offsets(self.footprint_rays, self.beam_divergence_deg)[0])

    def with_(self, **changes) -> RayTable:
        """A copy with some fields changed, checked again."""
        return replace(self, **changes)

    def rays(
        self, azimuth_range_deg: tuple[float, float] | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64]]:
        """Unit pulse directions, sensor frame, in table order: the contract of :meth:`Lidar.rays <zbuf_occlude.sensors.lidar.Lidar.rays>`.

        Parameters
        ----------
        azimuth_range_deg : (lo, hi), optional
            Keep only rows with azimuth in ``[lo, hi]`` degrees (wrapped to a turn); default: all.

        Returns
        -------
        directions : (N', 3) float64
            :func:`~zbuf_occlude.sensors.lidar.beam_directions` of the rows' elevations and azimuths.
        row : (N',) int64
            Each ray's row in the table (the pulse id).
        azimuth_deg : (N',) float64
        """
        row = np.arange(len(self), dtype=np.int64)
        if azimuth_range_deg is not None:
            lo, hi = (float(v) for v in azimuth_range_deg)
            if hi - lo < 360.0:
                row = row[np.mod(self.azimuth_deg - lo, 360.0) <= np.mod(hi - lo, 360.0)]
        return beam_directions(self.elevation_deg[row], self.azimuth_deg[row]), row, self.azimuth_deg[row]

    @classmethod
    def from_lidar(cls, lidar: Lidar, name: str | None = None) -> RayTable:
        """The table of one revolution of ``lidar``, in firing order: firing ``i`` of ring ``b`` is row ``i · n_beams + b``.

        Each row is fired at ``(i + b / n_beams) / (n_azimuths · rotation_hz)`` seconds, the LiDAR's own
        ``gps_time``, along the LiDAR's own direction
        (:func:`~zbuf_occlude.sensors.lidar.beam_directions` of the same angles).  The range,
        noise, dropout, footprint and return fields are the LiDAR's.  Without noise or dropout, a
        scan by the table has the LiDAR's points, pulse by pulse (the pulses' order differs: the
        LiDAR's is ring by ring, the table's by time, so noise draws fall on other pulses).

        Raises
        ------
        InvalidInputError
            ``lidar`` models what a table does not: a range-dependent dropout, a mixed-pixel
            ``echo_separation_m``, or a footprint with one return per pulse.
        """
        if lidar.dropout_range_per_m or lidar.echo_separation_m or (lidar.footprint_rays > 1 and lidar.max_returns == 1):
            raise InvalidInputError(
                f"lidar {lidar.name!r}: a ray table models neither dropout_range_per_m, echo_separation_m nor a footprint with one return per pulse"
            )
        firing = np.repeat(np.arange(lidar.n_azimuths, dtype=np.int64), lidar.n_beams)
        ring = np.tile(np.arange(lidar.n_beams, dtype=np.int64), lidar.n_azimuths)
        fields = ("min_range_m", "max_range_m", "range_noise_m", "dropout", "beam_divergence_deg", "footprint_rays", "beam_profile",
                  "max_returns", "range_resolution_m", "detection_reflectivity", "detection_range_m", "power_noise", "source")  # fmt: skip
        return cls(
            name or lidar.name, (firing + ring / lidar.n_beams) / (lidar.n_azimuths * lidar.rotation_hz), lidar.azimuths_deg[firing],
            np.asarray(lidar.elevations_deg)[ring], **{f: getattr(lidar, f) for f in fields},
        )  # fmt: skip


def load_ray_table(path: str | os.PathLike, *, name: str | None = None, within: str | os.PathLike | None = None, **fields) -> RayTable:
    """A :class:`RayTable` from a ``.csv`` or ``.npy`` file (:func:`~zbuf_occlude.io.ray_tables.read_ray_table`).

    Parameters
    ----------
    path : str or PathLike
    name : str, optional
        The sensor's name; default: the file's stem.
    within : str or PathLike, optional
        The folder ``path`` was named from: it must stay inside it, links resolved.
    **fields
        Other :class:`RayTable` fields (ranges, noise, the return model).

    Raises
    ------
    ArgumentTypeError
        ``path`` or ``within`` is not a path (naming the argument and the value).
    InvalidInputError
        One line naming the file: what :func:`~zbuf_occlude.io.ray_tables.read_ray_table`
        refuses (more rows than :data:`~zbuf_occlude.sensors.checks.MAX_SENSOR_RAYS` among
        them), or a column :class:`RayTable` refuses (NaN, time decreasing, elevation beyond ±90°).
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    time_s, azimuth_deg, elevation_deg = read_ray_table(path, max_rows=MAX_SENSOR_RAYS, within=within)
    with located(str(path)):
        return RayTable(Path(path).stem if name is None else name, time_s, azimuth_deg, elevation_deg, **fields)


def rosette_table(
    n_pulses: int, *, duration_s: float, fov_deg: float = ROSETTE_FOV_DEG, prism_hz: tuple[float, float] = ROSETTE_PRISM_HZ,
    name: str = "rosette", **fields,
) -> RayTable:  # fmt: skip
    """A Livox-like rosette: the non-repetitive pattern of two counter-rotating Risley prisms.

    Livox's Mid-40 and Avia steer one beam by two wedge prisms spinning in opposite directions;
    the beam draws a rosette whose petals pass through the centre of a circular field of view
    and turn a little each pass, so the pattern never repeats and covers more of the field the
    longer it integrates (Liu, Z., Zhang, F. & Hong, X., 2020, "Loam_livox: A fast, robust,
    high-precision LiDAR odometry and mapping package for LiDARs of small FoV", ICRA 2020,
    §II and Fig. 2).  To first order each prism deflects the beam by a fixed angle about its own
    rotation, and the deflections add: the off-axis angle at time ``t`` is the 2-D vector
    ``δ (cos 2π f₁t, sin 2π f₁t) + δ (cos 2π f₂t, sin 2π f₂t)``, ``δ = fov_deg / 4`` (both
    prisms alike: the petals reach the centre and the edge).  This is an APPROXIMATION: the
    prisms' rates are not published (:data:`ROSETTE_PRISM_HZ`), and neither are the Avia's six
    beams nor the prisms' second-order terms; record your unit's table for its real pattern.

    Parameters
    ----------
    n_pulses : int
        Rows, 1 to :data:`~zbuf_occlude.sensors.checks.MAX_SENSOR_RAYS`, fired evenly over
        ``[0, duration_s)`` (the Mid-40 fires 100,000 pulses per second).
    duration_s : float
        Seconds the table spans, > 0.
    fov_deg : float
        Full angle of the circular field of view about +x, degrees in (0, 180).
    prism_hz : (2,) float
        The prisms' rotation rates, revolutions per second (opposite signs: counter-rotating).
    name : str
    **fields
        Other :class:`RayTable` fields (ranges, noise, the return model).

    Returns
    -------
    RayTable
        Times ``duration_s · i / n_pulses`` seconds; directions within ``fov_deg / 2`` of +x.

    Raises
    ------
    InvalidInputError
        Naming the argument out of range, or a field :class:`RayTable` refuses.
    """
    n = count(n_pulses, "n_pulses", low=1, high=MAX_SENSOR_RAYS)
    duration = real(duration_s, "duration_s", low=0.0, low_open=True)
    fov = real(fov_deg, "fov_deg", low=0.0, high=180.0, low_open=True, high_open=True)
    f1, f2 = reals(prism_hz, "prism_hz", lengths=(2,))
    t = duration * (np.arange(n, dtype=np.float64) / n)
    delta = math.radians(fov) / 4.0
    u = delta * (np.cos(2 * np.pi * f1 * t) + np.cos(2 * np.pi * f2 * t))  # towards +y
    v = delta * (np.sin(2 * np.pi * f1 * t) + np.sin(2 * np.pi * f2 * t))  # towards +z
    off, around = np.hypot(u, v), np.arctan2(v, u)
    x, y, z = np.cos(off), np.sin(off) * np.cos(around), np.sin(off) * np.sin(around)
    azimuth, elevation = np.degrees(np.arctan2(y, x)), np.degrees(np.arcsin(np.clip(z, -1.0, 1.0)))
    return RayTable(name, t, azimuth, elevation, **fields)
