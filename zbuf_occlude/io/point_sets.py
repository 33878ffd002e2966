"""Point sets from files: PointNet-layout HDF5, ``.npy`` arrays and ``.ply`` point clouds.

Most point-cloud data sets hold points and no mesh.  This module reads the files they come in,
every cloud of a file as a :class:`PointSet` (points, normals where the file has them, the
file's label where it has one):

``.h5``, ``.hdf5``
    PointNet's ``modelnet40_ply_hdf5_2048`` layout (Qi et al. 2017, and the loaders of DGCNN,
    PointNet++ and their successors): ``data (B, N, 3)`` floats, one cloud a row, ``label
    (B, 1)`` or ``(B,)`` integers, optional ``normal (B, N, 3)``; ShapeNetPart's files add
    ``pid`` (per-point parts, not read here).  ``data (B, N, 6)`` is read as coordinates and
    normals.  The class names are the lines of ``shape_names.txt`` beside the file
    (:func:`shape_names`).
``.npy``
    One cloud, ``(N, 3)`` coordinates or ``(N, 6)`` coordinates and normals, memory-mapped, never
    unpickled.
``.ply``
    One cloud: the ``vertex`` element of a PLY with no faces (ASCII or binary; read by trimesh),
    its ``nx ny nz`` properties as normals where all three are present.  A PLY with faces is a
    mesh (:func:`zbuf_occlude.mesh.load.load_mesh` reads it).

Every file is untrusted.  Nothing is executed or unpickled; an HDF5 file is read only after
:func:`zbuf_occlude.io.hdf5.check_hdf5` has found no link to another file, no virtual dataset
and no external storage; sizes are checked from headers before anything is read
(:data:`~zbuf_occlude.defaults.MAX_POINT_SET_POINTS` points a cloud, what occluding it costs
named when it holds more (:func:`occlusion_cost`),
:data:`~zbuf_occlude.io.caps.MAX_POINT_SET_BYTES` a read), and what a read will allocate is
checked against the memory available (:func:`zbuf_occlude.resources.check_memory`) before it
allocates; NaN or infinite coordinates are refused, and so are normals that are zero or not finite
(:func:`unit_normals`).  A class list beside a file is read only when it is a regular file inside
the file's folder, links resolved (a ``shape_names.txt`` that links elsewhere is refused).  Each
error is one
:class:`~zbuf_occlude.errors.InvalidInputError` (:class:`~zbuf_occlude.errors.DatasetFormatError`
for HDF5 files) naming the file.
"""

from __future__ import annotations

import io
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.defaults import MAX_POINT_SET_POINTS
from zbuf_occlude.errors import DatasetFormatError, InvalidInputError, ZbufOccludeError
from zbuf_occlude.io.arrays import check_npy_sizes, npy_header
from zbuf_occlude.io.caps import MAX_LIST_BYTES, MAX_NPY_HEADER_BYTES, MAX_POINT_SET_BYTES, MAX_POINT_SET_PLY_HEADER_BYTES
from zbuf_occlude.io.file_errors import dtype_text, parser_failure
from zbuf_occlude.io.hdf5 import open_hdf5
from zbuf_occlude.io.regular_files import open_regular_file, read_text_file
from zbuf_occlude.resources import check_memory

__all__ = [
    "stored_up", "UP_AXES",
    "POINT_SET_SUFFIXES", "SHAPE_NAME_FILES", "PointSet", "is_point_set_file", "read_point_sets",
    "point_set_labels", "shape_names", "unit_normals", "check_npy_header", "BYTES_PER_READ_POINT", "BYTES_PER_LABEL",
    "occlusion_cost", "OCCLUSION_BYTES_PER_POINT", "OCCLUSION_FIXED_BYTES", "OCCLUSION_PREPARE_SECONDS_PER_POINT", "OCCLUSION_POSE_SECONDS_PER_POINT",
]  # fmt: skip

