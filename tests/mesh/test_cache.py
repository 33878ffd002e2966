"""The per-mesh cache behind the renderer, planes and Embree caches."""

from __future__ import annotations

import gc

import trimesh

from zbuf_occlude.mesh.cache import MeshCache


def _counting_cache(size=2):
    built, released = [], []

    def build(mesh):
        built.append(id(mesh))
        return object()

    return MeshCache(build, size, release=released.append), built, released


def test_one_build_per_mesh_and_rebuild_after_an_edit():
    cache, built, released = _counting_cache()
    mesh = trimesh.creation.box()
    first = cache(mesh)
    assert cache(mesh) is first and len(built) == 1
    mesh.vertices = mesh.vertices * 2.0
    second = cache(mesh)
    assert second is not first and len(built) == 2 and released == [first]


def test_least_recently_used_is_evicted_and_released():
    cache, built, released = _counting_cache(size=2)
    a, b, c = (trimesh.creation.box() for _ in range(3))
    va = cache(a)
    cache(b)
    cache(a)  # a is now the most recent
    vb = cache(b)
    cache(c)  # evicts the least recent: a
    assert released == [va]
    assert cache(b) is vb and len(built) == 3


def test_entries_of_collected_meshes_are_dropped():
    cache, built, released = _counting_cache(size=4)
    mesh = trimesh.creation.box()
    value = cache(mesh)
    del mesh
    gc.collect()
    cache(trimesh.creation.icosphere())
    assert released == [value]


def test_a_hit_refreshes_an_entry_lru_not_fifo():
    """a, b, a (hit), c: LRU evicts b (least recently *used*); FIFO would evict a (first in)."""
    cache, built, released = _counting_cache(size=2)
    a, b, c = (trimesh.creation.box() for _ in range(3))
    va, vb = cache(a), cache(b)
    assert cache(a) is va  # a hit: a becomes the most recent
    cache(c)
    assert released == [vb]
    assert cache(a) is va and len(built) == 3  # a survived: no rebuild
    # and on: a, c are cached, c the most recent after this lookup; a new mesh evicts a
    cache(c)
    d = trimesh.creation.box()
    cache(d)
    assert released == [vb, va]


def test_the_value_is_built_from_that_mesh():
    cache = MeshCache(lambda mesh: float(mesh.area), size=2)
    small, big = trimesh.creation.box(extents=(1, 1, 1)), trimesh.creation.box(extents=(2, 2, 2))
    assert cache(small) == 6.0 and cache(big) == 24.0


def test_without_release_evictions_and_clear_just_forget():
    cache = MeshCache(lambda mesh: object(), size=1)  # no release callback
    a, b = trimesh.creation.box(), trimesh.creation.icosphere()
    va = cache(a)
    cache(b)  # evicts a without calling a release
    assert cache(a) is not va
    cache.clear()


def test_clear_releases_every_entry_of_this_process():
    cache, built, released = _counting_cache(size=3)
    meshes = [trimesh.creation.box() for _ in range(3)]
    values = [cache(m) for m in meshes]
    cache.clear()
    assert released == values
    assert cache(meshes[0]) is not values[0] and len(built) == 4
