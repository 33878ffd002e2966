"""Mesh files whose content is another's: one key per content, whatever the OFF header's layout, and a list kept
without the copies (ModelNet40's and ModelNet10's copies of one mesh, a mesh copied into two class folders)."""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Sequence
from pathlib import Path

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.io.caps import MAX_MESH_FILE_BYTES
from zbuf_occlude.io.regular_files import read_regular_file

__all__ = ["dedupe_meshes", "mesh_content_key"]


def mesh_content_key(path: str | os.PathLike) -> str:
    """Hash of a mesh file's content that ignores the OFF header's layout.

    ModelNet40's ``OFF3514 3546 0`` and ModelNet10's ``OFF\\n3514 3546 0`` copies of the
    same mesh (and CRLF/LF variants) get the same key; other formats hash their bytes.

    Raises
    ------
    MeshLoadError
        The file is missing, not a regular file (a FIFO would block), or larger than
        :data:`~zbuf_occlude.io.caps.MAX_MESH_FILE_BYTES` (2 GiB); the message names it.
    """
    raw = read_regular_file(path, max_bytes=MAX_MESH_FILE_BYTES, error=MeshLoadError)
    if Path(path).suffix.lower() == ".off":
        text = raw.decode("latin-1")
        text = re.sub(r"^\s*OFF", "", text, count=1)
        return hashlib.sha256(" ".join(text.split()).encode()).hexdigest()
    return hashlib.sha256(raw).hexdigest()


def dedupe_meshes(paths: Sequence[str | os.PathLike]) -> tuple[list[Path], list[tuple[Path, Path]]]:
    """Drop meshes whose content duplicates an earlier one (:func:`mesh_content_key`).

    Returns
    -------
    kept : list of Path
        In input order.
    dropped : list of (duplicate, kept original)

    Raises
    ------
    MeshLoadError
        A file that cannot be read, as :func:`mesh_content_key` says.
    """
    seen: dict[str, Path] = {}
    kept, dropped = [], []
    for p in map(Path, paths):
        key = mesh_content_key(p)
        if key in seen:
            dropped.append((p, seen[key]))
        else:
            seen[key] = p
            kept.append(p)
    return kept, dropped
