"""Rendering: the only package that touches OpenGL.

``context`` makes GL contexts (EGL, then OSMesa); ``moderngl_backend`` renders depth and
face-index buffers and runs the visibility compute shaders; ``pyrender_backend`` renders
depth independently for cross-checks.
"""

from zbuf_occlude.render.context import context_info, create_context, shared_context
from zbuf_occlude.render.moderngl_backend import DepthRender, ModernGLRenderer, PointBuffer
from zbuf_occlude.render.renderer_cache import renderer_for

__all__ = [
    "create_context",
    "shared_context",
    "context_info",
    "ModernGLRenderer",
    "DepthRender",
    "PointBuffer",
    "render_depth",
    "renderer_for",
]


def render_depth(mesh, camera, backend: str = "moderngl"):
    """Linear depth ``(H, W) float32`` (object units, 0 = background, row 0 at the top).

    ``backend``: ``"moderngl"`` (cached renderer of the mesh) or ``"pyrender"``.
    """
    from zbuf_occlude.geometry.arguments import check_camera, check_mesh

    check_mesh(mesh)
    check_camera(camera)
    if backend == "moderngl":
        return renderer_for(mesh).render(camera).depth
    if backend == "pyrender":
        from zbuf_occlude.render.pyrender_backend import PyrenderRenderer

        with PyrenderRenderer(mesh) as renderer:
            return renderer.render_depth(camera)
    from zbuf_occlude.errors import InvalidInputError

    raise InvalidInputError(f"unknown render backend {backend!r}; use 'moderngl' or 'pyrender'")
