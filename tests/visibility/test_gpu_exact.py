"""``zbuffer-exact``'s GPU passes: the bin passes split over slices, results in the caller's order."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import zbuf_occlude as zo
from zbuf_occlude.errors import BackendUnavailable
from zbuf_occlude.visibility.gpu_exact import ExactScene


def _big_faces_mesh() -> trimesh.Trimesh:
    # box sides seen close cover thousands of 8 px tiles each; the sphere inside occludes and is occluded
    return trimesh.util.concatenate([trimesh.creation.icosphere(subdivisions=3, radius=0.3), trimesh.creation.box([0.9, 0.9, 0.9])])


@pytest.fixture
def scene():
    mesh = _big_faces_mesh()
    points, face_index = zo.sample_surface(mesh, 4000, seed=3)
    try:
        s = ExactScene(mesh, points, face_index)
    except BackendUnavailable as exc:  # pragma: no cover - every CI machine has Mesa EGL
        pytest.skip(str(exc))
    with s:
        yield mesh, points, face_index, s


@pytest.mark.parametrize("slices", [1, 3, 32])
def test_any_number_of_bin_slices_gives_the_oracle_bits_and_the_same_tile_lists(scene, slices):
    mesh, points, face_index, s = scene
    cams = [zo.camera_on_sphere(el, az, radius=1.6, resolution=512) for el, az in ((10.0, 20.0), (-50.0, 200.0))]
    s.gpu.bin_slices = 1
    reference = [(s.visible(cam), dict(s.gpu.last_stats)) for cam in cams]
    s.gpu.bin_slices = slices
    for cam, (ref, stats) in zip(cams, reference):
        got = s.visible(cam)
        assert np.array_equal(got, ref)
        assert s.gpu.last_stats == stats  # the same (tile, face) entries, in whatever order
        assert np.array_equal(got, zo.visible_mask(mesh, points, cam, "oracle", face_index=face_index))
    assert 0 < reference[0][0].sum() < len(points)  # some points hidden, some seen


def test_results_come_back_in_the_callers_order_not_the_gpus(scene):
    mesh, points, face_index, s = scene
    cam = zo.camera_on_sphere(25.0, 70.0, radius=1.6, resolution=256)
    perm = np.random.default_rng(0).permutation(len(points))
    with ExactScene(mesh, points[perm], face_index[perm]) as shuffled:
        assert np.array_equal(shuffled.visible(cam), s.visible(cam)[perm])


def test_profile_mode_times_every_stage(scene):
    _, _, _, s = scene
    s.gpu.profile = True
    try:
        s.visible(zo.camera_on_sphere(0.0, 0.0, radius=1.6, resolution=256))
    finally:
        s.gpu.profile = False
    assert list(s.gpu.last_timings) == ["bin count", "prefix sum", "bin fill", "points", "read back", "unpack"]
    assert all(t >= 0.0 for t in s.gpu.last_timings.values())
