"""Spinning LiDAR sensors: ring elevation tables and azimuth sampling (range limits, noise and dropout are the beam's).

Sensor frame (right-handed, metres): x forward (azimuth 0°), y left (azimuth +90°), z up
(elevation +90°).  A beam with elevation ``e`` and azimuth ``a`` points along
``(cos e cos a, cos e sin a, sin e)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.fields import IDEAL_BEAM, Beam, check_beam
from zbuf_occlude.sensors.pulses import Pulses, placed
from zbuf_occlude.sensors.checks import MAX_SENSOR_RAYS, located, preset, real, reals, replaced, sensor_name, text

__all__ = ["Lidar", "LIDAR_PRESETS", "SPINNING_INTENSITY_SCALE", "lidar_preset", "beam_directions", "in_sector"]


@dataclass(frozen=True)
class Lidar:
    """A spinning multi-beam LiDAR: a ring pattern that fires a :class:`~zbuf_occlude.sensors.beam.fields.Beam`.

    Parameters
    ----------
    name : str
        Preset or user name (metadata).
    elevations_deg : (B,) float
        Elevation of each beam (ring), degrees above the sensor's xy plane.  Ring ``k`` is
        ``elevations_deg[k]``; the order is kept (need not be sorted).
    rotation_hz : float
        Spin rate, revolutions per second.
    firing_rate_hz : float
        Firing cycles per second (every beam fires once per cycle).  The azimuth step is
        ``360 · rotation_hz / firing_rate_hz`` degrees.
    azimuth_offset_deg : float
        Azimuth of the first firing of a revolution, degrees.
    beam : Beam
        The pulse and its receiver: footprint, returns, detection, range noise, dropout and range
        limits (:class:`~zbuf_occlude.sensors.beam.fields.Beam`); default the ``ideal`` beam.
    source : str
        Data sheet the pattern's numbers come from.

    Raises
    ------
    InvalidInputError
        Naming the field: a value that is not a number (``True``, ``"5"``) or not finite;
        an empty beam table or elevations outside (−90°, 90°); non-positive rates; more than
        :data:`~zbuf_occlude.sensors.checks.MAX_SENSOR_RAYS` rays per revolution
        (``elevations × firing_rate_hz / rotation_hz``); a ``beam`` that is not a Beam; a name
        that cannot name files.
    """

    name: str
    elevations_deg: tuple[float, ...]
    rotation_hz: float = 10.0
    firing_rate_hz: float = 18_000.0
    azimuth_offset_deg: float = 0.0
    beam: Beam = IDEAL_BEAM
    source: str = ""
    _elev: NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        sensor_name(self.name, "lidar name")
        with located("lidar"):  # not by its name: a sensor file's name is one of its values, never quoted
            self._check()

    def _check(self) -> None:
        """Check every field and store the numbers as floats (messages start with the field's name)."""
        n_rays = MAX_SENSOR_RAYS
        elev = reals(self.elevations_deg, "elevations_deg", max_length=n_rays, low=-90.0, high=90.0, low_open=True, high_open=True)
        object.__setattr__(self, "elevations_deg", elev)
        object.__setattr__(self, "_elev", np.array(elev, dtype=np.float64))
        positive = {"low": 0.0, "low_open": True}
        for name, bounds in {"rotation_hz": positive, "firing_rate_hz": positive, "azimuth_offset_deg": {}}.items():
            object.__setattr__(self, name, real(getattr(self, name), name, **bounds))
        text(self.source, "source")
        check_beam(self.beam)
        if self.firing_rate_hz < self.rotation_hz:
            raise InvalidInputError("firing_rate_hz must be at least rotation_hz (a firing or more per revolution)")
        per_revolution = len(elev) * (self.firing_rate_hz / self.rotation_hz)  # checked before n_azimuths rounds it
        if not per_revolution <= n_rays:
            raise InvalidInputError(
                f"{len(elev):,} elevations_deg x firing_rate_hz / rotation_hz firings is more than {n_rays:,} rays per revolution"
            )

    @property
    def n_beams(self) -> int:
        """Number of beams (rings)."""
        return len(self.elevations_deg)

    @property
    def sweep_s(self) -> float:
        """Seconds one sweep (a revolution) lasts: ``1 / rotation_hz``."""
        return 1.0 / self.rotation_hz

    @property
    def azimuth_step_deg(self) -> float:
        """Azimuth between consecutive firings, degrees: ``360 · rotation_hz / firing_rate_hz``."""
        return 360.0 * self.rotation_hz / self.firing_rate_hz

    @property
    def n_azimuths(self) -> int:
        """Firings per revolution (``round(firing_rate_hz / rotation_hz)``)."""
        return int(round(self.firing_rate_hz / self.rotation_hz))

    @property
    def azimuths_deg(self) -> NDArray[np.float64]:
        """(A,) float64: azimuth of every firing of one revolution, degrees in [offset, offset + 360)."""
        return self.azimuth_offset_deg + np.arange(self.n_azimuths) * (360.0 / self.n_azimuths)

    @classmethod
    def preset(cls, name: str, **changes) -> Lidar:
        """The named preset with optional field changes (:func:`lidar_preset`)."""
        return lidar_preset(name, **changes)

    def with_(self, **changes) -> Lidar:
        """A copy with some fields changed (``lidar.with_(rotation_hz=20)``)."""
        return replaced(self, **changes)

    def rays(
        self, azimuth_range_deg: tuple[float, float] | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64]]:
        """Unit beam directions of one revolution, sensor frame.

        Parameters
        ----------
        azimuth_range_deg : (lo, hi), optional
            Keep only firings with azimuth in ``[lo, hi]`` degrees (wrapped to the revolution),
            e.g. the sector an object covers; default: all.

        Returns
        -------
        directions : (B·A', 3) float64
            Unit vectors, sensor frame, ring-major (all azimuths of ring 0 first).
        ring : (B·A',) int64
            Beam index into ``elevations_deg``.
        azimuth_deg : (B·A',) float64
        """
        az = self.azimuths_deg
        if azimuth_range_deg is not None:
            az = az[in_sector(az, azimuth_range_deg)]
        ring = np.repeat(np.arange(self.n_beams, dtype=np.int64), len(az))
        azimuth = np.tile(az, self.n_beams)
        return beam_directions(self._elev[ring], azimuth), ring, azimuth

    def pulses(self, platform, azimuth_range_deg: tuple[float, float] | None = None) -> Pulses:
        """The pulses of one revolution (:meth:`rays`) fired from ``platform`` (:func:`~zbuf_occlude.sensors.pulses.placed`).

        The beams of one firing cycle fire one after another, beam ``b`` (its index in
        ``elevations_deg``) ``b / B`` of a cycle (``1 / (n_azimuths · rotation_hz)`` seconds) after
        the cycle starts, so every pulse has a time of its own, as LAS readers that group returns
        into pulses by time expect (Velodyne HDL-32E user manual: its 32 lasers fire 1.152 µs apart
        in a 46.08 µs cycle; the model spreads the B beams evenly over the cycle).  ``pulse_id`` is
        ``ring · n_azimuths + azimuth index``; the scan angle is the beam's elevation.  On a moving
        platform each pulse leaves from where the scanner is at its time: the sweep's motion
        distortion.
        """
        d_sensor, ring, azimuth = self.rays(azimuth_range_deg)
        n_az = self.n_azimuths
        index = np.rint((azimuth - self.azimuth_offset_deg) / (360.0 / n_az)).astype(np.int64) % n_az
        time_s = (index + ring / self.n_beams) / (n_az * self.rotation_hz)
        directions, origins, rotation, rotations, time_s = placed(d_sensor, time_s, platform)
        return Pulses(
            d_sensor, directions, origins, rotation, pulse_id=ring * n_az + index, time_s=time_s,
            scan_angle_deg=self._elev[ring].astype(np.float32), ring=ring, rotations=rotations,
        )  # fmt: skip


