"""LAS/LAZ through the reading layer: las_bytes round-trips through laspy, read_las refuses what a file cannot hold.

The hostile files are forged from valid ones by patching the fields the ASPRS LAS 1.4 R15 header,
the VLRs and the LAZ chunks declare; each must be one InvalidInputError naming the file, never a
traceback, a hang (a FIFO) or an allocation the file does not back (lazrs reserves what a LAZ
chunk table or layer header declares).
"""

from __future__ import annotations

import io
import os
import struct
from pathlib import Path

import laspy
import numpy as np
import pytest

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError, UnsafePathError
from zbuf_occlude.io.las import MAX_VLRS, SCAN_ANGLE_STEP_DEG, LasPoints, SurveyFields, las_bytes, read_las

#: The real airborne scans (research-only, next to the repository; skipped when absent).
ALS_RETURNS = Path(os.environ.get("ZBUF_OCCLUDE_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data")) / "als_returns"
N = 600


def _fields(n: int = N, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    count = rng.integers(1, 6, n)
    return {
        "points": rng.uniform(-40.0, 40.0, (n, 3)) + [652_000.0, 6_862_000.0, 120.0],
        "intensity": rng.integers(0, 65_536, n),
        "return_number": np.minimum(rng.integers(1, 6, n), count),
        "number_of_returns": count,
        "gps_time": 3e5 + np.arange(n) * 1e-5,
        "scan_angle_deg": rng.uniform(-30.0, 30.0, n),
        "point_source_id": rng.integers(0, 65_536, n),
        "classification": rng.integers(0, 256, n),
    }


def _write(tmp_path: Path, data: bytes, name: str = "scan.las") -> Path:
    (tmp_path / name).write_bytes(data)
    return tmp_path / name


def _offset_to_points(data: bytes) -> int:
    return struct.unpack_from("<I", data, 96)[0]


@pytest.mark.parametrize("compress", [False, True])
@pytest.mark.parametrize("colour", [False, True])
def test_las_bytes_round_trips_through_laspy_and_read_las(tmp_path: Path, compress: bool, colour: bool) -> None:
    f = _fields()
    rgb = np.random.default_rng(1).integers(0, 65_536, (N, 3)) if colour else None
    data = las_bytes(
        f["points"], **{k: v for k, v in f.items() if k != "points"}, rgb=rgb, survey=SurveyFields(scale=0.001), compress=compress
    )
    back = laspy.read(io.BytesIO(data))
    assert back.header.version == "1.4" and back.header.point_format.id == (7 if colour else 6)
    assert back.header.are_points_compressed == compress
    assert not back.header.vlrs.get("WktCoordinateSystemVlr") and not back.header.vlrs.get("GeoKeyDirectoryVlr")  # CRS-free
    assert back.header.global_encoding.wkt  # formats 6-10 must use WKT (R15): set, with no WKT record
    xyz = np.stack([back.x, back.y, back.z], axis=1)
    assert np.abs(xyz - f["points"]).max() <= 0.0005 + 1e-9
    for key in ("intensity", "return_number", "number_of_returns", "point_source_id", "classification"):
        assert np.array_equal(np.asarray(back[key]), f[key]), key
    assert np.array_equal(np.asarray(back.gps_time), f["gps_time"])
    assert np.abs(np.asarray(back.scan_angle) * SCAN_ANGLE_STEP_DEG - f["scan_angle_deg"]).max() <= SCAN_ANGLE_STEP_DEG / 2 + 1e-9
    if colour:
        assert np.array_equal(np.stack([back.red, back.green, back.blue], axis=1), rgb)
    read = read_las(_write(tmp_path, data, "scan.laz" if compress else "scan.las"))
    assert isinstance(read, LasPoints) and len(read) == N and read.point_format_id == (7 if colour else 6) and read.has_gps_time
    assert np.array_equal(read.points, xyz) and np.array_equal(read.gps_time, f["gps_time"])
    assert np.array_equal(read.return_number, f["return_number"]) and read.return_number.dtype == np.uint8
    assert np.allclose(read.scan_angle_deg, np.asarray(back.scan_angle) * SCAN_ANGLE_STEP_DEG, atol=1e-4)
    assert not read.points.flags.writeable and not read.intensity.flags.writeable
    assert np.isnan(read.linear_unit_m)  # no CRS, no unit


def test_a_scan_of_no_points_and_a_file_of_another_scale_round_trip(tmp_path: Path) -> None:
    empty = read_las(_write(tmp_path, las_bytes(np.zeros((0, 3)), intensity=[], return_number=[], number_of_returns=[],
                                                gps_time=[], scan_angle_deg=[])))  # fmt: skip
    assert len(empty) == 0 and empty.points.shape == (0, 3)
    f = _fields(50)
    data = las_bytes(f["points"] * 1000, intensity=f["intensity"], return_number=f["return_number"],
                     number_of_returns=f["number_of_returns"], gps_time=f["gps_time"], scan_angle_deg=f["scan_angle_deg"], survey=SurveyFields(scale=1.0))  # fmt: skip
    assert np.abs(read_las(_write(tmp_path, data)).points - f["points"] * 1000).max() <= 0.5


def test_older_point_formats_read_with_their_scan_angle_rank_and_without_gps_time(tmp_path: Path) -> None:
    header = laspy.LasHeader(version="1.2", point_format=2)
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.arange(4.0), np.zeros(4), np.ones(4)
    las.scan_angle_rank = np.array([-20, -1, 0, 15], np.int8)
    las.classification = np.array([1, 2, 5, 31], np.uint8)
    buffer = io.BytesIO()
    las.write(buffer)
    read = read_las(_write(tmp_path, buffer.getvalue()))
    assert not read.has_gps_time and np.array_equal(read.gps_time, np.zeros(4)) and read.version == "1.2"
    assert np.array_equal(read.scan_angle_deg, [-20, -1, 0, 15]) and np.array_equal(read.classification, [1, 2, 5, 31])


@pytest.mark.parametrize(
    ("wkt", "metres"),
    [
        ('PROJCS["x",GEOGCS["g",UNIT["degree",0.0174532925199433]],PROJECTION["LCC"],UNIT["foot",0.3048,AUTHORITY["EPSG","9002"]]]', 0.3048),
        (('PROJCRS["RGF93 / Lambert-93",BASEGEOGCRS["RGF93",DATUM["d",ELLIPSOID["GRS 1980",6378137,298.25,LENGTHUNIT["metre",1]]]],'
          'CS[Cartesian,2],AXIS["Easting (X)",east],LENGTHUNIT["metre",1],ID["EPSG",2154]]'), 1.0),
        ('COMPD_CS["c",PROJCS["p",UNIT["US survey foot",0.304800609601219]],VERT_CS["v",UNIT["metre",1]]]', 0.304800609601219),
        ('GEOGCS["WGS 84",UNIT["degree",0.0174532925199433]]', float("nan")),
        ('PROJCS["broken",UNIT["metre",', float("nan")),
        ("[" * 200 + "]" * 200, float("nan")),
    ],
)  # fmt: skip
def test_the_coordinate_unit_comes_from_the_projected_crs_of_the_wkt(tmp_path: Path, wkt: str, metres: float) -> None:
    header = laspy.LasHeader(version="1.4", point_format=6)
    header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(wkt))
    las = laspy.LasData(header)
    las.x = las.y = las.z = np.zeros(2)
    buffer = io.BytesIO()
    las.write(buffer)
    assert read_las(_write(tmp_path, buffer.getvalue())).linear_unit_m == pytest.approx(metres, nan_ok=True)


