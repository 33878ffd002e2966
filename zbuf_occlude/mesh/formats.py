"""What trimesh's readers miss: structure checks of OFF, PLY and STL, and their encodings.

trimesh parses; this module makes sure the result is the whole file.  OFF and PLY declare
their vertex and face counts and binary STL its triangle count: fewer found than declared
(a file cut short, a face line missing corners) is an error with both numbers instead of a
partial mesh or numpy's "inhomogeneous shape".  Non-UTF-8 comments are decoded (OFF,
PLY headers) instead of failing, and OFF polygons of more than four corners mixed with
triangles, which trimesh 5.2 cannot read, are fanned first.
"""

from __future__ import annotations

import base64
import importlib.util
import io
import itertools
import logging
import re
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.mesh.flatten import flatten_scene
from zbuf_occlude.mesh.limits import check_collada_declared_sizes, check_gltf_declared_sizes
from zbuf_occlude.mesh.named_files import folder_resolver, read_regular_file

log = logging.getLogger(__name__)

if TYPE_CHECKING:  # trimesh (and scipy with it) is imported by the readers below, when a file is read
    import trimesh

__all__ = ["EXTENSIONS_TEXT", "FORMAT_EXTRAS", "SUPPORTED_EXTENSIONS", "ply_declared_counts", "read_trimesh"]

#: File extensions load_mesh accepts (lower case), mapped to trimesh's file type.
SUPPORTED_EXTENSIONS: dict[str, str] = {
    ".off": "off",
    ".obj": "obj",
    ".ply": "ply",
    ".stl": "stl",
    ".glb": "glb",
    ".gltf": "gltf",
    ".dae": "dae",
}
#: The extensions as the help of every command lists them (".off, .obj, ...").
EXTENSIONS_TEXT = ", ".join(SUPPORTED_EXTENSIONS)

#: The optional package each format needs beyond trimesh, and the extra that installs it.
FORMAT_EXTRAS: dict[str, tuple[str, str]] = {"dae": ("collada", "collada")}

#: Longest prefix before "OFF" on the header line (COFF, NOFF, STOFF, 4OFF, CNOFF ...).
_OFF_HEADER_MAX_PREFIX = 4


class _NotOff(ValueError):
    """The file does not start with an OFF header."""


class _NotMesh(ValueError):
    """The file parsed but holds no triangle mesh."""


class _NeedsExtra(ValueError):
    """The format needs an optional package that is not installed."""


class _Malformed(ValueError):
    """The file's structure contradicts itself (counts declared vs found, cut lines)."""


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
                faces.extend(f"3 {corners[0]} {a} {b}" for a, b in itertools.pairwise(corners[1:]))
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


def ply_declared_counts(raw: bytes) -> dict[str, int]:
    """The element counts a PLY header declares, e.g. ``{"vertex": 10, "face": 12}`` (empty without a header)."""
    end = raw.find(b"end_header")
    header = raw[: max(end, 0)].decode("utf-8", "replace")
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^element\s+(\w+)\s+(\d+)", header, re.MULTILINE)}


def _check_ply_counts(raw: bytes, mesh: trimesh.Trimesh) -> None:
    """Raise _Malformed when a PLY holds fewer vertices or faces than its header declares.

    trimesh reads an ASCII PLY cut short in its face list without complaint (1,551 of a
    chair's 2,234 faces).  Polygons become one or more triangles, so fewer faces than
    declared means lines are missing.
    """
    declared = ply_declared_counts(raw)
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


#: A 1×1 grey PNG: what every image a COLLADA file names resolves to.
_BLANK_PNG = base64.b64decode("iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAAAAAA6fptVAAAACklEQVR4nGNgAAAAAgABSK+kcQAAAABJRU5ErkJggg==")


def _no_textures_resolver():
    """A trimesh resolver that reads no file: every texture a COLLADA file names is one blank pixel.

    Only the geometry is used, so textures are not loaded: a missing image (Gazebo models name
    textures in other folders) would otherwise make trimesh log a warning with a whole
    traceback per material, and a file could make the loader open paths of its choosing.
    """
    import trimesh

    class _NoTextures(trimesh.resolvers.Resolver):
        def __init__(self) -> None:  # no folder: nothing to resolve against
            pass

        def get(self, name: str) -> bytes:
            return _BLANK_PNG

        def keys(self):
            return iter(())

        def namespaced(self, namespace: str):
            return self

        def write(self, name: str, data) -> None:
            raise NotImplementedError("reading only")

    return _NoTextures()


#: An OBJ face corner: ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``; the vertex index is the first number.
_OBJ_FACE_LINE = re.compile(rb"^[ \t]*f[ \t]+([^\r\n#]*)", re.MULTILINE)


