"""A checked copy (io.copies): the source a regular file inside its folder, the target written whole or not at all."""

from __future__ import annotations

import os

import pytest

from zbuf_occlude.errors import InvalidInputError, UnsafePathError
from zbuf_occlude.io.copies import copy_regular_file


def test_a_regular_file_is_copied_byte_for_byte(tmp_path):
    (tmp_path / "task").mkdir()
    (tmp_path / "task" / "shard.h5").write_bytes(bytes(range(256)) * 5000)
    target = copy_regular_file(tmp_path / "task" / "shard.h5", tmp_path / "out" / "shards" / "shard.h5", within=tmp_path / "task")
    assert target.read_bytes() == (tmp_path / "task" / "shard.h5").read_bytes()
    assert sorted(p.name for p in target.parent.iterdir()) == ["shard.h5"]  # no temporary left


def test_a_link_out_of_the_source_folder_is_refused_and_nothing_written(tmp_path):
    (tmp_path / "task").mkdir()
    (tmp_path / "secret").write_bytes(b"another file's bytes")
    (tmp_path / "task" / "shard.h5").symlink_to(tmp_path / "secret")
    with pytest.raises(UnsafePathError, match=r"shard\.h5 leads outside .*task"):
        copy_regular_file(tmp_path / "task" / "shard.h5", tmp_path / "out" / "shard.h5", within=tmp_path / "task")
    assert not (tmp_path / "out").exists()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
def test_a_fifo_is_refused_at_once_and_nothing_written(tmp_path):
    (tmp_path / "task").mkdir()
    os.mkfifo(tmp_path / "task" / "shard.h5")
    with pytest.raises(InvalidInputError, match=r"shard\.h5: is a FIFO; only regular files are read"):
        copy_regular_file(tmp_path / "task" / "shard.h5", tmp_path / "out" / "shard.h5", within=tmp_path / "task")
    assert not (tmp_path / "out").exists()


def test_a_missing_source_leaves_an_earlier_target_whole(tmp_path):
    (tmp_path / "task").mkdir()
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "shard.h5").write_bytes(b"earlier")
    with pytest.raises(InvalidInputError, match=r"shard\.h5: cannot read file"):
        copy_regular_file(tmp_path / "task" / "shard.h5", tmp_path / "out" / "shard.h5", within=tmp_path / "task")
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["shard.h5"]
    assert (tmp_path / "out" / "shard.h5").read_bytes() == b"earlier"
