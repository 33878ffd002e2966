"""Write N objects of a family into a class folder: ``OUT/CLASS/FAMILY_K.ply`` and ``OUT/CLASS/FAMILY.manifest.json``.

The files are binary PLY meshes, z up, in metres, standing on z = 0: any mesh folder reader takes
them (``farm``, ``generate``, ``experiment sim2real``; the class comes from the folder).  The
manifest is JSON: the family, its class, the seed, the generator module, and per file its path,
index, drawn parameters, bounding-box extent (metres), face count and which of its parts are open.
Object ``K`` is :func:`~zbuf_occlude.mesh.families.fitted.draw_object`'s (``family_rng(seed, K,
the family's name), so a file is the same whatever the count.  Every write goes through
:class:`~zbuf_occlude.io.owned.OwnedFolder` (locked, atomic, recorded): a second run replaces only
files a run of ours wrote and nobody changed since.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from zbuf_occlude.defaults import MAX_FAMILY_MESHES
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.sampling import check_seed
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.mesh.families.fitted import check_width_scale, draw_object
from zbuf_occlude.mesh.families.registry import get_family

__all__ = ["MANIFEST_SUFFIX", "FamilyRun", "write_family"]

#: The manifest's name beside the meshes: ``<family>.manifest.json``.
MANIFEST_SUFFIX = ".manifest.json"


@dataclass(frozen=True)
class FamilyRun:
    """What :func:`write_family` wrote: the mesh files (in index order) and the manifest."""

    files: list[Path]
    manifest: Path


def _plain(value: Any) -> Any:
    """``value`` with numpy scalars as Python numbers, for JSON."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value.item() if hasattr(value, "item") else value


def write_family(name: str, out: str | os.PathLike, *, count: int, seed: int, width_scale: tuple[float, float] | None = None) -> FamilyRun:
    """Write ``count`` objects of family ``name`` to ``out/<class>/<name>_<k>.ply`` with a manifest.

    Parameters
    ----------
    name : str
        A key of :data:`~zbuf_occlude.mesh.families.registry.FAMILIES`.
    out : str or PathLike
        The folder (created); its class subfolder holds the files.
    count : int
        Objects, 1 to :data:`~zbuf_occlude.defaults.MAX_FAMILY_MESHES`.
    seed : int
        0 to 2**63 - 1; object ``k`` draws from ``family_rng(name, seed, k)``.
    width_scale : (lo, hi), optional
        A fitted horizontal stretch (:class:`~zbuf_occlude.mesh.families.fitted.FamiliesFit`): each
        object, once drawn, is stretched in x and y by a factor drawn in it
        (:func:`~zbuf_occlude.mesh.families.fitted.widen`; the manifest records the range and each
        factor).  None: the family's own widths, and the manifest as without a fit.

    Returns
    -------
    FamilyRun

    Raises
    ------
    InvalidInputError
        An unknown family, a count out of range, a bad seed or ``width_scale`` (naming ``count``,
        ``seed``, ``width_scale``).
    OutputError, DatasetBusy, UnsafePathError
        ``out`` cannot be written, another run holds it, or a file of that name is not ours
        (:class:`~zbuf_occlude.io.owned.OwnedFolder`).
    """
    family = get_family(name)
    if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_FAMILY_MESHES:
        raise InvalidInputError(f"count must be an integer from 1 to {MAX_FAMILY_MESHES:,} (MAX_FAMILY_MESHES), got {count!r}")
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise InvalidInputError(f"seed must be an integer from 0 to 2**63 - 1, got a {type(seed).__name__}")
    check_seed(seed, name="seed")
    if width_scale is not None:
        width_scale = check_width_scale(width_scale)
    cls = family.class_name
    names = [rf"{re.escape(cls)}/{re.escape(name)}_\d+\.ply", re.escape(f"{cls}/{name}{MANIFEST_SUFFIX}")]
    entries, files = [], []
    with OwnedFolder(out, names=names, subfolders=[cls], what=f"the {name} family") as folder:
        for k in range(count):
            pieces, mesh, params = draw_object(family, seed, k, width_scale)
            rel = f"{cls}/{name}_{k}.ply"
            files.append(folder.write_bytes(rel, mesh.export(file_type="ply")))
            open_parts = sorted(p for p, group in pieces.items() if group and p in family.open_parts)
            entries.append({"path": rel, "index": k, "parameters": _plain(params), "extent_m": [float(e) for e in mesh.extents],
                            "faces": len(mesh.faces), "open_parts": open_parts})  # fmt: skip
        doc = {"family": name, "class": cls, "seed": seed, "count": count, "units": "m", "up": "+z", "generator": family.module,
               "ranges": {k: list(v) for k, v in family.ranges.items()}, "files": entries}  # fmt: skip
        if width_scale is not None:
            doc["fitted_width_scale"] = list(width_scale)
        manifest = folder.write_text(f"{cls}/{name}{MANIFEST_SUFFIX}", json.dumps(doc, indent=1) + "\n")
    return FamilyRun(files, manifest)
