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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError

__all__ = ["AirborneScanner", "AIRBORNE_PRESETS", "airborne_preset", "scan_airborne"]

#: Scan patterns (module docstring).
PATTERNS = ("linear", "oscillating")


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
    range_noise_m : float
        σ of the Gaussian range error, metres.
    dropout : float
        Probability in [0, 1) that a return is lost.
    source : str

    Raises
    ------
    InvalidInputError
        A non-positive or non-finite number, a swath outside (0°, 180°), an unknown pattern,
        fewer than one pulse per line.
    """

    name: str
    swath_deg: float
    pulse_rate_hz: float
    line_rate_hz: float
    altitude_m: float
    speed_mps: float
    pattern: str = "linear"
    range_noise_m: float = 0.02
    dropout: float = 0.0
    source: str = ""

    def __post_init__(self) -> None:
        for key in ("pulse_rate_hz", "line_rate_hz", "altitude_m", "speed_mps"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InvalidInputError(f"airborne scanner {self.name!r}: {key} must be a finite number > 0, got {value!r}")
        if not (0.0 < float(self.swath_deg) < 180.0):
            raise InvalidInputError(f"airborne scanner {self.name!r}: swath_deg must lie in (0, 180), got {self.swath_deg!r}")
        if self.pattern not in PATTERNS:
            raise InvalidInputError(f"airborne scanner {self.name!r}: pattern must be one of {PATTERNS}, got {self.pattern!r}")
        if not (math.isfinite(self.range_noise_m) and self.range_noise_m >= 0 and 0.0 <= self.dropout < 1.0):
            raise InvalidInputError(f"airborne scanner {self.name!r}: need range_noise_m >= 0 and dropout in [0, 1)")
        if self.pulses_per_line < 1:
            raise InvalidInputError(f"airborne scanner {self.name!r}: fewer than one pulse per line")

    @property
    def pulses_per_line(self) -> int:
        """Pulses fired during one scan line (``round(pulse_rate_hz / line_rate_hz)``)."""
        return int(round(self.pulse_rate_hz / self.line_rate_hz))

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

    def with_(self, **changes) -> AirborneScanner:
        """A copy with some fields changed."""
        return replace(self, **changes)

    def ground_rays(self, center_xy, half_size_m: float, phase_s: float = 0.0) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
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
        """
        cx, cy = (float(v) for v in center_xy)
        r = float(half_size_m)
        if not (math.isfinite(cx) and math.isfinite(cy) and math.isfinite(r) and r > 0):
            raise InvalidInputError(f"ground_rays needs a finite centre and half size > 0, got {center_xy!r}, {half_size_m!r}")
        m = self.pulses_per_line
        period = 1.0 / self.line_rate_hz
        s = math.radians(self.swath_deg)
        theta_grid = -s / 2.0 + s * (np.arange(m) + 0.5) / m
        ground_y = self.altitude_m * np.tan(theta_grid)
        columns = np.flatnonzero(np.abs(ground_y - cy) <= r)
        if len(columns) == 0:
            return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
        # lines whose pulses can land in [cx - r, cx + r] (a line spans speed · period along track)
        line_length = self.speed_mps * period
        k0 = math.floor((cx - r - self.speed_mps * phase_s) / line_length) - 1
        k1 = math.ceil((cx + r - self.speed_mps * phase_s) / line_length) + 1
        k = np.arange(k0, k1 + 1)
        reverse = (k % 2 == 1) if self.pattern == "oscillating" else np.zeros(len(k), bool)
        slot = np.where(reverse[:, None], m - 1 - columns[None, :], columns[None, :])  # pulse index within its line
        t = phase_s + k[:, None] * period + slot / self.pulse_rate_hz
        x = self.speed_mps * t
        theta = np.broadcast_to(theta_grid[columns][None, :], x.shape)
        keep = np.abs(x - cx) <= r
        x, theta = x[keep], theta[keep]
        origins = np.column_stack([x, np.zeros_like(x), np.full_like(x, self.altitude_m)])
        directions = np.column_stack([np.zeros_like(x), np.sin(theta), -np.cos(theta)])
        return origins, directions, np.degrees(theta)


