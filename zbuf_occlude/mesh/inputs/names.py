"""Names the input code shares with every layer above it: printable paths, ModelNet's splits, a
mesh's class and split from its path, and name sets of options (``--classes``, ``--splits``)."""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from os import PathLike
from pathlib import Path

__all__ = ["printable_path", "SPLITS", "DEFAULT_SPLIT", "class_and_split", "name_set"]


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
