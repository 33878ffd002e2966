"""The structure of a LAS or LAZ file from anyone, checked before laspy and lazrs read it.

A LAS file (ASPRS LAS 1.4 specification R15, 2019; 1.0 to 1.3 read too) is a public header, up to
2³² variable length records (VLRs), the point records, and in 1.4 extended VLRs (EVLRs) after them;
a LAZ file is the same with the points compressed by LASzip in chunks.  laspy decodes the records
and lazrs (laz-rs) decompresses the chunks, and both allocate what the file declares before they
read it: a forged count or size costs gigabytes, or aborts the process, however small the file.
So what they would read or allocate is checked here first, on the open file, with :mod:`struct`
(nothing is executed or unpickled):

* the **public header** (:func:`parse_header`): the ``LASF`` signature, version 1.0 to 1.4, a
  header size and an offset to the points consistent with the version and the file, point format
  0 to 10 allowed by the version, a record length at least the format's, finite non-zero scales
  and finite offsets;
* the **VLRs**: at most :data:`MAX_VLRS`, each inside the bytes before the points, which laspy reads
  whole (at most :data:`~zbuf_occlude.io.caps.MAX_LAS_HEADER_BYTES`); the **EVLRs**: at most :data:`MAX_EVLRS`, each inside
  the file; their contents (waveforms, a WKT, a COPC hierarchy) are never read;
* the **point count** (:func:`check_count`): at most ``max_points``; uncompressed, the records it
  declares must fit between the offset to the points and the first EVLR (or the end); compressed,
  at most :data:`MAX_LAZ_POINTS_PER_BYTE` per byte of compressed data;
* the **LAZ chunks** (:func:`check_laz`): the LASzip VLR must name a compressor and items lazrs
  reads, each of its type's size (laz-rs slices records by the VLR's sizes and decodes by the
  types': a mismatch panics in Rust), of the record length.  laz-rs starts a chunk every chunk
  size points whatever the chunk table says, rebuilding its models each time (half a millisecond
  for point-wise items: a chunk size forged to 1 costs tens of seconds), and each chunk stores its
  first point raw; so the chunks the count needs must fit the file's bytes, and the chunk table
  must be there and readable (laz-rs reads the points from the wrong place otherwise) and hold the
  declared points (chunks × chunk size, or the variable sizes' sum).  laz-rs
  allocates one entry per chunk the chunk table declares (2³² − 1 chunks are 64 GiB, and the
  process aborts), and each layer a chunk header declares in point formats 6 to 10 (up to 4 GiB
  each).  So the chunk table may declare no more chunks than points, nor than the bytes before it
  hold, and the chunks are walked as laz-rs will read them: every layer must end inside the file.

Every failure is one :class:`~zbuf_occlude.errors.InvalidInputError` line naming the file.
:mod:`zbuf_occlude.io.las_crs` reads the coordinate unit from the header laspy parsed;
:mod:`zbuf_occlude.io.las` reads the points.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.caps import MAX_LAS_HEADER_BYTES

__all__ = [
    "MAX_EVLRS", "MAX_LAZ_POINTS_PER_BYTE", "MAX_VLRS", "LasLayout", "check_count", "check_laz", "parse_header",
]  # fmt: skip

#: Most VLRs a file may declare: room for the 255 waveform packet descriptors the specification
#: allows (record ids 100 to 354) and the projection, LASzip, extra-bytes and text records; real
#: files hold a handful.
MAX_VLRS = 512
#: Most EVLRs a file may declare (a WKT, waveform data, a COPC hierarchy: a handful); only their
#: 60-byte headers are read, to check that each lies inside the file.
MAX_EVLRS = 1024
#: Most points a LAZ file may declare per byte of compressed data: laz-rs packs a million
#: identical format-6 points into 10,463 bytes (96 per byte), real scans hold 0.1 to 1 point per
#: byte (the shared IGN and Autzen samples: 0.20 and 0.18).
MAX_LAZ_POINTS_PER_BYTE = 1000
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
#: Item versions laz-rs 0.12 decodes (``set_fields_from``): 1 and 2 point-wise, 3 layered; it
#: picks the layered decompressor when the first item's version is 3 or 4 (4 it then refuses).
_POINTWISE_VERSIONS, _LAYERED_VERSIONS, _LAYERED_PICKED = (1, 2), (3,), (3, 4)
#: Extra-bytes item types, whose size the VLR gives (every other type has its own, :data:`_ITEM_SIZES`).
_EXTRA_BYTES_ITEMS = (0, 14)
#: Bytes of the chunk table's offset, at the start of the point data (LASzip; laz-rs ``ChunkTable::OFFSET_SIZE``).
_CHUNK_TABLE_OFFSET_BYTES = 8
#: Bytes of a layered chunk's point count and of each of its layer sizes (uint32, laz-rs ``LayeredPointRecordDecompressor``).
_LAYER_FIELD_BYTES = 4
#: Bytes of each LASzip item type (laz-rs ``LazItemType``: 0 and 14 are extra bytes, sized by the VLR).
_ITEM_SIZES = {6: 20, 7: 8, 8: 6, 9: 29, 10: 30, 11: 6, 12: 8, 13: 29}
#: Layers of each layered item (point14: 9, RGB: 1, RGB+NIR: 2, waveform: 1; extra bytes: one per byte).
_ITEM_LAYERS = {10: 9, 11: 1, 12: 2, 13: 1}


@dataclass(frozen=True)
class LasLayout:
    """What the header and the records around the points declare, checked by :func:`parse_header`.

    Attributes
    ----------
    version : (int, int)
        Major and minor version: ``(1, 0)`` to ``(1, 4)``.
    header_size, offset : int
        Bytes of the public header; byte where the points start.
    point_format_id : int
        0 to 10.
    compressed : bool
        LAZ: the points are LASzip chunks.
    record_length : int
        Bytes per point record, at least the format's.
    count : int
        Points declared (the 1.4 64-bit count where the version has one).
    vlrs : tuple of (bytes, int, int, int)
        Each VLR's user id (NULs stripped), record id, body offset and body length in bytes.
    evlrs, first_evlr : int
        EVLRs declared, and the byte of the first (0 before 1.4).
    """

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


def parse_header(fh: BinaryIO, size: int, name: str) -> LasLayout:
    """The public header of the open file ``fh`` of ``size`` bytes, its VLRs and EVLRs walked (module docstring).

    Parameters
    ----------
    fh : binary file
        Open, seekable; read with ``seek`` and ``read`` only.
    size : int
        The file's size in bytes.
    name : str
        The file's name, for messages.

    Returns
    -------
    LasLayout

    Raises
    ------
    InvalidInputError
        Naming the file: no ``LASF`` signature, a truncated header, a version other than 1.0 to
        1.4, sizes or offsets that do not fit the file, a point format or record length the version
        does not allow, non-finite or zero scales, more than :data:`MAX_VLRS` VLRs or
        :data:`MAX_EVLRS` EVLRs, more than :data:`~zbuf_occlude.io.caps.MAX_LAS_HEADER_BYTES` before the points, or a VLR or
        EVLR that runs past its bounds.
    """
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
        raise InvalidInputError(f"{name}: its scale factors or offsets are not finite and non-zero")
    evlrs = first_evlr = 0
    if minor >= 4:
        if len(head) < _HEADER_SIZES[4]:
            raise InvalidInputError(f"{name}: truncated LAS 1.4 header ({len(head)} bytes)")
        _, first_evlr, evlrs, count = _HEADER_14.unpack_from(head, _HEADER.size)
    if n_vlrs > MAX_VLRS or evlrs > MAX_EVLRS:
        raise InvalidInputError(f"{name}: declares {n_vlrs:,} VLRs and {evlrs:,} EVLRs; at most {MAX_VLRS} and {MAX_EVLRS} are read")
    if offset > MAX_LAS_HEADER_BYTES:
        raise InvalidInputError(f"{name}: {offset:,} bytes before the first point, more than the {MAX_LAS_HEADER_BYTES:,} read")
    vlrs = _walk_vlrs(fh, name, header_size, offset, n_vlrs)
    _walk_evlrs(fh, name, size, offset, first_evlr, evlrs)
    return LasLayout((major, minor), header_size, offset, point_format_id, compressed, record_length, count, vlrs, evlrs, first_evlr)


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


def check_count(layout: LasLayout, size: int, name: str, max_points: int) -> None:
    """Check the declared point count against ``max_points`` and the bytes that must hold the points.

    Raises
    ------
    InvalidInputError
        Naming the file: more than ``max_points`` points; uncompressed, records that end past the
        first EVLR (or the end of the file); compressed, more than :data:`MAX_LAZ_POINTS_PER_BYTE`
        points per byte after the offset to the points.
    """
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


def _laszip_items(fh: BinaryIO, layout: LasLayout, name: str) -> tuple[bytes, int, int, list[tuple[int, int, int]]]:
    """The LASzip VLR's bytes, compressor, chunk size and ``(type, size, version)`` items, checked as laz-rs reads them."""
    found = [v for v in layout.vlrs if (v[0], v[1]) == _LASZIP]
    if not found:
        raise InvalidInputError(f"{name}: compressed points but no LASzip VLR")
    body = _read_at(fh, found[0][2], found[0][3])
    if len(body) < _LASZIP_VLR.size:
        raise InvalidInputError(f"{name}: the LASzip VLR is truncated")
    compressor, _, _, _, _, _, chunk_size, _, _, n_items = _LASZIP_VLR.unpack_from(body)
    if not 0 < n_items <= (len(body) - _LASZIP_VLR.size) // _LASZIP_ITEM.size:
        raise InvalidInputError(f"{name}: the LASzip VLR declares {n_items} items and holds {len(body) - _LASZIP_VLR.size} bytes of them")
    items = [_LASZIP_ITEM.unpack_from(body, _LASZIP_VLR.size + i * _LASZIP_ITEM.size) for i in range(n_items)]
    # laz-rs picks the layered decompressor when the first item is of version 3 or 4, whatever the compressor says
    layered = items[0][2] in _LAYERED_PICKED
    kinds, versions = (_LAYERED_ITEMS, _LAYERED_VERSIONS) if layered else (_POINTWISE_ITEMS, _POINTWISE_VERSIONS)
    if compressor not in _COMPRESSORS or any(k not in kinds or v not in versions for k, _, v in items):
        raise InvalidInputError(f"{name}: LASzip compressor {compressor} with items {[(k, v) for k, _, v in items]} (type, version) "
                                "is not one lazrs reads")  # fmt: skip
    # laz-rs sizes each item's decoder by its type but slices the record by the VLR's sizes: a size
    # other than the type's (or an extra-bytes item of 0 bytes) panics inside Rust, on stderr
    for i, (kind, item_size, _) in enumerate(items):
        if item_size != _ITEM_SIZES.get(kind, item_size) or item_size == 0:
            want = "at least 1" if kind in _EXTRA_BYTES_ITEMS else str(_ITEM_SIZES[kind])
            raise InvalidInputError(
                f"{name}: LASzip item {i} (type {kind}) declares {item_size} bytes; its type takes {want} (damaged or forged)"
            )
    item_bytes = sum(item_size for _, item_size, _ in items)
    if item_bytes != layout.record_length:
        raise InvalidInputError(f"{name}: LASzip items of {item_bytes} bytes for records of {layout.record_length}")
    if compressor != _POINTWISE and chunk_size == 0:
        raise InvalidInputError(f"{name}: LASzip chunks of 0 points")
    return body, compressor, chunk_size, items


