"""A folder of meshes, one class per folder, loaded once and split into whole-mesh sides (``experiment sim2real``'s and
``fit-sensor --meshes``' input).

:func:`find_class_meshes` reads ``root/CLASS/...`` (any format :func:`zbuf_occlude.load_mesh`
reads), drops byte-identical duplicates and checks that every class can be validated;
:func:`split_whole_meshes` holds whole meshes out for validation, so that no mesh gives clouds
to both sides.
"""

from __future__ import annotations

import fnmatch
import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.inputs.duplicates import dedupe_meshes

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = ["MeshEntry", "MeshFolder", "find_class_meshes", "check_classes", "split_whole_meshes"]

log = logging.getLogger(__name__)


@dataclass
class MeshEntry:
    """One mesh of the experiment: file, class, stable name, the loaded (z-up, normalised) mesh.

    ``name`` is the file's path below the root without its suffix (``car/sedan``): the key of the
    mesh's own shape in :attr:`~zbuf_occlude.sensors.fit.class_placement.CropPlacement.per_mesh`.
    """

    path: Path
    class_name: str
    name: str
    mesh: trimesh.Trimesh


def _up_for(rel: str, up: str, up_map: dict[str, str]) -> str:
    for pattern, axis in up_map.items():
        if fnmatch.fnmatch(rel, pattern):
            return axis
    return up


def find_class_meshes(root: str | os.PathLike, *, up: str = "auto", up_map: dict[str, str] | None = None,
                      classes: list[str] | None = None) -> list[MeshEntry]:  # fmt: skip
    """Meshes under ``root/CLASS/...`` (the class is the first folder), loaded, duplicates dropped.

    Parameters
    ----------
    up : str
        Up axis of every file (:func:`zbuf_occlude.load_mesh`; ``auto``: each format's convention).
    up_map : dict, optional
        ``{glob of the path relative to root: axis}``, first match wins, for files that break
        their format's convention.
    classes : list of str, optional
        Only these class folders (default: every one).

    Raises
    ------
    InvalidInputError
        No mesh, fewer than two classes, or a class with a single mesh (nothing to validate on).
    MeshLoadError
        A mesh that cannot be loaded (named).
    """
    from zbuf_occlude.mesh.inputs.discovery import walk_mesh_files
    from zbuf_occlude.mesh.load import load_mesh

    root = Path(root)
    if not root.is_dir():
        raise InvalidInputError(f"mesh root {root} is not a folder")
    files, _ = walk_mesh_files(root, skip_hidden=True)
    files = [f for f in files if len(f.relative_to(root).parts) >= 2]
    kept, dropped = dedupe_meshes(files)
    for dup, orig in dropped:
        log.warning("dropping %s: same bytes as %s", dup, orig)
    out = []
    for f in kept:
        rel = f.relative_to(root).as_posix()
        cls = rel.split("/", 1)[0]
        if classes and cls not in classes:
            continue
        mesh = load_mesh(f, up=_up_for(rel, up, up_map or {}))
        out.append(MeshEntry(f, cls, rel.rsplit(".", 1)[0], mesh))
    check_classes(out, str(root))
    return out


@dataclass(frozen=True)
class MeshFolder:
    """A folder of class meshes and how its files stand: what :func:`find_class_meshes` reads.

    Parameters
    ----------
    root : str or PathLike
        One sub-folder per class of mesh files.
    up : str
        Up axis of every file (:func:`zbuf_occlude.load_mesh`; ``auto``: each format's convention).
    up_map : mapping of str to str
        ``{glob of the path relative to root: axis}``, first match wins, for files that break their format's convention.
    """

    root: str | os.PathLike
    up: str = "auto"
    up_map: Mapping[str, str] = field(default_factory=dict)

    def find(self, classes: list[str] | None = None) -> list[MeshEntry]:
        """:func:`find_class_meshes` of this folder (only ``classes``, where given); raises as it does."""
        return find_class_meshes(self.root, up=self.up, up_map=dict(self.up_map), classes=classes)


def check_classes(meshes: list[MeshEntry], where: str) -> None:
    """Refuse ``meshes`` unless they hold two or more classes of two or more meshes each.

    Raises
    ------
    InvalidInputError
        Fewer than two classes, or a class with one mesh (no whole mesh left to validate on),
        the message starting with ``where``.
    """
    by_class: dict[str, list[MeshEntry]] = {}
    for m in meshes:
        by_class.setdefault(m.class_name, []).append(m)
    if len(by_class) < 2:
        raise InvalidInputError(f"{where}: need meshes of two or more classes in CLASS/ folders, found {sorted(by_class)}")
    single = [c for c, ms in by_class.items() if len(ms) < 2]
    if single:
        raise InvalidInputError(f"{where}: classes {single} have one mesh; a held-out mesh is needed for validation")


def split_whole_meshes(meshes: list[MeshEntry], fraction: float, seed: int) -> tuple[list[MeshEntry], list[MeshEntry]]:
    """Training and validation meshes: per class ``round(fraction · n)`` whole meshes (at least
    one, at most ``n − 1``) drawn with ``seed`` go to validation; no mesh is on both sides."""
    rng = np.random.default_rng([seed, 0x5E2])
    train, val = [], []
    for cls in sorted({m.class_name for m in meshes}):
        ms = [m for m in meshes if m.class_name == cls]
        k = min(max(int(round(fraction * len(ms))), 1), len(ms) - 1)
        held = set(rng.permutation(len(ms))[:k].tolist())
        for i, m in enumerate(ms):
            (val if i in held else train).append(m)
    return train, val
