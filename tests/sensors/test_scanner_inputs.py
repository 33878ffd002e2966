"""Bad input to the scanner model from Python: one line naming the field, never a traceback from deep inside."""

from __future__ import annotations

import numpy as np
import pytest

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.io.las import las_bytes
from zbuf_occlude.sensors.patterns.airborne_presets import airborne_preset
from zbuf_occlude.sensors.beam.fields import IDEAL_BEAM
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.patterns.spinning import lidar_preset
from zbuf_occlude.sensors.platform import as_pose
from zbuf_occlude.sensors.scan_data import Scan, read_scan_npz


@pytest.mark.parametrize(
    ("make", "words"),
    [
        (
            lambda: lidar_preset("hdl32e", range_noise_m=0.1),
            r"Lidar has no field range_noise_m \(range_noise_m: the beam's; change them with with_beam\)",
        ),
        (lambda: lidar_preset("hdl32e").with_(laser=1), "Lidar has no field laser"),
        (lambda: with_beam(lidar_preset("hdl32e"), beam_divergence_deg=0.1), "Beam has no field beam_divergence_deg"),
        (lambda: IDEAL_BEAM.with_(footprint=7), "Beam has no field footprint"),
        (lambda: airborne_preset("riegl-q1560", footprint_rays=7), "AirborneScanner has no field footprint_rays"),
    ],
)
def test_an_unknown_field_is_named(make, words):
    with pytest.raises(InvalidInputError, match=words):
        make()


@pytest.mark.parametrize(
    ("pose", "words"),
    [("abc", "array of real numbers"), ([[1, 2], [3]], "array of real numbers"), (np.diag([1.0, 1.0, 1.0, 2.0]), "last row"),
     ([1.0, 2.0, float("nan")], "finite"), (np.diag([2.0, 2.0, 2.0, 1.0]), "orthonormal"), (np.diag([1.0, 1.0, -1.0, 1.0]), "right-handed")],
)  # fmt: skip
def test_a_bad_pose_is_refused(pose, words):
    with pytest.raises(InvalidInputError, match=words):
        as_pose(pose)


def test_a_pose_keeps_its_values():
    pose = np.eye(4)
    pose[:3, 3] = (1.0, 2.0, 3.0)
    assert np.array_equal(as_pose(pose), pose) and np.array_equal(as_pose([1.0, 2.0, 3.0]), pose)


@pytest.mark.parametrize("shift", [[1.0, 2.0, 3.0], "x", float("nan"), [[1.0]]])
def test_a_bad_lateral_shift_is_refused(shift):
    with pytest.raises(InvalidInputError, match="lateral_shift_m"):
        airborne_preset("dales-q1560").flight_lines(shift)


def test_a_lateral_shift_is_one_for_every_heading_or_one_per_heading():
    als = airborne_preset("dales-q1560", headings_deg=(0.0, 90.0), n_lines=1)
    assert [line.offset_m for line in als.flight_lines(5.0)] == [5.0, 5.0]
    assert [line.offset_m for line in als.flight_lines([1.0, 2.0])] == [1.0, 2.0]


def _scan(n: int = 4, **fields) -> Scan:
    return Scan(np.zeros((n, 3), np.float32), None, None, np.ones(n, np.float32), np.zeros(n, np.int64), np.ones(n, np.int32),
                np.tile(np.float32([0, 0, 1]), (n, 1)), np.zeros(n, np.float32), **fields)  # fmt: skip


@pytest.mark.parametrize("key", ["return_number", "number_of_returns"])
def test_a_scan_npz_with_return_numbers_beyond_las_is_refused_not_wrapped(tmp_path, key):
    s = _scan(return_number=np.ones(4, np.uint8), number_of_returns=np.ones(4, np.uint8))
    arrays = s.arrays() | {key: np.array([1, 257, 1, 1], np.int64)}
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(InvalidInputError, match=rf"bad\.npz: {key} must be 1 to 15"):
        read_scan_npz(path)


def test_select_crops_the_per_point_meta_arrays():
    s = _scan(meta={"line_id": np.array([0, 1, 2, 3], np.int32), "n_rays": 4, "line_phase_s": (0.1, 0.2)})
    kept = s.select(np.array([True, False, True, False]))
    assert kept.meta["line_id"].tolist() == [0, 2] and kept.meta["n_rays"] == 4 and kept.meta["line_phase_s"] == (0.1, 0.2)


@pytest.mark.parametrize("names", [7, None.__class__, "car"])
def test_las_class_names_that_are_not_a_list_of_text_are_refused(names):
    n = 2
    with pytest.raises(ArgumentTypeError, match="class_names"):
        las_bytes(np.zeros((n, 3)), intensity=np.zeros(n, np.uint16), return_number=np.ones(n, np.uint8),
                  number_of_returns=np.ones(n, np.uint8), gps_time=np.zeros(n), scan_angle_deg=np.zeros(n),
                  survey=_survey(names, n))  # fmt: skip


def _survey(names, n):
    from zbuf_occlude.io.las import SurveyFields

    return SurveyFields(class_index=np.zeros(n, np.int64), class_names=names)
