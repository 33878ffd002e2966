"""learn/reproducible.py: a training run gives the same weights, to the bit, whichever kernels the CPU would pick.

Another CPU is stood in for by the variables through which the libraries would pick their kernels
on it (ATen's capability, oneDNN's ISA, MKL's code branch): a child process trains a small PointNet
(matrix products: MKL; batch norm: ATen) and a small VoxNet (3-D convolutions: oneDNN) for a few
steps and prints a hash of the weights.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

pytest.importorskip("torch")

from zbuf_occlude.learn import reproducible  # noqa: E402

CHILD = r"""
import hashlib, json, sys
from zbuf_occlude.learn.reproducible import arithmetic_record, pin_cpu_arithmetic, training_threads
if sys.argv[1] == "pinned":
    pin_cpu_arithmetic()
import numpy as np
import torch
from zbuf_occlude.learn.data import CloudSet
from zbuf_occlude.learn.training import TrainConfig, train

rng = np.random.default_rng(0)
n = 16
points = rng.standard_normal((n, 48, 3)).astype(np.float32)
cloud_set = CloudSet(points, (np.arange(n) % 3).astype(np.int64), np.zeros(n), np.arange(n))
digest = hashlib.sha256()
threads = training_threads(None) if sys.argv[1] == "pinned" else 1
for model in ("pointnet", "voxnet"):
    config = TrainConfig(model=model, epochs=1, batch_size=8, width=0.125, patience=0, threads=threads)
    for key, value in sorted(train(cloud_set, 3, config, progress=False).model.state_dict().items()):
        digest.update(key.encode() + value.detach().contiguous().numpy().tobytes())
print(json.dumps({"hash": digest.hexdigest(), **arithmetic_record()}))
"""

#: What the libraries would pick on other CPUs: an older one (SSE4.1, no AVX2) and an AVX-512 one.
OLDER_CPU = {"ATEN_CPU_CAPABILITY": "default", "ONEDNN_MAX_CPU_ISA": "SSE41", "MKL_CBWR": "SSE4_2"}
AVX2_CPU = {"ATEN_CPU_CAPABILITY": "avx2", "ONEDNN_MAX_CPU_ISA": "AVX2", "MKL_CBWR": "AVX2"}
AVX512_CPU = {"ATEN_CPU_CAPABILITY": "avx512", "ONEDNN_MAX_CPU_ISA": "AVX512_CORE", "MKL_CBWR": "AVX512"}


def _cpu_flags() -> set[str]:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return set()
    return {flag for line in text.splitlines() if line.startswith("flags") for flag in line.split(":", 1)[1].split()}


def _train(mode: str, environ: dict[str, str]) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in reproducible.PINNED_ENVIRON and k != reproducible.NATIVE_ENV}
    out = subprocess.run([sys.executable, "-c", CHILD, mode], env={**env, **environ}, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def cpus() -> list[dict[str, str]]:
    """An older CPU's choice, an AVX2 CPU's and, where this CPU has AVX-512 (the subsets ATen's
    kernels use), an AVX-512 CPU's: each named, so that they differ on any CPU (this one's own
    choice is one of them)."""
    flags = _cpu_flags()
    if not {"avx2", "fma"} <= flags:
        pytest.skip("this CPU lacks AVX2 or FMA: the pinned kernels are AVX2 ones (x86-64-v3)")
    return [OLDER_CPU, AVX2_CPU] + ([AVX512_CPU] if {"avx512f", "avx512bw", "avx512vl", "avx512dq"} <= flags else [])


@pytest.mark.slow
def test_pinned_training_gives_the_same_weights_whichever_kernels_the_cpu_would_pick(cpus):
    with ThreadPoolExecutor(2) as pool:
        native = list(pool.map(lambda environ: _train("native", environ), cpus))
        pinned = list(pool.map(lambda environ: _train("pinned", environ), cpus))
    # the stand-ins do pick other kernels, and the weights differ without the pin (the test can fail)
    assert len({r["cpu_capability"] for r in native}) == len(cpus)
    assert len({r["hash"] for r in native}) > 1
    # with the pin: one capability, one thread, the same bits
    assert {r["cpu_capability"] for r in pinned} == {"AVX2"}
    assert {r["threads"] for r in pinned} == {reproducible.REPRODUCIBLE_THREADS}
    assert all(r["pinned"] for r in pinned) and not any(r["pinned"] for r in native)
    assert len({r["hash"] for r in pinned}) == 1


def test_the_native_variable_leaves_the_libraries_their_choice(monkeypatch):
    monkeypatch.setattr(reproducible, "_pinned", None)
    monkeypatch.setenv(reproducible.NATIVE_ENV, "1")
    for key in reproducible.PINNED_ENVIRON:
        monkeypatch.delenv(key, raising=False)
    assert reproducible.pin_cpu_arithmetic() is False
    assert not any(key in os.environ for key in reproducible.PINNED_ENVIRON)
    assert reproducible.training_threads(None) is None
    assert reproducible.training_threads(3) == 3


def test_pinning_after_torch_is_imported_is_refused_and_recorded(monkeypatch, caplog):
    import torch  # noqa: F401  (the situation under test)

    monkeypatch.setattr(reproducible, "_pinned", None)
    monkeypatch.delenv(reproducible.NATIVE_ENV, raising=False)
    for key in reproducible.PINNED_ENVIRON:
        monkeypatch.delenv(key, raising=False)
    assert reproducible.pin_cpu_arithmetic() is False
    assert "imported before" in caplog.text
    assert not any(key in os.environ for key in reproducible.PINNED_ENVIRON)  # nothing claimed that did not happen
    assert reproducible.arithmetic_record()["pinned"] is False


@pytest.mark.parametrize("value, native", [("1", True), ("yes", True), ("0", False), ("", False), ("false", False)])
def test_native_cpu_reads_the_variable(monkeypatch, value, native):
    monkeypatch.setenv(reproducible.NATIVE_ENV, value)
    assert reproducible.native_cpu() is native


@pytest.mark.slow
def test_training_commands_pin_before_torch_is_imported(tmp_path):
    """The CLI's training commands pin first: a run that stops early (no mesh tree) has already done it."""
    code = (
        "import sys\nfrom zbuf_occlude.cli.main import main\n"
        f"status = main(['experiment', '{{}}', {str(tmp_path / 'none')!r}, '--out', {str(tmp_path / 'out')!r}, {{}}])\n"
        "import torch\nfrom zbuf_occlude.learn.reproducible import arithmetic_record\n"
        "r = arithmetic_record(); print(status, r['pinned'], r['cpu_capability'], r['MKL_CBWR'])\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in reproducible.PINNED_ENVIRON and k != reproducible.NATIVE_ENV}
    env["ATEN_CPU_CAPABILITY"] = "default"  # what another CPU would pick: the pin overrides it
    for command, extra in (("elevation", ""), ("sim2real", f"'--real', {str(tmp_path / 'none')!r}, '--model', 'pointnet'")):
        out = subprocess.run([sys.executable, "-c", code.format(command, extra)], env=env, capture_output=True, text=True, timeout=120)
        status, pinned, capability, cbwr = out.stdout.split()[-4:]
        if {"avx2", "fma"} <= _cpu_flags():
            assert status != "0" and pinned == "True" and cbwr == "COMPATIBLE", out.stdout + out.stderr[-2000:]
            assert capability == "AVX2"
        else:  # AVX2 kernels would crash here: left to the libraries, and recorded so
            assert status != "0" and pinned == "False", out.stdout + out.stderr[-2000:]
