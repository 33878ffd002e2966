"""Writers and readers: formats, atomicity, clear errors."""

from __future__ import annotations

import contextlib
import errno
import io
import os
import subprocess
import sys
import tempfile
import threading
import zipfile
from pathlib import Path

import h5py
import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import DatasetFormatError, OutputError
from zbuf_occlude.geometry.samples import OccludedCloud
from zbuf_occlude.io.atomic import atomic_path
from zbuf_occlude.io.clouds import read_h5, read_npz, write_h5, write_npz, write_ply


def _cloud(n=64, seed=0, **kw):
    rng = np.random.default_rng(seed)
    base = dict(
        points=rng.uniform(-0.5, 0.5, (n, 3)).astype(np.float32), face_index=rng.integers(0, 100, n),
        elevation_deg=30.0, azimuth_deg=45.0, radius=4.0, label=2, class_name="chair", source="a/chair.off",
        sample_index=1, n_visible=n + 5,
    )  # fmt: skip
    return OccludedCloud(**{**base, **kw})


def test_npz_round_trip(tmp_path):
    c = _cloud()
    back = read_npz(write_npz(tmp_path / "x.npz", c))
    assert np.array_equal(back.points, c.points) and back.points.dtype == np.float32
    assert np.array_equal(back.face_index, c.face_index)
    assert (back.elevation_deg, back.azimuth_deg, back.radius, back.label, back.class_name) == (30.0, 45.0, 4.0, 2, "chair")
    assert not back.padded and _cloud(n_visible=10).padded


def test_read_npz_reads_the_file_it_checked_even_if_the_name_is_swapped_after(tmp_path, monkeypatch):
    # the sizes and headers are checked on one open file and the arrays read from it: a file put
    # in the name's place once it is open (a link swapped, a file replaced) is never read
    import zbuf_occlude.io.arrays as arrays

    checked, swapped = _cloud(seed=1), _cloud(seed=2)
    path = write_npz(tmp_path / "x.npz", checked)
    write_npz(tmp_path / "other.npz", swapped)
    opened = arrays.open_regular_file

    def open_then_swap(*args, **kwargs):
        result = opened(*args, **kwargs)
        if (tmp_path / "other.npz").exists():
            os.replace(tmp_path / "other.npz", path)
        return result

    monkeypatch.setattr(arrays, "open_regular_file", open_then_swap)
    assert np.array_equal(read_npz(path).points, checked.points)


def test_ply_opens_in_trimesh_with_the_points(tmp_path):
    c = _cloud()
    pc = trimesh.load(write_ply(tmp_path / "x.ply", c))
    assert np.allclose(pc.vertices, c.points)
    assert "elevation_deg 30.000000" in (tmp_path / "x.ply").read_bytes()[:600].decode("ascii", "replace")


def test_h5_has_pointnets_layout(tmp_path):
    clouds = [_cloud(seed=i, label=i % 2) for i in range(5)]
    d = read_h5(write_h5(tmp_path / "x.h5", clouds, shape_names=["bed", "chair"]))
    assert d["data"].shape == (5, 64, 3) and d["data"].dtype == np.float32
    assert d["label"].tolist() == [0, 1, 0, 1, 0]
    assert d["elevation_deg"].shape == (5,) and d["azimuth_deg"].shape == (5,)
    assert list(d["shape_names"]) == ["bed", "chair"] and d["source"][0] == "a/chair.off"


def test_h5_refuses_mixed_sizes(tmp_path):
    with pytest.raises(OutputError, match="sizes"):
        write_h5(tmp_path / "x.h5", [_cloud(10), _cloud(20)])


def test_a_failed_write_leaves_neither_target_nor_temporary(tmp_path):
    target = tmp_path / "x.npz"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"partial")
            raise RuntimeError("killed mid-write")
    assert list(tmp_path.iterdir()) == []


def test_existing_file_survives_a_failed_rewrite(tmp_path):
    target = write_npz(tmp_path / "x.npz", _cloud())
    before = target.read_bytes()
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"junk")
            raise RuntimeError
    assert target.read_bytes() == before


def test_disk_full_is_a_clear_error(tmp_path, monkeypatch):
    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(OutputError, match="disk full"):
        write_npz(tmp_path / "x.npz", _cloud())
    assert not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())


