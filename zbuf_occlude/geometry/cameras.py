"""Pinhole cameras on a sphere around the object, and the paper's pose schedules.

World frame: the object's frame after :func:`zbuf_occlude.load_mesh`, z up, object
centred at the origin with maximum extent 1 (Sryamkin et al. 2023, §4.1).

Camera frames (both are exposed, because OpenGL and OpenCV users each expect theirs):

* ``view_matrix`` maps world → OpenGL eye space (x right, y up, camera looks down −z).
* ``K`` and ``extrinsics`` follow OpenCV (x right, y down, camera looks down +z).
  ``extrinsics = diag(1, −1, −1) · view_matrix[:3]``.

Pixels follow OpenCV and Open3D (``PinholeCameraIntrinsic``): pixel ``(u, v)`` = (column, row),
row 0 at the top, **pixel centres at integer coordinates**, so pixel ``(i, j)`` covers
``[i − ½, i + ½) × [j − ½, j + ½)`` and a centred principal point is ``cx = (W − 1)/2``,
``cy = (H − 1)/2``.  The renderer lights pixel ``(i, j)`` for the surface through its centre
(OpenGL samples at pixel centres), so a point projected with ``K`` lands on the pixel
``round(u), round(v)`` that shows it.  Every class of the package that exposes intrinsics uses
this convention (:class:`zbuf_occlude.protocols.depth.PinholeView`, the protocols' ``K``).

Linear depth (``depth``) is the distance along the optical axis in object units,
i.e. ``−z_eye``; ``window_depth`` is OpenGL's [0, 1] value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.defaults import DEFAULT_RESOLUTION, MAX_CAMERA_RADIUS, MAX_VIEWS
from zbuf_occlude.errors import CameraError, InvalidInputError

__all__ = [
    "Camera",
    "camera_on_sphere",
    "view_schedule",
    "cameras_from_schedule",
    "DEFAULT_RADIUS",
    "UNIT_BOX_BOUNDING_RADIUS",
]

#: Camera distance for an object of maximum extent 1 (paper §4.1: 4 × max dimension).
DEFAULT_RADIUS = 4.0
#: Radius of the bounding sphere of a box of maximum extent 1 centred at the origin.
UNIT_BOX_BOUNDING_RADIUS = math.sqrt(3.0) / 2.0
#: Relative margin added around the bounding sphere when fitting fov and clip planes.
FIT_MARGIN = 0.02
#: Characters of a view schedule quoted in an error (a list of 10⁷ poses is not echoed whole).
SHOWN_SPEC_CHARS = 60


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: pose (eye, target, up) and intrinsics.

    Parameters
    ----------
    eye, target, up : (3,) float64
        Camera centre, look-at point and approximate up direction, world frame.
    yfov_deg : float
        Vertical field of view, degrees.
    width, height : int
        Image size, pixels.  Pixels are square (fx == fy).
    znear, zfar : float
        Clip planes, object units, ``0 < znear < zfar``.
    elevation_deg, azimuth_deg, radius : float or None
        The spherical pose this camera was made from, if any (metadata only).

    Raises
    ------
    CameraError
        On non-finite values, ``eye == target``, ``up`` parallel to the view
        direction, a field of view outside (0, 180) or bad clip planes.
    """

    eye: NDArray[np.float64]
    target: NDArray[np.float64]
    up: NDArray[np.float64]
    yfov_deg: float
    width: int
    height: int
    znear: float
    zfar: float
    elevation_deg: float | None = None
    azimuth_deg: float | None = None
    radius: float | None = None
    _basis: NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        eye, target, up = (np.asarray(v, dtype=np.float64).reshape(3) for v in (self.eye, self.target, self.up))
        for name, v in (("eye", eye), ("target", target), ("up", up)):
            if not np.all(np.isfinite(v)):
                raise CameraError(f"camera {name} must be finite, got {v}")
        if not (0.0 < self.yfov_deg < 180.0):
            raise CameraError(f"yfov_deg must lie in (0, 180), got {self.yfov_deg}")
        if int(self.width) < 1 or int(self.height) < 1:
            raise CameraError(f"image size must be positive, got {self.width}x{self.height}")
        if not (0.0 < self.znear < self.zfar) or not math.isfinite(self.zfar):
            raise CameraError(f"need 0 < znear < zfar < inf, got znear={self.znear}, zfar={self.zfar}")
        forward = target - eye
        norm = np.linalg.norm(forward)
        if norm == 0.0:
            raise CameraError("camera eye and target coincide")
        forward = forward / norm
        right = np.cross(forward, up)
        if np.linalg.norm(right) < 1e-9:
            raise CameraError(f"camera up {up} is parallel to the view direction {forward}")
        right /= np.linalg.norm(right)
        true_up = np.cross(right, forward)
        object.__setattr__(self, "eye", eye)
        object.__setattr__(self, "target", target)
        object.__setattr__(self, "up", up)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        object.__setattr__(self, "_basis", np.stack([right, true_up, -forward]))

    # -- extrinsics --------------------------------------------------------------
    @property
    def view_matrix(self) -> NDArray[np.float64]:
        """(4, 4) float64: world → OpenGL eye space (camera looks down −z)."""
        m = np.eye(4)
        m[:3, :3] = self._basis
        m[:3, 3] = -self._basis @ self.eye
        return m

    @property
    def extrinsics(self) -> NDArray[np.float64]:
        """(3, 4) float64: world → OpenCV camera frame ``[R | t]`` (looks down +z, y down)."""
        return (np.diag([1.0, -1.0, -1.0]) @ self.view_matrix[:3]).copy()

    # -- intrinsics --------------------------------------------------------------
    @property
    def resolution(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.width, self.height

    @property
    def focal_px(self) -> float:
        """Focal length in pixels (fx == fy)."""
        return 0.5 * self.height / math.tan(math.radians(self.yfov_deg) / 2.0)

    @property
    def K(self) -> NDArray[np.float64]:
        """(3, 3) float64 OpenCV intrinsics, pixels: ``[[f, 0, cx], [0, f, cy], [0, 0, 1]]``.

        Pixel centres at integer coordinates (module docstring), principal point at the image
        centre: ``cx = (W − 1)/2``, ``cy = (H − 1)/2``, as OpenCV and Open3D's
        ``PinholeCameraIntrinsic`` (and ModelNet40-C's intrinsics) have it.
        """
        f = self.focal_px
        cx, cy = self._principal_point
        return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])

    @property
    def _principal_point(self) -> tuple[float, float]:
        return (self.width - 1) / 2.0, (self.height - 1) / 2.0

    @property
    def projection_matrix(self) -> NDArray[np.float64]:
        """(4, 4) float64 OpenGL perspective matrix: eye space → clip space (NDC z in [−1, 1])."""
        t = 1.0 / math.tan(math.radians(self.yfov_deg) / 2.0)
        aspect = self.width / self.height
        n, f = self.znear, self.zfar
        m = np.zeros((4, 4))
        m[0, 0] = t / aspect
        m[1, 1] = t
        m[2, 2] = (f + n) / (n - f)
        m[2, 3] = 2.0 * f * n / (n - f)
        m[3, 2] = -1.0
        return m

    # -- projection helpers ------------------------------------------------------
    def project(self, points: NDArray[np.floating]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Project world points to pixels.

        Parameters
        ----------
        points : (N, 3) float
            World frame.

        Returns
        -------
        pixels : (N, 2) float64
            OpenCV pixel coordinates, ``K`` applied to the camera-frame point (u right, v down;
            pixel centres at integers: pixel (i, j) covers [i − ½, i + ½) × [j − ½, j + ½), so
            the pixel that shows the point is ``floor(pixels + ½)``).
        depth : (N,) float64
            Linear depth along the optical axis, object units (negative behind the camera).
        """
        cam = self._camera_frame(points)
        depth = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = cam[:, :2] / depth[:, None] * self.focal_px + np.array(self._principal_point)
        return uv, depth

    def _camera_frame(self, points: NDArray[np.floating]) -> NDArray[np.float64]:
        return np.stack(self._camera_columns(points), axis=1)

    def _camera_columns(self, points: NDArray[np.floating]) -> tuple[NDArray[np.float64], ...]:
        """The camera frame's x, y and z of ``points (N, 3)``, each ``(N,)`` float64:
        ``((p_x R_a0 + p_y R_a1) + p_z R_a2) + t_a``, in that order, for every method's frustum
        test.  Column sums rather than ``pts @ R.T``: a (N, 3) x (3, 3) product goes through
        multithreaded BLAS, several times slower for this shape on a busy machine."""
        p = np.asarray(points, dtype=np.float64).T
        rt = self.extrinsics
        term = np.empty(p.shape[1])
        columns = []
        for a in range(3):  # in place: fresh arrays of this size cost more than the arithmetic
            column = p[0] * rt[a, 0]
            column += np.multiply(p[1], rt[a, 1], out=term)
            column += np.multiply(p[2], rt[a, 2], out=term)
            column += rt[a, 3]
            columns.append(column)
        return tuple(columns)

    def in_frustum(self, points: NDArray[np.floating]) -> NDArray[np.bool_]:
        """(N,) bool: inside the view frustum (image bounds and znear ≤ depth ≤ zfar).

        The image bounds are the outer edges of the border pixels, ``−½ ≤ u < W − ½``; the test
        is computed from the image's top-left corner (``u + ½``), the arithmetic that
        :mod:`zbuf_occlude.visibility.cpu_zbuffer` and :mod:`zbuf_occlude.visibility.embree_fast`
        repeat to give the same answer to the last bit.
        """
        x, y, depth = self._camera_columns(points)
        focal = self.focal_px
        with np.errstate(divide="ignore", invalid="ignore"):
            u = x / depth * focal + self.width / 2.0
            v = y / depth * focal + self.height / 2.0
        return (depth >= self.znear) & (depth <= self.zfar) & (u >= 0) & (u < self.width) & (v >= 0) & (v < self.height)

    def pixel_size_at(self, depth: NDArray[np.floating]) -> NDArray[np.float64]:
        """Side of one pixel's footprint at linear ``depth``, object units."""
        return np.asarray(depth, dtype=np.float64) / self.focal_px


def _spherical_eye(elevation_deg: float, azimuth_deg: float, radius: float) -> NDArray[np.float64]:
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return radius * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


def camera_on_sphere(
    elevation_deg: float,
    azimuth_deg: float,
    radius: float = DEFAULT_RADIUS,
    *,
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION,
    yfov_deg: float | None = None,
    bounding_radius: float = UNIT_BOX_BOUNDING_RADIUS,
) -> Camera:
    """A camera on a sphere around the origin, looking at the origin.

    Convention of the paper's MATLAB code (Sryamkin et al. 2023, §3.3, Fig. 3; §4.1):
    z up, ``eye = radius · (cos el · cos az, cos el · sin az, sin el)``.  The up vector
    is the tangent of increasing elevation, ``(−sin el · cos az, −sin el · sin az, cos el)``,
    which stays well defined at el = ±90° (there it points to azimuth az + 180°).

    Parameters
    ----------
    elevation_deg, azimuth_deg : float
        Degrees.  Elevation in [−90, 90].
    radius : float
        Distance from the origin, object units (default 4 = 4 × max dimension, §4.1).
    resolution : int or (width, height)
        Image size in pixels.
    yfov_deg : float, optional
        Vertical field of view.  Default: fitted to the bounding sphere with a 2 % margin,
        so the whole object is in view from every pose.
    bounding_radius : float
        Radius of the object's bounding sphere (default: that of the unit box).  The
        near and far planes are set tightly around it, which maximises depth precision.

    Raises
    ------
    CameraError
        If the camera is inside (or on) the bounding sphere, farther than
        :data:`MAX_CAMERA_RADIUS` (float64 no longer resolves the visibility tolerance
        there), or the elevation is outside [−90, 90].
    """
    if not all(math.isfinite(v) for v in (elevation_deg, azimuth_deg, radius, bounding_radius)):
        raise CameraError(f"non-finite pose: el={elevation_deg}, az={azimuth_deg}, radius={radius}")
    if not -90.0 <= elevation_deg <= 90.0:
        raise CameraError(f"elevation_deg must lie in [-90, 90], got {elevation_deg}")
    r_fit = bounding_radius * (1.0 + FIT_MARGIN)
    if radius <= r_fit:
        raise CameraError(
            f"camera radius {radius} is inside the object's bounding sphere (radius {bounding_radius}); "
            f"use a radius > {r_fit:.3f} (default {DEFAULT_RADIUS})"
        )
    if radius > MAX_CAMERA_RADIUS:
        raise CameraError(
            f"camera radius {radius:g} is beyond {MAX_CAMERA_RADIUS:.3g} object units (the object's extent is 1), "
            "the farthest camera at which float64 still decides visibility's 1e-6 tolerance; use a smaller radius"
        )
    width, height = (resolution, resolution) if np.isscalar(resolution) else resolution
    if yfov_deg is None:
        yfov_deg = 2.0 * math.degrees(math.asin(r_fit / radius))
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    up = np.array([-math.sin(el) * math.cos(az), -math.sin(el) * math.sin(az), math.cos(el)])
    return Camera(
        eye=_spherical_eye(elevation_deg, azimuth_deg, radius),
        target=np.zeros(3),
        up=up,
        yfov_deg=float(yfov_deg),
        width=int(width),
        height=int(height),
        znear=radius - r_fit,
        zfar=radius + r_fit,
        elevation_deg=float(elevation_deg),
        azimuth_deg=float(azimuth_deg),
        radius=float(radius),
    )


def _paper100() -> list[tuple[float, float]]:
    # Sryamkin et al. 2023, §4.3, Eq. 11-12: el_i = (i-1)*10 - 90 for i = 1..19 and
    # N_i = min(i, 20 - i) azimuths evenly spaced over 360 degrees: 100 poses in total.
    poses = []
    for i in range(1, 20):
        el = (i - 1) * 10.0 - 90.0
        n = min(i, 20 - i)
        poses.extend((el, k * 360.0 / n) for k in range(n))
    return poses


def _fibonacci(n: int) -> list[tuple[float, float]]:
    # Fibonacci (golden-angle) lattice: near-uniform directions on the sphere.
    golden = math.pi * (3.0 - math.sqrt(5.0))
    poses = []
    for k in range(n):
        z = 1.0 - 2.0 * (k + 0.5) / n
        poses.append((math.degrees(math.asin(z)), math.degrees((k * golden) % (2.0 * math.pi))))
    return poses


def _shown(spec: str) -> str:
    """``spec`` quoted for a message, cut to :data:`SHOWN_SPEC_CHARS` characters."""
    if len(spec) <= SHOWN_SPEC_CHARS:
        return repr(spec)
    return f"{spec[:SHOWN_SPEC_CHARS]!r}... ({len(spec):,} characters)"


def _fibonacci_count(text: str) -> int:
    """N of ``fibonacci:N``; 0 when it is not a whole number (a 10⁶-digit N is not parsed: it is too many)."""
    if len(text) > len(str(MAX_VIEWS)) + 2:
        return MAX_VIEWS + 1 if text.isdecimal() else 0
    try:
        return int(text)
    except ValueError:
        return 0


def view_schedule(spec: str) -> list[tuple[float, float]]:
    """Named camera pose schedules, as ``(elevation_deg, azimuth_deg)`` pairs.

    Parameters
    ----------
    spec : str
        ``"paper100"``: Eq. 11-12 of Sryamkin et al. 2023 (§4.3), 19 elevations from −90°
        to 90° in 10° steps with ``min(i, 20 − i)`` azimuths each, 100 poses.
        ``"grid25"``: el ∈ {−80, −40, 0, 40, 80} × az ∈ {0, 72, 144, 216, 288}.
        ``"fibonacci:N"``: N near-uniform poses (golden-angle lattice).
        ``"EL:AZ,EL:AZ,..."``: an explicit list, degrees.
        At most :data:`~zbuf_occlude.defaults.MAX_VIEWS` poses, checked before any is made.

    Raises
    ------
    InvalidInputError
        On an unknown name, a malformed list, or more poses than ``MAX_VIEWS``.
    """
    spec = spec.strip()
    if spec == "paper100":
        return _paper100()
    if spec == "grid25":
        return [(el, az) for el in (-80.0, -40.0, 0.0, 40.0, 80.0) for az in (0.0, 72.0, 144.0, 216.0, 288.0)]
    if spec.startswith("fibonacci:"):
        n = _fibonacci_count(spec.split(":", 1)[1].strip())
        if n < 1:
            raise InvalidInputError(f"bad view schedule {_shown(spec)}: use fibonacci:N with N >= 1")
        if n > MAX_VIEWS:
            raise InvalidInputError(f"bad view schedule {_shown(spec)}: more than the {MAX_VIEWS:,} poses accepted (MAX_VIEWS)")
        return _fibonacci(n)
    listed = spec.count(",") + 1  # counted before the split: a list of 10⁷ poses is refused without making it
    if listed > MAX_VIEWS:
        raise InvalidInputError(
            f"bad view schedule {_shown(spec)}: {listed:,} poses listed, more than the {MAX_VIEWS:,} accepted (MAX_VIEWS)"
        )
    try:
        poses = [tuple(float(v) for v in item.split(":")) for item in spec.split(",") if item.strip()]
    except ValueError:
        poses = []
    if not poses or any(len(p) != 2 or not all(math.isfinite(v) for v in p) for p in poses):
        raise InvalidInputError(f"bad view schedule {_shown(spec)}: use paper100, grid25, fibonacci:N or EL:AZ,EL:AZ,... (degrees)")
    for el, _ in poses:
        if not -90.0 <= el <= 90.0:
            raise InvalidInputError(f"bad view schedule {_shown(spec)}: elevation {el} outside [-90, 90]")
    return [(p[0], p[1]) for p in poses]


def cameras_from_schedule(
    spec: str, radius: float = DEFAULT_RADIUS, *, resolution: int | tuple[int, int] = DEFAULT_RESOLUTION
) -> list[Camera]:
    """One :func:`camera_on_sphere` per pose of :func:`view_schedule` ``(spec)``."""
    return [camera_on_sphere(el, az, radius, resolution=resolution) for el, az in view_schedule(spec)]
