"""Writers and readers: formats, atomicity, clear errors."""

from __future__ import annotations

import errno
import os

import numpy as np
import pytest
import trimesh

from zbuf_occlude.errors import OutputError
from zbuf_occlude.io import OccludedCloud, atomic_path, read_h5, read_npz, write_h5, write_npz, write_ply


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
    from zbuf_occlude.io import read_h5_clouds

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
    from zbuf_occlude.io import write_csv, write_text

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
        "from zbuf_occlude.io import write_text\n"
        "p = write_text(sys.argv[1], 'x')\n"
        "print(oct(os.stat(p).st_mode & 0o777))\n"
    )
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "strict.txt")], capture_output=True, text=True, timeout=120
    )
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
