"""Paths and names that metadata gives us stay inside their folder.

A data set, a farm task folder or a mesh tree may come from anyone.  Every path that is
read from metadata (a data set's card, manifest, records, file lists; a task folder's
records) and every file the project writes or deletes because metadata named it goes
through :func:`path_inside`: it must be relative, without ``..``, and still inside the
folder once symlinks are resolved.  Names that become file or folder names (a mesh's
name under ``generate --out``) go through :func:`check_relative_name`; names written one
per line (class names in ``shape_names.txt``) through :func:`check_line_text`.

A file found by walking a folder (meshes, point sets, real scans) goes through
:func:`check_found_file`: a link in the folder that leads outside it is followed only to a file of
its own kind (its target's name ends in the link's extension: a ModelNet subset made of links to
``.off`` files); any other (``car/scan.xyz`` to ``~/.aws/credentials``) is refused before a byte of
it is read.
"""

from __future__ import annotations

import os
import unicodedata
from pathlib import Path, PurePosixPath

from zbuf_occlude.errors import InvalidInputError, UnsafePathError
from zbuf_occlude.io.file_errors import value_kind

__all__ = ["path_inside", "check_relative_name", "check_line_text", "control_character", "check_found_file"]

#: Unicode categories that break "one name per line" (``str.splitlines`` splits on
#: ``\n``, ``\r``, ``\x0b``, ``\x0c``, ``\x1c``-``\x1e``, ``\x85``, U+2028, U+2029): control
#: characters (Cc) and the line and paragraph separators (Zl, Zp).
_LINE_BREAKING = ("Cc", "Zl", "Zp")


def control_character(text: str) -> str | None:
    """The first control or line-separator character of ``text`` (``None`` if it has none)."""
    return next((c for c in text if unicodedata.category(c) in _LINE_BREAKING), None)


def check_line_text(text: object, *, what: str) -> str:
    """``text`` if it is a non-empty string that can stand on a line of its own.

    Raises
    ------
    InvalidInputError
        ``text`` is not a string, is empty, or holds a control character (``\\n``,
        ``\\x85``, ...): it would break the one-name-per-line files (``shape_names.txt``).
    """
    if not isinstance(text, str) or not text:
        raise InvalidInputError(f"{what} must be a non-empty string, got {value_kind(text)}")
    bad = control_character(text)
    if bad is not None:
        raise InvalidInputError(
            f"{what} {text!r} holds the control character U+{ord(bad):04X}; names are written one per line (shape_names.txt): rename it"
        )
    return text


def check_relative_name(name: object, *, what: str) -> str:
    """``name`` if it can name files and folders inside an output folder.

    A relative POSIX path whose parts are neither empty, ``.`` nor ``..`` and hold no
    control character (``chair/train/chair_0001`` is fine; ``..``, ``/etc/x``, ``a//b`` are not).

    Raises
    ------
    UnsafePathError
        The name would leave the folder or is not a plain relative path.
    """
    if not isinstance(name, str) or not name:
        raise UnsafePathError(f"{what} must be a non-empty relative path, got {value_kind(name)}")
    parts = name.split("/")
    if name.startswith("/") or any(p in ("", ".", "..") for p in parts) or "\0" in name or control_character(name):
        raise UnsafePathError(
            f"{what} {name!r} cannot name a file inside the output folder (absolute, empty, '.' or '..' parts, "
            "or control characters); rename the file"
        )
    return name


def path_inside(root: str | os.PathLike, rel: object, *, what: str, quoted: bool = True) -> Path:
    """``root / rel``, after checking that it lies inside ``root``.

    ``rel`` must be a relative path (str) without ``..`` parts, and ``root / rel`` must
    still be inside ``root`` once every symlink (of both) is resolved; the file need not
    exist.  Use it for every path read from metadata and every write or deletion that
    metadata decides.

    Parameters
    ----------
    root : str or PathLike
        The folder (a data set, ``--out``, a task folder).
    rel : str
        The path the metadata gives, relative to ``root``.
    what : str
        Where ``rel`` comes from, for the message (e.g. ``"manifest.jsonl:3 shards"``).
    quoted : bool
        Whether the message quotes ``rel`` (and where a link leads): for a name of ours (an output
        folder's ``shards``).  False for a path read from a user's file (a scene's mesh, a manifest's
        shard, a file a mesh names): the message names ``what`` and ``root``, never ``rel``, which is
        a value of that file.

    Returns
    -------
    Path
        ``root / rel`` (not resolved).

    Raises
    ------
    UnsafePathError
        ``rel`` is not a string, is absolute, has ``..`` parts, or leads outside ``root``
        (through a symlink).
    """
    if not isinstance(rel, (str, os.PathLike)) or not str(rel) or "\0" in str(rel):
        got = value_kind(rel) if not isinstance(rel, str) or not rel else "one holding NUL"
        raise UnsafePathError(
            f"{what}: {rel!r} is not a relative path" if quoted else f"{what}: the path must be a relative path, got {got}"
        )
    named = f"{str(rel)!r}" if quoted else "the path"
    rel_path = PurePosixPath(os.fspath(rel))
    if rel_path.is_absolute() or Path(rel).is_absolute():
        raise UnsafePathError(f"{what}: {named} is an absolute path; paths in metadata must stay inside {root}")
    if ".." in rel_path.parts:
        raise UnsafePathError(f"{what}: {named} leaves {root} ('..'); paths in metadata must stay inside it")
    root = Path(root)
    path = root / rel_path
    try:
        real_root, real = root.resolve(), path.resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop (RuntimeError before Python 3.13)
        raise UnsafePathError(f"{what}: {named} cannot be resolved inside {root} ({exc if quoted else type(exc).__name__})") from None
    if real != real_root and real_root not in real.parents:
        where = f" (to {real}, through a symlink)" if quoted else " through a symlink"
        raise UnsafePathError(f"{what}: {named} leads outside {root}{where}; refused")
    return path


def check_found_file(path: str | os.PathLike, folder: str | os.PathLike) -> Path:
    """``path``, a file found by walking ``folder``, after checking where its links lead.

    A file inside ``folder`` once links are resolved is taken.  One that leads outside (the file
    or a folder on the way is a link) is taken only when the file it leads to has the link's
    extension (any case): ``chair/train/chair_0001.off`` linking to another tree's ``.off`` is a
    data file followed on purpose; ``car/scan.xyz`` linking to ``~/.aws/credentials`` or
    ``/etc/passwd`` is not a scan, and reading it could put its bytes into our outputs.

    Parameters
    ----------
    path : str or PathLike
        A file under ``folder``, as the walk found it.
    folder : str or PathLike
        The folder the user gave.

    Returns
    -------
    Path
        ``path`` (not resolved).

    Raises
    ------
    UnsafePathError
        ``path`` leads outside ``folder`` to a file of another extension, or cannot be resolved
        (a link loop); the message names the link and the folder, not the link's target (which
        may be a private path) nor anything it holds.
    """
    path, folder = Path(path), Path(folder)
    try:
        real, root = path.resolve(), folder.resolve()
    except (OSError, RuntimeError):  # a link loop (RuntimeError before Python 3.13)
        raise UnsafePathError(f"{path}: a link in {folder} that cannot be resolved (a loop?); fix or remove it") from None
    if real == root or root in real.parents or (path.suffix and real.suffix.lower() == path.suffix.lower()):
        return path
    raise UnsafePathError(
        f"{path}: a link in {folder} to a file outside it that is not a {path.suffix or 'like-named'} file; "
        "refused unread (replace the link by the file, or link to a file of its format)"
    )
