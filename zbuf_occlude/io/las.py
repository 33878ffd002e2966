"""LAS and LAZ point clouds from anyone: the header, the records around the points and the LAZ chunks checked first.

A LAS file (ASPRS LAS 1.4 specification R15, 2019; 1.0 to 1.3 read too) is a public header, up to
2³² variable length records (VLRs), the point records, and in 1.4 extended VLRs (EVLRs) after them;
a LAZ file is the same with the points compressed by LASzip in chunks.  laspy decodes the records
and lazrs (laz-rs) decompresses the chunks; what they would read or allocate is checked here
first, on the open file, with :mod:`struct` (nothing is executed or unpickled):

* the file is opened by :func:`~zbuf_occlude.io.regular_files.open_regular_file`: a regular file,
  of at most ``max_bytes``, inside ``within`` once links are resolved;
* the **public header**: the ``LASF`` signature, version 1.0 to 1.4, a header size and an offset
  to the points consistent with the version and the file, point format 0 to 10 allowed by the
  version, a record length at least the format's, finite non-zero scales and finite offsets;
* the **VLRs**: at most :data:`MAX_VLRS`, each inside the bytes before the points, which laspy reads
  whole (at most :data:`MAX_HEADER_BYTES`); the **EVLRs**: at most :data:`MAX_EVLRS`, each inside
  the file; their contents (waveforms, a WKT, a COPC hierarchy) are never read;
* the **point count**: at most ``max_points``; uncompressed, the records it declares must fit
  between the offset to the points and the first EVLR (or the end); compressed, at most
  :data:`MAX_LAZ_POINTS_PER_BYTE` per byte of compressed data;
* the **LAZ chunks**: laz-rs allocates what the file declares before reading it: one entry per
  chunk the chunk table declares (2³² − 1 chunks are 64 GiB, and the process aborts), and each
  layer a chunk header declares in point formats 6 to 10 (up to 4 GiB each, however small the
  file).  So the chunk table may declare no more chunks than points, and the chunks are walked
  as laz-rs will read them: every layer must end inside the file;
* the memory the points will take is checked (:func:`~zbuf_occlude.resources.check_memory`)
  before it is allocated; points are decoded :data:`READ_CHUNK_POINTS` at a time.

Every failure, laspy's and lazrs's included, is one :class:`~zbuf_occlude.errors.InvalidInputError`
line naming the file.  :func:`las_bytes` encodes points as LAS 1.4 (or LAZ) bytes in memory, for
the layer's writers to write.
"""

from __future__ import annotations

import io
import math
import os
import re
import struct
from dataclasses import dataclass
from os import PathLike
from typing import Any, BinaryIO, ClassVar

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude._version import __version__
from zbuf_occlude.defaults import MAX_POINTS
from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError, ZbufOccludeError
from zbuf_occlude.geometry.arguments import check_points, described
from zbuf_occlude.io.regular_files import open_regular_file
from zbuf_occlude.resources import check_memory

__all__ = [
    "BYTES_PER_POINT", "MAX_EVLRS", "MAX_HEADER_BYTES", "MAX_LAS_BYTES", "MAX_LAZ_POINTS_PER_BYTE", "MAX_VLRS",
    "READ_CHUNK_POINTS", "SCAN_ANGLE_STEP_DEG", "LasPoints", "las_bytes", "read_las",
]  # fmt: skip