# -- las_bytes refuses what a LAS 1.4 file cannot hold, naming the argument ------------------------------------------------


def _encode(**changes) -> bytes:
    f = _fields(20)
    f.update(changes)
    return las_bytes(f.pop("points"), **f)


@pytest.mark.parametrize(
    ("changes", "error", "match"),
    [
        ({"points": "cloud.npy"}, ArgumentTypeError, "points must be a numeric array"),
        ({"intensity": np.full(20, 3.5)}, ArgumentTypeError, r"intensity must be integers \(round first\)"),
        ({"gps_time": "now"}, ArgumentTypeError, "gps_time must be a numeric array"),
        ({"classification": np.full(20, True)}, ArgumentTypeError, "classification must be integers"),
        ({"compress": "yes"}, ArgumentTypeError, "compress must be True or False"),
        ({"survey": SurveyFields(scale="1mm")}, ArgumentTypeError, "scale must be a number"),
        ({"points": np.zeros((20, 2))}, InvalidInputError, r"points must have shape \(N, 3\)"),
        ({"intensity": np.zeros(19, int)}, InvalidInputError, r"intensity must have shape \(20,\)"),
        ({"intensity": np.full(20, 70_000)}, InvalidInputError, r"intensity must be finite and within \[0, 65535\]"),
        ({"return_number": np.zeros(20, int)}, InvalidInputError, r"return_number must be finite and within \[1, 15\]"),
        ({"number_of_returns": np.full(20, 16)}, InvalidInputError, r"number_of_returns must be finite and within \[1, 15\]"),
        ({"return_number": np.full(20, 3), "number_of_returns": np.full(20, 2)}, InvalidInputError,
         "return_number exceeds number_of_returns at 20 points"),
        ({"scan_angle_deg": np.full(20, 181.0)}, InvalidInputError, r"scan_angle_deg must be finite and within \[-180, 180\]"),
        ({"gps_time": np.full(20, np.nan)}, InvalidInputError, "gps_time must be finite"),
        ({"rgb": np.zeros((20, 4), int)}, InvalidInputError, r"rgb must have shape \(20, 3\)"),
        ({"survey": SurveyFields(scale=0.0)}, InvalidInputError, "scale must be finite and > 0"),
        ({"points": np.array([[0.0, 0, 0], [5e6, 0, 0]] * 10)}, InvalidInputError, "points span 5e.06 units.*use a larger scale"),
    ],
)  # fmt: skip
def test_las_bytes_refuses_wrong_kinds_shapes_and_ranges(changes: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        _encode(**changes)


# -- read_las: hostile files, each one line naming the file -------------------------------------------------------------


def test_read_las_refuses_wrong_kinds_from_python() -> None:
    for bad in (123, None, b"scan.las", ["scan.las"]):
        with pytest.raises(ArgumentTypeError, match="path must be a LAS/LAZ file's path"):
            read_las(bad)  # type: ignore[arg-type]
    for cap in ({"max_points": "10"}, {"max_bytes": 1.5}, {"max_points": -1}, {"max_bytes": True}):
        with pytest.raises(ArgumentTypeError, match="must be a whole number >= 0"):
            read_las("scan.las", **cap)
    for within in (123, b"tiles", ["tiles"]):
        with pytest.raises(
            ArgumentTypeError, match=r"within must be a folder's path \(str or os.PathLike\) or None, got (int 123|bytes|list)"
        ):
            read_las("scan.las", within=within)  # type: ignore[arg-type]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
def test_a_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "scan.laz")
    with pytest.raises(InvalidInputError, match=r"scan\.laz: is a FIFO"):
        read_las(tmp_path / "scan.laz")


