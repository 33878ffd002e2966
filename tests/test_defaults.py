"""One home for defaults: every signature that has one takes it from zbuf_occlude.defaults."""

from __future__ import annotations

import inspect

import pytest

from zbuf_occlude import defaults
from zbuf_occlude.cameras import camera_on_sphere, cameras_from_schedule
from zbuf_occlude.compare import compare, run_compare
from zbuf_occlude.farm.config import FarmParams
from zbuf_occlude.occlude import occlude_object
from zbuf_occlude.render.moderngl_backend import ModernGLRenderer
from zbuf_occlude.visibility.peers import naive_zbuffer_visible
from zbuf_occlude.visibility.registry import visible_mask
from zbuf_occlude.visibility.zbuffer import ResidentPoints, zbuffer_tolerance_visible, zbuffer_visible


def _default(fn, name):
    return inspect.signature(fn).parameters[name].default


@pytest.mark.parametrize(
    "fn",
    [camera_on_sphere, cameras_from_schedule, occlude_object, zbuffer_visible, zbuffer_tolerance_visible,
     naive_zbuffer_visible, compare, run_compare],
)  # fmt: skip
def test_resolution_default(fn) -> None:
    assert _default(fn, "resolution") == defaults.DEFAULT_RESOLUTION


def test_method_default() -> None:
    assert _default(visible_mask, "method") == _default(occlude_object, "method") == defaults.DEFAULT_METHOD
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
