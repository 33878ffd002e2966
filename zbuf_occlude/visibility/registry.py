"""The registry of hidden-surface-removal (HSR) methods behind :func:`visible_mask`.

A method is a function ``fn(mesh, points, camera, *, face_index=None, **options) -> (N,) bool``
registered under one or more names with :func:`register`, which also declares what the
method can do (:class:`MethodInfo`: takes ``resolution``, takes ``grid``, keeps points on
the GPU across poses, needs an optional extra, exact...).  Callers ask
:func:`method_info` instead of testing method names, so adding a method is one new
function and one decorator line; :func:`visible_mask`, ``occlude_object`` and ``compare``
need no edit.

The definition every exact method decides (stated in full in
:mod:`zbuf_occlude.visibility.definition`): a point is visible iff it is in the frustum, its
own face (``face_index``, or every face containing it) is not seen within 1e-4 degrees of
edge-on, and no other face meets the segment to the camera centre farther than 1e-6 object
units from it.  ``oracle``, ``oracle-numpy``, ``zbuffer-exact``, ``embree-fast`` and
``auto`` implement it; ``zbuffer`` and the paper's and peers' methods approximate it.
"""

from __future__ import annotations

import functools
import importlib
import inspect
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude._version import install_hint
from zbuf_occlude.defaults import DEFAULT_METHOD
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError, RegistryError, UnknownOptionError
from zbuf_occlude.geometry.arguments import check_camera, check_face_index, check_mesh, check_points
from zbuf_occlude.geometry.cameras import Camera
from zbuf_occlude.geometry.placement import warn_camera_placement

if TYPE_CHECKING:  # annotations only: trimesh (and scipy with it) is imported where meshes are made
    import trimesh

__all__ = [
    "register",
    "available_methods",
    "get_method",
    "method_info",
    "unavailable_reason",
    "check_runnable",
    "EXTRA_MODULES",
    "MethodInfo",
    "PoseSession",
    "check_points",
    "check_face_index",
    "visible_in_frustum",
    "method_keywords",
    "signature_without",
    "resolution_option",
    "check_keywords",
]

log = logging.getLogger(__name__)

VisibilityMethod = Callable[..., NDArray[np.bool_]]

#: The module an extra of :attr:`MethodInfo.extra` must make importable (the extra's name when absent).
EXTRA_MODULES: dict[str, str] = {"open3d": "open3d"}
_METHODS: dict[str, VisibilityMethod] = {}
_INFO: dict[str, MethodInfo] = {}
#: Modules of this package whose import registers the built-in methods: image space (zbuffer,
#: zbuffer-exact), the exact oracles, the paper's object-space methods (§3.3-3.6), peers and
#: auto.  They are imported the first time a method is looked up, not with the package, so that
#: a program pays for numba, moderngl and Embree only when it asks for visibility.
BUILTIN_MODULES = (
    "auto", "embree_fast", "gpu_exact", "oracle", "peers", "point_splats", "zbuffer",
    "paper.object_space", "paper.occupancy", "paper.vertex",
)  # fmt: skip
_builtins_loaded = False


def _load_builtins() -> None:
    global _builtins_loaded
    if not _builtins_loaded:
        _builtins_loaded = True  # first: a method module that looks a method up while it loads must not recurse
        for module in BUILTIN_MODULES:
            importlib.import_module(f"{__package__}.{module}")


class PoseSession(Protocol):
    """Points kept resident (e.g. on the GPU) and tested from many cameras; see :attr:`MethodInfo.session`."""

    def visible(self, camera: Camera, **options: Any) -> NDArray[np.bool_]: ...

    def release(self) -> None: ...


