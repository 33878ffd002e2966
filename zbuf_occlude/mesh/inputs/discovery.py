"""Finding input files: folders searched recursively, and what had to be skipped.

Nothing is lost silently: a folder that cannot be read, a file whose path is not valid
UTF-8 and a file of a 3D format that is not read (``.fbx``, ``.blend``, ...:
:data:`~zbuf_occlude.mesh.formats.UNREAD_FORMATS`) are reported (:class:`SkippedInput`,
logged as warnings) and returned by :func:`scan_meshes`, so that a run can say so and exit
non-zero.  Files that sit beside meshes (a glTF's buffers and textures, an OBJ's materials,
notes) are no 3D format and are passed over.  A file that is a link leading outside the folder
searched is followed only to a file of its own extension (a ModelNet subset made of links); any
other is refused (:class:`~zbuf_occlude.errors.UnsafePathError`) before it is opened.  A format
whose optional package is missing is refused once, when its files are found, before any work
(:func:`check_readers_installed`).
The farm's discovery (:mod:`zbuf_occlude.mesh.inputs.plan`) walks with :func:`walk_mesh_files` too.

Each function looks for the input kinds it is given (``kinds``, :mod:`zbuf_occlude.mesh.inputs.kinds`;
meshes unless told): ``generate`` and ``farm`` ask for point-set files too
(:data:`~zbuf_occlude.mesh.inputs.kinds.INPUT_KINDS`): ``.npy``, HDF5 files (``.h5``, ``.hdf5``)
that hold a PointNet-layout ``data`` dataset, and ``.ply`` files with vertices and no faces
(:mod:`zbuf_occlude.mesh.inputs.point_sets` makes their objects).  An HDF5 file of another layout
is no point set and is passed over, as notes are.
"""

from __future__ import annotations

import errno
import logging
import os
import stat
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import NamedTuple

from zbuf_occlude._version import install_hint
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.io.safe_paths import check_found_file
from zbuf_occlude.mesh.formats import EXTENSIONS_TEXT, FORMATS, SUPPORTED_EXTENSIONS, UNREAD_FORMATS, missing_package
from zbuf_occlude.mesh.inputs.kinds import MESH, InputKind, kinds_text
from zbuf_occlude.mesh.paths import printable_path

__all__ = [
    "SkippedInput",
    "MeshScan",
    "non_utf8_reason",
    "unusable_entry_reason",
    "unread_format_reason",
    "check_input_file",
    "check_readers_installed",
    "collect_inputs",
    "no_inputs_error",
    "walk_mesh_files",
    "scan_meshes",
    "find_meshes",
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


def unusable_entry_reason(path: str | PathLike[str]) -> str | None:
    """Why a folder entry cannot be used although it may hold a mesh, or None.

    A dangling symbolic link or a loop of links (the target, maybe a mesh or a folder of
    them, cannot be reached) and a mesh-named FIFO, socket or device (opening it would
    block or read something that is no file) are reported instead of left out silently.
    """
    path = os.fspath(path)
    try:
        st = os.stat(path)
    except OSError as exc:
        if os.path.islink(path):
            # (the target is not named: the reason goes into a data set's card, and a link's
            # target may be an absolute path of the machine; `ls -l` on the link shows it)
            what = "symbolic link loop" if exc.errno == errno.ELOOP else "dangling symbolic link"
            return f"{what}: {exc.strerror or exc}; fix or remove the link"
        return None  # gone since it was listed: nothing to report
    if stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode):
        return None
    if Path(path).suffix.lower() in SUPPORTED_EXTENSIONS:
        return f"not a regular file ({_file_kind(st.st_mode)}); never opened"
    return None


def unread_format_reason(path: str | PathLike[str]) -> str | None:
    """Why a file is skipped although it holds a 3D model (its format is not read), or None.

    None for the formats read (:data:`~zbuf_occlude.mesh.formats.SUPPORTED_EXTENSIONS`) and
    for anything that is no 3D format (textures, a glTF's ``.bin``, an OBJ's ``.mtl``, notes).
    """
    name = UNREAD_FORMATS.get(Path(path).suffix.lower())
    if name is None:
        return None
    return f"{name}: a 3D format zbuf-occlude does not read; convert it to one of {EXTENSIONS_TEXT} (e.g. with Blender or assimp)"


def _file_kind(mode: int) -> str:
    for test, kind in (
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
    ):
        if test(mode):
            return kind
    return "not a file"