def test_unwritable_output_folder_is_a_clear_error(tmp_path):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("")
    with pytest.raises(OutputError, match="cannot write"):
        write_npz(blocker / "x.npz", _cloud())


def test_h5_clouds_round_trip(tmp_path):
    from zbuf_occlude.io.clouds import read_h5_clouds

    clouds = [_cloud(seed=i, label=i, sample_index=i) for i in range(3)]
    back = read_h5_clouds(write_h5(tmp_path / "x.h5", clouds))
    assert len(back) == 3
    for a, b in zip(clouds, back):
        assert np.array_equal(a.points, b.points) and np.array_equal(a.face_index, b.face_index)
        assert (a.label, a.sample_index, a.source, a.n_visible) == (b.label, b.sample_index, b.source, b.n_visible)


# -- the guarantees of atomic_path, one by one ---------------------------------------------
def _spy(monkeypatch, log):
    """Record os.fsync (with the path of the fd) and os.replace calls, in order."""
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        log.append(("fsync", os.readlink(f"/proc/self/fd/{fd}") if os.path.exists("/proc/self/fd") else fd))
        return real_fsync(fd)

    def replace(src, dst, *a, **k):
        log.append(("replace", os.fspath(src), os.fspath(dst)))
        return real_replace(src, dst, *a, **k)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)


def test_the_temporary_is_beside_the_target_not_in_tmpdir(tmp_path, monkeypatch):
    """os.replace is atomic only within one file system: the temporary must be created in
    the target's own folder, whatever $TMPDIR says."""
    import tempfile

    elsewhere = tmp_path / "tmpdir"
    elsewhere.mkdir()
    monkeypatch.setenv("TMPDIR", str(elsewhere))
    monkeypatch.setattr(tempfile, "tempdir", str(elsewhere))
    log = []
    _spy(monkeypatch, log)
    target = tmp_path / "out" / "x.npz"
    write_npz(target, _cloud())
    replaces = [e for e in log if e[0] == "replace"]
    assert len(replaces) == 1
    _, src, dst = replaces[0]
    assert os.path.dirname(src) == str(target.parent) and dst == str(target)
    assert list(elsewhere.iterdir()) == []
    assert sorted(p.name for p in target.parent.iterdir()) == ["x.npz"]


@pytest.mark.parametrize("writer", ["npz", "ply", "h5", "text", "csv"])
def test_data_are_fsynced_before_the_rename(tmp_path, monkeypatch, writer):
    from zbuf_occlude.io.atomic import write_csv, write_text

    log = []
    _spy(monkeypatch, log)
    target = tmp_path / f"x.{writer}"
    write = {
        "npz": lambda: write_npz(target, _cloud()),
        "ply": lambda: write_ply(target, _cloud()),
        "h5": lambda: write_h5(target, [_cloud()]),
        "text": lambda: write_text(target, "hello\n"),
        "csv": lambda: write_csv(target, [{"a": 1, "b": 2}]),
    }[writer]
    write()
    kinds = [e[0] for e in log]
    assert kinds == ["fsync", "replace"], log
    _, src, _ = log[1]
    if isinstance(log[0][1], str):  # the fsynced fd is the temporary's
        assert log[0][1] == src


def test_written_files_get_the_mode_the_umask_gives(tmp_path):
    """mkstemp makes 0600 files; outputs get 0666 & ~umask like a plain open()."""
    plain = tmp_path / "plain"
    plain.write_bytes(b"")
    target = write_npz(tmp_path / "x.npz", _cloud())
    assert target.stat().st_mode & 0o777 == plain.stat().st_mode & 0o777
    # and with a stricter umask, set before the process's first write
    code = (
        "import os, sys\n"
        "os.umask(0o027)\n"
        "from zbuf_occlude.io.atomic import write_text\n"
        "p = write_text(sys.argv[1], 'x')\n"
        "print(oct(os.stat(p).st_mode & 0o777))\n"
    )
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "strict.txt")], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "0o640"


