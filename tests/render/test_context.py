"""OpenGL context creation (zbuf_occlude.render.context): backend order, ``ZBUF_OCCLUDE_GL``,
and the automatic EGL → OSMesa fallback.

The order and fallback logic is tested in-process with fake backends; the real fallback
runs in a subprocess whose EGL library is made unloadable, so that no GL state leaks into
other tests.  Where OSMesa is not installed the subprocess must fail with an error naming
both backends, so these tests never skip.
"""

from __future__ import annotations

import ctypes.util
import json
import os
import subprocess
import sys
from types import SimpleNamespace

import pytest

from zbuf_occlude.errors import BackendUnavailable
from zbuf_occlude.render import context


class FakeBackends:
    """Stand-ins for the EGL and OSMesa factories: each call is logged; ``broken`` ones raise."""

    def __init__(self, monkeypatch, broken=(), error=BackendUnavailable):
        self.calls: list[str] = []
        for name in context.GL_BACKENDS:
            monkeypatch.setitem(context._FACTORIES, name, self._factory(name, name in broken, error))
        monkeypatch.setattr(context, "_shared", {})

    def _factory(self, name, broken, error):
        def make():
            self.calls.append(name)
            if broken:
                raise error(f"{name} is broken here")
            return SimpleNamespace(info={"GL_RENDERER": f"fake {name}"}, extra=None)

        return make


def test_default_order_is_egl_then_osmesa(monkeypatch):
    monkeypatch.delenv("ZBUF_OCCLUDE_GL", raising=False)
    fake = FakeBackends(monkeypatch)
    assert context.create_context().extra["backend"] == "egl"
    assert fake.calls == ["egl"]  # OSMesa is not even tried when EGL works


@pytest.mark.parametrize("error", [BackendUnavailable, ValueError, Exception])
def test_a_failing_egl_falls_back_to_osmesa(monkeypatch, error):
    """moderngl/glcontext raise bare Exception or ValueError; ours raise BackendUnavailable."""
    monkeypatch.delenv("ZBUF_OCCLUDE_GL", raising=False)
    fake = FakeBackends(monkeypatch, broken={"egl"}, error=error)
    assert context.create_context().extra["backend"] == "osmesa"
    assert fake.calls == ["egl", "osmesa"]


def test_when_every_backend_fails_the_error_lists_each_and_what_to_install(monkeypatch):
    monkeypatch.delenv("ZBUF_OCCLUDE_GL", raising=False)
    FakeBackends(monkeypatch, broken={"egl", "osmesa"})
    with pytest.raises(BackendUnavailable) as info:
        context.create_context()
    msg = str(info.value)
    assert "egl: egl is broken here" in msg and "osmesa: osmesa is broken here" in msg and "apt-get install" in msg


@pytest.mark.parametrize(
    ("env", "expected_calls", "backend"),
    [("osmesa", ["osmesa"], "osmesa"), ("OSMesa, egl", ["osmesa"], "osmesa"), ("egl", ["egl"], "egl")],
)
def test_zbuf_occlude_gl_sets_the_order(monkeypatch, env, expected_calls, backend):
    monkeypatch.setenv("ZBUF_OCCLUDE_GL", env)
    fake = FakeBackends(monkeypatch)
    assert context.create_context().extra["backend"] == backend
    assert fake.calls == expected_calls


def test_zbuf_occlude_gl_egl_alone_does_not_fall_back(monkeypatch):
    monkeypatch.setenv("ZBUF_OCCLUDE_GL", "egl")
    fake = FakeBackends(monkeypatch, broken={"egl"})
    with pytest.raises(BackendUnavailable, match="egl is broken"):
        context.create_context()
    assert fake.calls == ["egl"]


def test_an_explicit_backend_overrides_the_environment(monkeypatch):
    monkeypatch.setenv("ZBUF_OCCLUDE_GL", "egl")
    fake = FakeBackends(monkeypatch)
    assert context.create_context("osmesa").extra["backend"] == "osmesa"
    assert fake.calls == ["osmesa"]


@pytest.mark.parametrize("spec", ["vulkan", "egl,vulkan", ",", " "])
def test_unknown_backends_in_the_environment_are_refused(monkeypatch, spec):
    monkeypatch.setenv("ZBUF_OCCLUDE_GL", spec)
    fake = FakeBackends(monkeypatch)
    with pytest.raises(BackendUnavailable, match="unknown OpenGL backend"):
        context.create_context()
    assert fake.calls == []  # refused before any backend is tried


