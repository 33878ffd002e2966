"""Old module paths of the flat layout, kept for one release: importing one warns and gives the new module.

``import zbuf_occlude.cameras`` gives :mod:`zbuf_occlude.geometry.cameras` (the same module
object, so patching either patches both) with a :class:`DeprecationWarning` naming the new path.
Installed by the package's ``__init__``; each old name is listed once, in :data:`MOVED`.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

__all__ = ["MOVED", "install"]

#: Old module (relative to ``zbuf_occlude``) → its new home.
MOVED = {
    "cameras": "geometry.cameras",
    "sampling": "geometry.sampling",
    "mesh_formats": "mesh.formats",
    "mesh_layouts": "mesh.layouts",
    "mesh_scene": "mesh.scene",
    "mesh_cache": "mesh.cache",
    "discovery": "mesh.discovery",
    "object_sizes": "mesh.sizes",
    "farm.inputs": "mesh.inputs",
    "safe_paths": "io.safe_paths",
    "layout": "dataset.layout",
    "schema": "dataset.schema",
    "sample_files": "dataset.sample_files",
    "verify": "dataset.verify",
    "scan_files": "real_scans.files",
    "metrics": "visibility.metrics",
    "visibility.vertex": "visibility.paper.vertex",
    "visibility.object_space": "visibility.paper.object_space",
    "visibility.pruning": "visibility.paper.pruning",
    "visibility.occupancy": "visibility.paper.occupancy",
    "visibility.face_scan": "visibility.paper.face_scan",
    "elevation_profile": "experiments.elevation_profile",
    "profile": "experiments.elevation_profile",
    "occlude": "pipeline",
    "compare": "experiments.compare",
    "compare.run": "experiments.compare.run",
    "compare.results": "experiments.compare.results",
    "compare.report": "experiments.compare.report",
    "compare.tables": "experiments.compare.tables",
    "compare.cli": "cli.compare",
    "learn.experiments": "experiments.table3",
    "learn.paper": "experiments.paper",
    "learn.report": "experiments.table3_report",
    "learn.sim2real": "experiments.sim2real",
    "learn.sim2real_data": "experiments.sim2real_data",
    "learn.sim2real_report": "experiments.sim2real_report",
    "learn.cli": "cli.learn",
    "learn.sim2real_cli": "cli.sim2real",
    "sensors.realism": "experiments.realism",
    "sensors.cli": "cli.sensors",
    "protocols.cli": "cli.protocols",
    "farm.cli": "cli.farm",
}  # fmt: skip

_ROOT = __name__.rpartition(".")[0]


def new_module(old: str):
    """The new module of ``zbuf_occlude.<old>``, imported, after a :class:`DeprecationWarning`."""
    new = f"{_ROOT}.{MOVED[old]}"
    warnings.warn(f"{_ROOT}.{old} has moved to {new}; the old path goes in the next release", DeprecationWarning, stacklevel=3)
    return importlib.import_module(new)


class _OccludeModule(types.ModuleType):
    """The old ``zbuf_occlude.occlude`` module: the names it had, now in pipeline, geometry.samples and errors."""

    def __getattr__(self, name: str):
        for home in ("pipeline", "geometry.samples", "errors"):
            module = importlib.import_module(f"{_ROOT}.{home}")
            if hasattr(module, name):
                return getattr(module, name)
        raise AttributeError(f"module {self.__name__!r} has no attribute {name!r}")


class _Alias(importlib.abc.Loader):
    def __init__(self, old: str):
        self.old = old

    def create_module(self, spec):
        if self.old == "occlude":
            new_module(self.old)
            return _OccludeModule(spec.name)
        return new_module(self.old)

    def exec_module(self, module):
        pass


class _MovedFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        prefix = _ROOT + "."
        if fullname.startswith(prefix) and fullname[len(prefix):] in MOVED:
            return importlib.util.spec_from_loader(fullname, _Alias(fullname[len(prefix):]))
        return None


class _Package(types.ModuleType):
    """The package module: importing the old ``zbuf_occlude.occlude`` module must not replace the function.

    Python sets a package attribute for every submodule it imports; ``zbuf_occlude.occlude`` stays
    the function (resolved on first use from ``__init__.pyi``) whatever was imported.
    """

    def __setattr__(self, name: str, value) -> None:
        if name == "occlude" and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


def install() -> None:
    """Put the finder of old paths on ``sys.meta_path`` (once) and guard the package's ``occlude``."""
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _MovedFinder())  # before the path finder: `compare.run` must not load run.py twice
    sys.modules[_ROOT].__class__ = _Package