#: Largest LAS/LAZ file read: 16 GiB, :data:`~zbuf_occlude.defaults.MAX_POINTS` (10⁸) points of
#: the largest standard record (67 bytes, format 10) and some extra bytes per point.  A 1 km² tile
#: of a national survey holds 10 to 50 million points.
MAX_LAS_BYTES = 16 << 30
#: Most VLRs a file may declare: room for the 255 waveform packet descriptors the specification
#: allows (record ids 100 to 354) and the projection, LASzip, extra-bytes and text records; real
#: files hold a handful.
MAX_VLRS = 512
#: Most EVLRs a file may declare (a WKT, waveform data, a COPC hierarchy: a handful); only their
#: 60-byte headers are read, to check that each lies inside the file.
MAX_EVLRS = 1024
#: Most bytes before the first point (header, VLRs and any gap), which laspy reads into memory:
#: :data:`MAX_VLRS` records of at most 65,589 bytes (a 54-byte header and a uint16 length) are
#: 33.6 MB.
MAX_HEADER_BYTES = 64 << 20
#: Most points a LAZ file may declare per byte of compressed data: laz-rs packs a million
#: identical format-6 points into 10,463 bytes (96 per byte), real scans hold 0.1 to 1 point per
#: byte (the shared IGN and Autzen samples: 0.20 and 0.18).
MAX_LAZ_POINTS_PER_BYTE = 1000
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
#: Public header size of each LAS 1.x minor version (R15, "Public Header Block").
_HEADER_SIZES = {0: 227, 1: 227, 2: 227, 3: 235, 4: 375}
#: The fixed header up to the bounds (all versions), then 1.3's waveform start, then 1.4's fields.
_HEADER = struct.Struct("<4sHH16sBB32s32sHHHIIBHI5I3d3d6d")
_HEADER_14 = struct.Struct("<QQIQ")  # waveform start (1.3), first EVLR, number of EVLRs, points (1.4)
_VLR = struct.Struct("<H16sHH32s")  # reserved, user id, record id, length after header, description
_EVLR = struct.Struct("<H16sHQ32s")
#: Record length of each point format, and the LAS minor version that introduced it (R15, §2.6).
_RECORD_SIZES = {0: 20, 1: 28, 2: 26, 3: 34, 4: 57, 5: 63, 6: 30, 7: 36, 8: 38, 9: 59, 10: 67}
_FORMAT_MIN_MINOR = {0: 0, 1: 0, 2: 2, 3: 2, 4: 3, 5: 3, 6: 4, 7: 4, 8: 4, 9: 4, 10: 4}
_FORMATS_WITH_GPS_TIME = {1, 3, 4, 5, 6, 7, 8, 9, 10}
#: LASzip's VLR (user id, record id) and its fixed part: compressor, coder, version (3 fields),
#: options, chunk size, special EVLR count and offset, item count; then (type, size, version) items.
_LASZIP = (b"laszip encoded", 22204)
_LASZIP_VLR = struct.Struct("<HHBBHIIqqH")
_LASZIP_ITEM = struct.Struct("<HHH")
_VARIABLE_CHUNKS = 0xFFFFFFFF
#: LASzip compressors laz-rs reads: point-wise (one chunk), point-wise chunked, layered chunked.
_POINTWISE, _COMPRESSORS = 1, (1, 2, 3)
#: Item types of each kind of decompressor (laz-rs ``LazItemType``).
_POINTWISE_ITEMS, _LAYERED_ITEMS = (0, 6, 7, 8, 9), (10, 11, 12, 13, 14)
#: Bytes of each LASzip item type (laz-rs ``LazItemType``: 0 and 14 are extra bytes, sized by the VLR).
_ITEM_SIZES = {6: 20, 7: 8, 8: 6, 9: 29, 10: 30, 11: 6, 12: 8, 13: 29}
#: Layers of each layered item (point14: 9, RGB: 1, RGB+NIR: 2, waveform: 1; extra bytes: one per byte).
_ITEM_LAYERS = {10: 9, 11: 1, 12: 2, 13: 1}
#: EPSG codes of ProjLinearUnitsGeoKey (3076) → metres (metre, international foot, US survey foot).
_GEOKEY_UNITS_M = {9001: 1.0, 9002: 0.3048, 9003: 1200.0 / 3937.0}
_PROJECTED_WKT = ("PROJCS", "PROJCRS", "PROJECTEDCRS")
_WKT_MAX_DEPTH = 64
_WKT_TOKEN = re.compile(r'"((?:[^"]|"")*)"|([A-Za-z_][A-Za-z0-9_]*)\s*[\[(]|([\])])|([^,\[\]()"\s]+)')


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


