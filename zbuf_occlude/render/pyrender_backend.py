"""pyrender as a second, independent renderer of linear depth (cross-checks moderngl).

pyrender picks its platform from ``PYOPENGL_PLATFORM`` at import; we set ``egl`` unless the
user chose one.  pyrender makes its own context current for each render; our moderngl
renderer does the same (``with ctx``), so both can live in one process, with two quirks:

* ``OffscreenRenderer.delete()`` (also run by its ``__del__``) calls ``eglTerminate`` on the
  default EGL display, which invalidates every other EGL context of the process, ours
  included.  So one offscreen renderer per process is made and never deleted; it is resized
  per camera.
* pyrender's depth-only pass enables back-face culling whatever ``SKIP_CULL_FACES`` says
  (``Renderer._bind_and_draw_primitive``, 0.1.45); ModelNet faces have no consistent
  winding, so the mesh is handed over with every face in both windings.
* pyrender renders into a 4× multisampled framebuffer; the resolved depth is one sample's,
  up to ~0.4 px from the pixel centre, so its depth differs from ours by the surface's depth
  slope times that offset (~1e-3 object units at 4 units distance).
"""

from __future__ import annotations

import os

import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude._version import install_hint
from zbuf_occlude.errors import BackendUnavailable
from zbuf_occlude.geometry.cameras import Camera

__all__ = ["PyrenderRenderer"]


def _import_pyrender():
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    try:
        import pyrender
    except Exception as exc:  # ImportError, or PyOpenGL failing to find EGL
        raise BackendUnavailable(f"pyrender backend unavailable ({type(exc).__name__}: {exc}); {install_hint('pyrender')}") from exc
    return pyrender


_OFFSCREEN: dict[int, object] = {}


def _offscreen_renderer(pr, width: int, height: int):
    renderer = _OFFSCREEN.get(os.getpid())
    try:
        if renderer is None:
            renderer = _OFFSCREEN[os.getpid()] = pr.OffscreenRenderer(width, height)
        renderer.viewport_width, renderer.viewport_height = width, height
    except Exception as exc:
        raise BackendUnavailable(f"pyrender could not create an offscreen context: {exc}") from exc
    return renderer


class PyrenderRenderer:
    """Depth maps of one mesh with pyrender's offscreen renderer.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame.

    Raises
    ------
    BackendUnavailable
        pyrender or its OpenGL platform cannot be loaded.
    """

    def __init__(self, mesh: trimesh.Trimesh):
        self._pyrender = _import_pyrender()
        pr = self._pyrender
        self._scene = pr.Scene(bg_color=np.zeros(4), ambient_light=np.ones(3))
        faces = np.asarray(mesh.faces)
        two_sided = trimesh.Trimesh(mesh.vertices, np.vstack([faces, faces[:, ::-1]]), process=False)
        # smooth=False: a soup mesh must not have its vertices merged or normals averaged.
        self._scene.add(pr.Mesh.from_trimesh(two_sided, smooth=False))
        self._camera_node = None

    def render_depth(self, camera: Camera) -> NDArray[np.float32]:
        """Linear depth, ``(H, W) float32``, object units, 0 for background, row 0 at the top.

        Raises
        ------
        BackendUnavailable
            The offscreen context cannot be created.
        """
        pr = self._pyrender
        renderer = _offscreen_renderer(pr, camera.width, camera.height)
        K = camera.K
        # pyrender's principal point counts from the image's corner (centred: W/2), K's from the
        # first pixel's centre (centred: (W - 1)/2, OpenCV): half a pixel apart
        pr_camera = pr.IntrinsicsCamera(fx=K[0, 0], fy=K[1, 1], cx=K[0, 2] + 0.5, cy=K[1, 2] + 0.5, znear=camera.znear, zfar=camera.zfar)
        if self._camera_node is not None:
            self._scene.remove_node(self._camera_node)
        # pyrender wants the camera-to-world pose in OpenGL's camera frame.
        self._camera_node = self._scene.add(pr_camera, pose=np.linalg.inv(camera.view_matrix))
        depth = renderer.render(self._scene, flags=pr.RenderFlags.DEPTH_ONLY | pr.RenderFlags.SKIP_CULL_FACES)
        return np.asarray(depth, dtype=np.float32)

    def release(self) -> None:
        """Drop the scene (the process-wide offscreen renderer stays, see module docstring)."""
        self._scene.clear()
        self._camera_node = None

    def __enter__(self) -> PyrenderRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.release()
