"""LAS and LAZ point clouds from anyone, read with their per-return fields; LAS/LAZ bytes written in memory.

:func:`read_las` reads a LAS file (ASPRS LAS 1.4 specification R15, 2019; 1.0 to 1.3 read too) or
a LAZ file (the same, its points compressed by LASzip) as untrusted input:

* the file is opened by :func:`~zbuf_occlude.io.regular_files.open_regular_file`: a regular file,
  of at most ``max_bytes``, inside ``within`` once links are resolved;
* its structure is checked before laspy and lazrs (laz-rs) read it (:mod:`.las_layout`: the public
  header, the VLRs and EVLRs, the declared point count, the LASzip VLR's items and the chunks
  against the chunk table and the file's bytes), so that a forged count, chunk size or item is
  refused before anything is decompressed, and nothing from Rust reaches stderr;
* the memory the points will take is checked (:func:`~zbuf_occlude.resources.check_memory`)
  before it is allocated; points are decoded :data:`READ_CHUNK_POINTS` at a time, a LAZ file's
  arrays grow as its points are decoded (its count is not backed by its bytes, a LAS file's is),
  and NaN or infinite coordinates and GPS times are refused.

Every failure, laspy's and lazrs's included, is one :class:`~zbuf_occlude.errors.InvalidInputError`
line naming the file.  :func:`las_bytes` encodes points as LAS 1.4 (or LAZ) bytes in memory, for
the layer's writers to write.
"""

from __future__ import annotations

import io
import json
import math
import os
import struct
from dataclasses import dataclass
from os import PathLike
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude._version import __version__
from zbuf_occlude.defaults import MAX_POINTS
from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError, ZbufOccludeError
from zbuf_occlude.geometry.arguments import check_flag, check_points, described
from zbuf_occlude.io.caps import MAX_LAS_BYTES, MAX_VLR_RECORD_BYTES
from zbuf_occlude.io.file_errors import parser_failure
from zbuf_occlude.io.las_crs import epsg_crs, linear_unit_m
from zbuf_occlude.io.las_layout import (
    MAX_EVLRS,
    MAX_LAZ_POINTS_PER_BYTE,
    MAX_VLRS,
    LasLayout,
    check_count,
    check_laz,
    parse_header,
)
from zbuf_occlude.io.regular_files import open_regular_file
from zbuf_occlude.resources import check_memory

__all__ = [
    "BYTES_PER_POINT", "CLASS_NAMES_RECORD_ID", "CLASS_NAMES_USER_ID", "EXTRA_BYTES", "MAX_EVLRS", "MAX_LAZ_POINTS_PER_BYTE", "MAX_VLRS",
    "READ_CHUNK_POINTS", "SCAN_ANGLE_STEP_DEG", "LasPoints", "SurveyFields", "epsg_crs", "las_bytes", "read_las",
]  # fmt: skip

#: Points decoded at a time: bounds laspy's buffer of raw records (64 MiB of format-10 records).
READ_CHUNK_POINTS = 1 << 20
#: Degrees per unit of the scan angle of point formats 6 to 10 (R15, "Scan Angle").
SCAN_ANGLE_STEP_DEG = 0.006
#: Bytes per point of a :class:`LasPoints`: xyz float64, intensity and point source uint16,
#: gps_time float64, scan angle float32, return number, number of returns, class and channel uint8.
BYTES_PER_POINT = 3 * 8 + 2 + 2 + 8 + 4 + 4 * 1

#: Bytes per point of a decoded chunk beside its raw records: laspy's scaled x, y, z (float64) and
#: their stacked copy (tracemalloc: 5.05 MB read the 37,805 points of the IGN sample, as counted).
_DECODED_XYZ_BYTES = 2 * 3 * 8
#: Point formats whose records hold a GPS time (R15, §2.6).
_FORMATS_WITH_GPS_TIME = {1, 3, 4, 5, 6, 7, 8, 9, 10}