def in_sector(azimuth_deg: ArrayLike, azimuth_range_deg: tuple[float, float]) -> NDArray[np.bool_]:
    """Whether each azimuth (degrees, any shape) lies in ``[lo, hi]`` wrapped to a turn; all of them for a range of a turn or more."""
    az = np.asarray(azimuth_deg, dtype=np.float64)
    lo, hi = (float(v) for v in azimuth_range_deg)
    if hi - lo >= 360.0:
        return np.ones(az.shape, dtype=bool)
    return np.mod(az - lo, 360.0) <= np.mod(hi - lo, 360.0)


def beam_directions(elevation_deg: ArrayLike, azimuth_deg: ArrayLike) -> NDArray[np.float64]:
    """(N, 3) float64 unit vectors ``(cos e cos a, cos e sin a, sin e)``, sensor frame."""
    e = np.radians(np.asarray(elevation_deg, dtype=np.float64))
    a = np.radians(np.asarray(azimuth_deg, dtype=np.float64))
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1)


# -- presets ------------------------------------------------------------------------------------
# HDL-32E user's manual (Velodyne 63-9113 Rev. D), Appendix "Laser firing sequence / vertical
# angles": 32 lasers from -30.67° to +10.67°, listed to 0.01° (spacing 1.33° or 1.34°).
_HDL32E = (
    -30.67, -29.33, -28.00, -26.67, -25.33, -24.00, -22.67, -21.33, -20.00, -18.67, -17.33,
    -16.00, -14.67, -13.33, -12.00, -10.67, -9.33, -8.00, -6.67, -5.33, -4.00, -2.67, -1.33,
    0.00, 1.33, 2.67, 4.00, 5.33, 6.67, 8.00, 9.33, 10.67,
)  # fmt: skip
# HDL-64E S2 data sheet / manual (63-HDL64ES2): 26.8° vertical FOV, +2° to -24.8°; upper block
# of 32 lasers at ~1/3° spacing (+2.0° to -8.33°), lower block of 32 at ~1/2° (-8.83° to -24.33°
# here, i.e. the nominal spacing; the per-unit calibration file differs by up to ~0.2°).
_HDL64E = tuple(np.round(np.concatenate([2.0 - np.arange(32) / 3.0, -8.83 - 0.5 * np.arange(32)]), 4))

