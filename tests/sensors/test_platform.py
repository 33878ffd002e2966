"""The platform (:mod:`zbuf_occlude.sensors.platform`): a trajectory answers the pose at any time within it,
positions on the segment between samples and attitudes by slerp (against closed forms: a constant velocity, a
90° yaw); its fields are checked; trajectory CSVs of both layouts are read exactly, and hostile ones are refused
in one line naming the file (and the line), never quoting it."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import zbuf_occlude.io.trajectories as trajectories
import zbuf_occlude.sensors.platform as platform
from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError, UnsafePathError
from zbuf_occlude.sensors.platform import EULER_COLUMNS, QUATERNION_COLUMNS, TIME_SLACK_S, Trajectory, load_trajectory

EULER = ",".join(EULER_COLUMNS)
QUATERNION = ",".join(QUATERNION_COLUMNS)
#: What a private file holds; no message may show it (nor a part of it).
MARKER = "Zq7SecretMarker"


def _yaw(deg: float) -> np.ndarray:
    return Rotation.from_euler("z", deg, degrees=True).as_matrix()


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle of the rotation taking ``a`` to ``b``, degrees."""
    return float(np.degrees(Rotation.from_matrix(a.T @ b).magnitude()))


def _write(path: Path, text: str | bytes) -> Path:
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


# -- analytic cases --------------------------------------------------------------------------------


def test_a_linear_trajectory_is_at_p0_plus_v_t() -> None:
    p0, v = np.array([1.0, -2.0, 1.8]), np.array([3.0, 0.5, -0.25])
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = _yaw(30.0), p0
    trajectory = Trajectory.linear(pose, v, 10.0)
    t = np.linspace(0.0, 10.0, 101)
    rotation, position = trajectory.poses_at(t)
    np.testing.assert_allclose(position, p0 + v * t[:, None], rtol=0, atol=1e-12)
    np.testing.assert_allclose(rotation, np.broadcast_to(_yaw(30.0), (101, 3, 3)), rtol=0, atol=1e-12)
    assert (trajectory.start_s, trajectory.end_s, trajectory.duration_s, trajectory.is_static) == (0.0, 10.0, 10.0, False)


def test_a_linear_trajectory_starts_at_start_s() -> None:
    trajectory = Trajectory.linear([0.0, 0.0, 0.0], [2.0, 0.0, 0.0], 4.0, start_s=100.0)
    np.testing.assert_allclose(trajectory.pose_at(101.5)[:3, 3], [3.0, 0.0, 0.0], rtol=0, atol=1e-12)
    with pytest.raises(InvalidInputError, match=r"(before its first|after its last) sample \(1 of 1 times outside its span\)"):
        trajectory.pose_at(99.0)


def test_slerp_of_a_90_degree_yaw_over_a_second_gives_45_at_half() -> None:
    trajectory = Trajectory(np.array([0.0, 1.0]), np.zeros((2, 3)), np.stack([_yaw(0.0), _yaw(90.0)]))
    rotation, _ = trajectory.poses_at([0.25, 0.5, 0.75])
    np.testing.assert_allclose(rotation, np.stack([_yaw(22.5), _yaw(45.0), _yaw(67.5)]), rtol=0, atol=1e-12)


def test_slerp_takes_the_short_way_round() -> None:
    # 350° of yaw is 10° the other way: half way is at -5°, not at 175°
    trajectory = Trajectory(np.array([0.0, 1.0]), np.zeros((2, 3)), np.stack([_yaw(0.0), _yaw(350.0)]))
    np.testing.assert_allclose(trajectory.pose_at(0.5)[:3, :3], _yaw(-5.0), rtol=0, atol=1e-12)


