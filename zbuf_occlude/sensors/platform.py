"""The platform that carries a sensor: the sensor's pose (sensor → world) at any time.

A scanner is a device (the beam), a deflector (the scan pattern) and a platform: static, on a line, or
on a recorded trajectory (HELIOS++: Winiwarter et al. 2022, Remote Sensing of Environment 269).  A
:class:`Trajectory` answers the pose at any time within its samples: positions by linear interpolation,
attitudes by spherical linear interpolation (slerp: Shoemake 1985, "Animating rotation with quaternion
curves", SIGGRAPH '85, §3; :class:`scipy.spatial.transform.Slerp`).  :func:`load_trajectory` reads one
from a CSV a user gives (a robot's odometry).

Frames: the sensor frame is x forward, y left, z up (:func:`~zbuf_occlude.sensors.patterns.spinning.beam_directions`);
the world frame is z up, metres.  A pose is sensor → world: sensor point ``q`` is ``rotation @ q + position_m``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.geometry.arguments import described
from zbuf_occlude.io.caps import MAX_TRAJECTORY_POSES
from zbuf_occlude.io.trajectories import read_trajectory_table, trajectory_csv_bytes
from zbuf_occlude.sensors.checks import MAX_COORDINATE_M, located, real, reals, sensor_name, value_kind

__all__ = ["EULER_COLUMNS", "HALF_TURN_DEG", "HALF_TURN_SLACK_DEG", "MAX_TIME_S", "QUATERNION_COLUMNS", "QUATERNION_NORM_TOLERANCE",
           "ROTATION_TOLERANCE", "TIME_SLACK_S", "as_pose", "look_at_pose", "Trajectory", "load_trajectory"]  # fmt: skip

#: Largest |entry| of RᵀR − I, and |det R − 1|, of a rotation accepted (then re-orthonormalised):
#: a rotation printed to 7 significant digits passes, a scaled or sheared matrix does not.
ROTATION_TOLERANCE = 1e-6
#: Largest |‖q‖ − 1| of a file's quaternion accepted (then normalised): one printed to 4 decimals
#: is within 2e-4 of unit norm; one further off is not a rotation that was written down.
QUATERNION_NORM_TOLERANCE = 1e-3
#: Absolute slack, seconds, on a moving trajectory's span: a time computed as start + k·step may land
#: a rounding error past the last sample.
TIME_SLACK_S = 1e-9
#: Largest |time|, seconds (317 years): a Unix or GPS time is ~2e9 s; float64 keeps 2 µs steps up to here.
MAX_TIME_S = 1e10
#: Slerp turns the short way between two samples: a turn of a half turn or more between them is read as
#: another turn (a 270° yaw as 90° the other way, a 360° one as none), so it is refused.
HALF_TURN_DEG = 180.0
#: A turn within this of :data:`HALF_TURN_DEG` counts as one: a half turn written with rounded numbers
#: (a quaternion to 4 decimals is within 0.006° of it, a matrix to 7 digits within 1e-5°) would be
#: turned whichever way the rounding says.
HALF_TURN_SLACK_DEG = 0.01
#: Largest |roll|, |pitch|, |yaw| read, degrees (2,777 turns, for an unwrapped yaw); float64 keeps 1e-10° steps up to here.
_MAX_ANGLE_DEG = 1e6
#: The two CSV layouts: the header, then one row per pose.
EULER_COLUMNS = ("time_s", "x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg")
QUATERNION_COLUMNS = ("time_s", "x_m", "y_m", "z_m", "qx", "qy", "qz", "qw")


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Timed sensor poses (sensor → world), interpolated: position linearly, attitude by slerp (Shoemake 1985).

    Parameters
    ----------
    time_s : (T,) float
        Sample times, seconds (any origin), finite, strictly increasing, 1 ≤ T ≤
        :data:`~zbuf_occlude.io.caps.MAX_TRAJECTORY_POSES`, |t| ≤ :data:`MAX_TIME_S`.  T = 1: a
        static pose, valid at every time.
    position_m : (T, 3) float
        The sensor's origin in the world frame (z up), metres, each coordinate within
        ±:data:`~zbuf_occlude.sensors.checks.MAX_COORDINATE_M`.
    rotation : (T, 3, 3) float
        Sensor → world rotations (columns: the sensor's x forward, y left, z up in the world),
        orthonormal with det +1 within :data:`ROTATION_TOLERANCE`; stored re-orthonormalised (the
        nearest rotation, by SVD).  Each turns less than :data:`HALF_TURN_DEG` −
        :data:`HALF_TURN_SLACK_DEG` from the one before: slerp turns the short way, so a longer turn
        needs samples in between.
    name : str
        User name (metadata; it may name output files).

    Attributes
    ----------
    time_s, position_m, rotation : float64
        Read-only copies, shapes as above.

    Raises
    ------
    InvalidInputError
        Naming the trajectory and the field (``trajectory 'odom': time_s[3] must be later ...``):
        not real numbers of the shapes above; a value not finite or beyond its bound; a time not
        later than the one before; a matrix that is not a rotation; two consecutive attitudes a half
        turn or more apart (naming the samples: ``the attitude turns 180° or more between samples 3
        and 4``); a name that cannot name files.
    """

    time_s: NDArray[np.float64]
    position_m: NDArray[np.float64]
    rotation: NDArray[np.float64]
    name: str = "trajectory"

    def __post_init__(self) -> None:
        sensor_name(self.name, "trajectory name")
        with located(f"trajectory {self.name!r}"):
            time = _real_array(self.time_s, "time_s", (-1,))
            if not 1 <= len(time) <= MAX_TRAJECTORY_POSES:
                raise InvalidInputError(f"time_s must hold 1 to {MAX_TRAJECTORY_POSES:,} poses, got {len(time):,}")
            position = _real_array(self.position_m, "position_m", (len(time), 3))
            rotation = _real_array(self.rotation, "rotation", (len(time), 3, 3))
            bad = _first_bad(_sample_checks(time, position))
            if bad:
                raise InvalidInputError(f"{bad[0]}[{bad[1]}] {bad[2]}")
            rotation = _orthonormalised(rotation)
            turned = np.flatnonzero(_half_turns(rotation))
            if len(turned):
                raise InvalidInputError(f"{_turn_words(f'samples {turned[0] - 1} and {turned[0]}')}; add samples in between {_SHORT_WAY}")
        for field, value in (("time_s", time), ("position_m", position), ("rotation", rotation)):
            value.flags.writeable = False
            object.__setattr__(self, field, value)

    @classmethod
    def static(cls, pose: ArrayLike, *, name: str = "static") -> Trajectory:
        """One pose, valid at every time: ``pose`` (4, 4) sensor → world, or (3,) a position (world frame,
        metres) with the sensor's axes along the world's.  Raises InvalidInputError: ``pose`` is neither,
        its last row is not (0, 0, 0, 1), or :class:`Trajectory` refuses it."""
        rotation, position = _pose_parts(pose, "pose", single=True)
        return cls(np.zeros(1), position, rotation, name=name)

    @classmethod
    def linear(
        cls, pose: ArrayLike, velocity_mps: ArrayLike, duration_s: float, *, start_s: float = 0.0, name: str = "linear"
    ) -> Trajectory:
        """Constant velocity, fixed attitude: two samples, ``pose`` at ``start_s`` and moved by ``velocity_mps · duration_s``.

        Parameters
        ----------
        pose : (4, 4) or (3,) float
            The pose at ``start_s``, as :meth:`static` takes it.
        velocity_mps : (3,) float
            World frame, metres per second.
        duration_s, start_s : float
            Seconds; ``duration_s`` > 0.

        Raises
        ------
        InvalidInputError
            Not finite numbers of these shapes, ``duration_s`` ≤ 0, or what :class:`Trajectory` refuses.
        """
        rotation, position = _pose_parts(pose, "pose", single=True)
        velocity = np.array(reals(velocity_mps, "velocity_mps", lengths=(3,)))
        duration = real(duration_s, "duration_s", low=0.0, low_open=True)
        start = real(start_s, "start_s")
        time = np.array([start, start + duration])
        return cls(time, np.concatenate([position, position + velocity * duration]), np.concatenate([rotation, rotation]), name=name)

    @classmethod
    def from_poses(cls, time_s: ArrayLike, poses: ArrayLike, *, name: str = "trajectory") -> Trajectory:
        """Timed ``poses`` (T, 4, 4) sensor → world at ``time_s`` (T,) seconds.  Raises InvalidInputError: ``poses``
        not (T, 4, 4) real numbers, a last row other than (0, 0, 0, 1), or what :class:`Trajectory` refuses."""
        rotation, position = _pose_parts(poses, "poses", single=False)
        return cls(time_s, position, rotation, name=name)  # type: ignore[arg-type]

    @staticmethod
    def holds(position_m: ArrayLike) -> bool:
        """Whether positions ``(T, 3)`` metres lie within a trajectory's bound, ±:data:`~zbuf_occlude.sensors.checks.MAX_COORDINATE_M`."""
        return not np.any(_beyond_bound(np.asarray(position_m, dtype=np.float64).reshape(-1, 3)))

    def __len__(self) -> int:
        """T, the samples."""
        return len(self.time_s)

    @cached_property
    def is_static(self) -> bool:
        """One pose, or every sample's position and rotation equal (exactly): valid at every time."""
        return len(self) == 1 or bool(np.all(self.position_m == self.position_m[0]) and np.all(self.rotation == self.rotation[0]))

    @property
    def start_s(self) -> float:
        """The first sample's time, seconds."""
        return float(self.time_s[0])

    @property
    def end_s(self) -> float:
        """The last sample's time, seconds."""
        return float(self.time_s[-1])

    @property
    def duration_s(self) -> float:
        """``end_s − start_s``, seconds (0 for one pose)."""
        return self.end_s - self.start_s

    def poses_at(self, time_s: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The poses at ``time_s``: positions by linear interpolation, attitudes by slerp.

        Slerp (Shoemake 1985, SIGGRAPH '85, §3; :class:`scipy.spatial.transform.Slerp`) turns at a constant
        rate about one axis between two samples, the short way round, so consecutive samples are less
        than a half turn apart (:class:`Trajectory` refuses them otherwise): a longer turn is written
        with samples in between.  The work grows with the samples around ``time_s`` (found by binary
        search), not with the trajectory's length.

        Parameters
        ----------
        time_s : float or (N,) float
            Seconds.  A static trajectory (:attr:`is_static`) answers any finite time; a moving
            one, times within ``[start_s, end_s]`` (:data:`TIME_SLACK_S` beyond either end allowed).

        Returns
        -------
        rotation : (N, 3, 3) float64
            Sensor → world (N = 1 for a scalar time).
        position : (N, 3) float64
            World frame, metres; on the segment between the two samples around each time.

        Raises
        ------
        InvalidInputError
            ``time_s`` is not finite real numbers (a scalar or 1-D), or outside a moving trajectory's span (named).
        """
        t = _real_array(time_s, "time_s", None)
        if t.ndim > 1 or not np.all(np.isfinite(t)):
            raise InvalidInputError(f"trajectory {self.name!r}: time_s must be finite seconds (a number or 1-D), got {value_kind(time_s)}")
        t = t.reshape(-1)
        if self.is_static:
            return np.repeat(self.rotation[:1], len(t), axis=0), np.repeat(self.position_m[:1], len(t), axis=0)
        out = np.flatnonzero((t < self.start_s - TIME_SLACK_S) | (t > self.end_s + TIME_SLACK_S))
        if len(out):
            side = "before its first sample" if t[out[0]] < self.start_s else "after its last sample"
            raise InvalidInputError(
                f"trajectory {self.name!r}: time_s[{out[0]}] is {side} ({len(out):,} of {len(t):,} times outside its span)"
            )
        from scipy.spatial.transform import Rotation, Slerp

        t = np.clip(t, self.start_s, self.end_s)
        i = np.clip(np.searchsorted(self.time_s, t, side="right") - 1, 0, len(self) - 2)
        f = (t - self.time_s[i]) / (self.time_s[i + 1] - self.time_s[i])
        position = self.position_m[i] + f[:, None] * (self.position_m[i + 1] - self.position_m[i])
        if not len(t):
            return np.zeros((0, 3, 3)), position
        # Slerp over the samples around the times only: each segment is interpolated on its own, so the
        # window's answers are the whole trajectory's, bit for bit (its segment search is side="left")
        lo = max(int(np.searchsorted(self.time_s, t.min(), side="left")) - 1, 0)
        hi = max(int(np.searchsorted(self.time_s, t.max(), side="left")), lo + 1)
        window = slice(lo, hi + 1)
        rotation = Slerp(self.time_s[window], Rotation.from_matrix(self.rotation[window]))(t).as_matrix()
        return rotation, position

    def csv_bytes(self, time_offset_s: float = 0.0, position_offset_m=(0.0, 0.0, 0.0)) -> bytes:
        """The trajectory as a CSV of :data:`EULER_COLUMNS` that :func:`load_trajectory` reads back to these poses
        (:func:`~zbuf_occlude.io.trajectories.trajectory_csv_bytes`), times plus ``time_offset_s`` (seconds) and positions
        plus ``position_offset_m`` ((3,) metres: another frame's coordinates); each angle column unwrapped (179 then 181,
        not 179 then -179), as the reader wants."""
        from scipy.spatial.transform import Rotation

        angles = np.degrees(np.unwrap(np.radians(Rotation.from_matrix(self.rotation).as_euler("xyz", degrees=True)), axis=0))
        offset = np.asarray(position_offset_m, dtype=np.float64).reshape(3)
        return trajectory_csv_bytes(EULER_COLUMNS, np.column_stack([self.time_s + float(time_offset_s), self.position_m + offset, angles]))

    def since(self, start_s: float, until_s: float | None = None) -> Trajectory:
        """The trajectory from ``start_s`` on: the pose there (:meth:`poses_at`), then the samples after it.

        The platform of a later sweep along the same path (a scan starts at its platform's
        :attr:`start_s`).  A static trajectory stays static, starting at ``start_s``.

        Parameters
        ----------
        start_s : float
            Seconds, within a moving trajectory's span and before its end.
        until_s : float, optional
            Seconds: keep the samples up to the first at or after ``until_s`` (:data:`TIME_SLACK_S`
            beyond it), the last of them, if the trajectory ends sooner.  The new trajectory answers
            every time up to ``until_s`` as this one does, bit for bit, and holds only the samples
            around ``[start_s, until_s]``: a sweep of a long trajectory costs what its own samples
            cost.  Default: every later sample.

        Raises
        ------
        InvalidInputError
            ``start_s`` or ``until_s`` not a finite number, ``until_s`` not after ``start_s``,
            ``start_s`` outside a moving trajectory's span, or at its end (no motion left to sweep
            along).
        """
        t0 = real(start_s, "start_s")
        t1 = None if until_s is None else real(until_s, "until_s", low=t0, low_open=True)
        if self.is_static:
            return Trajectory(np.array([t0]), self.position_m[:1], self.rotation[:1], name=self.name)
        first = int(np.searchsorted(self.time_s, t0 + TIME_SLACK_S, side="right"))  # the first sample later than t0
        if first == len(self):
            raise InvalidInputError(
                f"trajectory {self.name!r}: start_s is at or after its last sample: nothing of it is left to sweep along"
            )
        last = len(self) if t1 is None else int(np.searchsorted(self.time_s, t1 + TIME_SLACK_S, side="left")) + 1
        later = slice(first, last)
        rotation, position = self.poses_at(np.array([t0]))
        return Trajectory(np.r_[t0, self.time_s[later]], np.vstack([position, self.position_m[later]]),
                          np.concatenate([rotation, self.rotation[later]]), name=self.name)  # fmt: skip

    def pose_at(self, t: float) -> NDArray[np.float64]:
        """(4, 4) float64 sensor → world pose at ``t`` seconds (:meth:`poses_at`, whose errors it raises)."""
        rotation, position = self.poses_at(np.array([real(t, "t")]))
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rotation[0], position[0]
        return pose


def look_at_pose(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> NDArray[np.float64]:
    """(4, 4) float64 camera → world transform of an OpenCV camera (x right, y down, z forward)
    at ``eye`` looking at ``target`` (world frame, metres).

    Raises
    ------
    InvalidInputError
        ``eye == target`` or ``up`` parallel to the view direction.
    """
    eye, target, up = (np.asarray(v, dtype=np.float64).reshape(3) for v in (eye, target, up))
    z = target - eye
    if np.linalg.norm(z) == 0:
        raise InvalidInputError("look_at_pose: eye and target coincide")
    z /= np.linalg.norm(z)
    x = np.cross(z, up)  # right of the view direction, with up above it: y = z × x points down
    if np.linalg.norm(x) < 1e-9:
        raise InvalidInputError(f"look_at_pose: up {up} is parallel to the view direction")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, :3] = np.column_stack([x, y, z])
    m[:3, 3] = eye
    return m


def as_pose(pose) -> NDArray[np.float64]:
    """(4, 4) float64 sensor → world pose from a (4, 4) matrix or a (3,) position (no turn), its values as given.

    Raises
    ------
    InvalidInputError
        Not real numbers (a string, a ragged list), another shape, a value not finite, a last row other
        than (0, 0, 0, 1), or a rotation that is not orthonormal and right-handed (no scale).
    """
    rotation, position = _pose_parts(pose, "sensor pose", single=True)
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rotation[0], position[0]
    if not np.all(np.isfinite(m)):
        raise InvalidInputError(f"sensor pose must be finite numbers, got {value_kind(pose)}")
    r = m[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
        raise InvalidInputError("sensor pose rotation must be orthonormal and right-handed (no scale)")
    return m


def load_trajectory(path: str | PathLike[str], *, within: str | PathLike[str] | None = None, name: str | None = None) -> Trajectory:
    """A :class:`Trajectory` from a CSV file (a robot's odometry, a survey's trajectory).

    A header line, then a row per pose, numbers separated by commas (spaces around them allowed;
    blank lines skipped, counted towards the cap on rows).  Two layouts, by header:

    * ``time_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg``: extrinsic x-y-z Euler angles in degrees (about
      the world's fixed x, then y, then z: ``scipy.spatial.transform.Rotation.from_euler("xyz", [roll,
      pitch, yaw], degrees=True)``), each within ±10⁶°;
    * ``time_s,x_m,y_m,z_m,qx,qy,qz,qw``: a unit quaternion, scalar last (scipy's order), normalised; a
      norm further than :data:`QUATERNION_NORM_TOLERANCE` from 1 is refused.

    Positions: the sensor's origin, world frame (z up), metres; the attitude turns the sensor frame (x
    forward, y left, z up) into the world's.  Slerp turns the short way between rows, so consecutive
    rows are less than a half turn apart (:data:`HALF_TURN_DEG`, within :data:`HALF_TURN_SLACK_DEG`),
    both in each angle column as written (unwrapped: 179 then 181, not 179 then -179) and in attitude;
    a longer turn is written with rows in between.  Read whole by :func:`~zbuf_occlude.io.regular_files.read_text_file`
    (a regular file, at most :data:`~zbuf_occlude.io.caps.MAX_TRAJECTORY_BYTES`, UTF-8).

    Parameters
    ----------
    path : str or PathLike
    within : str or PathLike, optional
        The folder ``path`` was named from: it must stay inside it, links resolved.
    name : str, optional
        The trajectory's name; default: the file's stem.

    Raises
    ------
    ArgumentTypeError
        ``path`` or ``within`` is not a path.
    InvalidInputError
        One line naming the file (and the line), never quoting it: missing, not a regular file (a FIFO, a
        folder), too large, not UTF-8; empty; another header; a line over :data:`~zbuf_occlude.io.caps.MAX_TRAJECTORY_LINE_BYTES`;
        more lines after the header than :data:`~zbuf_occlude.io.caps.MAX_TRAJECTORY_POSES` (before a row is
        parsed), or none; a row not of the header's width; a value not finite or out of bounds
        (:class:`Trajectory`'s); times not increasing; a quaternion far from unit norm; two consecutive
        rows a half turn or more apart (naming both lines), as an angle column is written (its
        difference, so 0 then 360, or 170 then -170, is a turn of 360° or 340°) or as the attitudes
        are (the rotation from one to the next).
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    if not isinstance(path, (str, PathLike)):
        raise ArgumentTypeError(f"path must be a trajectory file's path (str or os.PathLike), got {described(path)}")
    if within is not None and not isinstance(within, (str, PathLike)):
        raise ArgumentTypeError(f"within must be a folder's path (str or os.PathLike) or None, got {described(within)}")
    columns, table, line_of = read_trajectory_table(path, tuple(_LAYOUTS), within=within)
    *attitude_check, rotation, written_turns = _LAYOUTS[columns](table[:, 4:])
    bad = _first_bad([*_sample_checks(table[:, 0], table[:, 1:4]), attitude_check])
    if bad:
        raise InvalidInputError(f"{path}: line {line_of[bad[1]]:,}: {bad[0]} {bad[2]}")
    # the earliest pair of rows a half turn apart, as an angle column is written or (None) as the attitudes are
    checks = [*written_turns, (None, _half_turns(rotation))]
    turns = [(int(np.argmax(flags)), order, column) for order, (column, flags) in enumerate(checks) if flags.any()]
    if turns:
        row, _, column = min(turns)
        written = "" if column is None else f", as {column} is written"
        unwrap = (
            "" if column is None else ", or, for a short turn across ±180°, write the angles unwrapped (179 then 181, not 179 then -179)"
        )
        raise InvalidInputError(f"{path}: lines {line_of[row - 1]:,} and {line_of[row]:,}: {_turn_words('them')}{written}; "
                                f"add samples in between {_SHORT_WAY}{unwrap}")  # fmt: skip
    with located(str(path)):
        return Trajectory(table[:, 0], table[:, 1:4], rotation, name=Path(path).stem if name is None else name)


def _real_array(value: object, name: str, shape: tuple[int, ...] | None) -> NDArray[np.float64]:
    """``value`` as a float64 copy, refused unless real numbers (bools refused) of ``shape`` (-1: any length; None: any)."""
    try:
        a = np.asarray(value)
    except (ValueError, TypeError):  # a ragged list
        raise InvalidInputError(f"{name} must be an array of real numbers, got {described(value)}") from None
    fits = shape is None or (a.ndim == len(shape) and all(k in (-1, n) for k, n in zip(shape, a.shape, strict=True)))
    if a.dtype.kind not in "fiu" or not fits:
        want = "" if shape is None else f" of shape {tuple('N' if k == -1 else k for k in shape)}".replace("'", "")
        raise InvalidInputError(f"{name} must be an array of real numbers{want}, got shape {a.shape} dtype {a.dtype.name}")
    with np.errstate(over="ignore"):  # an integer beyond float64 becomes inf, refused as not finite
        return np.array(a, dtype=np.float64)


def _sample_checks(time: NDArray[np.float64], position: NDArray[np.float64]) -> list[tuple[str, NDArray[np.bool_], str]]:
    """``(field, the rows refused (T,) bool, why)`` of each check of the samples' times and positions."""
    return [
        ("time_s", ~(np.abs(time) <= MAX_TIME_S), f"must be a finite number of seconds within ±{MAX_TIME_S:g}"),
        ("position_m", _beyond_bound(position), f"must be finite, within ±{MAX_COORDINATE_M:g} m"),
        ("time_s", np.concatenate([[False], np.diff(time) <= 0]), "must be later than the time before it (times strictly increase)"),
    ]


def _beyond_bound(position: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(T,) bool: the rows of ``position (T, 3)`` not finite within ±:data:`~zbuf_occlude.sensors.checks.MAX_COORDINATE_M`."""
    return ~np.all(np.abs(position) <= MAX_COORDINATE_M, axis=1)


def _first_bad(checks: list) -> tuple[str, int, str] | None:
    """``(field, row, why)`` of the first row the first failing check of ``checks`` (:func:`_sample_checks`) refuses, or None."""
    for field, bad, what in checks:
        rows = np.flatnonzero(bad)
        if len(rows):
            return field, int(rows[0]), what
    return None


def _orthonormalised(rotation: NDArray[np.float64]) -> NDArray[np.float64]:
    """The nearest rotations (polar factor, by SVD) of ``rotation`` (T, 3, 3), each checked to be one within :data:`ROTATION_TOLERANCE`."""
    finite = np.all(np.isfinite(rotation), axis=(1, 2))
    with np.errstate(over="ignore", invalid="ignore"):  # a huge entry: an inf error, refused
        error = np.abs(np.swapaxes(rotation, 1, 2) @ rotation - np.eye(3)).max(axis=(1, 2))
        det = np.linalg.det(np.where(finite[:, None, None], rotation, 0.0))
    bad = np.flatnonzero(~finite | ~(error <= ROTATION_TOLERANCE) | ~(np.abs(det - 1.0) <= ROTATION_TOLERANCE))
    if len(bad):
        got = "a value that is not finite" if not finite[bad[0]] else f"|RᵀR − I| = {error[bad[0]]:.3g}, det {det[bad[0]]:.6g}"
        raise InvalidInputError(f"rotation[{bad[0]}] must be a rotation (orthonormal, det +1, within {ROTATION_TOLERANCE:g}); got {got}")
    u, _, vt = np.linalg.svd(rotation)
    return u @ vt


def _pose_parts(pose: ArrayLike, name: str, *, single: bool) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(rotations (T, 3, 3), positions (T, 3)) of (T, 4, 4) sensor → world poses, or (``single``) of one (4, 4) pose
    or one (3,) position (identity attitude), T = 1; a last row other than (0, 0, 0, 1) refused."""
    a = _real_array(pose, name, None if single else (-1, 4, 4))
    if single and a.shape == (3,):
        return np.eye(3)[None], a[None]
    if single and a.shape != (4, 4):
        raise InvalidInputError(f"{name} must be a (4, 4) sensor→world matrix or a (3,) position, got shape {a.shape}")
    a = a.reshape(-1, 4, 4)
    bad = np.flatnonzero(~np.all(np.abs(a[:, 3] - (0.0, 0.0, 0.0, 1.0)) <= ROTATION_TOLERANCE, axis=1))
    if len(bad):
        raise InvalidInputError(f"{name}[{bad[0]}]'s last row must be (0, 0, 0, 1): a sensor→world rigid transform")
    return a[:, :3, :3], a[:, :3, 3]


def _half_turns(rotation: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(T,) bool: whether rotation ``i`` (T, 3, 3) is :data:`HALF_TURN_DEG` or more (within :data:`HALF_TURN_SLACK_DEG`)
    from rotation ``i − 1``; False for the first.  By the trace, ``1 + 2 cos θ`` of ``R[i−1]ᵀ R[i]`` (linear in the
    entries, for a million samples at once): at the threshold, rounding moves θ by less than 1e-9°."""
    trace = np.einsum("tij,tij->t", rotation[:-1], rotation[1:])
    return np.r_[False, trace <= 1.0 + 2.0 * np.cos(np.radians(HALF_TURN_DEG - HALF_TURN_SLACK_DEG))]


def _turn_words(where: str) -> str:
    """What a half turn between two samples (``where``) is refused for."""
    return f"the attitude turns {HALF_TURN_DEG:g}° or more between {where}"


#: Why a long turn needs samples in between.
_SHORT_WAY = "(slerp turns the short way)"
#: Each angle column's name and the rows (N,) bool it turns a half turn or more from the row before, as written.
_Turns = list[tuple[str, NDArray[np.bool_]]]


def _euler_rotations(angles: NDArray[np.float64]) -> tuple[str, NDArray[np.bool_], str, NDArray[np.float64], _Turns]:
    """Roll, pitch, yaw (N, 3) degrees, extrinsic x-y-z: (their columns, the rows refused (N,) bool, why, the (N, 3, 3) rotations,
    and for each column ``(name, (N,) bool)``: the rows it turns a half turn or more from the row before, as written)."""
    from scipy.spatial.transform import Rotation

    bad = ~np.all(np.abs(angles) <= _MAX_ANGLE_DEG, axis=1)
    rotations = Rotation.from_euler("xyz", np.where(bad[:, None], 0.0, angles), degrees=True).as_matrix()
    with np.errstate(invalid="ignore"):  # a bad row's inf or NaN: refused before these are read
        written = np.abs(np.diff(angles, axis=0)) >= HALF_TURN_DEG - HALF_TURN_SLACK_DEG
    turns = [(column, np.r_[False, written[:, k]]) for k, column in enumerate(EULER_COLUMNS[4:])]
    return "roll_deg, pitch_deg, yaw_deg", bad, f"must be finite, within ±{_MAX_ANGLE_DEG:g}°", rotations, turns


def _quaternion_rotations(q: NDArray[np.float64]) -> tuple[str, NDArray[np.bool_], str, NDArray[np.float64], _Turns]:
    """Quaternions (N, 4), scalar last, normalised: (their columns, the rows refused (N,) bool, why, the (N, 3, 3) rotations,
    no turns as written: a quaternion and its negative are one attitude)."""
    from scipy.spatial.transform import Rotation

    with np.errstate(over="ignore", invalid="ignore"):
        norm = np.sqrt(np.sum(q * q, axis=1))
        bad = ~(np.abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE)
        rotations = Rotation.from_quat(np.where(bad[:, None], (0.0, 0.0, 0.0, 1.0), q / norm[:, None])).as_matrix()
    return "qx, qy, qz, qw", bad, f"must be a unit quaternion (norm within {QUATERNION_NORM_TOLERANCE:g} of 1)", rotations, []


#: Each header's columns → how the columns after the position are checked and become rotations.
_LAYOUTS: dict[tuple[str, ...], Callable[[NDArray[np.float64]], tuple]] = {
    EULER_COLUMNS: _euler_rotations, QUATERNION_COLUMNS: _quaternion_rotations,
}  # fmt: skip
