"""Normals estimated from points alone: perpendicular to a plane, facing the sensor (a law for any
plane, any sensor on either side)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.geometry.normals import estimate_normals

unit = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1)


@settings(max_examples=40, deadline=None)
@given(normal=unit, side=st.sampled_from([-1.0, 1.0]), seed=st.integers(0, 2**31))
def test_points_of_a_plane_get_its_normal_facing_the_sensor(normal, side, seed):
    n = np.asarray(normal) / np.linalg.norm(normal)
    rng = np.random.default_rng(seed)
    a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    uv = rng.uniform(-1, 1, size=(200, 2))
    points = uv[:, :1] * a + uv[:, 1:] * b
    eye = side * 5.0 * n
    got = estimate_normals(points, eye)
    assert got.dtype == np.float32 and got.shape == (200, 3)
    np.testing.assert_allclose(got, np.broadcast_to(side * n, got.shape), atol=1e-4)


def test_a_sphere_s_normals_point_out_toward_a_sensor_outside():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(2000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    visible = p[p @ np.array([0.0, 0.0, 1.0]) > 0.3]  # the cap a sensor far up +z sees
    got = estimate_normals(visible, np.array([0.0, 0.0, 10.0]))
    assert np.min(np.einsum("ni,ni->n", got, visible)) > 0.95


def test_too_few_points_still_give_unit_normals():
    assert np.allclose(np.linalg.norm(estimate_normals(np.zeros((2, 3)), np.ones(3)), axis=1), 1.0)