class SessionBase:
    """``with`` support for a :class:`PoseSession`: leaving the block calls ``release()``."""

    def release(self) -> None:
        """Free what the session holds (nothing here)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.release()


@dataclass(frozen=True)
class MethodInfo:
    """What a registered method can do, declared once in its :func:`register` line.

    Attributes
    ----------
    name : str
        The canonical name (first name given to :func:`register`).
    function : callable
        ``fn(mesh, points, camera, *, face_index=None, **options) -> (N,) bool``.
    takes_resolution : bool
        Image space: honours a ``resolution`` option (pixels), and its answer depends on it.
    takes_grid : bool
        Honours a ``grid`` option (occupancy-grid cells per axis).
    grid_of : str or None
        For a name that fixes the grid (``"og32"``): the method whose ``grid`` it fixes.
    session : callable or None
        ``session(mesh, points, face_index) -> PoseSession`` keeping the points resident
        across poses (uploaded to the GPU once); ``session(...).visible(camera, **options)``
        must equal the method's answer for that camera.  ``None``: call the method per pose.
    extra : str or None
        The extra of ``pyproject.toml`` the method needs, if any (:func:`~zbuf_occlude._version.install_hint`).
    exact : bool
        Decides the oracle's definition (Eq. 1-10 in float64, every occluder tested), not an
        approximation of it: the answer of ``"oracle-numpy"`` (``"oracle"`` up to Embree's
        documented float32 residue).
    gpu : bool
        Needs an OpenGL 4.3 context.
    """

    name: str
    function: VisibilityMethod
    takes_resolution: bool = False
    takes_grid: bool = False
    grid_of: str | None = None
    session: Callable[..., PoseSession] | None = None
    extra: str | None = None
    exact: bool = False
    gpu: bool = False


def register(*names: str, **capabilities: Any) -> Callable[[VisibilityMethod], VisibilityMethod]:
    """Decorator: register an HSR method under ``names`` (the first is canonical).

    ``capabilities`` are the fields of :class:`MethodInfo` other than ``name`` and
    ``function`` (``takes_resolution=True``, ``session=...``); unknown ones are an error.

    Raises
    ------
    RegistryError
        A name already registered to another function, or an unknown capability.
    """
    fields = set(MethodInfo.__dataclass_fields__) - {"name", "function"}
    unknown = sorted(set(capabilities) - fields)
    if unknown:
        raise RegistryError(f"unknown method capabilities {unknown}; known: {sorted(fields)}")

    def deco(fn: VisibilityMethod) -> VisibilityMethod:
        for name in names:
            if name in _METHODS and _METHODS[name] is not fn:
                raise RegistryError(f"visibility method {name!r} registered twice")
        info = MethodInfo(name=names[0], function=fn, **capabilities)
        for name in names:
            _METHODS[name] = fn
            _INFO[name] = info
        return fn

    return deco


def available_methods() -> list[str]:
    """Names accepted by ``visible_mask(..., method=...)``, sorted."""
    _load_builtins()
    return sorted(_METHODS)


def unavailable_reason(name: str) -> str | None:
    """Why method ``name`` cannot run here, or None: the extra it declares
    (:attr:`MethodInfo.extra`) does not import.  Unknown names raise as :func:`get_method`."""
    extra = method_info(name).extra
    if extra is None:
        return None
    try:
        importlib.import_module(EXTRA_MODULES.get(extra, extra))
    except (ImportError, OSError) as exc:  # a wheel whose shared libraries are missing fails with OSError
        return f"method {name!r} needs the {extra} extra ({install_hint(extra)}): {exc}"
    return None


def check_runnable(name: str) -> None:
    """Refuse, before any work, a method that is unknown or cannot run here.

    Raises
    ------
    InvalidInputError
        Unknown name.
    BackendUnavailable
        Its extra is not installed (:func:`unavailable_reason`).
    """
    problem = unavailable_reason(name)
    if problem:
        raise BackendUnavailable(problem)


def get_method(name: str) -> VisibilityMethod:
    """The function registered as ``name``; :class:`InvalidInputError` if unknown."""
    _load_builtins()
    try:
        return _METHODS[name]
    except KeyError:
        raise InvalidInputError(f"unknown visibility method {name!r}; available: {', '.join(available_methods())}") from None


def method_info(name: str) -> MethodInfo:
    """What method ``name`` can do (:class:`MethodInfo`); :class:`InvalidInputError` if unknown."""
    fn = get_method(name)
    info = _INFO.get(name)
    # A function put in _METHODS by hand (tests do) declares nothing.
    return info if info is not None and info.function is fn else MethodInfo(name=name, function=fn)


def visible_in_frustum(
    points: NDArray[np.float64], camera: Camera, occluded: Callable[[NDArray[np.int64]], NDArray[np.bool_]]
) -> NDArray[np.bool_]:
    """``camera.in_frustum(points) & ~occluded``, asking ``occluded(idx)`` only about the
    in-frustum points ``idx`` (the object-space methods' common frame).

    Returns
    -------
    visible : (N,) bool
    """
    visible = camera.in_frustum(points)
    idx = np.flatnonzero(visible)
    if len(idx):
        visible[idx[occluded(idx)]] = False
    return visible


def method_keywords(method: str) -> frozenset[str] | None:
    """The keywords ``method`` takes besides ``face_index`` (from its signature); ``None`` for
    a method that takes any (``**options``: a user's method may forward them elsewhere).

    Raises
    ------
    InvalidInputError
        Unknown method.
    """
    return _keywords_of(get_method(method))


@functools.cache
def _keywords_of(fn: VisibilityMethod) -> frozenset[str] | None:
    """:func:`method_keywords` of a registered function, cached per function (not per name: a
    name may be bound to another function, e.g. in a test's scratch registry)."""
    params = list(inspect.signature(fn).parameters.values())
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        return None
    named = (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return frozenset(p.name for p in params[3:] if p.kind in named and p.name != "face_index")  # after mesh, points, camera


def signature_without(fn: Callable[..., Any], *fixed: str) -> inspect.Signature:
    """``fn``'s signature without the keywords ``fixed``: the ``__signature__`` of a method that
    calls ``fn`` with those keywords set (``og32`` = ``og`` with ``grid=32``), so that
    :func:`method_keywords` tells what it takes."""
    sig = inspect.signature(fn)
    return sig.replace(parameters=[p for p in sig.parameters.values() if p.name not in fixed])


def resolution_option(method: str, resolution) -> dict[str, Any]:
    """``{"resolution": resolution}`` for a method that declares ``takes_resolution`` (the
    image-space methods), else ``{}``: what a caller that drives any method passes."""
    return {"resolution": resolution} if method_info(method).takes_resolution else {}


def check_keywords(method: str, options: dict[str, Any]) -> None:
    """Raise :class:`~zbuf_occlude.errors.UnknownOptionError` (a ``TypeError``) naming every key of ``options`` that ``method`` does not take
    (a misspelt ``tolerence`` must not run with the default instead)."""
    accepted = method_keywords(method)
    unknown = [] if accepted is None else sorted(set(options) - accepted)
    if unknown:
        takes = ", ".join(sorted(accepted)) or "none"
        raise UnknownOptionError(f"visibility method {method!r} takes no keyword {', '.join(map(repr, unknown))} (it takes: {takes})")


def visible_mask(
    mesh: trimesh.Trimesh,
    points: NDArray[np.floating],
    camera: Camera,
    method: str = DEFAULT_METHOD,
    *,
    face_index: NDArray[np.integer] | None = None,
    **options,
) -> NDArray[np.bool_]:
    """Which sampled points the camera sees: hidden surface removal (HSR) for one pose.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The occluding surface, world frame (normally from :func:`zbuf_occlude.load_mesh`).
    points : (N, 3) float
        Points on the surface, world frame.
    camera : Camera
        The pose and intrinsics; points outside its frustum are not visible.
    method : str
        One of :func:`available_methods`: ``"auto"`` (default: ``"zbuffer-exact"`` or
        ``"embree-fast"``, whichever is faster on this machine; on a software renderer
        ``"embree-fast"``), ``"zbuffer-exact"`` (GPU, complete candidate set from screen tiles;
        exact: bit-identical to the oracle on every view measured), ``"embree-fast"`` (threaded
        float32 Embree, float64 near-ties; near-exact: it agreed with the oracle on 99.9992 % of
        points on average and 99.9944 % on the worst mesh, 31 meshes × 25 poses, see
        docs/results/visibility.md; for exact answers use ``"zbuffer-exact"`` or ``"oracle"``),
        ``"zbuffer"`` (GPU, candidates from a triangle-id buffer, CPU fallback), ``"zbuffer-tolerance"`` (depth test with a slope-scaled
        tolerance), ``"oracle"`` (exact, Embree), ``"oracle-numpy"`` (exact, the paper's
        Eq. 1-10), and the paper's object-space methods.
    face_index : (N,) int, optional
        The face each point was sampled on (from :func:`zbuf_occlude.sample_surface`).
        A face never hides its own points; giving it makes methods faster and exact
        at grazing angles.
    **options
        Method-specific keywords (``resolution``, ``tolerance``, ...), see each method
        (:func:`method_keywords`).

    Returns
    -------
    visible : (N,) bool

    Raises
    ------
    InvalidInputError
        Unknown method, or bad ``points``/``face_index``.
    UnknownOptionError
        (a ``TypeError``) A keyword the method does not take (named).
    BackendUnavailable
        The method needs OpenGL or Embree and it cannot be had.
    """
    fn = get_method(method)
    check_keywords(method, options)
    check_mesh(mesh)
    check_camera(camera)
    pts = check_points(points)
    fi = check_face_index(face_index, len(pts), len(mesh.faces))
    warn_camera_placement(camera, mesh)
    return fn(mesh, pts, camera, face_index=fi, **options)
