"""look_at_pose gives an OpenCV camera: x right, y down, z forward (world z up)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.platform import look_at_pose


def test_level_camera_axes():
    m = look_at_pose([0, 0, 0], [1, 0, 0])
    x, y, z = m[:3, 0], m[:3, 1], m[:3, 2]
    np.testing.assert_allclose(z, [1, 0, 0])
    np.testing.assert_allclose(x, [0, -1, 0])  # looking along +x with z up, the right is -y
    np.testing.assert_allclose(y, [0, 0, -1])  # image rows grow downwards
    np.testing.assert_allclose(m[:3, 3], [0, 0, 0])


finite = st.floats(-10, 10, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(st.tuples(finite, finite, finite), st.tuples(finite, finite, finite))
def test_rotation_proper_and_ground_below(eye, target):
    eye, target = np.array(eye), np.array(target)
    d = target - eye
    if np.linalg.norm(d) < 1e-3 or np.linalg.norm(np.cross(d / np.linalg.norm(d), [0, 0, 1])) < 1e-3:
        return
    m = look_at_pose(eye, target)
    r = m[:3, :3]
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    # world up seen by the camera points to negative y (up in the image), and the
    # right-hand axis is horizontal
    assert (r.T @ [0, 0, 1])[1] < 0
    assert abs(r[2, 0]) < 1e-9


def test_refuses_degenerate():
    with pytest.raises(InvalidInputError):
        look_at_pose([0, 0, 0], [0, 0, 0])
    with pytest.raises(InvalidInputError):
        look_at_pose([0, 0, 0], [0, 0, 5])
