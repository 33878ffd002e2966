"""Occlusion on the fly from point sets: each cloud's preparation is cached, bounded by bytes, and a
cached preparation gives the mask a fresh one gives."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

pytest.importorskip("torch")

import zbuf_occlude as zo
from zbuf_occlude.learn.on_the_fly import ProcessCache, RandomOcclusion, prepared_bytes


def _sphere(n: int, seed: int) -> np.ndarray:
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def test_a_cached_preparation_gives_the_mask_of_a_fresh_one():
    points = _sphere(1_500, 0)
    t = RandomOcclusion(200, seed=2, normalize=False)
    first = t(points, index=0, epoch=0)
    assert len(t._prepared) == 1
    cached = t(points, index=0, epoch=0)  # the same view from the cache
    fresh = RandomOcclusion(200, seed=2, normalize=False)(points, index=0, epoch=0)
    for a in (cached, fresh):
        assert np.array_equal(a["point_index"], first["point_index"]) and a["n_visible"] == first["n_visible"]
    # and each later view of the cached cloud is what a fresh preparation sees
    surfels = next(iter(t._prepared.values()))
    again = zo.point_surfels(surfels.points)
    for el, az in ((10.0, 20.0), (-50.0, 200.0), (80.0, 5.0)):
        camera = zo.camera_on_sphere(el, az)
        assert np.array_equal(surfels.visible(camera), again.visible(camera))


def test_an_epoch_over_clouds_prepares_each_once():
    clouds = [_sphere(300, s) for s in range(4)]
    t = RandomOcclusion(50, seed=0)
    calls = []
    build = t._prepared.get_or_build

    def counting(key, make):
        return build(key, lambda: calls.append(key) or make())

    t._prepared.get_or_build = counting
    for epoch in range(3):
        for i, cloud in enumerate(clouds):
            t(cloud, index=i, epoch=epoch)
    assert len(calls) == len(clouds)


def test_the_cache_evicts_the_least_recently_used_by_bytes():
    cache = ProcessCache(100, per_process=False, max_bytes=1_000, nbytes=len)
    for key in "abc":
        cache.get_or_build(key, lambda: b"x" * 400)
    assert list(cache) == ["b", "c"] and cache.held_bytes == 800  # a went: 1,200 > 1,000
    cache.get_or_build("b", lambda: pytest.fail("b is cached"))  # b is now the most recent
    cache.get_or_build("d", lambda: b"x" * 300)
    assert list(cache) == ["b", "d"] and cache.held_bytes == 700
    cache.get_or_build("e", lambda: b"x" * 5_000)  # larger than the bound: kept alone
    assert list(cache) == ["e"] and cache.held_bytes == 5_000
    copy = pickle.loads(pickle.dumps(cache))  # a spawned worker's copy: empty, same bounds
    assert len(copy) == 0 and copy.held_bytes == 0 and copy.max_bytes == 1_000 and copy.nbytes is len


def test_the_cache_bound_counts_a_prepared_cloud_s_bytes():
    surfels = zo.point_surfels(_sphere(1_000, 1))
    assert prepared_bytes(surfels) == 136 * 1_000
    t = RandomOcclusion(50, seed=0)
    t._prepared.max_bytes = 2 * prepared_bytes(surfels) + 1
    for i in range(4):
        t(_sphere(1_000, 10 + i), index=i, epoch=0)
    assert len(t._prepared) == 2 and t._prepared.held_bytes == 2 * 136_000