def _check_obj_indices(raw: bytes) -> None:
    """Raise _Malformed on an OBJ face corner with index 0.

    OBJ indices start at 1 (negative ones count back from the last vertex); trimesh reads a
    0 as the first vertex, so ``f 0 4 5`` loads as another face instead of an error.
    """
    for match in _OBJ_FACE_LINE.finditer(raw):
        for corner in match.group(1).split():
            first = corner.split(b"/", 1)[0]
            if first.lstrip(b"+-").isdigit() and int(first) == 0:
                line = raw.count(b"\n", 0, match.start()) + 1
                raise _Malformed(f"line {line}: face {match.group(0).strip().decode('latin-1')[:60]!r} uses vertex index 0 (OBJ indices start at 1)")


def _warn_bind_pose(doc: Mapping[str, Any] | None, path: Path) -> None:
    """Log a warning naming ``path`` when its glTF ``doc`` has skinned mesh nodes: trimesh applies
    neither skins nor animations, so such a character (a simulator's pedestrian) loads in the pose
    it was modelled in, often a T-pose with the arms out, not as it stands or walks."""
    nodes = doc.get("nodes") if doc is not None else None
    skinned = sum(isinstance(n, dict) and "mesh" in n and "skin" in n for n in nodes) if isinstance(nodes, list) else 0
    if skinned:
        log.warning("%s: %d skinned mesh node(s) load in their bind pose (often a T-pose): skins and animations are not applied",
                    path, skinned)  # fmt: skip


def _read(path: Path, file_type: str) -> trimesh.Trimesh:
    """Parse ``path`` with trimesh into one Trimesh; scenes are flattened with transforms.

    The file and every file it names are read through :mod:`zbuf_occlude.mesh.named_files`
    (regular files only, inside the file's folder, size capped); glTF's and COLLADA's declared
    sizes are checked (:mod:`zbuf_occlude.mesh.limits`) before trimesh allocates them, and the
    scene is flattened in linear time (:mod:`zbuf_occlude.mesh.flatten`).
    """
    import trimesh

    raw = read_regular_file(path)
    if file_type == "ply":
        raw = _utf8_ply_header(raw)
        mesh = _to_mesh(trimesh.load_scene(io.BytesIO(raw), file_type="ply", process=False))
        _check_ply_counts(raw, mesh)
        return mesh
    if file_type == "stl":
        _check_binary_stl_length(raw)
    if file_type in FORMAT_EXTRAS:
        module, extra = FORMAT_EXTRAS[file_type]
        if importlib.util.find_spec(module) is None:
            raise _NeedsExtra(f"reading {file_type.upper()} needs the {module!r} package: pip install 'zbuf-occlude[{extra}]'")
    if file_type in ("gltf", "glb"):
        _warn_bind_pose(check_gltf_declared_sizes(raw, path), path)
    if file_type == "obj":
        _check_obj_indices(raw)
    if file_type == "dae":  # textures are not needed: never read (_no_textures_resolver)
        check_collada_declared_sizes(raw, path)
        # the bytes just checked, not the file read again (it could have changed in between)
        return _to_mesh(trimesh.load_scene(io.BytesIO(raw), file_type=file_type, process=False, resolver=_no_textures_resolver()))
    if file_type != "off":
        scene = trimesh.load_scene(io.BytesIO(raw), file_type=file_type, resolver=folder_resolver(path), process=False)
        return _to_mesh(scene)
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
    import trimesh

    # flatten_scene concatenates every Trimesh of a scene (GLB) with its node transform
    # baked in, and drops points and paths: Scene.to_mesh() in time linear in the nodes.
    # process=False at load keeps vertex and face order as in the file (no merging of
    # ModelNet's duplicated vertices).
    mesh = flatten_scene(scene)
    if len(mesh.faces) == 0:
        n_points = sum(len(g.vertices) for g in scene.geometry.values() if isinstance(g, trimesh.PointCloud))
        if n_points:
            raise _NotMesh(f"holds a point cloud of {n_points} points and no faces; a point cloud is not a mesh")
    return mesh


def read_trimesh(path: Path, file_type: str) -> trimesh.Trimesh:
    """Parse ``path`` with trimesh into one Trimesh (scenes flattened with their transforms).

    Parameters
    ----------
    path : Path
        The file.
    file_type : str
        A value of :data:`SUPPORTED_EXTENSIONS`.

    Returns
    -------
    mesh : trimesh.Trimesh
        As parsed (``process=False``): vertices and faces in file order.

    Raises
    ------
    MeshLoadError
        Naming the file: not an OFF file, a point cloud and no faces, fewer vertices or
        faces than declared, a vertex or face line cut short.
    OSError
        The file cannot be read.
    Exception
        Whatever trimesh raises on content it cannot parse (a zoo of types);
        :func:`zbuf_occlude.mesh.load.load_mesh` reports it with the file name.
    """
    try:
        return _read(path, file_type)
    except _NotOff as exc:
        raise MeshLoadError(f"{path}: not an OFF file ({exc})") from exc
    except (_NotMesh, _NeedsExtra) as exc:
        raise MeshLoadError(f"{path}: {exc}") from exc
    except _Malformed as exc:
        raise MeshLoadError(f"{path}: cannot parse as {file_type.upper()}: {exc}") from exc
