"""What a program pays at import: ``import zbuf_occlude`` and ``zbuf-occlude --help`` load no heavy
library; each is imported by the code that uses it (the public names come from __init__.pyi)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("numba", "moderngl", "scipy", "h5py", "torch", "trimesh", "embreex", "open3d")


def _loaded_after(code: str) -> list[str]:
    probe = f"{code}\nimport json, sys\nprint(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))"
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, timeout=120, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_import_zbuf_occlude_loads_no_heavy_library():
    assert _loaded_after("import zbuf_occlude") == []


@pytest.mark.slow
def test_a_public_name_imports_what_it_needs_and_nothing_else():
    # visibility's registry is numpy only; the methods (numba, moderngl, Embree) load when one is asked for
    assert _loaded_after("import zbuf_occlude as zo\nzo.visible_mask, zo.Camera, zo.camera_on_sphere") == []
    assert "trimesh" in _loaded_after("import zbuf_occlude as zo\nzo.load_mesh")


def test_help_loads_no_heavy_library():
    # every subcommand's parser is built for --help: none may import a mesh, GL or learning library to do it
    code = "from zbuf_occlude.cli.main import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass"
    assert _loaded_after(code) == []


def test_every_public_name_resolves_and_occlude_is_the_function():
    import zbuf_occlude as zo

    for name in zo.__all__:
        assert getattr(zo, name) is not None, name
    import zbuf_occlude.pipeline  # importing the module of the same name must not replace the function

    assert callable(zo.occlude) and zo.occlude.__module__ == "zbuf_occlude.pipeline"


def test_all_lists_the_names_the_stub_imports():
    import zbuf_occlude as zo

    submodules = {n for n in zo._stub_names if n not in zo.__all__ and n != "__version__"}
    assert set(zo.__all__) == set(zo._stub_names) - submodules
    assert all(getattr(zo, m).__name__ == f"zbuf_occlude.{m}" for m in submodules)


def test_the_farms_all_lists_the_names_its_stub_imports():
    import zbuf_occlude.farm as farm

    assert set(farm.__all__) == set(farm._stub_names)
    assert all(getattr(farm, name) is not None for name in farm.__all__)


def test_the_learn_extras_dense_cloud_is_the_pipelines_and_needs_no_torch():
    import zbuf_occlude.learn as learn
    from zbuf_occlude.pipeline import DenseCloud

    assert "DenseCloud" in learn.__all__ and learn.DenseCloud is DenseCloud
    assert "torch" not in _loaded_after("from zbuf_occlude.learn import DenseCloud")


@pytest.mark.slow
def test_cpu_visibility_methods_load_no_opengl():
    # Embree, the CPU z-buffer and the paper's methods run where no GL driver exists
    code = (
        "import zbuf_occlude.visibility.embree_fast, zbuf_occlude.visibility.cpu_zbuffer\n"
        "import zbuf_occlude.visibility.oracle, zbuf_occlude.visibility.paper.object_space\n"
        "import sys\nassert not {'moderngl', 'glcontext'} & set(sys.modules), sorted(sys.modules)"
    )
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    subprocess.run([sys.executable, "-c", code], env=env, timeout=300, check=True)