@pytest.mark.parametrize("exc", [RuntimeError("numpy failed"), KeyboardInterrupt()])
def test_an_exception_mid_write_leaves_no_partial_file(tmp_path, monkeypatch, exc):
    """A writer dying half-way (error or Ctrl-C): no target, no temporary; an existing
    target keeps its old bytes; while writing, the target never holds new bytes."""
    target = tmp_path / "x.npz"
    seen_during_write = []

    def dying_savez(fh, **arrays):
        fh.write(b"PK\x03\x04 half a zip")
        fh.flush()
        seen_during_write.append(target.exists())
        raise exc

    monkeypatch.setattr(np, "savez_compressed", dying_savez)
    with pytest.raises(type(exc)):
        write_npz(target, _cloud())
    assert list(tmp_path.iterdir()) == [] and seen_during_write == [False]
    monkeypatch.undo()
    old = write_npz(target, _cloud(seed=1)).read_bytes()
    monkeypatch.setattr(np, "savez_compressed", dying_savez)
    with pytest.raises(type(exc)):
        write_npz(target, _cloud(seed=2))
    assert target.read_bytes() == old and [p.name for p in tmp_path.iterdir()] == ["x.npz"]


# -- every field, every documented dtype ---------------------------------------------------
def _odd_types_cloud(seed=0, **kw):
    """A cloud whose fields come in other dtypes than the files store (float64 points,
    int32 face_index, numpy scalar metadata), with non-ASCII text."""
    rng = np.random.default_rng(seed)
    base = dict(
        points=rng.uniform(-0.5, 0.5, (16, 3)),  # float64: stored float32
        face_index=rng.integers(0, 100, 16).astype(np.int32),  # stored int64 (npz) / int32 (h5)
        elevation_deg=np.float32(12.5), azimuth_deg=np.float32(300.25), radius=np.float32(4.5),
        label=np.int32(3), class_name="chaise_longue_é", source="données/chaise_0001.off",
        sample_index=np.int16(7), n_visible=np.int32(11),
    )  # fmt: skip
    return OccludedCloud(**{**base, **kw})


def _same_cloud(a: OccludedCloud, b: OccludedCloud) -> None:
    assert np.array_equal(b.points, np.asarray(a.points, dtype=np.float32)) and b.points.dtype == np.float32
    assert np.array_equal(b.face_index, a.face_index) and b.face_index.dtype == np.int64
    for key in ("elevation_deg", "azimuth_deg", "radius"):
        assert getattr(b, key) == pytest.approx(float(getattr(a, key)), abs=0) and type(getattr(b, key)) is float
    for key in ("label", "sample_index", "n_visible"):
        assert getattr(b, key) == int(getattr(a, key)) and type(getattr(b, key)) is int
    for key in ("class_name", "source"):
        assert getattr(b, key) == getattr(a, key) and type(getattr(b, key)) is str


def test_npz_round_trip_keeps_every_field_and_normalises_dtypes(tmp_path):
    c = _odd_types_cloud()
    _same_cloud(c, read_npz(write_npz(tmp_path / "x.npz", c)))
    with np.load(tmp_path / "x.npz") as z:
        assert z["points"].dtype == np.float32 and z["face_index"].dtype == np.int64


def test_h5_round_trip_keeps_every_field_in_pointnets_dtypes(tmp_path):
    from zbuf_occlude.io.clouds import read_h5_clouds

    clouds = [_odd_types_cloud(seed=i, label=np.int32(i)) for i in range(3)]
    clouds[1].face_index = clouds[1].face_index.astype(np.int64)  # stored int32 whatever comes in
    path = write_h5(tmp_path / "x.h5", clouds, shape_names=["a", "b", "c", "chaise_longue_é"])
    for a, b in zip(clouds, read_h5_clouds(path)):
        _same_cloud(a, b)
    d = read_h5(path)
    expected = {
        "data": np.float32, "label": np.int64, "face_index": np.int32, "elevation_deg": np.float64,
        "azimuth_deg": np.float64, "radius": np.float64, "sample_index": np.int64, "n_visible": np.int64,
    }  # fmt: skip
    for key, dtype in expected.items():
        assert d[key].dtype == dtype, key
    assert d["data"].shape == (3, 16, 3) and d["face_index"].shape == (3, 16)
    assert list(d["shape_names"]) == ["a", "b", "c", "chaise_longue_é"]


