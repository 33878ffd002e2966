"""Structured-light depth cameras: pinhole intrinsics, depth limits, axial noise, quantisation.

Camera frame: OpenCV (x right, y down, z forward), metres.  A pixel ``(u, v)`` (column, row;
pixel centres at half-integers) looks along ``K⁻¹ (u, v, 1)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.checks import (
    MAX_RANGE_M,
    MAX_SENSOR_RAYS,
    count,
    located,
    preset,
    real,
    reals,
    replaced,
    sensor_name,
    value_kind,
    text,
)

__all__ = ["DepthCamera", "DEPTH_CAMERA_PRESETS", "depth_camera_preset", "nguyen_axial_sigma_m"]


def nguyen_axial_sigma_m(depth_m: ArrayLike, incidence_deg: ArrayLike | float = 0.0) -> NDArray[np.float64]:
    """Axial (along z) noise σ of a Kinect-style structured-light sensor, metres.

    ``σ_z(z, θ) = 0.0012 + 0.0019 (z − 0.4)² + 0.0001 / √z · θ² / (π/2 − θ)²`` with ``z`` in
    metres and ``θ`` the incidence angle in radians (the last term matters only past ~60°).

    Source: C. V. Nguyen, S. Izadi, D. Lovell, "Modeling Kinect Sensor Noise for Improved 3D
    Reconstruction and Tracking", 3DIMPVT 2012, Eq. 2 and 3 (fit for 10° < θ < 60°; the θ term
    extends it to larger angles).
    """
    z = np.asarray(depth_m, dtype=np.float64)
    theta = np.radians(np.minimum(np.asarray(incidence_deg, dtype=np.float64), 89.9))
    return 0.0012 + 0.0019 * (z - 0.4) ** 2 + 0.0001 / np.sqrt(np.maximum(z, 1e-9)) * theta**2 / (math.pi / 2 - theta) ** 2


@dataclass(frozen=True)
class DepthCamera:
    """A depth camera (structured light by default).

    Parameters
    ----------
    name : str
    K : (3, 3) float
        OpenCV intrinsics, pixels (``fx, fy, cx, cy``; no skew).
    width, height : int
        Image size, pixels.
    min_depth_m, max_depth_m : float
        Depths (along the optical axis) outside this range are invalid (dropped), metres.
    noise : {"nguyen2012", "none"} or float
        Axial noise model: Nguyen et al. 2012 (:func:`nguyen_axial_sigma_m`), none, or a
        constant σ in metres.
    quantization_m_per_m2 : float
        Depth step at depth z is ``q · z²`` metres (disparity quantisation); 0 turns it off.
        Kinect v1: ``q ≈ 2.85e-3 /m`` (~7 cm at 5 m; Khoshelham & Elberink, Sensors 2012).
    max_incidence_deg : float
        Returns at a larger angle between the ray and the surface normal are invalid
        (structured-light patterns are not decoded at grazing incidence), degrees.
    dropout : float
        Probability in [0, 1) that a valid pixel is lost anyway.
    source : str

    Raises
    ------
    InvalidInputError
        Naming the field: a value that is not a number (``True``, ``"5"``) or not finite; a K
        that is not a (3, 3) OpenCV matrix with fx, fy > 0; an image size below 1 pixel or of
        more than :data:`~zbuf_occlude.sensors.checks.MAX_SENSOR_RAYS` pixels; a depth range
        not ``0 <= min_depth_m < max_depth_m <=`` :data:`~zbuf_occlude.sensors.checks.MAX_RANGE_M`;
        a bad noise, angle or probability; a name that cannot name files.
    """

    name: str
    K: tuple[tuple[float, float, float], ...]
    width: int
    height: int
    min_depth_m: float = 0.5
    max_depth_m: float = 4.0
    noise: str | float = "nguyen2012"
    quantization_m_per_m2: float = 0.0
    max_incidence_deg: float = 75.0
    dropout: float = 0.0
    source: str = ""
    _K: NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        sensor_name(self.name, "depth camera name")
        with located(f"depth camera {self.name!r}"):
            self._check()

    def _check(self) -> None:
        """Check every field and store the numbers as floats (messages start with the field's name)."""
        rows = self.K.tolist() if isinstance(self.K, np.ndarray) else self.K
        if not (isinstance(rows, (list, tuple)) and len(rows) == 3):
            raise InvalidInputError(f"K must be a finite (3, 3) OpenCV matrix with fx, fy > 0, got {value_kind(self.K)}")
        K = np.array([reals(row, f"K[{i}]", lengths=(3,)) for i, row in enumerate(rows)])
        if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], [0, 0, 1]):
            raise InvalidInputError(f"K must be a finite (3, 3) OpenCV matrix with fx, fy > 0, got {value_kind(self.K)}")
        object.__setattr__(self, "K", tuple(tuple(float(v) for v in row) for row in K))
        object.__setattr__(self, "_K", K)
        for name in ("width", "height"):
            object.__setattr__(self, name, count(getattr(self, name), name, low=1, high=MAX_SENSOR_RAYS))
        if self.width * self.height > MAX_SENSOR_RAYS:
            raise InvalidInputError(f"image size {self.width}x{self.height} is more than {MAX_SENSOR_RAYS:,} pixels")
        object.__setattr__(self, "min_depth_m", real(self.min_depth_m, "min_depth_m", low=0.0, high=MAX_RANGE_M))
        object.__setattr__(self, "max_depth_m", real(self.max_depth_m, "max_depth_m", low=0.0, low_open=True, high=MAX_RANGE_M))
        if not self.min_depth_m < self.max_depth_m:
            raise InvalidInputError(f"need min_depth_m < max_depth_m, got {self.min_depth_m}, {self.max_depth_m}")
        if isinstance(self.noise, str):
            text(self.noise, "noise", choices=("nguyen2012", "none"))
        else:
            object.__setattr__(
                self, "noise", real(self.noise, "noise", low=0.0, high=MAX_RANGE_M, expected="'nguyen2012', 'none' or a σ >= 0 metres")
            )
        numbers = {
            "quantization_m_per_m2": {"low": 0.0, "high": 1.0, "high_open": True},
            "max_incidence_deg": {"low": 0.0, "low_open": True, "high": 90.0},
            "dropout": {"low": 0.0, "high": 1.0, "high_open": True},
        }
        for name, bounds in numbers.items():
            object.__setattr__(self, name, real(getattr(self, name), name, **bounds))
        text(self.source, "source")

    @property
    def intrinsics(self) -> NDArray[np.float64]:
        """(3, 3) float64 copy of K."""
        return self._K.copy()

    @classmethod
    def preset(cls, name: str, **changes) -> DepthCamera:
        """The named preset with optional field changes (:func:`depth_camera_preset`)."""
        return depth_camera_preset(name, **changes)

    def with_(self, **changes) -> DepthCamera:
        """A copy with some fields changed."""
        return replaced(self, **changes)

    def sigma_m(self, depth_m: ArrayLike, incidence_deg: ArrayLike) -> NDArray[np.float64]:
        """(N,) float64 axial noise σ at these depths (m) and incidence angles (degrees)."""
        z = np.asarray(depth_m, dtype=np.float64)
        if isinstance(self.noise, str):
            return nguyen_axial_sigma_m(z, incidence_deg) if self.noise == "nguyen2012" else np.zeros_like(z)
        return np.full_like(z, float(self.noise))

    def quantize(self, depth_m: ArrayLike) -> NDArray[np.float64]:
        """Depths rounded to the disparity grid: steps of ``q · z²`` metres."""
        z = np.asarray(depth_m, dtype=np.float64)
        q = self.quantization_m_per_m2
        if q == 0.0:
            return z
        # Disparity ∝ 1/z is what the sensor quantises; a step of 1/z of q gives dz ≈ q z².
        return 1.0 / (np.round(1.0 / (q * z)) * q)

    def rays(self) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Per-pixel rays through the pixel centres, camera frame.

        Returns
        -------
        directions : (H·W, 3) float64
            ``K⁻¹ (u, v, 1)``, z component 1 (so that ray parameter = depth): OpenCV's convention,
            pixel centres at integer ``(u, v)``, as every intrinsics matrix of the package.
        pixel : (H·W, 2) int64
            ``(u, v)`` column and row, row-major order.
        """
        v, u = np.mgrid[0 : self.height, 0 : self.width]
        pixel = np.stack([u.ravel(), v.ravel()], axis=1).astype(np.int64)
        uv1 = np.column_stack([pixel.astype(np.float64), np.ones(len(pixel))])
        return uv1 @ np.linalg.inv(self._K).T, pixel


def _kinect_K(width: int, height: int, f_px: float) -> tuple[tuple[float, ...], ...]:
    # OpenCV's convention: pixel centres at integers, so the image centre is ((W − 1)/2, (H − 1)/2)
    return ((f_px, 0.0, (width - 1) / 2.0), (0.0, f_px, (height - 1) / 2.0), (0.0, 0.0, 1.0))


DEPTH_CAMERA_PRESETS: dict[str, DepthCamera] = {
    # Kinect v1: 640×480 depth, focal length ~585.6 px (Khoshelham & Elberink 2012, Sensors
    # 12(2):1437, Table 1 calibration), 0.5–4 m operating range (same paper), noise model of
    # Nguyen et al. 2012, depth resolution ~2.85e-3 z² m (Khoshelham & Elberink §4).
    "kinect-v1": DepthCamera(
        "kinect-v1", _kinect_K(640, 480, 585.6), 640, 480, min_depth_m=0.5, max_depth_m=4.0,
        noise="nguyen2012", quantization_m_per_m2=2.85e-3, max_incidence_deg=75.0,
        source="Khoshelham & Elberink 2012 (intrinsics, range, resolution); Nguyen, Izadi & Lovell 2012 (noise)",
    ),
}  # fmt: skip


def depth_camera_preset(name: str, **changes) -> DepthCamera:
    """The preset ``name`` (see :data:`DEPTH_CAMERA_PRESETS`), with optional field changes.

    Raises
    ------
    InvalidInputError
        Unknown name.
    """
    return preset(DEPTH_CAMERA_PRESETS, name, "depth camera preset", **changes)
