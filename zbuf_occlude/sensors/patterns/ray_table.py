"""A ray table as a sensor: one ``(time, azimuth, elevation)`` row per pulse, fired in order.

Non-repetitive scanners (Livox Avia, Mid-40 and Mid-70 rosettes, DJI Zenmuse L2) and hybrid
solid-state units fire along a pattern that no beam table and spin rate describe.  Their users
can give that pattern as a table (:mod:`zbuf_occlude.io.ray_tables` reads CSV and ``.npy``):
:class:`RayTable` scans like a :class:`~zbuf_occlude.sensors.patterns.spinning.Lidar` whose rays are the
table's rows, in the LiDAR's sensor frame and angle convention
(:func:`~zbuf_occlude.sensors.patterns.spinning.beam_directions`: x forward at azimuth 0°, y left at +90°,
z up at elevation +90°), with each point's time the table's time of its pulse.

:func:`rosette_table` makes a Livox-like rosette table, an approximation for trying the sensor
without a recorded pattern.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.ray_tables import read_ray_table
from zbuf_occlude.sensors.checks import MAX_SENSOR_RAYS, count, located, real, reals, replaced, sensor_name, text, value_kind
from zbuf_occlude.sensors.beam.fields import IDEAL_BEAM, Beam, check_beam
from zbuf_occlude.sensors.patterns.spinning import Lidar, beam_directions, in_sector
from zbuf_occlude.sensors.pulses import Pulses, placed

__all__ = ["RAY_TABLE_FILE_BEAM", "RAY_TABLE_PRESETS", "ROSETTE_FOV_DEG", "ROSETTE_PRISM_HZ", "RayTable", "load_ray_table", "rosette_table"]

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
        (:func:`~zbuf_occlude.sensors.patterns.spinning.beam_directions`).
    beam : Beam
        The pulse and its receiver (:class:`~zbuf_occlude.sensors.beam.fields.Beam`); default the ``ideal`` beam.
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
        a time below the one before it; an elevation outside [−90°, 90°]; a ``beam`` that is not
        a Beam; a name that cannot name files.

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
    beam: Beam = IDEAL_BEAM
    source: str = ""

    def __post_init__(self) -> None:
        sensor_name(self.name, "ray table name")
        with located("ray table"):  # not by its name: a sensor file's name is one of its values, never quoted
            self._check_columns()
            self._check_model()

    def _check_columns(self) -> None:
        """The three columns: 1-D real numbers of one length, finite, time non-decreasing, elevations within ±90°."""
        columns = {}
        for name in ("time_s", "azimuth_deg", "elevation_deg"):
            value = getattr(self, name)
            n = len(value) if hasattr(value, "__len__") else -1
            if not 1 <= n <= MAX_SENSOR_RAYS:
                raise InvalidInputError(
                    f"{name} must be a list of 1 to {MAX_SENSOR_RAYS:,} numbers (one per pulse), got {value_kind(value)}"
                )
            a = np.asarray(value)
            if a.ndim != 1 or a.dtype.kind not in "fiu":
                raise InvalidInputError(f"{name} must be a 1-D array of real numbers, got shape {a.shape} dtype {a.dtype.name}")
            a = np.array(a, dtype=np.float64)  # a copy: the caller's array may change
            bad = np.flatnonzero(~np.isfinite(a))
            if len(bad):
                raise InvalidInputError(
                    f"{name}[{bad[0]}] must be a finite number, got {value_kind(float(a[bad[0]]))} ({len(bad):,} rows not finite)"
                )
            a.flags.writeable = False
            columns[name] = a
        lengths = {len(a) for a in columns.values()}
        if len(lengths) > 1:
            raise InvalidInputError(f"time_s, azimuth_deg and elevation_deg must have one length, got {[len(a) for a in columns.values()]}")
        back = np.flatnonzero(np.diff(columns["time_s"]) < 0)
        if len(back):
            i = back[0] + 1
            raise InvalidInputError(f"time_s must not decrease: time_s[{i}] is below time_s[{i - 1}]")
        out = np.flatnonzero(np.abs(columns["elevation_deg"]) > 90.0)
        if len(out):
            raise InvalidInputError(
                f"elevation_deg[{out[0]}] must be in [-90, 90], got a number outside that range ({len(out):,} rows outside)"
            )
        for name, a in columns.items():
            object.__setattr__(self, name, a)

    def _check_model(self) -> None:
        """The source and the beam."""
        text(self.source, "source")
        check_beam(self.beam)

    def __len__(self) -> int:
        """N, the table's rows (pulses)."""
        return len(self.time_s)

    @property
    def sweep_s(self) -> float:
        """Seconds one sweep of the table lasts: its last row's time less its first's."""
        return float(self.time_s[-1] - self.time_s[0])

    def with_(self, **changes) -> RayTable:
        """A copy with some fields changed, checked again."""
        return replaced(self, **changes)

    def rays(
        self, azimuth_range_deg: tuple[float, float] | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64]]:
        """Unit pulse directions, sensor frame, in table order: the contract of :meth:`Lidar.rays <zbuf_occlude.sensors.patterns.spinning.Lidar.rays>`.

        Parameters
        ----------
        azimuth_range_deg : (lo, hi), optional
            Keep only rows with azimuth in ``[lo, hi]`` degrees (wrapped to a turn); default: all.

        Returns
        -------
        directions : (N', 3) float64
            :func:`~zbuf_occlude.sensors.patterns.spinning.beam_directions` of the rows' elevations and azimuths.
        row : (N',) int64
            Each ray's row in the table (the pulse id).
        azimuth_deg : (N',) float64
        """
        row = np.arange(len(self), dtype=np.int64)
        if azimuth_range_deg is not None:
            row = row[in_sector(self.azimuth_deg, azimuth_range_deg)]
        return beam_directions(self.elevation_deg[row], self.azimuth_deg[row]), row, self.azimuth_deg[row]

    def pulses(self, platform, azimuth_range_deg: tuple[float, float] | None = None) -> Pulses:
        """The table's pulses (:meth:`rays`) fired from ``platform`` (:func:`~zbuf_occlude.sensors.pulses.placed`).

        ``pulse_id`` is the row, the scan angle the row's elevation.  From a fixed pose each pulse
        keeps its row's ``time_s`` exactly; on a trajectory, the table's first row fires at the
        trajectory's start and the rest ``time_s − time_s[0]`` after it.
        """
        d_sensor, row, _ = self.rays(azimuth_range_deg)
        relative = self.time_s[row] - self.time_s[0]
        directions, origins, rotation, rotations, time_s = placed(d_sensor, relative, platform)
        if isinstance(platform, np.ndarray):
            time_s = self.time_s[row]
        return Pulses(d_sensor, directions, origins, rotation, pulse_id=row, time_s=time_s,
                      scan_angle_deg=self.elevation_deg[row].astype(np.float32), rotations=rotations)  # fmt: skip

    @classmethod
    def from_lidar(cls, lidar: Lidar, name: str | None = None) -> RayTable:
        """The table of one revolution of ``lidar``, in firing order: firing ``i`` of ring ``b`` is row ``i · n_beams + b``.

        Each row is fired at ``(i + b / n_beams) / (n_azimuths · rotation_hz)`` seconds, the LiDAR's own
        ``gps_time``, along the LiDAR's own direction
        (:func:`~zbuf_occlude.sensors.patterns.spinning.beam_directions` of the same angles), with the LiDAR's beam.  Without noise or dropout, a
        scan by the table has the LiDAR's points, pulse by pulse (the pulses' order differs: the
        LiDAR's is ring by ring, the table's by time, so noise draws fall on other pulses).

        The table fires the LiDAR's beam as it is: the one pipeline models every beam for every
        pattern (range-dependent dropout, mixed pixels, a footprint with one return per pulse).
        """
        firing = np.repeat(np.arange(lidar.n_azimuths, dtype=np.int64), lidar.n_beams)
        ring = np.tile(np.arange(lidar.n_beams, dtype=np.int64), lidar.n_azimuths)
        return cls(
            name or lidar.name, (firing + ring / lidar.n_beams) / (lidar.n_azimuths * lidar.rotation_hz), lidar.azimuths_deg[firing],
            np.asarray(lidar.elevations_deg)[ring], beam=lidar.beam, source=lidar.source,
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
        Other :class:`RayTable` fields: ``beam=`` (a :class:`~zbuf_occlude.sensors.beam.fields.Beam`: the
        ranges, noise and return model) and ``source=``.

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
        Other :class:`RayTable` fields: ``beam=`` (a :class:`~zbuf_occlude.sensors.beam.fields.Beam`: the
        ranges, noise and return model) and ``source=``.

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


#: The beam ``scan --ray-table FILE`` fires a table file with: a generic 905 nm receiver, ranges 1–100 m, σ 0.02 m,
#: τ = 0.8 / 100² (a generic receiver, not a device).
RAY_TABLE_FILE_BEAM = Beam(
    "generic-905",
    min_range_m=1.0,
    max_range_m=100.0,
    range_noise_m=0.02,
    detection_threshold=0.8 / 100.0**2,
    source="zbuf_occlude's generic receiver for a ray table file (ASSUMPTION: ranges 1-100 m, 0.02 m noise; not a data sheet)",
)

# Livox Mid-70 (Livox Mid-70 user manual v1.2 and data sheet): a Risley-prism scanner of 70.4°
# circular field of view, 100,000 points per second (first return), 905 nm, range precision
# 2 cm (1σ at 20 m), 90 m at 10 % reflectivity and 260 m at 80 %, minimal detection range
# 0.05 m, dual-return mode (two returns per pulse; the default is one).  Its beam is
# elliptical, 0.28° × 0.03° (FWHM, data sheet); the footprint here is round, of HELIOS++'s
# 0.89 mrad (1/e² full angle, pyhelios/data/scanners_tls.xml, "livox_mid-70"), 0.051°.  The
# prisms' rates: 121.567 and −77.733 revolutions per second (HELIOS++ commit eea12035, which
# corrected the 7,294 and −4,664 of earlier versions: revolutions per minute).  The pattern is
# :func:`rosette_table`'s first-order Risley model over one 0.1 s frame (10,000 pulses).
# Intensity: the 8-bit reflectivity of Livox's point format, 0–150 for reflectivities of 0–100 % in the Lambertian
# model and 151–255 for retro-reflectors (Livox Mid-70 user manual v1.2, "Point Cloud Data"; the same in the Livox HAP
# user manual, 2022): the calibrated reflectivity E · R² at 150 counts per unit, at most 255 (as the spinning presets,
# :data:`~zbuf_occlude.sensors.patterns.spinning.SPINNING_INTENSITY_SCALE`).
#: Counts per unit reflectance of a Livox unit's reflectivity (comment above).
LIVOX_INTENSITY_SCALE = 150.0
RAY_TABLE_PRESETS: dict[str, RayTable] = {
    "livox-mid70": rosette_table(
        10_000, duration_s=0.1, fov_deg=70.4, prism_hz=(121.567, -77.733), name="livox-mid70",
        beam=Beam("livox-mid70", wavelength_nm=905.0, divergence_deg=0.051, min_range_m=0.05, max_range_m=260.0, range_noise_m=0.02,
                  detection_threshold=0.1 / 90.0**2, intensity_scale=LIVOX_INTENSITY_SCALE, max_intensity=255, intensity_unit="reflectivity",
                  source="Livox Mid-70 data sheet and user manual v1.2 (90 m at 10 %, precision 2 cm); divergence: HELIOS++ scanners_tls.xml"),
        source="Livox Mid-70 (Risley prisms at 121.567 and -77.733 Hz: HELIOS++ pyhelios/data/scanners_tls.xml, commit eea12035)",
    ),
}  # fmt: skip