#: Suffixes of the files read here (any case).
POINT_SET_SUFFIXES: tuple[str, ...] = (".h5", ".hdf5", ".npy", ".ply")
#: Class lists looked for beside an HDF5 file, in this order: PointNet's, PointNet++'s, and
#: ShapeNetPart's (``Airplane<TAB>02691156``: the first field).
SHAPE_NAME_FILES = ("shape_names.txt", "modelnet40_shape_names.txt", "all_object_categories.txt")
_HDF5 = (".h5", ".hdf5")
#: Columns of a cloud: coordinates, or coordinates and normals.
_COLUMNS = (3, 6)
_PLY_CHUNK_BYTES = 1 << 10
#: Most digits of an element count in a PLY header: 18 (below int64's 9.2e18, and far past every
#: cap); Python refuses to parse an integer of over 4,300 digits with a bare ValueError.
_PLY_COUNT_DIGITS = 18
#: Bytes a read allocates per point beyond the file's own values: the float64 coordinates and
#: unit normals a :class:`PointSet` keeps (24 + 24), and the float64 copy of the normals and
#: their lengths while they are made unit (24 + 8).
BYTES_PER_READ_POINT = 80
#: Bytes per cloud of reading a file's labels (:func:`point_set_labels`): the int64 array, and
#: the list of Python ints returned (an 8-byte slot and a 32-byte int each).
BYTES_PER_LABEL = 48
#: What occluding a cloud costs (:func:`occlusion_cost`), named when a cloud holds more points than
#: accepted; measured with ``generate``'s job for one cloud (:func:`zbuf_occlude.pipeline.occlude_point_set`,
#: normals estimated, the 25 poses of ``grid25``) on two cores, at 1 and 2 million points.  Bytes a
#: point: the address space (``VmPeak``) grew 485 B a point from 1 to 2 million; the splats'
#: preparation alone is estimated at 512 (:data:`~zbuf_occlude.visibility.point_splats.BYTES_PER_SURFEL`
#: and ``BYTES_PER_ESTIMATED_NORMAL``), the read adds its :data:`BYTES_PER_READ_POINT`; rounded up.
OCCLUSION_BYTES_PER_POINT = 600
#: Bytes of the job whatever its points: the libraries it imports and its threads' stacks and malloc
#: arenas (``VmPeak`` grew 934 MiB at a million points, 463 MiB of them the points' at 485 B).
OCCLUSION_FIXED_BYTES = 400 << 20
#: Seconds a point of preparing the splats (neighbour search, normals' estimate): 5.3 s a million measured.
OCCLUSION_PREPARE_SECONDS_PER_POINT = 5.5e-6
#: Seconds a point of each pose (splatting and deciding one view): 1.15 s a million measured.
OCCLUSION_POSE_SECONDS_PER_POINT = 1.2e-6
#: A ``.npy`` file's first bytes: the magic string, the format version (major, minor), then the
#: header's length, 2 bytes little-endian in version 1 and 4 in versions 2 and 3 (NEP 1).
_NPY_MAGIC = b"\x93NUMPY"
_NPY_LENGTH_BYTES = {1: 2, 2: 4, 3: 4}


@dataclass(frozen=True)
class PointSet:
    """One cloud of a point-set file.

    Attributes
    ----------
    points : (N, 3) float64
        Coordinates, as stored (file units and frame).
    normals : (N, 3) float64 or None
        Unit normals where the file has them.
    label : int or None
        The file's label of the cloud (PointNet HDF5 ``label``), else None.
    name : str
        The file's stem, or ``<stem>_<row:04d>`` for the rows of an HDF5 file.
    """

    points: NDArray[np.float64]
    normals: NDArray[np.float64] | None
    label: int | None
    name: str


def _suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in POINT_SET_SUFFIXES:
        raise InvalidInputError(f"{path}: not a point-set file; its extension is not one of {', '.join(POINT_SET_SUFFIXES)}")
    return suffix


def _check_max_points(max_points: object) -> int:
    if isinstance(max_points, bool) or not isinstance(max_points, (int, np.integer)) or int(max_points) < 1:
        raise InvalidInputError(f"max_points must be an integer >= 1, got {max_points!r}")
    return int(max_points)


def occlusion_cost(n_points: int) -> tuple[int, float, float]:
    """What occluding one cloud of ``n_points`` points costs, by the measured law above.

    Parameters
    ----------
    n_points : int

    Returns
    -------
    memory_bytes : int
        Address space the job maps beyond the interpreter's (:data:`OCCLUSION_FIXED_BYTES`, and
        :data:`OCCLUSION_BYTES_PER_POINT` a point).
    prepare_s : float
        Seconds of preparing its splats on two cores (:data:`OCCLUSION_PREPARE_SECONDS_PER_POINT` a point).
    pose_s : float
        Seconds of each pose on two cores (:data:`OCCLUSION_POSE_SECONDS_PER_POINT` a point).
    """
    n = int(n_points)
    return (
        OCCLUSION_FIXED_BYTES + n * OCCLUSION_BYTES_PER_POINT,
        n * OCCLUSION_PREPARE_SECONDS_PER_POINT,
        n * OCCLUSION_POSE_SECONDS_PER_POINT,
    )


