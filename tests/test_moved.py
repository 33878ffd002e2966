"""Old module paths of the flat layout: one release with a DeprecationWarning, the same module objects."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from zbuf_occlude._moved import MOVED


@pytest.mark.parametrize("old", sorted(MOVED))
def test_old_path_warns_and_gives_the_new_module(old: str) -> None:
    new = importlib.import_module(f"zbuf_occlude.{MOVED[old]}")
    sys.modules.pop(f"zbuf_occlude.{old}", None)
    with pytest.warns(DeprecationWarning, match=MOVED[old].replace(".", r"\.")):
        module = importlib.import_module(f"zbuf_occlude.{old}")
    if old == "occlude":
        import zbuf_occlude as zo

        assert module.occlude_object is new.occlude_object and module.OccludedCloud is zo_cloud()
        assert zo.occlude is new.occlude  # the package attribute stays the function
    else:
        assert module is new


def zo_cloud():
    from zbuf_occlude.geometry.samples import OccludedCloud

    return OccludedCloud


def test_old_occlude_module_leaves_the_function_callable() -> None:
    # importing zbuf_occlude.occlude sets the package attribute `occlude`; it must still be the call it was
    code = (
        "import warnings; warnings.simplefilter('ignore')\n"
        "import zbuf_occlude as zo\n"
        "from zbuf_occlude.occlude import OccludedCloud, occlude_object\n"
        "clouds = zo.occlude('data/samples/chair/train/chair_0001.off', views='0:0', n_points=64, dense_points=2000)\n"
        "print(type(clouds[0]).__name__)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=_root())
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "OccludedCloud"


def test_old_top_level_attribute_warns() -> None:
    import zbuf_occlude as zo
    from zbuf_occlude.geometry import cameras

    vars(zo).pop("cameras", None)  # an earlier `import zbuf_occlude.cameras` set the attribute
    with pytest.warns(DeprecationWarning, match="geometry.cameras"):
        assert zo.cameras is cameras


def test_new_paths_do_not_warn() -> None:
    code = (
        "import warnings; warnings.simplefilter('error', DeprecationWarning)\n"
        "import zbuf_occlude as zo, zbuf_occlude.geometry.cameras, zbuf_occlude.mesh.load, zbuf_occlude.dataset.reader\n"
        "zo.occlude, zo.load_mesh, zo.OccludedDataset, zo.VisibilitySession, zo.visible_mask\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=_root())
    assert out.returncode == 0, out.stderr


def _root():
    from pathlib import Path

    return Path(__file__).resolve().parents[1]
