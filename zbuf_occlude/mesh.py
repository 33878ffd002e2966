"""Load meshes from disk, drop degenerate faces and normalise them to the unit box.

trimesh does the parsing; this module adds what the pipeline needs on top:
errors that name the file and the cause, removal of degenerate faces (ModelNet has
them), and the normalisation of Sryamkin et al. 2023, §4.1 (centre the axis-aligned
bounding box on the origin, scale uniformly to a maximum extent of 1).

Provenance is stored on every mesh this module returns, in
``mesh.metadata["zbuf_occlude"]``:

``source`` : str or None
    The file the mesh was loaded from.
``n_degenerate_faces_dropped`` : int
    Faces removed because they repeat a vertex index or have (numerically) zero area.
``n_unreferenced_vertices_dropped`` : int
    Vertices removed because no kept face uses them.
``center`` : list of 3 float, ``scale`` : float
    The normalisation that was applied, in the source file's units:
    ``normalised = (original - center) * scale``.  Identity (``[0, 0, 0]``, ``1.0``)
    when the mesh was not normalised.

Files cut short are errors, not partial meshes: OFF and PLY declare their vertex and
face counts and binary STL its triangle count, and fewer found than declared raises
:class:`~zbuf_occlude.errors.MeshLoadError` with both numbers (OBJ declares nothing).

ModelNet quirks handled (all verified on real files with trimesh 5.2): the malformed
header ``OFF3514 3546 0`` (counts on the ``OFF`` line), CRLF line endings, triangle
soup with duplicated vertices (kept as is: meshes need not be watertight or
manifold), polygons with more than three vertices (fan-triangulated by trimesh) and
zero-area faces.
"""

from __future__ import annotations

import io
import logging
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import trimesh
from numpy.typing import NDArray

from .errors import InvalidInputError, MeshLoadError, ZbufOccludeError

__all__ = [
    "SUPPORTED_EXTENSIONS",
    "find_meshes",
    "scan_meshes",
    "walk_mesh_files",
    "MeshScan",
    "SkippedInput",
    "printable_path",
    "non_utf8_reason",
    "class_and_split",
    "SPLITS",
    "DEFAULT_SPLIT",
    "DEGENERATE_AREA_RTOL",
    "MAX_ABS_COORDINATE",
    "METADATA_KEY",
    "load_mesh",
    "normalize_mesh",
    "clean_mesh",
    "degenerate_faces",
]

log = logging.getLogger(__name__)

#: File extensions load_mesh accepts (lower case), mapped to trimesh's file type.
SUPPORTED_EXTENSIONS: dict[str, str] = {
    ".off": "off",
    ".obj": "obj",
    ".ply": "ply",
    ".stl": "stl",
    ".glb": "glb",
}

#: A face whose area is at most this times the squared maximum extent of the mesh is
#: degenerate.  1e-14 is about 50 float64 epsilons: it catches faces that are exactly
#: flat but whose cross product rounding left at ~1e-16 (ModelNet has such faces at
#: 4e-21), while a triangle 1e-7 of the object on a side is still kept.
DEGENERATE_AREA_RTOL = 1e-14

#: Largest vertex coordinate magnitude accepted: float32's maximum (~3.4e38).  The GPU
#: methods work in float32, and beyond it areas and squared extents overflow float64 too
#: (1e200 squared); such files are corrupt or in absurd units.
MAX_ABS_COORDINATE = float(np.finfo(np.float32).max)

#: Longest prefix before "OFF" on the header line (COFF, NOFF, STOFF, 4OFF, CNOFF ...).
_OFF_HEADER_MAX_PREFIX = 4

#: Key of this package's provenance dictionary in ``trimesh.Trimesh.metadata``.
METADATA_KEY = "zbuf_occlude"


class _NotOff(ValueError):
    """The file does not start with an OFF header."""


class _NotMesh(ValueError):
    """The file parsed but holds no triangle mesh."""


class _Malformed(ValueError):
    """The file's structure contradicts itself (counts declared vs found, cut lines)."""