@dataclass(frozen=True)
class _Layout:
    """What the header and the records around the points declare (checked)."""

    version: tuple[int, int]
    header_size: int
    offset: int
    point_format_id: int
    compressed: bool
    record_length: int
    count: int
    vlrs: tuple[tuple[bytes, int, int, int], ...]  # (user id, record id, body offset, body length)
    evlrs: int
    first_evlr: int


def _read_at(fh: BinaryIO, offset: int, n: int) -> bytes:
    fh.seek(offset)
    return fh.read(n)


def _parse_header(fh: BinaryIO, size: int, name: str) -> _Layout:
    head = _read_at(fh, 0, _HEADER_SIZES[4])
    if head[:4] != b"LASF":
        raise InvalidInputError(f"{name}: not a LAS/LAZ file (no LASF signature)")
    if len(head) < _HEADER.size:
        raise InvalidInputError(f"{name}: truncated LAS header ({len(head)} bytes)")
    h = _HEADER.unpack_from(head)
    major, minor, header_size, offset, n_vlrs, format_byte, record_length, count = h[4], h[5], *h[10:16]
    scales, offsets = np.array(h[21:24]), np.array(h[24:27])
    if major != 1 or minor not in _HEADER_SIZES:
        raise InvalidInputError(f"{name}: LAS version {major}.{minor}; versions 1.0 to 1.4 are read")
    if not _HEADER_SIZES[minor] <= header_size <= offset <= size:
        raise InvalidInputError(f"{name}: header size {header_size} and offset to points {offset} do not fit "
                                f"LAS {major}.{minor} in a file of {size:,} bytes")  # fmt: skip
    point_format_id, compressed = format_byte & 0x3F, bool(format_byte & 0x80)
    if format_byte & 0x40 or point_format_id not in _RECORD_SIZES or _FORMAT_MIN_MINOR[point_format_id] > minor:
        raise InvalidInputError(f"{name}: point format {format_byte} is not a format of LAS {major}.{minor}")
    if record_length < _RECORD_SIZES[point_format_id]:
        raise InvalidInputError(f"{name}: records of {record_length} bytes, fewer than point format {point_format_id}'s "
                                f"{_RECORD_SIZES[point_format_id]}")  # fmt: skip
    if not (np.all(np.isfinite(scales)) and np.all(scales != 0) and np.all(np.isfinite(offsets))):
        raise InvalidInputError(
            f"{name}: scale factors {scales.tolist()} or offsets {offsets.tolist()} are not finite and non-zero"
        )
    evlrs = first_evlr = 0
    if minor >= 4:
        if len(head) < _HEADER_SIZES[4]:
            raise InvalidInputError(f"{name}: truncated LAS 1.4 header ({len(head)} bytes)")
        _, first_evlr, evlrs, count = _HEADER_14.unpack_from(head, _HEADER.size)
    if n_vlrs > MAX_VLRS or evlrs > MAX_EVLRS:
        raise InvalidInputError(
            f"{name}: declares {n_vlrs:,} VLRs and {evlrs:,} EVLRs; at most {MAX_VLRS} and {MAX_EVLRS} are read"
        )
    if offset > MAX_HEADER_BYTES:
        raise InvalidInputError(f"{name}: {offset:,} bytes before the first point, more than the {MAX_HEADER_BYTES:,} read")
    vlrs = _walk_vlrs(fh, name, header_size, offset, n_vlrs)
    _walk_evlrs(fh, name, size, offset, first_evlr, evlrs)
    return _Layout(
        (major, minor), header_size, offset, point_format_id, compressed, record_length, count, vlrs, evlrs, first_evlr
    )


