"""The one place that creates OpenGL contexts: headless EGL, then OSMesa as a fallback.

Pattern of ``pyrender/platforms``: platform quirks live here and nowhere else.
Visibility needs OpenGL 4.3 (compute shaders, shader storage buffers).

The backend order can be forced with the environment variable ``ZBUF_OCCLUDE_GL``
(``egl``, ``osmesa``, or a comma-separated order such as ``osmesa,egl``).

Mesa loads its llvmpipe driver and the ``libLLVM`` it links into the global symbol scope;
:mod:`zbuf_occlude._llvm` (installed by ``import zbuf_occlude``) keeps Triton's own LLVM from
binding to it, for our contexts and every other (pyrender's, a user's own).

Under an address-space limit (``ulimit -v``, ``prlimit --as``, a batch scheduler's), llvmpipe's
threads are bounded (:func:`bound_llvmpipe_threads`): Mesa starts two a core by default, and each
maps about 72 MiB (an 8 MiB stack and a 64 MiB malloc arena), so on 16 cores a context alone would
take 2.3 GiB of a limit that holds the job comfortably on 2.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import os
import threading

import moderngl
import numpy as np

from zbuf_occlude.errors import BackendUnavailable, InvalidInputError

__all__ = [
    "bound_llvmpipe_threads",
    "create_context",
    "shared_context",
    "context_info",
    "max_image_size",
    "check_image_size",
    "GL_BACKENDS",
    "REQUIRED_GL_VERSION",
    "SOFTWARE_RENDERERS",
    "is_software_renderer",
]

log = logging.getLogger(__name__)

#: OpenGL version the shaders need (430: compute shaders and SSBOs).
REQUIRED_GL_VERSION = 430
#: Backends tried in order when none is named.
GL_BACKENDS = ("egl", "osmesa")
#: Substrings of ``GL_RENDERER`` (lower case) naming a rasteriser that runs on the CPU.
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "swiftshader", "lavapipe", "software")

_INSTALL_HINT = (
    "install Mesa's EGL and llvmpipe driver (Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri), "
    "or OSMesa (apt-get install libosmesa6), or an NVIDIA driver with EGL"
)


class _OSMesaLoader:
    """A moderngl loader over an OSMesa core-profile context (software, no display).

    ``moderngl.init_context(loader=...)`` asks the loader for GL function pointers;
    OSMesa renders into a client-memory buffer, which we never read (we render into FBOs).
    """

    # From GL/osmesa.h
    _OSMESA_FORMAT, _OSMESA_RGBA = 0x22, 0x1908
    _OSMESA_DEPTH_BITS, _OSMESA_STENCIL_BITS, _OSMESA_ACCUM_BITS = 0x30, 0x31, 0x32
    _OSMESA_PROFILE, _OSMESA_CORE_PROFILE = 0x33, 0x34
    _OSMESA_CONTEXT_MAJOR_VERSION, _OSMESA_CONTEXT_MINOR_VERSION = 0x36, 0x37
    _GL_UNSIGNED_BYTE = 0x1401
    _BUFFER_SIDE = 16  # pixels; the default framebuffer is unused

    def __init__(self) -> None:
        name = ctypes.util.find_library("OSMesa")
        if name is None:
            raise BackendUnavailable(f"OSMesa library not found; {_INSTALL_HINT}")
        lib = ctypes.CDLL(name)
        lib.OSMesaCreateContextAttribs.restype = ctypes.c_void_p
        lib.OSMesaCreateContextAttribs.argtypes = [ctypes.POINTER(ctypes.c_int), ctypes.c_void_p]
        lib.OSMesaMakeCurrent.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_int]
        lib.OSMesaGetProcAddress.restype = ctypes.c_void_p
        lib.OSMesaGetProcAddress.argtypes = [ctypes.c_char_p]
        lib.OSMesaDestroyContext.argtypes = [ctypes.c_void_p]
        attribs = [
            self._OSMESA_FORMAT, self._OSMESA_RGBA,
            self._OSMESA_DEPTH_BITS, 24,
            self._OSMESA_STENCIL_BITS, 0,
            self._OSMESA_ACCUM_BITS, 0,
            self._OSMESA_PROFILE, self._OSMESA_CORE_PROFILE,
            self._OSMESA_CONTEXT_MAJOR_VERSION, REQUIRED_GL_VERSION // 100,
            self._OSMESA_CONTEXT_MINOR_VERSION, (REQUIRED_GL_VERSION // 10) % 10,
            0,
        ]  # fmt: skip
        arr = (ctypes.c_int * len(attribs))(*attribs)
        self._lib = lib
        self._ctx = lib.OSMesaCreateContextAttribs(arr, None)
        if not self._ctx:
            raise BackendUnavailable(f"OSMesa could not create an OpenGL {REQUIRED_GL_VERSION / 100:.1f} core context")
        self._buffer = (ctypes.c_ubyte * (4 * self._BUFFER_SIDE * self._BUFFER_SIDE))()
        self.make_current()

    def make_current(self) -> None:
        side = self._BUFFER_SIDE
        if not self._lib.OSMesaMakeCurrent(self._ctx, self._buffer, self._GL_UNSIGNED_BYTE, side, side):
            raise BackendUnavailable("OSMesaMakeCurrent failed")

    def load_opengl_function(self, name: str) -> int:
        return self._lib.OSMesaGetProcAddress(name.encode()) or 0

    def load(self, name: str) -> int:  # older moderngl loader protocol
        return self.load_opengl_function(name)

    def release(self) -> None:
        if self._ctx:
            self._lib.OSMesaDestroyContext(self._ctx)
            self._ctx = None

    def __enter__(self):
        self.make_current()
        return self

    def __exit__(self, *exc) -> None:
        pass


def _create_egl() -> moderngl.Context:
    return moderngl.create_standalone_context(backend="egl", require=REQUIRED_GL_VERSION)


def _create_osmesa() -> moderngl.Context:
    loader = _OSMesaLoader()
    moderngl.init_context(loader=loader)
    ctx = moderngl.get_context()
    # init_context registers the context as moderngl's process-wide default; detach it so
    # later moderngl.create_context() calls by user code do not silently reuse ours.
    moderngl._store.default_context = None
    ctx.extra = {"osmesa_loader": loader}
    if ctx.version_code < REQUIRED_GL_VERSION:
        raise BackendUnavailable(f"OSMesa gave OpenGL {ctx.version_code}, need {REQUIRED_GL_VERSION}")
    return ctx


_FACTORIES = {"egl": _create_egl, "osmesa": _create_osmesa}


def _backend_order(backend: str | None) -> list[str]:
    spec = backend or os.environ.get("ZBUF_OCCLUDE_GL") or ",".join(GL_BACKENDS)
    order = [b.strip().lower() for b in spec.split(",") if b.strip()]
    unknown = [b for b in order if b not in _FACTORIES]
    if unknown or not order:
        raise BackendUnavailable(f"unknown OpenGL backend {spec!r}; choose from {', '.join(GL_BACKENDS)}")
    return order


#: llvmpipe threads a context starts under an address-space limit unless ``LP_NUM_THREADS`` is set: a
#: farm already runs a process per core, and each thread maps about 72 MiB of the limit.
LIMITED_LLVMPIPE_THREADS = 2


def bound_llvmpipe_threads() -> None:
    """Set ``LP_NUM_THREADS`` to at most :data:`LIMITED_LLVMPIPE_THREADS` when this process has an
    address-space limit (``RLIMIT_AS``) and the user set no value; otherwise change nothing.

    Mesa reads the variable when a context's screen is made, so this runs before each context.
    """
    import resource

    if "LP_NUM_THREADS" in os.environ or resource.getrlimit(resource.RLIMIT_AS)[0] == resource.RLIM_INFINITY:
        return
    os.environ["LP_NUM_THREADS"] = str(min(os.cpu_count() or 1, LIMITED_LLVMPIPE_THREADS))
    log.debug("address-space limit: llvmpipe keeps to %s threads (LP_NUM_THREADS)", os.environ["LP_NUM_THREADS"])


def create_context(backend: str | None = None) -> moderngl.Context:
    """A new headless moderngl context with OpenGL ≥ 4.3 core.

    Parameters
    ----------
    backend : str, optional
        ``"egl"``, ``"osmesa"`` or a comma-separated order.  Default: ``$ZBUF_OCCLUDE_GL``,
        else EGL (Mesa llvmpipe, or the NVIDIA driver where present), then OSMesa.

    Raises
    ------
    BackendUnavailable
        No backend gives an OpenGL 4.3 context; the message lists each backend's failure
        and what to install.
    """
    bound_llvmpipe_threads()
    failures = []
    order = _backend_order(backend)
    for name in order:
        try:
            ctx = _FACTORIES[name]()
        except BackendUnavailable as exc:
            failures.append(f"{name}: {exc}")
            continue
        except Exception as exc:  # moderngl/glcontext raise bare Exception and ValueError
            failures.append(f"{name}: {type(exc).__name__}: {exc}")
            continue
        log.debug("OpenGL context via %s: %s", name, ctx.info["GL_RENDERER"])
        ctx.extra = {**(ctx.extra or {}), "backend": name}
        return ctx
    raise BackendUnavailable("no headless OpenGL 4.3 context could be created (" + "; ".join(failures) + f"); {_INSTALL_HINT}")


_shared: dict[tuple[int, str | None], moderngl.Context] = {}
_shared_lock = threading.Lock()


def shared_context(backend: str | None = None) -> moderngl.Context:
    """The process's cached context (one per process and backend choice).

    Keyed on the process id, so a forked worker never touches its parent's context: it
    makes its own on first use.
    """
    key = (os.getpid(), backend)
    with _shared_lock:
        ctx = _shared.get(key)
        if ctx is None:
            for stale in [k for k in _shared if k[0] != key[0]]:
                del _shared[stale]  # inherited across fork: unusable, never released here
            ctx = _shared[key] = create_context(backend)
        return ctx


def is_software_renderer(renderer: str) -> bool:
    """True when ``renderer`` (a ``GL_RENDERER`` string) names a rasteriser that runs on the CPU
    (Mesa llvmpipe and the like, :data:`SOFTWARE_RENDERERS`): there a shader invocation costs
    CPU time, and work is shaped for few cores, not a GPU."""
    return any(s in renderer.lower() for s in SOFTWARE_RENDERERS)


def context_info(ctx: moderngl.Context | None = None) -> dict[str, str]:
    """GL vendor, renderer, version and backend of ``ctx`` (default: the shared context)."""
    ctx = ctx or shared_context()
    return {
        "backend": (ctx.extra or {}).get("backend", "unknown"),
        "vendor": ctx.info["GL_VENDOR"],
        "renderer": ctx.info["GL_RENDERER"],
        "version": ctx.info["GL_VERSION"],
    }


#: The GL limits that bound a render target's width and height (it is a texture, drawn
#: through a viewport; some drivers also cap renderbuffers lower).
_IMAGE_SIZE_LIMITS = ("GL_MAX_TEXTURE_SIZE", "GL_MAX_RENDERBUFFER_SIZE", "GL_MAX_VIEWPORT_DIMS")


def max_image_size(ctx: moderngl.Context | None = None) -> int:
    """Largest width and height, in pixels, of an image this context can render.

    The smallest of ``GL_MAX_TEXTURE_SIZE``, ``GL_MAX_RENDERBUFFER_SIZE`` and
    ``GL_MAX_VIEWPORT_DIMS`` (16384 on Mesa llvmpipe; 32768 on recent NVIDIA drivers).

    Parameters
    ----------
    ctx : moderngl.Context, optional
        Default: the shared context (:func:`shared_context`), created if needed.

    Raises
    ------
    BackendUnavailable
        No OpenGL context can be created.
    """
    ctx = ctx or shared_context()
    sizes = []
    for name in _IMAGE_SIZE_LIMITS:
        value = ctx.info[name]
        sizes.extend(value if isinstance(value, tuple) else (value,))
    return int(min(sizes))


def check_image_size(
    resolution: int | tuple[int, int], *, ctx: moderngl.Context | None = None, name: str = "resolution"
) -> tuple[int, int]:
    """Validate an image size against the GL's limits, before any allocation.

    Without this check a too-large size fails inside moderngl with "framebuffer is not
    complete".  Call it up front with ``name="--resolution"`` to name the option.

    Parameters
    ----------
    resolution : int or (width, height)
        Pixels.
    ctx : moderngl.Context, optional
        Default: the shared context.
    name : str
        The argument or option named in the message.

    Returns
    -------
    size : (width, height) int

    Raises
    ------
    InvalidInputError
        Not positive integers, or larger than :func:`max_image_size` (the message gives
        the maximum and the renderer).
    BackendUnavailable
        No OpenGL context can be created.
    """
    if isinstance(resolution, (int, np.integer)):
        size: tuple = (resolution, resolution)
    else:
        try:
            size = tuple(resolution)
        except TypeError:
            size = ()
    if len(size) != 2 or any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1 for v in size):
        raise InvalidInputError(f"{name} must be a positive number of pixels (or width, height), got {resolution!r}")
    ctx = ctx or shared_context()
    limit = max_image_size(ctx)
    if max(size) > limit:
        raise InvalidInputError(
            f"{name} {resolution!r} is larger than this OpenGL's maximum image size of {limit} pixels "
            f"({ctx.info['GL_RENDERER']}: min of {', '.join(_IMAGE_SIZE_LIMITS)}); use {name} <= {limit}"
        )
    return int(size[0]), int(size[1])
