"""PLY (Stanford): Latin-1 header comments decoded, and the element counts of the header compared with the mesh read.

trimesh reads an ASCII PLY cut short in its face list without complaint (1,551 of a chair's
2,234 faces), so the counts are compared after parsing: polygons become one or more triangles,
so fewer faces than declared means lines are missing.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING

from zbuf_occlude.errors import ZbufOccludeError
from zbuf_occlude.mesh.formats.base import Format, malformed, parse

if TYPE_CHECKING:
    import trimesh

__all__ = ["FORMATS", "ply_declared_counts", "read_ply"]


def _utf8_ply_header(raw: bytes) -> bytes:
    """PLY bytes whose header is valid UTF-8.

    trimesh decodes the header as strict UTF-8, so a Latin-1 ``comment`` line (exporters
    write the author's name or a path there) fails with UnicodeDecodeError.  Header
    keywords are ASCII, so decoding it as Latin-1 (which decodes any byte) and encoding
    as UTF-8 changes only the comments; the body, binary or text, is kept byte for byte.
    """
    end = raw.find(b"end_header")
    if end < 0:
        return raw  # trimesh reports the missing header
    header = raw[:end]
    try:
        header.decode("utf-8")
    except UnicodeDecodeError:
        return header.decode("latin-1").encode("utf-8") + raw[end:]
    return raw


def ply_declared_counts(raw: bytes) -> dict[str, int]:
    """The element counts a PLY header declares, e.g. ``{"vertex": 10, "face": 12}`` (empty without a header)."""
    end = raw.find(b"end_header")
    header = raw[: max(end, 0)].decode("utf-8", "replace")
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^element\s+(\w+)\s+(\d+)", header, re.MULTILINE)}


def read_ply(raw: bytes, path: Path, file_type: str) -> trimesh.Trimesh:
    """A PLY file parsed by trimesh, then checked against the counts its header declares.

    Raises
    ------
    MeshLoadError
        Naming ``path``: with both numbers, when the mesh read has fewer vertices or faces
        than the header declares (the file is cut short), or a body trimesh cannot parse as what
        the header declares (the parser's message is not quoted); a point cloud and no faces.
    """
    raw = _utf8_ply_header(raw)
    declared = ply_declared_counts(raw)
    n_vertices, n_faces = declared.get("vertex"), declared.get("face")
    try:
        mesh = parse(raw, path, "ply")
    except (ZbufOccludeError, MemoryError):
        raise
    except Exception:  # trimesh's message may quote the file: say what the header declares instead
        if n_vertices is None:
            raise
        raise malformed(
            path,
            "ply",
            f"its body does not hold the {n_vertices:,} vertices and {n_faces or 0:,} faces its header declares; "
            "the file is cut short or damaged",
        ) from None
    if (n_vertices is not None and len(mesh.vertices) < n_vertices) or (n_faces is not None and len(mesh.faces) < n_faces):
        raise malformed(
            path,
            "ply",
            f"declares {n_vertices or 0:,} vertices and {n_faces or 0:,} faces but holds {len(mesh.vertices):,} "
            f"vertices and {len(mesh.faces):,} faces; the file is cut short",
        )
    return mesh


FORMATS = (Format("ply", (".ply",), read=read_ply),)
