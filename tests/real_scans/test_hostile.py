"""Hostile real-scan files and folders: declared sizes checked before allocating, no point or class lost silently.

Each file is built here and is small (sparse files stand for the multi-GB ones: they take no disk).
"""

from __future__ import annotations

import io
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.caps import MAX_REAL_SCAN_BYTES, MAX_REAL_SCAN_LINE_BYTES
from zbuf_occlude.real_scans import files
from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.real_scans.files import (
    load_scan_folder,
    read_points,
)

ROWS = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.5]])


def _pcd_head(points: int, width: int, mode: str) -> bytes:
    return (f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {width}\nHEIGHT 1\n"
            f"POINTS {points}\nDATA {mode}\n").encode()  # fmt: skip


# -- memory: declared and inflated sizes --------------------------------------------------
def test_npz_member_inflating_past_the_cap_is_refused_from_the_zip_directory(tmp_path: Path, monkeypatch) -> None:
    path = tmp_path / "zeros.npz"
    np.savez_compressed(path, points=np.zeros((1_000_000, 3)))  # 24 MB inflated, ~25 KB stored
    assert path.stat().st_size < 100_000
    monkeypatch.setattr(files, "MAX_REAL_SCAN_ARRAY_BYTES", 1 << 20)  # stands for the 1 GiB cap
    with pytest.raises(InvalidInputError, match=r"zeros\.npz: its members inflate to 24,000,\d+ bytes, more than the 1,048,576 accepted"):
        read_points(path)


def test_npy_header_declaring_more_than_the_member_holds_is_refused(tmp_path: Path) -> None:
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**9, 3)})
    path = tmp_path / "forged.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("points.npy", header.getvalue() + np.zeros(9).tobytes())
    with pytest.raises(InvalidInputError, match=r"forged\.npz: member 1 declares 24,000,000,000 bytes"):
        read_points(path)


