"""Compile the package's numba kernels ahead of use, into numba's on-disk cache.

numba compiles a kernel the first time a process calls it, so the first mesh after an install
waits seconds for the kernels of the default method.  Every kernel is decorated with
``cache=True``: the compiled code is written to disk and later processes load it instead.
:func:`warm_up` (``python -m zbuf_occlude.visibility.warmup``, which ``scripts/install.sh``
runs) calls each kernel once through the code that calls it in use (``embree-fast`` with and
without ``face_index``, one-shot, kept and without its pre-pass; the oracle; every other
registered CPU method) on a small mesh, so that the argument types are those of real runs and
real runs find the cache.

Where numba keeps the cache (numba's rules): ``$NUMBA_CACHE_DIR`` when set; else
``__pycache__`` beside each module, when the user can write there; else the user's cache
folder (``~/.cache/numba``).  A package folder the user cannot write (a system-wide install)
therefore means one compile per user, into their own folder.  The cache is keyed by the source
file (time stamp and size) and the CPU: an edited module, or another CPU, compiles anew, once.
"""

from __future__ import annotations

import logging
import sys
import time
from dataclasses import dataclass
from types import ModuleType
from typing import Any

__all__ = ["KernelReport", "kernel_reports", "kernels", "default_method_kernels", "DEFAULT_METHOD_MODULES", "warm_up", "main"]

log = logging.getLogger(__name__)

#: Points sampled on the warm-up mesh: enough that the pre-pass leaves some points to rays and
#: near-ties, few enough that the whole warm-up is compiling, not computing.
WARMUP_POINTS = 20_000
#: The warm-up's poses (elevation, azimuth), degrees: each sees the box hide part of the sphere.
WARMUP_POSES = ((20.0, 30.0), (-35.0, 200.0))
#: Points given to each of the other CPU methods (the paper's loops are O(points × faces)).
WARMUP_METHOD_POINTS = 200


@dataclass(frozen=True)
class KernelReport:
    """What :func:`warm_up` did to one kernel.

    Attributes
    ----------
    name : str
        ``module.function``, relative to the package warmed up (``zbuf_occlude.visibility`` or ``zbuf_occlude.sensors``).
    signatures : int
        Argument-type signatures compiled or loaded in this process.
    loaded : int
        Of those, how many came from the on-disk cache.
    compiled : int
        How many were compiled now (and written to the cache).
    """

    name: str
    signatures: int
    loaded: int
    compiled: int


def _kernel_modules(package: ModuleType | None = None) -> list[ModuleType]:
    """The modules of ``package`` (default :mod:`zbuf_occlude.visibility`) whose source calls numba, imported."""
    import importlib
    import importlib.util
    import pkgutil
    from pathlib import Path

    if package is None:
        import zbuf_occlude.visibility as package

    found = []
    for info in pkgutil.walk_packages(package.__path__, f"{package.__name__}."):
        spec = importlib.util.find_spec(info.name)
        if spec is not None and spec.origin and spec.origin.endswith(".py") and "numba" in Path(spec.origin).read_text(encoding="utf-8"):
            found.append(importlib.import_module(info.name))
    return found


def kernels(package: ModuleType | None = None) -> dict[str, Any]:
    """Every numba kernel of ``package`` that is compiled on its own, by ``module.function`` relative to it.

    Kernels are found in the modules of ``package`` (default :mod:`zbuf_occlude.visibility`;
    :mod:`zbuf_occlude.sensors.warmup` asks for :mod:`zbuf_occlude.sensors`') that use numba.
    Kernels compiled only inside others (``inline="always"``) are left out: they have no
    machine code of their own; so is the paper's object-space loop, which
    :mod:`zbuf_occlude.visibility.paper.face_scan` makes on first request (:func:`warm_up`
    compiles it all the same).

    Returns
    -------
    dict of str to numba dispatcher
    """
    found = {}
    prefix = f"{package.__name__ if package is not None else 'zbuf_occlude.visibility'}."
    for module in _kernel_modules(package):
        found.update(_own_kernels(module, module.__name__.removeprefix(prefix)))
    return found


