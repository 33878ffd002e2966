"""The first-run line asks numba's cache only for kernels an ordinary command compiles (zbuf_occlude.cli.first_run.kernels_cold)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from zbuf_occlude.cli import first_run
from zbuf_occlude.visibility import warmup

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
COLD = "from zbuf_occlude.cli.first_run import kernels_cold; print(kernels_cold())"


def test_the_kernels_asked_for_are_the_default_methods_that_the_warm_up_compiles() -> None:
    asked = warmup.default_method_kernels()
    assert asked and set(asked) <= set(warmup.kernels())  # python -m zbuf_occlude.visibility.warmup compiles each
    assert {name.split(".")[0] for name in asked} == set(warmup.DEFAULT_METHOD_MODULES)
    # none is compiled only inside another kernel (such a one has no cache entry of its own)
    assert all(k.targetoptions.get("inline") != "always" for k in asked.values())
    from zbuf_occlude.visibility import embree_fast

    inlined = [name for name, value in vars(embree_fast).items() if getattr(value, "targetoptions", {}).get("inline") == "always"]
    assert inlined and not any(name.endswith(f".{n}") for n in inlined for name in asked)


def test_one_kernel_in_the_cache_is_enough(monkeypatch) -> None:
    """A view compiles the kernels its mesh and pose need: any one cached means a command ran with this cache."""
    paths = [k._cache._cache_file._index_path for k in warmup.default_method_kernels().values()]
    monkeypatch.setattr(first_run.os.path, "isfile", lambda path: path == paths[-1])
    assert first_run.kernels_cold() is False
    monkeypatch.setattr(first_run.os.path, "isfile", lambda path: False)
    assert first_run.kernels_cold() is True


@pytest.mark.slow
def test_after_one_ordinary_farm_the_kernels_are_no_longer_cold(tmp_path: Path) -> None:
    """A farm of one shipped mesh, two views, in a fresh numba cache; then a new process finds the kernels warm."""
    cache = tmp_path / "numba"
    cache.mkdir()
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env.pop("ZBUF_OCCLUDE_AUTO", None)

    def cold() -> str:
        run = subprocess.run([sys.executable, "-c", COLD], env=env, capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr
        return run.stdout.strip()

    assert cold() == "True"
    farm = [sys.executable, "-m", "zbuf_occlude", "farm", str(SAMPLES), "--out", str(tmp_path / "farm"), "--classes", "chair",
            "--per-class", "1", "--splits", "train", "--views", "fibonacci:2", "--samples-per-view", "1", "--points", "256",
            "--workers", "1", "--no-progress"]  # fmt: skip
    run = subprocess.run(farm, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert cold() == "False"
