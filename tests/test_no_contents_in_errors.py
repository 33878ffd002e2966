"""A file's bytes never reach our messages or outputs, and a link out of a folder is not read.

Every reader of a user's file (meshes, real scans, point sets, lists) is walked with malformed
files seeded with a marker string where a parser would quote it: the marker never appears in the
error, which is one line naming the file.  A file found by walking a folder that is a link leading
outside it to a file of another kind (``car/scan.xyz`` to ``~/.aws/credentials``) is refused unread,
naming the link and the folder; a link to a file of its own kind (a ModelNet subset made of links)
is followed, and its contents still never reach the errors, ``manifest.jsonl`` or the records.
"""

from __future__ import annotations

import io
import json
import struct
import zipfile
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest

from zbuf_occlude.errors import UnsafePathError, ZbufOccludeError

REPO_ROOT = Path(__file__).resolve().parents[1]
CHAIR = REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"
DESK = REPO_ROOT / "data" / "samples" / "desk" / "test" / "desk_0201.off"
#: What a private file holds; no message, record or manifest may show it (nor its first half).
MARKER = "aws_secret_access_key=Zq7SecretMarker"
SECRET = MARKER.encode()
#: Parts of the marker that must not appear either (a message that cuts the quote at 20 or 40 characters).
PIECES = (MARKER, "Zq7Secret", "aws_secret")


def _leaks(text: str) -> list[str]:
    return [piece for piece in PIECES if piece in text]


def _npy(header: str, body: bytes = b"", version: int = 1) -> bytes:
    """A .npy file with a header of our own (numpy would not write these)."""
    text = header.encode("latin-1") + b"\n"
    length = struct.pack("<H", len(text)) if version == 1 else struct.pack("<I", len(text))
    return b"\x93NUMPY" + bytes([version, 0]) + length + text + body


def _npz(members: dict[str, bytes]) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return buffer.getvalue()


PLY_HEAD = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
LIDARNET_HEAD = b"origin_x,origin_y,origin_z,relative_x,relative_y,relative_z,object,complexity\n"

