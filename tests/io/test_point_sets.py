"""Point sets from files (io/point_sets.py): PointNet-layout HDF5, .npy and .ply point clouds, and
hostile or damaged files refused in one line naming the file."""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.defaults import MAX_POINT_SET_POINTS
from zbuf_occlude.errors import DatasetFormatError, InsufficientMemoryError, InvalidInputError, UnsafePathError
from zbuf_occlude.io.point_sets import (
    POINT_SET_SUFFIXES,
    PointSet,
    is_point_set_file,
    occlusion_cost,
    point_set_labels,
    read_point_sets,
    shape_names,
    unit_normals,
)

RNG = np.random.default_rng(0)
CLOUDS = RNG.uniform(-1, 1, (3, 64, 3)).astype(np.float32)
NORMALS = RNG.normal(size=(3, 64, 3)).astype(np.float32)


def _pointnet(path: Path, *, labels=((2,), (0,), (1,)), normals: bool = False, **extra) -> Path:
    """A file of ``modelnet40_ply_hdf5_2048``'s layout: data (B, N, 3) float32, label (B, 1) uint8."""
    with h5py.File(path, "w") as f:
        f["data"] = CLOUDS
        if labels is not None:
            f["label"] = np.asarray(labels, dtype=np.uint8)
        if normals:
            f["normal"] = NORMALS
        for key, value in extra.items():
            f[key] = value
    return path


def _ply(path: Path, points: np.ndarray, normals: np.ndarray | None = None, *, binary: bool = True) -> Path:
    names = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else [])
    values = points if normals is None else np.hstack([points, normals])
    header = "\n".join(
        ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", f"element vertex {len(points)}"]
        + [f"property float {n}" for n in names] + ["end_header", ""]
    )  # fmt: skip
    if binary:
        body = values.astype("<f4").tobytes()
    else:
        body = "".join(" ".join(f"{v:.7g}" for v in row) + "\n" for row in values).encode()
    path.write_bytes(header.encode() + body)
    return path


def _one_line_naming(exc: pytest.ExceptionInfo, path: Path) -> None:
    message = str(exc.value)
    assert "\n" not in message and str(path) in message, message


# -- the formats -------------------------------------------------------------------------------------
def test_pointnet_hdf5_gives_every_row_with_its_label_and_class_list(tmp_path):
    path = _pointnet(tmp_path / "ply_data_train0.h5", normals=True)
    (tmp_path / "shape_names.txt").write_text("airplane\nbathtub\n\nbed\n")
    assert POINT_SET_SUFFIXES == (".h5", ".hdf5", ".npy", ".ply")
    assert is_point_set_file(path)
    sets = read_point_sets(path)
    assert [s.name for s in sets] == ["ply_data_train0_0000", "ply_data_train0_0001", "ply_data_train0_0002"]
    assert [s.label for s in sets] == [2, 0, 1] == point_set_labels(path)
    assert all(isinstance(s, PointSet) and s.points.dtype == np.float64 for s in sets)
    assert np.array_equal(sets[1].points, CLOUDS[1].astype(np.float64))
    expected = NORMALS[1] / np.linalg.norm(NORMALS[1].astype(np.float64), axis=1, keepdims=True)
    assert np.allclose(sets[1].normals, expected) and np.allclose(np.linalg.norm(sets[1].normals, axis=1), 1.0)
    assert shape_names(path) == ["airplane", "bathtub", "bed"]
    (row,) = read_point_sets(path, rows=[2])
    assert row.name == "ply_data_train0_0002" and np.array_equal(row.points, sets[2].points)


def test_shapenetpart_hdf5_ignores_pid_and_reads_its_category_list(tmp_path):
    path = _pointnet(tmp_path / "ply_data_val0.hdf5", labels=[[0], [1], [1]], pid=np.zeros((3, 64), np.uint8))
    (tmp_path / "all_object_categories.txt").write_text("Airplane\t02691156\nBag\t02773838\n")
    sets = read_point_sets(path)
    assert [s.label for s in sets] == [0, 1, 1] and sets[0].normals is None
    assert shape_names(path) == ["Airplane", "Bag"]


