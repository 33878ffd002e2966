"""Array headers of .npy/.npz files from anyone: read before a byte of array is inflated."""

from __future__ import annotations

import io
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.errors import InvalidInputError, MeshLoadError, UnsafePathError
from zbuf_occlude.io.arrays import check_array_sizes, load_npy, load_npz, npy_header, npz_member_header


def _forged_npz(path: Path, shape: tuple[int, ...], descr: str = "<f8", payload: bytes = b"\x00" * 72) -> Path:
    """A zip whose ``points.npy`` header declares ``shape`` over a few bytes of data."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": descr, "fortran_order": False, "shape": shape})
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("points.npy", header.getvalue() + payload)
    return path


def test_a_member_header_gives_the_declared_shape_and_dtype_without_inflating(tmp_path):
    path = _forged_npz(tmp_path / "forged.npz", (10**9, 3))  # 24 GB declared, 72 bytes held
    with zipfile.ZipFile(path) as zf:
        assert npz_member_header(zf, "points") == ((10**9, 3), np.dtype("<f8"))


def test_a_member_header_of_a_written_file_matches_its_array(tmp_path):
    np.savez_compressed(tmp_path / "x.npz", points=np.zeros((7, 3), np.float32), face_index=np.arange(7))
    with np.load(tmp_path / "x.npz", allow_pickle=False) as z:
        assert npz_member_header(z.zip, "points") == ((7, 3), np.dtype(np.float32))
        assert npz_member_header(z.zip, "face_index") == ((7,), np.dtype(np.int64))
        with pytest.raises(KeyError):
            npz_member_header(z.zip, "normal")


def test_a_header_of_a_format_version_numpy_does_not_read_is_refused():
    with pytest.raises(ValueError, match="version 9.0"):
        npy_header(io.BytesIO(b"\x93NUMPY\x09\x00" + b"\x00" * 16))


@pytest.mark.parametrize("error", [InvalidInputError, MeshLoadError])
def test_check_array_sizes_raises_the_callers_error_naming_the_file(tmp_path, error):
    path = _forged_npz(tmp_path / "forged.npz", (10**9, 3))
    with pytest.raises(error, match=r"forged\.npz: member 1 declares 24,000,000,000 bytes of array but holds 200"):
        check_array_sizes(path, max_bytes=1 << 40, error=error)
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 not a zip")
    with pytest.raises(error, match=r"junk\.npz: cannot read its array headers \(not a zip file, or a damaged one\)"):
        check_array_sizes(tmp_path / "junk.npz", max_bytes=1 << 20, error=error)


def _damaged(path: Path, how: str) -> Path:
    """A one-member .npz damaged as ``how`` says, its zip directory intact."""
    data = io.BytesIO()
    np.lib.format.write_array(data, np.arange(4096.0))
    info = zipfile.ZipInfo("points.npy")
    info.compress_type = zipfile.ZIP_DEFLATED
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr(info, data.getvalue())
    raw = bytearray(path.read_bytes())
    if how == "deflate":
        start = 30 + len("points.npy")  # the member's data, after its local header
        raw[start : start + 8] = b"\xff" * 8
    else:  # a field of the local header and the central directory: flags, or compression method
        central, at = zipfile.ZipFile(path).start_dir, {"encrypted": 6, "method": 8}[how]
        raw[at : at + 2] = raw[central + at + 2 : central + at + 4] = (1 if how == "encrypted" else 99).to_bytes(2, "little")
    path.write_bytes(bytes(raw))
    return path


@pytest.mark.parametrize(
    ("how", "said"),
    [("deflate", r"cannot read its array headers \(error from the parser"), ("encrypted", r"cannot read its array headers \(RuntimeError from the parser"),
     ("method", r"member 1 is compressed with zip method 99; only stored or deflated members")],
)  # fmt: skip
def test_check_array_sizes_names_the_file_of_a_damaged_zip(tmp_path, how, said):
    path = _damaged(tmp_path / "damaged.npz", how)
    with pytest.raises(InvalidInputError, match=rf"^{path}: {said}"):
        check_array_sizes(path, max_bytes=1 << 20, error=InvalidInputError)


def _lying_npz(path: Path, *, method: int = zipfile.ZIP_STORED, inflated: int | None = None, beyond: bool = False) -> Path:
    """A .npz of one honest (1000, 3) float64 member whose zip directory (and local header) then
    claims about ``inflated`` bytes once inflated (its .npy header declares as much array, so that
    numpy would allocate what the zip claims), and as many stored when ``beyond``."""
    header = io.BytesIO()
    rows = ((inflated or 0) - 128) // 24 if inflated else 1000
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (rows, 3)})
    with zipfile.ZipFile(path, "w", compression=method) as zf:
        zf.writestr("points.npy", header.getvalue() + np.zeros((1000, 3)).tobytes())
    raw = bytearray(path.read_bytes())
    for signature, sizes_at in ((b"PK\x03\x04", 18), (b"PK\x01\x02", 20)):  # compressed size, then inflated size
        at = raw.find(signature) + sizes_at
        old_compressed, old_inflated = struct.unpack_from("<II", raw, at)
        claimed = len(header.getvalue()) + rows * 24 if inflated else old_inflated
        struct.pack_into("<II", raw, at, claimed if beyond else old_compressed, claimed)
    path.write_bytes(bytes(raw))
    return path


#: Bytes the lying members claim: more than a test child's address-space headroom (1.5 GiB), less than 4 GiB (no zip64).
_CLAIMED = 2_100_000_000


@pytest.mark.parametrize(
    ("kind", "said"),
    [("stored", r"member 1 declares [\d,]+ bytes inflated from [\d,]+, more than its compression can hold"),
     ("deflated", r"member 1 declares [\d,]+ bytes inflated from [\d,]+, more than its compression can hold"),
     ("beyond the file", r"its members declare [\d,]+ bytes of data in a file of [\d,]+; the file is damaged or forged")],
)  # fmt: skip
def test_a_member_claiming_more_than_the_file_can_hold_is_refused_before_numpy_allocates_it(tmp_path, kind, said):
    # numpy allocates a header's whole array before it reads a byte: a few hundred bytes claiming 2 GB would reserve 2 GB
    lie = {"stored": {"inflated": _CLAIMED}, "deflated": {"method": zipfile.ZIP_DEFLATED, "inflated": _CLAIMED},
           "beyond the file": {"inflated": _CLAIMED, "beyond": True}}[kind]  # fmt: skip
    path = _lying_npz(tmp_path / "lying.npz", **lie)
    for read in (lambda: check_array_sizes(path, max_bytes=1 << 32), lambda: load_npz(path, max_bytes=1 << 32)):
        with pytest.raises(InvalidInputError, match=rf"^{path}: {said}"):
            read()


@pytest.mark.slow
def test_a_lying_npz_is_refused_in_one_line_under_an_address_space_limit(tmp_path):
    # under prlimit --as numpy's allocation of the claimed 2 GB was a MemoryError, not the file's error
    from memory_limit import run_python_limited

    path = _lying_npz(tmp_path / "lying.npz", inflated=_CLAIMED)
    done = run_python_limited(
        "from zbuf_occlude.errors import InvalidInputError\nfrom zbuf_occlude.io.arrays import load_npz\n"
        f"try:\n    load_npz({str(path)!r}, max_bytes=1 << 32)\nexcept InvalidInputError as exc:\n    print(exc)"
    )
    assert done.returncode == 0 and done.stdout.startswith(f"{path}: member 1 declares"), done.stderr[-2000:]


def test_a_deflated_member_of_zeros_inflating_near_deflates_limit_is_read(tmp_path):
    # the bound is deflate's own (about 1032:1): savez_compressed's most compressible member stays readable
    np.savez_compressed(tmp_path / "zeros.npz", points=np.zeros((400_000, 3)))
    member = zipfile.ZipFile(tmp_path / "zeros.npz").getinfo("points.npy")
    assert member.file_size > 900 * member.compress_size
    assert load_npz(tmp_path / "zeros.npz", max_bytes=1 << 30)["points"].shape == (400_000, 3)


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="needs os.mkfifo")
@pytest.mark.parametrize("name", ["pipe.npz", "pipe.npy"])
def test_check_array_sizes_refuses_a_fifo_before_reading_it(tmp_path, name):
    # zipfile and numpy would wait for a writer forever; every reader of arrays relies on this check
    import os

    os.mkfifo(tmp_path / name)
    with pytest.raises(InvalidInputError, match=rf"{name}: is a FIFO; only regular files are read"):
        check_array_sizes(tmp_path / name, max_bytes=1 << 20, error=InvalidInputError)


# -- load_npy, load_npz: the one way to load arrays from anyone ---------------------------------
def test_load_npy_and_load_npz_read_what_numpy_wrote(tmp_path):
    points = np.arange(12, dtype=np.float32).reshape(4, 3)
    np.save(tmp_path / "p.npy", points)
    np.savez_compressed(tmp_path / "p.npz", points=points, face_index=np.arange(4))
    loaded = load_npy(tmp_path / "p.npy", max_bytes=1 << 20)
    assert loaded.dtype == np.float32 and np.array_equal(loaded, points)
    arrays = load_npz(tmp_path / "p.npz", max_bytes=1 << 20)
    assert list(arrays) == ["points", "face_index"] and np.array_equal(arrays["points"], points)
    assert list(load_npz(tmp_path / "p.npz", max_bytes=1 << 20, keys=("face_index", "normal"))) == ["face_index"]


def test_load_npy_refuses_a_header_declaring_more_than_the_file_before_allocating(tmp_path):
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**9, 3)})
    (tmp_path / "forged.npy").write_bytes(header.getvalue() + b"\x00" * 72)
    with pytest.raises(InvalidInputError, match=r"forged\.npy: its header declares 24,000,000,000 bytes of array, more than the file"):
        load_npy(tmp_path / "forged.npy", max_bytes=1 << 40)


def test_load_npz_asks_check_with_the_declared_shapes_before_inflating(tmp_path):
    path = _forged_npz(tmp_path / "forged.npz", (3, 3))  # 72 bytes declared, 72 held: passes the size checks
    seen = []

    def check(declared):
        seen.append(declared)
        raise MeshLoadError("refused by the caller")

    with pytest.raises(MeshLoadError, match="refused by the caller"):
        load_npz(path, max_bytes=1 << 20, check=check)
    assert seen == [{"points": ((3, 3), np.dtype("<f8"))}]


@pytest.mark.parametrize("suffix", [".npy", ".npz"])
def test_loading_never_unpickles(tmp_path, suffix):
    objects = np.array([{"a": 1}], dtype=object)
    path = tmp_path / f"objects{suffix}"
    if suffix == ".npy":
        np.save(path, objects, allow_pickle=True)
    else:
        np.savez(path, points=objects)
    load = load_npy if suffix == ".npy" else load_npz
    with pytest.raises(
        InvalidInputError, match=rf"^{path}: cannot read its arrays? \(it holds pickled Python objects, which are never loaded\)$"
    ):
        load(path, max_bytes=1 << 20)


@pytest.mark.parametrize("how", ["deflate", "encrypted", "method"])
def test_load_npz_names_the_file_of_a_damaged_zip_in_one_line(tmp_path, how):
    path = _damaged(tmp_path / "damaged.npz", how)
    with pytest.raises(InvalidInputError, match=rf"^{path}: (cannot read its array|member 1 is compressed with zip method 99)") as info:
        load_npz(path, max_bytes=1 << 20)
    assert "\n" not in str(info.value)


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="needs os.mkfifo")
@pytest.mark.parametrize("name", ["pipe.npz", "pipe.npy"])
def test_loading_refuses_a_fifo_at_once(tmp_path, name):
    import os

    os.mkfifo(tmp_path / name)
    load = load_npy if name.endswith(".npy") else load_npz
    with pytest.raises(InvalidInputError, match=rf"{name}: is a FIFO; only regular files are read"):
        load(tmp_path / name, max_bytes=1 << 20)


@pytest.mark.parametrize("name", ["p.npz", "p.npy"])
def test_loading_refuses_a_link_out_of_its_folder(tmp_path, name):
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "data").mkdir()
    outside = tmp_path / "elsewhere" / name
    np.save(outside, np.zeros((2, 3))) if name.endswith(".npy") else np.savez(outside, points=np.zeros((2, 3)))
    (tmp_path / "data" / name).symlink_to(outside)
    load = load_npy if name.endswith(".npy") else load_npz
    with pytest.raises(UnsafePathError, match=rf"{name} leads outside {tmp_path / 'data'}"):
        load(tmp_path / "data" / name, max_bytes=1 << 20, within=tmp_path / "data")