def _referenced_extent(
    vertices: NDArray[np.float64], faces: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(3,) min and max corner of the vertices used by ``faces``."""
    used = vertices[np.unique(faces)]
    return used.min(axis=0), used.max(axis=0)


def _face_areas(vertices: NDArray[np.float64], faces: NDArray[np.int64]) -> NDArray[np.float64]:
    v0 = vertices[faces[:, 0]]
    cross = np.cross(vertices[faces[:, 1]] - v0, vertices[faces[:, 2]] - v0)
    return 0.5 * np.sqrt(np.einsum("ij,ij->i", cross, cross))


def _degenerate_mask(
    vertices: NDArray[np.float64], faces: NDArray[np.int64], max_extent: float, area_rtol: float
) -> NDArray[np.bool_]:
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    return repeated | (_face_areas(vertices, faces) <= area_rtol * max_extent**2)


def _check_coordinates(vertices: NDArray[np.float64], *, what: str, error: type[ZbufOccludeError]) -> None:
    """Raise ``error`` on NaN/inf vertices or coordinates beyond :data:`MAX_ABS_COORDINATE`."""
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise error(
            f"{what}: {int(bad.sum())} of {len(vertices)} vertices are NaN or inf "
            f"(first at index {int(np.argmax(bad))}); fix or re-export the mesh"
        )
    if len(vertices):
        magnitude = np.abs(vertices).max(axis=1)
        if magnitude.max() > MAX_ABS_COORDINATE:
            first = int(np.argmax(magnitude > MAX_ABS_COORDINATE))
            raise error(
                f"{what}: vertex coordinates reach {magnitude.max():.3g} (first at index {first}), beyond the "
                f"float32 range (+-{MAX_ABS_COORDINATE:.3g}) the renderer works in; the file is corrupt or in "
                "absurd units: rescale it"
            )


def _check(
    vertices: NDArray[np.float64],
    faces: NDArray[np.int64],
    *,
    what: str,
    error: type[ZbufOccludeError],
    area_rtol: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Validate a mesh; return its referenced bounds and degenerate-face mask.

    Raises ``error`` with a message starting with ``what`` (the file or "mesh").
    """
    if len(vertices) == 0 and len(faces) == 0:
        raise error(f"{what}: empty mesh (no vertices, no faces)")
    if len(faces) == 0:
        raise error(f"{what}: mesh has {len(vertices)} vertices but no faces; a point cloud is not a mesh")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise error(f"{what}: faces must be (F, 3) triangles, got shape {faces.shape}")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise error(
            f"{what}: face indices span [{faces.min()}, {faces.max()}] but there are only {len(vertices)} vertices"
        )
    _check_coordinates(vertices, what=what, error=error)
    lo, hi = _referenced_extent(vertices, faces)
    max_extent = float((hi - lo).max())
    if max_extent == 0.0:
        raise error(f"{what}: all vertices coincide at {lo.tolist()} (zero extent); nothing to normalise or sample")
    degenerate = _degenerate_mask(vertices, faces, max_extent, area_rtol)
    if degenerate.all():
        raise error(
            f"{what}: all {len(faces)} faces are degenerate (repeated vertex index or zero area); "
            "the mesh has no surface"
        )
    return lo, hi, degenerate


def _provenance(mesh: trimesh.Trimesh) -> dict[str, Any]:
    """A fresh copy of the mesh's provenance dictionary, with defaults for missing keys."""
    old = dict(mesh.metadata.get(METADATA_KEY, {}))
    return {
        "source": old.get("source"),
        "n_degenerate_faces_dropped": int(old.get("n_degenerate_faces_dropped", 0)),
        "n_unreferenced_vertices_dropped": int(old.get("n_unreferenced_vertices_dropped", 0)),
        "center": list(old.get("center", [0.0, 0.0, 0.0])),
        "scale": float(old.get("scale", 1.0)),
    }


def _drop_faces(
    vertices: NDArray[np.float64], faces: NDArray[np.int64], keep: NDArray[np.bool_]
) -> tuple[NDArray[np.float64], NDArray[np.int64], int]:
    """Keep ``faces[keep]`` in their order and only the vertices they use, in their order."""
    faces = faces[keep]
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    remap = np.cumsum(used) - 1
    return vertices[used], remap[faces].astype(np.int64), int(len(vertices) - used.sum())


def _normalised(
    vertices: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    # Sryamkin et al. 2023, §4.1: centre of the axis-aligned bounding box to the origin,
    # then one uniform scale so that the largest side is 1 (aspect ratio preserved).
    center = (lo + hi) / 2.0
    scale = 1.0 / float((hi - lo).max())
    return (vertices - center) * scale, center, scale


def _as_arrays(mesh: trimesh.Trimesh) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    if not isinstance(mesh, trimesh.Trimesh):
        raise InvalidInputError(f"expected a trimesh.Trimesh, got {type(mesh).__name__}")
    vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if faces.size == 0:
        faces = faces.reshape(0, 3)
    return vertices, faces


def _make(
    vertices: NDArray[np.float64], faces: NDArray[np.int64], metadata: dict[str, Any], provenance: dict[str, Any]
) -> trimesh.Trimesh:
    # process=False: merging duplicated vertices would change ModelNet's triangle soup,
    # and faces must stay in file order so that face_index means the same everywhere.
    out = trimesh.Trimesh(vertices=vertices, faces=faces, process=False, validate=False)
    out.metadata.update({k: v for k, v in metadata.items() if k != METADATA_KEY})
    out.metadata[METADATA_KEY] = provenance
    return out


def _check_rtol(area_rtol: float) -> None:
    if not (np.isfinite(area_rtol) and area_rtol >= 0.0):
        raise InvalidInputError(f"area_rtol must be finite and >= 0, got {area_rtol}")


def degenerate_faces(mesh: trimesh.Trimesh, *, area_rtol: float = DEGENERATE_AREA_RTOL) -> NDArray[np.bool_]:
    """Which faces are degenerate.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    area_rtol : float
        A face with area ``<= area_rtol * max_extent**2`` is degenerate, where
        ``max_extent`` is the largest side of the bounding box of the referenced
        vertices (default :data:`DEGENERATE_AREA_RTOL`, scale invariant).

    Returns
    -------
    degenerate : (F,) bool
        True for faces that repeat a vertex index or have (numerically) zero area.
        All True when every vertex coincides (zero extent); empty for a mesh without faces.

    Raises
    ------
    InvalidInputError
        If ``mesh`` is not a Trimesh, has face indices out of range or NaN/inf
        vertices, or ``area_rtol`` is negative or not finite.
    """
    _check_rtol(area_rtol)
    vertices, faces = _as_arrays(mesh)
    if len(faces) == 0:
        return np.zeros(0, dtype=bool)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InvalidInputError(f"mesh face indices span [{faces.min()}, {faces.max()}] for {len(vertices)} vertices")
    _check_coordinates(vertices, what="mesh", error=InvalidInputError)
    lo, hi = _referenced_extent(vertices, faces)
    return _degenerate_mask(vertices, faces, float((hi - lo).max()), area_rtol)


def clean_mesh(mesh: trimesh.Trimesh, *, area_rtol: float = DEGENERATE_AREA_RTOL) -> trimesh.Trimesh:
    """A copy of ``mesh`` without degenerate faces and unreferenced vertices.

    The kept faces and vertices stay in their order; duplicated vertices are *not*
    merged and the mesh need not be watertight.  The numbers of dropped faces and
    vertices are added to ``metadata["zbuf_occlude"]`` (see the module docstring).

    Parameters
    ----------
    mesh : trimesh.Trimesh
    area_rtol : float
        See :func:`degenerate_faces`.

    Returns
    -------
    mesh : trimesh.Trimesh
        New mesh; vertices (V', 3) float64, faces (F', 3) int64.

    Raises
    ------
    InvalidInputError
        If the mesh is empty, has no faces, has NaN/inf vertices, face indices out of
        range, zero extent, or only degenerate faces; or ``area_rtol`` is negative
        or not finite.
    """
    _check_rtol(area_rtol)
    vertices, faces = _as_arrays(mesh)
    _, _, degenerate = _check(vertices, faces, what="mesh", error=InvalidInputError, area_rtol=area_rtol)
    vertices, faces, n_unref = _drop_faces(vertices, faces, ~degenerate)
    prov = _provenance(mesh)
    prov["n_degenerate_faces_dropped"] += int(degenerate.sum())
    prov["n_unreferenced_vertices_dropped"] += n_unref
    return _make(vertices, faces, mesh.metadata, prov)


def normalize_mesh(mesh: trimesh.Trimesh, *, area_rtol: float = DEGENERATE_AREA_RTOL) -> trimesh.Trimesh:
    """A copy of ``mesh`` centred and scaled to the unit box (Sryamkin et al. 2023, §4.1).

    The centre of the axis-aligned bounding box of the referenced vertices moves to the
    origin and one uniform scale makes the largest side 1.  Faces and vertices are
    kept as they are (use :func:`clean_mesh` to drop degenerate faces); unreferenced
    vertices are transformed too but do not count for the bounding box.

    ``metadata["zbuf_occlude"]["center"]`` and ``["scale"]`` are composed with any
    earlier normalisation, so they always map back to the source file's units:
    ``normalised = (original - center) * scale``.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    area_rtol : float
        Only used for the check that not every face is degenerate; see
        :func:`degenerate_faces`.

    Returns
    -------
    mesh : trimesh.Trimesh
        New mesh; vertices (V, 3) float64 with bounding box centre 0 and max extent 1.

    Raises
    ------
    InvalidInputError
        Same checks as :func:`clean_mesh`.
    """
    _check_rtol(area_rtol)
    vertices, faces = _as_arrays(mesh)
    lo, hi, _ = _check(vertices, faces, what="mesh", error=InvalidInputError, area_rtol=area_rtol)
    new_vertices, center, scale = _normalised(vertices, lo, hi)
    prov = _provenance(mesh)
    # Compose with the earlier map x1 = (x0 - c0) * s0:  x2 = (x1 - c1) * s1
    # = (x0 - (c0 + c1 / s0)) * (s0 * s1).
    old_center, old_scale = np.asarray(prov["center"], dtype=np.float64), prov["scale"]
    prov["center"] = (old_center + center / old_scale).tolist()
    prov["scale"] = old_scale * scale
    return _make(new_vertices, faces, mesh.metadata, prov)


def _off_layout(text: str) -> tuple[str, int, int, list[str]]:
    """Header keyword, declared vertex and face counts, and the data lines of OFF text.

    Comments (``#`` to the end of the line) and blank lines are dropped.  The counts may
    follow the keyword on its own line (ModelNet40's ``OFF3514 3546 0``).

    Raises
    ------
    _Malformed
        No count line, or counts that are not non-negative integers.
    """
    lines = [line.split("#", 1)[0].strip() for line in text.splitlines()]
    lines = [line for line in lines if line]
    head = lines[0] if lines else ""
    end = head.upper().find("OFF")
    if end < 0:
        raise _NotOff(f"no OFF header, first line is {head[:40]!r}" if head else "file is empty")
    end += len("OFF")
    if head[end:].strip():
        counts, body = head[end:].split(), lines[1:]
    elif len(lines) > 1:
        counts, body = lines[1].split(), lines[2:]
    else:
        raise _Malformed("the OFF header has no vertex and face counts")
    try:
        n_vertices, n_faces = int(counts[0]), int(counts[1])
    except (IndexError, ValueError):
        raise _Malformed(f"the OFF count line must be 'VERTICES FACES [EDGES]', got {' '.join(counts)[:60]!r}") from None
    if n_vertices < 0 or n_faces < 0:
        raise _Malformed(f"the OFF header declares negative counts ({n_vertices} vertices, {n_faces} faces)")
    return head[:end], n_vertices, n_faces, body


def _off_line_problem(body: list[str], index: int, n_vertices: int) -> str | None:
    """Why data line ``index`` of an OFF body is malformed, or None if it is fine."""
    tokens = body[index].split()
    if index < n_vertices:
        if len(tokens) < 3:
            return f"vertex {index} has {len(tokens)} coordinates, expected 3"
        return None
    face = index - n_vertices
    try:
        n_corners = int(tokens[0])
    except ValueError:
        return f"face {face} starts with {tokens[0]!r}, expected its corner count"
    if len(tokens) < 1 + n_corners:
        return f"face {face} lists {len(tokens) - 1} of its {n_corners} corners"
    return None


def _check_off_counts(text: str) -> tuple[int, int]:
    """Compare the vertex and face counts an OFF file declares with what it holds.

    trimesh reads the first ``V`` and ``F`` data lines whatever is there, so a file cut
    short in its face list loads as part of the object.  Only the last vertex and face
    lines are inspected (truncation cuts at the end; a full scan is done when trimesh
    fails, by :func:`_off_first_problem`).

    Returns
    -------
    n_vertices, n_faces : int
        The declared counts.

    Raises
    ------
    _Malformed
        With both numbers, when the file holds fewer vertices or faces than declared or
        its last line is cut.
    """
    _, n_vertices, n_faces, body = _off_layout(text)
    if len(body) < n_vertices:
        raise _Malformed(
            f"declares {n_vertices:,} vertices and {n_faces:,} faces but holds only {len(body):,} vertices "
            "and no faces; the file is cut short"
        )
    found = len(body) - n_vertices
    if found < n_faces:
        raise _Malformed(f"declares {n_faces:,} faces but holds {found:,}; the file is cut short")
    for index in (n_vertices - 1, n_vertices + n_faces - 1):
        problem = _off_line_problem(body, index, n_vertices) if index >= 0 else None
        if problem:
            raise _Malformed(f"{problem} (declared {n_vertices:,} vertices, {n_faces:,} faces); the file is cut short")
    return n_vertices, n_faces


def _off_first_problem(text: str) -> str | None:
    """The first malformed vertex or face line of OFF text, described; None if none is."""
    try:
        _, n_vertices, n_faces, body = _off_layout(text)
    except ValueError as exc:
        return str(exc)
    for index in range(min(len(body), n_vertices + n_faces)):
        problem = _off_line_problem(body, index, n_vertices)
        if problem:
            return problem
    return None


def _fan_triangulate_off(text: str) -> str | None:
    """OFF text with every polygon of more than 4 corners replaced by a triangle fan.

    Returns None when there is no such polygon or the structure cannot be read (the
    caller then reports trimesh's own error).
    """
    try:
        keyword, n_vertices, n_faces, body = _off_layout(text)
        faces, n_fanned = [], 0
        for line in body[n_vertices : n_vertices + n_faces]:
            tokens = line.split()
            corners = tokens[1 : 1 + int(tokens[0])]
            if len(corners) > 4:
                n_fanned += 1
                # the same fan trimesh builds: (c0, ci, ci+1)
                faces.extend(f"3 {corners[0]} {a} {b}" for a, b in zip(corners[1:-1], corners[2:]))
            else:
                faces.append(" ".join([str(len(corners)), *corners]))
    except (IndexError, ValueError):
        return None
    if n_fanned == 0:
        return None
    return "\n".join([keyword, f"{n_vertices} {len(faces)} 0", *body[:n_vertices], *faces]) + "\n"


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


def _check_ply_counts(raw: bytes, mesh: trimesh.Trimesh) -> None:
    """Raise _Malformed when a PLY holds fewer vertices or faces than its header declares.

    trimesh reads an ASCII PLY cut short in its face list without complaint (1,551 of a
    chair's 2,234 faces).  Polygons become one or more triangles, so fewer faces than
    declared means lines are missing.
    """
    header = raw[: raw.find(b"end_header")].decode("utf-8", "replace")
    declared = {m.group(1): int(m.group(2)) for m in re.finditer(r"^element\s+(vertex|face)\s+(\d+)", header, re.M)}
    n_vertices, n_faces = declared.get("vertex"), declared.get("face")
    if (n_vertices is not None and len(mesh.vertices) < n_vertices) or (n_faces is not None and len(mesh.faces) < n_faces):
        raise _Malformed(
            f"declares {n_vertices or 0:,} vertices and {n_faces or 0:,} faces but holds {len(mesh.vertices):,} "
            f"vertices and {len(mesh.faces):,} faces; the file is cut short"
        )


#: Binary STL: 80-byte header, uint32 triangle count, then 50 bytes per triangle.
_STL_HEADER_BYTES, _STL_TRIANGLE_BYTES = 84, 50


def _check_binary_stl_length(raw: bytes) -> None:
    """Raise _Malformed when a binary STL is shorter than its triangle count says.

    ASCII STL starts with ``solid``; a binary file that does is judged by its length.
    """
    if len(raw) < _STL_HEADER_BYTES:
        return  # trimesh reports it (empty or not an STL)
    n_triangles = int.from_bytes(raw[80:84], "little")
    expected = _STL_HEADER_BYTES + _STL_TRIANGLE_BYTES * n_triangles
    if raw[:5].lower() == b"solid" and b"facet" in raw[:1024]:
        return  # ASCII
    if len(raw) < expected:
        found = (len(raw) - _STL_HEADER_BYTES) // _STL_TRIANGLE_BYTES
        raise _Malformed(
            f"binary STL declares {n_triangles:,} triangles ({expected:,} bytes) but holds {found:,} "
            f"({len(raw):,} bytes); the file is cut short"
        )


def _read(path: Path, file_type: str) -> trimesh.Trimesh:
    """Parse ``path`` with trimesh into one Trimesh; scenes are flattened with transforms."""
    if file_type == "ply":
        raw = _utf8_ply_header(path.read_bytes())
        mesh = _to_mesh(trimesh.load_scene(io.BytesIO(raw), file_type="ply", process=False))
        _check_ply_counts(raw, mesh)
        return mesh
    if file_type == "stl":
        _check_binary_stl_length(path.read_bytes())
    if file_type != "off":
        return _to_mesh(trimesh.load_scene(str(path), file_type=file_type, process=False))
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        # trimesh decodes non-UTF-8 text with the optional charset_normalizer and fails
        # with ModuleNotFoundError without it.  OFF is ASCII numbers, so Latin-1 (which
        # decodes any byte) is a safe fallback.
        text = raw.decode("latin-1")
        raw = text.encode("utf-8")
    # trimesh splits at the first "OFF" anywhere in the text, so garbage would fail
    # later with an unrelated message.  The header may carry a prefix (COFF, NOFF, ...)
    # and, in ModelNet40, the counts on the same line ("OFF3514 3546 0"), which trimesh
    # parses correctly.
    lines = (line.strip() for line in text.splitlines())
    first = next((line for line in lines if line and not line.startswith("#")), "")
    if "OFF" not in first[: _OFF_HEADER_MAX_PREFIX + len("OFF")].upper():
        raise _NotOff(f"no OFF header, first line is {first[:40]!r}" if first else "file is empty")
    _, n_faces = _check_off_counts(text)
    try:
        mesh = _to_mesh(trimesh.load_scene(io.BytesIO(raw), file_type="off", process=False))
    except Exception:
        # A malformed line in the middle (trimesh says "inhomogeneous shape"): name it.
        problem = _off_first_problem(text)
        if problem:
            raise _Malformed(problem) from None
        # trimesh 5.2 fails (TypeError from numpy string multiply) when polygons of more
        # than 4 corners are mixed with triangles or quads: it fans them while the
        # indices are still strings.  Fan them here, as trimesh would, and retry once.
        fixed = _fan_triangulate_off(text)
        if fixed is None:
            raise
        return _to_mesh(trimesh.load_scene(io.BytesIO(fixed.encode("utf-8")), file_type="off", process=False))
    if len(mesh.faces) < n_faces:
        # Every polygon gives at least one triangle: trimesh dropped malformed face lines.
        problem = _off_first_problem(text)
        raise _Malformed(
            (problem or f"declares {n_faces:,} faces but only {len(mesh.faces):,} could be read")
            + f" ({len(mesh.faces):,} of {n_faces:,} faces read)"
        )
    return mesh


def _to_mesh(scene: trimesh.Scene) -> trimesh.Trimesh:
    # Scene.to_mesh() concatenates every Trimesh of a scene (GLB) with its node
    # transform baked in, and drops points and paths.  process=False at load keeps
    # vertex and face order as in the file (no merging of ModelNet's duplicated vertices).
    mesh = scene.to_mesh()
    if len(mesh.faces) == 0:
        n_points = sum(len(g.vertices) for g in scene.geometry.values() if isinstance(g, trimesh.PointCloud))
        if n_points:
            raise _NotMesh(f"holds a point cloud of {n_points} points and no faces; a point cloud is not a mesh")
    return mesh


def load_mesh(
    path: str | PathLike[str], *, normalize: bool = True, area_rtol: float = DEGENERATE_AREA_RTOL
) -> trimesh.Trimesh:
    """Load a triangle mesh from OFF, OBJ, PLY, STL or GLB, cleaned and normalised.

    Steps: parse with trimesh (polygons are fan-triangulated, scenes flattened with
    their transforms), check, drop degenerate faces and unreferenced vertices
    (:func:`clean_mesh`), then, if ``normalize``, centre and scale to the unit box as
    in Sryamkin et al. 2023, §4.1 (:func:`normalize_mesh`).  Duplicated vertices are
    kept and the mesh need not be watertight or manifold.  GLB files are read as
    stored: glTF is y-up and no axis conversion is done.

    Parameters
    ----------
    path : str or PathLike
        Mesh file; the format comes from the extension (case-insensitive), see
        :data:`SUPPORTED_EXTENSIONS`.
    normalize : bool
        Centre the bounding box on the origin and scale the max extent to 1.
    area_rtol : float
        Relative area below which a face is degenerate; see :func:`degenerate_faces`.

    Returns
    -------
    mesh : trimesh.Trimesh
        vertices (V, 3) float64, faces (F, 3) int64, in file order minus dropped ones.
        ``mesh.metadata["zbuf_occlude"]`` holds the provenance (module docstring).

    Raises
    ------
    MeshLoadError
        With the file name and cause: missing file, a directory, unsupported
        extension, unreadable or unparsable content, no vertices or no faces,
        NaN/inf vertices, face indices out of range, zero extent (all vertices
        coincide) or only degenerate faces.
    InvalidInputError
        If ``area_rtol`` is negative or not finite.
    """
    _check_rtol(area_rtol)
    path = Path(path)
    if not path.exists():
        raise MeshLoadError(f"{path}: no such file")
    if path.is_dir():
        raise MeshLoadError(f"{path}: is a directory, expected a mesh file")
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_EXTENSIONS:
        raise MeshLoadError(
            f"{path}: unsupported extension {path.suffix!r}; use one of {', '.join(SUPPORTED_EXTENSIONS)}"
        )
    file_type = SUPPORTED_EXTENSIONS[suffix]
    try:
        loaded = _read(path, file_type)
    except OSError as exc:
        raise MeshLoadError(f"{path}: cannot read file ({exc.strerror or exc})") from exc
    except MemoryError:
        raise
    except _NotOff as exc:
        raise MeshLoadError(f"{path}: not an OFF file ({exc})") from exc
    except _NotMesh as exc:
        raise MeshLoadError(f"{path}: {exc}") from exc
    except _Malformed as exc:
        raise MeshLoadError(f"{path}: cannot parse as {file_type.upper()}: {exc}") from exc
    except Exception as exc:  # trimesh raises a zoo of types (ValueError, IndexError, NameError, KeyError, ...)
        raise MeshLoadError(
            f"{path}: cannot parse as {file_type.upper()} ({type(exc).__name__}: {exc})"
        ) from exc

    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshLoadError(f"{path}: trimesh returned a {type(loaded).__name__}, not a triangle mesh")
    vertices, faces = _as_arrays(loaded)
    _, _, degenerate = _check(vertices, faces, what=str(path), error=MeshLoadError, area_rtol=area_rtol)
    n_degenerate = int(degenerate.sum())
    if n_degenerate:
        log.debug("%s: dropping %d degenerate faces of %d", path, n_degenerate, len(faces))
    vertices, faces, n_unref = _drop_faces(vertices, faces, ~degenerate)
    prov = {
        "source": str(path),
        "n_degenerate_faces_dropped": n_degenerate,
        "n_unreferenced_vertices_dropped": n_unref,
        "center": [0.0, 0.0, 0.0],
        "scale": 1.0,
    }
    if normalize:
        # Dropping degenerate faces never empties the mesh (checked above), so the
        # bounds of the kept vertices are finite and, being a superset of a
        # non-degenerate face, of positive extent.
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        vertices, center, scale = _normalised(vertices, lo, hi)
        prov["center"], prov["scale"] = center.tolist(), scale
    return _make(vertices, faces, loaded.metadata, prov)


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
