"""Usage and environment checks made before any mesh is loaded (``generate``, ``farm``).

A bad option or a missing OpenGL used to surface once per mesh, after every mesh had been
loaded, as an object failure with exit status 1 and an internal name in the message.  Here
everything that does not depend on a mesh is checked once, up front, and raises an error
that names the option or the environment variable; the CLI exits 2 on it.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections.abc import Sequence
from pathlib import Path

from zbuf_occlude.dataset.storage import ObjectSize, StorageKind, storage_kind
from zbuf_occlude.defaults import DEFAULT_METHOD
from zbuf_occlude.errors import BackendUnavailable, CameraError, InvalidInputError
from zbuf_occlude.farm.config import FarmParams
from zbuf_occlude.farm.options import OPTION_NAMES
from zbuf_occlude.mesh.paths import printable_path
from zbuf_occlude.mesh.inputs.plan import FarmObject
from zbuf_occlude.mesh.inputs.kinds import POINT_SET, POINT_SET_METHOD, plan_kind
from zbuf_occlude.geometry.cameras import camera_on_sphere
from zbuf_occlude.io.owned import make_folder
from zbuf_occlude.resources import check_memory, estimate_job_memory
from zbuf_occlude.visibility.registry import get_method

__all__ = [
    "check_before_work",
    "check_memory_up_front",
    "check_out_option",
    "check_out_outside_inputs",
    "check_radius",
    "prepare_out",
    "check_gl",
    "storage_of",
    "object_size",
    "check_point_set_options",
]

log = logging.getLogger(__name__)


def check_out_option(out: str | os.PathLike, option: str = "--out") -> None:
    """Refuse an empty or blank output folder before it becomes ``Path("")``, the working folder.

    Raises
    ------
    InvalidInputError
        ``out`` is ``""`` or whitespace only (the message names the value and ``option``).
    """
    if not os.fspath(out).strip():
        raise InvalidInputError(f"{option} must name a folder, got {os.fspath(out)!r}")


def check_out_outside_inputs(out: str | os.PathLike, inputs: Sequence[str | os.PathLike]) -> None:
    """Refuse an ``out`` inside an input folder (symlinks resolved): a rerun would find the
    outputs written there (a ``--format ply`` sample is a mesh file) among its inputs.

    Raises
    ------
    InvalidInputError
        ``out`` is an input folder or lies inside one (both named).
    """
    target = Path(out).resolve()
    for source in inputs:
        folder = Path(source).resolve()
        if folder.is_dir() and (target == folder or folder in target.parents):
            raise InvalidInputError(
                f"--out {out} lies inside the input folder {source}: a rerun would read its outputs as inputs; choose an --out outside it"
            )


def prepare_out(out: Path) -> None:
    """Create ``out`` and check it is writable (:func:`zbuf_occlude.io.owned.make_folder`).

    Raises
    ------
    OutputError
        It is a file, or it cannot be created or written (the message says: choose a
        writable ``--out``).
    """
    make_folder(out)


def check_gl(resolution: int) -> None:
    """Make this process's OpenGL context now and check ``--resolution`` fits it.

    Raises
    ------
    BackendUnavailable
        No context (the message names ``ZBUF_OCCLUDE_GL`` when it is set).
    InvalidInputError
        ``resolution`` exceeds the GL's maximum image size
        (:func:`~zbuf_occlude.render.context.check_image_size`).
    """
    from zbuf_occlude.render.context import check_image_size, shared_context

    try:
        ctx = shared_context()
    except BackendUnavailable as exc:
        env = os.environ.get("ZBUF_OCCLUDE_GL")
        where = f" (ZBUF_OCCLUDE_GL={env!r}; unset it or use egl, osmesa or an order such as osmesa,egl)" if env else ""
        raise BackendUnavailable(f"{exc}{where}") from exc
    check_image_size(resolution, ctx=ctx, name="--resolution")


def storage_of(params: FarmParams) -> StorageKind:
    """The storage kind a run of ``params`` writes (:func:`~zbuf_occlude.dataset.storage.storage_kind`;
    ``farm --sensor``: its scans)."""
    return storage_kind(params.storage, sensor=params.sensor is not None)


def object_size(params: FarmParams) -> ObjectSize:
    """The sizes of one object of a run of ``params``, which its storage kind estimates from
    (``dense_points`` 0 with ``--density``: unknown before the mesh is read)."""
    return ObjectSize(len(params.poses), params.samples_per_view, params.n_points, params.dense_points or 0)


def check_memory_up_front(params: FarmParams, *, workers: int = 1) -> None:
    """Refuse a run whose objects cannot fit in memory, naming the option that costs most.

    Each of ``workers`` processes holds one object at a time: its dense cloud
    (``--dense-points``; unknown with ``--density``, then not counted), its image
    (``--resolution``) and the samples its storage kind holds until they are written
    (:meth:`~zbuf_occlude.dataset.storage.StorageKind.memory_held`: all of an object's samples
    for one file per object, ``dense`` and ``h5``; one pose's for ``npz`` and ``ply``; none for
    ``compact``, which stores visibility bits).

    Raises
    ------
    InsufficientMemoryError
        The estimate exceeds the memory available (:func:`~zbuf_occlude.resources.check_memory`).
    """
    points, held = storage_of(params).memory_held(object_size(params))
    estimate = estimate_job_memory(
        points=points, samples_per_view=params.samples_per_view, samples_held=held, dense_points=params.dense_points or 0,
        resolution=params.resolution, workers=workers,
    )  # fmt: skip
    check_memory(estimate)


def check_radius(radius: float, resolution: int) -> None:
    """``--radius`` makes a camera: outside the object's bounding sphere, and not so far that
    float64 no longer decides visibility (:data:`~zbuf_occlude.geometry.cameras.MAX_CAMERA_RADIUS`).

    Raises InvalidInputError naming ``--radius``.
    """
    try:
        camera_on_sphere(0.0, 0.0, radius, resolution=resolution)
    except CameraError as exc:
        raise InvalidInputError(f"--radius {radius}: {exc}") from None


def check_before_work(params: FarmParams, out: str | os.PathLike, *, gl: bool = True, workers: int | None = 1) -> None:
    """Every check of a run that needs no mesh, in the order a user fixes them.

    Options (``FarmParams`` checked its own ranges and ``--seed`` when it was made): the
    method exists, the camera distance ``--radius`` is outside the normalised object's
    bounding sphere; then the environment: ``out`` writable, an OpenGL context (``gl``:
    the run renders in this process) whose maximum image size holds ``--resolution``
    (before the memory, so that a huge ``--resolution`` is told the maximum), and the
    memory ``workers`` processes need (:func:`check_memory_up_front`; None: they run
    elsewhere, not checked).

    Raises
    ------
    InvalidInputError
        An option is unusable (``out`` empty included); the message names it.
    OutputError
        ``out`` is a file or cannot be created or written.
    BackendUnavailable
        No OpenGL context here.
    InsufficientMemoryError
        The run needs more memory than is available (an :class:`InvalidInputError`).
    """
    check_out_option(out)
    get_method(params.method)
    check_radius(params.radius, params.resolution)
    prepare_out(Path(out))
    if gl:
        check_gl(params.resolution)
    if workers is not None:
        check_memory_up_front(params, workers=workers)


def check_point_set_options(
    objects: Sequence[FarmObject], params: FarmParams, defaults: FarmParams | None = None, set_params: frozenset[str] | None = None
) -> FarmParams:
    """Refuse options that cannot apply to the objects' input kinds (:mod:`zbuf_occlude.mesh.inputs.kinds`),
    before any work; the parameters the plan runs with.

    A point-set input is seen from its points alone, by :data:`~zbuf_occlude.mesh.inputs.kinds.POINT_SET_METHOD`:
    ``--method`` may be left at its default (which then picks per input: the points' method for
    clouds, ``auto``'s for meshes) or name that method, which then decides the meshes too.  Any
    other method decides from a mesh, which a point set has not; ``farm --sensor`` scans meshes.
    Where every object is of one kind, the options its kind does not use
    (:attr:`~zbuf_occlude.mesh.inputs.kinds.InputKind.unused_params`: ``--dense-points``,
    ``--density``, ``--resolution`` for point sets) are refused when set, the method recorded is
    the kind's (``point-splat``), and ``--points`` left unset takes the kind's default
    (:attr:`~zbuf_occlude.mesh.inputs.kinds.InputKind.default_points`).

    Parameters
    ----------
    defaults : FarmParams, optional
        The command's defaults (default :class:`FarmParams` ``()``, the farm's).
    set_params : frozenset of str, optional
        The fields the user set; None: those whose value differs from ``defaults``.

    Returns
    -------
    FarmParams
        ``params``, with the method (and unset ``n_points``) of the plan's one input kind where that kind has its own.

    Raises
    ------
    InvalidInputError
        ``--method`` other than the default or :data:`~zbuf_occlude.mesh.inputs.kinds.POINT_SET_METHOD`,
        or ``--sensor``, with point-set inputs (naming the value and one of the files); an
        option the plan's one kind does not use, set (naming it).
    """
    clouds = [o for o in objects if o.kind is POINT_SET]
    if not clouds:
        return params
    files = len({o.source for o in clouds})
    which = f"{len(clouds)} cloud{'s' if len(clouds) > 1 else ''} of {files} point-set file{'s' if files > 1 else ''}, e.g. {printable_path(clouds[0].source)}"
    if params.sensor is not None:
        raise InvalidInputError(f"{OPTION_NAMES['sensor']} {params.sensor.name} scans meshes, and the inputs hold {which}: leave those out")
    if params.method not in (DEFAULT_METHOD, POINT_SET_METHOD):
        raise InvalidInputError(
            f"{OPTION_NAMES['method']} {params.method} decides visibility from a mesh, and the inputs hold {which}, whose "
            f"visibility comes from their points alone ({POINT_SET_METHOD}): leave {OPTION_NAMES['method']} out or give "
            f"{OPTION_NAMES['method']} {POINT_SET_METHOD}"
        )
    kind = plan_kind(objects)
    if kind is None:
        return params
    defaults = defaults or FarmParams()

    def is_set(field: str) -> bool:
        value = getattr(params, field)
        return field in set_params if set_params is not None else value is not None and value != getattr(defaults, field)

    for field in kind.unused_params:
        if is_set(field):
            raise InvalidInputError(
                f"{OPTION_NAMES[field]} {getattr(params, field)} does nothing for {kind.name} inputs ({which}): their dense "
                f"cloud is their own points and their visibility comes from them ({kind.method}); leave {OPTION_NAMES[field]} out"
            )
    changes = {"method": kind.method} if kind.method is not None else {}
    if kind.default_points is not None and not is_set("n_points"):
        changes["n_points"] = kind.default_points
    return dataclasses.replace(params, **changes) if changes else params
