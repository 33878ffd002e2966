"""The same trained weights, to the bit, on any x86-64 CPU: the CPU arithmetic of torch pinned.

What differs between CPUs.  A training run with a fixed seed and deterministic algorithms
(:func:`zbuf_occlude.learn.training.seed_everything`) still does its float32 arithmetic in an
order, and with instructions, that the CPU chooses, and float32 sums in another order differ in
the last bits; over thousands of optimiser steps the weights, the validation losses and the
scores move.  Four libraries choose by the CPU they find:

* ATen (torch's own kernels: batch norm, pooling, losses, the optimisers) picks its vectorised
  kernels by instruction set when torch is imported (``ATEN_CPU_CAPABILITY``:
  ``default``, ``avx2`` or ``avx512``);
* oneDNN (``mkldnn``, torch's 3-D convolutions on CPU: VoxNet, 3DmFV-Net) picks its just-in-time
  kernels by instruction set on first use (``ONEDNN_MAX_CPU_ISA``);
* MKL (torch's matrix products on CPU in the x86-64 wheels: PointNet's shared MLP, every
  ``Linear``) picks a code branch per CPU model, vendor included (``MKL_CBWR``, "conditional
  numerical reproducibility"; Intel oneMKL Developer Guide, "Obtaining Numerically Reproducible
  Results"): only its ``COMPATIBLE`` branch is documented to give the same results on Intel and
  on other vendors' processors;
* OpenMP splits reductions by the number of threads (``torch.set_num_threads``).

:func:`pin_cpu_arithmetic` sets the first three (:data:`PINNED_ENVIRON`) before torch is first
imported in the process; the environment variables have no effect once torch is loaded, so the
CLI's training commands call it first thing.  The thread count is fixed by
:func:`training_threads` (:data:`REPRODUCIBLE_THREADS` unless the user gives one).
:func:`arithmetic_record` is what a run's ``run.json`` records of it (``cpu_arithmetic``), so that
two runs can be told comparable or not.

``ZBUF_OCCLUDE_NATIVE_CPU=1`` (:data:`NATIVE_ENV`) leaves the libraries their own choice (the
fastest kernels of this CPU, results that differ between CPUs) and torch's default thread count.

What is not reached: a CPU without AVX2 and FMA runs other kernels (its ``cpu_capability`` is
recorded as ``DEFAULT``); other versions of torch, MKL or numpy; GPUs; other architectures
(aarch64).
"""

from __future__ import annotations

import logging
import os
import platform
import sys

__all__ = [
    "PINNED_ENVIRON", "NATIVE_ENV", "REPRODUCIBLE_THREADS", "pin_cpu_arithmetic", "native_cpu", "training_threads",
    "arithmetic_record",
]  # fmt: skip

log = logging.getLogger(__name__)

#: The environment that pins torch's CPU arithmetic (module docstring), read when torch is imported
#: (ATen) or first used (oneDNN, MKL).  AVX2 and FMA: every x86-64 server and desktop CPU since
#: 2015 has them (x86-64-v3), and its kernels cost little against the AVX-512 ones on these models;
#: MKL's ``COMPATIBLE`` is its only branch documented to agree across CPU vendors.
PINNED_ENVIRON: dict[str, str] = {"ATEN_CPU_CAPABILITY": "avx2", "ONEDNN_MAX_CPU_ISA": "AVX2", "MKL_CBWR": "COMPATIBLE"}
#: Set to 1 to leave the CPU arithmetic to the libraries (faster on some CPUs; results differ between CPUs).
NATIVE_ENV = "ZBUF_OCCLUDE_NATIVE_CPU"
#: torch's CPU threads of a pinned run when the user names none: reductions are split by the thread
#: count, so it must be the same on every machine, and one thread costs least where cores are few.
REPRODUCIBLE_THREADS = 1

# whether this process pinned the environment before torch was imported (None: never asked)
_pinned: bool | None = None


def native_cpu() -> bool:
    """True when the user asked for the libraries' own CPU arithmetic (``ZBUF_OCCLUDE_NATIVE_CPU`` set and not 0/false/no/empty)."""
    return os.environ.get(NATIVE_ENV, "").strip().lower() not in ("", "0", "false", "no")


def pin_cpu_arithmetic() -> bool:
    """Pin torch's CPU arithmetic (:data:`PINNED_ENVIRON`, set over any value there) for this process
    and the processes it starts, before torch is imported.

    Call it before anything imports torch; the training commands of the CLI do.  Does nothing with
    ``ZBUF_OCCLUDE_NATIVE_CPU=1``.

    Returns
    -------
    bool
        True when the arithmetic is pinned (now or by an earlier call); False with
        ``ZBUF_OCCLUDE_NATIVE_CPU=1``, on a CPU that is not an x86-64 one with AVX2 and FMA, or when
        torch was already imported (a warning says so for these two: the variables would crash the
        first, and change nothing in the second; the run is recorded as not pinned).
    """
    global _pinned
    if _pinned:
        return True
    if native_cpu():
        _pinned = False
        return False
    if "torch" in sys.modules:
        log.warning("torch was imported before the CPU arithmetic was pinned: this run's results may differ on another CPU")
        _pinned = False
        return False
    if not _has_avx2():  # ATen takes the variable on trust: AVX2 kernels on a CPU without them would crash
        log.warning("this CPU is not an x86-64 one with AVX2 and FMA: its CPU arithmetic is left to the libraries")
        _pinned = False
        return False
    os.environ.update(PINNED_ENVIRON)
    _pinned = True
    return True


def _has_avx2() -> bool:
    """Whether this is an x86-64 CPU with AVX2 and FMA (:func:`~zbuf_occlude.resources.cpu_flags`; False
    where they cannot be read): the kernels :data:`PINNED_ENVIRON` names run only there."""
    from zbuf_occlude.resources import cpu_flags

    return platform.machine().lower() in ("x86_64", "amd64") and {"avx2", "fma"} <= cpu_flags()


def training_threads(threads: int | None) -> int | None:
    """The CPU thread count a training run uses: ``threads`` when given, else
    :data:`REPRODUCIBLE_THREADS` when the arithmetic is pinned (:func:`pin_cpu_arithmetic`), else
    None (torch's default, the number of cores)."""
    if threads is not None:
        return threads
    return REPRODUCIBLE_THREADS if _pinned else None


def arithmetic_record() -> dict:
    """How this process's torch does its CPU arithmetic, for a run's ``run.json`` (``cpu_arithmetic``).

    Returns
    -------
    dict
        ``pinned`` (bool: :func:`pin_cpu_arithmetic` set :data:`PINNED_ENVIRON` before torch was
        imported), ``cpu_capability`` (ATen's kernels in use: ``DEFAULT``, ``AVX2``, ``AVX512``),
        ``threads`` (torch's CPU threads now), ``mkldnn`` (oneDNN enabled), each variable of
        :data:`PINNED_ENVIRON` as the environment holds it (None: unset), ``torch``, ``numpy``
        and ``architecture`` (``x86_64``, ``aarch64``).  Runs agree to the bit where all of these
        agree and ``pinned`` is true (module docstring).
    """
    import numpy as np
    import torch

    return {
        "pinned": bool(_pinned), "cpu_capability": torch.backends.cpu.get_cpu_capability(), "threads": torch.get_num_threads(),
        "mkldnn": bool(torch.backends.mkldnn.enabled), **{k: os.environ.get(k) for k in PINNED_ENVIRON},
        "torch": torch.__version__, "numpy": np.__version__, "architecture": platform.machine(),
    }  # fmt: skip