def _decode_errors() -> tuple[type[BaseException], ...]:
    from laspy.errors import LaspyException
    from lazrs import LazrsError

    # struct.error, EOFError and OSError: a truncated file; ValueError, IndexError, KeyError and
    # UnicodeDecodeError: laspy's parsers on damaged records
    return (LaspyException, LazrsError, OSError, EOFError, ValueError, IndexError, KeyError, struct.error)


@dataclass(frozen=True, eq=False)
class LasPoints:
    """The points of a LAS/LAZ file, with what a scanner records per return (ASPRS LAS 1.4 R15, §2.6).

    Arrays are read-only; ``N`` is the number of points.

    Attributes
    ----------
    points : (N, 3) float64
        x, y, z: the stored integers times the header's scale plus its offset, in the file's
        coordinate reference system and unit (:attr:`linear_unit_m`).
    intensity : (N,) uint16
        Pulse return magnitude, as the scanner stored it (R15 normalises it to 0–65535).
    return_number : (N,) uint8
        1 for a pulse's first return, up to 15 (5 in formats 0 to 5); 0 is invalid but kept.
    number_of_returns : (N,) uint8
        Returns the scanner recorded for the pulse of this point.
    gps_time : (N,) float64
        Seconds: GPS week time, or adjusted standard GPS time where the header's global encoding
        bit 0 is set; the returns of one pulse share it.  Zeros where the format has none
        (:attr:`has_gps_time` False); never NaN.
    scan_angle_deg : (N,) float32
        Degrees from nadir, positive to the right of the flight direction: the scan angle rank
        (formats 0 to 5, whole degrees) or the scan angle times 0.006° (formats 6 to 10).
    classification : (N,) uint8
        ASPRS class (2 ground, 3/4/5 low/medium/high vegetation, 6 building, ...).
    point_source_id : (N,) uint16
        The flight line (or other source) of each point.
    scanner_channel : (N,) uint8
        The channel of a multi-channel scanner (formats 6 to 10; zeros before).
    has_gps_time : bool
    point_format_id : int
        0 to 10.
    version : str
        ``"1.4"``, ...
    linear_unit_m : float
        Metres per coordinate unit, from the file's WKT or GeoTIFF keys (0.3048 for feet); NaN
        where the file does not say.

    Raises
    ------
    InvalidInputError
        Built by hand with arrays of other lengths or non-finite points or times.
    """

    points: NDArray[np.float64]
    intensity: NDArray[np.uint16]
    return_number: NDArray[np.uint8]
    number_of_returns: NDArray[np.uint8]
    gps_time: NDArray[np.float64]
    scan_angle_deg: NDArray[np.float32]
    classification: NDArray[np.uint8]
    point_source_id: NDArray[np.uint16]
    scanner_channel: NDArray[np.uint8]
    has_gps_time: bool = True
    point_format_id: int = 6
    version: str = "1.4"
    linear_unit_m: float = math.nan

    _DTYPES: ClassVar[dict[str, type]] = {"intensity": np.uint16, "return_number": np.uint8, "number_of_returns": np.uint8, "gps_time": np.float64,
               "scan_angle_deg": np.float32, "classification": np.uint8, "point_source_id": np.uint16,
               "scanner_channel": np.uint8}  # fmt: skip

    def __post_init__(self) -> None:
        points = check_points(self.points)
        points.flags.writeable = False
        object.__setattr__(self, "points", points)
        for name, dtype in self._DTYPES.items():
            array = np.array(getattr(self, name), dtype=dtype)  # a copy: the caller's arrays stay theirs
            if array.shape != (len(points),):
                raise InvalidInputError(f"LasPoints: {name} must have shape ({len(points)},), got {array.shape}")
            array.flags.writeable = False
            object.__setattr__(self, name, array)
        if not np.all(np.isfinite(self.gps_time)):
            raise InvalidInputError(f"LasPoints: gps_time holds {int((~np.isfinite(self.gps_time)).sum())} NaN/inf values")

    def __len__(self) -> int:
        return len(self.points)

    @property
    def metres_per_unit(self) -> float:
        """Metres per coordinate unit: :attr:`linear_unit_m`, or 1 (metres assumed) where the file does not say."""
        return self.linear_unit_m if math.isfinite(self.linear_unit_m) else 1.0