def _walk_vlrs(fh: BinaryIO, name: str, start: int, end: int, n: int) -> tuple[tuple[bytes, int, int, int], ...]:
    vlrs, position = [], start
    for i in range(n):
        raw = _read_at(fh, position, _VLR.size) if position + _VLR.size <= end else b""
        if len(raw) < _VLR.size:
            raise InvalidInputError(f"{name}: VLR {i + 1} of {n} does not fit before the points (byte {end:,})")
        _, user_id, record_id, length, _ = _VLR.unpack(raw)
        body = position + _VLR.size
        position = body + length
        if position > end:
            raise InvalidInputError(f"{name}: VLR {i + 1} of {n} ({length:,} bytes) runs past the first point (byte {end:,})")
        vlrs.append((user_id.rstrip(b"\0"), record_id, body, length))
    return tuple(vlrs)


def _walk_evlrs(fh: BinaryIO, name: str, size: int, offset: int, first: int, n: int) -> None:
    position = first
    if n and first < offset:
        raise InvalidInputError(f"{name}: its first EVLR (byte {first:,}) lies before its points (byte {offset:,})")
    for i in range(n):
        raw = _read_at(fh, position, _EVLR.size) if position + _EVLR.size <= size else b""
        if len(raw) < _EVLR.size:
            raise InvalidInputError(f"{name}: EVLR {i + 1} of {n} lies past the end of the file ({size:,} bytes)")
        position += _EVLR.size + _EVLR.unpack(raw)[3]
        if position > size:
            raise InvalidInputError(f"{name}: EVLR {i + 1} of {n} runs past the end of the file ({size:,} bytes)")


def _check_count(layout: _Layout, size: int, name: str, max_points: int) -> None:
    count, offset = layout.count, layout.offset
    if count > max_points:
        raise InvalidInputError(f"{name}: declares {count:,} points, more than max_points={max_points:,}; read a smaller tile")
    if layout.compressed:
        if count > (size - offset) * MAX_LAZ_POINTS_PER_BYTE:
            raise InvalidInputError(f"{name}: declares {count:,} points in {size - offset:,} bytes of LAZ data, more than "
                                    f"{MAX_LAZ_POINTS_PER_BYTE} per byte (damaged or forged)")  # fmt: skip
        return
    end = layout.first_evlr if layout.evlrs else size
    if offset + count * layout.record_length > end:
        raise InvalidInputError(f"{name}: declares {count:,} points of {layout.record_length} bytes after byte {offset:,}, "
                                f"{offset + count * layout.record_length:,} bytes, but its points end at byte {end:,} "
                                "(truncated or forged)")  # fmt: skip


def _laszip_items(fh: BinaryIO, layout: _Layout, name: str) -> tuple[bytes, int, int, list[tuple[int, int, int]]]:
    """The LASzip VLR's bytes, compressor, chunk size and ``(type, size, version)`` items, checked as laz-rs reads them."""
    found = [v for v in layout.vlrs if (v[0], v[1]) == _LASZIP]
    if not found:
        raise InvalidInputError(f"{name}: compressed points but no LASzip VLR")
    body = _read_at(fh, found[0][2], found[0][3])
    if len(body) < _LASZIP_VLR.size:
        raise InvalidInputError(f"{name}: the LASzip VLR is truncated")
    compressor, _, _, _, _, _, chunk_size, _, _, n_items = _LASZIP_VLR.unpack_from(body)
    if not 0 < n_items <= (len(body) - _LASZIP_VLR.size) // _LASZIP_ITEM.size:
        raise InvalidInputError(
            f"{name}: the LASzip VLR declares {n_items} items and holds {len(body) - _LASZIP_VLR.size} bytes of them"
        )
    items = [_LASZIP_ITEM.unpack_from(body, _LASZIP_VLR.size + i * _LASZIP_ITEM.size) for i in range(n_items)]
    # laz-rs picks the layered decompressor when the first item is of version 3 or 4, whatever the compressor says
    layered = items[0][2] in (3, 4)
    kinds, versions = (_LAYERED_ITEMS, (3, 4)) if layered else (_POINTWISE_ITEMS, (1, 2))
    if compressor not in _COMPRESSORS or any(k not in kinds or v not in versions for k, _, v in items):
        raise InvalidInputError(f"{name}: LASzip compressor {compressor} with items {[(k, v) for k, _, v in items]} (type, version) "
                                "is not one lazrs reads")  # fmt: skip
    item_bytes = sum(item_size if kind in (0, 14) else _ITEM_SIZES[kind] for kind, item_size, _ in items)
    if item_bytes != layout.record_length:
        raise InvalidInputError(f"{name}: LASzip items of {item_bytes} bytes for records of {layout.record_length}")
    if compressor != _POINTWISE and chunk_size == 0:
        raise InvalidInputError(f"{name}: LASzip chunks of 0 points")
    return body, compressor, chunk_size, items


