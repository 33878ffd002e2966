"""Files a mesh names: the trimesh resolver that keeps them inside the mesh's folder, regular files only.

A mesh names other files (a glTF buffer or image ``uri``, an OBJ ``mtllib``, a texture,
COLLADA images).  Each such name is

* resolved **inside the mesh file's folder**, symlinks resolved, by the project's one rule
  (:func:`zbuf_occlude.io.safe_paths.path_inside`): ``../../secret`` is refused;
* read by :func:`zbuf_occlude.io.regular_files.read_regular_file`: only a **regular file**,
  opened without blocking (a FIFO, socket or device is refused), its size checked first
  against :data:`zbuf_occlude.io.caps.MAX_MESH_FILE_BYTES`.

:func:`folder_resolver` is the trimesh resolver every mesh reader is given, so glTF buffers and
images, OBJ materials and COLLADA images all go through it; errors are
:class:`~zbuf_occlude.errors.MeshLoadError` naming the file.
"""

from __future__ import annotations

import os
from functools import lru_cache
from os import PathLike
from typing import Any

from zbuf_occlude.errors import MeshLoadError, UnsafePathError
from zbuf_occlude.io.caps import MAX_MESH_FILE_BYTES
from zbuf_occlude.io.regular_files import read_regular_file
from zbuf_occlude.io.safe_paths import path_inside

__all__ = ["folder_resolver"]


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
                    path = path_inside(self.parent, candidate, what=f"{self.file_path}: a file it names", quoted=False)
                except UnsafePathError as exc:
                    refused = refused or exc
                    continue
                if os.path.lexists(path):
                    return read_regular_file(path, max_bytes=MAX_MESH_FILE_BYTES, error=MeshLoadError)
            if refused is not None:
                raise MeshLoadError(str(refused))
            raise FileNotFoundError(name)

    return RegularFileResolver


def folder_resolver(path: str | PathLike[str]) -> Any:
    """The trimesh resolver for the files ``path`` names: inside its folder, regular files only.

    Returns
    -------
    trimesh.resolvers.FilePathResolver
        Whose ``get`` reads through :func:`zbuf_occlude.io.regular_files.read_regular_file`
        (cap :data:`zbuf_occlude.io.caps.MAX_MESH_FILE_BYTES`) and raises
        :class:`~zbuf_occlude.errors.MeshLoadError` naming the file.
    """
    return _resolver_class()(str(path))