def _reserve(out: dict[str, np.ndarray], n: int) -> dict[str, np.ndarray]:
    """``out``'s arrays (or new ones) grown to ``n`` points, new entries zero (``ndarray.resize``: a realloc, no copy)."""
    if not out:
        return {"points": np.zeros((n, 3), np.float64), **{key: np.zeros(n, dtype) for key, dtype in LasPoints._DTYPES.items()}}
    for key, array in out.items():
        array.resize((n, 3) if key == "points" else (n,), refcheck=False)  # only this dict refers to them
    return out


def _read_points(reader: Any, layout: LasLayout, name: str) -> dict[str, np.ndarray]:
    """The decoded fields of the file's points, reserved as the file backs them.

    A LAS file's records fit its bytes (:func:`~zbuf_occlude.io.las_layout.check_count`): all are
    reserved at once.  A LAZ file's declared count is bounded only by a compression ratio
    (:data:`MAX_LAZ_POINTS_PER_BYTE`), so its arrays grow (doubling, up to the count) as points are
    decoded: a forged count costs the memory of the points the file really decodes to.
    """
    n = layout.count
    capacity = min(n, READ_CHUNK_POINTS) if layout.compressed else n
    out = _reserve({}, capacity)
    dims = set(reader.header.point_format.dimension_names)
    done = 0
    while done < n:
        if done == capacity:
            capacity = min(n, 2 * capacity)
            out = _reserve(out, capacity)
        rec = reader.read_points(min(READ_CHUNK_POINTS, capacity - done))
        got = len(rec)
        if got == 0:
            raise InvalidInputError(f"{name}: truncated: {done:,} of {n:,} points read")
        part = slice(done, done + got)
        with np.errstate(over="ignore", invalid="ignore"):  # a huge scale overflows: refused below, naming the file
            out["points"][part] = np.stack([np.asarray(rec.x), np.asarray(rec.y), np.asarray(rec.z)], axis=1)
        for key in ("intensity", "return_number", "number_of_returns", "classification", "point_source_id"):
            out[key][part] = np.asarray(rec[key])
        if "gps_time" in dims:
            out["gps_time"][part] = np.asarray(rec["gps_time"])
        if "scanner_channel" in dims:
            out["scanner_channel"][part] = np.asarray(rec["scanner_channel"])
        if "scan_angle" in dims:
            out["scan_angle_deg"][part] = np.asarray(rec["scan_angle"], np.float32) * np.float32(SCAN_ANGLE_STEP_DEG)
        else:
            out["scan_angle_deg"][part] = np.asarray(rec["scan_angle_rank"])
        done += got
    for key in ("points", "gps_time"):
        bad = int(np.count_nonzero(~np.isfinite(out[key]) if key == "gps_time" else ~np.isfinite(out[key]).all(axis=1)))
        if bad:
            raise InvalidInputError(f"{name}: {bad:,} points have a NaN or infinite {'coordinate' if key == 'points' else key}")
    return out


