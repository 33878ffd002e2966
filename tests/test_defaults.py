"""One home for defaults: every signature that has one takes it from zbuf_occlude.defaults."""

from __future__ import annotations

import inspect

import pytest

from zbuf_occlude import defaults
from zbuf_occlude.experiments.compare import CompareConfig
from zbuf_occlude.farm.config import FarmParams
from zbuf_occlude.geometry.cameras import camera_on_sphere, cameras_from_schedule
from zbuf_occlude.pipeline import CameraSphere, PoseDraws, occlude_point_set, occlude_poses
from zbuf_occlude.render.moderngl_backend import ModernGLRenderer
from zbuf_occlude.visibility.peers import naive_zbuffer_visible
from zbuf_occlude.visibility.registry import visible_mask
from zbuf_occlude.visibility.zbuffer import ResidentPoints, zbuffer_tolerance_visible, zbuffer_visible


def _default(fn, name):
    return inspect.signature(fn).parameters[name].default


@pytest.mark.parametrize(
    "fn",
    [camera_on_sphere, cameras_from_schedule, CameraSphere, zbuffer_visible, zbuffer_tolerance_visible,
     naive_zbuffer_visible, CompareConfig],
)  # fmt: skip
def test_resolution_default(fn) -> None:
    assert _default(fn, "resolution") == defaults.DEFAULT_RESOLUTION


def test_the_pipeline_takes_its_cameras_defaults_from_camera_on_sphere() -> None:
    for fn in (occlude_poses, occlude_point_set):
        assert _default(fn, "cameras") == CameraSphere() == CameraSphere(_default(camera_on_sphere, "radius"), defaults.DEFAULT_RESOLUTION)


def test_method_default() -> None:
    assert _default(visible_mask, "method") == _default(occlude_poses, "method") == defaults.DEFAULT_METHOD
    assert FarmParams.__dataclass_fields__["method"].default == defaults.DEFAULT_METHOD


def test_gpu_constants_agree_between_backend_and_methods() -> None:
    """The renderer's own defaults are the methods' (max_slope was 10 there, 4 in zbuffer)."""
    for fn in (ModernGLRenderer.visible, ResidentPoints.visible, zbuffer_visible):
        assert _default(fn, "tolerance") == defaults.DEFAULT_GPU_TOLERANCE
    for fn in (ModernGLRenderer.visible, ResidentPoints.visible_tolerance, zbuffer_tolerance_visible):
        assert _default(fn, "max_slope") == defaults.DEFAULT_MAX_SLOPE == 4.0
    for fn in (ResidentPoints.visible_tolerance, zbuffer_tolerance_visible):
        assert _default(fn, "depth_tolerance") == defaults.DEFAULT_DEPTH_TOLERANCE
        assert _default(fn, "slope_scale") == defaults.DEFAULT_SLOPE_SCALE


def test_sample_sizes_and_views_of_generate_validate_farm_and_occlude_poses() -> None:
    from zbuf_occlude.cli.main import build_parser
    from zbuf_occlude.defaults import DEFAULT_VIEWS as COMPARE_VIEWS
    from zbuf_occlude.farm.config import GENERATE_DEFAULTS

    parser = build_parser()
    gen = parser.parse_args(["generate", "--out", "x"])
    val = parser.parse_args(["validate"])
    farm = FarmParams()
    assert _default(PoseDraws, "n_points") == GENERATE_DEFAULTS.n_points == farm.n_points == gen.points == defaults.DEFAULT_N_POINTS
    assert (_default(PoseDraws, "samples_per_view") == GENERATE_DEFAULTS.samples_per_view == farm.samples_per_view
            == gen.samples_per_view == defaults.DEFAULT_SAMPLES_PER_VIEW)  # fmt: skip
    assert GENERATE_DEFAULTS.dense_points == gen.dense_points == val.dense_points == defaults.DEFAULT_DENSE_POINTS
    assert GENERATE_DEFAULTS.resolution == gen.resolution == val.resolution == defaults.DEFAULT_RESOLUTION
    assert GENERATE_DEFAULTS.views == gen.views == val.views == COMPARE_VIEWS == defaults.DEFAULT_VIEWS


def test_the_farm_and_occlude_take_their_own_defaults_from_defaults() -> None:
    from zbuf_occlude import occlude as occlude_fn

    fields = FarmParams.__dataclass_fields__
    assert fields["views"].default == defaults.DEFAULT_FARM_VIEWS == "paper100"
    assert fields["dense_points"].default == defaults.DEFAULT_FARM_DENSE_POINTS
    assert fields["resolution"].default == defaults.DEFAULT_FARM_RESOLUTION
    assert _default(occlude_fn, "samples_per_view") == defaults.DEFAULT_OCCLUDE_SAMPLES_PER_VIEW
    assert _default(occlude_fn, "views") == defaults.DEFAULT_VIEWS
    assert _default(occlude_fn, "seed") == _default(occlude_poses, "seed") == defaults.DEFAULT_SEED
