"""Point-cloud files of real scans, whatever wrote them: CSV, TXT/XYZ, PLY, PCD, NPY/NPZ, KITTI BIN.

:func:`read_points` returns the ``(N, 3)`` coordinates of one file; :func:`load_scan_folder`
reads a folder with one sub-folder per class (the class is the first folder under the root,
renamed by a label map), turns each scan to z up and metres, and returns
:class:`zbuf_occlude.real_scans.datasets.RealScan` objects normalised like the paper's meshes.

Formats (by extension, case-insensitive):

``.csv``
    A header row is detected (a first row with a non-numeric field); columns named ``x y z``
    (any case, also ``X``/``points_x``/``origin_x``...) are used, else the first three
    numeric columns.  Separator: comma, semicolon, tab or spaces.
``.txt``, ``.xyz``, ``.pts``
    ``x y z ...`` per line (spaces, tabs or commas); ``#`` and ``//`` comments; a first line
    holding a single integer (the ``.pts`` point count) is skipped.
``.ply``
    ASCII or binary, read by trimesh (vertex ``x y z``).
``.pcd``
    Point Cloud Library's format, ``DATA ascii`` or ``binary`` (fields ``x y z`` of any
    ``SIZE``/``TYPE``; ``binary_compressed`` is refused with a message), per the PCL file
    format specification (pointclouds.org, "The PCD (Point Cloud Data) file format").
``.npy``, ``.npz``
    An ``(N, ≥3)`` array (or a structured array with ``x y z`` fields); in ``.npz`` the array
    named ``points``, ``xyz`` or ``data``, else the only ``(N, ≥3)`` one.  Never unpickled.
``.bin``
    KITTI Velodyne records, float32 ``x y z reflectance`` (16 bytes each), little-endian.

Every file is untrusted: a malformed one raises :class:`~zbuf_occlude.errors.InvalidInputError`
naming it and the cause, never a traceback.
"""

from __future__ import annotations

import csv
import io
import itertools
import logging
import os
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InsufficientMemoryError, InvalidInputError
from zbuf_occlude.io.arrays import load_npy, load_npz
from zbuf_occlude.io.caps import MAX_REAL_SCAN_ARRAY_BYTES, MAX_REAL_SCAN_BYTES, MAX_REAL_SCAN_LINE_BYTES
from zbuf_occlude.io.file_errors import dtype_text, parser_failure
from zbuf_occlude.io.ply import parse_ply_vertices
from zbuf_occlude.io.point_sets import check_npy_header
from zbuf_occlude.io.safe_paths import check_found_file
from zbuf_occlude.io.regular_files import file_digest, open_regular_file, read_regular_file, regular_file_size
from zbuf_occlude.mesh.formats.ply import ply_declared_counts
from zbuf_occlude.mesh.scene import up_rotation
from zbuf_occlude.real_scans.records import RealScan, normalize_points
from zbuf_occlude.resources import check_memory

__all__ = [
    "POINT_EXTENSIONS",
    "UNITS_M",
    "MAX_SCAN_POINTS",
    "row_capacity",
    "read_points",
    "read_lines",
    "scan_digest",
    "units_to_m",
    "find_scan_files",
    "load_scan_folder",
]

log = logging.getLogger(__name__)

#: File extensions :func:`read_points` reads.
POINT_EXTENSIONS = (".csv", ".txt", ".xyz", ".pts", ".ply", ".pcd", ".npy", ".npz", ".bin")
#: Unit names accepted by ``units`` (metres per unit).
UNITS_M = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048, "km": 1000.0}
#: Points one scan may hold: 50 million.  A segmented object is thousands to a million points;
#: 5e7 is 1.2 GB as float64 (x, y, z), checked before the array is allocated.
MAX_SCAN_POINTS = 50_000_000
#: Rows parsed into Python objects at a time before they are stored as float64.
_ROWS_PER_CHUNK = 65536
_KITTI_RECORD = np.dtype("<f4")
_PCD_TYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4", ("I", 8): "<i8",
              ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4", ("U", 8): "<u8"}  # fmt: skip
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^[+-]?(nan|inf)$", re.IGNORECASE)


