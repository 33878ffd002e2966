"""Point splats at the edges of float64 and memory, and given the wrong kinds from Python
(visibility/point_splats.py, point_kernels.py): one named error in one line, or the right answer,
never a traceback or a silent mask."""

from __future__ import annotations

import numpy as np
import pytest

import zbuf_occlude as zo
from zbuf_occlude import resources
from zbuf_occlude.errors import ArgumentTypeError, InsufficientMemoryError, InvalidInputError, ZbufOccludeError
from zbuf_occlude.visibility.point_kernels import splat_surfels
from zbuf_occlude.visibility.point_splats import MAX_SPLAT_COORDINATE, MAX_SPLAT_SCALE, point_surfels

RNG = np.random.default_rng(0)
SPHERE = RNG.normal(size=(800, 3))
SPHERE /= np.linalg.norm(SPHERE, axis=1, keepdims=True)
CAMERA = zo.camera_on_sphere(30.0, 45.0)


def _refused(error: type[Exception], words: str, **kwargs) -> None:
    points = kwargs.pop("points", SPHERE)
    with pytest.raises(error, match=words) as info:
        zo.visible_mask_points(points, CAMERA, **kwargs)
    assert isinstance(info.value, ZbufOccludeError) and "\n" not in str(info.value), info.value


def test_a_point_past_float64s_reach_is_named_not_an_index_error() -> None:
    far = SPHERE.copy()
    far[5] = [1e200, 0.0, 0.0]  # squared distances overflow: the neighbour search found no neighbours
    _refused(InvalidInputError, r"1 row has a coordinate beyond ±1e\+100, first row 5 \[1e\+200, 0.0, 0.0\]", points=far)


def test_a_far_point_within_reach_is_decided() -> None:
    far = SPHERE.copy()
    far[5] = [MAX_SPLAT_COORDINATE / 10, 0.0, 0.0]
    visible = zo.visible_mask_points(far, CAMERA)
    near = zo.visible_mask_points(np.delete(SPHERE, 5, axis=0), CAMERA)
    assert not visible[5] and visible.sum() > 100
    assert (np.delete(visible, 5) == near).mean() > 0.98  # the rest, as without it


@pytest.mark.parametrize(
    "scale", [1e308, MAX_SPLAT_SCALE * 2, float("inf"), 10**400, 10**5000], ids=["1e308", "twice the cap", "inf", "10**400", "10**5000"]
)
def test_a_splat_scale_past_its_cap_is_named_not_an_overflow_error(scale) -> None:
    _refused(InvalidInputError, "splat_scale must be finite and >= 0 and <= 1000", splat_scale=scale)


def test_the_largest_splat_scale_is_decided() -> None:
    visible = zo.visible_mask_points(SPHERE, CAMERA, splat_scale=MAX_SPLAT_SCALE)
    assert visible.shape == (len(SPHERE),) and 0 < visible.sum() < len(SPHERE)


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_points_are_named(value) -> None:
    bad = SPHERE.copy()
    bad[[3, 9], 1] = value
    _refused(InvalidInputError, "points contain 2 rows with NaN/inf", points=bad)


@pytest.mark.parametrize(
    ("normal", "said"),
    [((0.0, 0.0, 0.0), "are zero"), ((np.nan, 0.0, 1.0), "contain 1 rows with NaN/inf")],
    ids=["zero", "nan"],
)  # fmt: skip
def test_normals_that_cannot_be_made_unit_are_named(normal, said) -> None:
    normals = SPHERE.copy()
    normals[4] = normal
    _refused(InvalidInputError, f"normals {said}", normals=normals)


@pytest.mark.parametrize("length", [1e150, 1e300, 1e-300], ids=["1e150", "1e300", "1e-300"])
def test_normals_of_any_finite_length_but_zero_give_the_answer_of_unit_ones(length) -> None:
    """Normals of length 1e300 once overflowed to a length of inf and divided to 0 (every point
    visible); any finite length but zero is a direction (io.point_sets.unit_normals)."""
    unit = zo.visible_mask_points(SPHERE, CAMERA, normals=SPHERE, oriented=True)
    assert np.array_equal(zo.visible_mask_points(SPHERE, CAMERA, normals=SPHERE * length, oriented=True), unit)
    assert unit.sum() < 0.6 * len(SPHERE)  # not every point: the far side is hidden