def _layers(items: list[tuple[int, int, int]]) -> int:
    """Layers of a layered chunk: each item's (:data:`_ITEM_LAYERS`), one per byte of extra bytes."""
    return sum(_ITEM_LAYERS.get(kind, item_size) for kind, item_size, _ in items)


def _smallest_chunk(layout: LasLayout, items: list[tuple[int, int, int]]) -> int:
    """The fewest bytes a chunk of points takes: its first point raw, and a layered chunk's point count and layer sizes."""
    if items[0][2] not in _LAYERED_PICKED:
        return layout.record_length
    return layout.record_length + _LAYER_FIELD_BYTES * (1 + _layers(items))


def _chunk_table(fh: BinaryIO, layout: LasLayout, size: int, name: str, vlr: bytes, smallest: int) -> list[tuple[int, int]]:
    """The chunk table lazrs will read, after checking that the bytes before it can hold the chunks it declares.

    laz-rs 0.12 needs it to read chunked points from a file: without one it fails at once, and with
    one it cannot read (past the end, or damaged) it reads the points from where reading the table
    stopped, decoding (and reserving layers from) bytes no check here has seen.  So it must be read.
    """
    import lazrs

    # where laz-rs looks for it (ChunkTable::read_offset): after the points' start, or at the file's end
    (table,) = struct.unpack("<q", _read_at(fh, layout.offset, _CHUNK_TABLE_OFFSET_BYTES).ljust(_CHUNK_TABLE_OFFSET_BYTES, b"\0"))
    if table <= layout.offset:
        (table,) = struct.unpack("<q", _read_at(fh, max(size - 8, 0), 8).ljust(8, b"\0"))
        if table <= layout.offset:
            raise InvalidInputError(f"{name}: its LAZ chunk table is missing (no offset to it after the points or at the end of the "
                                    "file); lazrs cannot read chunked points without it (truncated or damaged)")  # fmt: skip
    head = _read_at(fh, table, 8) if table + 8 <= size else b""
    if len(head) < 8:
        raise InvalidInputError(f"{name}: its LAZ chunk table (byte {table:,}) lies past the end of the file ({size:,} bytes; "
                                "truncated or forged)")  # fmt: skip
    _, n_chunks = struct.unpack("<II", head)
    if n_chunks > layout.count + 1:
        raise InvalidInputError(f"{name}: its LAZ chunk table declares {n_chunks:,} chunks for {layout.count:,} points (forged)")
    # laz-rs reserves an entry per chunk before decoding them; every chunk but an empty last one
    # takes at least ``smallest`` bytes before the table
    chunk_bytes = table - layout.offset - _CHUNK_TABLE_OFFSET_BYTES
    if (n_chunks - 1) * smallest > chunk_bytes:
        raise InvalidInputError(f"{name}: its LAZ chunk table declares {n_chunks:,} chunks of at least {smallest} bytes in "
                                f"{chunk_bytes:,} bytes of LAZ data (forged)")  # fmt: skip
    fh.seek(layout.offset)
    try:
        return list(lazrs.read_chunk_table(fh, lazrs.LazVlr(vlr)))
    except lazrs.LazrsError as exc:
        raise InvalidInputError(
            f"{name}: its LAZ chunk table (byte {table:,}) is unreadable ({' '.join(str(exc).split())}; damaged)"
        ) from None


