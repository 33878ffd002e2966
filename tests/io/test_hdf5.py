"""HDF5 files that point elsewhere are refused before a byte of data is read (io/hdf5.py)."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from zbuf_occlude.errors import DatasetFormatError
from zbuf_occlude.io.clouds import read_h5
from zbuf_occlude.io.hdf5 import Column, check_hdf5, open_hdf5

POINTS = np.arange(24, dtype=np.float32).reshape(2, 4, 3)
SCHEMA = {"data": Column("f", 3), "label": Column("iu", 1)}


@pytest.fixture
def secret(tmp_path: Path) -> Path:
    """A file elsewhere on the machine: raw bytes, and an HDF5 file holding a 'data' dataset."""
    folder = tmp_path / "elsewhere"
    folder.mkdir()
    (folder / "secret.bin").write_bytes(np.full(24, 7, dtype=np.float32).tobytes())
    with h5py.File(folder / "secret.h5", "w") as f:
        f["data"] = np.full((2, 4, 3), 7, dtype=np.float32)
    return folder


def _hostile(path: Path, how: str, secret: Path) -> Path:
    with h5py.File(path, "w") as f:
        f["label"] = np.zeros(2, dtype=np.int64)
        if how == "external storage":
            f.create_dataset("data", shape=(2, 4, 3), dtype=np.float32, external=[(str(secret / "secret.bin"), 0, 96)])
        elif how == "external link, absolute":
            f["data"] = h5py.ExternalLink(str(secret / "secret.h5"), "/data")
        elif how == "external link, ../":
            f["data"] = h5py.ExternalLink("../elsewhere/secret.h5", "/data")
        elif how == "soft link":
            f["points"] = POINTS
            f["data"] = h5py.SoftLink("/points")
        elif how == "virtual dataset":
            layout = h5py.VirtualLayout(shape=(2, 4, 3), dtype=np.float32)
            layout[:] = h5py.VirtualSource(str(secret / "secret.h5"), "data", shape=(2, 4, 3))
            f.create_virtual_dataset("data", layout)
        elif how == "string data":
            f["data"] = np.array(["a", "b"], dtype=h5py.string_dtype())
        elif how == "integer data":
            f["data"] = POINTS.astype(np.int32)
        elif how == "nested link":
            f.create_group("g")["data"] = h5py.ExternalLink(str(secret / "secret.h5"), "/data")
            f["data"] = POINTS
        else:
            raise AssertionError(how)
    return path


HOSTILE = [
    ("external storage", "another file .external storage"),
    ("external link, absolute", "'/data' is an external link"),
    ("external link, ../", "'/data' is an external link"),
    ("soft link", "'/data' is a soft link"),
    ("virtual dataset", "'/data' is a virtual dataset"),
    ("string data", "'/data' holds string values .* schema says float with 3 dimensions"),
    ("integer data", "'/data' holds signed integer values .* schema says float"),
    ("nested link", "'/g/data' is an external link"),
]


@pytest.mark.parametrize("how, message", HOSTILE, ids=[h for h, _ in HOSTILE])
def test_a_file_that_points_elsewhere_or_holds_other_types_is_refused(tmp_path: Path, secret: Path, how: str, message: str):
    folder = tmp_path / "ds"
    folder.mkdir()
    path = _hostile(folder / "shard.h5", how, secret)
    with pytest.raises(DatasetFormatError, match=rf"{path}.*{message}"):
        open_hdf5(path, SCHEMA)
    with pytest.raises(DatasetFormatError, match=str(path)):
        read_h5(path, SCHEMA)


def test_what_h5py_writes_is_accepted(tmp_path: Path):
    path = tmp_path / "ok.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("data", data=POINTS, chunks=(1, 4, 3), compression="gzip", shuffle=True, fletcher32=True)
        f.create_dataset("label", data=np.zeros(2, np.uint8), chunks=(2,), compression="lzf")
        f["name"] = np.array(["a", "b"], dtype=h5py.string_dtype())
    with open_hdf5(path, SCHEMA) as f:
        assert np.array_equal(f["data"][()], POINTS)
    assert list(read_h5(path)["name"]) == ["a", "b"]


def test_a_file_that_is_not_hdf5_names_itself(tmp_path: Path):
    path = tmp_path / "x.h5"
    path.write_bytes(b"not hdf5")
    with pytest.raises(DatasetFormatError, match=rf"{path} is not a readable HDF5 file"):
        open_hdf5(path)


def test_compound_and_reference_types_are_refused(tmp_path: Path):
    path = tmp_path / "x.h5"
    with h5py.File(path, "w") as f:
        f["data"] = POINTS
        f["refs"] = np.array([f["data"].ref], dtype=h5py.ref_dtype)
    with h5py.File(path, "r") as f, pytest.raises(DatasetFormatError, match="'/refs' holds"):
        check_hdf5(f, path)


def test_open_hdf5_refuses_a_fifo_unopened_and_a_file_that_links_out(tmp_path):
    """h5py's open of a FIFO waits for a writer forever: the layer refuses it before HDF5 sees it."""
    import os

    import h5py
    import numpy as np

    from zbuf_occlude.errors import DatasetFormatError, UnsafePathError
    from zbuf_occlude.io.hdf5 import open_hdf5

    os.mkfifo(tmp_path / "pipe.h5")
    with pytest.raises(DatasetFormatError, match="pipe.h5: is a FIFO"):
        open_hdf5(tmp_path / "pipe.h5")
    with h5py.File(tmp_path / "real.h5", "w") as f:
        f["data"] = np.zeros((2, 3), np.float32)
    (tmp_path / "ds").mkdir()
    (tmp_path / "ds" / "shard.h5").symlink_to(tmp_path / "real.h5")
    with pytest.raises(UnsafePathError, match="leads outside"):
        open_hdf5(tmp_path / "ds" / "shard.h5", within=tmp_path / "ds")
    with open_hdf5(tmp_path / "ds" / "shard.h5") as f:  # no folder named: read where it is
        assert f["data"].shape == (2, 3)