def test_an_empty_h5_is_written_and_read_back(tmp_path):
    from zbuf_occlude.io.clouds import read_h5_clouds

    path = write_h5(tmp_path / "x.h5", [])
    assert read_h5_clouds(path) == []
    assert read_h5(path)["data"].shape == (0, 0, 3)


def test_read_h5_reads_a_plain_pointnet_file_without_shape_names(tmp_path):
    import h5py

    with h5py.File(tmp_path / "p.h5", "w") as f:
        f.create_dataset("data", data=np.zeros((2, 4, 3), dtype=np.float32))
        f.create_dataset("label", data=np.array([1, 0]))
    d = read_h5(tmp_path / "p.h5")
    assert d["data"].shape == (2, 4, 3) and d["label"].tolist() == [1, 0] and len(d["shape_names"]) == 0


def test_ply_header_is_a_valid_binary_ply_with_the_pose(tmp_path):
    c = _odd_types_cloud()
    raw = write_ply(tmp_path / "x.ply", c).read_bytes()
    header, _, body = raw.partition(b"end_header\n")
    lines = header.decode("ascii").splitlines()
    assert lines[:2] == ["ply", "format binary_little_endian 1.0"]
    assert lines[-4:] == ["property float x", "property float y", "property float z", "property int face_index"]
    assert "element vertex 16" in lines and "comment zbuf_occlude occluded point cloud" in lines
    assert "comment elevation_deg 12.500000" in lines and "comment radius 4.500000" in lines
    # the header is ASCII: non-ASCII text is escaped, not a UnicodeEncodeError
    assert "comment class chaise_longue_\\xe9 label 3 sample 7 n_visible 11" in lines
    rows = np.frombuffer(body, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("face_index", "<i4")])
    assert np.array_equal(np.stack([rows["x"], rows["y"], rows["z"]], 1), c.points.astype(np.float32))
    assert np.array_equal(rows["face_index"], c.face_index)
    named = write_ply(tmp_path / "n.ply", _cloud()).read_bytes().partition(b"end_header")[0].decode("ascii")
    assert "comment class chair label 2 sample 1 n_visible 69" in named.splitlines()
    anonymous = write_ply(tmp_path / "a.ply", _cloud(class_name="")).read_bytes().partition(b"end_header")[0]
    assert "comment class - label 2 sample 1 n_visible 69" in anonymous.decode("ascii").splitlines()


def test_write_csv_columns_extras_and_empty(tmp_path):
    import csv

    from zbuf_occlude.io.atomic import write_csv

    rows = [{"b": 1, "a": 2, "extra": 3}, {"b": 4, "a": 5}]
    with open(write_csv(tmp_path / "d.csv", rows[1:]), newline="", encoding="utf-8") as fh:
        assert list(csv.reader(fh)) == [["b", "a"], ["4", "5"]]  # default: the first row's keys
    with open(write_csv(tmp_path / "c.csv", rows, fieldnames=["a", "b"]), newline="", encoding="utf-8") as fh:
        assert list(csv.reader(fh)) == [["a", "b"], ["2", "1"], ["5", "4"]]  # extra keys left out
    assert write_csv(tmp_path / "e.csv", []).read_text(encoding="utf-8").strip() == ""


@pytest.mark.parametrize(
    ("err", "message"),
    [(errno.EACCES, "permission denied"), (errno.EROFS, "permission denied"), (errno.EIO, "cannot write")],
)
def test_os_errors_become_output_errors_with_a_hint(tmp_path, monkeypatch, err, message):
    def failing(*a, **k):
        raise OSError(err, os.strerror(err))

    monkeypatch.setattr(os, "replace", failing)
    with pytest.raises(OutputError, match=message) as info:
        write_npz(tmp_path / "x.npz", _cloud())
    if err == errno.EIO:
        assert "permission" not in str(info.value) and os.strerror(err) in str(info.value)