def test_a_link_out_of_the_folder_it_was_named_from_is_refused(tmp_path: Path) -> None:
    (tmp_path / "outside").mkdir()
    (tmp_path / "tiles").mkdir()
    real = _write(tmp_path / "outside", _encode())
    (tmp_path / "tiles" / "scan.las").symlink_to(real)
    with pytest.raises(UnsafePathError, match="leads outside"):
        read_las(tmp_path / "tiles" / "scan.las", within=tmp_path / "tiles")
    assert len(read_las(tmp_path / "tiles" / "scan.las")) == 20  # named by the user: read


def _patched(data: bytes, offset: int, fmt: str, value: int) -> bytes:
    out = bytearray(data)
    struct.pack_into(fmt, out, offset, value)
    return bytes(out)


def _laz() -> bytes:
    return _encode(compress=True)


def _laz_chunk_table(data: bytes) -> int:
    return struct.unpack_from("<q", data, _offset_to_points(data))[0]


HOSTILE = {
    "not LAS": (lambda: b"ply\nformat ascii 1.0\n" * 40, "not a LAS/LAZ file"),
    "empty": (lambda: b"", "not a LAS/LAZ file"),
    "truncated header": (lambda: _encode()[:150], "truncated LAS header"),
    "truncated points": (lambda: _encode()[:-7], "declares 20 points of 30 bytes.*truncated or forged"),
    "10^10 points": (lambda: _patched(_encode(), 247, "<Q", 10**10), "declares 10,000,000,000 points, more than max_points"),
    "10^7 points": (lambda: _patched(_encode(), 247, "<Q", 10**7), "declares 10,000,000 points of 30 bytes"),
    "LAZ 10^7 points": (lambda: _patched(_laz(), 247, "<Q", 10**7), "more than 1000 per byte"),
    "too many VLRs": (lambda: _patched(_encode(), 100, "<I", MAX_VLRS + 1), f"declares {MAX_VLRS + 1:,} VLRs"),
    "VLR past the points": (lambda: _patched(_encode(), 100, "<I", 3), "VLR 1 of 3 does not fit before the points"),
    "huge offset to points": (lambda: _patched(_encode(), 96, "<I", 2**32 - 1), "header size 375 and offset to points"),
    "version 2.0": (lambda: _patched(_encode(), 24, "<B", 2), "LAS version 2.4; versions 1.0 to 1.4"),
    "point format 11": (lambda: _patched(_encode(), 104, "<B", 11), "point format 11 is not a format of LAS 1.4"),
    "short records": (lambda: _patched(_encode(), 105, "<H", 20), "records of 20 bytes, fewer than point format 6's 30"),
    "zero scale": (lambda: _patched(_encode(), 131, "<d", 0.0), "scale factors or offsets are not finite and non-zero"),
    "EVLRs past the end": (lambda: _patched(_patched(_encode(), 243, "<I", 2), 235, "<Q", 10**6), "EVLR 1 of 2 lies past the end"),
    "too many EVLRs": (lambda: _patched(_encode(), 243, "<I", 10**6), "1,000,000 EVLRs"),
    "NaN GPS time": (lambda: _patched(_encode(), 375 + 22, "<Q", 0x7FF8000000000000), "1 points have a NaN or infinite gps_time"),
    "LAZ cut short": (lambda: _laz()[:900], r"its LAZ chunk table \(byte [\d,]+\) lies past the end of the file \(900 bytes"),
    "LAZ chunk table of 2^20 chunks": (
        lambda: _patched(_laz(), _laz_chunk_table(_laz()) + 4, "<I", 1 << 20), "chunk table declares 1,048,576 chunks for 20 points"),
    "LAZ layer of 64 MiB": (
        lambda: _patched(_laz(), _offset_to_points(_laz()) + 8 + 30 + 4, "<I", 64 << 20), "LAZ chunk 0 declares .* bytes of layers"),
    "LAZ without its LASzip VLR": (lambda: _patched(_laz(), 100, "<I", 0), "compressed points but no LASzip VLR"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_a_hostile_file_is_one_line_naming_it(tmp_path: Path, case: str) -> None:
    make, match = HOSTILE[case]
    path = _write(tmp_path, make(), "tile 7.laz")
    with pytest.raises(InvalidInputError, match=match) as caught:
        read_las(path)
    message = str(caught.value)
    assert message.startswith(str(path)) and "\n" not in message


def test_caps_on_points_and_bytes_are_the_callers(tmp_path: Path) -> None:
    path = _write(tmp_path, _encode())
    with pytest.raises(InvalidInputError, match="declares 20 points, more than max_points=19"):
        read_las(path, max_points=19)
    with pytest.raises(InvalidInputError, match="more than the 900 a file read here may have"):
        read_las(path, max_bytes=900)
    assert len(read_las(path, max_points=20)) == 20


def test_las_points_built_by_hand_are_checked() -> None:
    arrays = {k: np.zeros(3) for k in LasPoints._DTYPES}
    with pytest.raises(InvalidInputError, match=r"intensity must have shape \(2,\)"):
        LasPoints(points=np.zeros((2, 3)), **arrays)
    arrays = {k: np.zeros(2) for k in LasPoints._DTYPES} | {"gps_time": [0.0, np.inf]}
    with pytest.raises(InvalidInputError, match="gps_time holds 1 NaN/inf"):
        LasPoints(points=np.zeros((2, 3)), **arrays)


# -- the shared real scans -------------------------------------------------------------------------------------------------


@pytest.mark.skipif(not ALS_RETURNS.is_dir(), reason="../shared/data/als_returns not present")
@pytest.mark.parametrize(
    ("name", "count", "point_format", "version", "metres"),
    [("ign_lidarhd_sample.laz", 37_805, 8, "1.4", 1.0), ("autzen_trim.laz", 110_000, 3, "1.2", 0.3048)],
)
def test_the_shared_scans_read_as_laspy_reads_them(name: str, count: int, point_format: int, version: str, metres: float) -> None:
    read = read_las(ALS_RETURNS / name, within=ALS_RETURNS)
    assert (len(read), read.point_format_id, read.version, read.linear_unit_m) == (count, point_format, version, metres)
    ref = laspy.read(ALS_RETURNS / name)
    assert np.array_equal(read.points, np.stack([ref.x, ref.y, ref.z], axis=1))
    for key in ("intensity", "return_number", "number_of_returns", "classification", "point_source_id", "gps_time"):
        assert np.array_equal(getattr(read, key), np.asarray(ref[key])), key


def test_a_scale_that_overflows_the_coordinates_is_refused_naming_the_file(tmp_path: Path) -> None:
    path = _write(tmp_path, _patched(_encode(), 131, "<d", 1e305))
    with pytest.raises(InvalidInputError, match=r"scan\.las: \d+ points have a NaN or infinite coordinate"):
        read_las(path)


# -- forged LAZ chunks and items: refused from the bytes, before lazrs decompresses a point -------------------------------


def _laszip_vlr(data: bytes) -> int:
    """The byte where the LASzip VLR's body starts (compressor, coder, version, options, chunk size, ..., items)."""
    position = struct.unpack_from("<H", data, 94)[0]
    for _ in range(struct.unpack_from("<I", data, 100)[0]):
        _, user_id, _, length, _ = struct.unpack_from("<H16sHH32s", data, position)
        if user_id.rstrip(b"\0") == b"laszip encoded":
            return position + 54
        position += 54 + length
    raise AssertionError("no LASzip VLR")


#: Offsets in the LASzip VLR's body: chunk size (uint32), then each item's (type, size, version) uint16s.
_CHUNK_SIZE_AT, _ITEMS_AT = 12, 34


def _pointwise_laz(n: int = N) -> bytes:
    """A LAS 1.2 point format 3 LAZ: point-wise LASzip items of version 2 (laz-rs writes them for formats 0 to 5)."""
    f = _fields(n)
    las = laspy.LasData(laspy.LasHeader(version="1.2", point_format=3))
    las.x, las.y, las.z = f["points"].T
    las.gps_time, las.intensity = f["gps_time"], f["intensity"]
    buffer = io.BytesIO()
    las.write(buffer, do_compress=True, laz_backend=laspy.LazBackend.Lazrs)
    return buffer.getvalue()


def _layered_laz(n: int = N) -> bytes:
    f = _fields(n)
    return las_bytes(f.pop("points"), **f, compress=True)


def _with_count(data: bytes, count: int) -> bytes:
    """``data`` declaring ``count`` points (the 1.4 64-bit count, or the legacy 32-bit one before 1.4)."""
    return _patched(data, 247, "<Q", count) if data[25] == 4 else _patched(data, 107, "<I", count)


@pytest.fixture
def no_decompression(monkeypatch):
    """lazrs's point decompressors fail the test if they are built: the refusal must come from the bytes alone."""
    import lazrs

    def never(*args, **kwargs):
        raise AssertionError("lazrs was asked to decompress points")

    for name in ("LasZipDecompressor", "ParLasZipDecompressor"):
        monkeypatch.setattr(lazrs, name, never)


def _chunk_size_1(data: bytes) -> bytes:
    return _patched(data, _laszip_vlr(data) + _CHUNK_SIZE_AT, "<I", 1)


def _table_chunks(data: bytes, n_chunks: int) -> bytes:
    return _patched(data, _laz_chunk_table(data) + 4, "<I", n_chunks)


def _no_table(data: bytes) -> bytes:
    """No offset to the chunk table after the points' start nor at the end (where a writer that cannot seek puts it)."""
    return _patched(_patched(data, _offset_to_points(data), "<q", -1), len(data) - 8, "<q", -1)


def _unreadable_table(data: bytes) -> bytes:
    """The table's offset moved to the last 8 bytes, made a table of 1 chunk whose entry is missing."""
    out = _patched(data, _offset_to_points(data), "<q", len(data) - 8)
    return _patched(_patched(out, len(data) - 8, "<I", 0), len(data) - 4, "<I", 1)


FORGED_LAZ = {
    # laz-rs starts a chunk (and rebuilds its models) every chunk-size points: 600 chunks, each its first point raw
    "point-wise chunk size 1": (lambda: _chunk_size_1(_pointwise_laz()), r"declares 600 points in 600 LAZ chunks of at least 34 bytes"),
    "layered chunk size 1": (lambda: _chunk_size_1(_layered_laz()), r"declares 600 points in 600 LAZ chunks of at least 70 bytes"),
    # chunks of 100 points fit the bytes, but the table holds one chunk: 100 points
    "point-wise chunk size 100": (lambda: _patched(_pointwise_laz(), _laszip_vlr(_pointwise_laz()) + _CHUNK_SIZE_AT, "<I", 100),
                                  r"chunk table of 1 chunks holds at most 100 points of the 600 declared \(forged\)"),
    "point-wise 10^5 points": (lambda: _with_count(_pointwise_laz(), 10**5),
                               r"chunk table of 1 chunks holds at most 50,000 points of the 100,000 declared \(forged\)"),
    "layered 10^5 points": (lambda: _with_count(_layered_laz(), 10**5),
                            r"chunk table of 1 chunks holds at most 50,000 points of the 100,000 declared \(forged\)"),
    "chunk table of 15 chunks": (lambda: _table_chunks(_layered_laz(20), 15),
                                 r"chunk table declares 15 chunks of at least 70 bytes in \d+ bytes of LAZ data \(forged\)"),
    # laz-rs decodes each item by its type, but slices the record by the VLR's sizes: a Rust panic
    "point-wise item of 0 bytes": (lambda: _patched(_pointwise_laz(), _laszip_vlr(_pointwise_laz()) + _ITEMS_AT + 2, "<H", 0),
                                   r"LASzip item 0 \(type 6\) declares 0 bytes; its type takes 20"),
    "layered item of 0 bytes": (lambda: _patched(_layered_laz(), _laszip_vlr(_layered_laz()) + _ITEMS_AT + 2, "<H", 0),
                                r"LASzip item 0 \(type 10\) declares 0 bytes; its type takes 30"),
    # laz-rs needs the table; one it cannot read makes it decode from where reading the table stopped (a 3000-point
    # file took 2.4 s of CPU to fail, the IGN sample reserved 767 MB)
    "chunk table past the end": (lambda: _patched(_layered_laz(), _offset_to_points(_layered_laz()), "<q", 10**15),
                                 r"its LAZ chunk table \(byte 1,000,000,000,000,000\) lies past the end of the file"),
    "no chunk table": (lambda: _no_table(_pointwise_laz()), r"its LAZ chunk table is missing \(no offset to it"),
    "unreadable chunk table": (lambda: _unreadable_table(_layered_laz()), r"its LAZ chunk table \(byte [\d,]+\) is unreadable \(.*; damaged\)"),
    "layered item of version 4": (lambda: _patched(_layered_laz(), _laszip_vlr(_layered_laz()) + _ITEMS_AT + 4, "<H", 4),
                                  r"items \[\(10, 4\)\] \(type, version\) is not one lazrs reads"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(FORGED_LAZ))
def test_a_forged_laz_is_refused_before_decompression_with_nothing_on_stderr(tmp_path: Path, case: str, no_decompression, capfd) -> None:
    make, match = FORGED_LAZ[case]
    path = _write(tmp_path, make(), "tile 7.laz")
    with pytest.raises(InvalidInputError, match=match) as caught:
        read_las(path)
    assert str(caught.value).startswith(str(path)) and "\n" not in str(caught.value)
    assert capfd.readouterr().err == ""  # no Rust panic, no backtrace


def test_the_shared_forms_of_laz_still_read_with_the_decompressor(tmp_path: Path) -> None:
    for data in (_pointwise_laz(), _layered_laz()):
        read = read_las(_write(tmp_path, data, "ok.laz"))
        assert len(read) == N and np.array_equal(read.points, np.stack([laspy.read(io.BytesIO(data)).x, laspy.read(io.BytesIO(data)).y,
                                                                        laspy.read(io.BytesIO(data)).z], axis=1))  # fmt: skip


def test_a_chunk_table_of_10_8_chunks_is_refused_under_a_memory_limit(tmp_path: Path) -> None:
    """lazrs reserves 16 bytes per chunk the table declares (1.6 GB for 10⁸) before decoding them: under a
    1 GiB address-space limit it aborts the process; the table is refused from the bytes before it."""
    from memory_limit import run_python_limited

    data = _layered_laz(12_000)
    path = _write(tmp_path, _table_chunks(_with_count(data, 10**8), 10**8), "tile.laz")
    done = run_python_limited(
        "from zbuf_occlude.errors import InvalidInputError\n"
        "from zbuf_occlude.io.las import read_las\n"
        f"try:\n    read_las({str(path)!r})\nexcept InvalidInputError as exc:\n    print(exc)\n",
        headroom=1 << 30,
    )
    assert done.returncode == 0, done.stderr
    assert "its LAZ chunk table declares 100,000,000 chunks of at least 70 bytes" in done.stdout, done.stdout + done.stderr


@pytest.mark.parametrize("compress", [False, True])
def test_points_read_in_many_small_reads_are_the_points(tmp_path: Path, monkeypatch, compress: bool) -> None:
    """A LAZ's arrays grow as its points are decoded (doubling from READ_CHUNK_POINTS): the points are laspy's."""
    import zbuf_occlude.io.las as las_module

    monkeypatch.setattr(las_module, "READ_CHUNK_POINTS", 7)
    data = _layered_laz() if compress else _encode()
    ref = laspy.read(io.BytesIO(data))
    read = read_las(_write(tmp_path, data, "scan.laz" if compress else "scan.las"))
    assert np.array_equal(read.points, np.stack([ref.x, ref.y, ref.z], axis=1))
    for key in ("intensity", "return_number", "number_of_returns", "classification", "point_source_id", "gps_time"):
        assert np.array_equal(getattr(read, key), np.asarray(ref[key])), key


def test_a_laz_declaring_more_points_than_it_decodes_reserves_what_it_decodes(tmp_path: Path, monkeypatch) -> None:
    """One chunk of 2³¹ points holding 600, declaring 9·10⁶ (540 MB of arrays): refused as unreadable, having
    reserved the arrays of the points decoded, not of the count (a LAS's count is bounded by its bytes)."""
    import zbuf_occlude.io.las as las_module

    reserved = []
    real = las_module._reserve
    monkeypatch.setattr(las_module, "_reserve", lambda out, n: reserved.append(n) or real(out, n))
    data = _layered_laz()
    data = _with_count(_patched(data, _laszip_vlr(data) + _CHUNK_SIZE_AT, "<I", 1 << 31), 9 * 10**6)
    with pytest.raises(InvalidInputError, match="not a readable LAS/LAZ file"):
        read_las(_write(tmp_path, data, "tile.laz"))
    assert reserved and max(reserved) <= las_module.READ_CHUNK_POINTS
