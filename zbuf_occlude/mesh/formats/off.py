"""OFF (Object File Format, ModelNet's): the header and the declared counts checked, non-UTF-8 text read.

trimesh reads the first ``V`` and ``F`` data lines whatever is there, so a file cut short loads
as part of the object; here the vertex and face counts the header declares are compared with
what the file holds first (fewer found is an error with both numbers instead of a partial mesh
or numpy's "inhomogeneous shape").  Non-UTF-8 comments are decoded instead of failing, and
polygons of more than four corners mixed with triangles, which trimesh 5.2 cannot read, are
fanned first.  A plain file (ModelNet's: ``OFF``, the counts, ``x y z`` and ``3 a b c`` lines) is
parsed in one vectorised pass into the same arrays; anything else goes through trimesh.
"""

from __future__ import annotations

import functools
import itertools
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.mesh.flatten import flatten_scene
from zbuf_occlude.mesh.formats.base import Format, malformed, parse

if TYPE_CHECKING:
    import trimesh

__all__ = ["FORMATS", "check_off", "read_off"]

#: Longest prefix before "OFF" on the header line (COFF, NOFF, STOFF, 4OFF, CNOFF ...).
_OFF_HEADER_MAX_PREFIX = 4


#: Bytes of a plain OFF file's vertex lines and, without ``+-.eE``, of its face lines.
_NUMBER_BYTES = b"0123456789+-.eE \t\r\n"
_INDEX_BYTES = b"0123456789 \t\r\n"
_WHITESPACE = np.zeros(256, dtype=bool)
_WHITESPACE[list(b" \t\r\n")] = True
#: Longest vertex or face count the one-pass parse reads (Python's int() refuses past 4,300 digits).
_MAX_COUNT_DIGITS = 18


class _NotOff(ValueError):
    """The file does not start with an OFF header."""


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
        raise _NotOff("no OFF header: the first line that is not blank or a comment does not start with OFF" if head else "file is empty")
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
        raise _Malformed("the OFF count line must be 'VERTICES FACES [EDGES]', two or three integers") from None
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
        return f"face {face} does not start with its corner count (an integer)"
    if len(tokens) < 1 + n_corners:
        return f"face {face} lists {len(tokens) - 1} of its {n_corners} corners"
    corners = [int(t) for t in tokens[1 : 1 + n_corners] if t.lstrip("+-").isdigit()]
    if any(not 0 <= c < n_vertices for c in corners):
        return f"face {face} names a vertex outside the range of the {n_vertices:,} vertices (0 to {n_vertices - 1:,})"
    return None


def _check_off_counts(text: str) -> tuple[int, int]:
    """Compare the vertex and face counts an OFF file declares with what it holds.

    Only the last vertex and face lines are inspected (truncation cuts at the end; a full
    scan is done when trimesh fails, by :func:`_off_first_problem`).

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


def _plain_counts(raw: bytes) -> tuple[int, int, int] | None:
    """``(n_vertices, n_faces, body_start)`` of an OFF file whose first line is ``OFF`` and whose
    second is ``V F [E]``, or ``OFF`` directly followed by those counts; None for any other start."""
    first_end = raw.find(b"\n")
    if not raw.startswith(b"OFF") or first_end < 0:
        return None
    head, body_start = raw[3:first_end], first_end + 1
    if not head.strip(b" \t\r"):
        second_end = raw.find(b"\n", body_start)
        if second_end < 0:
            return None
        head, body_start = raw[body_start:second_end], second_end + 1
    counts = head.split()
    if len(counts) not in (2, 3) or not all(c.isdigit() and len(c) <= _MAX_COUNT_DIGITS for c in counts):
        return None
    return int(counts[0]), int(counts[1]), body_start


@functools.lru_cache(maxsize=1)  # check_off, then read_off, on the same bytes
def _plain_off(raw: bytes) -> tuple[NDArray[np.float64], NDArray[np.int64]] | None:
    """Vertices and triangles of a plain OFF file, in one vectorised pass; None for any other file.

    Plain: ASCII without comments or carriage returns but before a line feed, the header of
    :func:`_plain_counts`, then exactly the declared lines (blank lines aside), each vertex ``x y z`` and each face ``3 a b c``
    of decimal indices below the vertex count, every coordinate finite.  These are parsed as
    trimesh parses them, bit for bit (the same strings converted by numpy); any other file,
    hostile ones included, goes to trimesh and the checks above, which give its errors.
    The arrays are read-only (cached): copy them.
    """
    # \r only in \r\n, where it is whitespace at a line's end (alone, str.splitlines breaks there)
    counts = _plain_counts(raw) if raw.isascii() and b"#" not in raw and raw.count(b"\r") == raw.count(b"\r\n") else None
    if counts is None:
        return None
    n_vertices, n_faces, body_start = counts
    body = raw[body_start:]
    if n_vertices == 0 or n_faces == 0 or body.translate(None, _NUMBER_BYTES):
        return None
    byte = np.frombuffer(body, dtype=np.uint8)
    space = _WHITESPACE[byte]
    starts = np.flatnonzero(~space & np.concatenate(([True], space[:-1])))  # first byte of each token
    line_of_token = np.cumsum(byte == ord("\n"))[starts]
    tokens_per_line = np.bincount(line_of_token)
    tokens_per_line = tokens_per_line[tokens_per_line > 0]
    if len(tokens_per_line) != n_vertices + n_faces:  # before anything of the declared sizes is allocated
        return None
    if (tokens_per_line[:n_vertices] != 3).any() or (tokens_per_line[n_vertices:] != 4).any():
        return None
    if body[starts[3 * n_vertices] :].translate(None, _INDEX_BYTES):
        return None
    tokens = body.split()
    try:
        vertices = np.array(tokens[: 3 * n_vertices], dtype=np.float64).reshape(n_vertices, 3)
        faces = np.array(tokens[3 * n_vertices :], dtype=np.int64).reshape(n_faces, 4)
    except (ValueError, OverflowError):  # an index past int64: the checks name its face
        return None
    if not (faces[:, 0] == 3).all() or faces[:, 1:].max() >= n_vertices or not np.isfinite(vertices).all():
        return None
    faces = np.ascontiguousarray(faces[:, 1:])
    vertices.flags.writeable = faces.flags.writeable = False
    return vertices, faces


def _plain_mesh(vertices: NDArray[np.float64], faces: NDArray[np.int64]) -> trimesh.Trimesh:
    """The mesh :func:`~zbuf_occlude.mesh.formats.base.parse` gives for the same vertices and faces."""
    import trimesh

    return flatten_scene(trimesh.Scene(trimesh.Trimesh(vertices=vertices.copy(), faces=faces.copy(), process=False)))


def _off_text(raw: bytes) -> tuple[str, bytes]:
    """The file's text, and its bytes as UTF-8 (what trimesh is given)."""
    try:
        return raw.decode("utf-8"), raw
    except UnicodeDecodeError:
        # trimesh decodes non-UTF-8 text with the optional charset_normalizer and fails
        # with ModuleNotFoundError without it.  OFF is ASCII numbers, so Latin-1 (which
        # decodes any byte) is a safe fallback.
        text = raw.decode("latin-1")
        return text, text.encode("utf-8")