def test_hdf5_of_six_columns_and_flat_labels(tmp_path):
    with h5py.File(tmp_path / "x.h5", "w") as f:
        f["data"] = np.concatenate([CLOUDS, NORMALS], axis=2)
        f["label"] = np.array([4, 5, 6], dtype=np.int64)  # zbuf_occlude's own shards: (B,)
    (a, b, c) = read_point_sets(tmp_path / "x.h5")
    assert (a.label, c.label) == (4, 6) and np.allclose(b.points, CLOUDS[1]) and b.normals.shape == (64, 3)
    assert shape_names(tmp_path / "x.h5") is None


def test_hdf5_without_labels(tmp_path):
    path = _pointnet(tmp_path / "clouds.h5", labels=None)
    assert point_set_labels(path) == [None, None, None]
    assert [s.label for s in read_point_sets(path)] == [None] * 3


@pytest.mark.parametrize("columns", [3, 6])
def test_npy_of_points_or_points_and_normals(tmp_path, columns):
    array = np.hstack([CLOUDS[0], NORMALS[0]])[:, :columns].astype(np.float64)
    np.save(tmp_path / "chair_0001.npy", array)
    (s,) = read_point_sets(tmp_path / "chair_0001.npy")
    assert s.name == "chair_0001" and s.label is None and np.array_equal(s.points, array[:, :3])
    assert (s.normals is None) == (columns == 3)
    assert is_point_set_file(tmp_path / "chair_0001.npy") and point_set_labels(tmp_path / "chair_0001.npy") == [None]
    assert shape_names(tmp_path / "chair_0001.npy") is None


@pytest.mark.parametrize("binary", [True, False])
def test_ply_point_cloud_with_and_without_normals(tmp_path, binary):
    with_normals = _ply(tmp_path / "a.ply", CLOUDS[0], NORMALS[0], binary=binary)
    (s,) = read_point_sets(with_normals)
    assert s.name == "a" and np.allclose(s.points, CLOUDS[0], atol=1e-6)
    assert np.allclose(s.normals, NORMALS[0] / np.linalg.norm(NORMALS[0], axis=1, keepdims=True), atol=1e-5)
    (bare,) = read_point_sets(_ply(tmp_path / "b.ply", CLOUDS[1], binary=binary))
    assert bare.normals is None and len(bare.points) == 64
    assert is_point_set_file(with_normals)


def test_a_ply_mesh_is_no_point_set(tmp_path):
    path = tmp_path / "box.ply"
    trimesh.creation.box().export(path)
    assert not is_point_set_file(path)
    with pytest.raises(InvalidInputError, match="a mesh .12 faces.") as exc:
        read_point_sets(path)
    _one_line_naming(exc, path)


