"""io.atomic.file_sha256: the hash of a file, read in pieces no larger than the file."""

from __future__ import annotations

import hashlib
import tracemalloc

from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.io.atomic import file_sha256


def test_a_small_file_is_hashed_without_reserving_a_whole_chunk(tmp_path):
    # read(1 MiB) allocates the MiB before it reads the 12 bytes of a record
    (tmp_path / "record.json").write_bytes(b'{"done": 1}\n')
    tracemalloc.start()
    try:
        digest = file_sha256(tmp_path / "record.json", chunk_bytes=1 << 20)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert digest == hashlib.sha256(b'{"done": 1}\n').hexdigest()
    assert peak < 64 << 10, f"hashing 12 bytes took {peak:,} bytes"


@settings(max_examples=30, deadline=None)
@given(data=st.binary(max_size=5000), chunk_bytes=st.integers(1, 4096))
def test_the_digest_is_hashlibs_whatever_the_piece(tmp_path_factory, data, chunk_bytes):
    path = tmp_path_factory.mktemp("hash") / "f.bin"
    path.write_bytes(data)
    assert file_sha256(path, chunk_bytes=chunk_bytes) == hashlib.sha256(data).hexdigest()