def walk_mesh_files(
    root: str | PathLike[str], *, skip_hidden: bool = False, kinds: Sequence[InputKind] = (MESH,)
) -> tuple[list[Path], list[SkippedInput]]:
    """Mesh files (the files of ``kinds``) under a folder, recursively, and the inputs that had to be skipped.

    A file of ``kinds`` that is a link leading outside ``root`` is taken only when it leads to a
    file of its own extension (another tree's ``.off``); any other is refused before it is opened
    (:func:`~zbuf_occlude.io.safe_paths.check_found_file`).

    Like ``Path(root).rglob("*")`` (symbolic links to folders are not followed) but a
    folder that cannot be listed (permissions, I/O error), a dangling symbolic link, a
    loop of links and a FIFO or device with a mesh's extension
    (:func:`unusable_entry_reason`) are reported instead of being left out silently, and
    files whose path is not valid UTF-8 and files of a 3D format that is not read
    (:func:`unread_format_reason`) are reported and left out.  Other files (textures,
    buffers, materials, notes) are passed over.

    Parameters
    ----------
    root : str or PathLike
        Folder to search.
    skip_hidden : bool
        Leave out files and folders whose name starts with ``.`` (not searched, not
        reported).
    kinds : sequence of InputKind
        The kinds of file to find (:mod:`zbuf_occlude.mesh.inputs.kinds`): a file named by one of
        them (its ``suffixes``) that it ``finds``; a FIFO or device with such a name is reported
        as a mesh-named one is.

    Returns
    -------
    files : list of Path
        Regular files (or links to them) of ``kinds`` (a mesh: an extension of
        :data:`SUPPORTED_EXTENSIONS`, any case), sorted.
    skipped : list of SkippedInput
        Folders that could not be read, broken links, non-regular mesh-named entries, files
        with non-UTF-8 paths and files of 3D formats not read; each is also logged as a warning.

    Raises
    ------
    UnsafePathError
        A file of ``kinds`` is a link leading outside ``root`` to a file of another extension
        (``chair.off`` to ``~/.aws/credentials``): named with ``root``, nothing of it read.
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
            problem = unusable_entry_reason(path)
            if problem:
                skipped.append(SkippedInput(printable_path(path), problem))
                continue
            named = [k for k in kinds if path.suffix.lower() in k.suffixes]
            if not path.is_file():  # (a regular file, or a link to one)
                if named:
                    skipped.append(SkippedInput(printable_path(path), "not a regular file; never opened"))
                continue
            if not named:
                problem = unread_format_reason(path)
                if problem:
                    skipped.append(SkippedInput(printable_path(path), problem))
                continue
            if path.is_symlink():  # the walk follows no folder link: only a file that is a link can lead outside root
                check_found_file(path, root)  # before finds(), which opens an HDF5 file
            if not any(k.finds(path) for k in named):
                continue  # an HDF5 file of another layout: no 3D format, passed over
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
        ``meshes``: ``(file, name)`` sorted per folder; ``skipped``: unreadable folders,
        non-UTF-8 file names and files of 3D formats not read (each logged as a warning).
        A caller that must not lose inputs silently exits non-zero when ``skipped`` is not
        empty.

    Raises
    ------
    InvalidInputError
        A path does not exist, a file given is not a mesh by its extension
        (:func:`check_input_file`), or no mesh was found (the message lists what was
        skipped).
    BackendUnavailable
        A format found needs an optional package that is not installed
        (:func:`check_readers_installed`).
    """
    inputs, skipped = collect_inputs(paths)
    found: list[tuple[Path, str]] = []
    for path, files in inputs:
        if files is None:
            found.append((path, path.stem))
        else:
            found.extend((f, f.relative_to(path).with_suffix("").as_posix()) for f in files)
    if not found:
        raise no_inputs_error(paths, skipped)
    check_readers_installed(f for f, _ in found)
    return MeshScan(found, skipped)