def _own_kernels(module: ModuleType, short: str) -> dict[str, Any]:
    """The kernels ``module`` defines that are compiled on their own (:func:`kernels`' rule), by ``short.function``."""
    from numba.core.registry import CPUDispatcher

    return {
        f"{short}.{name}": value for name, value in vars(module).items()
        if isinstance(value, CPUDispatcher) and value.targetoptions.get("inline") != "always" and value.__module__ == module.__name__
    }  # fmt: skip


#: The modules of :mod:`zbuf_occlude.visibility` whose kernels the default method compiles on the
#: CPU the first time a command computes visibility: ``auto`` runs ``embree-fast`` there, whose
#: per-view pre-pass is the CPU z-buffer's.  Which of their kernels a view calls depends on the
#: mesh and the pose (a view whose pre-pass decides every point casts no ray); the z-buffer's
#: run on every view.
DEFAULT_METHOD_MODULES = ("embree_fast", "cpu_zbuffer")


def default_method_kernels() -> dict[str, Any]:
    """The kernels of :data:`DEFAULT_METHOD_MODULES` that :func:`kernels` lists (compiled on their
    own, each with its own entry in numba's cache), by ``module.function``; only those two modules
    are imported.

    Returns
    -------
    dict of str to numba dispatcher
        A subset of :func:`kernels`; :func:`warm_up` compiles every one of them.
    """
    import importlib

    found = {}
    for short in DEFAULT_METHOD_MODULES:
        found.update(_own_kernels(importlib.import_module(f"zbuf_occlude.visibility.{short}"), short))
    return found


def _cpu_methods() -> list[str]:
    """The registered methods that run on the CPU with the core dependencies (no extra, no OpenGL), ``auto`` aside."""
    from zbuf_occlude.visibility.registry import available_methods, method_info

    return [m for m in available_methods() if m != "auto" and not method_info(m).gpu and method_info(m).extra is None]


def _exercise() -> None:
    """Run the code that calls each kernel on a small mesh: a sphere, and a box hiding part of it."""
    import trimesh

    from zbuf_occlude.errors import BackendUnavailable
    from zbuf_occlude.geometry.cameras import camera_on_sphere
    from zbuf_occlude.geometry.sampling import sample_surface
    from zbuf_occlude.visibility.embree_fast import FastScene, embree_fast_visible
    from zbuf_occlude.visibility.oracle_embree import occluded_embree
    from zbuf_occlude.visibility.registry import visible_mask
    from zbuf_occlude.visibility.session import VisibilitySession

    # curved and flat faces, one object partly hiding the other: points near creases, silhouettes
    # and grazing faces, which the pre-pass leaves to rays and near-ties
    back = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    front = trimesh.creation.box(extents=(0.3, 0.3, 0.3), transform=trimesh.transformations.translation_matrix((0.6, 0.3, 0.2)))
    mesh = trimesh.util.concatenate([back, front])
    points, face_index = sample_surface(mesh, WARMUP_POINTS, seed=0)
    for elevation_deg, azimuth_deg in WARMUP_POSES:
        camera = camera_on_sphere(elevation_deg, azimuth_deg, 3.0, resolution=64)
        for fi in (face_index, None):
            embree_fast_visible(mesh, points, camera, face_index=fi)  # one shot: points grouped by face
            with VisibilitySession(mesh, points, fi, method="embree-fast") as session:  # kept: Morton order
                session.visible(camera)
            FastScene(mesh, points, fi, prepass=False).visible(camera)  # every point cast as a ray
            occluded_embree(mesh, points, camera.eye, face_index=fi)
            for method in _cpu_methods():  # every other CPU method once, on a few points
                few, fi_few = points[:WARMUP_METHOD_POINTS], None if fi is None else fi[:WARMUP_METHOD_POINTS]
                try:
                    visible_mask(mesh, few, camera, method, face_index=fi_few)
                except BackendUnavailable as exc:
                    log.debug("warm-up: %s skipped: %s", method, exc)
    _compile_threaded()


