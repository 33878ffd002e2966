"""One cached :class:`ModernGLRenderer` per mesh in use: the mesh stays on the GPU across calls.

Used by :func:`zbuf_occlude.render.render_depth` and the z-buffer visibility methods
(:mod:`zbuf_occlude.visibility.zbuffer`).
"""

from __future__ import annotations

import trimesh

from zbuf_occlude.mesh.cache import MeshCache
from zbuf_occlude.render.moderngl_backend import ModernGLRenderer

__all__ = ["renderer_for", "RENDERER_CACHE_SIZE"]

#: Meshes whose renderers stay cached by :func:`renderer_for`.
RENDERER_CACHE_SIZE = 4

_renderers: MeshCache[ModernGLRenderer] = MeshCache(ModernGLRenderer, RENDERER_CACHE_SIZE, release=ModernGLRenderer.release)


def renderer_for(mesh: trimesh.Trimesh) -> ModernGLRenderer:
    """The cached :class:`ModernGLRenderer` of ``mesh`` in this process (made on first use).

    One entry per live mesh object (:class:`~zbuf_occlude.mesh.cache.MeshCache`); a mesh
    whose vertices or faces changed gets a new renderer, and evicted renderers release
    their GL objects.
    """
    return _renderers(mesh)