def read_las(
    path: str | PathLike[str],
    *,
    within: str | PathLike[str] | None = None,
    max_points: int = MAX_POINTS,
    max_bytes: int = MAX_LAS_BYTES,
) -> LasPoints:
    """The points of a LAS or LAZ file, with their per-return fields, read as untrusted input (module docstring).

    Parameters
    ----------
    path : str or PathLike
        A ``.las`` or ``.laz`` file, LAS 1.0 to 1.4, point format 0 to 10.
    within : str or PathLike, optional
        The folder ``path`` was named from: it must stay inside it, links resolved.
    max_points : int
        Most points the header may declare (default :data:`~zbuf_occlude.defaults.MAX_POINTS`).
    max_bytes : int
        Largest file read (default :data:`~zbuf_occlude.io.caps.MAX_LAS_BYTES`).

    Returns
    -------
    LasPoints
        Fields as the ASPRS LAS 1.4 specification R15 defines them (§2.6, "Point Data Records").

    Raises
    ------
    ArgumentTypeError
        ``path`` or ``within`` is not a path, or a cap is not a whole number.
    InvalidInputError
        Naming the file, in one line: missing, not a regular file, too large, not LAS/LAZ, a header,
        VLR, EVLR or LAZ chunk that declares more than the file holds, more points than
        ``max_points``, truncated or damaged points, NaN GPS times.
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    InsufficientMemoryError
        The points would need more memory than is available.
    """
    import laspy

    if not isinstance(path, (str, PathLike)):
        raise ArgumentTypeError(f"path must be a LAS/LAZ file's path (str or os.PathLike), got {described(path)}")
    if within is not None and not isinstance(within, (str, PathLike)):
        raise ArgumentTypeError(f"within must be a folder's path (str or os.PathLike) or None, got {described(within)}")
    for cap, value in (("max_points", max_points), ("max_bytes", max_bytes)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ArgumentTypeError(f"{cap} must be a whole number >= 0, got {described(value)}")
    name = os.fsdecode(path)
    fh, size = open_regular_file(path, max_bytes=max_bytes, error=InvalidInputError, within=within)
    with fh:
        try:
            layout = parse_header(fh, size, name)
            check_count(layout, size, name, max_points)
            chunk_bytes = check_laz(fh, layout, size, name) if layout.compressed else 0
            raw_bytes = min(layout.count, READ_CHUNK_POINTS) * (layout.record_length + _DECODED_XYZ_BYTES)
            check_memory(layout.count * BYTES_PER_POINT + raw_bytes + chunk_bytes, option=f"reading {name} ({layout.count:,} points)",
                         hint="read a smaller tile or a crop")  # fmt: skip
            fh.seek(0)
            reader = laspy.LasReader(fh, closefd=False, laz_backend=laspy.LazBackend.Lazrs, read_evlrs=False)
            arrays = _read_points(reader, layout, name)
            unit = linear_unit_m(reader.header)
        except ZbufOccludeError:
            raise
        except _decode_errors() as exc:
            raise InvalidInputError(f"{name}: not a readable LAS/LAZ file ({parser_failure(exc)})") from None
        except BaseException as exc:  # a Rust panic inside lazrs (pyo3's PanicException derives from BaseException)
            if type(exc).__name__ != "PanicException":
                raise
            raise InvalidInputError(f"{name}: damaged LAZ data ({parser_failure(exc)})") from None
    return LasPoints(**arrays, has_gps_time=layout.point_format_id in _FORMATS_WITH_GPS_TIME, point_format_id=layout.point_format_id,
                     version=f"{layout.version[0]}.{layout.version[1]}", linear_unit_m=unit)  # fmt: skip


def _per_point(value: Any, name: str, n: int, *, kinds: str, low: float, high: float, dtype: type, width: int = 0) -> np.ndarray:
    """``value`` as ``(n,)`` (or ``(n, width)``) ``dtype``, every value finite and in ``[low, high]``."""
    if isinstance(value, (str, bytes, PathLike, dict)) or value is None:
        raise ArgumentTypeError(f"{name} must be a numeric array, got {described(value)}")
    try:
        array = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be a numeric array: {exc}") from None
    if array.dtype.kind not in kinds and not (array.size == 0 and array.dtype.kind == "f"):  # [] is float64
        want = "integers (round first)" if kinds == "iu" else "numbers"
        raise ArgumentTypeError(f"{name} must be {want}, got dtype {array.dtype}")
    shape = (n, width) if width else (n,)
    if array.shape != shape:
        raise InvalidInputError(f"{name} must have shape {shape}, got {array.shape}")
    if array.size and not (np.all(np.isfinite(array)) and array.min() >= low and array.max() <= high):
        raise InvalidInputError(f"{name} must be finite and within [{low:g}, {high:g}], got values in [{array.min()}, {array.max()}]")
    return array.astype(dtype)


def _scaled(points: NDArray[np.float64], scale: Any) -> tuple[np.ndarray, NDArray[np.int32]]:
    """Offsets (multiples of ``scale`` near the points' centre) and the int32 coordinates of ``points``."""
    if isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating)):
        raise ArgumentTypeError(f"scale must be a number, got {described(scale)}")
    if not (math.isfinite(scale) and scale > 0):
        raise InvalidInputError(f"scale must be finite and > 0, got {scale}")
    scale = float(scale)
    centre = (points.min(axis=0) + points.max(axis=0)) / 2.0 if len(points) else np.zeros(3)
    offsets = np.round(centre / scale) * scale
    stored = np.round((points - offsets) / scale)
    limit = np.iinfo(np.int32).max
    if stored.size and np.abs(stored).max() > limit:
        extent = float((points.max(axis=0) - points.min(axis=0)).max())
        raise InvalidInputError(f"points span {extent:.6g} units: LAS stores int32 multiples of scale={scale:g}, at most "
                                f"{2 * limit * scale:.6g} across; use a larger scale")  # fmt: skip
    return offsets, stored.astype(np.int32)