def _too_many_points(path: Path, declared: str, n: int, max_points: int) -> InvalidInputError:
    """The refusal of a cloud of ``n`` points, more than ``max_points``: ``declared`` (what the header
    says), then what occluding it would cost (:func:`occlusion_cost`, for the default poses)."""
    from zbuf_occlude.defaults import DEFAULT_VIEWS
    from zbuf_occlude.geometry.cameras import view_schedule

    memory, prepare_s, pose_s = occlusion_cost(n)
    poses = len(view_schedule(DEFAULT_VIEWS))
    return InvalidInputError(
        f"{path}: {declared}, more than the {max_points:,} accepted; occluding {n:,} points needs about "
        f"{memory / 2**30:.1f} GiB of memory and, on two cores, {prepare_s:.0f} s plus {pose_s:.1f} s a pose "
        f"({(prepare_s + poses * pose_s) / 60:.1f} minutes for the default {poses} poses): subsample the cloud to at "
        f"most {max_points:,} points"
    )


def _point_set(path: Path, name: str, cloud: NDArray, normals: NDArray | None, label: int | None) -> PointSet:
    """A checked :class:`PointSet` of ``cloud (N, 3 or 6)`` (``normals`` given separately or in columns 3:6)."""
    if len(cloud) == 0:
        raise InvalidInputError(f"{path}: cloud {name!r} holds no points")
    points = np.ascontiguousarray(cloud[:, :3], dtype=np.float64)
    bad = int((~np.isfinite(points)).any(axis=1).sum())
    if bad:
        raise InvalidInputError(f"{path}: cloud {name!r}: {bad} points have NaN or inf coordinates")
    if normals is None and cloud.shape[1] == 6:
        normals = cloud[:, 3:6]
    if normals is not None:
        normals = unit_normals(normals, what=f"{path}: cloud {name!r}")
    return PointSet(points, normals, label, name)


def unit_normals(normals: NDArray[np.floating], *, what: str) -> NDArray[np.float64]:
    """``normals (N, 3)`` made unit, after checking that each can be: finite and not zero.

    A normal is a direction: its length does not matter.  Each row is first divided by its
    largest absolute component (exact for a power of two, else one rounding per component), which
    leaves components in [-1, 1] and one of them ±1, so that the squared length summed by
    ``numpy.linalg.norm`` lies in [1, 3]: no length from the smallest positive float64 (5e-324,
    a subnormal) to the largest (1.8e308, and rows whose every component is that large) overflows
    to inf or underflows to 0 (dividing by the length directly would make a normal of length
    1e300 divide to 0, a point facing no way).

    Parameters
    ----------
    normals : (N, 3) float
    what : str
        The cloud, first words of the message.

    Returns
    -------
    (N, 3) float64
        Unit, C-contiguous.

    Raises
    ------
    InvalidInputError
        Naming ``what``, how many normals are zero or hold NaN or inf, and the first such row.
    """
    normals = np.asarray(normals, dtype=np.float64)
    finite = np.isfinite(normals).all(axis=1)
    with np.errstate(invalid="ignore"):
        largest = np.abs(normals).max(axis=1) if len(normals) else np.zeros(0)
    zero = finite & (largest == 0)
    problems = [(zero, "are zero"), (~finite, "hold NaN or inf")]
    found = [(int(np.count_nonzero(bad)), int(np.argmax(bad)), said) for bad, said in problems if bad.any()]
    if found:
        count, row, said = found[0]
        raise InvalidInputError(f"{what}: {count:,} normals {said}, first row {row}; a normal gives the direction a surface faces")
    scaled = normals / largest[:, None]
    return np.ascontiguousarray(scaled / np.linalg.norm(scaled, axis=1)[:, None])


