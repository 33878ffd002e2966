"""STL: a binary file's length checked against the triangle count it declares."""

from __future__ import annotations

from pathlib import Path

from zbuf_occlude.mesh.formats.base import Format, malformed, read_with_named_files

__all__ = ["FORMATS", "check_binary_stl_length"]

#: Binary STL: 80-byte header, uint32 triangle count, then 50 bytes per triangle.
_STL_HEADER_BYTES, _STL_TRIANGLE_BYTES = 84, 50


def check_binary_stl_length(raw: bytes, path: Path) -> None:
    """Raise MeshLoadError when a binary STL is shorter than its triangle count says.

    ASCII STL starts with ``solid``; a binary file that does is judged by its length.
    Files shorter than a binary header are left to trimesh (empty or not an STL).

    Raises
    ------
    MeshLoadError
        Naming ``path``, with the declared and the found triangles and bytes.
    """
    if len(raw) < _STL_HEADER_BYTES:
        return  # trimesh reports it (empty or not an STL)
    n_triangles = int.from_bytes(raw[80:84], "little")
    expected = _STL_HEADER_BYTES + _STL_TRIANGLE_BYTES * n_triangles
    if raw[:5].lower() == b"solid" and b"facet" in raw[:1024]:
        return  # ASCII
    if len(raw) < expected:
        found = (len(raw) - _STL_HEADER_BYTES) // _STL_TRIANGLE_BYTES
        raise malformed(
            path,
            "stl",
            f"binary STL declares {n_triangles:,} triangles ({expected:,} bytes) but holds {found:,} "
            f"({len(raw):,} bytes); the file is cut short",
        )


FORMATS = (Format("stl", (".stl",), read=read_with_named_files, check=check_binary_stl_length),)