def test_an_empty_zbuf_occlude_gl_means_the_default_order(monkeypatch):
    monkeypatch.setenv("ZBUF_OCCLUDE_GL", "")
    fake = FakeBackends(monkeypatch, broken={"egl"})
    assert context.create_context().extra["backend"] == "osmesa"
    assert fake.calls == ["egl", "osmesa"]


def test_shared_context_is_one_per_process_and_backend_choice(monkeypatch):
    monkeypatch.delenv("ZBUF_OCCLUDE_GL", raising=False)
    fake = FakeBackends(monkeypatch)
    first = context.shared_context()
    assert context.shared_context() is first
    other = context.shared_context("osmesa")
    assert other is not first and context.shared_context("osmesa") is other
    assert fake.calls == ["egl", "osmesa"]
    # a context inherited from another process (fork) is not reused
    context._shared[(os.getpid() + 1, None)] = context._shared.pop((os.getpid(), None))
    assert context.shared_context() is not first and (os.getpid() + 1, None) not in context._shared


# -- the real thing, in a subprocess --------------------------------------------------------
_PROBE = """
import json
from zbuf_occlude.errors import BackendUnavailable
from zbuf_occlude.render.context import context_info, create_context
try:
    info = context_info(create_context())
    ctx_ok = True
except BackendUnavailable as exc:
    info, ctx_ok = {"error": str(exc)}, False
print(json.dumps({"ok": ctx_ok, **info}))
"""
HAVE_OSMESA = ctypes.util.find_library("OSMesa") is not None
# glcontext loads EGL from this path when set; a missing file makes EGL fail to load
NO_EGL = {"GLCONTEXT_LINUX_LIBEGL": "/nonexistent/libEGL.so"}


def _probe(**env) -> dict:
    full = {k: v for k, v in os.environ.items() if k != "ZBUF_OCCLUDE_GL"}
    full.update(env)
    out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, env=full, timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_without_egl_the_default_falls_back_to_osmesa_for_real():
    got = _probe(**NO_EGL)
    if HAVE_OSMESA:
        assert got["ok"] and got["backend"] == "osmesa", got
        assert "4." in got["version"]  # an OpenGL 4.x core context
    else:
        assert not got["ok"] and "egl:" in got["error"] and "osmesa:" in got["error"], got


@pytest.mark.slow
def test_zbuf_occlude_gl_picks_the_backend_for_real():
    got = _probe(ZBUF_OCCLUDE_GL="osmesa")
    if HAVE_OSMESA:
        assert got["ok"] and got["backend"] == "osmesa", got
    else:
        assert not got["ok"] and "osmesa:" in got["error"] and "egl:" not in got["error"], got
    # forcing EGL where it cannot load: an error, no silent fallback
    got = _probe(ZBUF_OCCLUDE_GL="egl", **NO_EGL)
    assert not got["ok"] and "egl:" in got["error"] and "osmesa:" not in got["error"], got


@pytest.mark.parametrize(
    "limit, cpus, given, expected",
    [(4 << 30, 16, None, "2"), (4 << 30, 1, None, "1"), (None, 16, None, None), (4 << 30, 16, "8", "8")],
    ids=["limited-16-cores", "limited-1-core", "unlimited", "user-value-kept"],
)
def test_llvmpipe_threads_are_bounded_only_under_an_address_space_limit(monkeypatch, limit, cpus, given, expected) -> None:
    """Mesa starts two llvmpipe threads a core, ~72 MiB of address space each: on 16 cores a context
    took 2.3 GiB of a `prlimit --as` limit that holds the whole job on 2 cores."""
    import resource

    from zbuf_occlude.render import context

    monkeypatch.setenv("LP_NUM_THREADS", "0")  # records the variable's state, so that what the call sets is undone
    monkeypatch.delenv("LP_NUM_THREADS")
    if given is not None:
        monkeypatch.setenv("LP_NUM_THREADS", given)
    soft = resource.RLIM_INFINITY if limit is None else limit
    monkeypatch.setattr(resource, "getrlimit", lambda which: (soft, resource.RLIM_INFINITY))
    monkeypatch.setattr(context.os, "cpu_count", lambda: cpus)
    context.bound_llvmpipe_threads()
    assert context.os.environ.get("LP_NUM_THREADS") == expected