# -- HDF5 -------------------------------------------------------------------------------------------
def _hdf5_layout(f: Any, path: Path, max_points: int) -> tuple[Any, Any | None]:
    """``data`` (at least one cloud of at most ``max_points`` points) and ``normal`` (or None) of a
    checked, open PointNet-layout file."""
    import h5py

    data = f.get("data")
    if not isinstance(data, h5py.Dataset):
        raise DatasetFormatError(f"{path}: no 'data' dataset; a PointNet-layout HDF5 file holds data (B, N, 3)")
    if data.dtype.kind != "f" or data.ndim != 3 or data.shape[2] not in _COLUMNS:
        raise DatasetFormatError(
            f"{path}: 'data' holds {dtype_text(data.dtype)} values of shape {data.shape}, not (B, N, 3) or (B, N, 6) floats"
        )
    if data.shape[0] * 8 > MAX_POINT_SET_BYTES:  # its labels alone would pass the cap
        raise DatasetFormatError(f"{path}: 'data' declares {data.shape[0]:,} clouds; refused")
    normal = f.get("normal")
    if normal is not None and (not isinstance(normal, h5py.Dataset) or normal.dtype.kind != "f" or normal.shape != data.shape[:2] + (3,)):
        shape = getattr(normal, "shape", "a group")
        raise DatasetFormatError(f"{path}: 'normal' is {shape}, not (B, N, 3) floats like 'data' {data.shape}")
    if data.shape[0] == 0:
        raise DatasetFormatError(f"{path}: 'data' holds no clouds")
    if data.shape[1] > max_points:
        raise _too_many_points(path, f"its clouds hold {data.shape[1]:,} points each", data.shape[1], max_points)
    return data, normal


def _check_read_memory(path: Path, clouds: int, points: int, stored_bytes_per_point: int) -> None:
    """Refuse a read of ``clouds`` clouds of ``points`` points that would exhaust memory, before it
    allocates: the file's values (``stored_bytes_per_point``) and :data:`BYTES_PER_READ_POINT`."""
    check_memory(
        clouds * points * (stored_bytes_per_point + BYTES_PER_READ_POINT),
        option=f"reading {path} ({clouds:,} {'cloud' if clouds == 1 else 'clouds'} of {points:,} points)",
        hint="read fewer rows at a time, or free memory",
    )


def _hdf5_labels(f: Any, path: Path, rows: int) -> NDArray[np.int64] | None:
    """The ``label`` of every row, or None without one."""
    import h5py

    label = f.get("label")
    if label is None:
        return None
    if not isinstance(label, h5py.Dataset) or label.dtype.kind not in "iu" or label.shape not in ((rows,), (rows, 1)):
        raise DatasetFormatError(f"{path}: 'label' is {getattr(label, 'shape', 'a group')}, not ({rows},) or ({rows}, 1) integers")
    values = np.asarray(label[()], dtype=np.int64).reshape(rows)
    if values.size and values.min() < 0:
        raise DatasetFormatError(f"{path}: 'label' holds negative values ({int(values.min())}); labels number the classes from 0")
    return values


def _row_list(path: Path, rows: Sequence[int] | None, count: int) -> list[int]:
    if rows is None:
        return list(range(count))
    out = []
    for r in rows:
        if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or not 0 <= int(r) < count:
            raise InvalidInputError(f"{path}: row {r!r} out of range; the file holds {count} clouds")
        out.append(int(r))
    return out


def _read_hdf5(path: Path, max_points: int, rows: Sequence[int] | None) -> list[PointSet]:
    with open_hdf5(path) as f:
        data, normal = _hdf5_layout(f, path, max_points)
        count, n, _ = data.shape
        labels = _hdf5_labels(f, path, count)
        wanted = _row_list(path, rows, count)
        if len(wanted) * n * 6 * 8 > MAX_POINT_SET_BYTES:
            raise InvalidInputError(
                f"{path}: {len(wanted):,} clouds of {n:,} points are more than the {MAX_POINT_SET_BYTES:,} bytes one read "
                "may take; read fewer rows at a time"
            )
        stored = data.dtype.itemsize * data.shape[2] + (0 if normal is None else normal.dtype.itemsize * 3)
        _check_read_memory(path, len(wanted), n, stored)
        whole = rows is None
        clouds = data[()] if whole else None
        normals = normal[()] if whole and normal is not None else None
        out = []
        for r in wanted:
            cloud = clouds[r] if whole else data[r]
            nrm = None if normal is None else (normals[r] if whole else normal[r])
            out.append(_point_set(path, f"{path.stem}_{r:04d}", cloud, nrm, None if labels is None else int(labels[r])))
        return out