def test_text_files_are_utf8_whatever_the_locale(tmp_path):
    """write_text and write_csv write UTF-8 even where the locale's encoding is ASCII."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from zbuf_occlude.io.atomic import write_csv, write_text\n"
        "write_text(sys.argv[1] + '/t.txt', 'chaise_\\u00e9\\n')\n"  # ASCII source: the locale is C
        "write_csv(sys.argv[1] + '/c.csv', [{'class': 'chaise_\\u00e9'}])\n"
    )
    env = {**os.environ, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0", "PYTHONIOENCODING": "ascii"}
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "t.txt").read_bytes() == "chaise_é\n".encode()
    assert (tmp_path / "c.csv").read_bytes() == "class\r\nchaise_é\r\n".encode()


def test_concat_h5_joins_parts_row_wise_and_fills_missing_columns(tmp_path):
    from zbuf_occlude.io.clouds import concat_h5

    a = [_cloud(seed=i, split="train") for i in range(3)]
    b = [_cloud(seed=10 + i) for i in range(2)]
    write_h5(tmp_path / "a.h5", a, columns={"object_index": [0, 0, 0]})
    write_h5(tmp_path / "b.h5", b, columns={"object_index": [1, 1]})
    with h5py.File(tmp_path / "b.h5", "a") as f:
        del f["split"]  # a part of an older version
    concat_h5(tmp_path / "ab.h5", [tmp_path / "a.h5", tmp_path / "b.h5"], fill={"split": "train"}, attrs={"shape_names": ["x"]})
    joined, da, db = read_h5(tmp_path / "ab.h5"), read_h5(tmp_path / "a.h5"), read_h5(tmp_path / "b.h5")
    for key in ("data", "label", "face_index", "source", "object_index", "n_visible", "elevation_deg"):
        assert np.array_equal(joined[key], np.concatenate([da[key], db[key]])), key
    assert list(joined["split"]) == ["train"] * 5 and list(joined["shape_names"]) == ["x"]

    write_h5(tmp_path / "c.h5", [_cloud(n=32)])
    with pytest.raises(OutputError, match="c.h5"):
        concat_h5(tmp_path / "ac.h5", [tmp_path / "a.h5", tmp_path / "c.h5"])
    assert not (tmp_path / "ac.h5").exists() and not list(tmp_path.glob(".ac.h5*"))


# -- read_npz: a cloud file from anyone ----------------------------------------------------------------
def _cloud_arrays(n: int = 8) -> dict[str, np.ndarray]:
    """The arrays write_npz writes for ``_cloud(n)``."""
    path = write_npz(Path(tempfile.mkdtemp()) / "x.npz", _cloud(n))
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def _npz_with(path: Path, **members: np.ndarray | bytes | None) -> Path:
    """A cloud .npz of ``_cloud(8)`` whose members ``members`` are replaced (raw ``.npy`` bytes
    written as given, ``None`` left out)."""
    arrays = _cloud_arrays()
    with zipfile.ZipFile(path, "w") as zf:
        for key in dict.fromkeys([*arrays, *members]):
            value = members.get(key, arrays.get(key))
            if value is None:
                continue
            if not isinstance(value, bytes):
                buf = io.BytesIO()
                np.lib.format.write_array(buf, np.asanyarray(value), allow_pickle=True)
                value = buf.getvalue()
            zf.writestr(f"{key}.npy", value)
    return path


def _forged_npy(shape: tuple[int, ...], descr: str = "<f4") -> bytes:
    """A .npy header declaring ``shape`` over 96 bytes of data."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": descr, "fortran_order": False, "shape": shape})
    return header.getvalue() + bytes(96)


def _refuses(path: Path, message: str) -> None:
    """read_npz raises one DatasetFormatError, one line opening with the file's name, saying ``message``."""
    with pytest.raises(DatasetFormatError, match=message) as info:
        read_npz(path)
    assert str(info.value).startswith(f"{path}:") and "\n" not in str(info.value)


def test_npz_round_trip_of_a_file_without_split_reads_an_empty_split(tmp_path):
    back = read_npz(_npz_with(tmp_path / "old.npz", split=None))
    assert back.split == "" and np.array_equal(back.points, _cloud(8).points)