# Detection threshold τ = ρ / R² from a data sheet's "range at reflectivity": HDL-64E S2 data sheet
# "120 m for cars and foliage (~0.80 reflectivity), 50 m for pavement (~0.10)"; OS1-64 data sheet
# "120 m @ 80 % Lambertian".  The VLP-16 and HDL-32E sheets give 100 m without a reflectivity:
# 0.8 at 100 m is an ASSUMPTION by analogy with the HDL-64E S2.  Applied where a scan is given
# reflectivities.
#
# Intensity: a Velodyne writes an 8-bit *calibrated reflectivity*, "independent of laser power and distances":
# diffuse reflectors 0–100 for reflectivities of 0–100 %, retro-reflectors 101–255, 255 an ideal one (VLP-16 user
# manual 63-9243 Rev. D, §6.1 "Calibrated Reflectivity"; HDL-32E from firmware 2.0, Velodyne "HDL-32E Software Version
# 2.0 Description", 2012).  Ouster firmware writes a calibrated reflectivity too, "measured signal photons scaled by
# range and sensor sensitivity" (Ouster firmware user manual, "Calibrated Reflectivity"), 0–100 for Lambertian targets
# (an ASSUMPTION for the Gen 1 OS1-64's firmware of 2019); the HDL-64E S2 calibrates each laser's intensity and is
# given the same convention (an ASSUMPTION).  So the presets write the apparent reflectance E · R² = ρ |cos θ| s
# (``intensity_unit`` "reflectivity") at 100 counts per unit, at most 255: a white wall met head-on reads 100 at 2 m and
# at 50 m, a grazing or partial hit less, a retro-reflector (ρ > 1) above 100 (linearly, where the devices compress
# that range: an ASSUMPTION).
#: Counts per unit reflectance of the spinning presets' calibrated reflectivity (comment above).
SPINNING_INTENSITY_SCALE = 100.0


def _spinning_beam(name: str, **fields) -> Beam:
    """A spinning LiDAR preset's beam: 905 nm, one return per pulse (the firmware's strongest-return mode with
    one ray), τ = 0.8 / 100² unless given, an 8-bit calibrated reflectivity."""
    fields = {"detection_threshold": 0.8 / 100.0**2, "intensity_scale": SPINNING_INTENSITY_SCALE, "max_intensity": 255,
              "intensity_unit": "reflectivity", **fields}  # fmt: skip
    return Beam(name, wavelength_nm=905.0, **fields)


