"""``auto``: calibrated separately for kept sessions and one-shot calls."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import zbuf_occlude as zo
from zbuf_occlude.visibility import auto


@pytest.fixture
def hardware_machine(monkeypatch):
    """A machine with a hardware renderer and Embree, where calibration decides; the timings are
    stand-ins (a GPU whose sessions win and whose one-shot calls lose, as on an H100)."""
    calls = []

    def fake_calibrate(n_points=50_000, views=5, *, one_shot=False):
        calls.append(one_shot)
        return {"zbuffer-exact": 0.030, "embree-fast": 0.006} if one_shot else {"zbuffer-exact": 0.001, "embree-fast": 0.003}

    monkeypatch.delenv(auto.AUTO_ENV, raising=False)
    monkeypatch.setattr(auto, "_gl_renderer", lambda: "NVIDIA H100 80GB HBM3/PCIe/SSE2")
    monkeypatch.setattr(auto, "_has_embree", lambda: True)
    monkeypatch.setattr(auto, "calibrate", fake_calibrate)
    auto.choose_method.cache_clear()
    yield calls
    auto.choose_method.cache_clear()


def test_sessions_and_one_shot_calls_are_calibrated_apart(hardware_machine):
    assert auto.choose_method() == "zbuffer-exact"
    assert auto.choose_method(one_shot=True) == "embree-fast"
    assert auto.choose_method() == "zbuffer-exact" and auto.choose_method(one_shot=True) == "embree-fast"
    assert hardware_machine == [False, True]  # each decided once per process


def test_the_one_shot_call_runs_the_one_shot_choice_and_a_session_the_session_choice(hardware_machine, monkeypatch):
    from zbuf_occlude.visibility import registry

    ran = []
    real = registry.get_method

    def spy(name):
        ran.append(name)
        return real(name)

    monkeypatch.setattr(auto, "get_method", spy)
    mesh = trimesh.creation.icosphere(subdivisions=2)
    points, face_index = zo.sample_surface(mesh, 300, seed=0)
    cam = zo.camera_on_sphere(20.0, 30.0, resolution=128)
    visible = zo.visible_mask(mesh, points, cam, face_index=face_index)
    assert ran == ["embree-fast"]
    assert np.array_equal(visible, zo.visible_mask(mesh, points, cam, "oracle", face_index=face_index))
    with zo.method_info("auto").session(mesh, points, face_index) as scene:
        assert type(scene).__name__ == "ExactScene"


def test_a_software_renderer_takes_embree_fast_both_ways(monkeypatch):
    monkeypatch.delenv(auto.AUTO_ENV, raising=False)
    monkeypatch.setattr(auto, "_gl_renderer", lambda: "llvmpipe (LLVM 15.0.6, 256 bits)")
    monkeypatch.setattr(auto, "_has_embree", lambda: True)
    monkeypatch.setattr(auto, "calibrate", lambda *a, **k: pytest.fail("no calibration on a software renderer"))
    auto.choose_method.cache_clear()
    try:
        assert auto.choose_method() == auto.choose_method(one_shot=True) == "embree-fast"
    finally:
        auto.choose_method.cache_clear()


@pytest.mark.parametrize("one_shot", [False, True])
def test_calibration_times_both_candidates_the_way_they_are_called(one_shot):
    seconds = auto.calibrate(n_points=2000, views=2, one_shot=one_shot)
    assert set(seconds) <= {"zbuffer-exact", "embree-fast"} and "embree-fast" in seconds
    assert all(0.0 < s < 60.0 for s in seconds.values())
