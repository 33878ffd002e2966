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
import hashlib
import io
import logging
import os
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.scene import up_rotation
from zbuf_occlude.real_scans.records import RealScan, normalize_points

__all__ = ["POINT_EXTENSIONS", "UNITS_M", "read_points", "units_to_m", "load_scan_folder"]

log = logging.getLogger(__name__)

#: File extensions :func:`read_points` reads.
POINT_EXTENSIONS = (".csv", ".txt", ".xyz", ".pts", ".ply", ".pcd", ".npy", ".npz", ".bin")
#: Unit names accepted by ``units`` (metres per unit).
UNITS_M = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048, "km": 1000.0}
#: Files larger than this are refused before reading (a scan of one object is kilobytes to megabytes).
MAX_FILE_BYTES = 1 << 30
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


def _rows_to_array(path: Path, rows: list[list[str]], columns: list[int] | None, first_line: int) -> NDArray[np.float64]:
    out = np.empty((len(rows), 3))
    for i, row in enumerate(rows):
        try:
            out[i] = [float(row[c]) for c in columns] if columns else [float(v) for v in row[:3]]
            if len(row) < 3:
                raise IndexError
        except (ValueError, IndexError):
            raise InvalidInputError(f"{path}:{first_line + i}: expected three numbers, got {row[:6]!r}") from None
    return out


def _split(line: str) -> list[str]:
    return [t for t in re.split(r"[,;\s]+", line.strip()) if t]


def _read_text_table(path: Path, text: str) -> NDArray[np.float64]:
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines())]
    lines = [(i, ln) for i, ln in lines if ln.strip() and not ln.lstrip().startswith(("#", "//"))]
    if not lines:
        raise InvalidInputError(f"{path}: no points")
    columns, start = None, 0
    first = _split(lines[0][1]) if path.suffix.lower() != ".csv" else next(csv.reader(io.StringIO(lines[0][1])))
    if path.suffix.lower() == ".csv" and len(first) < 3:
        first = _split(lines[0][1])
    if not all(_NUMBER.match(t.strip()) for t in first):
        columns, start = _xyz_columns(first), 1
        if columns is None:
            numeric = _split(lines[1][1]) if len(lines) > 1 else []
            columns = [j for j, t in enumerate(numeric) if _NUMBER.match(t)][:3] or None
    elif len(first) == 1 and len(lines) > 1:  # a .pts count line
        start = 1
    rows = [_split(ln) for _, ln in lines[start:]]
    if not rows:
        raise InvalidInputError(f"{path}: a header and no points")
    return _rows_to_array(path, rows, columns, lines[start][0])


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
        n = int(header.get("POINTS", [0])[0]) or int(header["WIDTH"][0]) * int(header.get("HEIGHT", ["1"])[0])
        sizes = [int(s) for s in header.get("SIZE", ["4"] * len(fields))]
        types = header.get("TYPE", ["F"] * len(fields))
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
    except (KeyError, ValueError, IndexError):
        raise InvalidInputError(f"{path}: PCD header lacks FIELDS/POINTS or has non-numeric sizes ({header})") from None
    if not all(a in fields for a in "xyz"):
        raise InvalidInputError(f"{path}: PCD fields {fields} have no x y z")
    if not (len(sizes) == len(types) == len(counts) == len(fields)) or n < 0:
        raise InvalidInputError(f"{path}: PCD header's FIELDS, SIZE, TYPE and COUNT disagree")
    mode = header["DATA"][0].lower() if header["DATA"] else ""
    if mode == "ascii":
        table = np.array([_split(ln) for ln in raw[pos:].decode("latin-1").splitlines() if ln.strip()], dtype=object)
        offsets = np.cumsum([0] + counts)
        try:
            cols = [np.asarray(table[:, offsets[fields.index(a)]], dtype=np.float64) for a in "xyz"] if len(table) else [np.zeros(0)] * 3
        except (ValueError, IndexError):
            raise InvalidInputError(f"{path}: PCD ascii rows are not numbers in the header's layout") from None
        return np.stack(cols, axis=1)
    if mode != "binary":
        raise InvalidInputError(f"{path}: PCD DATA {mode or '(none)'} is not supported (ascii or binary; convert binary_compressed with pcl_convert_pcd_ascii_binary)")
    try:
        dtype = np.dtype([(f, _PCD_TYPES[(t.upper(), s)], (c,)) for f, s, t, c in zip(fields, sizes, types, counts)])
    except (KeyError, TypeError, ValueError):
        raise InvalidInputError(f"{path}: PCD field types {list(zip(types, sizes))} not supported") from None
    body = raw[pos:]
    if len(body) < n * dtype.itemsize:
        raise InvalidInputError(f"{path}: PCD declares {n} points ({n * dtype.itemsize} bytes) but holds {len(body)} bytes")
    rec = np.frombuffer(body, dtype=dtype, count=n)
    return np.stack([rec[a][:, 0].astype(np.float64) for a in "xyz"], axis=1)


