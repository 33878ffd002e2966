"""PLY point clouds from anyone: the bytes, read by the layer's rules, parsed by trimesh from memory.

A caller reads the file with :func:`~zbuf_occlude.io.regular_files.read_regular_file` (a regular
file, inside its folder, at most a cap), checks what its header declares against its own caps,
then hands the bytes here: trimesh never opens a path, and whatever its parser raises on hostile
bytes becomes one line naming the file.
"""

from __future__ import annotations

import io
from os import PathLike

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError, ZbufOccludeError
from zbuf_occlude.io.file_errors import parser_failure

__all__ = ["parse_ply_vertices"]


def parse_ply_vertices(
    raw: bytes,
    path: str | PathLike[str],
    *,
    error: type[ZbufOccludeError] = InvalidInputError,
    points_only: bool = False,
) -> NDArray[np.float64]:
    """The ``x y z`` of the vertex element of a PLY file's bytes (ASCII or binary; trimesh's parser).

    Parameters
    ----------
    raw : bytes
        The whole file, read through :func:`~zbuf_occlude.io.regular_files.read_regular_file`.
    path : str or PathLike
        The file, named in errors.
    error : type
        The exception raised (:class:`~zbuf_occlude.errors.InvalidInputError` or a subclass).
    points_only : bool
        Refuse a PLY that holds faces (a mesh, not a point cloud).

    Returns
    -------
    vertices : (N, 3) float64
        As stored (a float32 file's values, exactly).

    Raises
    ------
    ``error``
        Naming ``path``: bytes trimesh cannot parse as PLY (the parser's exception type, never
        its message, which may quote the file), or with ``points_only``, a mesh.
    MemoryError
        What the file declares does not fit in memory (the caller caps it before).
    """
    import trimesh

    try:
        loaded = trimesh.load(io.BytesIO(raw), file_type="ply", process=False)
        if points_only and not isinstance(loaded, trimesh.PointCloud):
            raise error(f"{path}: a {type(loaded).__name__}, not a point cloud")
        return np.asarray(loaded.vertices, dtype=np.float64)
    except (ZbufOccludeError, MemoryError):
        raise
    except Exception as exc:  # noqa: BLE001 - trimesh raises a zoo of types on hostile bytes (ValueError, KeyError, ...)
        raise error(f"{path}: cannot parse as PLY ({parser_failure(exc)})") from None