@pytest.mark.parametrize(
    ("members", "message"),
    [
        ({"label": None}, r"not a cloud of write_npz: no array 'label'"),
        ({"points": None, "source": None}, r"no array 'points', 'source'"),
        ({"points": np.zeros((8, 2), np.float32)}, r"points is declared \(8, 2\), not \(n, 3\)"),
        ({"points": np.zeros(24, np.float32)}, r"points is declared \(24,\) float32, not a \(n, 3\) array of floats"),
        ({"points": np.zeros((8, 3), np.int64)}, r"points is declared \(8, 3\) int64, not a \(n, 3\) array of floats"),
        ({"points": np.array([[None] * 3] * 8, dtype=object)}, r"points is declared \(8, 3\) object"),
        ({"face_index": np.arange(7)}, r"face_index is declared \(7,\), not \(8,\) like points"),
        ({"face_index": np.zeros(8)}, r"face_index is declared \(8,\) float64, not a \(n,\) array of integers"),
        ({"label": np.arange(2)}, r"label is declared \(2,\) int64, not a 0-d array of integers"),
        ({"n_visible": np.float64(3.5)}, r"n_visible is declared \(\) float64, not a 0-d array of integers"),
        ({"elevation_deg": np.str_("high")}, r"elevation_deg is declared \(\) <U4, not a 0-d array of numbers"),
        ({"class_name": np.int64(3)}, r"class_name is declared \(\) int64, not a 0-d array of text"),
        ({"split": np.array({"a": 1}, dtype=object)}, r"split is declared \(\) object, not a 0-d array of text"),
    ],
    ids=["no label", "no points", "points (n, 2)", "points flat", "points ints", "points pickled", "face_index short",
         "face_index floats", "label 1-d", "n_visible float", "elevation text", "class_name number", "split pickled"],
)  # fmt: skip
def test_read_npz_refuses_a_cloud_file_of_another_layout_naming_the_file(tmp_path, members, message):
    _refuses(_npz_with(tmp_path / "bad.npz", **members), message)


@pytest.mark.parametrize(
    ("content", "message"),
    [(b"", "cannot read its array headers"), (b"PK\x03\x04 not a zip", "not a zip file"), (b"\x93NUMPY\x01\x00", "not a zip file"),
     (b"\x80\x04K\x01.", "not a zip file")],
    ids=["empty", "damaged zip", "npy", "pickle"],
)  # fmt: skip
def test_read_npz_refuses_a_file_that_is_not_an_npz_naming_the_file(tmp_path, content, message):
    path = tmp_path / "junk.npz"
    path.write_bytes(content)
    _refuses(path, message)


def test_read_npz_refuses_a_truncated_file(tmp_path):
    path = write_npz(tmp_path / "cut.npz", _cloud())
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    _refuses(path, "cannot read its array headers")


#: A guard, not a measurement: a refusal is immediate, a reader blocked on a FIFO waits forever.
_BLOCKED_SECONDS = 10


def _refuses_without_blocking(path: Path, message: str) -> None:
    """As :func:`_refuses`, in a thread given :data:`_BLOCKED_SECONDS`: a read that blocks fails the test."""
    raised: list[BaseException] = []

    def read() -> None:
        try:
            _refuses(path, message)
        except BaseException as exc:  # noqa: BLE001 - handed to the test's thread
            raised.append(exc)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(_BLOCKED_SECONDS)
    if reader.is_alive():
        with contextlib.suppress(OSError):  # a writer that comes and goes unblocks the reader
            os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
        pytest.fail(f"read_npz({path.name}) blocked for {_BLOCKED_SECONDS} s")
    if raised:
        raise raised[0]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
def test_read_npz_of_a_fifo_is_refused_at_once_naming_the_file(tmp_path):
    os.mkfifo(tmp_path / "cloud.npz")
    _refuses_without_blocking(tmp_path / "cloud.npz", "is a FIFO; only regular files are read")