# -- .npy -------------------------------------------------------------------------------------------
def _npy_shape(path: Path, max_points: int) -> tuple[int, int, np.dtype]:
    """``(N, columns, dtype)`` of a ``.npy`` cloud, from its header (the file's sizes checked first)."""
    fh, size = open_regular_file(path, error=InvalidInputError)
    with fh:
        return _checked_npy_layout(fh, size, path, max_points)


def _checked_npy_layout(fh: BinaryIO, size: int, path: Path, max_points: int) -> tuple[int, int, np.dtype]:
    """:func:`_npy_layout` once the header and the sizes of the ``.npy`` open at ``fh`` (of ``size`` bytes) are checked."""
    check_npy_header(fh, path)
    check_npy_sizes(fh, path, size, max_bytes=MAX_POINT_SET_BYTES, error=InvalidInputError)
    return _npy_layout(fh, path, max_points)


def check_npy_header(fh: BinaryIO, path: str | os.PathLike, *, error: type[ZbufOccludeError] = InvalidInputError) -> None:
    """Refuse the ``.npy`` file open at ``fh`` (at its start; rewound after) unless numpy can read its header.

    Checked before numpy reads it, so that the message is one line of ours: numpy's own
    messages on a bad header run over several lines and quote the header.

    Parameters
    ----------
    fh : binary file
        Open at the start of the file.
    path : str or PathLike
        The file, named in the message.
    error : type
        The exception raised.

    Raises
    ------
    ``error``
        Naming ``path``: no ``.npy`` magic string, a format version numpy does not write, a header
        longer than :data:`~zbuf_occlude.io.caps.MAX_NPY_HEADER_BYTES` (its length given) or one numpy cannot parse
        (the parser's exception type, never the header).
    """
    head = fh.read(len(_NPY_MAGIC) + 2 + max(_NPY_LENGTH_BYTES.values()))
    fh.seek(0)
    if not head.startswith(_NPY_MAGIC) or len(head) < len(_NPY_MAGIC) + 2:
        raise error(f"{path}: not a .npy file (it does not start with numpy's magic string)")
    major = head[len(_NPY_MAGIC)]
    if major not in _NPY_LENGTH_BYTES:
        raise error(f"{path}: .npy format version {major}, not one numpy writes (1, 2 or 3)")
    start = len(_NPY_MAGIC) + 2
    length_field = head[start : start + _NPY_LENGTH_BYTES[major]]
    length = int.from_bytes(length_field, "little")
    if len(length_field) < _NPY_LENGTH_BYTES[major]:
        raise error(f"{path}: its .npy header is cut short")
    if length > MAX_NPY_HEADER_BYTES:
        raise error(
            f"{path}: its .npy header is {length:,} bytes, more than the {MAX_NPY_HEADER_BYTES:,} numpy parses; save the array again"
        )
    try:
        npy_header(fh)
    except Exception as exc:  # numpy's messages quote the header, over several lines
        raise error(f"{path}: its .npy header cannot be parsed ({parser_failure(exc)}); save the array again with numpy.save") from None
    finally:
        fh.seek(0)


def _npy_layout(fh: Any, path: Path, max_points: int) -> tuple[int, int, np.dtype]:
    """``(N, columns, dtype)`` of the ``.npy`` cloud open at ``fh`` (at its start), from its header."""
    shape, dtype = npy_header(fh)
    if dtype.kind not in "fiu" or dtype.fields is not None or len(shape) != 2 or shape[1] not in _COLUMNS:
        raise InvalidInputError(
            f"{path}: holds {dtype_text(dtype)} values of shape {shape}, not (N, 3) or (N, 6) numbers (coordinates, normals)"
        )
    if shape[0] > max_points:
        raise _too_many_points(path, f"{shape[0]:,} points", shape[0], max_points)
    return shape[0], shape[1], dtype


def _read_npy(path: Path, max_points: int) -> list[PointSet]:
    fh, size = open_regular_file(path, error=InvalidInputError)
    with fh:  # the array is read from the file whose header was checked, not opened again by name
        n, columns, dtype = _checked_npy_layout(fh, size, path, max_points)
        _check_read_memory(path, 1, n, dtype.itemsize * columns)
        fh.seek(0)
        array = np.lib.format.read_array(fh, allow_pickle=False)
    return [_point_set(path, path.stem, array, None, None)]