def collect_inputs(
    paths: Sequence[str | PathLike[str]], *, skip_hidden: bool = False, kinds: Sequence[InputKind] = (MESH,)
) -> tuple[list[tuple[Path, list[Path] | None]], list[SkippedInput]]:
    """The paths given, each a folder with its mesh files or a mesh file, and what was skipped.

    Parameters
    ----------
    kinds : sequence of InputKind
        The kinds of file taken (:func:`walk_mesh_files`), in folders and given by name.

    Returns
    -------
    inputs : list of (Path, list of Path or None)
        ``(folder, its mesh files)`` (:func:`walk_mesh_files`) or ``(file, None)``, in order.
    skipped : list of SkippedInput
        As :func:`walk_mesh_files`, and files given whose name is not UTF-8.

    Raises
    ------
    InvalidInputError
        A path does not exist, is no regular file or folder, or a file given is not a
        file of ``kinds`` (:func:`check_input_file`).
    """
    inputs: list[tuple[Path, list[Path] | None]] = []
    skipped: list[SkippedInput] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            files, missed = walk_mesh_files(path, skip_hidden=skip_hidden, kinds=kinds)
            skipped.extend(missed)
            inputs.append((path, files))
        elif path.is_file():
            check_input_file(path, kinds)
            problem = non_utf8_reason(path)
            if problem:
                skipped.append(SkippedInput(printable_path(path), problem))
                log.warning("skipped %s", skipped[-1])
            else:
                inputs.append((path, None))
        else:
            problem = (unusable_entry_reason(path) or "not a regular file or folder") if os.path.lexists(path) else None
            raise InvalidInputError(f"{printable_path(path)}: {problem}" if problem else f"no such file or folder: {printable_path(path)}")
    return inputs, skipped


def no_inputs_error(
    paths: Sequence[str | PathLike[str]], skipped: Sequence[SkippedInput], kinds: Sequence[InputKind] = (MESH,)
) -> InvalidInputError:
    """The error of a search that found no file of ``kinds`` under ``paths`` (naming what was skipped)."""
    where = ", ".join(printable_path(p) for p in paths)
    missed = f"; skipped {len(skipped)}: " + "; ".join(map(str, skipped[:3])) if skipped else ""
    return InvalidInputError(f"no {kinds_text(kinds)} under {where}{missed}")


def check_input_file(path: str | PathLike[str], kinds: Sequence[InputKind] = (MESH,)) -> None:
    """Refuse a file given by name that is of none of ``kinds`` (``notes.txt``, ``car.fbx``, an HDF5
    file of another layout).

    Raises
    ------
    InvalidInputError
        No kind names its extension (a mesh's: :data:`SUPPORTED_EXTENSIONS`), or none that does
        finds it (:attr:`~zbuf_occlude.mesh.inputs.kinds.InputKind.refusal` says why); the
        message names the file (and the format, for a 3D format that is not read:
        :func:`unread_format_reason`).
    """
    named = [k for k in kinds if Path(path).suffix.lower() in k.suffixes]
    if named:
        if not any(k.finds(path) for k in named):
            raise InvalidInputError(f"{printable_path(path)} {named[0].refusal}")
        return
    unread = unread_format_reason(path)
    if unread:
        raise InvalidInputError(f"{printable_path(path)}: {unread}")
    raise InvalidInputError(f"{printable_path(path)} is not a mesh file: its extension is not one of {', '.join(SUPPORTED_EXTENSIONS)}")


def check_readers_installed(files: Iterable[str | PathLike[str]]) -> None:
    """Refuse mesh files whose format needs an optional package that is not installed.

    Checked once per format (not per file), when the files are found and before any work,
    so that a run does not fail file by file after it has done the rest.  Files without a
    mesh extension are passed over (the loader reports them).

    Raises
    ------
    BackendUnavailable
        One line per missing package: the format, how many of its files, one of them, and
        the extra to install (``3 COLLADA files (.dae) need the 'collada' package, ...``).
    """
    by_format: dict[str, list[str]] = {}
    for f in files:
        file_type = SUPPORTED_EXTENSIONS.get(Path(f).suffix.lower())
        if file_type is not None and FORMATS[file_type].needs is not None:
            by_format.setdefault(file_type, []).append(printable_path(f))
    problems = []
    for file_type, found in by_format.items():
        fmt = FORMATS[file_type]
        if missing_package(fmt):
            module, extra = fmt.needs
            n = f"{len(found)} {fmt.title} file{'s' if len(found) > 1 else ''} ({', '.join(fmt.extensions)})"
            problems.append(
                f"{n} need{'' if len(found) > 1 else 's'} the {module!r} package, not installed (e.g. {found[0]}): {install_hint(extra)}"
            )
    if problems:
        raise BackendUnavailable("; ".join(problems) + "; nothing was done")


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