_READ_IN_CHILD = """
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))
from zbuf_occlude.errors import DatasetFormatError
from zbuf_occlude.io.clouds import read_npz
try:
    read_npz(sys.argv[1])
except DatasetFormatError as exc:
    print("DatasetFormatError:", exc)
"""


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero")
def test_read_npz_of_a_device_is_refused_naming_the_file(tmp_path):
    # In a child under a memory limit: a reader of /dev/zero reads without end (zipfile reads to
    # the end of the file looking for the zip directory), which a thread could not stop.
    (tmp_path / "zero.npz").symlink_to("/dev/zero")
    try:
        done = subprocess.run([sys.executable, "-c", _READ_IN_CHILD, str(tmp_path / "zero.npz")], capture_output=True,
                              text=True, timeout=60, check=False)  # fmt: skip
    except subprocess.TimeoutExpired:
        pytest.fail("read_npz(zero.npz) read /dev/zero for 60 s")
    assert done.stdout.strip() == f"DatasetFormatError: {tmp_path / 'zero.npz'}: is not a regular file; only regular files are read", (
        done.stdout + done.stderr[-2000:]
    )


def _no_inflating(monkeypatch) -> None:
    """From here on, any array numpy reads fails the test: a refusal must come from the headers alone."""

    def read_array(*args, **kwargs):
        raise AssertionError("an array was inflated")

    monkeypatch.setattr(np.lib.format, "read_array", read_array)


def test_read_npz_refuses_a_member_declaring_gigabytes_before_inflating_it(tmp_path, monkeypatch):
    path = _npz_with(tmp_path / "bomb.npz", points=_forged_npy((10**9, 3)))  # 12 GB declared over 96 bytes
    _no_inflating(monkeypatch)
    _refuses(path, r"member \d declares 12,000,000,000 bytes of array but holds 224")


def test_read_npz_refuses_zeros_inflating_past_the_cap_before_inflating_them(tmp_path, monkeypatch):
    import zbuf_occlude.io.clouds as clouds

    path = tmp_path / "zeros.npz"
    np.savez_compressed(
        path, **{**_cloud_arrays(), "points": np.zeros((1_000_000, 3), np.float32), "face_index": np.zeros(1_000_000, np.int64)}
    )
    assert path.stat().st_size < 100_000  # 20 MB inflated
    monkeypatch.setattr(clouds, "MAX_CLOUD_NPZ_BYTES", 1 << 20)  # stands for the 3.2 GB cap
    _no_inflating(monkeypatch)
    _refuses(path, r"its members inflate to 20,00\d,\d+ bytes, more than the 1,048,576 accepted")


def test_the_npz_cap_holds_the_largest_cloud_the_cli_writes():
    from zbuf_occlude.defaults import MAX_POINTS
    from zbuf_occlude.io.caps import MAX_CLOUD_NPZ_BYTES, MAX_CLOUD_NPZ_POINTS

    assert MAX_CLOUD_NPZ_POINTS == MAX_POINTS and MAX_CLOUD_NPZ_BYTES >= MAX_POINTS * (3 * 8 + 8)


_VALID_NPZ = None


def _valid_npz_bytes() -> bytes:
    global _VALID_NPZ
    if _VALID_NPZ is None:
        _VALID_NPZ = write_npz(Path(tempfile.mkdtemp()) / "x.npz", _cloud(8)).read_bytes()
    return _VALID_NPZ


@pytest.mark.slow
@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_read_npz_of_a_damaged_file_raises_dataset_format_error_or_reads_a_valid_cloud(tmp_path, data):
    raw = bytearray(_valid_npz_bytes())
    if data.draw(st.booleans(), label="truncate"):
        raw = raw[: data.draw(st.integers(0, len(raw) - 1), label="length")]
    for _ in range(data.draw(st.integers(0 if len(raw) < len(_valid_npz_bytes()) else 1, 4), label="flips")):
        if raw:
            i = data.draw(st.integers(0, len(raw) - 1), label="at")
            raw[i] ^= data.draw(st.integers(1, 255), label="xor")
    path = tmp_path / "damaged.npz"
    path.write_bytes(bytes(raw))
    try:
        cloud = read_npz(path)
    except DatasetFormatError as exc:
        assert str(exc).startswith(f"{path}:") and "\n" not in str(exc)
        return
    n = len(cloud.points)
    assert cloud.points.shape == (n, 3) and cloud.points.dtype.kind == "f"
    assert cloud.face_index.shape == (n,) and cloud.face_index.dtype.kind in "iu"
    assert all(isinstance(getattr(cloud, k), str) for k in ("class_name", "source", "split"))
