"""Files a user or another file names are read only when regular, sizes checked first: a FIFO never blocks."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from zbuf_occlude.errors import InvalidInputError, MeshLoadError
from zbuf_occlude.io.regular_files import file_digest, read_regular_file, regular_file_size

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")


def test_read_regular_file_refuses_fifos_and_sizes_past_the_cap(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "pipe")
    with pytest.raises(MeshLoadError, match="pipe: is a FIFO"):
        read_regular_file(tmp_path / "pipe", error=MeshLoadError)
    with pytest.raises(InvalidInputError, match="pipe: is a FIFO"):
        file_digest(tmp_path / "pipe", max_bytes=10, error=InvalidInputError)
    (tmp_path / "big").write_bytes(b"x" * 11)
    with pytest.raises(MeshLoadError, match=r"big: 11 bytes, more than the 10"):
        read_regular_file(tmp_path / "big", max_bytes=10, error=MeshLoadError)
    with pytest.raises(MeshLoadError, match=r"big: 11 bytes, more than the 10"):
        file_digest(tmp_path / "big", max_bytes=10, error=MeshLoadError)
    assert read_regular_file(tmp_path / "big", max_bytes=11) == b"x" * 11


def test_regular_file_size_names_what_is_not_a_regular_file_and_raises_invalid_input_by_default(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "pipe")
    (tmp_path / "folder").mkdir()
    (tmp_path / "file").write_bytes(b"abc")
    assert regular_file_size(tmp_path / "file") == 3
    with pytest.raises(InvalidInputError, match="pipe: is a FIFO; only regular files are read"):
        regular_file_size(tmp_path / "pipe")
    with pytest.raises(InvalidInputError, match=r"folder: cannot read file \(Is a directory\)"):
        read_regular_file(tmp_path / "folder")
    with pytest.raises(InvalidInputError, match=r"missing: cannot read file \(No such file or directory\)"):
        file_digest(tmp_path / "missing", max_bytes=10)