# -- .ply -------------------------------------------------------------------------------------------
def _ply_elements(path: Path) -> dict[str, int]:
    """The element counts a PLY header declares (``{"vertex": 2048}``)."""
    fh, _ = open_regular_file(path, error=InvalidInputError)
    head = b""
    with fh:  # a header is a few hundred bytes: read a little at a time, not the cap at once
        while b"end_header" not in head and len(head) < MAX_POINT_SET_PLY_HEADER_BYTES and (chunk := fh.read(_PLY_CHUNK_BYTES)):
            head += chunk
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise InvalidInputError(
            f"{path}: not a PLY file (no 'ply' ... 'end_header' header in its first {MAX_POINT_SET_PLY_HEADER_BYTES:,} bytes)"
        )
    text = head[:end].decode("ascii", "replace")
    counts = {m[1]: m[2] for m in re.finditer(r"^element\s+(\S+)\s+(\d+)\s*$", text, re.MULTILINE)}
    for digits in counts.values():
        if len(digits.lstrip("0")) > _PLY_COUNT_DIGITS:
            raise InvalidInputError(f"{path}: its PLY header gives an element a count of {len(digits):,} digits; refused")
    return {element: int(digits) for element, digits in counts.items()}


def _ply_vertex_count(path: Path, max_points: int) -> int:
    counts = _ply_elements(path)
    n, faces = counts.get("vertex", 0), counts.get("face", 0)
    if faces:
        raise InvalidInputError(f"{path}: a mesh ({faces:,} faces), not a point cloud; give it as a mesh")
    if n == 0:
        raise InvalidInputError(f"{path}: its PLY header declares no vertices")
    if n > max_points:
        raise _too_many_points(path, f"its PLY header declares {n:,} points", n, max_points)
    return n


def _read_ply(path: Path, max_points: int) -> list[PointSet]:
    from trimesh.exchange.ply import load_ply

    n = _ply_vertex_count(path, max_points)
    fh, size = open_regular_file(path, max_bytes=MAX_POINT_SET_BYTES, error=InvalidInputError)
    with fh:  # read from the file whose size was checked: the bytes the memory check counted, no more
        # the file's bytes, trimesh's columns of them (at most as many), and the float64 x, y, z and normals
        check_memory(2 * size + n * BYTES_PER_READ_POINT, option=f"reading {path} ({size:,} bytes, {n:,} points)", hint="free memory")
        raw = fh.read(size)
    vertex = load_ply(io.BytesIO(raw), skip_materials=True)["metadata"]["_ply_raw"]["vertex"]["data"]
    if vertex is None or any(c not in _fields(vertex) for c in "xyz"):
        raise InvalidInputError(f"{path}: its vertices have no x, y, z properties")
    xyz = np.stack([np.asarray(vertex[c], dtype=np.float64).reshape(-1) for c in "xyz"], axis=1)
    if len(xyz) != n:
        raise InvalidInputError(f"{path}: its PLY header declares {n:,} vertices but it holds {len(xyz):,}; the file is cut short")
    normals = None
    if all(c in _fields(vertex) for c in ("nx", "ny", "nz")):
        normals = np.stack([np.asarray(vertex[c], dtype=np.float64).reshape(-1) for c in ("nx", "ny", "nz")], axis=1)
    return [_point_set(path, path.stem, xyz, normals, None)]


def _fields(vertex: Any) -> tuple[str, ...]:
    # trimesh gives a structured array for binary PLY and a dict of columns for ASCII
    return tuple(vertex.keys()) if isinstance(vertex, dict) else tuple(vertex.dtype.names or ())


# -- the public functions ---------------------------------------------------------------------------
def is_point_set_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a point-set file by its extension and head (nothing else is read).

    A ``.npy``; an ``.h5``/``.hdf5`` with a ``data`` entry of shape ``(B, N, 3)`` or ``(B, N, 6)``
    (or one that points elsewhere: :func:`read_point_sets` then says why it is refused); a
    ``.ply`` whose header declares vertices and no faces.  False for anything else, files that
    are not regular files or cannot be opened included.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in POINT_SET_SUFFIXES or not path.is_file():  # is_file: a regular file (a FIFO would block)
        return False
    if suffix == ".npy":
        return True
    if suffix == ".ply":
        try:
            counts = _ply_elements(path)
        except InvalidInputError:
            return False
        return counts.get("vertex", 0) > 0 and counts.get("face", 0) == 0
    import h5py

    try:
        with h5py.File(path, "r") as f:
            link = f.get("data", getlink=True)  # the link itself: nothing is followed
            if link is None:
                return False
            if not isinstance(link, h5py.HardLink):
                return True
            data = f.get("data")
            return isinstance(data, h5py.Dataset) and data.ndim == 3 and data.shape[2] in _COLUMNS
    except (OSError, ValueError):
        return False