def _from_array(path: Path, arr: np.ndarray) -> NDArray[np.float64]:
    if arr.dtype.names and all(a in arr.dtype.names for a in "xyz"):
        return np.stack([np.asarray(arr[a], np.float64).reshape(-1) for a in "xyz"], axis=1)
    if arr.ndim != 2 or arr.shape[1] < 3 or not np.issubdtype(arr.dtype, np.number):
        raise InvalidInputError(f"{path}: expected an (N, >=3) numeric array, got shape {arr.shape} dtype {arr.dtype}")
    return np.asarray(arr[:, :3], dtype=np.float64)


def _read_npz(path: Path) -> NDArray[np.float64]:
    with np.load(path, allow_pickle=False) as z:
        for key in ("points", "xyz", "data"):
            if key in z.files:
                return _from_array(path, z[key])
        arrays = [z[k] for k in z.files]
    fits = [a for a in arrays if a.ndim == 2 and a.shape[1] >= 3]
    if len(fits) != 1:
        raise InvalidInputError(f"{path}: no array named points/xyz/data and {len(fits)} (N, >=3) arrays; name one 'points'")
    return _from_array(path, fits[0])


def read_points(path: str | os.PathLike) -> NDArray[np.float64]:
    """The ``(N, 3) float64`` coordinates of one point-cloud file, as stored (module docstring).

    Raises
    ------
    InvalidInputError
        Naming the file: missing, too large, unknown extension, malformed content,
        non-finite coordinates or no point.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in POINT_EXTENSIONS:
        raise InvalidInputError(f"{path}: unsupported point-cloud extension {path.suffix!r}; use one of {', '.join(POINT_EXTENSIONS)}")
    try:
        if not path.is_file():
            raise InvalidInputError(f"{path}: no such file")
        if path.stat().st_size > MAX_FILE_BYTES:
            raise InvalidInputError(f"{path}: {path.stat().st_size:,} bytes, more than the {MAX_FILE_BYTES:,} a scan may have")
        if suffix in (".npy", ".npz"):
            pts = _from_array(path, np.load(path, allow_pickle=False)) if suffix == ".npy" else _read_npz(path)
        elif suffix == ".ply":
            import trimesh

            pts = np.asarray(trimesh.load(path, file_type="ply", process=False).vertices, dtype=np.float64)
        else:
            raw = path.read_bytes()
            if suffix == ".bin":
                if len(raw) % (4 * _KITTI_RECORD.itemsize):
                    raise InvalidInputError(f"{path}: {len(raw)} bytes is not a whole number of 16-byte KITTI records (float32 x y z r)")
                pts = np.frombuffer(raw, dtype=_KITTI_RECORD).reshape(-1, 4)[:, :3].astype(np.float64)
            elif suffix == ".pcd":
                pts = _read_pcd(path, raw)
            else:
                pts = _read_text_table(path, raw.decode("utf-8", errors="replace"))
    except InvalidInputError:
        raise
    except OSError as exc:
        raise InvalidInputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except Exception as exc:  # numpy/trimesh raise many types on hostile bytes
        raise InvalidInputError(f"{path}: cannot parse as {suffix[1:].upper()} ({type(exc).__name__}: {exc})") from None
    if len(pts) == 0:
        raise InvalidInputError(f"{path}: no points")
    if not np.isfinite(pts).all():
        raise InvalidInputError(f"{path}: {int((~np.isfinite(pts)).any(axis=1).sum())} points have NaN or inf coordinates")
    return pts


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
        ``root`` not a folder, no scan file in a class folder, a bad ``up``/``units``, or a
        file that cannot be read (named).
    """
    root = Path(root)
    if not root.is_dir():
        raise InvalidInputError(f"real scans: {root} is not a folder")
    rot = up_rotation(up)[:3, :3]
    scale = units_to_m(units)
    label_map = dict(label_map or {})
    files = sorted(p for p in root.rglob("*") if p.suffix.lower() in POINT_EXTENSIONS and p.is_file()
                   and len(p.relative_to(root).parts) >= 2 and p.name != "MANIFEST.csv")  # fmt: skip
    if not files:
        raise InvalidInputError(f"real scans: no {'/'.join(POINT_EXTENSIONS)} files in class folders under {root}")
    seen, scans, few = set(), [], 0
    for f in files:
        if dedupe:
            digest = hashlib.md5(f.read_bytes()).hexdigest()
            if digest in seen:
                continue
            seen.add(digest)
        pts = read_points(f) @ rot.T * scale
        if len(pts) < min_points:
            few += 1
            continue
        folder = f.relative_to(root).parts[0]
        try:
            normalised = normalize_points(pts)
        except InvalidInputError as exc:
            raise InvalidInputError(f"{f}: {exc}") from None
        scans.append(RealScan(points=normalised, label=label_map.get(folder, folder), source=str(f),
                              dataset=dataset, extent_m=pts.max(axis=0) - pts.min(axis=0)))  # fmt: skip
    if few:
        log.info("real scans: %d files under %s have fewer than %d points", few, root, min_points)
    if not scans:
        raise InvalidInputError(f"real scans: no scan with {min_points} or more points under {root}")
    return scans