def test_what_is_no_point_set_file(tmp_path):
    (tmp_path / "notes.h5").write_text("not HDF5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["points"] = CLOUDS
    with h5py.File(tmp_path / "flat.h5", "w") as f:
        f["data"] = CLOUDS[0]  # (N, 3): no batch of clouds
    (tmp_path / "cloud.xyz").write_text("0 0 0\n")
    for name in ("notes.h5", "other.h5", "flat.h5", "cloud.xyz", "missing.npy"):
        assert not is_point_set_file(tmp_path / name), name
    os.mkfifo(tmp_path / "fifo.npy")  # would block a reader
    assert not is_point_set_file(tmp_path / "fifo.npy")
    with pytest.raises(InvalidInputError, match="not a regular file|FIFO") as exc:
        read_point_sets(tmp_path / "fifo.npy")
    _one_line_naming(exc, tmp_path / "fifo.npy")


# -- hostile and damaged files -----------------------------------------------------------------------
def _secret(folder: Path) -> Path:
    folder.mkdir()
    with h5py.File(folder / "secret.h5", "w") as f:
        f["data"] = np.full((3, 64, 3), 7, dtype=np.float32)
    (folder / "secret.bin").write_bytes(np.full(3 * 64 * 3, 7, dtype=np.float32).tobytes())
    return folder


@pytest.mark.parametrize("how", ["external link", "external link ../", "virtual dataset", "external storage", "soft link"])
def test_hdf5_that_points_elsewhere_is_refused(tmp_path, how):
    secret = _secret(tmp_path / "elsewhere")
    (tmp_path / "set").mkdir()
    path = tmp_path / "set" / "ply_data_train0.h5"
    with h5py.File(path, "w") as f:
        f["label"] = np.zeros((3, 1), np.uint8)
        if how == "external link":
            f["data"] = h5py.ExternalLink(str(secret / "secret.h5"), "/data")
        elif how == "external link ../":
            f["data"] = h5py.ExternalLink("../elsewhere/secret.h5", "/data")
        elif how == "virtual dataset":
            layout = h5py.VirtualLayout(shape=(3, 64, 3), dtype=np.float32)
            layout[:] = h5py.VirtualSource(str(secret / "secret.h5"), "data", shape=(3, 64, 3))
            f.create_virtual_dataset("data", layout)
        elif how == "external storage":
            f.create_dataset("data", shape=(3, 64, 3), dtype=np.float32, external=[(str(secret / "secret.bin"), 0, 3 * 64 * 12)])
        else:
            f["points"] = CLOUDS
            f["data"] = h5py.SoftLink("/points")
    assert is_point_set_file(path)  # it names 'data': the reader says why it is refused
    for read in (read_point_sets, point_set_labels):
        with pytest.raises(DatasetFormatError, match="refused") as exc:
            read(path)
        _one_line_naming(exc, path)


def _write(path: Path, what) -> Path:
    if path.suffix == ".npy":
        np.save(path, what, allow_pickle=True)
    elif path.suffix == ".ply":
        path.write_bytes(what)
    else:
        with h5py.File(path, "w") as f:
            for key, value in what.items():
                f[key] = value
    return path


NAN = CLOUDS.copy()
NAN[1, 5, 2] = np.nan
BAD = [
    ("nan.h5", {"data": NAN, "label": np.zeros((3, 1), np.uint8)}, "1 points have NaN or inf"),
    ("inf.npy", np.array([[0.0, 0.0, np.inf], [1.0, 0.0, 0.0]]), "NaN or inf"),
    ("four.npy", np.zeros((5, 4)), r"not \(N, 3\) or \(N, 6\)"),
    ("batch.npy", np.zeros((2, 5, 3)), r"not \(N, 3\) or \(N, 6\)"),
    ("pickle.npy", np.array([{"x": 1}], dtype=object), "object"),
    ("empty.npy", np.zeros((0, 3)), "no points"),
    ("zero_normals.npy", np.hstack([CLOUDS[0], np.zeros((64, 3), np.float32)]), "normals are zero"),
    ("two.h5", {"data": CLOUDS[:, :, :2]}, r"not \(B, N, 3\)"),
    ("ints.h5", {"data": CLOUDS.astype(np.int32)}, r"not \(B, N, 3\)"),
    ("no_data.h5", {"points": CLOUDS}, "no 'data' dataset"),
    ("label_shape.h5", {"data": CLOUDS, "label": np.zeros((2, 1), np.uint8)}, "'label' is"),
    ("label_float.h5", {"data": CLOUDS, "label": np.zeros(3, np.float32)}, "'label' is"),
    ("negative.h5", {"data": CLOUDS, "label": np.array([0, -1, 2])}, "negative"),
    ("normal_shape.h5", {"data": CLOUDS, "normal": NORMALS[:, :10]}, "'normal' is"),
    ("none.h5", {"data": np.zeros((0, 64, 3), np.float32)}, "no clouds"),
    ("cut.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nproperty float y\n"
                b"property float z\nend_header\n" + bytes(40), "cannot read as a PLY"),
    ("no_header.ply", b"ply\nformat ascii 1.0\n" + b"0 0 0\n" * 10, "not a PLY file"),
    ("no_vertices.ply", b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nend_header\n", "declares no vertices"),
]  # fmt: skip


@pytest.mark.parametrize(("name", "what", "message"), BAD, ids=[b[0] for b in BAD])
def test_damaged_files_get_one_line_naming_the_file(tmp_path, name, what, message):
    path = _write(tmp_path / name, what)
    with pytest.raises(InvalidInputError, match=message) as exc:
        read_point_sets(path)
    _one_line_naming(exc, path)


def test_absurd_sizes_are_refused_from_headers(tmp_path):
    np.save(tmp_path / "big.npy", np.zeros((100, 3)))
    with pytest.raises(InvalidInputError, match="100 points, more than the 99") as exc:
        read_point_sets(tmp_path / "big.npy", max_points=99)
    _one_line_naming(exc, tmp_path / "big.npy")
    # a header declaring far more than the file holds: refused before anything is read
    with open(tmp_path / "lie.npy", "wb") as fh:
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f8", "fortran_order": False, "shape": (10**10, 3)})
        fh.write(bytes(24))
    with pytest.raises(InvalidInputError, match="declares 240,000,000,000 bytes") as exc:
        read_point_sets(tmp_path / "lie.npy")
    _one_line_naming(exc, tmp_path / "lie.npy")
    _pointnet(tmp_path / "wide.h5")
    with pytest.raises(InvalidInputError, match="64 points each, more than the 10") as exc:
        read_point_sets(tmp_path / "wide.h5", max_points=10)
    _one_line_naming(exc, tmp_path / "wide.h5")
    ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\nproperty float x\nend_header\n"
    (tmp_path / "huge.ply").write_bytes(ply)
    with pytest.raises(InvalidInputError, match="declares 99,999,999,999 points") as exc:
        read_point_sets(tmp_path / "huge.ply")
    _one_line_naming(exc, tmp_path / "huge.ply")
    with h5py.File(tmp_path / "sparse.h5", "w") as f:  # declares 10^12 rows, stores none (chunks never written)
        f.create_dataset("data", shape=(10**12, 64, 3), dtype=np.float32, chunks=(1, 64, 3))
    with pytest.raises(DatasetFormatError, match=r"declares shape \(1000000000000, 64, 3\).*stores 0 bytes") as exc:
        point_set_labels(tmp_path / "sparse.h5")
    _one_line_naming(exc, tmp_path / "sparse.h5")


@pytest.mark.parametrize("chunks", [None, (1, 2048, 3)])
def test_a_point_set_that_declares_what_it_does_not_store_is_refused(tmp_path, chunks):
    """(100000, 2048, 3) declared in a file of a few kB, data never written: no plan of 100,000 objects."""
    path = tmp_path / "empty.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("data", shape=(100_000, 2048, 3), dtype=np.float32, chunks=chunks)
        f["label"] = np.zeros((100_000, 1), np.int64)
    assert path.stat().st_size < 1_000_000
    with pytest.raises(DatasetFormatError, match=r"'/data' declares shape \(100000, 2048, 3\).*stores 0 bytes") as exc:
        point_set_labels(path)
    _one_line_naming(exc, path)


def test_a_compressed_point_set_that_stores_its_data_is_read(tmp_path):
    """The stored-size check leaves real compression alone: zeros compress about 1000:1 under gzip."""
    path = tmp_path / "zeros.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("data", data=np.zeros((64, 2048, 3), np.float32), compression="gzip", compression_opts=9)
        f["label"] = np.zeros((64, 1), np.int64)
    assert len(point_set_labels(path)) == 64


def test_bad_arguments(tmp_path):
    path = _pointnet(tmp_path / "x.h5")
    with pytest.raises(InvalidInputError, match="row 3 out of range; the file holds 3 clouds"):
        read_point_sets(path, rows=[3])
    with pytest.raises(InvalidInputError, match="max_points"):
        read_point_sets(path, max_points=0)
    with pytest.raises(InvalidInputError, match="not a point-set file") as exc:
        read_point_sets(tmp_path / "x.txt")
    _one_line_naming(exc, tmp_path / "x.txt")
    with pytest.raises(InvalidInputError, match="cannot read file") as exc:
        read_point_sets(tmp_path / "missing.npy")
    _one_line_naming(exc, tmp_path / "missing.npy")


def test_a_class_list_that_is_not_text(tmp_path):
    path = _pointnet(tmp_path / "x.h5")
    (tmp_path / "shape_names.txt").write_bytes(b"chair\n\xff\xfe\n")
    with pytest.raises(InvalidInputError, match="not UTF-8") as exc:
        shape_names(path)
    _one_line_naming(exc, tmp_path / "shape_names.txt")


# -- a hostile shared folder: the class list, declared sizes, normals, headers ------------------------
def test_a_class_list_that_links_out_of_the_folder_is_refused_not_read(tmp_path):
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "secret.txt").write_text("SECRET_A\nSECRET_B\nSECRET_C\n")
    (tmp_path / "set").mkdir()
    path = _pointnet(tmp_path / "set" / "x.h5")
    os.symlink(tmp_path / "elsewhere" / "secret.txt", tmp_path / "set" / "shape_names.txt")
    with pytest.raises(UnsafePathError, match="leads outside") as exc:
        shape_names(path)
    _one_line_naming(exc, tmp_path / "set" / "shape_names.txt")
    assert "SECRET" not in str(exc.value)
    (tmp_path / "set" / "shape_names.txt").unlink()  # a FIFO would block: refused at once, not passed over
    os.mkfifo(tmp_path / "set" / "shape_names.txt")
    with pytest.raises(InvalidInputError, match="FIFO") as exc:
        shape_names(path)
    _one_line_naming(exc, tmp_path / "set" / "shape_names.txt")


@pytest.mark.parametrize("name", ["../../etc", "a/b", "..", "a\\b"])
def test_a_class_name_that_is_no_plain_name_is_refused(tmp_path, name):
    path = _pointnet(tmp_path / "x.h5")
    (tmp_path / "shape_names.txt").write_text(f"chair\n{name}\n")
    with pytest.raises(InvalidInputError, match="not a plain name") as exc:
        shape_names(path)
    _one_line_naming(exc, tmp_path / "shape_names.txt")


@pytest.mark.parametrize(
    ("normal", "said"),
    [((0.0, 0.0, 0.0), "are zero"), ((-0.0, 0.0, -0.0), "are zero"), ((np.inf, 0.0, 0.0), "hold NaN or inf"),
     ((1.0, np.nan, 0.0), "hold NaN or inf")],
    ids=["zero", "minus zero", "inf", "nan"],
)  # fmt: skip
def test_normals_that_cannot_be_made_unit_are_refused_naming_the_row(tmp_path, normal, said):
    normals = np.tile([0.0, 0.0, 1.0], (64, 1))
    normals[7] = normal
    np.save(tmp_path / "c.npy", np.hstack([CLOUDS[0], normals]))
    with pytest.raises(InvalidInputError, match=f"1 normals {said}, first row 7;") as exc:
        read_point_sets(tmp_path / "c.npy")
    _one_line_naming(exc, tmp_path / "c.npy")


@pytest.mark.parametrize("length", [1e300, 1e-300, 1e154, 1e-154, float(np.finfo(np.float64).max), 5e-324])
def test_a_long_or_short_normal_is_a_direction_like_any_other(tmp_path, length):
    """A normal of length 1e300 overflowed to a length of inf and divided to 0 (seen from everywhere);
    one of 1e-300 underflowed to 0: both were refused although float64 holds them."""
    normals = np.tile([0.0, 0.0, 1.0], (64, 1))
    normals[7] = (length, -length, 0.0)
    np.save(tmp_path / "c.npy", np.hstack([CLOUDS[0], normals]))
    (cloud,) = read_point_sets(tmp_path / "c.npy")
    assert np.allclose(cloud.normals[7], [2**-0.5, -(2**-0.5), 0.0], rtol=0, atol=4 * EPS)
    assert np.array_equal(cloud.normals[np.arange(64) != 7], normals[np.arange(64) != 7])


#: float64's machine epsilon: the rounding of one division and one square root, a few of which make a unit normal.
EPS = float(np.finfo(np.float64).eps)
#: Lengths to scale a direction to: every finite positive float64, subnormals included (hypothesis draws the
#: exponent's ends as well as the middle).
LENGTHS = st.floats(min_value=float(np.finfo(np.float64).smallest_subnormal), max_value=float(np.finfo(np.float64).max),
                    allow_nan=False, allow_infinity=False)  # fmt: skip


@settings(max_examples=300, deadline=None)
@given(
    direction=st.tuples(*[st.floats(-1, 1, allow_nan=False, allow_subnormal=False)] * 3).filter(lambda d: max(map(abs, d)) > 0.25),
    length=LENGTHS,
)
def test_a_normal_of_any_finite_length_gives_the_unit_normal_of_its_direction(direction, length):
    """The law: unit_normals(d * s) is d / |d| for every scale s from the smallest positive float64 to the
    largest, as long as d * s holds d's direction (its largest component a normal float64)."""
    d = np.asarray(direction, dtype=np.float64)
    scaled = d / np.abs(d).max() * length  # the largest component ±length; the others at most that
    expected = d / np.linalg.norm(d)
    (got,) = unit_normals(scaled[None], what="n")
    # a few roundings of eps each; a component that fell to a subnormal lost up to half the smallest subnormal
    # on the way, which the division by the largest (length) magnifies
    subnormal_loss = float(np.finfo(np.float64).smallest_subnormal) / length
    assert np.allclose(got, expected, rtol=0, atol=8 * EPS + subnormal_loss)
    assert abs(np.linalg.norm(got) - 1) <= 4 * EPS


@settings(max_examples=200, deadline=None)
@given(length=LENGTHS, axis=st.integers(0, 2), sign=st.sampled_from([-1.0, 1.0]))
def test_a_normal_along_an_axis_of_any_finite_length_is_that_axis(length, axis, sign):
    normal = np.zeros((1, 3))
    normal[0, axis] = sign * length
    expected = np.zeros((1, 3))
    expected[0, axis] = sign
    assert np.array_equal(unit_normals(normal, what="n"), expected)


def test_a_read_that_would_exhaust_memory_is_refused_before_it_allocates(tmp_path, monkeypatch):
    from zbuf_occlude import resources

    big = np.random.default_rng(2).random((2, 3000, 3)).astype(np.float32)
    with h5py.File(tmp_path / "big.h5", "w") as f:
        f["data"] = big
        f["label"] = np.zeros((2, 1), np.uint8)
        f["normal"] = big + 1.0
    np.save(tmp_path / "big.npy", big[0])
    trimesh.PointCloud(big[0]).export(tmp_path / "big.ply")
    monkeypatch.setattr(resources, "available_memory", lambda: (2**16, "test budget"))
    monkeypatch.setattr(resources, "MIN_CHECKED_BYTES", 0)  # small files, a smaller budget
    for name, said in (("big.h5", "2 clouds of 3,000 points"), ("big.npy", "1 cloud of 3,000 points"), ("big.ply", "3,000 points")):
        with pytest.raises(InsufficientMemoryError, match=said) as exc:
            read_point_sets(tmp_path / name)
        _one_line_naming(exc, tmp_path / name)
    monkeypatch.undo()
    assert len(read_point_sets(tmp_path / "big.h5")) == 2


def test_labels_of_more_clouds_than_memory_holds_are_refused_before_they_are_read(tmp_path, monkeypatch):
    from zbuf_occlude import resources

    with h5py.File(tmp_path / "rows.h5", "w") as f:
        f["data"] = np.zeros((20_000, 1, 3), np.float32)
        f["label"] = np.zeros((20_000, 1), np.uint8)
    monkeypatch.setattr(resources, "available_memory", lambda: (2**16, "test budget"))
    monkeypatch.setattr(resources, "MIN_CHECKED_BYTES", 0)  # a small file, a smaller budget
    with pytest.raises(InsufficientMemoryError, match="20,000 clouds") as exc:
        point_set_labels(tmp_path / "rows.h5")
    _one_line_naming(exc, tmp_path / "rows.h5")


def test_a_ply_header_with_a_count_python_cannot_parse_is_refused(tmp_path):
    """Python refuses integers of over 4,300 digits with a ValueError: named here, and no point set."""
    path = tmp_path / "huge.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex " + b"9" * 5000 + b"\nproperty float x\nend_header\n0\n")
    assert not is_point_set_file(path)
    with pytest.raises(InvalidInputError, match="a count of 5,000 digits") as exc:
        read_point_sets(path)
    _one_line_naming(exc, path)