@pytest.mark.parametrize("pose", [np.array([1.0, 2.0, 3.0]), np.array([[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1.0]])])
def test_a_static_trajectory_answers_any_time(pose: np.ndarray) -> None:
    trajectory = Trajectory.static(pose)
    expected = pose if pose.shape == (4, 4) else np.block([[np.eye(3), pose[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]])
    assert trajectory.is_static and trajectory.duration_s == 0.0
    for t in (-1e9, 0.0, 3.5, 1e9):
        np.testing.assert_array_equal(trajectory.pose_at(t), expected)
    rotation, position = trajectory.poses_at(np.array([-5.0, 5.0]))
    assert rotation.shape == (2, 3, 3) and position.shape == (2, 3) and rotation.dtype == position.dtype == np.float64


def test_samples_all_equal_are_static_and_answer_outside_their_span() -> None:
    trajectory = Trajectory(np.array([0.0, 1.0, 2.0]), np.ones((3, 3)), np.stack([_yaw(10.0)] * 3))
    assert trajectory.is_static
    np.testing.assert_array_equal(trajectory.pose_at(50.0)[:3, :3], trajectory.rotation[0])
    moved = Trajectory(np.array([0.0, 1.0]), np.array([[0.0, 0, 0], [0, 0, 1e-9]]), np.stack([np.eye(3)] * 2))
    assert not moved.is_static


def test_from_poses_gives_back_the_poses_at_their_times() -> None:
    rng = np.random.default_rng(0)
    rotations = Rotation.random(6, random_state=1).as_matrix()
    poses = np.tile(np.eye(4), (6, 1, 1))
    poses[:, :3, :3], poses[:, :3, 3] = rotations, rng.uniform(-50.0, 50.0, (6, 3))
    time = np.cumsum(rng.uniform(0.01, 1.0, 6)) + 1.7e9  # a Unix time
    trajectory = Trajectory.from_poses(time, poses)
    for t, pose in zip(time, poses, strict=True):
        np.testing.assert_allclose(trajectory.pose_at(t), pose, rtol=0, atol=1e-12)
    rotation, position = trajectory.poses_at(time)
    np.testing.assert_allclose(rotation, rotations, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(position, poses[:, :3, 3])


def test_a_time_outside_a_moving_trajectory_is_refused_naming_the_span() -> None:
    trajectory = Trajectory.linear([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 2.0, name="odom")
    trajectory.poses_at([-TIME_SLACK_S / 2, 2.0 + TIME_SLACK_S / 2])  # rounding past an end is allowed
    with pytest.raises(InvalidInputError, match=r"trajectory 'odom': time_s\[1\] is after its last sample"):
        trajectory.poses_at([1.0, 2.001])
    with pytest.raises(InvalidInputError, match=r"time_s must be finite seconds"):
        trajectory.poses_at([np.nan])


def test_a_rotation_slightly_off_is_re_orthonormalised() -> None:
    noisy = _yaw(20.0) + 1e-8 * np.random.default_rng(3).standard_normal((3, 3))
    stored = Trajectory(np.zeros(1), np.zeros((1, 3)), noisy[None]).rotation[0]
    np.testing.assert_allclose(stored.T @ stored, np.eye(3), rtol=0, atol=1e-15)
    np.testing.assert_allclose(stored, _yaw(20.0), rtol=0, atol=1e-7)


def test_the_arrays_are_read_only_copies() -> None:
    time = np.array([0.0, 1.0])
    trajectory = Trajectory(time, np.zeros((2, 3)), np.stack([np.eye(3)] * 2))
    time[1] = 5.0
    assert trajectory.end_s == 1.0
    with pytest.raises(ValueError, match="read-only"):
        trajectory.position_m[0, 0] = 1.0


_I2 = np.stack([np.eye(3)] * 2)


@pytest.mark.parametrize(
    ("fields", "match"),
    [
        ((np.array([0.0, 0.0]), np.zeros((2, 3)), _I2), r"time_s\[1\] must be later than the time before it"),
        ((np.array([1.0, 0.0]), np.zeros((2, 3)), _I2), r"time_s\[1\] must be later"),
        ((np.array([0.0, np.nan]), np.zeros((2, 3)), _I2), r"time_s\[1\] must be a finite number of seconds"),
        ((np.array([0.0, 1e300]), np.zeros((2, 3)), _I2), r"time_s\[1\] must be a finite number of seconds within"),
        ((np.array([0.0, 1.0]), np.array([[0, 0, 0], [0, np.inf, 0]]), _I2), r"position_m\[1\] must be finite"),
        ((np.array([0.0, 1.0]), np.array([[0, 0, 0], [0, 1e300, 0]]), _I2), r"position_m\[1\] must be finite, within"),
        ((np.array([0.0, 1.0]), np.zeros((2, 3)), np.stack([np.eye(3), 2 * np.eye(3)])), r"rotation\[1\] must be a rotation"),
        ((np.array([0.0, 1.0]), np.zeros((2, 3)), np.stack([np.eye(3), -np.eye(3)])), r"rotation\[1\] must be a rotation.*det -1"),
        ((np.array([0.0, 1.0]), np.zeros((2, 3)), np.stack([np.eye(3), np.full((3, 3), np.nan)])), r"rotation\[1\].*not finite"),
        ((np.array([0.0, 1.0]), np.zeros((3, 3)), _I2), r"position_m must be an array of real numbers of shape \(2, 3\)"),
        ((np.array([0.0, 1.0]), np.zeros((2, 3)), np.zeros((2, 4, 4))), r"rotation must be .* shape \(2, 3, 3\)"),
        ((np.array([True]), np.zeros((1, 3)), _I2[:1]), r"time_s must be an array of real numbers .*dtype bool"),
        ((np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3))), r"time_s must hold 1 to 1,000,000 poses, got 0"),
    ],
)
def test_bad_fields_are_refused_naming_the_field(fields: tuple, match: str) -> None:
    with pytest.raises(InvalidInputError, match=r"^trajectory 'trajectory': " + match):
        Trajectory(*fields)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: Trajectory.static(np.ones((4, 4))), r"pose\[0\]'s last row must be \(0, 0, 0, 1\)"),
        (lambda: Trajectory.static(np.zeros(4)), r"pose must be a \(4, 4\) sensor→world matrix or a \(3,\) position"),
        (lambda: Trajectory.linear([0, 0, 0], [1, 0], 1.0), r"velocity_mps must be a list of 3 numbers"),
        (lambda: Trajectory.linear([0, 0, 0], [1, 0, 0], 0.0), r"duration_s must be a finite number > 0"),
        (lambda: Trajectory.linear([0, 0, 0], [1e300, 0, 0], 1.0), r"position_m\[1\] must be finite, within"),
        (lambda: Trajectory.from_poses([0.0], np.eye(3)[None]), r"poses must be .* shape \(N, 4, 4\)"),
        (lambda: Trajectory(np.zeros(1), np.zeros((1, 3)), _I2[:1], name="a/b"), r"trajectory name must be"),
        (
            lambda: Trajectory.linear([0, 0, 0], [1, 0, 0], 1.0).poses_at(np.zeros((2, 2))),
            r"time_s must be finite seconds \(a number or 1-D\)",
        ),
    ],
)
def test_bad_arguments_are_refused(make, match: str) -> None:
    with pytest.raises(InvalidInputError, match=match):
        make()