#: The up axes an HDF5 point-set file's ``up`` attribute may name (:data:`zbuf_occlude.mesh.scene.UP_CHOICES` less ``auto``).
UP_AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
#: Datasets that mark an HDF5 file as one of zbuf_occlude's own data sets (``generate``'s joined
#: files, the farm's shards), written in its +z-up frame.
_OWN_DATASETS = ("pose_index", "face_index")


def stored_up(path: str | os.PathLike) -> tuple[str, str]:
    """The up axis a point-set file's clouds are stored with, by its layout, and why.

    * HDF5: the file's ``up`` attribute where it has one (``"+y"``...); else ``"+z"`` for one of
      zbuf_occlude's own data sets (``pose_index`` and ``face_index`` beside ``data``); else
      ``"+y"``, PointNet's layout: ``modelnet40_ply_hdf5_2048`` holds ModelNet's clouds +y up, as
      PointNet, PointNet++ and DGCNN train on them (their augmentation turns about y: PointNet's
      ``provider.rotate_point_cloud``, "along up direction").
    * ``.npy`` and ``.ply``: no frame is declared; as stored, ``"+z"``.

    Returns
    -------
    up : str
        ``"+x"`` ... ``"-z"``.
    why : str
        For the records (``up_source``): ``"PointNet HDF5 layout (+y)"``, ``"as stored (+z)"``...

    Raises
    ------
    DatasetFormatError
        An HDF5 file that cannot be opened or is refused by :func:`~zbuf_occlude.io.hdf5.check_hdf5`.
    """
    path = Path(path)
    if path.suffix.lower() not in (".h5", ".hdf5"):
        return "+z", "as stored (+z)"
    with open_hdf5(path) as f:
        up = f.attrs.get("up")
        up = up.decode("utf-8", "replace") if isinstance(up, bytes) else up
        if isinstance(up, str) and up in UP_AXES:
            return up, f"the file's 'up' attribute ({up})"
        if all(name in f for name in _OWN_DATASETS):
            return "+z", "a zbuf_occlude data set (+z)"
    return "+y", "PointNet HDF5 layout (+y)"


def read_point_sets(
    path: str | os.PathLike, *, max_points: int = MAX_POINT_SET_POINTS, rows: Sequence[int] | None = None
) -> list[PointSet]:
    """Every cloud of one point-set file (module docstring), in file order.

    Parameters
    ----------
    path : str or PathLike
        A ``.h5``/``.hdf5``, ``.npy`` or ``.ply`` file (:data:`POINT_SET_SUFFIXES`).
    max_points : int
        The most points a cloud may hold (default :data:`~zbuf_occlude.defaults.MAX_POINT_SET_POINTS`); a
        larger cloud is refused from the header, before its values are read, with what occluding it
        would cost (:func:`occlusion_cost`).
    rows : sequence of int, optional
        HDF5 files: read only these rows, in this order (the other formats hold one cloud, row 0).

    Returns
    -------
    list of PointSet
        ``points (N, 3) float64`` as stored, ``normals (N, 3) float64`` unit length or None,
        ``label`` the file's (HDF5 ``label``) or None, ``name`` the stem (``<stem>_<row:04d>``
        for HDF5 rows).

    Raises
    ------
    InvalidInputError
        Naming the file: missing, not a regular file, an unknown extension, another shape or
        dtype than the format's, no points, more points than ``max_points`` or more bytes than
        :data:`~zbuf_occlude.io.caps.MAX_POINT_SET_BYTES`, NaN/inf coordinates, zero or
        non-finite normals, a PLY with faces or cut short, a row out of range, damaged bytes.
        :class:`~zbuf_occlude.errors.DatasetFormatError` (a subclass) for HDF5 files that are
        not HDF5, link or map to other files (:func:`zbuf_occlude.io.hdf5.check_hdf5`), or lack
        ``data (B, N, 3)``, and for a ``label`` that is not one non-negative integer per row.
    InsufficientMemoryError
        The read (the file's values and :data:`BYTES_PER_READ_POINT` a point) would need more
        memory than is available; checked before it allocates (naming the file and the clouds).
    """
    path = Path(path)
    suffix = _suffix(path)
    max_points = _check_max_points(max_points)
    try:
        if suffix in _HDF5:
            return _read_hdf5(path, max_points, rows)
        _row_list(path, rows, 1)
        return _read_npy(path, max_points) if suffix == ".npy" else _read_ply(path, max_points)
    except InvalidInputError:
        raise
    except MemoryError:
        raise InvalidInputError(f"{path}: not enough memory to read it") from None
    except Exception as exc:  # numpy, h5py and trimesh raise many types on damaged or hostile bytes
        raise InvalidInputError(f"{path}: cannot read as a {suffix[1:].upper()} point set ({parser_failure(exc)})") from None