def units_to_m(units: str | float) -> float:
    """Metres per unit from a name of :data:`UNITS_M` or a positive number (``0.2`` = 5 units per metre)."""
    if isinstance(units, str) and units.strip().lower() in UNITS_M:
        return UNITS_M[units.strip().lower()]
    try:
        value = float(units)
    except (TypeError, ValueError):
        raise InvalidInputError(f"units must be one of {', '.join(UNITS_M)} or metres per unit, got {units!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise InvalidInputError(f"units must be a positive number of metres per unit, got {units!r}")
    return value


def _xyz_columns(header: list[str]) -> list[int] | None:
    low = [h.strip().lower() for h in header]
    for prefix in ("", "points_", "point_", "origin_", "pos_"):
        if all(prefix + a in low for a in "xyz"):
            return [low.index(prefix + a) for a in "xyz"]
    return None


def _split(line: str) -> list[str]:
    return [t for t in re.split(r"[,;\s]+", line.strip()) if t]


def read_lines(path: Path, fh: io.BufferedReader, errors: str = "replace"):
    """``(line number, text)`` of a binary file handle, one line at a time, none longer than
    :data:`~zbuf_occlude.io.caps.MAX_REAL_SCAN_LINE_BYTES`.

    ``errors`` is the UTF-8 decoder's (``"strict"``: a ``UnicodeDecodeError`` for the caller to name).

    Raises
    ------
    InvalidInputError
        Naming the file and the line, on a line longer than the cap (a file with no newline).
    """
    for lineno, line in enumerate(iter(lambda: fh.readline(MAX_REAL_SCAN_LINE_BYTES + 1), b""), 1):
        if len(line) > MAX_REAL_SCAN_LINE_BYTES:
            raise InvalidInputError(f"{path}:{lineno}: a line longer than {MAX_REAL_SCAN_LINE_BYTES:,} bytes is not a row of a point cloud")
        yield lineno, line.decode("utf-8", errors=errors)


def _check_points(path: Path, n: int, what: str = "declares", bytes_per_point: int = 24) -> None:
    """Refuse ``n`` points past :data:`MAX_SCAN_POINTS` or the memory there is, before allocating them.

    ``bytes_per_point``: what one point takes once read (24: three float64).

    Raises
    ------
    InvalidInputError
        Naming ``path``, the count and the cap, or the memory needed.
    """
    if n > MAX_SCAN_POINTS:
        raise InvalidInputError(f"{path}: {what} {n:,} points, more than the {MAX_SCAN_POINTS:,} a scan may have")
    try:
        check_memory(n * int(bytes_per_point), option=f"{path}")
    except InsufficientMemoryError as exc:
        raise InvalidInputError(str(exc)) from None


def _count_lines(fh: io.BufferedReader) -> int:
    """Lines of a binary file (a last line without newline counts), read in 1 MiB chunks."""
    n, last = 0, b"\n"
    while chunk := fh.read(1 << 20):
        n += chunk.count(b"\n")
        last = chunk[-1:]
    fh.seek(0)
    return n + (last != b"\n")


def row_capacity(path: Path, fh: io.BufferedReader, bytes_per_point: int = 24) -> int:
    """Lines of the open file ``fh`` (rewound), checked as points (:func:`_check_points`): the
    rows to allocate before a text scan is streamed in.

    Raises
    ------
    InvalidInputError
        Naming ``path``: more lines than :data:`MAX_SCAN_POINTS`, or than the memory holds.
    """
    capacity = _count_lines(fh)
    _check_points(path, capacity, "has up to", bytes_per_point=bytes_per_point)
    return capacity


def _read_text_table(path: Path) -> NDArray[np.float64]:
    """Rows of a CSV/TXT/XYZ/PTS file, streamed: memory is the (N, 3) float64 result, not Python strings."""
    fh, _ = open_regular_file(path, max_bytes=MAX_REAL_SCAN_BYTES, error=InvalidInputError)
    with fh:
        capacity = row_capacity(path, fh)
        content = ((i, ln) for i, ln in read_lines(path, fh) if ln.strip() and not ln.lstrip().startswith(("#", "//")))
        head = next(content, None)
        if head is None:
            raise InvalidInputError(f"{path}: no points")
        first = _split(head[1]) if path.suffix.lower() != ".csv" else next(csv.reader(io.StringIO(head[1])))
        if path.suffix.lower() == ".csv" and len(first) < 3:
            first = _split(head[1])
        columns, pending = None, []
        if not all(_NUMBER.match(t.strip()) for t in first):
            columns = _xyz_columns(first)
            if columns is None:
                second = next(content, None)
                if second is not None:
                    pending = [second]
                    columns = [j for j, t in enumerate(_split(second[1])) if _NUMBER.match(t)][:3] or None
        elif len(first) != 1:  # a single number first is the .pts count line
            pending = [head]
        out = np.empty((capacity, 3))
        n = 0
        for lineno, line in itertools.chain(pending, content):
            row = _split(line)
            try:
                out[n] = [float(row[c]) for c in columns] if columns else [float(v) for v in row[:3]]
                if len(row) < 3:
                    raise IndexError
            except (ValueError, IndexError):
                raise InvalidInputError(f"{path}:{lineno}: expected three numbers (x y z) on the line") from None
            n += 1
    if n == 0:
        raise InvalidInputError(f"{path}: a header and no points")
    return out[:n] if n == capacity else out[:n].copy()


def _read_pcd(path: Path, raw: bytes) -> NDArray[np.float64]:
    header: dict[str, list[str]] = {}
    pos = 0
    while True:
        end = raw.find(b"\n", pos)
        if end < 0:
            raise InvalidInputError(f"{path}: PCD header has no DATA line")
        line = raw[pos:end].decode("latin-1").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            break
    try:
        fields = header["FIELDS"]
        grid = int(header["WIDTH"][0]) * int(header.get("HEIGHT", ["1"])[0]) if "WIDTH" in header else None
        n = int(header["POINTS"][0]) if "POINTS" in header else grid
        sizes = [int(s) for s in header.get("SIZE", ["4"] * len(fields))]
        types = header.get("TYPE", ["F"] * len(fields))
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
    except (KeyError, ValueError, IndexError):
        raise InvalidInputError(f"{path}: PCD header lacks FIELDS/POINTS or has non-numeric WIDTH, HEIGHT, POINTS, SIZE or COUNT") from None
    if n is None:
        raise InvalidInputError(f"{path}: PCD header has neither POINTS nor WIDTH")
    if grid is not None and grid != n:
        raise InvalidInputError(f"{path}: PCD header declares POINTS {n:,} but WIDTH x HEIGHT = {grid:,}")
    _check_points(path, n)
    if not all(a in fields for a in "xyz"):
        raise InvalidInputError(f"{path}: PCD header's FIELDS has no x y z")
    if not (len(sizes) == len(types) == len(counts) == len(fields)) or n < 0:
        raise InvalidInputError(f"{path}: PCD header's FIELDS, SIZE, TYPE and COUNT disagree")
    mode = header["DATA"][0].lower() if header["DATA"] else ""
    if mode == "ascii":
        table = np.array([_split(ln) for ln in raw[pos:].decode("latin-1").splitlines() if ln.strip()], dtype=object)
        if len(table) != n:
            raise InvalidInputError(f"{path}: PCD declares {n:,} points but holds {len(table):,} rows")
        offsets = np.cumsum([0] + counts)
        try:
            cols = [np.asarray(table[:, offsets[fields.index(a)]], dtype=np.float64) for a in "xyz"] if len(table) else [np.zeros(0)] * 3
        except (ValueError, IndexError):
            raise InvalidInputError(f"{path}: PCD ascii rows are not numbers in the header's layout") from None
        return np.stack(cols, axis=1)
    if mode != "binary":
        raise InvalidInputError(f"{path}: PCD DATA is not ascii or binary (convert binary_compressed with pcl_convert_pcd_ascii_binary)")
    try:
        dtype = np.dtype([(f, _PCD_TYPES[(t.upper(), s)], (c,)) for f, s, t, c in zip(fields, sizes, types, counts)])
    except (KeyError, TypeError, ValueError):
        raise InvalidInputError(f"{path}: PCD header's TYPE and SIZE give a field type other than F 4/8, I or U 1/2/4/8") from None
    body = raw[pos:]
    if len(body) != n * dtype.itemsize:
        raise InvalidInputError(
            f"{path}: PCD declares {n:,} points ({n * dtype.itemsize:,} bytes) but holds {len(body):,} bytes "
            f"({len(body) / dtype.itemsize:,.6g} points)"
        )
    rec = np.frombuffer(body, dtype=dtype, count=n)
    return np.stack([rec[a][:, 0].astype(np.float64) for a in "xyz"], axis=1)


def _from_array(path: Path, arr: np.ndarray) -> NDArray[np.float64]:
    if arr.dtype.names and all(a in arr.dtype.names for a in "xyz"):
        return np.stack([np.asarray(arr[a], np.float64).reshape(-1) for a in "xyz"], axis=1)
    if arr.ndim != 2 or arr.shape[1] < 3 or not np.issubdtype(arr.dtype, np.number):
        raise InvalidInputError(f"{path}: expected an (N, >=3) numeric array, got shape {arr.shape} dtype {dtype_text(arr.dtype)}")
    return np.asarray(arr[:, :3], dtype=np.float64)


def _read_npz(path: Path) -> NDArray[np.float64]:
    arrays = load_npz(path, max_bytes=MAX_REAL_SCAN_ARRAY_BYTES, error=InvalidInputError)
    for key in ("points", "xyz", "data"):
        if key in arrays:
            return _from_array(path, arrays[key])
    fits = [a for a in arrays.values() if a.ndim == 2 and a.shape[1] >= 3]
    if len(fits) != 1:
        raise InvalidInputError(f"{path}: no array named points/xyz/data and {len(fits)} (N, >=3) arrays; name one 'points'")
    return _from_array(path, fits[0])


def _read_ply(path: Path, raw: bytes) -> NDArray[np.float64]:
    """Vertices of a PLY, exactly as many as its header declares."""
    declared = ply_declared_counts(raw).get("vertex")
    if declared is None:
        raise InvalidInputError(f"{path}: PLY header declares no vertex element")
    _check_points(path, declared)
    pts = parse_ply_vertices(raw, path, error=InvalidInputError)
    if len(pts) != declared:
        raise InvalidInputError(f"{path}: PLY declares {declared:,} vertices but holds {len(pts):,}; the file is cut short")
    return pts


def scan_digest(path: Path) -> str:
    """MD5 of a scan file (for dropping duplicates), its size checked first and read in chunks.

    Raises
    ------
    InvalidInputError
        Naming the file: larger than :data:`~zbuf_occlude.io.caps.MAX_REAL_SCAN_BYTES`, not a regular file, unreadable.
    """
    return file_digest(path, max_bytes=MAX_REAL_SCAN_BYTES, error=InvalidInputError)


def read_points(path: str | os.PathLike) -> NDArray[np.float64]:
    """The ``(N, 3) float64`` coordinates of one point-cloud file, as stored (module docstring).

    Raises
    ------
    InvalidInputError
        Naming the file: missing, not a regular file, larger than :data:`~zbuf_occlude.io.caps.MAX_REAL_SCAN_BYTES`,
        declaring more than :data:`MAX_SCAN_POINTS` points or (``.npy``/``.npz``) more than
        :data:`~zbuf_occlude.io.caps.MAX_REAL_SCAN_ARRAY_BYTES` inflated, a line longer than
        :data:`~zbuf_occlude.io.caps.MAX_REAL_SCAN_LINE_BYTES`, a PLY or PCD holding more or fewer points than its header declares, unknown extension,
        malformed content, non-finite coordinates or no point.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in POINT_EXTENSIONS:
        raise InvalidInputError(f"{path}: unsupported point-cloud extension {path.suffix!r}; use one of {', '.join(POINT_EXTENSIONS)}")
    try:
        if not path.exists():
            raise InvalidInputError(f"{path}: no such file")
        size = regular_file_size(path, error=InvalidInputError)
        if size > MAX_REAL_SCAN_BYTES:
            raise InvalidInputError(f"{path}: {size:,} bytes, more than the {MAX_REAL_SCAN_BYTES:,} a scan may have")
        if suffix == ".npy":
            fh, _ = open_regular_file(path, error=InvalidInputError)
            with fh:  # one line of ours on a header numpy would refuse with several lines quoting it
                check_npy_header(fh, path)
            pts = _from_array(path, load_npy(path, max_bytes=MAX_REAL_SCAN_ARRAY_BYTES, error=InvalidInputError))
        elif suffix == ".npz":
            pts = _read_npz(path)
        elif suffix == ".ply":
            pts = _read_ply(path, read_regular_file(path, max_bytes=MAX_REAL_SCAN_BYTES, error=InvalidInputError))
        elif suffix in (".csv", ".txt", ".xyz", ".pts"):
            pts = _read_text_table(path)
        else:
            raw = read_regular_file(path, max_bytes=MAX_REAL_SCAN_BYTES, error=InvalidInputError)
            if suffix == ".bin":
                if len(raw) % (4 * _KITTI_RECORD.itemsize):
                    raise InvalidInputError(f"{path}: {len(raw)} bytes is not a whole number of 16-byte KITTI records (float32 x y z r)")
                pts = np.frombuffer(raw, dtype=_KITTI_RECORD).reshape(-1, 4)[:, :3].astype(np.float64)
            else:
                pts = _read_pcd(path, raw)
    except InvalidInputError:
        raise
    except OSError as exc:
        raise InvalidInputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except MemoryError:
        raise InvalidInputError(f"{path}: not enough memory to read it") from None
    except Exception as exc:  # numpy/trimesh raise many types on hostile bytes
        raise InvalidInputError(f"{path}: cannot parse as {suffix[1:].upper()} ({parser_failure(exc)})") from None
    if len(pts) == 0:
        raise InvalidInputError(f"{path}: no points")
    if not np.isfinite(pts).all():
        raise InvalidInputError(f"{path}: {int((~np.isfinite(pts)).any(axis=1).sum())} points have NaN or inf coordinates")
    return pts


def find_scan_files(root: Path) -> list[Path]:
    """Every point-cloud file under ``root`` (any extension :func:`read_points` knows) but ``MANIFEST.csv``, sorted.

    Links to folders are not followed (:meth:`pathlib.Path.rglob`); a file that is a link leading
    outside ``root`` is refused unless it leads to a file of its own extension
    (:func:`~zbuf_occlude.io.safe_paths.check_found_file`), before any file is read.

    Raises
    ------
    UnsafePathError
        A link in ``root`` to a file outside it of another extension (naming the link and ``root``).
    """
    found = sorted(p for p in root.rglob("*") if p.suffix.lower() in POINT_EXTENSIONS and p.is_file() and p.name != "MANIFEST.csv")
    return [check_found_file(p, root) for p in found]


def load_scan_folder(
    root: str | os.PathLike,
    *,
    label_map: Mapping[str, str] | None = None,
    up: str = "+z",
    units: str | float = "m",
    min_points: int = 1,
    dedupe: bool = True,
    dataset: str = "folder",
):
    """Every scan under ``root/CLASS/...``: one file one object, z up, metres, normalised.

    Parameters
    ----------
    root : path
        A folder with one sub-folder per class (the first folder under ``root`` names the class;
        deeper folders are searched too).
    label_map : mapping, optional
        Renames folder names (``{"Trunk": "pole"}``).
    up : {"+z", "+y", "-y", "+x", "-x", "-z"}
        The scans' up axis, rotated to +z (:func:`zbuf_occlude.mesh.scene.up_rotation`).
    units : str or float
        Unit of the coordinates (:func:`units_to_m`): ``extent_m`` is in metres.
    min_points : int
        Scans with fewer points are left out (logged).
    dedupe : bool
        Leave out files byte-identical to an earlier one (sorted path order).

    Returns
    -------
    list of RealScan
        Sorted by path.

    Raises
    ------
    InvalidInputError
        ``root`` not a folder, no scan file in a class folder, a point-cloud file beside the
        class folders (named), a bad ``up``/``units``, or a file that cannot be read (named).
    UnsafePathError
        A file in ``root`` is a link leading outside it to a file of another extension
        (:func:`find_scan_files`); a subclass of InvalidInputError.
    """
    root = Path(root)
    if not root.is_dir():
        raise InvalidInputError(f"real scans: {root} is not a folder")
    rot = up_rotation(up)[:3, :3]
    scale = units_to_m(units)
    label_map = dict(label_map or {})
    found = find_scan_files(root)
    loose = [p.name for p in found if len(p.relative_to(root).parts) < 2]
    if loose:
        # Not silently left out: a file beside the class folders has no class.
        raise InvalidInputError(f"real scans under {root}: {len(loose)} file(s) outside any class folder "
                                f"({', '.join(loose[:5])}); move each into its class's folder")  # fmt: skip
    files = [p for p in found if len(p.relative_to(root).parts) >= 2]
    if not files:
        raise InvalidInputError(f"real scans: no {'/'.join(POINT_EXTENSIONS)} files in class folders under {root}")
    seen, scans, few = set(), [], 0
    for f in files:
        if dedupe:
            digest = scan_digest(f)
            if digest in seen:
                continue
            seen.add(digest)
        pts = read_points(f) @ rot.T * scale
        if len(pts) < min_points:
            few += 1
            continue
        folder = f.relative_to(root).parts[0]
        normalised = normalize_points(pts, what=str(f))
        scans.append(RealScan(points=normalised, label=label_map.get(folder, folder), source=str(f),
                              dataset=dataset, extent_m=pts.max(axis=0) - pts.min(axis=0),
                              points_sensor_m=np.asarray(pts, dtype=np.float64)))  # fmt: skip
    if few:
        log.info("real scans: %d files under %s have fewer than %d points", few, root, min_points)
    if not scans:
        raise InvalidInputError(f"real scans: no scan with {min_points} or more points under {root}")
    return scans