# -- laws ------------------------------------------------------------------------------------------

_quaternions = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1)
_positions = st.lists(st.floats(-1000.0, 1000.0), min_size=3, max_size=3)


def _less_than_half_turns_apart(samples) -> bool:
    """Consecutive attitudes less than 179.9° apart (a trajectory refuses half turns): |q·q'| = |cos(θ/2)|."""
    q = np.array([quat for _, _, quat in samples]) / np.linalg.norm([quat for _, _, quat in samples], axis=1)[:, None]
    return bool(np.all(np.abs(np.sum(q[:-1] * q[1:], axis=1)) > np.cos(np.radians(179.9 / 2))))


_samples = st.lists(st.tuples(st.floats(1e-3, 10.0), _positions, _quaternions), min_size=2, max_size=6).filter(_less_than_half_turns_apart)


def _trajectory(samples) -> Trajectory:
    time = np.cumsum([step for step, _, _ in samples])
    return Trajectory(time, np.array([p for _, p, _ in samples]), Rotation.from_quat([q for _, _, q in samples]).as_matrix())


@settings(max_examples=80, deadline=None)
@given(samples=_samples, fractions=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20))
def test_interpolated_rotations_stay_rotations(samples, fractions) -> None:
    trajectory = _trajectory(samples)
    rotation, _ = trajectory.poses_at(trajectory.start_s + np.array(fractions) * trajectory.duration_s)
    np.testing.assert_allclose(np.swapaxes(rotation, 1, 2) @ rotation, np.broadcast_to(np.eye(3), rotation.shape), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rotation), 1.0, rtol=0, atol=1e-12)


