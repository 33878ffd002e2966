"""Wavefront OBJ: face corners checked for index 0 before trimesh reads them; materials read inside the folder."""

from __future__ import annotations

import re
from pathlib import Path

from zbuf_occlude.mesh.formats.base import Format, malformed, read_with_named_files

__all__ = ["FORMATS", "check_obj_indices"]

#: An OBJ face corner: ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``; the vertex index is the first number.
_OBJ_FACE_LINE = re.compile(rb"^[ \t]*f[ \t]+([^\r\n#]*)", re.MULTILINE)


def check_obj_indices(raw: bytes, path: Path) -> None:
    """Raise MeshLoadError on an OBJ face corner with index 0.

    OBJ indices start at 1 (negative ones count back from the last vertex); trimesh reads a
    0 as the first vertex, so ``f 0 4 5`` loads as another face instead of an error.

    Raises
    ------
    MeshLoadError
        Naming ``path``, the line and the face.
    """
    for match in _OBJ_FACE_LINE.finditer(raw):
        for corner in match.group(1).split():
            first = corner.split(b"/", 1)[0]
            if first.lstrip(b"+-").isdigit() and int(first) == 0:
                line = raw.count(b"\n", 0, match.start()) + 1
                raise malformed(
                    path,
                    "obj",
                    f"line {line}: a face uses vertex index 0 (OBJ indices start at 1)",
                )


FORMATS = (Format("obj", (".obj",), read=read_with_named_files, check=check_obj_indices),)
