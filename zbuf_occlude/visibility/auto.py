"""``auto`` (the default method): the fastest exact method on this machine.

Both candidates decide the same definition (:mod:`~zbuf_occlude.visibility.definition`):
``zbuffer-exact`` on the GPU (:mod:`~zbuf_occlude.visibility.gpu_exact`) and ``embree-fast``
on the CPU's threads (:mod:`~zbuf_occlude.visibility.embree_fast`).  :func:`choose_method`
picks once per process, separately for the two ways of calling: a kept session
(:class:`~zbuf_occlude.visibility.session.VisibilitySession`, the farm, many views of one point set: the points' set-up is paid once)
and the one-shot call (``visible_mask``: the points' set-up is paid every view; uploading
and ordering 1M points for the GPU costs more than Embree's whole view on 16 cores):

* ``$ZBUF_OCCLUDE_AUTO`` names one of them (or ``calibrate``): that wins;
* only one of OpenGL 4.3 / ``embreex`` is available: that one;
* the OpenGL renderer is a software rasteriser (llvmpipe, softpipe, swrast, SwiftShader,
  lavapipe): ``embree-fast``, since the "GPU" runs on the same cores, where Embree is
  measured several times faster (README, "Measured results");
* a hardware renderer: a short calibration (:func:`calibrate`, ~1 s) times both on a
  built-in problem, the way they will be called, and keeps the faster.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import time

import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.geometry.cameras import Camera, camera_on_sphere, view_schedule
from zbuf_occlude.render.context import is_software_renderer
from zbuf_occlude.visibility.definition import TOLERANCE
from zbuf_occlude.visibility.registry import get_method, method_info, register, resolution_option

__all__ = ["choose_method", "calibrate", "auto_visible", "AUTO_ENV"]

log = logging.getLogger(__name__)

#: Environment variable that forces ``auto``'s choice.
AUTO_ENV = "ZBUF_OCCLUDE_AUTO"
_CANDIDATES = ("zbuffer-exact", "embree-fast")


def _gl_renderer() -> str | None:
    try:
        from zbuf_occlude.render.context import shared_context

        return str(shared_context().info["GL_RENDERER"])
    except BackendUnavailable:
        return None


def _has_embree() -> bool:
    try:
        import embreex  # noqa: F401
    except ImportError:
        return False
    return True


def calibrate(n_points: int = 50_000, views: int = 5, *, one_shot: bool = False) -> dict[str, float]:
    """Median seconds per view of each candidate on a built-in problem (a subdivided
    icosphere inside a box, ``n_points`` points, ``views`` views after one warm-up).

    Parameters
    ----------
    n_points : int
        Points of the problem (the farm's dense clouds hold 32,768).
    views : int
        Timed views (fibonacci poses) after the warm-up view.
    one_shot : bool
        Time the one-shot call (``method(mesh, points, camera)``: the points are set up every
        view, the mesh's state is kept) instead of ``session.visible(camera)``.

    Returns
    -------
    seconds : dict
        Method name → seconds per view, for the candidates that run here.
    """
    from zbuf_occlude.visibility.embree_fast import FastScene
    from zbuf_occlude.visibility.gpu_exact import ExactScene

    mesh = trimesh.util.concatenate([trimesh.creation.icosphere(subdivisions=4, radius=0.3), trimesh.creation.box([0.9, 0.9, 0.9])])
    points, face_index = trimesh.sample.sample_surface(mesh, n_points, seed=0)
    cameras = [camera_on_sphere(el, az) for el, az in view_schedule(f"fibonacci:{views + 1}")]
    out: dict[str, float] = {}
    for name, make in (("zbuffer-exact", ExactScene), ("embree-fast", FastScene)):
        try:
            with contextlib.nullcontext() if one_shot else make(mesh, points, face_index) as scene:
                view = functools.partial(get_method(name), mesh, points, face_index=face_index) if one_shot else scene.visible
                view(cameras[0])  # warm-up: shaders, JIT, thread pool, the mesh's cached state
                times = []
                for cam in cameras[1:]:
                    t = time.perf_counter()
                    view(cam)
                    times.append(time.perf_counter() - t)
            out[name] = float(np.median(times))
        except BackendUnavailable as exc:
            log.debug("auto: %s unavailable: %s", name, exc)
    return out


@functools.lru_cache(maxsize=2)
def choose_method(one_shot: bool = False) -> str:
    """The method ``auto`` runs in this process (decided once per way of calling; see the
    module docstring): for kept sessions, or with ``one_shot`` for one-shot calls.

    Raises
    ------
    InvalidInputError
        ``$ZBUF_OCCLUDE_AUTO`` names something else than a candidate or ``calibrate``.
    BackendUnavailable
        Neither OpenGL 4.3 nor Embree is available.
    """
    forced = os.environ.get(AUTO_ENV, "").strip()
    if forced and forced not in (*_CANDIDATES, "calibrate"):
        raise InvalidInputError(f"${AUTO_ENV}={forced!r}: use one of {', '.join(_CANDIDATES)} or 'calibrate'")
    if forced in _CANDIDATES:
        return forced
    renderer = _gl_renderer()
    embree = _has_embree()
    if renderer is None and not embree:
        raise BackendUnavailable("method 'auto' needs OpenGL 4.3 or embreex; use method='oracle-numpy'")
    if renderer is None:
        return "embree-fast"
    if not embree:
        return "zbuffer-exact"
    if forced != "calibrate" and is_software_renderer(renderer):
        log.info("auto: software OpenGL renderer %r shares the CPU: embree-fast", renderer)
        return "embree-fast"
    seconds = calibrate(one_shot=one_shot)
    choice = min(seconds, key=seconds.get) if seconds else "embree-fast"
    log.info("auto: renderer %r, %s calibration %s: %s", renderer, "one-shot" if one_shot else "session", seconds, choice)
    return choice


def _session(mesh: trimesh.Trimesh, points, face_index=None):
    # auto's session factory: the session of the method chosen for kept sessions
    return method_info(choose_method()).session(mesh, points, face_index)


@register("auto", takes_resolution=True, session=_session)
def auto_visible(
    mesh: trimesh.Trimesh,
    points: NDArray[np.float64],
    camera: Camera,
    *,
    face_index: NDArray[np.int64] | None = None,
    resolution: int | tuple[int, int] | None = None,
    tolerance: float = TOLERANCE,
) -> NDArray[np.bool_]:
    """The default HSR method: ``choose_method(one_shot=True)``'s.

    ``tolerance`` (object units) goes to the chosen method; ``resolution`` (the tile grid of
    ``zbuffer-exact``; it does not change the answer) only where it takes one.
    """
    method = choose_method(one_shot=True)
    options = resolution_option(method, resolution) if resolution is not None else {}
    return get_method(method)(mesh, points, camera, face_index=face_index, tolerance=tolerance, **options)
