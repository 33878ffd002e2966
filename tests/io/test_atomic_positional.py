"""The writers the owned folder's temporaries use: an HDF5 file at a temporary (``temp_h5``) and
bytes written at offsets of a temporary that already holds its layout (``positional_writer``)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from zbuf_occlude.io.atomic import atomic_h5, positional_writer, temp_h5
from zbuf_occlude.io.owned import OwnedFolder


def test_rows_written_at_their_offsets_read_back_as_one_array(tmp_path):
    rows = np.arange(24, dtype="<f4").reshape(4, 2, 3)
    with OwnedFolder(tmp_path / "out", files=["d.h5"]) as folder, folder.write("d.h5") as tmp:
        with temp_h5(tmp) as f:
            dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
            dcpl.set_layout(h5py.h5d.CONTIGUOUS)
            dcpl.set_alloc_time(h5py.h5d.ALLOC_TIME_EARLY)
            ds = h5py.h5d.create(f.id, b"data", h5py.h5t.IEEE_F32LE, h5py.h5s.create_simple(rows.shape), dcpl=dcpl)
            offset = ds.get_offset()
        with positional_writer(tmp) as write:
            for i in (3, 0, 2, 1):  # in any order
                write(offset + i * rows[i].nbytes, rows[i].tobytes())
        assert folder.written() == []  # recorded once complete, as it takes its name
    with h5py.File(tmp_path / "out" / "d.h5", "r") as f:
        np.testing.assert_array_equal(f["data"][()], rows)


def test_a_link_is_not_written_through(tmp_path):
    target = tmp_path / "elsewhere"
    target.write_bytes(b"kept")
    (tmp_path / "tmp").symlink_to(target)
    with pytest.raises(OSError), positional_writer(tmp_path / "tmp"):
        pass
    assert target.read_bytes() == b"kept"


def test_atomic_h5_still_leaves_no_temporary(tmp_path):
    with atomic_h5(tmp_path / "a.h5") as f:
        f["x"] = np.zeros(3)
    assert [p.name for p in tmp_path.iterdir()] == ["a.h5"]
