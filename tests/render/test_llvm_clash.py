"""Mesa's LLVM and Triton's LLVM in one process: no order of imports or calls crashes.

PyPI's default PyTorch brings Triton, whose ``libtriton.so`` carries its own LLVM.  Mesa's EGL
loads llvmpipe and its ``libLLVM`` into the global symbol scope; a ``libtriton.so`` loaded after
that bound its LLVM calls to Mesa's and died with SIGSEGV (``torch.use_deterministic_algorithms``,
``torch.compile``, ``import triton``), whoever made the context: us, pyrender, or the user's own
moderngl code (zbuf_occlude._llvm).  Each case runs in a fresh interpreter, since a crash kills
the process.  CI installs Triton (the ``test`` extra) so that these run there.
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


def _run(code: str, timeout: float = 300, path: Path | None = None) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(str(p) for p in (REPO_ROOT, path) if p)}
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


@pytest.mark.slow
@pytest.mark.parametrize(
    "then",
    [
        "torch.use_deterministic_algorithms(True)",  # imports torch._dynamo, which imports triton
        "import triton, triton.language",
    ],
)
def test_triton_after_a_gl_context_does_not_crash(then):
    _assert_survives(_run(CONTEXT_FIRST.format(then=then)))


@pytest.mark.slow
def test_triton_before_a_gl_context_still_works():
    _assert_survives(
        _run(
            "import torch, triton\nfrom zbuf_occlude.render.context import shared_context\nshared_context()\n"
            "torch.use_deterministic_algorithms(True)\nprint('ok')"
        )
    )


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.slow
def test_import_loads_no_llvm_and_importing_triton_loads_it_bound_to_itself():
    code = """
import sys
import zbuf_occlude
from zbuf_occlude.render.context import shared_context
shared_context()
assert "libtriton.so" not in open("/proc/self/maps").read()  # nothing paid until Triton is imported
import triton
assert "libtriton.so" in open("/proc/self/maps").read()
print("ok")
"""
    _assert_survives(_run(code))


COMPILE = "f = torch.compile(lambda x: (x * 2).sin().sum()); assert abs(float(f(torch.ones(8))) - 8 * 0.9092974) < 1e-4"


@pytest.mark.slow
@pytest.mark.parametrize("then", ["torch.use_deterministic_algorithms(True)", COMPILE])
def test_pyrender_backend_then_triton(then):
    pytest.importorskip("pyrender")
    code = f"""
import torch, trimesh, zbuf_occlude as zo
mesh = trimesh.creation.icosphere(subdivisions=2)
depth = zo.render_depth(mesh, zo.camera_on_sphere(20.0, 30.0, resolution=64), backend="pyrender")
assert depth.max() > 0
{then}
print("ok")
"""
    _assert_survives(_run(code, timeout=600))


@pytest.mark.slow
@pytest.mark.parametrize(
    "before",
    [
        "import zbuf_occlude\nimport moderngl\nctx = moderngl.create_standalone_context(backend='egl')",
        # the user's own context before importing us: the library is still bound to itself
        "import moderngl\nctx = moderngl.create_standalone_context(backend='egl')\nimport zbuf_occlude",
    ],
    ids=["import-then-own-context", "own-context-then-import"],
)
@pytest.mark.parametrize("then", ["torch.use_deterministic_algorithms(True)", COMPILE], ids=["deterministic", "compile"])
def test_a_users_own_moderngl_context(before, then):
    _assert_survives(_run(f"import torch\n{before}\n{then}\nprint('ok')", timeout=600))


@pytest.mark.slow
def test_torch_compile_before_the_first_render():
    code = """
import torch, trimesh, zbuf_occlude as zo
f = torch.compile(lambda x: (x * 2).sin().sum())
f(torch.ones(8))
mesh = trimesh.creation.icosphere(subdivisions=2)
points, fi = zo.sample_surface(mesh, 500, seed=0)
zo.visible_mask(mesh, points, zo.camera_on_sphere(20.0, 30.0, resolution=64), "zbuffer-exact", face_index=fi)
f(torch.ones(16))
print("ok")
"""
    _assert_survives(_run(code, timeout=600))


@pytest.mark.slow
def test_spawned_dataloader_workers_render_and_import_triton(tmp_path):
    (tmp_path / "spawn_items.py").write_text("""
import torch
from torch.utils.data import Dataset

class Items(Dataset):
    def __len__(self):
        return 4
    def __getitem__(self, i):
        from zbuf_occlude.render.context import shared_context
        shared_context()  # a Mesa context in the fresh worker first
        import triton  # then Triton
        return torch.tensor(float(i))
""")
    code = """
from torch.utils.data import DataLoader
from spawn_items import Items
if __name__ == "__main__":
    loader = DataLoader(Items(), batch_size=2, num_workers=2, multiprocessing_context="spawn")
    assert sorted(float(x) for batch in loader for x in batch) == [0.0, 1.0, 2.0, 3.0]
    print("ok")
"""
    script = tmp_path / "main.py"
    script.write_text(code)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), str(tmp_path)])}
    res = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=300)
    _assert_survives(res)
