"""zbuf_occlude.visibility.warmup: every numba kernel is cached on disk and compiled by the warm-up,
so that the first mesh after an install loads them instead of compiling them."""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import zbuf_occlude
from zbuf_occlude.visibility import warmup

PACKAGE = Path(zbuf_occlude.__file__).parent


def _njit_calls() -> list[tuple[Path, int, ast.Call]]:
    """``(file, line, call)`` of every ``numba.njit(...)`` / ``numba.jit(...)`` / ``njit(...)`` in the package."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call):
                name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
                if name in ("njit", "jit"):
                    found.append((path, node.lineno, node))
    return found


def test_every_numba_kernel_is_cached_on_disk():
    calls = _njit_calls()
    assert calls, "no numba kernel found: the scan is broken"
    uncached = [
        f"{path.relative_to(PACKAGE.parent)}:{line}" for path, line, call in calls
        if not any(k.arg == "cache" and isinstance(k.value, ast.Constant) and k.value.value is True for k in call.keywords)
    ]  # fmt: skip
    assert not uncached, f"give these kernels cache=True (the warm-up at install relies on it): {uncached}"


def _is_kernel(node: ast.AST) -> bool:
    """A ``numba.njit(...)`` call that is not inlined into other kernels (``inline="always"``)."""
    return (
        isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in ("njit", "jit")
        and not any(k.arg == "inline" and getattr(k.value, "value", None) == "always" for k in node.keywords)
    )  # fmt: skip


def _module_level_kernels(package: str = "visibility") -> set[str]:
    """``module.name`` (below zbuf_occlude.<package>) of every kernel made at a module's top level:
    ``name = numba.njit(...)(function)`` or a function decorated ``@numba.njit(...)``."""
    names = set()
    for path in sorted((PACKAGE / package).rglob("*.py")):
        module = ".".join(path.relative_to(PACKAGE / package).with_suffix("").parts)
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call) and _is_kernel(node.value.func):
                names |= {f"{module}.{t.id}" for t in node.targets if isinstance(t, ast.Name)}
            elif isinstance(node, ast.FunctionDef) and any(_is_kernel(d) for d in node.decorator_list):
                names.add(f"{module}.{node.name}")
    return names


def test_the_warm_ups_list_every_kernel_of_the_package():
    # a kernel outside zbuf_occlude.visibility and zbuf_occlude.sensors would be missed by the two warm-ups: there are none
    from zbuf_occlude.sensors import warmup as sensors_warmup

    assert all(path.is_relative_to(PACKAGE / "visibility") or path.is_relative_to(PACKAGE / "sensors") for path, _, _ in _njit_calls())
    expected = _module_level_kernels()
    assert expected and set(warmup.kernels()) == expected
    expected = _module_level_kernels("sensors")
    assert expected and set(sensors_warmup.kernels()) == expected


def _warm_up_in_child(cache: Path, package: str = "visibility") -> list[dict]:
    """:func:`warmup.warm_up` (or ``zbuf_occlude.<package>.warmup``'s) in a new process whose numba cache is ``cache``: its reports."""
    code = (f"import dataclasses, json; from zbuf_occlude.{package}.warmup import warm_up; "
            "print(json.dumps([dataclasses.asdict(r) for r in warm_up()]))")  # fmt: skip
    r = subprocess.run([sys.executable, "-c", code], env={**os.environ, "NUMBA_CACHE_DIR": str(cache)}, capture_output=True,
                       text=True, timeout=600)  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout)


@pytest.mark.slow
def test_the_warm_up_compiles_every_kernel_and_a_second_process_only_loads_them(tmp_path):
    cold = _warm_up_in_child(tmp_path / "numba")  # an empty cache: every kernel reached is compiled
    assert {r["name"] for r in cold} == set(warmup.kernels())
    assert [r["name"] for r in cold if not r["signatures"] or not r["compiled"]] == []  # none left to the first mesh
    warm = _warm_up_in_child(tmp_path / "numba")
    assert sum(r["compiled"] for r in warm) == 0 and sum(r["loaded"] for r in warm) > 0, warm


def test_the_sensors_warm_up_compiles_their_kernels_and_a_second_process_only_loads_them(tmp_path):
    from zbuf_occlude.sensors import warmup as sensors_warmup

    cold = _warm_up_in_child(tmp_path / "numba", "sensors")
    assert {r["name"] for r in cold} == set(sensors_warmup.kernels())
    assert [r["name"] for r in cold if not r["signatures"] or not r["compiled"]] == []
    warm = _warm_up_in_child(tmp_path / "numba", "sensors")
    assert sum(r["compiled"] for r in warm) == 0 and sum(r["loaded"] for r in warm) > 0, warm


def test_the_command_refuses_an_unknown_option(caplog):
    from zbuf_occlude.sensors import warmup as sensors_warmup

    assert warmup.main(["--bogus"]) == 2
    assert "python -m zbuf_occlude.visibility.warmup: unknown option(s) --bogus" in caplog.text
    assert sensors_warmup.main(["--bogus"]) == 2
    assert "python -m zbuf_occlude.sensors.warmup: unknown option(s) --bogus" in caplog.text


def test_compiling_the_threaded_kernels_keeps_forked_children_serial():
    # compiling a parallel kernel starts numba's threads: the warm-up notes it, so that a process
    # forked from one that warmed up never runs GNU OpenMP's threads (threads_for yields 1)
    code = (
        "import os, numpy as np\n"
        "from zbuf_occlude.geometry.cameras import camera_on_sphere\n"
        "from zbuf_occlude.visibility import point_kernels as k, warmup\n"
        "from zbuf_occlude.visibility.point_splats import visible_mask_points\n"
        "visible_mask_points(np.random.default_rng(0).normal(size=(300, 3)), camera_on_sphere(0, 0, 4))\n"
        "warmup._compile_threaded()\n"
        "assert k.splat_surfels_threaded.signatures and k.decide_threaded.signatures\n"
        "assert k._threads_pid == [os.getpid()], k._threads_pid\n"
        "print('ok')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]