# RIEGL LMS-Q1560 (the scanner of DALES: Varney, Asari & Graehling, "DALES: A Large-scale Aerial
# LiDAR Data Set for Semantic Segmentation", CVPR Workshops 2020, flown at about 1,300 m): data
# sheet "RIEGL LMS-Q1560" (2015): two channels, up to 800 kHz laser pulse rate in all, 58° field of
# view, rotating polygon mirrors (parallel scan lines), up to 2 x 200 lines/s, ranging accuracy
# 20 mm.  Speed 72 m/s (140 kn) is a typical survey speed of the twin-engine aircraft such systems
# fly in (an ASSUMPTION); 209 lines/s makes the along- and across-track spacings equal (0.34 m).
# One pass: 7.7 points/m² (DALES reaches ~50 with overlapping strips).
AIRBORNE_PRESETS: dict[str, AirborneScanner] = {
    "riegl-q1560": AirborneScanner(
        "riegl-q1560", swath_deg=58.0, pulse_rate_hz=800_000.0, line_rate_hz=209.0, altitude_m=1300.0,
        speed_mps=72.0, pattern="linear", range_noise_m=0.02,
        source="RIEGL LMS-Q1560 data sheet (2015); DALES (Varney et al., CVPRW 2020) flight altitude 1,300 m",
    ),
}  # fmt: skip


def airborne_preset(name: str, **changes) -> AirborneScanner:
    """The preset ``name`` of :data:`AIRBORNE_PRESETS`, with optional field changes.

    Raises
    ------
    InvalidInputError
        Unknown name.
    """
    key = str(name).lower()
    if key not in AIRBORNE_PRESETS:
        raise InvalidInputError(f"unknown airborne scanner {name!r}; choose one of {sorted(AIRBORNE_PRESETS)}")
    return replace(AIRBORNE_PRESETS[key], **changes)


def scan_airborne(scene, scanner: AirborneScanner, center_xy=(0.0, 0.0), half_size_m: float = 10.0, *, seed: int = 0,
                  phase_s: float | None = None):  # fmt: skip
    """Scan the part of ``scene`` around ``center_xy`` with an airborne scanner; world frame.

    Parameters
    ----------
    scene : ScanScene or trimesh.Trimesh
        World frame, metres, ground at z = 0 (a bare mesh: as given).
    scanner : AirborneScanner
    center_xy, half_size_m
        The square of flat ground whose pulses are cast (:meth:`AirborneScanner.ground_rays`).
    seed : int
        Noise, dropout and (when ``phase_s`` is None) the lines' time phase.

    Returns
    -------
    Scan
        ``frame="world"``, ``ring`` and ``pixel`` None, ``sensor_position`` the mean aircraft
        position of the returns, ``meta["scan_angle_deg"]`` per return.
    """
    from zbuf_occlude.sensors.raycast import cast_embree
    from zbuf_occlude.sensors.scan import Scan, build_scene

    built = build_scene(scene)
    rng = np.random.default_rng(seed)
    phase = float(rng.uniform(0.0, 1.0 / scanner.line_rate_hz)) if phase_s is None else float(phase_s)
    origins, directions, angle = scanner.ground_rays(center_xy, half_size_m, phase)
    face, t = cast_embree(built.mesh, origins, directions) if len(origins) else (np.zeros(0, np.int64), np.zeros(0))
    hit = np.flatnonzero(face >= 0)
    face, t, o, d = face[hit], t[hit], origins[hit], directions[hit]
    measured = t + scanner.range_noise_m * rng.standard_normal(len(hit))
    keep = (rng.random(len(hit)) >= scanner.dropout) & (measured > 0)
    face, measured, o, d = face[keep], measured[keep], o[keep], d[keep]
    tri = np.asarray(built.mesh.triangles, dtype=np.float64)[face]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    cos_in = np.einsum("ij,ij->i", normal, d)
    normal[cos_in > 0] *= -1.0
    position = o.mean(axis=0) if len(o) else np.array([0.0, 0.0, scanner.altitude_m])
    pose = np.eye(4)
    pose[:3, 3] = position
    return Scan(
        points=(o + d * measured[:, None]).astype(np.float32), ring=None, pixel=None, range_m=measured.astype(np.float32),
        face_index=built.face_local[face], object_id=built.face_object[face], normal=normal.astype(np.float32),
        incidence_deg=np.degrees(np.arccos(np.clip(np.abs(cos_in), 0.0, 1.0))).astype(np.float32), frame="world",
        sensor_position=position, sensor_to_world=pose, sensor=scanner.name,
        meta={"n_rays": len(origins), "phase_s": phase, "scan_angle_deg": angle[hit][keep]},
    )  # fmt: skip
