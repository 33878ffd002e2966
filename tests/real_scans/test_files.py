"""Real-scan files of any kind: CSV, TXT/XYZ, PLY, PCD (ascii, binary), NPY/NPZ, KITTI BIN; class folders."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.real_scans.files import POINT_EXTENSIONS, load_scan_folder, read_points, units_to_m

PTS = np.array([[1.0, 2.0, 3.0], [4.5, -5.0, 6.25], [-7.0, 8.0, 0.5], [0.0, 0.0, 10.0]])


def _pcd(fields: str, rows: np.ndarray, binary: bool) -> bytes:
    head = (f"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE 4 4 4 4\nTYPE F F F F\n"
            f"COUNT 1 1 1 1\nWIDTH {len(rows)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(rows)}\n"
            f"DATA {'binary' if binary else 'ascii'}\n").encode()  # fmt: skip
    if binary:
        return head + rows.astype("<f4").tobytes()
    return head + "".join(" ".join(f"{v:.6g}" for v in r) + "\n" for r in rows).encode()


def _write_all(folder: Path) -> dict[str, Path]:
    folder.mkdir(parents=True, exist_ok=True)
    four = np.column_stack([PTS, np.arange(len(PTS))])  # an extra column (intensity)
    files = {
        "csv": ("intensity,X,Y,Z\n" + "".join(f"{i},{x},{y},{z}\n" for i, (x, y, z) in enumerate(PTS))).encode(),
        "txt": ("# x y z i\n" + "".join(f"{x} {y} {z} 7\n" for x, y, z in PTS)).encode(),
        "xyz": "".join(f"{x},{y},{z}\n" for x, y, z in PTS).encode(),
        "pts": (f"{len(PTS)}\n" + "".join(f"{x} {y} {z} 1 2 3\n" for x, y, z in PTS)).encode(),
        "bin": four.astype("<f4").tobytes(),
    }
    out = {}
    for ext, data in files.items():
        out[ext] = folder / f"scan.{ext}"
        out[ext].write_bytes(data)
    out["pcd_ascii"] = folder / "a.pcd"
    out["pcd_ascii"].write_bytes(_pcd("x y z intensity", four, False))
    out["pcd_binary"] = folder / "b.pcd"
    out["pcd_binary"].write_bytes(_pcd("intensity x y z", np.column_stack([four[:, 3], PTS]), True))
    out["npy"] = folder / "scan.npy"
    np.save(out["npy"], four)
    out["npz"] = folder / "scan.npz"
    np.savez(out["npz"], labels=np.zeros(4), points=PTS)
    out["ply"] = folder / "scan.ply"
    trimesh.PointCloud(PTS).export(out["ply"])
    out["ply_ascii"] = folder / "ascii.ply"
    out["ply_ascii"].write_bytes(trimesh.exchange.ply.export_ply(trimesh.PointCloud(PTS), encoding="ascii"))
    return out


def test_every_format_reads_the_same_points(tmp_path: Path) -> None:
    for kind, path in _write_all(tmp_path).items():
        np.testing.assert_allclose(read_points(path), PTS, rtol=1e-6, err_msg=kind)


@pytest.mark.parametrize(
    "name, data, message",
    [
        ("cut.bin", b"\x00" * 20, "16-byte"),
        ("short.pcd", b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 10\nDATA binary\n" + b"\x00" * 12, "declares 10 points"),
        ("zip.pcd", b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 1\nDATA binary_compressed\n", "binary_compressed"),
        ("noxyz.pcd", b"FIELDS a b c\nPOINTS 1\nDATA ascii\n1 2 3\n", "no x y z"),
        ("words.txt", b"hello world foo\nbar baz qux\n", "expected three numbers"),
        ("two.csv", b"x,y,z\n1,2\n", "expected three numbers"),
        ("nan.xyz", b"1 2 nan\n", "NaN or inf"),
        ("empty.txt", b"# nothing\n", "no points"),
        ("pickle.npy", b"\x93NUMPY\x01\x00v\x00{'descr': '|O', 'fortran_order': False, 'shape': (1,), }" + b" " * 60 + b"\n", "npy"),
        ("flat.npy", None, "(N, >=3)"),
        ("x.las", b"LASF", "unsupported"),
    ],
)
def test_bad_files_name_the_file(tmp_path: Path, name: str, data: bytes | None, message: str) -> None:
    path = tmp_path / name
    if data is None:
        np.save(path, np.zeros(5))
    else:
        path.write_bytes(data)
    with pytest.raises(InvalidInputError) as info:
        read_points(path)
    assert name in str(info.value) and message.lower() in str(info.value).lower()


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.sampled_from(POINT_EXTENSIONS), st.binary(max_size=300))
def test_hostile_bytes_give_points_or_a_clear_error(tmp_path: Path, ext: str, data: bytes) -> None:
    path = tmp_path / f"fuzz{ext}"
    path.write_bytes(data)
    try:
        pts = read_points(path)
    except InvalidInputError as exc:
        assert "fuzz" in str(exc)
    else:
        assert pts.ndim == 2 and pts.shape[1] == 3 and len(pts) and np.isfinite(pts).all()


def test_class_folders_with_label_map_up_axis_and_units(tmp_path: Path) -> None:
    root = tmp_path / "scans"
    tall_y = np.array([[0.0, 0.0, 0.0], [50.0, 180.0, 40.0], [10.0, 90.0, 5.0]])  # cm, y up, 1.8 m tall
    for cls, n in (("Person", 2), ("Trunk", 3)):
        (root / cls).mkdir(parents=True)
        for i in range(n):
            np.save(root / cls / f"{i}.npy", tall_y + i + 10 * n)
    scans = load_scan_folder(root, label_map={"Trunk": "pole"}, up="+y", units="cm")
    assert sorted(s.label for s in scans) == ["Person", "Person", "pole", "pole", "pole"]
    for s in scans:
        np.testing.assert_allclose(s.extent_m, [0.5, 0.4, 1.8], atol=1e-9)  # y up → z up, cm → m
        assert s.points.max(axis=0)[2] - s.points.min(axis=0)[2] == pytest.approx(1.0)
    auto = load_real_scans(root, label_map={"Trunk": "pole"}, up="+y", units=0.01)  # detected as a folder
    assert [s.label for s in auto] == [s.label for s in scans]


def test_byte_identical_scans_are_dropped_once(tmp_path: Path) -> None:
    (tmp_path / "car").mkdir()
    for name in ("a.xyz", "b.xyz"):
        (tmp_path / "car" / name).write_text("0 0 0\n1 1 1\n")
    (tmp_path / "car" / "c.xyz").write_text("0 0 0\n2 1 1\n")
    assert len(load_scan_folder(tmp_path)) == 2
    assert len(load_scan_folder(tmp_path, dedupe=False)) == 3


def test_units_and_bad_options() -> None:
    assert units_to_m("in") == 0.0254 and units_to_m(0.2) == 0.2
    for bad in ("furlong", -1, 0, "nan"):
        with pytest.raises(InvalidInputError):
            units_to_m(bad)


def test_a_one_point_scan_names_its_file(tmp_path: Path) -> None:
    (tmp_path / "car").mkdir()
    (tmp_path / "car" / "dot.xyz").write_text("1 2 3\n")
    with pytest.raises(InvalidInputError, match="dot.xyz"):
        load_scan_folder(tmp_path)