def _chunk_table(fh: BinaryIO, layout: _Layout, size: int, name: str, vlr: bytes) -> list[tuple[int, int]] | None:
    """The chunk table lazrs will read, after checking that it declares no more chunks than points."""
    import lazrs

    # where laz-rs looks for it (ChunkTable::read_offset): after the points, or at the file's end
    (table,) = struct.unpack("<q", _read_at(fh, layout.offset, 8).ljust(8, b"\0"))
    if table <= layout.offset:
        (table,) = struct.unpack("<q", _read_at(fh, max(size - 8, 0), 8).ljust(8, b"\0"))
        if table <= layout.offset:
            return None
    head = _read_at(fh, table, 8) if table + 8 <= size else b""
    if len(head) < 8:
        return None
    _, n_chunks = struct.unpack("<II", head)
    if n_chunks > layout.count + 1:
        raise InvalidInputError(f"{name}: its LAZ chunk table declares {n_chunks:,} chunks for {layout.count:,} points (forged)")
    fh.seek(layout.offset)
    try:
        return list(lazrs.read_chunk_table(fh, lazrs.LazVlr(vlr)))
    except lazrs.LazrsError:
        return None  # lazrs reads on without it where it can, and refuses where it cannot


def _check_laz(fh: BinaryIO, layout: _Layout, size: int, name: str) -> int:
    """Check the chunks lazrs will decompress; returns the most bytes one chunk's layers allocate."""
    vlr, compressor, chunk_size, items = _laszip_items(fh, layout, name)
    if layout.count == 0:
        return 0
    table = None if compressor == _POINTWISE else _chunk_table(fh, layout, size, name, vlr)
    variable = compressor != _POINTWISE and chunk_size == _VARIABLE_CHUNKS
    if variable and table is not None and sum(n for n, _ in table) < layout.count:
        raise InvalidInputError(
            f"{name}: its LAZ chunk table holds {sum(n for n, _ in table):,} points of the {layout.count:,} declared"
        )
    if items[0][2] not in (3, 4):
        return 0  # point-wise items: one arithmetic-coded stream per chunk, nothing allocated from the data
    # layered chunks: the first point raw, the chunk's point count, then every layer's size
    first, layers = layout.record_length, sum(_ITEM_LAYERS.get(kind, item_size) for kind, item_size, _ in items)
    head = struct.Struct(f"<I{layers}I")
    position, covered, largest, k = layout.offset + 8, 0, 0, 0
    while covered < layout.count:
        raw = _read_at(fh, position + first, head.size)
        if len(raw) < head.size:
            raise InvalidInputError(f"{name}: LAZ chunk {k} is truncated (byte {position:,})")
        embedded, *layer_sizes = head.unpack(raw)
        total = sum(layer_sizes)
        position += first + head.size + total
        if position > size:
            raise InvalidInputError(
                f"{name}: LAZ chunk {k} declares {total:,} bytes of layers, past the end of the file (truncated or forged)"
            )
        # how many points laz-rs takes from this chunk (LasZipDecompressor::decompress_one)
        if compressor == _POINTWISE:
            points = layout.count
        elif not variable:
            points = chunk_size
        else:
            points = embedded if table is None else table[k][0]
        if points == 0:
            raise InvalidInputError(f"{name}: LAZ chunk {k} holds no points")
        covered, largest, k = covered + points, max(largest, total), k + 1
    return largest


