"""Checkpoints are read as weights only, by the reading layer's rules: regular files, inside their folder, capped."""

from __future__ import annotations

import io
import os
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="checkpoints need PyTorch: pip install -e '.[learn]'")

from zbuf_occlude.errors import CheckpointError, UnsafePathError
from zbuf_occlude.io.checkpoints import checkpoint_bytes, load_checkpoint


class _Marker:
    """Unpickling it creates a file: the proof that a checkpoint ran code."""

    def __init__(self, path: Path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def _state() -> dict:
    return {"model": {"w": torch.arange(6, dtype=torch.float32).reshape(2, 3)}, "epoch": 3, "name": "x", "none": None}


def test_bytes_written_and_read_back_are_the_same_state(tmp_path: Path) -> None:
    (tmp_path / "a.pt").write_bytes(checkpoint_bytes(_state()))
    state = load_checkpoint(tmp_path / "a.pt", keys=("model", "epoch"), within=tmp_path)
    assert state["epoch"] == 3 and state["name"] == "x" and state["none"] is None
    assert torch.equal(state["model"]["w"], _state()["model"]["w"])


def test_a_pickled_object_is_refused_and_runs_nothing(tmp_path: Path) -> None:
    marker = tmp_path / "ran.txt"
    torch.save({**_state(), "history": _Marker(marker)}, tmp_path / "a.pt")
    with pytest.raises(CheckpointError, match=r"a\.pt needs more than weights to load .*refused"):
        load_checkpoint(tmp_path / "a.pt")
    assert not marker.exists(), "loading the checkpoint ran code"


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
def test_a_fifo_is_refused_at_once_without_blocking(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "last.pt")
    # in a child with a deadline: a reader that opened the FIFO would wait for a writer forever
    code = (
        "import sys\nfrom zbuf_occlude.io.checkpoints import load_checkpoint\n"
        "try:\n    load_checkpoint(sys.argv[1])\nexcept Exception as exc:\n    print(type(exc).__name__, exc)\n"
    )
    done = subprocess.run([sys.executable, "-c", code, str(tmp_path / "last.pt")], capture_output=True, text=True, timeout=60, check=False)
    assert done.stdout.startswith("CheckpointError") and "last.pt: is a FIFO" in done.stdout, done.stdout + done.stderr


def test_a_link_out_of_the_checkpoint_folder_is_refused(tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere.pt"
    elsewhere.write_bytes(checkpoint_bytes(_state()))
    run = tmp_path / "run"
    run.mkdir()
    (run / "last.pt").symlink_to(elsewhere)
    with pytest.raises(UnsafePathError, match=r"last\.pt leads outside .*run"):
        load_checkpoint(run / "last.pt", within=run)
    assert load_checkpoint(run / "last.pt")["epoch"] == 3  # without within=: the file a user named, wherever it lies


def test_a_checkpoint_past_the_cap_is_refused_before_it_is_read(tmp_path: Path) -> None:
    data = checkpoint_bytes(_state())
    (tmp_path / "a.pt").write_bytes(data)
    with pytest.raises(CheckpointError, match=rf"a\.pt: {len(data):,} bytes, more than the {len(data) - 1:,}"):
        load_checkpoint(tmp_path / "a.pt", max_bytes=len(data) - 1)


@pytest.mark.parametrize(
    "data, message",
    [(b"", "damaged, truncated or not a PyTorch checkpoint"), (b"PK\x03\x04" + b"\0" * 60, "not a PyTorch checkpoint"),
     (b"not a checkpoint\n", "refused")],
    ids=["empty", "zip-header", "text"],
)  # fmt: skip
def test_a_damaged_file_names_itself(tmp_path: Path, data: bytes, message: str) -> None:
    (tmp_path / "a.pt").write_bytes(data)
    with pytest.raises(CheckpointError, match=rf"a\.pt.*{message}"):
        load_checkpoint(tmp_path / "a.pt")


def test_missing_keys_and_a_state_that_is_not_a_dict_are_named(tmp_path: Path) -> None:
    (tmp_path / "a.pt").write_bytes(checkpoint_bytes(_state()))
    with pytest.raises(CheckpointError, match=r"a\.pt is not a zbuf_occlude checkpoint of this kind: it lacks optimizer"):
        load_checkpoint(tmp_path / "a.pt", keys=("model", "optimizer"))
    torch.save(torch.zeros(3), tmp_path / "t.pt")
    with pytest.raises(CheckpointError, match=r"t\.pt is not a zbuf_occlude checkpoint \(a Tensor, not a dict\)"):
        load_checkpoint(tmp_path / "t.pt")
    with pytest.raises(CheckpointError, match=r"missing\.pt: cannot read file"):
        load_checkpoint(tmp_path / "missing.pt")


def test_io_imports_without_torch() -> None:
    code = "import sys; sys.modules['torch'] = None\nimport zbuf_occlude.io.checkpoints\nprint('ok')"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False)
    assert done.stdout.strip() == "ok", done.stderr


def _rezipped(data: bytes, method: int) -> bytes:
    """The checkpoint ``data`` with every record compressed by zip ``method``."""
    source, out = zipfile.ZipFile(io.BytesIO(data)), io.BytesIO()
    with zipfile.ZipFile(out, "w", compression=method) as zf:
        for name in source.namelist():
            zf.writestr(name, source.read(name))
    return out.getvalue()


def _tensor_record(data: bytes) -> zipfile.ZipInfo:
    """The zip entry of the checkpoint's first tensor (``<archive>/data/0``)."""
    return next(i for i in zipfile.ZipFile(io.BytesIO(data)).infolist() if i.filename.endswith("/data/0"))


def _claiming(data: bytes, inflated: int) -> bytes:
    """``data``, a checkpoint, whose first tensor's record claims to inflate to ``inflated`` bytes
    (in its local header and its directory entry)."""
    raw, record = bytearray(data), _tensor_record(data)
    struct.pack_into("<I", raw, record.header_offset + 22, inflated)  # the local header's uncompressed size
    at = raw.find(b"PK\x01\x02")
    while raw[at + 46 : at + 46 + len(record.filename)] != record.filename.encode():  # its directory entry
        at = raw.find(b"PK\x01\x02", at + 4)
    struct.pack_into("<I", raw, at + 24, inflated)
    return bytes(raw)


def test_a_deflated_checkpoint_reads_and_one_compressed_otherwise_is_refused_naming_the_method(tmp_path: Path) -> None:
    data = checkpoint_bytes(_state())
    (tmp_path / "deflated.pt").write_bytes(_rezipped(data, zipfile.ZIP_DEFLATED))
    assert load_checkpoint(tmp_path / "deflated.pt")["epoch"] == 3
    (tmp_path / "bzip2.pt").write_bytes(_rezipped(data, zipfile.ZIP_BZIP2))
    with pytest.raises(
        CheckpointError, match=r"bzip2\.pt: member .* is compressed with zip method 12; only stored or deflated members \(torch\.save\)"
    ):
        load_checkpoint(tmp_path / "bzip2.pt")


def test_a_record_claiming_more_than_its_bytes_hold_is_refused_before_torch_allocates_it(tmp_path: Path) -> None:
    # torch's zip reader allocates a record's declared size first: here 2 GB claimed by 24 bytes
    data = checkpoint_bytes(_state())
    (tmp_path / "lying.pt").write_bytes(_claiming(data, 2_100_000_000))
    with pytest.raises(CheckpointError, match=r"lying\.pt: member \d+ declares 2,100,000,000 bytes inflated from 24, more than its"):
        load_checkpoint(tmp_path / "lying.pt")


@pytest.mark.slow
def test_a_deflated_checkpoint_inflating_past_the_memory_left_is_refused_naming_it(tmp_path: Path) -> None:
    # in a child under an address-space limit (1.5 GiB above its footprint, torch's libraries in it: a
    # CUDA build maps more than that at import): a 2 MB file whose tensor inflates to 1,000 times that
    # (deflate's own limit is about 1,032) is refused before torch allocates it
    from memory_limit import TORCH, run_python_limited

    noise = torch.from_numpy(np.random.default_rng(0).random(500_000, dtype=np.float32))  # 2 MB that deflate hardly shrinks
    data = _rezipped(checkpoint_bytes({"w": noise}), zipfile.ZIP_DEFLATED)
    (tmp_path / "big.pt").write_bytes(_claiming(data, 1000 * _tensor_record(data).compress_size))
    done = run_python_limited(
        "from zbuf_occlude.errors import InsufficientMemoryError\nfrom zbuf_occlude.io.checkpoints import load_checkpoint\n"
        f"try:\n    load_checkpoint({str(tmp_path / 'big.pt')!r})\nexcept InsufficientMemoryError as exc:\n    print(exc)",
        preload=TORCH,
    )
    assert done.returncode == 0 and done.stdout.startswith(f"the checkpoint {tmp_path / 'big.pt'} needs about"), (
        done.stdout + done.stderr[-2000:]
    )
