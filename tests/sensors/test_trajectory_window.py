"""A sweep along a long trajectory costs what its own samples cost: :meth:`Trajectory.poses_at` slerps only over the
samples around the times asked (found by binary search), :meth:`Trajectory.since` with ``until_s`` keeps only the
samples of the sweep, and ``scan --trajectory F --samples K`` hands each sweep only its own.  The work is counted
(the rotations handed to slerp, the samples checked), never timed; and the answers are the whole trajectory's,
bit for bit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.spatial.transform
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation, Slerp

import zbuf_occlude as zo
import zbuf_occlude.sensors.platform as platform
from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.sensors.kinds import sensor_to_json
from zbuf_occlude.sensors.platform import Trajectory

SCENE = str(Path(__file__).resolve().parents[2] / "data" / "scenes" / "street.json")
#: A long trajectory: samples every millisecond, for 200 s.
POSES, STEP_S = 200_000, 1e-3
#: A spinning LiDAR of few pulses (2 beams, 36 firings a revolution of 0.1 s): the sweep, not the rays, is tested.
TINY = zo.Lidar(name="tiny", elevations_deg=(-10.0, 0.0), rotation_hz=10.0, firing_rate_hz=360.0)


def _moving(n: int, step_s: float, seed: int) -> Trajectory:
    """``n`` samples ``step_s`` apart from t = 1000 s, driving along +x at 1.8 m and turning a little at each."""
    rng = np.random.default_rng(seed)
    time = 1000.0 + np.arange(n) * step_s
    position = np.c_[-5.0 + 10.0 * (time - time[0]), rng.uniform(-0.01, 0.01, n), np.full(n, 1.8)]
    angles = np.c_[rng.uniform(-2.0, 2.0, (n, 2)), np.cumsum(rng.uniform(-1.0, 1.0, n))]
    return Trajectory(time, position, Rotation.from_euler("xyz", angles, degrees=True).as_matrix(), name="drive")


@pytest.fixture(scope="module")
def long_trajectory() -> Trajectory:
    return _moving(POSES, STEP_S, seed=0)


#: A short trajectory whose answers are compared with the whole trajectory's slerp.
SHORT = _moving(400, 0.01, seed=1)


class _Work:
    """The rotations handed to slerp and the samples checked (re-orthonormalised), per call."""

    def __init__(self, monkeypatch) -> None:
        self.slerped: list[int] = []
        self.checked: list[int] = []
        work = self

        class CountingSlerp(Slerp):
            def __init__(self, times, rotations) -> None:
                work.slerped.append(len(rotations))
                super().__init__(times, rotations)

        orthonormalised = platform._orthonormalised

        def counting_orthonormalised(rotation):
            work.checked.append(len(rotation))
            return orthonormalised(rotation)

        monkeypatch.setattr(scipy.spatial.transform, "Slerp", CountingSlerp)
        monkeypatch.setattr(platform, "_orthonormalised", counting_orthonormalised)


def _samples_within(trajectory: Trajectory, t0: float, t1: float) -> int:
    return int(np.count_nonzero((trajectory.time_s >= t0) & (trajectory.time_s <= t1)))


# -- bounded work ----------------------------------------------------------------------------------


def test_poses_at_slerps_only_the_samples_around_the_times(long_trajectory: Trajectory, monkeypatch) -> None:
    work = _Work(monkeypatch)
    t0 = long_trajectory.start_s + 123.4567
    times = t0 + np.random.default_rng(2).uniform(0.0, 0.1, 5000)  # a sweep's pulses, in no order
    long_trajectory.poses_at(times)
    inside = _samples_within(long_trajectory, times.min(), times.max())
    assert len(work.slerped) == 1 and inside <= work.slerped[0] <= inside + 2  # and one sample either side
    work.slerped.clear()
    long_trajectory.pose_at(long_trajectory.end_s)
    long_trajectory.pose_at(long_trajectory.start_s)
    assert work.slerped == [2, 2]


def test_since_until_holds_only_the_sweep_samples(long_trajectory: Trajectory, monkeypatch) -> None:
    work = _Work(monkeypatch)
    t0 = long_trajectory.start_s + 77.7777
    sweep = long_trajectory.since(t0, until_s=t0 + 0.1)
    inside = _samples_within(long_trajectory, t0, t0 + 0.1)
    assert len(sweep) == inside + 2  # the pose at t0, the samples inside, the first after the sweep
    assert sweep.start_s == t0 and sweep.time_s[-2] <= t0 + 0.1 <= sweep.end_s
    assert work.checked == [len(sweep)] and max(work.slerped) == 2  # no sample outside the sweep is checked or slerped


def test_a_scan_along_a_long_trajectory_slerps_only_its_sweep(long_trajectory: Trajectory, monkeypatch) -> None:
    work = _Work(monkeypatch)
    zo.scan(zo.load_scene(SCENE), TINY, long_trajectory.since(long_trajectory.start_s + 50.0, until_s=long_trajectory.start_s + 50.1))
    assert work.slerped and max(work.slerped) <= TINY.sweep_s / STEP_S + 3
    assert max(work.checked) <= TINY.sweep_s / STEP_S + 3


def test_the_cli_sweeps_each_sample_along_its_own_samples_only(tmp_path: Path, long_trajectory: Trajectory, monkeypatch, capsys) -> None:
    sensor = tmp_path / "tiny.json"
    sensor.write_text(json.dumps(sensor_to_json(TINY)))
    monkeypatch.setattr(platform, "load_trajectory", lambda path, **kw: long_trajectory)  # read once: not the work counted
    work = _Work(monkeypatch)
    code = cli_main(["scan", SCENE, "--sensor", str(sensor), "--trajectory", str(tmp_path / "drive.csv"), "--samples", "3",
                     "--no-progress", "--out", str(tmp_path / "o")])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    assert len(list((tmp_path / "o").glob("*.npz"))) == 3
    per_sweep = TINY.sweep_s / STEP_S + 3  # a sweep's samples, the pose at its start and one sample past its end
    assert len(work.checked) == 3 and max(work.checked) <= per_sweep, work.checked
    assert len(work.slerped) >= 3 and max(work.slerped) <= per_sweep, work.slerped


# -- the same answers ------------------------------------------------------------------------------


def _whole(trajectory: Trajectory, t: np.ndarray) -> np.ndarray:
    """Slerp over every sample of ``trajectory``: the reference the windowed answers must equal, in the same arithmetic."""
    return Slerp(trajectory.time_s, Rotation.from_matrix(trajectory.rotation))(t).as_matrix()


_fraction = st.floats(0.0, 1.0)


@settings(max_examples=80, deadline=None)
@given(
    lo=_fraction,
    width=_fraction,
    fractions=st.lists(_fraction, min_size=1, max_size=30),
    at_samples=st.lists(st.integers(0, 399), max_size=5),
)
def test_the_windowed_slerp_is_the_whole_slerp_bit_for_bit(lo: float, width: float, fractions: list[float], at_samples: list[int]) -> None:
    t0 = SHORT.start_s + lo * SHORT.duration_s
    t1 = min(t0 + width * width * (SHORT.end_s - t0), SHORT.end_s)
    times = np.r_[t0 + np.array(fractions) * (t1 - t0), SHORT.time_s[at_samples]]  # times between samples and at them
    rotation, _ = SHORT.poses_at(times)
    np.testing.assert_array_equal(rotation, _whole(SHORT, times))


@settings(max_examples=40, deadline=None)
@given(start=_fraction, width=st.floats(1e-4, 1.0), fractions=st.lists(_fraction, min_size=1, max_size=30))
def test_since_until_answers_as_since_does_bit_for_bit(start: float, width: float, fractions: list[float]) -> None:
    t0 = SHORT.start_s + start * 0.999 * SHORT.duration_s
    t1 = t0 + width * (SHORT.end_s - t0)
    times = np.clip(t0 + np.array(fractions) * (t1 - t0), t0, t1)
    windowed, every = SHORT.since(t0, until_s=t1), SHORT.since(t0)
    assert len(windowed) <= len(every)
    for a, b in zip(windowed.poses_at(times), every.poses_at(times), strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_scan_of_the_sweep_is_the_scan_of_the_rest_bit_for_bit() -> None:
    scene = zo.load_scene(SCENE)
    t0 = SHORT.start_s + 1.234
    a = zo.scan(scene, TINY, SHORT.since(t0, until_s=t0 + TINY.sweep_s), seed=3, frame="world")
    b = zo.scan(scene, TINY, SHORT.since(t0), seed=3, frame="world")
    assert len(a) > 0
    for field in ("points", "gps_time", "range_m", "sensor_position"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


def test_until_must_be_after_start() -> None:
    with pytest.raises(platform.InvalidInputError, match=r"until_s must be a finite number >"):
        SHORT.since(SHORT.start_s + 1.0, until_s=SHORT.start_s + 1.0)
    assert len(SHORT.since(SHORT.end_s - 0.5, until_s=SHORT.end_s + 5.0)) == len(SHORT.since(SHORT.end_s - 0.5))  # past the end: the rest