WRONG_KINDS = {
    "splat_scale text": (ArgumentTypeError, "splat_scale must be a number, got str '1'", {"splat_scale": "1"}),
    "splat_scale bool": (ArgumentTypeError, "splat_scale must be a number, got bool True", {"splat_scale": True}),
    "tolerance None": (ArgumentTypeError, "tolerance must be a number, got NoneType", {"tolerance": None}),
    "tolerance list": (ArgumentTypeError, "tolerance must be a number", {"tolerance": [0.1]}),
    "neighbours float": (InvalidInputError, "neighbours must be an integer >= 1, got 2.7", {"neighbours": 2.7}),
    "neighbours text": (ArgumentTypeError, "neighbours must be an integer, got str '4'", {"neighbours": "4"}),
    "neighbours bool": (ArgumentTypeError, "neighbours must be an integer, got bool True", {"neighbours": True}),
    "oriented text": (ArgumentTypeError, "oriented must be True or False, got str 'yes'", {"oriented": "yes"}),
    "backend number": (InvalidInputError, "backend must be 'cpu' or 'gpu', got 3", {"backend": 3}),
    "normals text": (ArgumentTypeError, "normals must be a numeric array", {"normals": "normals.npy"}),
    "points text": (ArgumentTypeError, "points must be a numeric array", {"points": "cloud.ply"}),
}


@pytest.mark.parametrize("case", sorted(WRONG_KINDS))
def test_wrong_kinds_are_named_errors_never_bare_ones(case) -> None:
    error, words, kwargs = WRONG_KINDS[case]
    _refused(error, words, **kwargs)


def test_a_cloud_whose_preparation_would_exhaust_memory_is_refused_first(monkeypatch) -> None:
    """Under the 10-million-point cap, a cloud's splats can still need more memory than there is."""
    monkeypatch.setattr(resources, "available_memory", lambda: (2**16, "test budget"))
    monkeypatch.setattr(resources, "MIN_CHECKED_BYTES", 0)  # a small cloud, a smaller budget
    with pytest.raises(InsufficientMemoryError, match=r"preparing the splats of 800 points needs about 825 KiB.*or normals") as info:
        point_surfels(SPHERE)
    assert "\n" not in str(info.value)
    with pytest.raises(InsufficientMemoryError, match=r"800 points needs about 456 KiB"):
        point_surfels(SPHERE, SPHERE)
    monkeypatch.setattr(resources, "available_memory", lambda: (2**21, "test budget"))
    point_surfels(SPHERE)  # what fits is prepared


def test_a_disk_that_nearly_reaches_the_camera_plane_covers_the_image() -> None:
    """Its box in pixels lies beyond int64; it was converted to an int regardless (undefined: on
    x86 the box came out empty and the disk covered nothing)."""
    radius = np.nextafter(1.0, 0.0)  # the disk's near edge 1e-16 in front of the camera plane
    cam, normal = np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, -1.0]])
    depth, ids = splat_surfels(cam, normal, np.array([radius]), 1e-4, -5e-4, -5e-4, 10, 10)
    assert (ids == 0).all() and np.allclose(depth, 1.0)


#: Points of the cloud under the 10-million-point cap of a point-set file whose splats' estimated
#: normals need an (N, 48) float64 array of 3.5 GiB (and as much again for the indices).
_NEAR_CAP_POINTS = 9_900_000
#: The address space of the child, as a user's ``ulimit -v`` of 3 GB (2 GB for the view).
_PREPARE_LIMIT, _VIEW_LIMIT = 3 << 30, 2 << 30
#: About the child's footprint, which the limit adds to the headroom (tests/memory_limit.py): 152 MiB measured.
_FOOTPRINT = 160 << 20

#: In a child under an address-space limit: prepare (or view, prepared by hand) 9.9 million
#: points; print the refusal and exit 3.
_NEAR_CAP = """
import sys
import numpy as np
import zbuf_occlude as zo
from zbuf_occlude.errors import ZbufOccludeError
from zbuf_occlude.visibility.point_splats import PointSurfels, point_surfels
n = {n}
points = np.random.default_rng(0).normal(size=(n, 3))
try:
    if "{what}" == "prepare":
        point_surfels(points)
    else:
        ones = np.ones(n)
        surfels = PointSurfels(points, points, ones * 1e-3, ones * 1e-3, False, order=np.arange(n))
        surfels.visible(zo.camera_on_sphere(30.0, 45.0))
except ZbufOccludeError as exc:
    print(exc)
    sys.exit(3)
"""


@pytest.mark.parametrize("what", ["prepare", "view"])
def test_a_cloud_near_the_point_cap_is_refused_before_the_work_under_a_memory_limit(what) -> None:
    """9.9 million points fit the point-set cap; their preparation (10 GB with normals estimated)
    or one view (2 GB) does not fit a 3 GB or 2 GB process: one line, before any of it is
    allocated, never a MemoryError."""
    from memory_limit import run_python_limited

    headroom = (_PREPARE_LIMIT if what == "prepare" else _VIEW_LIMIT) - _FOOTPRINT
    done = run_python_limited(_NEAR_CAP.format(n=_NEAR_CAP_POINTS, what=what), headroom=headroom)
    assert done.returncode == 3 and not done.stderr, done.stdout + done.stderr[-2000:]
    said = "preparing the splats of 9,900,000 points" if what == "prepare" else "a view of the splats of 9,900,000 points"
    assert done.stdout.startswith(f"{said} needs about") and len(done.stdout.splitlines()) == 1, done.stdout
    assert "ulimit -v" in done.stdout