def test_an_npy_is_read_from_the_file_its_header_was_checked_in(tmp_path):
    """Fortran order and a big-endian dtype are read as numpy writes them, through the one open file."""
    array = np.asfortranarray(CLOUDS[0].astype(">f8"))
    np.save(tmp_path / "f.npy", array)
    (cloud,) = read_point_sets(tmp_path / "f.npy")
    assert np.array_equal(cloud.points, CLOUDS[0].astype(np.float64))
    np.save(tmp_path / "short.npy", CLOUDS[0])
    (tmp_path / "short.npy").write_bytes((tmp_path / "short.npy").read_bytes()[:-40])  # its body cut short
    with pytest.raises(InvalidInputError, match="cannot read as a NPY") as exc:
        read_point_sets(tmp_path / "short.npy")
    _one_line_naming(exc, tmp_path / "short.npy")


# -- the cap on a cloud's points ---------------------------------------------------------------------
def _write_cloud(path: Path, n: int) -> Path:
    """A cloud of ``n`` points (float32) in the format of ``path``'s suffix."""
    points = np.random.default_rng(n).uniform(-1, 1, (n, 3)).astype(np.float32)
    if path.suffix == ".npy":
        np.save(path, points)
    elif path.suffix == ".ply":
        _ply(path, points)
    else:
        with h5py.File(path, "w") as f:
            f["data"] = points[None]
    return path


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 40), cap=st.integers(1, 40), suffix=st.sampled_from([".npy", ".ply", ".h5"]))
def test_a_cloud_is_read_up_to_the_cap_and_refused_beyond_it_naming_what_occluding_it_needs(tmp_path_factory, n, cap, suffix):
    path = _write_cloud(tmp_path_factory.mktemp("cap") / f"cloud{suffix}", n)
    if n <= cap:
        assert len(read_point_sets(path, max_points=cap)[0].points) == n
        assert len(point_set_labels(path, max_points=cap)) == 1
        return
    memory, prepare_s, pose_s = occlusion_cost(n)
    for read in (read_point_sets, point_set_labels):
        with pytest.raises(InvalidInputError) as exc:
            read(path, max_points=cap)
        _one_line_naming(exc, path)
        message = str(exc.value)
        assert f"{n:,} points" in message and f"more than the {cap:,} accepted" in message, message
        assert f"needs about {memory / 2**30:.1f} GiB of memory and, on two cores, {prepare_s:.0f} s plus {pose_s:.1f} s a pose" in message
        assert message.endswith(f"subsample the cloud to at most {cap:,} points"), message