def _compile_threaded() -> None:
    """Compile point-splat's threaded kernels with the argument types their serial twins were
    just called with (plus the bands' int64), without running them: a view takes them only from
    :data:`~zbuf_occlude.visibility.point_kernels.THREADED_MIN_POINTS` points, and running them
    here would start numba's threads in a process that may fork."""
    from numba import types

    from zbuf_occlude.visibility import point_kernels as k

    k.threads_started()  # compiling a parallel kernel starts numba's threads
    for serial, threaded, extra in ((k.splat_surfels, k.splat_surfels_threaded, (types.int64,)), (k.decide, k.decide_threaded, ())):
        for signature in serial.signatures:
            threaded.compile(tuple(signature) + extra)


def warm_up() -> list[KernelReport]:
    """Compile (or load from numba's cache) every kernel of :func:`kernels` in this process.

    Returns
    -------
    list of KernelReport
        One per kernel, in the order of :func:`kernels`.  A kernel with no signature was either
        called only from other kernels whose code came from the cache (its code is in theirs)
        or, when nothing came from the cache, not reached on the warm-up mesh (it compiles on
        first use).

    Raises
    ------
    BackendUnavailable
        Embree (``embreex``) cannot be imported.
    """
    _exercise()
    return kernel_reports(kernels())


def kernel_reports(found: dict[str, Any]) -> list[KernelReport]:
    """A :class:`KernelReport` of each of ``found`` (:func:`kernels`), from its dispatcher's signatures and cache statistics."""
    reports = []
    for name, dispatcher in found.items():
        stats = dispatcher.stats
        loaded, compiled = sum(stats.cache_hits.values()), sum(stats.cache_misses.values())
        reports.append(KernelReport(name, len(dispatcher.signatures), loaded, compiled))
    return reports


#: The options of ``python -m zbuf_occlude.visibility.warmup`` (it takes no other).
QUIET_OPTIONS = ("-q", "--quiet")


def main(argv: list[str] | None = None, *, command: str = "python -m zbuf_occlude.visibility.warmup", run=None) -> int:
    """``python -m zbuf_occlude.visibility.warmup [-q]``: :func:`warm_up`, one line per kernel on stderr
    (``command`` and ``run``: another warm-up's name and function, :mod:`zbuf_occlude.sensors.warmup`'s).

    ``-q`` (``--quiet``) keeps the summary line only.  A kernel without a signature is named
    there: one called only from other kernels, whose code was loaded with theirs from the
    cache, or one the warm-up mesh did not reach (it compiles on first use).

    Returns
    -------
    int
        0; 2 for an unknown option.
    """
    argv = sys.argv[1:] if argv is None else argv
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if unknown := [a for a in argv if a not in QUIET_OPTIONS]:
        log.error("%s: unknown option(s) %s; it takes only -q (--quiet)", command, " ".join(unknown))
        return 2
    t0 = time.perf_counter()
    reports = (run or warm_up)()
    if not any(a in QUIET_OPTIONS for a in argv):
        for r in reports:
            log.info("  %-40s %d signature(s): %d loaded from the cache, %d compiled", r.name, r.signatures, r.loaded, r.compiled)
    alone = [r.name for r in reports if not r.signatures]
    log.info(
        "numba kernels ready in %.1f s: %d compiled now, %d loaded from the cache%s",
        time.perf_counter() - t0, sum(r.compiled for r in reports), sum(r.loaded for r in reports),
        f"; without a signature of their own (inside other kernels, or compiled on first use): {', '.join(alone)}" if alone else "",
    )  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