#: Extra bytes :func:`las_bytes` may add to each point record: name → (dtype, the Extra Bytes
#: VLR's description, at most 32 characters).
EXTRA_BYTES = {
    "object_id": (np.dtype(np.int32), "scene object id (0: the ground)"),
    "class_index": (np.dtype(np.uint16), "index into the class names VLR"),
}
#: The VLR that holds the class names ``class_index`` indexes: its user id and record id; its
#: record is a UTF-8 JSON array of strings.
CLASS_NAMES_USER_ID, CLASS_NAMES_RECORD_ID = "zbuf_occlude", 1
#: The class names VLR's description (a VLR's description field holds 32 bytes, NUL-terminated).
CLASS_NAMES_DESCRIPTION = "names of class_index (JSON)"


@dataclass(frozen=True)
class SurveyFields:
    """What :func:`las_bytes` writes beside the points' standard fields, as a survey's file holds it.

    Attributes
    ----------
    object_id : (N,) int, optional
        Written as the extra bytes ``object_id`` (int32): the scene object each point lies on.
    class_index : (N,) int, optional
        Written as the extra bytes ``class_index`` (uint16), each ``< len(class_names)``; needs
        ``class_names``.
    class_names : sequence of str, optional
        The names ``class_index`` indexes, written to the class names VLR (UTF-8 JSON, at most
        65,535 bytes).
    adjusted_standard_gps_time : bool
        ``gps_time`` is adjusted standard GPS time (global encoding bit 0 set); default False, GPS
        week time.
    crs : int or str, optional
        The coordinate reference system of the points: an EPSG code (``2154``, ``"EPSG:2154"``,
        ``"EPSG:2154+5720"``) of a projected CRS in metres, or of one compound with a vertical CRS
        in metres (:func:`~zbuf_occlude.io.las_crs.epsg_crs`), written as OGC WKT (pyproj makes it:
        the ``crs`` extra).
    scale : float
        Metres (units) per stored integer step of the coordinates, > 0 (default 1 mm).
    """

    object_id: Any = None
    class_index: Any = None
    class_names: Sequence[str] | None = None
    adjusted_standard_gps_time: bool = False
    crs: int | str | None = None
    scale: float = 0.001


def _extra_bytes(n: int, object_id: Any, class_index: Any, class_names: Sequence[str] | None) -> dict[str, np.ndarray]:
    """The extra bytes of :func:`las_bytes`, checked: name → ``(n,)`` array of :data:`EXTRA_BYTES`' dtype."""
    out = {}
    if object_id is not None:
        info = np.iinfo(np.int32)
        out["object_id"] = _per_point(object_id, "object_id", n, kinds="iu", low=info.min, high=info.max, dtype=np.int32)
    if (class_index is None) != (class_names is None):
        raise InvalidInputError("class_index and class_names go together: give both or neither")
    if class_names is not None:
        if (
            not isinstance(class_names, Sequence)
            or isinstance(class_names, (str, bytes))
            or not all(isinstance(n, str) for n in class_names)
        ):
            raise ArgumentTypeError(f"class_names must be a sequence of str, got {described(class_names)}")
        high = min(len(class_names), 65536) - 1
        if high < 0 and n:
            raise InvalidInputError("class_names is empty: class_index has nothing to index")
        out["class_index"] = _per_point(class_index, "class_index", n, kinds="iu", low=0, high=max(high, 0), dtype=np.uint16)
    return out