#: (file name, bytes): each malformed where a parser quotes what it read, the marker in that place.
MESHES = [
    ("not_off.off", SECRET + b"\n"),
    ("off_after_secret.off", b"# c\n" + SECRET + b" OFF\n3 1 0\n"),
    ("count_line.off", b"OFF\n" + SECRET + b" 1 0\n0 0 0\n"),
    ("face_corner_count.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n" + SECRET + b" 0 1 2\n"),
    ("vertex_text.off", b"OFF\n3 1 0\n0 0 0\n1 0 " + SECRET + b"\n0 1 0\n3 0 1 2\n"),
    ("face_text.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 " + SECRET + b"\n"),
    ("latin1.off", b"OFF\n3 1 0\n0 0 0\n\xe9 " + SECRET + b"\n0 1 0\n3 0 1 2\n"),
    ("zero_index.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2 " + SECRET + b"\n"),
    ("vertex_text.obj", b"v " + SECRET + b" 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
    ("vertex_text.ply", PLY_HEAD + b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 " + SECRET + b"\n"),
    ("format.ply", b"ply\nformat " + SECRET + b" 1.0\nelement vertex 1\nproperty float x\nend_header\n"),
    ("property.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty " + SECRET + b" x\nend_header\n0\n"),
    ("ascii.stl", b"solid " + SECRET + b"\nfacet normal 0 0 " + SECRET + b"\nouter loop\nvertex 0 0 0\n"),
    ("json.gltf", b'{"asset": {"version": "' + SECRET + b'"}, "scenes": [' + SECRET + b"]}"),
    (
        "accessor.gltf",
        json.dumps(
            {
                "asset": {"version": "2.0"},
                "meshes": [{"primitives": [{"attributes": {"POSITION": MARKER}}]}],
                "scenes": [{"nodes": [0]}],
                "nodes": [{"mesh": 0}],
            }
        ).encode(),
    ),  # fmt: skip
    ("xml.dae", b"<?xml version='1.0'?><COLLADA><" + SECRET + b"></COLLADA>"),
    (
        "collada.dae",
        b"<?xml version='1.0'?><COLLADA xmlns='http://www.collada.org/2005/11/COLLADASchema'><asset><up_axis>"
        + SECRET
        + b"</up_axis></asset><library_geometries><geometry id='"
        + SECRET
        + b"'/></library_geometries></COLLADA>",
    ),
]

#: .npy files whose header numpy would quote: the same for the scan and the point-set readers.
BAD_NPY = [
    ("descr.npy", _npy("{'descr': '" + MARKER + "', 'fortran_order': False, 'shape': (1, 3), }")),
    ("dict.npy", _npy("{'descr': '<f8', 'fortran_order': False, 'shape': (1, 3), '" + MARKER + "': 1}")),
    ("not_a_dict.npy", _npy(MARKER)),
    ("huge_header.npy", _npy("{'descr': '<f8', 'fortran_order': False, 'shape': (1, 3), }" + " " * 200_000 + MARKER, b"\0" * 24, 2)),
]

SCANS = [
    ("words.xyz", SECRET + b" 1 2\n"),
    ("second.xyz", b"1 2 3\n4 5 " + SECRET + b"\n"),
    ("two.txt", b"1 2 3\n" + SECRET + b"\n"),
    ("cell.csv", b"x,y,z\n1," + SECRET + b",3\n"),
    ("header.csv", SECRET + b",b,c\n1,2\n"),
    ("count.pts", b"3\n1 2 3\n" + SECRET + b" 0 0\n"),
    ("fields.pcd", b"FIELDS " + SECRET + b"\nSIZE 4\nTYPE F\nCOUNT 1\nWIDTH 1\nPOINTS 1\nDATA ascii\n1\n"),
    ("size.pcd", b"FIELDS x y z\nSIZE " + SECRET + b"\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n"),
    ("type.pcd", b"FIELDS x y z\nSIZE 4 4 4\nTYPE Q Q " + SECRET + b"\nCOUNT 1 1 1\nWIDTH 1\nPOINTS 1\nDATA binary\n" + b"\0" * 12),
    ("data.pcd", b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nPOINTS 1\nDATA " + SECRET + b"\n"),
    ("rows.pcd", b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 " + SECRET + b" 3\n"),
    ("vertex_text.ply", PLY_HEAD + b"end_header\n0 0 0\n1 0 " + SECRET + b"\n0 1 0\n"),
    *BAD_NPY,
]

SUO_CSV = [("4wd.0.1.csv", b"1,2,3,4,5,6,7,8," + SECRET + b"\n"), ("car.0.2.csv", SECRET + b",2,3,4,5,6,7,8,9\n")]
LIDARNET = [
    ("header.csv", b"origin_x,origin_y,origin_z," + SECRET + b"\n1,2,3\n"),
    ("row.csv", LIDARNET_HEAD + b"1,2," + SECRET + b",0,0,0,car,1\n"),
    ("label.csv", LIDARNET_HEAD + b"1,2,3,0,0,0,car,1\n1,2,3,0,0,0," + SECRET + b",1\n"),
    ("nul.csv", LIDARNET_HEAD + b"1,2,3,0,0,0,\0" + SECRET + b",1\n"),
    ("one_point.csv", LIDARNET_HEAD + b"1,2,3,0,0,0," + SECRET + b",1\n"),
]

#: Point sets whose header is malformed: refused by point_set_labels (which reads headers only) as well.
BAD_HEADERS = ("descr.npy", "dict.npy", "not_a_dict.npy", "huge_header.npy", "count.ply")
POINT_SETS = [
    *BAD_NPY,
    ("count.ply", b"ply\nformat ascii 1.0\nelement " + SECRET + b" " + b"9" * 40 + b"\nelement vertex 1\nend_header\n"),
    ("vertex_text.ply", PLY_HEAD + b"end_header\n0 0 0\n1 0 " + SECRET + b"\n0 1 0\n"),
    ("format.ply", b"ply\nformat " + SECRET + b" 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n"),
]


def _assert_clean(exc: BaseException, path: Path) -> None:
    message = str(exc)
    assert isinstance(exc, ZbufOccludeError), repr(exc)
    assert not _leaks(message), message
    assert "\n" not in message and "\r" not in message, message
    assert path.name in message, message


def _refused(read: Callable[[Path], object], path: Path) -> None:
    with pytest.raises(ZbufOccludeError) as info:
        read(path)
    _assert_clean(info.value, path)


@pytest.mark.parametrize(("name", "data"), MESHES, ids=[m[0] for m in MESHES])
def test_a_mesh_reader_never_quotes_the_file(tmp_path: Path, name: str, data: bytes) -> None:
    from zbuf_occlude.mesh.load import load_mesh

    path = tmp_path / name
    path.write_bytes(data)
    _refused(load_mesh, path)


@pytest.mark.parametrize(("name", "data"), SCANS, ids=[s[0] for s in SCANS])
def test_a_scan_reader_never_quotes_the_file(tmp_path: Path, name: str, data: bytes) -> None:
    from zbuf_occlude.real_scans.files import read_points

    path = tmp_path / name
    path.write_bytes(data)
    _refused(read_points, path)


@pytest.mark.parametrize(("name", "data"), SUO_CSV + LIDARNET, ids=[s[0] for s in SUO_CSV + LIDARNET])
def test_the_suo_and_lidarnet_readers_never_quote_the_file(tmp_path: Path, name: str, data: bytes) -> None:
    from zbuf_occlude.real_scans.datasets import read_lidarnet_csv, read_suo_csv

    path = tmp_path / name
    path.write_bytes(data)
    _refused(read_suo_csv if name.count(".") == 3 else read_lidarnet_csv, path)


@pytest.mark.parametrize(("name", "data"), POINT_SETS, ids=[s[0] for s in POINT_SETS])
def test_a_point_set_reader_never_quotes_the_file(tmp_path: Path, name: str, data: bytes) -> None:
    from zbuf_occlude.io.point_sets import point_set_labels, read_point_sets

    path = tmp_path / name
    path.write_bytes(data)
    _refused(read_point_sets, path)
    if name in BAD_HEADERS:
        _refused(point_set_labels, path)


def _structured_npy() -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.zeros(4, dtype=[(MARKER, "<f8"), ("b", "<f8")]))
    return buffer.getvalue()


def test_an_array_of_records_is_refused_without_naming_its_fields(tmp_path: Path) -> None:
    from zbuf_occlude.io.point_sets import point_set_labels, read_point_sets
    from zbuf_occlude.real_scans.files import read_points

    path = tmp_path / "records.npy"
    path.write_bytes(_structured_npy())
    for read in (read_point_sets, point_set_labels, read_points):
        _refused(read, path)


def test_an_hdf5_point_set_of_records_is_refused_without_naming_its_fields(tmp_path: Path) -> None:
    from zbuf_occlude.io.point_sets import read_point_sets

    with h5py.File(tmp_path / "records.h5", "w") as f:
        f["data"] = np.zeros((1, 4), dtype=[(MARKER, "<f8"), ("b", "<f8")])
    _refused(read_point_sets, tmp_path / "records.h5")


def test_a_200_kb_npy_header_is_one_line_giving_its_length(tmp_path: Path) -> None:
    """numpy's refusal ran over three lines, quoted as is into the skip message."""
    from zbuf_occlude.io.caps import MAX_NPY_HEADER_BYTES
    from zbuf_occlude.io.point_sets import read_point_sets
    from zbuf_occlude.real_scans.files import read_points

    path = tmp_path / "big.npy"
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 3), }" + " " * 200_000
    path.write_bytes(_npy(header, b"\0" * 24, 2))
    for read in (read_point_sets, read_points):
        with pytest.raises(ZbufOccludeError) as info:
            read(path)
        assert str(info.value) == (
            f"{path}: its .npy header is {len(header) + 1:,} bytes, more than the {MAX_NPY_HEADER_BYTES:,} numpy parses; "
            "save the array again"
        )


def test_an_npy_header_numpy_reads_is_still_read(tmp_path: Path) -> None:
    from zbuf_occlude.io.point_sets import read_point_sets

    points = np.random.default_rng(0).uniform(-1, 1, (50, 3))
    for version in ((1, 0), (2, 0), (3, 0)):
        buffer = io.BytesIO()
        np.lib.format.write_array(buffer, points, version=version)
        (tmp_path / "c.npy").write_bytes(buffer.getvalue())
        (cloud,) = read_point_sets(tmp_path / "c.npy")
        assert np.array_equal(cloud.points, points)


def test_an_npz_scan_never_quotes_the_file(tmp_path: Path) -> None:
    from zbuf_occlude.real_scans.files import read_points

    path = tmp_path / "s.npz"
    path.write_bytes(_npz({"points.npy": _npy("{'descr': '" + MARKER + "', 'fortran_order': False, 'shape': (1, 3), }")}))
    _refused(read_points, path)


def test_an_hdf5_point_set_of_text_never_quotes_the_file(tmp_path: Path) -> None:
    from zbuf_occlude.io.point_sets import read_point_sets

    path = tmp_path / "s.h5"
    with h5py.File(path, "w") as f:
        f["data"] = np.array([[[MARKER.encode()] * 3]])
        f.attrs["note"] = MARKER
    _refused(read_point_sets, path)


@pytest.mark.parametrize("line", [MARKER + "\x01", "../" + MARKER, MARKER + "/x"])
def test_a_class_list_is_refused_by_its_line_number_not_its_text(tmp_path: Path, line: str) -> None:
    from zbuf_occlude.io.point_sets import shape_names

    (tmp_path / "shape_names.txt").write_text(f"chair\n{line}\n", encoding="utf-8")
    with pytest.raises(ZbufOccludeError) as info:
        shape_names(tmp_path / "s.h5")
    _assert_clean(info.value, tmp_path / "shape_names.txt")
    assert "shape_names.txt:2:" in str(info.value)


def test_a_list_file_and_a_taxonomy_are_refused_by_line_and_entry_not_text(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.layouts import read_taxonomy
    from zbuf_occlude.mesh.inputs.plan import discover_objects

    (tmp_path / "list.txt").write_text(f"{CHAIR} chair\n{MARKER}\n", encoding="utf-8")
    with pytest.raises(ZbufOccludeError) as info:
        discover_objects(tmp_path / "list.txt")
    _assert_clean(info.value, tmp_path / "list.txt")
    assert "list.txt:2:" in str(info.value)
    (tmp_path / "taxonomy.json").write_text(json.dumps([{"synsetId": "0", "name": "\x01" + MARKER}]), encoding="utf-8")
    with pytest.raises(ZbufOccludeError) as info:
        read_taxonomy(tmp_path)
    _assert_clean(info.value, tmp_path / "taxonomy.json")


# -- links out of a folder that is walked ------------------------------------------------------------
@pytest.fixture
def credentials(tmp_path: Path) -> Path:
    """A private file outside every folder given: what a link in a downloaded data set may point to."""
    path = tmp_path / "home" / ".aws" / "credentials"
    path.parent.mkdir(parents=True)
    path.write_bytes(b"[default]\n" + SECRET + b"\n")
    return path


def _refused_link(exc: BaseException, link: Path, folder: Path) -> None:
    message = str(exc)
    assert isinstance(exc, UnsafePathError), repr(exc)
    assert str(link) in message and f"in {folder} " in message and "\n" not in message, message
    assert "credentials" not in message and not _leaks(message), message  # not the target's path either


@pytest.mark.parametrize("suffix", [".xyz", ".csv", ".npy", ".bin"])
def test_a_scan_that_links_out_of_the_folder_to_another_kind_of_file_is_refused_unread(
    tmp_path: Path, credentials: Path, suffix: str, monkeypatch
) -> None:
    from zbuf_occlude.real_scans import datasets, files
    from zbuf_occlude.real_scans.datasets import load_real_scans

    root = tmp_path / "real"
    (root / "car").mkdir(parents=True)
    np.savetxt(root / "car" / "a.xyz", np.random.default_rng(0).uniform(size=(20, 3)))
    (root / "car" / f"b{suffix}").symlink_to(credentials)
    opened = []
    for module in (files, datasets):
        real_open = module.open_regular_file
        monkeypatch.setattr(module, "open_regular_file", lambda p, *a, _o=real_open, **k: opened.append(Path(p)) or _o(p, *a, **k))
    for dataset in ("auto", "folder"):
        with pytest.raises(ZbufOccludeError) as info:
            load_real_scans(root, dataset=dataset)
        _refused_link(info.value, root / "car" / f"b{suffix}", root)
    assert opened == []  # refused before any file was read


def test_a_scan_that_links_to_a_scan_is_followed_and_one_inside_the_folder_too(tmp_path: Path) -> None:
    from zbuf_occlude.real_scans.datasets import load_real_scans

    root, elsewhere = tmp_path / "real", tmp_path / "elsewhere"
    (root / "car").mkdir(parents=True)
    elsewhere.mkdir()
    rng = np.random.default_rng(0)
    np.savetxt(elsewhere / "x.xyz", rng.uniform(size=(20, 3)))
    np.savetxt(root / "car" / "a.xyz", rng.uniform(size=(20, 3)))
    (root / "car" / "b.xyz").symlink_to(elsewhere / "x.xyz")  # a scan kept elsewhere: its own kind
    (root / "car" / "c.txt").symlink_to(root / "car" / "a.xyz")  # inside the folder: any name
    scans = load_real_scans(root, dataset="folder", dedupe=False)
    assert [Path(s.source).name for s in scans] == ["a.xyz", "b.xyz", "c.txt"]


def test_a_mesh_that_links_out_of_the_folder_to_another_kind_of_file_is_refused(tmp_path: Path, credentials: Path) -> None:
    from zbuf_occlude.mesh.inputs.discovery import scan_meshes, walk_mesh_files
    from zbuf_occlude.mesh.inputs.kinds import INPUT_KINDS
    from zbuf_occlude.mesh.inputs.plan import discover_objects

    root = tmp_path / "meshes"
    (root / "chair").mkdir(parents=True)
    (root / "chair" / "a.off").symlink_to(CHAIR)  # a mesh kept elsewhere: followed
    finders = (lambda: walk_mesh_files(root, kinds=INPUT_KINDS), lambda: scan_meshes([root]), lambda: discover_objects(root))
    for name, finds in (("b.off", finders), ("c.h5", finders[:1])):  # (an .h5 is looked for as a point set only)
        (root / "chair" / name).symlink_to(credentials)
        for find in finds:
            with pytest.raises(ZbufOccludeError) as info:
                find()
            _refused_link(info.value, root / "chair" / name, root)
        (root / "chair" / name).unlink()
    assert [p.name for p in walk_mesh_files(root)[0]] == ["a.off"]


def _all_text(folder: Path) -> str:
    return "\n".join(p.read_bytes().decode("latin-1") for p in folder.rglob("*") if p.is_file())


def test_generate_refuses_a_link_to_a_private_file_in_one_line_and_writes_nothing(tmp_path: Path, credentials: Path) -> None:
    from memory_limit import run_cli_limited

    root = tmp_path / "meshes"
    for cls, mesh in (("chair", CHAIR), ("desk", DESK)):
        (root / cls).mkdir(parents=True)
        (root / cls / mesh.name).write_bytes(mesh.read_bytes())
    (root / "chair" / "stolen.off").symlink_to(credentials)
    done = run_cli_limited(["generate", str(root), "--out", str(tmp_path / "out"), "--views", "0:0", "--points", "32"])
    assert done.returncode == 2, done.stderr
    err = done.stderr.strip()
    assert "\n" not in err and str(root / "chair" / "stolen.off") in err and not _leaks(done.stdout + err), err
    assert not (tmp_path / "out").exists() or not _leaks(_all_text(tmp_path / "out"))


def test_generate_on_a_link_to_a_like_named_private_file_keeps_its_bytes_out_of_every_output(tmp_path: Path) -> None:
    """A private file behind a link of its own extension is read, fails to parse, and its first 40
    characters used to go into the error, manifest.jsonl and the records."""
    from memory_limit import run_cli_limited

    secret = tmp_path / "home" / "notes.off"
    secret.parent.mkdir()
    secret.write_bytes(SECRET + b"\n" + SECRET + b"\n")
    root = tmp_path / "meshes"
    for cls, mesh in (("chair", CHAIR), ("desk", DESK)):
        (root / cls).mkdir(parents=True)
        (root / cls / mesh.name).write_bytes(mesh.read_bytes())
    (root / "chair" / "notes.off").symlink_to(secret)
    out = tmp_path / "out"
    done = run_cli_limited(["generate", str(root), "--out", str(out), "--views", "0:0", "--points", "32"])
    assert done.returncode == 1, done.stderr  # the other meshes are done; one failed
    assert not _leaks(done.stdout + done.stderr), done.stderr
    manifest = (out / "manifest.jsonl").read_text()
    assert "chair/notes.off: not an OFF file" in manifest and not _leaks(_all_text(out))


def test_realism_refuses_a_scan_that_links_to_a_private_file(tmp_path: Path, credentials: Path, capsys) -> None:
    from zbuf_occlude.cli.main import main

    root = tmp_path / "real"
    (root / "car").mkdir(parents=True)
    np.savetxt(root / "car" / "a.xyz", np.random.default_rng(0).uniform(size=(20, 3)))
    (root / "car" / "b.xyz").symlink_to(credentials)
    code = main(["realism", str(root), str(root), "--out", str(tmp_path / "o"), "--no-figure"])
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert code == 2 and "\n" not in err and str(root / "car" / "b.xyz") in err, err
    assert not _leaks(captured.out + err)


def test_generate_skips_a_point_set_with_a_200_kb_npy_header_in_one_line(tmp_path: Path) -> None:
    """numpy's refusal (three lines, naming max_header_size and allow_pickle) was the skip message as is."""
    from memory_limit import run_cli_limited

    root = tmp_path / "sets" / "chair"
    root.mkdir(parents=True)
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (64, 3), }" + " " * 200_000
    (root / "big.npy").write_bytes(_npy(header, np.zeros((64, 3)).tobytes(), 2))
    np.save(root / "good.npy", np.random.default_rng(0).uniform(size=(256, 3)))
    done = run_cli_limited(["generate", str(root.parent), "--out", str(tmp_path / "out"), "--views", "0:0", "--points", "32"])
    assert done.returncode == 1, done.stderr  # the good cloud is done; the other skipped
    skipped = [line for line in done.stderr.splitlines() if str(root / "big.npy") in line]
    assert skipped and all(f"its .npy header is {len(header) + 1:,} bytes" in line for line in skipped), done.stderr
    assert "max_header_size" not in done.stderr and "allow_pickle" not in done.stderr, done.stderr