@settings(max_examples=80, deadline=None)
@given(samples=_samples, segment=st.integers(0, 4), fraction=st.floats(0.0, 1.0))
def test_an_interpolated_pose_lies_between_its_neighbouring_samples(samples, segment, fraction) -> None:
    trajectory = _trajectory(samples)
    i = segment % (len(trajectory) - 1)
    t0, t1 = trajectory.time_s[i], trajectory.time_s[i + 1]
    t = min(t0 + fraction * (t1 - t0), t1)
    rotation, position = trajectory.poses_at(t)
    # the position is on the segment between the samples' positions
    p0, p1 = trajectory.position_m[i], trajectory.position_m[i + 1]
    d = p1 - p0
    s = float(np.dot(position[0] - p0, d) / np.dot(d, d)) if np.dot(d, d) > 0 else 0.0
    assert -1e-12 <= s <= 1 + 1e-12
    np.testing.assert_allclose(position[0], p0 + s * d, rtol=0, atol=1e-9)
    # the attitude turns the short way at a constant rate about one axis: the angles from either sample add up to the step's
    r0, r1 = trajectory.rotation[i], trajectory.rotation[i + 1]
    step = _angle_deg(r0, r1)
    if step < 179.0:  # at 180° the short way round is not unique
        np.testing.assert_allclose(_angle_deg(r0, rotation[0]) + _angle_deg(rotation[0], r1), step, rtol=0, atol=1e-6)
        np.testing.assert_allclose(_angle_deg(r0, rotation[0]), (t - t0) / (t1 - t0) * step, rtol=0, atol=1e-6)


# -- CSV files -------------------------------------------------------------------------------------


def test_an_euler_csv_is_read_as_extrinsic_xyz_degrees(tmp_path: Path) -> None:
    rows = np.array([[0.0, 1.0, 2.0, 3.0, 10.0, 20.0, 370.0], [0.5, 2.0, 2.5, 3.0, -5.0, 40.0, 400.0]])  # yaw unwrapped past a turn
    text = EULER + "\n" + "\n".join(",".join(f"{v:.17g}" for v in row) for row in rows) + "\n"
    trajectory = load_trajectory(_write(tmp_path / "odom.csv", text))
    assert trajectory.name == "odom"
    np.testing.assert_array_equal(trajectory.time_s, rows[:, 0])
    np.testing.assert_array_equal(trajectory.position_m, rows[:, 1:4])
    expected = Rotation.from_euler("xyz", rows[:, 4:], degrees=True).as_matrix()
    np.testing.assert_allclose(trajectory.rotation, expected, rtol=0, atol=1e-15)
    intrinsic = Rotation.from_euler("XYZ", rows[:, 4:], degrees=True).as_matrix()
    assert np.abs(trajectory.rotation - intrinsic).max() > 0.1  # the convention is told apart


