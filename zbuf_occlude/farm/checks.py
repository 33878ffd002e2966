"""Usage and environment checks made before any mesh is loaded (``generate``, ``farm``).

A bad option or a missing OpenGL used to surface once per mesh, after every mesh had been
loaded, as an object failure with exit status 1 and an internal name in the message.  Here
everything that does not depend on a mesh is checked once, up front, and raises an error
that names the option or the environment variable; the CLI exits 2 on it.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from ..cameras import camera_on_sphere
from ..errors import BackendUnavailable, CameraError, InvalidInputError, OutputError
from ..visibility.registry import get_method
from .config import FarmParams

__all__ = ["check_before_work", "prepare_out", "check_gl"]

log = logging.getLogger(__name__)


def prepare_out(out: Path) -> None:
    """Create ``out`` and check it is writable.

    Raises
    ------
    OutputError
        It cannot be created or written (the message says: choose a writable ``--out``).
    """
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the output folder {out}: {exc.strerror or exc}; choose a writable --out") from exc
    if not os.access(out, os.W_OK | os.X_OK):
        raise OutputError(f"the output folder {out} is not writable; choose a writable --out")


def check_gl(resolution: int) -> None:
    """Make this process's OpenGL context now and check ``--resolution`` fits it.

    Raises
    ------
    BackendUnavailable
        No context (the message names ``ZBUF_OCCLUDE_GL`` when it is set).
    InvalidInputError
        ``resolution`` exceeds the GL's maximum renderbuffer size.
    """
    from ..render.context import shared_context

    try:
        ctx = shared_context()
    except BackendUnavailable as exc:
        env = os.environ.get("ZBUF_OCCLUDE_GL")
        where = f" (ZBUF_OCCLUDE_GL={env!r}; unset it or use egl, osmesa or an order such as osmesa,egl)" if env else ""
        raise BackendUnavailable(f"{exc}{where}") from exc
    # TODO(badinput): replace the three lines below by
    #   render.context.check_image_size(resolution, ctx=ctx, name="--resolution")
    # (it takes the smallest of the texture, renderbuffer and viewport limits), so the limit is queried in one place
    limit = int(ctx.info.get("GL_MAX_RENDERBUFFER_SIZE", 0) or 0)
    if limit and resolution > limit:
        raise InvalidInputError(f"--resolution {resolution} is larger than this OpenGL can render ({limit} pixels, GL_MAX_RENDERBUFFER_SIZE)")


def check_before_work(params: FarmParams, out: str | os.PathLike, *, gl: bool = True) -> None:
    """Every check of a run that needs no mesh, in the order a user fixes them.

    Options (``FarmParams`` checked its own ranges when it was made): the method exists,
    the camera distance ``--radius`` is outside the normalised object's bounding sphere;
    then the environment: ``out`` writable, an OpenGL context (``gl``: the run renders in
    this process) whose maximum image size holds ``--resolution``.

    Raises
    ------
    InvalidInputError
        An option is unusable; the message names it.
    OutputError
        ``out`` cannot be created or written.
    BackendUnavailable
        No OpenGL context here.
    """
    get_method(params.method)
    try:
        camera_on_sphere(0.0, 0.0, params.radius, resolution=params.resolution)
    except CameraError as exc:
        raise InvalidInputError(f"--radius {params.radius}: {exc}") from None
    # TODO(badinput): sampling.check_seed(params.seed, name="--seed") (FarmParams checks >= 0 meanwhile) and
    #   resources.check_memory(resources.estimate_job_memory(points=params.n_points,
    #       samples_per_view=params.samples_per_view, dense_points=params.dense_points or 0,
    #       resolution=params.resolution, workers=workers)) go here, before any mesh is loaded
    prepare_out(Path(out))
    if gl:
        check_gl(params.resolution)
