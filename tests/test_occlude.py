"""Per-object occlusion: sample draws, padding, determinism."""

from __future__ import annotations

import numpy as np
import pytest

import zbuf_occlude as zo
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.occlude import derive_rng, draw_sample, object_key, occlude_object


def test_draw_sample_is_without_replacement_when_enough_are_visible():
    visible = np.arange(100, 1100)
    chosen, n_visible = draw_sample(visible, 512, derive_rng(0, 1))
    assert n_visible == 1000 and len(set(chosen.tolist())) == 512 and np.isin(chosen, visible).all()


def test_draw_sample_pads_with_repeats_when_too_few_are_visible():
    visible = np.arange(10)
    chosen, n_visible = draw_sample(visible, 25, derive_rng(0, 1))
    assert n_visible == 10 and len(chosen) == 25 and set(chosen.tolist()) == set(range(10))
    assert draw_sample(np.zeros(0, dtype=np.int64), 5, derive_rng(0))[0].size == 0


@pytest.fixture(scope="module")
def small_mesh(sample_mesh_files):
    path = next(p for p in sample_mesh_files if "sofa" in p.name)
    return path, zo.load_mesh(path)


def _run(mesh, poses, seed):
    out = []
    for pose_index, visible, clouds in occlude_object(
        mesh, poses, key=object_key("sofa"), n_points=256, samples_per_view=3, seed=seed, resolution=256
    ):
        out.append((pose_index, visible, clouds))
    return out


def test_occlude_object_is_deterministic_for_a_seed_and_differs_across_seeds(small_mesh):
    _, mesh = small_mesh
    poses = zo.view_schedule("30:45,-40:200")
    a, b, c = _run(mesh, poses, 0), _run(mesh, poses, 0), _run(mesh, poses, 1)
    for (_, va, ca), (_, vb, cb) in zip(a, b):
        assert np.array_equal(va, vb)
        assert all(np.array_equal(x.points, y.points) for x, y in zip(ca, cb))
    assert not np.array_equal(a[0][2][0].points, c[0][2][0].points)
    # samples of one pose differ from each other, and every point is a visible dense point
    assert not np.array_equal(a[0][2][0].points, a[0][2][1].points)
    assert all(cl.points.shape == (256, 3) and cl.points.dtype == np.float32 for cl in a[0][2])


def test_occlude_object_rejects_bad_counts(small_mesh):
    _, mesh = small_mesh
    with pytest.raises(InvalidInputError):
        next(occlude_object(mesh, [(0.0, 0.0)], key=1, n_points=0))
