"""What a mesh file's path says, for every layer above: the path as printable text, ModelNet's
splits, a mesh's class and split from its path (ModelNet's layout), ShapeNetCore's synset and model
(:func:`shapenet_path`, which also decides its up axis, :mod:`zbuf_occlude.mesh.scene`), and name
sets of options (``--classes``, ``--splits``)."""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from os import PathLike
from pathlib import Path

__all__ = ["printable_path", "SPLITS", "DEFAULT_SPLIT", "class_and_split", "shapenet_path", "name_set"]


def printable_path(path: str | PathLike[str]) -> str:
    """``path`` as valid text: undecodable bytes of a file name become ``\\xNN``."""
    return os.fsencode(path).decode("utf-8", "backslashreplace")


#: ModelNet's split folders.
SPLITS = ("train", "test")
#: Split of a mesh whose path names none (flat folder, list file without a split column).
DEFAULT_SPLIT = "train"


def class_and_split(path: str | Path) -> tuple[str, str]:
    """Class and split of a mesh from its path, ModelNet's layout.

    ``.../<class>/<split>/<name>.off`` (split ``train`` or ``test``), else
    ``.../<class>/<name>.off`` (split :data:`DEFAULT_SPLIT`), else, for a bare file name
    ``<class>_<NNNN>.off`` (a flat folder), the name without its number.
    """
    path = Path(path)
    parent = path.parent
    if parent.name in SPLITS and parent.parent.name:
        return parent.parent.name, parent.name
    if parent.name:
        return parent.name, DEFAULT_SPLIT
    return re.sub(r"_\d+$", "", path.stem) or path.stem, DEFAULT_SPLIT


def name_set(spec: str | Iterable[str] | None) -> set[str] | None:
    """Names from a comma-separated string or a sequence (``None`` stays ``None``)."""
    if spec is None:
        return None
    if isinstance(spec, str):
        return {s.strip() for s in spec.split(",") if s.strip()}
    return {str(s) for s in spec}


_V2 = ("models", "model_normalized.obj")
_V1 = "model.obj"
#: A WordNet noun offset, the name of every ShapeNetCore synset folder.
_SYNSET = re.compile(r"\d{8}")


def shapenet_path(path: str | PathLike[str]) -> tuple[str, str, str] | None:
    """``(layout, synset, model_id)`` of a ShapeNetCore file path, else None.

    The synset folder must be a WordNet offset (8 digits), as every ShapeNetCore synset is:
    ``chairs/abc/model.obj`` is no ShapeNetCore path.  A relative path is made absolute
    first (the synset folder may be the working folder's name).
    """
    parts = Path(path).absolute().parts
    if tuple(parts[-2:]) == _V2 and len(parts) >= 5 and _SYNSET.fullmatch(parts[-4]):
        return "shapenetcore-v2", parts[-4], parts[-3]
    if parts[-1] == _V1 and len(parts) >= 4 and _SYNSET.fullmatch(parts[-3]):
        return "shapenetcore-v1", parts[-3], parts[-2]
    return None