@given(n=st.integers(0, 10**8))
def test_what_occluding_a_cloud_costs_grows_in_step_with_its_points(n):
    # affine in the points: memory from the job's fixed part, the times from nothing
    none, some, twice = occlusion_cost(0), occlusion_cost(n), occlusion_cost(2 * n)
    assert none[0] > 0 and none[1:] == (0.0, 0.0)
    for zero, one, two in zip(none, some, twice, strict=True):
        assert two - one == pytest.approx(one - zero) and one >= zero


def test_a_cloud_beyond_the_default_cap_is_refused_from_its_header_before_its_values_are_read(tmp_path, monkeypatch):
    """The held-out case: one cloud of 9.9 million points, gzip making the file small, refused by
    the header before any value is read (``generate``'s plan reads labels with point_set_labels)."""
    big = 9_900_000
    assert big > MAX_POINT_SET_POINTS
    path = tmp_path / "scan.h5"
    with h5py.File(path, "w") as f:  # 119 MB of float32 values in 0.5 MB: a regular pattern compresses
        data = f.create_dataset("data", shape=(1, big, 3), dtype=np.float32, compression="gzip", compression_opts=1, chunks=(1, 1 << 20, 3))
        for start in range(0, big, 1 << 20):
            data[0, start : start + (1 << 20)] = 0.5
        f["label"] = np.zeros((1, 1), np.uint8)
    npy = tmp_path / "scan.npy"  # a header of cap + 1 points, the values a hole in a sparse file
    with open(npy, "wb") as fh:
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f4", "fortran_order": False, "shape": (MAX_POINT_SET_POINTS + 1, 3)})
        fh.truncate(fh.tell() + (MAX_POINT_SET_POINTS + 1) * 12)
    reads = []
    dataset_read = h5py.Dataset.__getitem__
    monkeypatch.setattr(h5py.Dataset, "__getitem__", lambda self, key: reads.append(self.name) or dataset_read(self, key))
    monkeypatch.setattr(np.lib.format, "read_array", lambda *a, **k: reads.append("npy") or pytest.fail("the values were read"))
    for file, n in ((path, big), (npy, MAX_POINT_SET_POINTS + 1)):
        for read in (point_set_labels, read_point_sets):
            with pytest.raises(
                InvalidInputError, match=rf"{n:,} points.*more than the {MAX_POINT_SET_POINTS:,} accepted; occluding"
            ) as exc:
                read(file)
            _one_line_naming(exc, file)
    assert "/data" not in reads and "npy" not in reads, reads
    with open(npy, "r+b") as fh:  # the cap itself is accepted
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f4", "fortran_order": False, "shape": (MAX_POINT_SET_POINTS, 3)})
        fh.truncate(fh.tell() + MAX_POINT_SET_POINTS * 12)
    assert point_set_labels(npy) == [None]