def test_a_quaternion_csv_is_read_scalar_last_and_normalised(tmp_path: Path) -> None:
    q = Rotation.from_euler("z", [[0.0], [90.0]], degrees=True).as_quat()  # scalar last
    q[1] *= 1.0005  # printed with a few decimals: not quite unit
    text = f"\ufeff {QUATERNION.replace(',', ' , ')}\r\n" + "".join(
        f"{t}, 1, 2, 3, {', '.join(f'{v:.6f}' for v in quat)}\r\n\r\n" for t, quat in zip([0.0, 2.0], q, strict=True)
    )
    trajectory = load_trajectory(_write(tmp_path / "q.csv", text), name="imu")
    assert trajectory.name == "imu"
    np.testing.assert_allclose(trajectory.rotation, np.stack([_yaw(0.0), _yaw(90.0)]), rtol=0, atol=1e-6)
    np.testing.assert_allclose(trajectory.pose_at(1.0)[:3, :3], _yaw(45.0), rtol=0, atol=1e-6)


def test_a_link_is_followed_inside_its_folder_and_refused_outside(tmp_path: Path) -> None:
    outside, folder = tmp_path / "outside", tmp_path / "folder"
    outside.mkdir()
    folder.mkdir()
    target = _write(outside / "t.csv", f"{EULER}\n0,1,2,3,0,0,0\n")
    link = folder / "t.csv"
    link.symlink_to(target)
    assert load_trajectory(link).position_m.tolist() == [[1.0, 2.0, 3.0]]  # no folder named: followed
    _write(folder / "inside.csv", f"{EULER}\n0,1,2,3,0,0,0\n")
    assert len(load_trajectory(folder / "inside.csv", within=folder)) == 1
    _refused(link, r"outside", error=UnsafePathError, within=folder)


# -- hostile files: one line naming the file (and the line), never quoting it -----------------------


def _refused(path: Path, match: str, *, error: type[Exception] = InvalidInputError, **kw) -> str:
    with pytest.raises(error, match=match) as info:
        load_trajectory(path, **kw)
    message = str(info.value)
    assert "\n" not in message and str(path) in message and "Zq7Secret" not in message, message
    return message