@pytest.mark.slow
def test_a_csv_scan_takes_memory_like_its_points_not_like_python_strings(tmp_path: Path) -> None:
    path = tmp_path / "many.csv"
    n = 200_000
    path.write_bytes(b"1,2,3\n" * n)
    tracemalloc.start()
    try:
        pts = read_points(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert pts.shape == (n, 3)
    # the result alone is 24 bytes a row, 4x the 6-byte rows; a list of split strings is ~50x
    assert peak < 6 * path.stat().st_size, peak / path.stat().st_size


def test_a_one_line_csv_is_refused_by_its_line_length(tmp_path: Path) -> None:
    path = tmp_path / "one_line.csv"
    path.write_bytes(b"1," * (MAX_REAL_SCAN_LINE_BYTES * 4))  # no newline at all
    with pytest.raises(InvalidInputError, match=rf"one_line\.csv:1: a line longer than {MAX_REAL_SCAN_LINE_BYTES:,} bytes"):
        read_points(path)


def _no_whole_reads(monkeypatch) -> None:
    def refuse(self):
        raise AssertionError(f"{self} read whole before its size was checked")

    monkeypatch.setattr(Path, "read_bytes", refuse)


def test_a_multi_gb_scan_is_refused_before_it_is_hashed(tmp_path: Path, monkeypatch) -> None:
    big = tmp_path / "car" / "big.xyz"
    big.parent.mkdir()
    with open(big, "wb") as fh:
        fh.truncate(MAX_REAL_SCAN_BYTES + 1)  # sparse: no disk, no memory
    _no_whole_reads(monkeypatch)
    with pytest.raises(InvalidInputError, match=rf"big\.xyz: {MAX_REAL_SCAN_BYTES + 1:,} bytes, more than the {MAX_REAL_SCAN_BYTES:,}"):
        load_scan_folder(tmp_path, dedupe=True)


_LIDARNET_HEAD = b"origin_x,origin_y,origin_z,relative_x,relative_y,relative_z,object,complexity\n"


def _peak_bytes(read, path: Path):
    tracemalloc.start()
    try:
        result = read(path)
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.slow
def test_a_lidarnet_csv_takes_memory_like_its_points_not_like_python_rows(tmp_path: Path) -> None:
    from zbuf_occlude.real_scans.datasets import read_lidarnet_csv

    path = tmp_path / "car0.csv"
    n = 100_000
    path.write_bytes(_LIDARNET_HEAD + b"".join(b"%d,2,3,0,0,0,car,1\n" % (i % 10) for i in range(n)))
    scan, peak = _peak_bytes(read_lidarnet_csv, path)
    assert scan.points_sensor_m.shape == (n, 3) and scan.label == "car"
    # the points (24 B each) and the copies a RealScan holds (z-up metres, normalised float32)
    # take ~84 B a point; a list of float lists would take ~150 B a point more
    assert peak < 100 * n, peak / n


@pytest.mark.slow
def test_a_suo_csv_takes_memory_like_its_records_not_like_python_tuples(tmp_path: Path) -> None:
    from zbuf_occlude.real_scans.datasets import SUO_DTYPE, read_suo_csv

    path = tmp_path / "car.0.csv"
    n = 100_000
    path.write_bytes(b"1,2,3,1.5,2.5,3.5,4.5,5.5,7\n" * n)
    records, peak = _peak_bytes(read_suo_csv, path)
    assert records.dtype == SUO_DTYPE and len(records) == n and records["x"][0] == 1.5
    assert peak < 2.5 * path.stat().st_size, peak / path.stat().st_size  # 40 B a record against 28 B a line


def test_a_lidarnet_csv_with_a_line_past_the_cap_is_refused_naming_it(tmp_path: Path) -> None:
    from zbuf_occlude.real_scans.datasets import read_lidarnet_csv

    path = tmp_path / "car0.csv"
    path.write_bytes(_LIDARNET_HEAD + b"1,2,3,0,0,0,car,1\n" + b"9" * (4 * MAX_REAL_SCAN_LINE_BYTES))
    with pytest.raises(InvalidInputError, match=rf"car0\.csv:3: a line longer than {MAX_REAL_SCAN_LINE_BYTES:,} bytes"):
        read_lidarnet_csv(path)


def test_a_lidarnet_csv_stops_at_its_second_object_label(tmp_path: Path) -> None:
    from zbuf_occlude.real_scans.datasets import read_lidarnet_csv

    path = tmp_path / "car0.csv"
    path.write_bytes(_LIDARNET_HEAD + b"1,2,3,0,0,0,car,1\n" + b"1,2,3,0,0,0,bush,1\n" + b"1,2,3,0,0,0,x,1\n" * 1000)
    with pytest.raises(InvalidInputError, match=r"car0\.csv:3: a second object label; a LiDARNet CSV holds one object$"):
        read_lidarnet_csv(path)


def test_a_lidarnet_csv_with_more_lines_than_a_scan_may_have_is_refused_before_reading(tmp_path: Path, monkeypatch) -> None:
    from zbuf_occlude.real_scans.datasets import read_lidarnet_csv

    path = tmp_path / "car0.csv"
    path.write_bytes(_LIDARNET_HEAD + b"1,2,3,0,0,0,car,1\n" * 50)
    monkeypatch.setattr(files, "MAX_SCAN_POINTS", 10)  # stands for the 50 M cap
    with pytest.raises(InvalidInputError, match=r"car0\.csv: has up to 51 points, more than the 10 a scan may have"):
        read_lidarnet_csv(path)


def test_a_multi_gb_lidarnet_csv_is_refused_before_it_is_hashed(tmp_path: Path, monkeypatch) -> None:
    big = tmp_path / "Car" / "car1.csv"
    big.parent.mkdir()
    with open(big, "wb") as fh:
        fh.write(b"origin_x,origin_y,origin_z,object\n")
        fh.truncate(MAX_REAL_SCAN_BYTES + 1)
    _no_whole_reads(monkeypatch)
    with pytest.raises(InvalidInputError, match=rf"car1\.csv: {MAX_REAL_SCAN_BYTES + 1:,} bytes, more than the {MAX_REAL_SCAN_BYTES:,}"):
        load_real_scans(tmp_path)


def test_detection_reads_a_bounded_first_line(tmp_path: Path, monkeypatch) -> None:
    """A CSV with no newline: detection reads at most one line's cap, never the whole file."""
    (tmp_path / "Car").mkdir()
    (tmp_path / "Car" / "a.csv").write_bytes(b"1" * (4 * MAX_REAL_SCAN_LINE_BYTES))
    seen = []
    real_open = open

    def spy_open(file, mode="r", *args, **kwargs):
        fh = real_open(file, mode, *args, **kwargs)
        if "b" in mode:
            original = fh.readline
            fh.readline = lambda size=-1: seen.append(size) or original(size)  # type: ignore[method-assign]
        return fh

    # the one opener of the files a user names
    from zbuf_occlude.io import regular_files

    monkeypatch.setattr(regular_files, "open", spy_open, raising=False)
    with pytest.raises(InvalidInputError):
        load_real_scans(tmp_path)
    # detection's read first; the reader's after it, one byte more to tell a line too long: every read bounded
    assert seen and 0 < seen[0] <= MAX_REAL_SCAN_LINE_BYTES and all(0 < s <= MAX_REAL_SCAN_LINE_BYTES + 1 for s in seen), seen


# -- silent losses ------------------------------------------------------------------------
def test_auto_detection_refuses_files_the_lidarnet_reader_would_drop(tmp_path: Path) -> None:
    (tmp_path / "Car").mkdir()
    (tmp_path / "Car" / "car1.csv").write_text("origin_x,origin_y,origin_z,object\n1,2,3,Car\n4,5,6,Car\n7,8,9.5,Car\n")
    (tmp_path / "Bush").mkdir()
    (tmp_path / "Bush" / "bush1.pcd").write_bytes(_pcd_head(3, 3, "binary") + ROWS.astype("<f4").tobytes())
    with pytest.raises(InvalidInputError, match=r"lidarnet reader cannot read 1 file\(s\): Bush/bush1\.pcd"):
        load_real_scans(tmp_path)
    labels = {s.label for s in load_real_scans(tmp_path, dataset="folder")}  # the way out the message gives
    assert labels == {"Car", "Bush"}
    with pytest.raises(InvalidInputError, match=r"bush1\.pcd"):
        load_real_scans(tmp_path, dataset="lidarnet")


def test_a_scan_beside_the_class_folders_is_named(tmp_path: Path) -> None:
    (tmp_path / "car").mkdir()
    np.savetxt(tmp_path / "car" / "a.xyz", ROWS)
    np.savetxt(tmp_path / "stray.xyz", ROWS)
    with pytest.raises(InvalidInputError, match=r"outside any class folder \(stray\.xyz\)"):
        load_scan_folder(tmp_path)


def test_ascii_ply_holding_fewer_vertices_than_declared_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "short.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\n"
                    "end_header\n1 2 3\n4 5 6\n7 8 9\n")  # fmt: skip
    with pytest.raises(InvalidInputError, match=r"short\.ply: PLY declares 10 vertices but holds 3"):
        read_points(path)


