"""Files a user or another file names are read only when regular, sizes checked first: a FIFO never blocks."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from zbuf_occlude.errors import InvalidInputError, MeshLoadError
from zbuf_occlude.io.regular_files import file_digest, read_at_most, read_regular_file, regular_file_size

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")


def test_read_regular_file_refuses_fifos_and_sizes_past_the_cap(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "pipe")
    with pytest.raises(MeshLoadError, match="pipe: is a FIFO"):
        read_regular_file(tmp_path / "pipe", max_bytes=10, error=MeshLoadError)
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
        read_regular_file(tmp_path / "folder", max_bytes=10)
    with pytest.raises(InvalidInputError, match=r"missing: cannot read file \(No such file or directory\)"):
        file_digest(tmp_path / "missing", max_bytes=10)


def test_within_refuses_a_file_or_folder_that_links_out_and_reads_links_that_stay(tmp_path: Path) -> None:
    from zbuf_occlude.errors import UnsafePathError
    from zbuf_occlude.io.caps import MAX_LIST_BYTES
    from zbuf_occlude.io.regular_files import read_text_file

    (tmp_path / "secret").write_text("root:x:0:0\n")
    data = tmp_path / "data"
    (data / "sub").mkdir(parents=True)
    (data / "names.txt").symlink_to(tmp_path / "secret")
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "names.txt").write_text("x\n")
    (data / "linked").symlink_to(tmp_path / "elsewhere")
    (data / "sub" / "real.txt").write_text("chair\n")
    (data / "inside.txt").symlink_to(data / "sub" / "real.txt")
    for name in ("names.txt", "linked/names.txt", "sub/../../secret"):
        with pytest.raises(UnsafePathError, match="leads outside"):
            read_text_file(data / name, max_bytes=MAX_LIST_BYTES, within=data)
    assert read_text_file(data / "inside.txt", max_bytes=MAX_LIST_BYTES, within=data) == "chair\n"
    assert read_text_file(data / "names.txt", max_bytes=MAX_LIST_BYTES) == "root:x:0:0\n"  # no folder named: the user named the file


def test_read_text_file_is_capped_refuses_fifos_and_names_bytes_that_are_not_utf8(tmp_path: Path) -> None:
    from zbuf_occlude.io.caps import MAX_LIST_BYTES
    from zbuf_occlude.io.regular_files import read_text_file

    os.mkfifo(tmp_path / "pipe")
    with pytest.raises(InvalidInputError, match="pipe: is a FIFO"):
        read_text_file(tmp_path / "pipe", max_bytes=MAX_LIST_BYTES, within=tmp_path)
    (tmp_path / "bad.txt").write_bytes(b"ok\n\xff\xfe\n")
    with pytest.raises(InvalidInputError, match=r"bad.txt: not UTF-8 text \(byte 3\)"):
        read_text_file(tmp_path / "bad.txt", max_bytes=MAX_LIST_BYTES)
    assert read_text_file(tmp_path / "bad.txt", max_bytes=MAX_LIST_BYTES, errors="replace") == "ok\n\ufffd\ufffd\n"
    with open(tmp_path / "big.txt", "wb") as fh:  # sparse: declares its size without using the disk
        fh.truncate(MAX_LIST_BYTES + 1)
    with pytest.raises(InvalidInputError, match=rf"big.txt: {MAX_LIST_BYTES + 1:,} bytes, more than the {MAX_LIST_BYTES:,}"):
        read_text_file(tmp_path / "big.txt", max_bytes=MAX_LIST_BYTES)


def test_read_json_file_is_capped_refuses_fifos_links_out_and_deep_nesting(tmp_path: Path) -> None:
    from zbuf_occlude.errors import UnsafePathError
    from zbuf_occlude.io.json_files import read_json_file

    os.mkfifo(tmp_path / "pipe.json")
    with pytest.raises(InvalidInputError, match="pipe.json: is a FIFO"):
        read_json_file(tmp_path / "pipe.json")
    (tmp_path / "big.json").write_text('{"a": "' + "x" * 100 + '"}')
    with pytest.raises(InvalidInputError, match="big.json: 109 bytes, more than the 100"):
        read_json_file(tmp_path / "big.json", max_bytes=100)
    (tmp_path / "deep.json").write_text("[" * 5000 + "]" * 5000)
    with pytest.raises(InvalidInputError, match="deep.json nests arrays or objects deeper than 64"):
        read_json_file(tmp_path / "deep.json")
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "card.json").symlink_to(tmp_path / "big.json")
    with pytest.raises(UnsafePathError, match="leads outside"):
        read_json_file(tmp_path / "run" / "card.json", within=tmp_path / "run")
    assert read_json_file(tmp_path / "big.json") == {"a": "x" * 100}


def test_a_small_file_under_a_huge_cap_reserves_its_size_not_the_cap(tmp_path: Path) -> None:
    """``read(cap + 1)`` allocates the cap before reading: a 6-byte file under a 32 GiB cap raised
    MemoryError on a 23 GiB machine.  In a child whose address space is 1 GiB above its footprint,
    the read must succeed, which it cannot if it reserves anything near the cap."""
    import subprocess
    import sys
    import textwrap

    small = tmp_path / "small.txt"
    small.write_bytes(b"hello\n")
    code = textwrap.dedent(
        """
        import resource, sys
        from zbuf_occlude.io.regular_files import read_regular_file
        size = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmSize:")) * 1024
        resource.setrlimit(resource.RLIMIT_AS, (size + (1 << 30), resource.RLIM_INFINITY))
        print(read_regular_file(sys.argv[1], max_bytes=32 << 30) == b"hello\\n")
        """
    )
    done = subprocess.run([sys.executable, "-c", code, str(small)], capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0 and done.stdout.strip() == "True", done.stderr[-2000:]


@pytest.mark.parametrize("grow_by", [0, 1, 5000, (1 << 20) + 7])
def test_read_at_most_reads_a_file_that_grew_after_fstat_up_to_one_byte_past_the_cap(tmp_path: Path, grow_by: int) -> None:
    """The size passed in is what fstat said at open; bytes appended since are read in chunks, and the
    read stops one byte past the cap (so the caller can refuse it) without reading the rest."""
    path = tmp_path / "growing.bin"
    path.write_bytes(b"a" * 100)
    cap = 100 + 4096
    with open(path, "rb") as fh:
        with open(path, "ab") as writer:
            writer.write(b"b" * grow_by)
        data = read_at_most(fh, 100, cap)
    assert data == (b"a" * 100 + b"b" * grow_by)[: cap + 1]
    assert len(data) <= cap + 1