def point_set_labels(path: str | os.PathLike, *, max_points: int = MAX_POINT_SET_POINTS) -> list[int | None]:
    """The label of every cloud of a point-set file, in file order, reading headers and labels only.

    Its length is the number of clouds :func:`read_point_sets` returns; an entry is the file's
    label (HDF5 ``label``) or None.

    Raises
    ------
    InvalidInputError
        As :func:`read_point_sets`, for what headers and labels show.
    InsufficientMemoryError
        Reading the labels (:data:`BYTES_PER_LABEL` a cloud) would need more memory than is
        available (naming the number of clouds).
    """
    path = Path(path)
    suffix = _suffix(path)
    max_points = _check_max_points(max_points)
    try:
        if suffix == ".npy":
            _npy_shape(path, max_points)
            return [None]
        if suffix == ".ply":
            _ply_vertex_count(path, max_points)
            return [None]
        with open_hdf5(path) as f:
            data, _ = _hdf5_layout(f, path, max_points)
            check_memory(
                data.shape[0] * BYTES_PER_LABEL,
                option=f"the labels of {path} ({data.shape[0]:,} clouds)",
                hint="split the file, or free memory",
            )
            labels = _hdf5_labels(f, path, data.shape[0])
            return [None] * data.shape[0] if labels is None else [int(v) for v in labels]
    except InvalidInputError:
        raise
    except Exception as exc:  # as read_point_sets
        raise InvalidInputError(f"{path}: cannot read as a {suffix[1:].upper()} point set ({parser_failure(exc)})") from None


def shape_names(path: str | os.PathLike) -> list[str] | None:
    """The class names of an HDF5 point-set file's labels, from the class list beside it.

    The first of :data:`SHAPE_NAME_FILES` in the file's folder: one class a line, label ``i``
    on line ``i`` (blank lines skipped; ShapeNetPart's ``all_object_categories.txt``: the first
    field of each line).  The list is read by
    :func:`~zbuf_occlude.io.regular_files.read_text_file`'s rules: a regular file (a FIFO is
    refused unopened), inside the point-set file's folder once links are resolved (one that
    links elsewhere would name the classes with another file's lines), of at most
    :data:`~zbuf_occlude.io.caps.MAX_LIST_BYTES`.

    Returns
    -------
    list of str or None
        None for a file that is not HDF5 or has no class list beside it.

    Raises
    ------
    InvalidInputError
        The class list is not a regular file (a FIFO, a folder, a dangling link), larger than
        :data:`~zbuf_occlude.io.caps.MAX_LIST_BYTES`, not UTF-8, or holds a name that is
        not printable or not a plain name (``/``, ``\\``, ``.``, ``..``: exports name folders by
        class, as a mesh's class is its folder's name), naming it and the line.
    UnsafePathError
        The class list leads outside the point-set file's folder (a link); a subclass of
        InvalidInputError.
    """
    path = Path(path)
    if path.suffix.lower() not in _HDF5:
        return None
    for file_name in SHAPE_NAME_FILES:
        names_file = path.parent / file_name
        if os.path.lexists(names_file):  # whatever it is: a FIFO or a link is refused, not passed over
            break
    else:
        return None
    text = read_text_file(names_file, max_bytes=MAX_LIST_BYTES, error=InvalidInputError, within=path.parent)
    names = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        name = line.split("\t")[0].split()[0] if file_name == "all_object_categories.txt" and line.strip() else line.strip()
        if not name:
            continue
        if not name.isprintable():
            raise InvalidInputError(f"{names_file}:{lineno}: the class name is not printable text")
        if name in (".", "..") or "/" in name or "\\" in name:  # a class names a folder where meshes' classes do
            raise InvalidInputError(f"{names_file}:{lineno}: the class name is not a plain name (no '/', '\\', '.' or '..')")
        names.append(name)
    return names