def _linear_unit_m(header: Any) -> float:
    """Metres per coordinate unit from the WKT VLR (the projected CRS's unit) or GeoTIFF's ProjLinearUnitsGeoKey."""
    for vlr in header.vlrs.get("WktCoordinateSystemVlr"):
        found = _wkt_linear_unit_m(str(vlr.string))
        if math.isfinite(found):
            return found
    for vlr in header.vlrs.get("GeoKeyDirectoryVlr"):
        for key in vlr.geo_keys:
            if key.id == 3076 and key.tiff_tag_location == 0:
                return _GEOKEY_UNITS_M.get(int(key.value_offset), math.nan)
    return math.nan


def _wkt_tree(text: str) -> list | None:
    """``[KEYWORD, children]`` of a WKT (1 or 2) string, children strings or nodes; None when malformed."""
    root: list = ["", []]
    stack = [root]
    for quoted, keyword, close, bare in _WKT_TOKEN.findall(text):
        if keyword:
            node: list = [keyword.upper(), []]
            stack[-1][1].append(node)
            stack.append(node)
            if len(stack) > _WKT_MAX_DEPTH:
                return None
        elif close:
            if len(stack) == 1:
                return None
            stack.pop()
        else:
            stack[-1][1].append(quoted or bare)
    first = root[1][0] if root[1] else None
    return first if isinstance(first, list) else None


def _wkt_linear_unit_m(text: str) -> float:
    node = _wkt_tree(text)
    if node is not None and node[0] in ("COMPD_CS", "COMPOUNDCRS"):
        node = next((c for c in node[1] if isinstance(c, list) and c[0] in _PROJECTED_WKT), None)
    if node is None or node[0] not in _PROJECTED_WKT:
        return math.nan
    axes = [c for c in node[1] if isinstance(c, list) and c[0] == "AXIS"]
    for holder in [node, *axes]:  # WKT1 and WKT2 put the unit under the CRS; WKT2 may put it on each axis
        for c in holder[1]:
            if isinstance(c, list) and c[0] in ("UNIT", "LENGTHUNIT") and len(c[1]) > 1:
                try:
                    factor = float(c[1][1])
                except (TypeError, ValueError):
                    return math.nan
                return factor if math.isfinite(factor) and factor > 0 else math.nan
    return math.nan