@pytest.mark.parametrize(
    ("points", "width", "stored", "match"),
    [
        (2, 10, 10, "header declares POINTS 2 but WIDTH x HEIGHT = 10"),
        (2, 2, 10, r"declares 2 points \(24 bytes\) but holds 120 bytes"),
        (10, 10, 3, "declares 10 points"),
    ],
)
def test_binary_pcd_points_must_match_width_height_and_body(tmp_path: Path, points, width, stored, match) -> None:
    path = tmp_path / "scan.pcd"
    path.write_bytes(_pcd_head(points, width, "binary") + np.tile(ROWS, (4, 1))[:stored].astype("<f4").tobytes())
    with pytest.raises(InvalidInputError, match=rf"scan\.pcd: PCD {match}"):
        read_points(path)


def test_ascii_pcd_rows_must_match_points(tmp_path: Path) -> None:
    path = tmp_path / "scan.pcd"
    path.write_bytes(_pcd_head(10, 10, "ascii") + b"1 2 3\n4 5 6\n7 8 9\n")
    with pytest.raises(InvalidInputError, match=r"scan\.pcd: PCD declares 10 points but holds 3 rows"):
        read_points(path)
    path.write_bytes(_pcd_head(3, 3, "ascii") + b"1 2 3\n4 5 6\n7 8 9\n")
    assert read_points(path).shape == (3, 3)