def check_off(raw: bytes, path: Path) -> None:
    """Refuse OFF bytes without an OFF header or holding fewer vertices or faces than declared.

    Raises
    ------
    MeshLoadError
        Naming ``path``: ``not an OFF file (...)``, no ``OFF`` keyword (after a prefix of at
        most four letters: COFF, NOFF, STOFF, ...) on the first line that is not a comment;
        ``cannot parse as OFF: ...``, a count line that cannot be read, fewer vertices or
        faces than declared, or a last vertex or face line cut short.
    """
    if _plain_off(raw) is not None:
        return
    text, _ = _off_text(raw)
    # trimesh splits at the first "OFF" anywhere in the text, so garbage would fail
    # later with an unrelated message.  The header may carry a prefix (COFF, NOFF, ...)
    # and, in ModelNet40, the counts on the same line ("OFF3514 3546 0"), which trimesh
    # parses correctly.
    lines = (line.strip() for line in text.splitlines())
    first = next((line for line in lines if line and not line.startswith("#")), "")
    try:
        if "OFF" not in first[: _OFF_HEADER_MAX_PREFIX + len("OFF")].upper():
            raise _NotOff(
                "no OFF header: the first line that is not blank or a comment does not start with OFF" if first else "file is empty"
            )
        _check_off_counts(text)
    except _NotOff as exc:
        raise MeshLoadError(f"{path}: not an OFF file ({exc})") from exc
    except _Malformed as exc:
        raise malformed(path, "off", exc) from exc


def read_off(raw: bytes, path: Path, file_type: str) -> trimesh.Trimesh:
    """An OFF file (checked by :func:`check_off`) parsed by trimesh; polygons are fanned.

    Raises
    ------
    MeshLoadError
        Naming ``path``: a malformed vertex or face line (the first one is named), fewer faces
        read than declared, a point cloud and no faces.
    Exception
        What trimesh raises when the file is neither of these and cannot be parsed.
    """
    plain = _plain_off(raw)
    if plain is not None:
        return _plain_mesh(*plain)
    text, raw = _off_text(raw)
    _, _, n_faces, _ = _off_layout(text)
    try:
        mesh = parse(raw, path, "off")
    except Exception:
        # A malformed line in the middle (trimesh says "inhomogeneous shape"): name it.
        problem = _off_first_problem(text)
        if problem:
            raise malformed(path, "off", problem) from None
        # trimesh 5.2 fails (TypeError from numpy string multiply) when polygons of more
        # than 4 corners are mixed with triangles or quads: it fans them while the
        # indices are still strings.  Fan them here, as trimesh would, and retry once.
        fixed = _fan_triangulate_off(text)
        if fixed is None:
            raise
        return parse(fixed.encode("utf-8"), path, "off")
    if len(mesh.faces) < n_faces:
        # Every polygon gives at least one triangle: trimesh dropped malformed face lines.
        problem = _off_first_problem(text)
        raise malformed(
            path,
            "off",
            (problem or f"declares {n_faces:,} faces but only {len(mesh.faces):,} could be read")
            + f" ({len(mesh.faces):,} of {n_faces:,} faces read)",
        )
    return mesh


FORMATS = (Format("off", (".off",), read=read_off, check=check_off),)