def _read_points(reader: Any, layout: _Layout, name: str) -> dict[str, np.ndarray]:
    n = layout.count
    out = {"points": np.empty((n, 3), np.float64), **{key: np.zeros(n, dtype) for key, dtype in LasPoints._DTYPES.items()}}
    dims = set(reader.header.point_format.dimension_names)
    done = 0
    while done < n:
        rec = reader.read_points(min(READ_CHUNK_POINTS, n - done))
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
        Largest file read (default :data:`MAX_LAS_BYTES`).

    Returns
    -------
    LasPoints
        Fields as the ASPRS LAS 1.4 specification R15 defines them (§2.6, "Point Data Records").

    Raises
    ------
    ArgumentTypeError
        ``path`` is not a path, or a cap is not a whole number.
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
    for cap, value in (("max_points", max_points), ("max_bytes", max_bytes)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ArgumentTypeError(f"{cap} must be a whole number >= 0, got {described(value)}")
    name = os.fsdecode(path)
    fh, size = open_regular_file(path, max_bytes=max_bytes, error=InvalidInputError, within=within)
    with fh:
        try:
            layout = _parse_header(fh, size, name)
            _check_count(layout, size, name, max_points)
            chunk_bytes = _check_laz(fh, layout, size, name) if layout.compressed else 0
            raw_bytes = min(layout.count, READ_CHUNK_POINTS) * (layout.record_length + _DECODED_XYZ_BYTES)
            check_memory(layout.count * BYTES_PER_POINT + raw_bytes + chunk_bytes, option=f"reading {name} ({layout.count:,} points)",
                         hint="read a smaller tile or a crop")  # fmt: skip
            fh.seek(0)
            reader = laspy.LasReader(fh, closefd=False, laz_backend=laspy.LazBackend.Lazrs, read_evlrs=False)
            arrays = _read_points(reader, layout, name)
            unit = _linear_unit_m(reader.header)
        except ZbufOccludeError:
            raise
        except _decode_errors() as exc:
            raise InvalidInputError(f"{name}: not a readable LAS/LAZ file ({_one_line(exc)})") from None
        except BaseException as exc:  # a Rust panic inside lazrs (pyo3's PanicException derives from BaseException)
            if type(exc).__name__ != "PanicException":
                raise
            raise InvalidInputError(f"{name}: damaged LAZ data ({_one_line(exc)})") from None
    return LasPoints(**arrays, has_gps_time=layout.point_format_id in _FORMATS_WITH_GPS_TIME, point_format_id=layout.point_format_id,
                     version=f"{layout.version[0]}.{layout.version[1]}", linear_unit_m=unit)  # fmt: skip


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


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
        raise InvalidInputError(
            f"{name} must be finite and within [{low:g}, {high:g}], got values in [{array.min()}, {array.max()}]"
        )
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
    scale: float = 0.001,
    compress: bool = False,
) -> bytes:
    """Points and their per-return fields as the bytes of a LAS 1.4 file (LAZ with ``compress``), in memory.

    Point format 6, or 7 with ``rgb`` (ASPRS LAS 1.4 specification R15, §2.6).  The header holds no
    coordinate reference system (no WKT or GeoTIFF VLR; the global encoding's WKT bit is set, as
    formats 6 to 10 require, and its GPS time bit is not: times are GPS week time, seconds as
    given, a simulated scan's seconds from its start).  The offsets are multiples of ``scale``
    near the points' centre, so every coordinate reads back within ``scale / 2``.  The header's
    creation date is today's.  Write the bytes through the layer
    (:meth:`~zbuf_occlude.io.owned.OwnedFolder.write_bytes`).

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
    scale : float
        Metres (units) per stored integer step, > 0 (default 1 mm).
    compress : bool
        LAZ (LASzip through lazrs) instead of LAS.

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
        ``number_of_returns``, or points too far apart for int32 steps of ``scale``.
    """
    import laspy

    pts = check_points(points)
    n = len(pts)
    if not isinstance(compress, (bool, np.bool_)):
        raise ArgumentTypeError(f"compress must be True or False, got {described(compress)}")
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
    offsets, stored = _scaled(pts, scale)
    header = laspy.LasHeader(version="1.4", point_format=6 if colours is None else 7)
    header.scales, header.offsets = np.full(3, float(scale)), offsets
    header.global_encoding.wkt = True
    header.generating_software = f"zbuf_occlude {__version__}"
    las = laspy.LasData(header)
    las.X, las.Y, las.Z = stored[:, 0], stored[:, 1], stored[:, 2]
    for key, values in fields_.items():
        las[key] = values
    if colours is not None:
        las.red, las.green, las.blue = colours[:, 0], colours[:, 1], colours[:, 2]
    las.update_header()
    buffer = io.BytesIO()
    las.write(buffer, do_compress=bool(compress), laz_backend=laspy.LazBackend.Lazrs)
    return buffer.getvalue()