def check_laz(fh: BinaryIO, layout: LasLayout, size: int, name: str) -> int:
    """Check the LASzip VLR and the chunks lazrs will decompress, before it allocates what they declare.

    Everything checked costs a few reads of the file's bytes, at most one per chunk, and nothing is
    decompressed: a forged chunk size or count is refused before laz-rs spends time or memory on it.

    Parameters
    ----------
    fh : binary file
        The open LAZ file, seekable.
    layout : LasLayout
        Its checked header (:func:`parse_header`), ``compressed`` True.
    size : int
        The file's size in bytes.
    name : str
        The file's name, for messages.

    Returns
    -------
    int
        The most bytes one chunk's layers allocate (0 for point-wise items): memory lazrs holds
        besides the points.

    Raises
    ------
    InvalidInputError
        Naming the file: no or a truncated LASzip VLR, a compressor or items lazrs does not read
        (a type, size or version other than laz-rs's), items that do not add up to the record
        length, chunks of 0 points, more chunks (points over the chunk size) than the file's bytes
        can hold (each chunk stores its first point raw), a chunk table that is missing, past the
        end or unreadable, that declares more chunks than points or than the bytes before it hold,
        or that holds fewer points than declared
        (chunks × chunk size, or the sum of variable chunks), or a chunk whose layers end past the
        end of the file.
    """
    vlr, compressor, chunk_size, items = _laszip_items(fh, layout, name)
    if layout.count == 0:
        return 0
    smallest = _smallest_chunk(layout, items)
    # the chunks start after the chunk table's offset; laz-rs reads none in point-wise (unchunked) data
    start = layout.offset + (0 if compressor == _POINTWISE else _CHUNK_TABLE_OFFSET_BYTES)
    data_bytes = max(size - start, 0)
    variable = compressor != _POINTWISE and chunk_size == _VARIABLE_CHUNKS
    # laz-rs starts a chunk every chunk_size points, reading on whether or not the table says so
    chunks = 1 if compressor == _POINTWISE or variable else -(-layout.count // chunk_size)
    if chunks * smallest > data_bytes:
        raise InvalidInputError(f"{name}: declares {layout.count:,} points in {chunks:,} LAZ chunks of at least {smallest} bytes, more "
                                f"than its {data_bytes:,} bytes of LAZ data (truncated or forged)")  # fmt: skip
    table = None if compressor == _POINTWISE else _chunk_table(fh, layout, size, name, vlr, smallest)
    if table is not None:
        holds = sum(n for n, _ in table) if variable else len(table) * chunk_size
        if holds < layout.count:
            raise InvalidInputError(f"{name}: its LAZ chunk table of {len(table):,} chunks holds at most {holds:,} points of the "
                                    f"{layout.count:,} declared (forged)")  # fmt: skip
    if items[0][2] not in _LAYERED_PICKED:
        return 0  # point-wise items: one arithmetic-coded stream per chunk, nothing allocated from the data
    # layered chunks: the first point raw, the chunk's point count, then every layer's size
    first = layout.record_length
    head = struct.Struct(f"<I{_layers(items)}I")
    position, covered, largest, k = start, 0, 0, 0
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
