"""Mesa's LLVM and Triton's LLVM in one process: no order of imports or calls crashes.

PyPI's default PyTorch brings Triton, whose ``libtriton.so`` carries its own LLVM.  Mesa's EGL
loads llvmpipe and its ``libLLVM`` into the global symbol scope; a ``libtriton.so`` loaded after
that bound its LLVM calls to Mesa's and died with SIGSEGV (``torch.use_deterministic_algorithms``,
``torch.compile``, ``import triton``).  Each case runs in a fresh interpreter, since a crash
kills the process.  CI installs Triton (the ``test`` extra) so that these run there.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("triton") is None or importlib.util.find_spec("torch") is None,
    reason="needs torch and triton (pip install -e '.[test,learn]' on Linux x86-64)",
)


def _run(code: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=timeout)


def _assert_survives(res: subprocess.CompletedProcess) -> None:
    assert res.returncode == 0, f"exit {res.returncode} (-11 / 139: SIGSEGV)\n{res.stderr[-3000:]}"
    assert res.stdout.strip().endswith("ok"), res.stdout


CONTEXT_FIRST = """
import torch
from zbuf_occlude.render.context import shared_context
shared_context()
{then}
print("ok")
"""


@pytest.mark.parametrize(
    "then",
    [
        "torch.use_deterministic_algorithms(True)",  # imports torch._dynamo, which imports triton
        "import triton, triton.language",
    ],
)
def test_triton_after_a_gl_context_does_not_crash(then):
    _assert_survives(_run(CONTEXT_FIRST.format(then=then)))


def test_triton_before_a_gl_context_still_works():
    _assert_survives(_run("import torch, triton\nfrom zbuf_occlude.render.context import shared_context\nshared_context()\n"
                          "torch.use_deterministic_algorithms(True)\nprint('ok')"))


def test_a_users_torch_compile_after_visibility_work():
    code = """
import numpy as np, torch, trimesh, zbuf_occlude as zo
mesh = trimesh.creation.icosphere(subdivisions=2)
points, fi = zo.sample_surface(mesh, 500, seed=0)
zo.visible_mask(mesh, points, zo.camera_on_sphere(20.0, 30.0, resolution=64), "zbuffer-exact", face_index=fi)
f = torch.compile(lambda x: (x * 2).sin().sum())
assert abs(float(f(torch.ones(8))) - 8 * float(np.sin(2.0))) < 1e-5
print("ok")
"""
    _assert_survives(_run(code, timeout=600))


def test_forked_dataloader_workers_import_triton_after_the_parents_context():
    code = """
import torch
from torch.utils.data import DataLoader, Dataset
from zbuf_occlude.render.context import shared_context

class Items(Dataset):
    def __len__(self):
        return 4
    def __getitem__(self, i):
        import triton  # a worker's first use of triton, after the parent made a GL context
        shared_context()  # and the worker's own context
        return torch.tensor(float(i))

shared_context()
loader = DataLoader(Items(), batch_size=2, num_workers=2, multiprocessing_context="fork")
assert sorted(float(x) for batch in loader for x in batch) == [0.0, 1.0, 2.0, 3.0]
print("ok")
"""
    _assert_survives(_run(code))


def test_the_preload_loads_triton_without_importing_it():
    code = """
import sys
from zbuf_occlude.render.context import shared_context
shared_context()
maps = open("/proc/self/maps").read()
assert "libtriton.so" in maps and "triton" not in sys.modules, sorted(m for m in sys.modules if "triton" in m)
print("ok")
"""
    _assert_survives(_run(code))
