"""Opening files whose names come from untrusted places: regular files only, sizes checked first.

A mesh or a scan names other files (a glTF buffer ``uri``, an OBJ ``mtllib``, a texture), and
a folder of scans names itself.  Every such name is opened here, so that one set of rules holds:

* only a **regular file** is read.  A FIFO, a socket or a device named by a file would block
  the reader forever (a FIFO) or read without end (``/dev/zero``).  The file is opened with
  ``O_NONBLOCK`` (opening a FIFO for reading then returns at once instead of waiting for a
  writer), and its type is checked on the open file (``fstat``), so a name swapped between a
  check and the open cannot slip through;
* its **size is checked before it is read**, against a cap the caller gives (the error names
  the file, its size and the cap);
* a name a file gives is resolved **inside that file's folder**, symlinks resolved, by the
  project's one rule (:func:`zbuf_occlude.io.safe_paths.path_inside`): ``../../secret`` is refused.

:func:`folder_resolver` is the trimesh resolver every mesh reader is given, so glTF buffers and
images, OBJ materials and COLLADA images all go through :func:`read_regular_file`.
"""

from __future__ import annotations

import hashlib
import os
import stat
from functools import lru_cache
from os import PathLike
from pathlib import Path
from typing import Any, BinaryIO

from zbuf_occlude.errors import MeshLoadError, UnsafePathError, ZbufOccludeError
from zbuf_occlude.io.safe_paths import path_inside

__all__ = ["MAX_NAMED_FILE_BYTES", "file_digest", "folder_resolver", "read_regular_file", "regular_file_size"]

#: Largest file a mesh may name (a glTF buffer, an OBJ material, a texture): 2 GiB.  glTF
#: buffers are addressed with 32-bit byte lengths and a GLB is at most 4 GiB by its uint32
#: length field; a buffer larger than this is not an object's mesh.
MAX_NAMED_FILE_BYTES = 2 << 30
#: Bytes read at a time when a file is hashed (bounded memory, whatever the file's size).
_HASH_CHUNK_BYTES = 1 << 20


def _nonblocking(name: str, flags: int) -> int:
    # O_NONBLOCK: opening a FIFO for reading returns at once instead of waiting for a writer.
    return os.open(name, flags | getattr(os, "O_NONBLOCK", 0))


def _open_regular(path: Path, error: type[ZbufOccludeError]) -> tuple[BinaryIO, int]:
    """(binary file, size) of ``path`` opened for reading; refuses anything but a regular file."""
    try:
        fh = open(path, "rb", opener=_nonblocking)  # noqa: SIM115 - closed by the callers
    except OSError as exc:
        raise error(f"{path}: cannot read file ({exc.strerror or exc})") from None
    info = os.fstat(fh.fileno())
    if not stat.S_ISREG(info.st_mode):
        fh.close()
        kind = "a FIFO" if stat.S_ISFIFO(info.st_mode) else "a folder" if stat.S_ISDIR(info.st_mode) else "not a regular file"
        raise error(f"{path}: is {kind}; only regular files are read")
    return fh, int(info.st_size)


def regular_file_size(path: str | PathLike[str], *, error: type[ZbufOccludeError] = MeshLoadError) -> int:
    """Bytes of ``path``, checking that it is a regular file (without reading it).

    Raises
    ------
    ``error``
        Naming the file: missing, unreadable, or a FIFO, socket, device or folder.
    """
    fh, size = _open_regular(Path(path), error)
    fh.close()
    return size


def read_regular_file(
    path: str | PathLike[str], *, max_bytes: int = MAX_NAMED_FILE_BYTES, error: type[ZbufOccludeError] = MeshLoadError
) -> bytes:
    """The bytes of ``path``, when it is a regular file of at most ``max_bytes`` bytes.

    Parameters
    ----------
    path : path
    max_bytes : int
        The cap, checked against the file's size before anything is read.
    error : type
        The exception raised (:class:`~zbuf_occlude.errors.MeshLoadError` for meshes,
        :class:`~zbuf_occlude.errors.InvalidInputError` for scans).

    Raises
    ------
    ``error``
        Naming the file: missing, unreadable, not a regular file (a FIFO would block), or
        larger than ``max_bytes`` (both numbers given).
    """
    path = Path(path)
    fh, size = _open_regular(path, error)
    with fh:
        if size > max_bytes:
            raise error(f"{path}: {size:,} bytes, more than the {max_bytes:,} a file named here may have")
        data = fh.read(max_bytes + 1)  # the file may grow after fstat: never read past the cap
    if len(data) > max_bytes:
        raise error(f"{path}: more than the {max_bytes:,} bytes a file named here may have")
    return data


def file_digest(path: str | PathLike[str], *, max_bytes: int, error: type[ZbufOccludeError] = MeshLoadError) -> str:
    """MD5 hex digest of a regular file of at most ``max_bytes``, read in 1 MiB chunks (never whole).

    Raises
    ------
    ``error``
        As :func:`read_regular_file`; the size is checked before the first byte is hashed.
    """
    path = Path(path)
    fh, size = _open_regular(path, error)
    with fh:
        if size > max_bytes:
            raise error(f"{path}: {size:,} bytes, more than the {max_bytes:,} a file read here may have")
        digest = hashlib.md5(usedforsecurity=False)
        while chunk := fh.read(_HASH_CHUNK_BYTES):
            digest.update(chunk)
    return digest.hexdigest()


@lru_cache(maxsize=1)
def _resolver_class() -> type:
    from trimesh.resolvers import FilePathResolver

    class RegularFileResolver(FilePathResolver):
        """trimesh's folder resolver (names stay inside the folder), reading regular files only."""

        def namespaced(self, namespace: str) -> RegularFileResolver:
            return RegularFileResolver(os.path.join(self.parent, namespace))

        def get(self, name: str) -> bytes:
            # trimesh's candidates (as written, without a leading "/", the bare file name),
            # each kept inside the folder by the project's one rule (io.safe_paths.path_inside).
            candidates = (name.strip(), name.strip().lstrip("/"), os.path.split(name.strip())[-1])
            refused = None
            for candidate in candidates:
                try:
                    path = path_inside(self.parent, candidate, what=f"{self.file_path}: a file it names")
                except UnsafePathError as exc:
                    refused = refused or exc
                    continue
                if os.path.lexists(path):
                    return read_regular_file(path)
            if refused is not None:
                raise MeshLoadError(str(refused))
            raise FileNotFoundError(name)

    return RegularFileResolver


def folder_resolver(path: str | PathLike[str]) -> Any:
    """The trimesh resolver for the files ``path`` names: inside its folder, regular files only.

    Returns
    -------
    trimesh.resolvers.FilePathResolver
        Whose ``get`` reads through :func:`read_regular_file` (cap :data:`MAX_NAMED_FILE_BYTES`).
    """
    return _resolver_class()(str(path))