LIDAR_PRESETS: dict[str, Lidar] = {
    # VLP-16 data sheet (Velodyne 63-9229 Rev-C) and manual: 16 channels, ±15° at 2°,
    # 5–20 Hz, firing cycle 55.296 µs (18 084 Hz; 0.2° at 10 Hz), range 100 m, accuracy ±3 cm.
    "vlp16": Lidar(
        "vlp16", tuple(float(e) for e in range(-15, 16, 2)), rotation_hz=10.0, firing_rate_hz=1.0 / 55.296e-6,
        beam=_spinning_beam("vlp16", min_range_m=0.5, max_range_m=100.0, range_noise_m=0.03, divergence_deg=0.172,
                            source="Velodyne VLP-16 data sheet 63-9229 Rev-C (range 100 m, accuracy ±3 cm)"),
        source="Velodyne VLP-16 data sheet 63-9229 Rev-C; VLP-16 user manual 63-9243 Rev. D (firing 55.296 us)",
    ),
    # HDL-32E data sheet (97-0038 Rev. M) and manual: 32 lasers +10.67° to -30.67°, 5–20 Hz,
    # firing cycle 46.08 µs (21 701 Hz; 0.166° at 10 Hz), 80–100 m range, accuracy < 2 cm.
    "hdl32e": Lidar(
        "hdl32e", _HDL32E, rotation_hz=10.0, firing_rate_hz=1.0 / 46.08e-6,
        beam=_spinning_beam("hdl32e", min_range_m=1.0, max_range_m=100.0, range_noise_m=0.02, divergence_deg=0.16,
                            source="Velodyne HDL-32E data sheet 97-0038 Rev. M (range 100 m, accuracy < 2 cm)"),
        source="Velodyne HDL-32E data sheet 97-0038 Rev. M; HDL-32E user manual 63-9113 Rev. D (firing 46.08 us)",
    ),
    # HDL-64E S2 data sheet: 64 lasers, +2° to -24.8°, 5–15 Hz, azimuth resolution 0.09°
    # (40 kHz firing at 10 Hz), 120 m, accuracy < 2 cm (1σ).
    "hdl64e": Lidar(
        "hdl64e", _HDL64E, rotation_hz=10.0, firing_rate_hz=40_000.0,
        beam=_spinning_beam("hdl64e", min_range_m=0.9, max_range_m=120.0, range_noise_m=0.02, detection_threshold=0.8 / 120.0**2,
                            source="Velodyne HDL-64E S2 data sheet 97-0038 Rev. J (120 m at 0.80, accuracy < 2 cm)"),
        source="Velodyne HDL-64E S2 data sheet 97-0038 Rev. J; HDL-64E S2 user manual 63-HDL64ES2",
    ),
    # Ouster OS1-64 (Gen 1) data sheet: 64 channels over 33.2° (+16.6° to -16.6°, uniform),
    # 1024 columns at 10 Hz (10 240 firings/s), 0.8–120 m, precision ±3 cm (1σ, 1–20 m).
    "os1-64": Lidar(
        "os1-64", tuple(np.round(np.linspace(16.6, -16.6, 64), 4)), rotation_hz=10.0, firing_rate_hz=10_240.0,
        beam=_spinning_beam("os1-64", min_range_m=0.8, max_range_m=120.0, range_noise_m=0.03, divergence_deg=0.13,
                            detection_threshold=0.8 / 120.0**2, source="Ouster OS1-64 data sheet (Gen 1, rev. 2019): 120 m at 80 %"),
        source="Ouster OS1-64 hardware user guide / data sheet (Gen 1, rev. 2019)",
    ),
}  # fmt: skip


def lidar_preset(name: str, **changes) -> Lidar:
    """The preset ``name`` (see :data:`LIDAR_PRESETS`), with optional field changes.

    Raises
    ------
    InvalidInputError
        Unknown name.
    """
    return preset(LIDAR_PRESETS, name, "lidar preset", **changes)