@pytest.mark.parametrize(
    ("text", "match"),
    [
        pytest.param(f"{EULER}\n0,0,0,0,0,0,0\n1,0,0,0,0,0,0\n0.5,0,0,0,0,0,0\n", r"line 4: time_s must be later", id="decreasing"),
        pytest.param(f"{EULER}\n0,0,0,0,0,0,0\n\n0,1,0,0,0,0,0\n", r"line 4: time_s must be later", id="duplicate-time"),
        pytest.param(f"{EULER}\n0,0,0,0,0,0,0\n1,nan,0,0,0,0,0\n", r"line 3: position_m must be finite", id="nan"),
        pytest.param(f"{EULER}\ninf,0,0,0,0,0,0\n", r"line 2: time_s must be a finite number", id="inf"),
        pytest.param(f"{EULER}\n0,0,0,0,0,0,0\n1,0,0,0,0,0,0,7\n", r"line 3 is not a row of 7 numbers", id="extra-column"),
        pytest.param(f"{QUATERNION}\n0,0,0,0,0,0,0\n", r"line 2 holds 7 numbers; each row holds 8", id="missing-column"),
        pytest.param(f"{EULER}\n0,0,0,0,0,0,{MARKER}\n", r"line 2 is not a row of 7 numbers", id="not-a-number"),
        pytest.param(f'{EULER}\n"0",0,0,0,0,0,0\n', r"line 2 is not a row of 7 numbers", id="quoted"),
        pytest.param(
            f"time_s,x_m,y_m,z_m,{MARKER},pitch_deg,yaw_deg\n0,0,0,0,0,0,0\n", r"line 1 must be the header .*holds 7 other", id="header"
        ),
        pytest.param("time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg\n0,0,0,0,0,0,0\n", r"line 1 must be the header", id="header-order"),
        pytest.param("", r"the file is empty", id="empty"),
        pytest.param(" \n\n", r"the file is empty", id="blank"),
        pytest.param(f"{EULER}\n\n", r"no rows after the header", id="header-only"),
        pytest.param(f"{EULER}\n0,1e300,0,0,0,0,0\n", r"line 2: position_m must be finite, within", id="huge-position"),
        pytest.param(f"{EULER}\n0,{'9' * 400},0,0,0,0,0\n", r"line 2: position_m must be finite", id="huge-digits"),
        pytest.param(f"{EULER}\n1e300,0,0,0,0,0,0\n", r"line 2: time_s must be a finite number of seconds within", id="huge-time"),
        pytest.param(f"{EULER}\n0,0,0,0,0,1e300,0\n", r"line 2: roll_deg, pitch_deg, yaw_deg must be finite", id="huge-angle"),
        pytest.param(
            f"{QUATERNION}\n0,0,0,0,0,0,0,1\n1,0,0,0,0,0,0,1.01\n", r"line 3: qx, qy, qz, qw must be a unit quaternion", id="quat-norm"
        ),
        pytest.param(f"{QUATERNION}\n0,0,0,0,1e300,0,0,1\n", r"line 2: qx, qy, qz, qw must be a unit quaternion", id="huge-quat"),
        pytest.param(f"{EULER}\n0,0,0,0,0,0,0\n{'0' * 2000}\n", r"line 3 is longer than 1,024 bytes", id="long-line"),
        pytest.param(f"{EULER}\n0,0,0,0,0,0,0\n".encode() + b"\xff\xfe" + MARKER.encode(), r"not UTF-8", id="not-utf8"),
    ],
)
def test_a_hostile_file_is_one_line_naming_it(tmp_path: Path, text: str | bytes, match: str) -> None:
    _refused(_write(tmp_path / "odom.csv", text), match)


def test_more_rows_than_the_cap_are_refused_before_parsing(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(platform, "MAX_TRAJECTORY_POSES", 3)
    monkeypatch.setattr(trajectories, "MAX_TRAJECTORY_POSES", 3)  # the file's cap, read before the rows are parsed
    path = _write(tmp_path / "odom.csv", EULER + "\n" + "".join(f"{t},0,0,0,0,0,0\n" for t in range(3)))
    assert len(load_trajectory(path)) == 3
    _write(path, EULER + "\n" + "".join(f"{t},0,0,0,0,0,0\n" for t in range(4)))
    _refused(path, r"more than 3 lines after the header, the most poses a trajectory holds")
    _write(path, EULER + "\n" + "\n" * 5 + "0,0,0,0,0,0,0\n")  # blank lines count
    _refused(path, r"more than 3 lines after the header")


def test_a_file_larger_than_the_cap_is_refused_unread(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setattr(trajectories, "MAX_TRAJECTORY_BYTES", 64)
    _refused(_write(tmp_path / "odom.csv", EULER + "\n" + "0,0,0,0,0,0,0\n" * 10), r"odom\.csv")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "odom.csv")
    _refused(tmp_path / "odom.csv", r"FIFO")


def test_a_directory_is_refused(tmp_path: Path) -> None:
    (tmp_path / "odom.csv").mkdir()
    _refused(tmp_path / "odom.csv", r"odom\.csv")


def test_a_missing_file_is_one_line(tmp_path: Path) -> None:
    _refused(tmp_path / "none.csv", r"none\.csv")


def test_a_path_that_is_not_a_path_is_a_type_error() -> None:
    with pytest.raises(ArgumentTypeError, match=r"path must be a trajectory file's path"):
        load_trajectory(3)  # type: ignore[arg-type]
    with pytest.raises(ArgumentTypeError, match=r"within must be a folder's path"):
        load_trajectory("odom.csv", within=b"folder")  # type: ignore[arg-type]
