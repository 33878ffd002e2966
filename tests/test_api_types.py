"""The public API refuses a wrong kind of argument with a TypeError that says what it wanted.

A file name where a mesh goes, ``(30, 45)`` where a camera goes, text or complex numbers where
points go: each is a :class:`~zbuf_occlude.ArgumentTypeError` (a ``TypeError`` and a
``ZbufOccludeError``) naming the argument, what it must be and what was given
(zbuf_occlude.geometry.arguments).
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError, ZbufOccludeError

MESH = trimesh.creation.icosphere(subdivisions=1)
POINTS = np.asarray(MESH.vertices[:8], dtype=np.float64)
CAMERA = zo.camera_on_sphere(20.0, 30.0, resolution=64)

CALLS = {
    "visible_mask/mesh": (
        lambda: zo.visible_mask("chair.off", POINTS, CAMERA, method="oracle"),
        "mesh must be a trimesh.Trimesh",
        "zo.load_mesh",
    ),
    "visible_mask/camera": (
        lambda: zo.visible_mask(MESH, POINTS, (30, 45), method="oracle"),
        "camera must be a zbuf_occlude.Camera",
        "zo.camera_on_sphere",
    ),
    "visible_mask/points": (lambda: zo.visible_mask(MESH, "points.npy", CAMERA, method="oracle"), "points must be a numeric array", "str"),
    "visible_mask/face_index": (
        lambda: zo.visible_mask(MESH, POINTS, CAMERA, method="oracle", face_index="0"),
        "face_index must be a numeric array",
        "str",
    ),
    "visible_mask/complex": (
        lambda: zo.visible_mask(MESH, POINTS.astype(complex), CAMERA, method="oracle"),
        "points must be a numeric array",
        "complex",
    ),
    "visible_mask/objects": (
        lambda: zo.visible_mask(MESH, np.array([[0, 0, "x"]], dtype=object), CAMERA, method="oracle"),
        "points must be a numeric array",
        "not all numbers",
    ),
    "sample_surface/mesh": (lambda: zo.sample_surface("chair.off", 100), "mesh must be a trimesh.Trimesh", "zo.load_mesh"),
    "render_depth/mesh": (lambda: zo.render_depth("chair.off", CAMERA), "mesh must be a trimesh.Trimesh", "chair.off"),
    "render_depth/camera": (lambda: zo.render_depth(MESH, [10.0, 20.0]), "camera must be a zbuf_occlude.Camera", "zo.camera_on_sphere"),
    "session/mesh": (lambda: zo.VisibilitySession("chair.off", POINTS, method="oracle"), "mesh must be a trimesh.Trimesh", "chair.off"),
    "session/camera": (lambda: zo.VisibilitySession(MESH, POINTS, method="oracle").visible((30, 45)), "camera must be", "tuple (30, 45)"),
}


@pytest.mark.parametrize("call, words, hint", CALLS.values(), ids=CALLS.keys())
def test_a_wrong_kind_of_argument_is_a_type_error_saying_what_was_expected(call, words, hint):
    with pytest.raises(ArgumentTypeError) as info:
        call()
    assert isinstance(info.value, TypeError) and isinstance(info.value, ZbufOccludeError)
    assert words in str(info.value) and hint in str(info.value)


def test_a_float_face_index_is_not_truncated_silently():
    with pytest.raises(ArgumentTypeError, match="face_index must be a numeric array, got dtype float64"):
        zo.visible_mask(MESH, POINTS, CAMERA, method="oracle", face_index=np.zeros(len(POINTS)) + 0.7)


@settings(max_examples=40, deadline=None)
@given(st.one_of(st.text(max_size=20), st.binary(max_size=20), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2)))
def test_text_bytes_or_a_mapping_is_never_points(value):
    with pytest.raises(ArgumentTypeError):
        zo.visible_mask(MESH, value, CAMERA, method="oracle")


@settings(max_examples=40, deadline=None)
@given(st.one_of(st.none(), st.integers(), st.floats(), st.text(max_size=10), st.tuples(st.floats(), st.floats())))
def test_anything_but_a_camera_is_refused_before_any_work(value):
    with pytest.raises(ArgumentTypeError, match="camera must be a zbuf_occlude.Camera"):
        zo.visible_mask(MESH, POINTS, value, method="oracle")


def test_right_kinds_with_wrong_values_stay_value_errors():
    with pytest.raises(InvalidInputError, match=r"shape \(N, 3\)"):
        zo.visible_mask(MESH, POINTS[:, :2], CAMERA, method="oracle")
    with pytest.raises(InvalidInputError, match="NaN/inf"):
        zo.visible_mask(MESH, np.full((2, 3), np.nan), CAMERA, method="oracle")


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(*[st.floats(allow_nan=True, allow_infinity=True)] * 3), min_size=1, max_size=6))
def test_points_are_refused_exactly_when_a_coordinate_is_not_finite(rows):
    # (the check sums the points first: huge finite values whose sum overflows must still pass)
    from zbuf_occlude.geometry.arguments import check_points

    pts = np.array(rows, dtype=np.float64)
    bad = int((~np.isfinite(pts)).any(axis=1).sum())
    if bad:
        with pytest.raises(InvalidInputError, match=f"contain {bad} rows with NaN/inf"):
            check_points(pts)
    else:
        assert np.array_equal(check_points(pts), pts)


def test_points_whose_sum_overflows_are_finite():
    from zbuf_occlude.geometry.arguments import check_points

    pts = np.full((4, 3), 1.5e308)
    pts[0, 0] = -1.7e308
    assert np.array_equal(check_points(pts), pts)
