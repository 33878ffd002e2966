"""Ray table files (:mod:`zbuf_occlude.io.ray_tables`): CSV and ``.npy`` read back exactly, and hostile
files refused in one line naming the file, the large ones before their rows are allocated."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numpy.lib import format as npy_format

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError, UnsafePathError
from zbuf_occlude.io.ray_tables import RAY_TABLE_COLUMNS, ray_table_bytes, read_ray_table
from zbuf_occlude.sensors.patterns.ray_table import load_ray_table

HEADER = ",".join(RAY_TABLE_COLUMNS)


def _write(path: Path, data: bytes | str) -> Path:
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


def _refused(path: Path, match: str, *, max_rows: int = 100, error=InvalidInputError, **kw) -> str:
    with pytest.raises(error, match=match) as info:
        read_ray_table(path, max_rows=max_rows, **kw)
    message = str(info.value)
    assert "\n" not in message and str(path) in message, message
    return message


_finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=st.lists(st.tuples(_finite, _finite, _finite), min_size=1, max_size=12), suffix=st.sampled_from([".csv", ".npy"]))
def test_a_table_reads_back_bit_for_bit(tmp_path: Path, rows, suffix: str) -> None:
    table = np.array(rows, dtype=np.float64)
    path = _write(tmp_path / f"t{suffix}", ray_table_bytes(table[:, 0], table[:, 1], table[:, 2], suffix=suffix))
    columns = read_ray_table(path, max_rows=len(rows))
    for got, want in zip(columns, table.T, strict=True):
        assert got.dtype == np.float64 and got.flags.c_contiguous
        assert got.tobytes() == want.tobytes()  # -0.0 and subnormals included


def test_csv_header_may_have_spaces_and_crlf_and_blank_lines(tmp_path: Path) -> None:
    path = _write(tmp_path / "t.CSV", " time_s , azimuth_deg,elevation_deg \r\n0,1.5,-2\r\n\r\n0.25, 3 ,4e-1\r\n")
    t, a, e = read_ray_table(path, max_rows=3)  # the blank line counts towards the cap
    assert t.tolist() == [0.0, 0.25] and a.tolist() == [1.5, 3.0] and e.tolist() == [-2.0, 0.4]


def test_npy_of_float32_reads_as_float64(tmp_path: Path) -> None:
    table = np.array([[0.0, 1.0, 2.5], [1e-3, -3.0, 89.0]], np.float32)
    path = _write(tmp_path / "t.npy", _npy(table))
    t, a, e = read_ray_table(path, max_rows=2)
    assert t.dtype == np.float64 and np.array_equal(np.column_stack([t, a, e]), table.astype(np.float64))


def test_nan_is_a_number_here_the_sensor_refuses_it(tmp_path: Path) -> None:
    # the reader checks the format; RayTable checks the values (tests/sensors/test_ray_table.py)
    path = _write(tmp_path / "t.csv", f"{HEADER}\n0,nan,1\n")
    assert np.isnan(read_ray_table(path, max_rows=1)[1][0])


@pytest.mark.parametrize(
    "text, match",
    [
        ("0,1,2\n1,2,3\n", r"first line must be the header time_s,azimuth_deg,elevation_deg; line 1 holds 3 other fields$"),
        ("time,azimuth,elevation\n0,1,2\n", r"must be the header .*; line 1 holds 3 other fields$"),
        ("azimuth_deg,time_s,elevation_deg\n0,1,2\n", r"must be the header .*; line 1 names them in another order$"),
        (f"{HEADER},intensity\n0,1,2,3\n", r"must be the header .*; line 1 holds 4 other fields$"),
        ("", r"must be the header .*; the file is empty$"),
        (f"{HEADER}\n", r"the ray table has no rows"),
        (f"{HEADER}\n\n\n", r"the ray table has no rows"),
        (f"{HEADER}\n0,1\n", r"line 2 holds 2 numbers; each row must hold 3 \(time_s,azimuth_deg,elevation_deg\)"),
        (f"{HEADER}\n0,1,2,3\n", r"line 2 holds 4 numbers; each row must hold 3"),
        (f"{HEADER}\n0,1,2\n0,1\n", r"line 3 holds 2 numbers"),
        (f"{HEADER}\n0,1,x\n", r"line 2 is not a row of three numbers separated by commas \(column 3 is not a number\)$"),
        (f"{HEADER}\n0,1,2\n\n\r\n0,y,1\r\n", r"line 5 is not a row of three numbers separated by commas \(column 2 is not a number\)$"),
        (f"{HEADER}\n0,1,2\n   \n0,1,2\n", r"line 3 is not a row of three numbers separated by commas \(column 1 is not a number\)$"),
        (f"{HEADER}\n# a comment\n0,1,2\n", r"line 2 is not a row of three numbers separated by commas \(column 1 is not a number\)$"),
        (f'{HEADER}\n"0","1","2"\n', r"line 2 is not a row of three numbers separated by commas \(column 1 is not a number\)$"),
        (f"{HEADER}\n0,1,2\r\r\n", r"line 2 is not a row of three numbers separated by commas$"),  # numpy: an embedded line end
        (f"{HEADER}\n0,1,2\n" + "0," * 600, r"line 3 is longer than 1,024 bytes"),
    ],
)
def test_a_csv_that_is_not_a_ray_table_is_one_line(tmp_path: Path, text: str, match: str) -> None:
    _refused(_write(tmp_path / "t.csv", text), match)


def test_a_csv_that_is_not_utf8_is_one_line(tmp_path: Path) -> None:
    _refused(_write(tmp_path / "t.csv", HEADER.encode() + b"\n0,1,2\n0,1,\xff\n"), r"line 3 is not UTF-8 text")


def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    return buffer.getvalue()


@pytest.mark.parametrize(
    "array, match",
    [
        (np.zeros((4, 3), np.int64), r"an \(N, 3\) floating-point array .*got shape \(4, 3\) dtype int64"),
        (np.zeros((4, 3), bool), r"dtype bool"),
        (np.zeros((4, 3), np.complex64), r"dtype complex64"),
        (np.zeros((4, 2)), r"got shape \(4, 2\)"),
        (np.zeros(12), r"got shape \(12,\)"),
        (np.zeros((2, 2, 3)), r"got shape \(2, 2, 3\)"),
        (np.zeros(4, dtype=[("time_s", "f8"), ("azimuth_deg", "f8"), ("elevation_deg", "f8")]), r"got shape \(4,\) dtype void192$"),
        (np.zeros((0, 3)), r"the ray table has no rows"),
    ],
)
def test_a_npy_that_is_not_an_n_by_3_float_array_is_one_line(tmp_path: Path, array: np.ndarray, match: str) -> None:
    _refused(_write(tmp_path / "t.npy", _npy(array)), match)


def test_a_huge_declared_npy_is_refused_from_its_header(tmp_path: Path, monkeypatch) -> None:
    """A header declaring 10⁹ rows over a few bytes: refused before numpy reads (allocates) the body."""
    buffer = io.BytesIO()
    npy_format.write_array_header_1_0(buffer, {"descr": "<f8", "fortran_order": False, "shape": (10**9, 3)})
    path = _write(tmp_path / "huge.npy", buffer.getvalue() + b"\0" * 48)

    def no_body(*args, **kwargs):
        raise AssertionError("the body was read")

    monkeypatch.setattr(npy_format, "read_array", no_body)
    _refused(path, r"its header declares 24,000,000,000 bytes of array", max_rows=4)


def test_more_rows_than_the_cap_are_refused(tmp_path: Path) -> None:
    t = np.arange(5.0)
    _refused(_write(tmp_path / "t.npy", ray_table_bytes(t, t, t, suffix=".npy")), r"declares 120 bytes .* the 96 accepted", max_rows=4)
    _refused(_write(tmp_path / "t.csv", ray_table_bytes(t, t, t)), r"more than 4 lines after the header", max_rows=4)
    assert len(read_ray_table(tmp_path / "t.csv", max_rows=5)[0]) == 5


def test_a_csv_larger_than_its_rows_may_take_is_refused_before_reading(tmp_path: Path) -> None:
    path = _write(tmp_path / "t.csv", f"{HEADER}\n0,0,0\n" + " " * 10_000)
    _refused(path, r"10,039 bytes, more than the 4,192 a file read here may have", max_rows=1)


@pytest.mark.parametrize("suffix", [".txt", ".npz", ""])
def test_other_suffixes_are_refused(tmp_path: Path, suffix: str) -> None:
    _refused(_write(tmp_path / f"t{suffix}", f"{HEADER}\n0,0,0\n"), r"must be a \.csv or a \.npy file")


def test_a_missing_file_is_one_line(tmp_path: Path) -> None:
    _refused(tmp_path / "none.csv", r"none\.csv")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
@pytest.mark.parametrize("suffix", [".csv", ".npy"])
def test_a_fifo_is_refused_without_blocking(tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"fifo{suffix}"
    os.mkfifo(path)
    _refused(path, r"is a FIFO; only regular files are read")


@pytest.mark.parametrize("suffix", [".csv", ".npy"])
def test_a_link_out_of_the_folder_is_refused(tmp_path: Path, suffix: str) -> None:
    outside, folder = tmp_path / "outside", tmp_path / "folder"
    outside.mkdir()
    folder.mkdir()
    target = _write(outside / f"t{suffix}", ray_table_bytes([0.0], [1.0], [2.0], suffix=suffix))
    link = folder / f"t{suffix}"
    link.symlink_to(target)
    assert read_ray_table(link, max_rows=1)[1].tolist() == [1.0]  # no folder named: the link is followed
    _refused(link, r"outside", error=UnsafePathError, within=folder)


def test_the_writer_refuses_ragged_columns_and_other_suffixes() -> None:
    with pytest.raises(InvalidInputError, match="one length"):
        ray_table_bytes([0.0, 1.0], [0.0], [0.0, 1.0])
    with pytest.raises(InvalidInputError, match=r"\.csv or \.npy"):
        ray_table_bytes([0.0], [0.0], [0.0], suffix=".las")


# -- a CSV is read a block of lines at a time: what it holds beyond a block is never held whole -----------------------------


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    rows=st.lists(st.tuples(_finite, _finite, _finite), min_size=1, max_size=30),
    block=st.one_of(st.integers(1, 300), st.just(1 << 20)),  # lines split across blocks, or all in one
    blank=st.lists(st.booleans(), min_size=30, max_size=30),
    bad=st.one_of(st.none(), st.integers(0, 29)),
)
def test_blocks_of_any_size_read_the_same_rows_and_name_the_same_line(tmp_path: Path, monkeypatch, rows, block, blank, bad) -> None:
    """The law: the block size changes nothing, neither the rows read nor the line a refusal names
    (blank lines, CRLF ends and lines split across blocks included)."""
    import zbuf_occlude.io.ray_tables as ray_tables

    monkeypatch.setattr(ray_tables, "CSV_BLOCK_BYTES", block)
    lines, bad_line = [HEADER], None
    for i, row in enumerate(rows):
        if blank[i]:
            lines.append("" if i % 2 else "\r")
        if bad == i:
            lines.append("0,1,nope")
            bad_line = len(lines)
        lines.append(",".join(f"{v!r}" for v in row) + ("\r" if i % 3 == 0 else ""))
    path = _write(tmp_path / "t.csv", "\n".join(lines) + "\n")
    if bad_line is not None:
        _refused(
            path, rf"line {bad_line} is not a row of three numbers separated by commas \(column 3 is not a number\)$", max_rows=len(lines)
        )
        return
    columns = read_ray_table(path, max_rows=len(lines))
    assert np.column_stack(columns).tobytes() == np.array(rows, dtype=np.float64).tobytes()


def test_one_endless_line_is_refused_after_a_block_under_a_memory_limit(tmp_path: Path) -> None:
    """400 MB after the header and no line end (a sparse file: nothing on disk), within the 402 MB a
    sensor's table may take: read whole it took 6.3 GB; refused from the first block, in 512 MiB."""
    from memory_limit import run_python_limited

    path = tmp_path / "endless.csv"
    with path.open("wb") as fh:
        fh.write(f"{HEADER}\n0".encode())
        fh.truncate(400_000_000)
    done = run_python_limited(
        "from zbuf_occlude.errors import InvalidInputError\n"
        "from zbuf_occlude.sensors.patterns.ray_table import load_ray_table\n"
        f"try:\n    load_ray_table({str(path)!r})\nexcept InvalidInputError as exc:\n    print(exc)\n",
        headroom=512 << 20,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f"{path}: line 2 is longer than 1,024 bytes; a ray table's rows are three numbers ({HEADER})"


def test_more_rows_than_the_cap_are_refused_before_the_rest_is_read(tmp_path: Path, monkeypatch) -> None:
    """Short rows ("0,0,0": 6 bytes) fit 16 times the cap's rows in the size cap; reading stops a block after the cap."""
    import zbuf_occlude.io.ray_tables as ray_tables

    path = _write(tmp_path / "t.csv", f"{HEADER}\n" + "0,0,0\n" * 15_000)
    read = []
    opener = ray_tables.open_regular_file

    class Counted:
        def __init__(self, fh):
            self.fh = fh

        def read(self, n=-1):
            read.append(len(data := self.fh.read(n)))
            return data

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

    def counted(*args, **kwargs):
        fh, size = opener(*args, **kwargs)
        return Counted(fh), size

    monkeypatch.setattr(ray_tables, "open_regular_file", counted)
    monkeypatch.setattr(ray_tables, "CSV_BLOCK_BYTES", 4096)
    _refused(path, r"more than 1,000 lines after the header", max_rows=1_000)
    assert sum(read) <= 1_000 * 6 + 2 * 4096 < path.stat().st_size / 4  # the cap's rows and a block, of 90 kB


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: read_ray_table(123, max_rows=4), r"path must be a ray table's path \(str or os.PathLike\), got int 123"),
        (lambda: read_ray_table(None, max_rows=4), r"path must be a ray table's path .*got NoneType"),
        (lambda: read_ray_table("t.csv", max_rows="4"), r"max_rows must be a whole number >= 1, got str '4'"),
        (lambda: read_ray_table("t.csv", max_rows=True), r"max_rows must be a whole number >= 1, got bool True"),
        (lambda: read_ray_table("t.csv", max_rows=0), r"max_rows must be a whole number >= 1, got int 0"),
        (lambda: read_ray_table("t.csv", max_rows=4, within=1), r"within must be a folder's path .* or None, got int 1"),
        (lambda: load_ray_table(123), r"path must be a ray table's path .*got int 123"),
        (lambda: load_ray_table(None), r"path must be a ray table's path .*got NoneType"),
        (lambda: load_ray_table("t.csv", within=b"tables"), r"within must be a folder's path .*got bytes b'tables'"),
    ],
)  # fmt: skip
def test_wrong_kinds_name_the_argument_and_the_value(call, match: str) -> None:
    with pytest.raises(ArgumentTypeError, match=match) as info:
        call()
    assert isinstance(info.value, TypeError) and "\n" not in str(info.value)


#: What a private file holds (a link or a wrong path given as a ray table): it never reaches a message.
SECRET = "aws_secret_access_key=Zq7SecretMarker"


@pytest.mark.parametrize(
    ("name", "data"),
    [
        ("header.csv", f"{SECRET},b,c\n0,1,2\n"),
        ("one_line.csv", f"{SECRET}\n"),
        ("cell.csv", f"{HEADER}\n0,1,2\n0,{SECRET},2\n"),
        ("ragged.csv", f"{HEADER}\n0,1,2\n0,1,2,{SECRET}\n"),
        ("quoted.csv", f'{HEADER}\n"{SECRET}",1,2\n'),
        ("carriage.csv", f"{HEADER}\n0,1,{SECRET}\r\r\n"),
        ("long.csv", f"{HEADER}\n0,1,2,{SECRET * 40}\n"),
        ("fields.npy", _npy(np.zeros((2, 3), dtype=[(SECRET, "f8")]))),
    ],
)  # fmt: skip
def test_a_ray_table_is_refused_without_quoting_it(tmp_path: Path, name: str, data) -> None:
    message = _refused(_write(tmp_path / name, data), r".")
    assert "Zq7Secret" not in message and "aws_secret" not in message, message
