"""Per-mesh caches of derived data: the GL renderer, the face planes, the Embree scene.

Many cameras of one mesh must not rebuild what depends on the mesh alone.  One mechanism
serves every such cache: an entry is keyed on the process and the mesh *object*, checked
against the mesh's content hash (``Trimesh.__hash__``, cached by trimesh until the arrays
change), and dropped once the mesh is garbage-collected.  Entries made in another process
(inherited across ``fork``) are never used or released.
"""

from __future__ import annotations

import os
import threading
import weakref
from collections import OrderedDict
from collections.abc import Callable
from typing import TYPE_CHECKING, Generic, TypeVar

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = ["MeshCache"]

T = TypeVar("T")


class MeshCache(Generic[T]):
    """A least-recently-used cache of ``build(mesh)``, one entry per live mesh object.

    Parameters
    ----------
    build : callable
        ``build(mesh) -> value``; called outside the lock.
    size : int
        Entries kept; the least recently used are evicted.
    release : callable, optional
        ``release(value)`` for entries evicted or made stale in the process that built
        them (GL objects).  It runs in the caller's thread during a later call, never
        from a garbage-collection callback, so GL calls are safe there.
    """

    def __init__(self, build: Callable[[trimesh.Trimesh], T], size: int, release: Callable[[T], None] | None = None):
        self._build = build
        self._size = int(size)
        self._release = release
        self._entries: OrderedDict[tuple[int, int], tuple[weakref.ref, int, T]] = OrderedDict()
        self._lock = threading.RLock()

    def _drop(self, key: tuple[int, int]) -> None:
        _, _, value = self._entries.pop(key)
        if self._release is not None and key[0] == os.getpid():
            self._release(value)

    def __call__(self, mesh: trimesh.Trimesh) -> T:
        """The cached value for ``mesh``, built on first use or after the mesh changed."""
        key, content = (os.getpid(), id(mesh)), hash(mesh)
        with self._lock:
            entry = self._entries.get(key)
            if entry is not None and entry[0]() is mesh and entry[1] == content:
                self._entries.move_to_end(key)
                return entry[2]
        value = self._build(mesh)
        with self._lock:
            # stale: this key's old mesh changed or died (its id reused), other processes'
            # entries, and meshes collected since
            stale = [k for k, (ref, _, _) in self._entries.items() if k == key or k[0] != key[0] or ref() is None]
            for k in stale:
                self._drop(k)
            self._entries[key] = (weakref.ref(mesh), content, value)
            while len(self._entries) > self._size:
                self._drop(next(iter(self._entries)))
        return value

    def clear(self) -> None:
        """Drop every entry (releasing those of this process)."""
        with self._lock:
            for k in list(self._entries):
                self._drop(k)
