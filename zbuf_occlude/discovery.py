"""Finding mesh files: folders searched recursively, names, ModelNet's class and split.

Nothing is lost silently: a folder that cannot be read and a file whose path is not
valid UTF-8 are reported (:class:`SkippedInput`, logged as warnings) and returned by
:func:`scan_meshes`, so that a run can say so and exit non-zero.  The farm's discovery
(:mod:`zbuf_occlude.farm.inputs`) walks with :func:`walk_mesh_files` too.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import NamedTuple

from .errors import InvalidInputError
from .mesh_formats import SUPPORTED_EXTENSIONS

__all__ = [
    "SkippedInput",
    "MeshScan",
    "printable_path",
    "non_utf8_reason",
    "walk_mesh_files",
    "scan_meshes",
    "find_meshes",
    "SPLITS",
    "DEFAULT_SPLIT",
    "class_and_split",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SkippedInput:
    """An input that mesh discovery could not use, and why.

    Attributes
    ----------
    path : str
        The folder or file, printable: bytes that are not UTF-8 appear as ``\\xNN``.
    reason : str
        E.g. "cannot read folder (Permission denied)", "file name is not valid UTF-8".
    """

    path: str
    reason: str

    def __str__(self) -> str:
        return f"{self.path}: {self.reason}"


class MeshScan(NamedTuple):
    """What :func:`scan_meshes` found."""

    #: ``(file, name)`` pairs, as :func:`find_meshes` returns them.
    meshes: list[tuple[Path, str]]
    #: Unreadable folders and files with names that are not UTF-8, in the order met.
    skipped: list[SkippedInput]


def printable_path(path: str | PathLike[str]) -> str:
    """``path`` as valid text: undecodable bytes of a file name become ``\\xNN``."""
    return os.fsencode(path).decode("utf-8", "backslashreplace")


def non_utf8_reason(path: str | PathLike[str]) -> str | None:
    """Why ``path`` cannot be used (its name is not valid UTF-8), or None if it can."""
    # Python decodes undecodable file-name bytes to lone surrogates (PEP 383); names
    # seed the samples and are written into JSON, HDF5 and PLY headers, all UTF-8.
    try:
        os.fspath(path).encode("utf-8")
    except UnicodeEncodeError:
        return (
            "file name is not valid UTF-8 (skipped: names are written into the outputs as UTF-8); "
            "rename it, e.g. convmv -f latin1 -t utf8 --notest"
        )
    return None


def walk_mesh_files(root: str | PathLike[str], *, skip_hidden: bool = False) -> tuple[list[Path], list[SkippedInput]]:
    """Mesh files under a folder, recursively, and the inputs that had to be skipped.

    Like ``Path(root).rglob("*")`` (symbolic links to folders are not followed) but a
    folder that cannot be listed (permissions, I/O error) is reported instead of being
    left out silently, and files whose path is not valid UTF-8 are reported and left out.

    Parameters
    ----------
    root : str or PathLike
        Folder to search.
    skip_hidden : bool
        Leave out files and folders whose name starts with ``.`` (not searched, not
        reported).

    Returns
    -------
    files : list of Path
        Regular files (or links to them) with an extension of :data:`SUPPORTED_EXTENSIONS`
        (any case), sorted.
    skipped : list of SkippedInput
        Folders that could not be read and files with non-UTF-8 paths; each is also
        logged as a warning.
    """
    root = Path(root)
    files: list[Path] = []
    skipped: list[SkippedInput] = []

    def unreadable(exc: OSError) -> None:
        folder = exc.filename if exc.filename is not None else root
        skipped.append(SkippedInput(printable_path(folder), f"cannot read folder ({exc.strerror or exc})"))

    for folder, dirnames, filenames in os.walk(root, onerror=unreadable):
        if skip_hidden:
            dirnames[:] = [d for d in dirnames if not d.startswith(".")]
            filenames = [f for f in filenames if not f.startswith(".")]
        dirnames.sort()
        for name in filenames:
            path = Path(folder, name)
            if path.suffix.lower() not in SUPPORTED_EXTENSIONS or not path.is_file():
                continue
            problem = non_utf8_reason(path)
            if problem:
                skipped.append(SkippedInput(printable_path(path), problem))
            else:
                files.append(path)
    for s in skipped:
        log.warning("skipped %s", s)
    return sorted(files), skipped


def scan_meshes(paths: Sequence[str | PathLike[str]]) -> MeshScan:
    """Mesh files under ``paths`` with unique names, and what had to be skipped.

    Files are taken as given; folders are searched recursively (:func:`walk_mesh_files`).
    A mesh's name is its path relative to the folder given, without the suffix (a file
    given directly: its stem).

    Returns
    -------
    MeshScan
        ``meshes``: ``(file, name)`` sorted per folder; ``skipped``: unreadable folders
        and non-UTF-8 file names (each logged as a warning).  A caller that must not
        lose inputs silently exits non-zero when ``skipped`` is not empty.

    Raises
    ------
    InvalidInputError
        A path does not exist, or no mesh was found (the message lists what was skipped).
    """
    found: list[tuple[Path, str]] = []
    skipped: list[SkippedInput] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            files, missed = walk_mesh_files(path)
            skipped.extend(missed)
            found.extend((f, f.relative_to(path).with_suffix("").as_posix()) for f in files)
        elif path.is_file():
            problem = non_utf8_reason(path)
            if problem:
                skipped.append(SkippedInput(printable_path(path), problem))
                log.warning("skipped %s", skipped[-1])
            else:
                found.append((path, path.stem))
        else:
            raise InvalidInputError(f"no such file or folder: {printable_path(path)}")
    if not found:
        where = ", ".join(printable_path(p) for p in paths)
        missed = f"; skipped {len(skipped)}: " + "; ".join(map(str, skipped[:3])) if skipped else ""
        raise InvalidInputError(f"no mesh files ({', '.join(SUPPORTED_EXTENSIONS)}) under {where}{missed}")
    return MeshScan(found, skipped)


def find_meshes(paths: Sequence[str | PathLike[str]]) -> list[tuple[Path, str]]:
    """Mesh files under ``paths`` (files, or folders searched recursively), sorted, each with a
    unique name: its path relative to the folder given, without the suffix.

    Unreadable folders and files with non-UTF-8 names are logged as warnings and left
    out; use :func:`scan_meshes` to get them (and exit non-zero).

    Raises
    ------
    InvalidInputError
        A path does not exist, or nothing was found.
    """
    return scan_meshes(paths).meshes


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
