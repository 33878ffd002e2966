"""A trajectory's consecutive attitudes are less than a half turn apart: slerp turns the short way, so a turn of
180° or more between two samples would be read as another turn (0 then 270 as 90° the other way, 0 then 360 as
none).  It is refused wherever a trajectory is made (a CSV file, naming both lines and never the values; Python,
naming the samples), as the angles are written and as the attitudes are; a turn under a half turn is kept, and
slerp's midpoint of two written yaws is their mean."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.platform import (
    EULER_COLUMNS,
    HALF_TURN_DEG,
    HALF_TURN_SLACK_DEG,
    QUATERNION_COLUMNS,
    Trajectory,
    load_trajectory,
)

EULER = ",".join(EULER_COLUMNS)
QUATERNION = ",".join(QUATERNION_COLUMNS)
SCENE = str(Path(__file__).resolve().parents[2] / "data" / "scenes" / "street.json")


def _yaw(deg: float) -> np.ndarray:
    return Rotation.from_euler("z", deg, degrees=True).as_matrix()


def _yaw_deg_of(rotation: np.ndarray) -> float:
    return float(Rotation.from_matrix(rotation).as_euler("xyz", degrees=True)[2])


def _wrapped(deg: float) -> float:
    """``deg`` in [-180, 180)."""
    return (deg + 180.0) % 360.0 - 180.0


def _euler_file(path: Path, yaws: list[float], *, blank_after_first: bool = False) -> Path:
    rows = [f"{t},{t},0,1.8,0,0,{float(yaw)!r}" for t, yaw in enumerate(yaws)]
    if blank_after_first:
        rows.insert(1, "")
    path.write_text(EULER + "\n" + "\n".join(rows) + "\n")
    return path


def _refused(path: Path, match: str) -> str:
    with pytest.raises(InvalidInputError, match=match) as info:
        load_trajectory(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"{path}: "), message
    return message


# -- written angles: the turn as the user wrote it -------------------------------------------------


@pytest.mark.parametrize(
    ("yaws", "written"),
    [
        pytest.param([0.0, 270.0], "270", id="0-270"),
        pytest.param([0.0, 360.0], "360", id="0-360-a-whole-turn-not-none"),
        pytest.param([170.0, -170.0], "-170", id="170-minus-170-is-340-as-written"),
        pytest.param([0.0, -180.0], "-180", id="a-half-turn"),
    ],
)
def test_a_half_turn_as_written_is_refused_naming_both_lines(tmp_path: Path, yaws: list[float], written: str) -> None:
    path = _euler_file(tmp_path / "odom.csv", yaws)
    message = _refused(path, r": lines 2 and 3: the attitude turns 180° or more between them, "
                       r"as yaw_deg is written; add samples in between \(slerp turns the short way\), or, .* write the angles unwrapped")  # fmt: skip
    words = message.removeprefix(str(path)).replace("179 then -179", "")  # the hint's example is the only angle shown
    assert written not in words, message


def test_the_lines_named_are_the_file_lines_of_the_pair(tmp_path: Path) -> None:
    path = _euler_file(tmp_path / "odom.csv", [0.0, 90.0, 170.0, 100.0, 300.0], blank_after_first=True)
    _refused(path, r": lines 6 and 7: the attitude turns 180° or more between them, as yaw_deg is written")


@pytest.mark.parametrize("column", [4, 5])
def test_roll_and_pitch_are_held_to_it_too(tmp_path: Path, column: int) -> None:
    rows = [["0", "0", "0", "1.8", "0", "0", "0"], ["1", "0", "0", "1.8", "0", "0", "0"], ["2", "0", "0", "1.8", "0", "0", "0"]]
    rows[1][column], rows[2][column] = "5", "-175"
    (tmp_path / "odom.csv").write_text(EULER + "\n" + "".join(",".join(row) + "\n" for row in rows))
    _refused(tmp_path / "odom.csv", rf": lines 3 and 4: .* as {EULER_COLUMNS[column]} is written")


@pytest.mark.parametrize("step", [179.0, -179.0, HALF_TURN_DEG - 2 * HALF_TURN_SLACK_DEG])
def test_a_turn_under_a_half_turn_is_kept_and_turns_the_written_way(tmp_path: Path, step: float) -> None:
    trajectory = load_trajectory(_euler_file(tmp_path / "odom.csv", [0.0, step]))
    np.testing.assert_allclose(_yaw_deg_of(trajectory.pose_at(0.5)[:3, :3]), step / 2, rtol=0, atol=1e-9)
    np.testing.assert_allclose(_yaw_deg_of(trajectory.pose_at(0.25)[:3, :3]), step / 4, rtol=0, atol=1e-9)


def test_0_then_179_is_at_89_5_half_way(tmp_path: Path) -> None:
    trajectory = load_trajectory(_euler_file(tmp_path / "odom.csv", [0.0, 179.0]))
    np.testing.assert_allclose(trajectory.pose_at(0.5)[:3, :3], _yaw(89.5), rtol=0, atol=1e-12)


def test_unwrapped_angles_past_a_turn_are_kept(tmp_path: Path) -> None:
    # the same attitudes as 170 then -170, written unwrapped: 20° the short way, through 180
    trajectory = load_trajectory(_euler_file(tmp_path / "odom.csv", [170.0, 190.0, 350.0, 530.0 - 2 * HALF_TURN_SLACK_DEG]))
    np.testing.assert_allclose(_wrapped(_yaw_deg_of(trajectory.pose_at(0.5)[:3, :3])), -180.0, rtol=0, atol=1e-9)


def test_the_cli_refuses_it_before_scanning(tmp_path: Path, capsys) -> None:
    path = _euler_file(tmp_path / "drive.csv", [0.0, 270.0])
    code = cli_main(["scan", SCENE, "--trajectory", str(path), "--no-progress", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert f"{path}: lines 2 and 3: the attitude turns 180° or more" in err and "270" not in err.replace(str(path), ""), err
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


# -- attitudes: the rotation from one sample to the next -------------------------------------------


def test_a_half_turn_of_quaternions_is_refused_naming_both_lines(tmp_path: Path) -> None:
    path = tmp_path / "imu.csv"
    path.write_text(f"{QUATERNION}\n0,0,0,0,0,0,0,1\n1,0,0,0,0,0,0.7071068,0.7071068\n2,0,0,0,0,0,-0.7071068,0.7071068\n")
    _refused(path, r": lines 3 and 4: the attitude turns 180° or more between them; add samples in between \(slerp turns the short way\)$")


def test_a_quaternion_and_its_negative_are_one_attitude(tmp_path: Path) -> None:
    path = tmp_path / "imu.csv"
    path.write_text(f"{QUATERNION}\n0,0,0,0,0,0,0,1\n1,0,0,0,0,0,0,-1\n")
    trajectory = load_trajectory(path)
    np.testing.assert_allclose(trajectory.pose_at(0.5)[:3, :3], np.eye(3), rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("make", "pair"),
    [
        pytest.param(lambda: Trajectory(np.arange(2.0), np.zeros((2, 3)), np.stack([_yaw(0.0), _yaw(180.0)])), "0 and 1", id="yaw"),
        pytest.param(
            lambda: Trajectory(np.arange(3.0), np.zeros((3, 3)), np.stack([_yaw(0.0), _yaw(90.0), _yaw(270.0)])), "1 and 2", id="later"
        ),
        pytest.param(
            lambda: Trajectory(np.arange(2.0), np.zeros((2, 3)), Rotation.from_rotvec([[0, 0, 0], [np.pi, 0, 0]]).as_matrix()),
            "0 and 1",
            id="roll",
        ),
        pytest.param(
            lambda: Trajectory(
                np.arange(2.0), np.zeros((2, 3)), np.stack([_yaw(10.0), _yaw(10.0 + HALF_TURN_DEG - HALF_TURN_SLACK_DEG / 2)])
            ),
            "0 and 1",
            id="within-the-slack",
        ),
        pytest.param(
            lambda: Trajectory.from_poses([0.0, 1.0], np.stack([np.eye(4), np.diag([1.0, -1.0, -1.0, 1.0])]), name="odom"),
            "0 and 1",
            id="from-poses",
        ),
    ],
)
def test_a_half_turn_of_rotations_is_refused_naming_the_samples(make, pair: str) -> None:
    with pytest.raises(InvalidInputError, match=rf"^trajectory '\w+': the attitude turns 180° or more between samples {pair}; "
                       r"add samples in between \(slerp turns the short way\)$"):  # fmt: skip
        make()


def test_a_turn_just_under_the_slack_is_kept() -> None:
    step = HALF_TURN_DEG - 2 * HALF_TURN_SLACK_DEG
    trajectory = Trajectory(np.arange(2.0), np.zeros((2, 3)), np.stack([_yaw(-step), _yaw(0.0)]))
    np.testing.assert_allclose(_yaw_deg_of(trajectory.pose_at(0.5)[:3, :3]), -step / 2, rtol=0, atol=1e-9)


# -- the law: slerp's midpoint of two written yaws is their mean ------------------------------------

_steps = st.floats(-(HALF_TURN_DEG - 2 * HALF_TURN_SLACK_DEG), HALF_TURN_DEG - 2 * HALF_TURN_SLACK_DEG)


@settings(max_examples=60, deadline=None)
@given(
    first=st.floats(-720.0, 720.0),
    steps=st.lists(_steps, min_size=1, max_size=8),
    dts=st.lists(st.floats(1e-3, 10.0), min_size=9, max_size=9),
)
def test_the_midpoint_of_written_yaws_under_a_half_turn_apart_is_their_mean(first: float, steps: list[float], dts: list[float]) -> None:
    yaws = np.r_[first, first + np.cumsum(steps)]
    time = np.r_[0.0, np.cumsum(dts[: len(steps)])]
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "odom.csv"
        path.write_text(EULER + "\n" + "".join(f"{float(t)!r},0,0,1.8,0,0,{float(yaw)!r}\n" for t, yaw in zip(time, yaws, strict=True)))
        trajectory = load_trajectory(path)  # every pair is under a half turn apart: none is refused
    rotation, _ = trajectory.poses_at((time[:-1] + time[1:]) / 2)
    for i, r in enumerate(rotation):
        assert abs(_wrapped(_yaw_deg_of(r) - (yaws[i] + yaws[i + 1]) / 2)) < 1e-9, (i, yaws[i], yaws[i + 1])