def _names_json(class_names: Sequence[str]) -> bytes:
    """``class_names`` as the record of the class names VLR: a UTF-8 JSON array."""
    data = json.dumps(list(class_names), ensure_ascii=False).encode("utf-8")
    if len(data) > MAX_VLR_RECORD_BYTES:
        raise InvalidInputError(f"class_names take {len(data):,} bytes as JSON; a VLR holds at most {MAX_VLR_RECORD_BYTES:,}")
    return data


def las_bytes(
    points: Any,
    *,
    intensity: Any,
    return_number: Any,
    number_of_returns: Any,
    gps_time: Any,
    scan_angle_deg: Any,
    point_source_id: Any = None,
    classification: Any = None,
    rgb: Any = None,
    compress: bool = False,
    survey: SurveyFields | None = None,
) -> bytes:
    """Points and their per-return fields as the bytes of a LAS 1.4 file (LAZ with ``compress``), in memory.

    Point format 6, or 7 with ``rgb`` (ASPRS LAS 1.4 specification R15, §2.6).  The global
    encoding's WKT bit is set, as formats 6 to 10 require; the header holds a WKT VLR
    (``LASF_Projection``, record 2112) with ``crs``, else no coordinate reference system.  The
    global encoding's bit 0 (GPS time type) is set with ``adjusted_standard_gps_time``: the times
    are then adjusted standard GPS time (GPS seconds − 10⁹); else GPS week time, seconds as given.
    With ``object_id`` or ``class_index`` (:class:`SurveyFields`), each point record carries extra
    bytes, described by the Extra Bytes VLR (``LASF_Spec``, record 4) that laspy reads:
    ``object_id`` int32 and ``class_index`` uint16, and a VLR :data:`CLASS_NAMES_USER_ID` /
    :data:`CLASS_NAMES_RECORD_ID` holds ``class_names`` as a UTF-8 JSON array
    (``class_names[class_index]`` is a point's class).
    The offsets are multiples of the survey's ``scale`` near the points' centre, so every coordinate reads back
    within ``scale / 2``.  The header's creation date is today's.  Write the bytes through the
    layer (:meth:`~zbuf_occlude.io.owned.OwnedFolder.write_bytes`).

    Parameters
    ----------
    points : (N, 3) float
        x, y, z, finite, in the unit the reader will assume (metres for a scan).
    intensity : (N,) int
        0 to 65535.
    return_number, number_of_returns : (N,) int
        1 to 15, ``return_number <= number_of_returns``.
    gps_time : (N,) float
        Seconds, finite; the returns of one pulse share it.
    scan_angle_deg : (N,) float
        Degrees from nadir, positive to the right of the flight direction, within ±180; stored in
        steps of 0.006°.
    point_source_id : (N,) int, optional
        0 to 65535 (default 0: one source).
    classification : (N,) int, optional
        ASPRS class 0 to 255 (default 0: created, never classified).
    rgb : (N, 3) int, optional
        Red, green, blue, 0 to 65535; selects point format 7.
    compress : bool
        LAZ (LASzip through lazrs) instead of LAS.
    survey : SurveyFields, optional
        Object ids, class indices and names, the GPS time type, the CRS and the coordinates' scale (default: none of
        them, GPS week time, 1 mm steps).

    Returns
    -------
    bytes
        The whole file.

    Raises
    ------
    ArgumentTypeError
        An argument of the wrong kind (text, floats where integers go, a non-bool ``compress``).
    InvalidInputError
        A shape other than ``(N,)``/``(N, 3)``, a value out of range, ``return_number`` above
        ``number_of_returns``, points too far apart for int32 steps of ``scale``, ``class_index``
        without ``class_names`` (or beyond them), class names over a VLR's 65,535 bytes, a ``crs``
        that :func:`~zbuf_occlude.io.las_crs.epsg_crs` refuses (not a projected CRS in metres).
    BackendUnavailable
        ``crs`` given and pyproj not installed (the extra to install is named).
    """
    import laspy

    pts = check_points(points)
    n = len(pts)
    check_flag(compress, "compress")
    returns = _per_point(return_number, "return_number", n, kinds="iu", low=1, high=15, dtype=np.uint8)
    count = _per_point(number_of_returns, "number_of_returns", n, kinds="iu", low=1, high=15, dtype=np.uint8)
    if np.any(returns > count):
        raise InvalidInputError(f"return_number exceeds number_of_returns at {int((returns > count).sum()):,} points "
                                f"(first at index {int(np.argmax(returns > count))})")  # fmt: skip
    fields_ = {
        "intensity": _per_point(intensity, "intensity", n, kinds="iu", low=0, high=65535, dtype=np.uint16),
        "gps_time": _per_point(gps_time, "gps_time", n, kinds="iuf", low=-np.inf, high=np.inf, dtype=np.float64),
        "scan_angle": np.round(_per_point(scan_angle_deg, "scan_angle_deg", n, kinds="iuf", low=-180, high=180, dtype=np.float64)
                               / SCAN_ANGLE_STEP_DEG).astype(np.int16),
        "point_source_id": np.zeros(n, np.uint16) if point_source_id is None else
        _per_point(point_source_id, "point_source_id", n, kinds="iu", low=0, high=65535, dtype=np.uint16),
        "classification": np.zeros(n, np.uint8) if classification is None else
        _per_point(classification, "classification", n, kinds="iu", low=0, high=255, dtype=np.uint8),
        "return_number": returns, "number_of_returns": count,
    }  # fmt: skip
    colours = None if rgb is None else _per_point(rgb, "rgb", n, kinds="iu", low=0, high=65535, dtype=np.uint16, width=3)
    survey = SurveyFields() if survey is None else survey
    if not isinstance(survey, SurveyFields):
        raise ArgumentTypeError(f"survey must be a SurveyFields or None, got {described(survey)}")
    check_flag(survey.adjusted_standard_gps_time, "adjusted_standard_gps_time")
    extra = _extra_bytes(n, survey.object_id, survey.class_index, survey.class_names)
    wkt_crs = None if survey.crs is None else epsg_crs(survey.crs)
    offsets, stored = _scaled(pts, survey.scale)
    header = laspy.LasHeader(version="1.4", point_format=6 if colours is None else 7)
    header.scales, header.offsets = np.full(3, float(survey.scale)), offsets
    header.global_encoding.wkt = True
    if survey.adjusted_standard_gps_time:
        header.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
    header.generating_software = f"zbuf_occlude {__version__}"
    if wkt_crs is not None:
        header.add_crs(wkt_crs)
    if extra:
        header.add_extra_dims([laspy.ExtraBytesParams(name=key, type=values.dtype, description=EXTRA_BYTES[key][1])
                               for key, values in extra.items()])  # fmt: skip
    if survey.class_names is not None:
        header.vlrs.append(laspy.VLR(CLASS_NAMES_USER_ID, CLASS_NAMES_RECORD_ID, CLASS_NAMES_DESCRIPTION,
                                     _names_json(survey.class_names)))  # fmt: skip
    las = laspy.LasData(header)
    las.X, las.Y, las.Z = stored[:, 0], stored[:, 1], stored[:, 2]
    for key, values in fields_.items():
        las[key] = values
    if colours is not None:
        las.red, las.green, las.blue = colours[:, 0], colours[:, 1], colours[:, 2]
    for key, values in extra.items():
        las[key] = values
    las.update_header()
    buffer = io.BytesIO()
    las.write(buffer, do_compress=bool(compress), laz_backend=laspy.LazBackend.Lazrs)
    return buffer.getvalue()
