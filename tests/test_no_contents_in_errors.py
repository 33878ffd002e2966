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
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

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


# -- values read from a user's file: named by key, row, type and size, never quoted --------------------
#: A secret a linked file may hold (an OAuth token); a valid sensor or class name, so it is planted in every place.
CANARY = "ya29.CanaryTok3n"
#: A number a file may hold; no message may show it either ("outside [0, 255]", not the number).
CANARY_NUMBER = 987654.321
#: What may not appear: the secret, its core, the number's digits (as a float, an int or cut).
CANARY_PIECES = (CANARY, "CanaryTok3n", "987654")
#: The values planted in each place: the secret alone, in a list and in an object (a docker config), the numbers.
PLANTED = (CANARY, [CANARY], {"auth": CANARY}, {"auths": {"x": {"auth": CANARY}}}, CANARY_NUMBER, 987654, -CANARY_NUMBER)


def _canary_free(text: str) -> None:
    assert not [piece for piece in CANARY_PIECES if piece in text], text
    assert "\n" not in text.strip(), text


def _refusal(read: Callable[[], object]) -> str | None:
    """The message of what ``read`` raises (a ZbufOccludeError), None if it reads."""
    try:
        read()
    except ZbufOccludeError as exc:
        return str(exc)
    return None


def _json(path: Path, doc: object) -> Path:
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def _class_maps(tmp_path: Path, capsys) -> list[str | None]:
    from zbuf_occlude.sensors.scene.las_classes import load_class_map

    docs = [{"access_token": v} for v in PLANTED] + [{"car": 1, "x": v} for v in PLANTED] + [list(PLANTED), CANARY, CANARY_NUMBER]
    docs += [{"car": 12, "token": CANARY}, {"car": 987654}]
    return [_refusal(lambda d=d: load_class_map(_json(tmp_path / "classes.json", d))) for d in docs]


def _class_map_cli(tmp_path: Path, capsys) -> list[str | None]:
    """``scan ... --class-map classes.json``, the map a link to a credentials file outside the folder."""
    from zbuf_occlude.cli.main import main

    out = []
    for doc in ({"access_token": CANARY}, {"auths": {"registry": {"auth": CANARY}}}, {"car": CANARY_NUMBER}):
        secret = _json(tmp_path / "home" / ".config" / "token.json", doc) if (tmp_path / "home" / ".config").is_dir() else None
        if secret is None:
            (tmp_path / "home" / ".config").mkdir(parents=True)
            secret = _json(tmp_path / "home" / ".config" / "token.json", doc)
        work = tmp_path / "work"
        work.mkdir(exist_ok=True)
        link = work / "classes.json"
        link.unlink(missing_ok=True)
        link.symlink_to(secret)
        street = REPO_ROOT / "data" / "scenes" / "street.json"
        code = main(["scan", str(street), "--format", "las", "--class-map", str(link), "--out", str(work / "o")])
        captured = capsys.readouterr()
        assert code == 2 and str(link) in captured.err, captured.err
        out.append(captured.out + captured.err)
    return out


_LIDAR = {"kind": "lidar", "name": "l", "elevations_deg": [0.0, 1.0]}
_LIDAR_FIELDS = ("name", "elevations_deg", "rotation_hz", "firing_rate_hz", "azimuth_offset_deg", "source", "preset", "kind", "beam")
_BEAM_FIELDS = ("name", "divergence_deg", "footprint_rays", "max_returns", "profile", "return_mode", "echo_rule", "range_noise_m",
                "dropout", "min_range_m", "max_range_m", "intensity_scale", "max_intensity", "source")  # fmt: skip
_AIRBORNE = {"kind": "airborne", "preset": "dales-q1560"}


def _sensors(tmp_path: Path, capsys) -> list[str | None]:
    from zbuf_occlude.sensors.kinds import sensor_from_name

    docs = [{**_LIDAR, key: v} for key in _LIDAR_FIELDS for v in PLANTED]
    docs += [{**_LIDAR, "beam": {key: v}} for key in _BEAM_FIELDS for v in PLANTED]
    docs += [
        {**_AIRBORNE, key: v} for key in ("altitude_m", "speed_mps", "swath_deg", "pattern", "n_lines", "headings_deg") for v in PLANTED
    ]
    docs += [
        {**_LIDAR, "name": CANARY, "rotation_hz": -1},
        {**_LIDAR, "name": CANARY, "beam": {"dropout": 2}},
    ]  # a valid name, then a fault
    docs += [{**_LIDAR, "name": CANARY, "beam": {"name": CANARY, "min_range_m": 50, "max_range_m": 10}}]
    docs += [{**_LIDAR, "beam": {"footprint_rays": 7, "divergence_deg": 0}}, {**_LIDAR, "firing_rate_hz": 1, "rotation_hz": 987654.321}]
    docs += [list(PLANTED), CANARY]  # (a key is named, cut: not planted here)
    return [_refusal(lambda d=d: sensor_from_name(_json(tmp_path / "sensor.json", d))) for d in docs]


_OBJECT = {"mesh": {"box_m": [1.0, 1.0, 1.0]}, "class": "car", "position_m": [5.0, 0.0]}


def _scene_docs() -> list[object]:
    docs: list[object] = [{"objects": [{**_OBJECT, key: v}]} for key in ("mesh", "class", "position_m", "yaw_deg", "size_m", "up", "foliage")
                          for v in PLANTED]  # fmt: skip
    docs += [{"objects": [{**_OBJECT, "mesh": {"box_m": [1.0, 1.0, v]}}]} for v in PLANTED]
    docs += [{"objects": [{**_OBJECT, "mesh": {"cylinder": {"radius_m": v, "height_m": 1.0}}}]} for v in PLANTED]
    docs += [{"objects": [{**_OBJECT, "mesh": path}]} for path in ("../" + CANARY + ".off", "/" + CANARY + ".off", CANARY + "\0")]
    docs += [{"ground": {key: v}} for key in ("z_m", "half_extent_m") for v in PLANTED]
    docs += [{"sensor": {key: v}} for key in ("height_m", "position_m") for v in PLANTED]
    docs += [{key: v} for key in ("ground", "objects", "occluders", "sensor") for v in PLANTED]
    docs += [{"objects": [{**_OBJECT, "class": CANARY, "yaw_deg": None}]}, list(PLANTED), CANARY]
    return docs


def _scenes(tmp_path: Path, capsys) -> list[str | None]:
    import yaml

    from zbuf_occlude.sensors.scene.files import load_scene

    out = []
    for doc in _scene_docs():
        out.append(_refusal(lambda d=doc: load_scene(_json(tmp_path / "scene.json", d))))
        (tmp_path / "scene.yaml").write_text(yaml.safe_dump(doc), encoding="utf-8")
        out.append(_refusal(lambda: load_scene(tmp_path / "scene.yaml")))
    for text in (
        f"ground: !{CANARY} 1\n",
        f"objects: [{{mesh: '{CANARY}'\n",
        f"a: &{CANARY} 1\nb: *{CANARY}\n",
        f"ground:\n\t{CANARY}: 1\n",
    ):
        (tmp_path / "scene.yaml").write_text(text, encoding="utf-8")
        out.append(_refusal(lambda: load_scene(tmp_path / "scene.yaml")))
    for text in ('{"ground": "' + CANARY + "\x01" + '"}', '{"ground": ' + CANARY + "}", '{"a": "\\' + CANARY + '"}'):
        (tmp_path / "scene.json").write_text(text, encoding="utf-8")
        out.append(_refusal(lambda: load_scene(tmp_path / "scene.json")))
    return out


def _trajectories(tmp_path: Path, capsys) -> list[str | None]:
    from zbuf_occlude.sensors.platform import load_trajectory

    head = "time_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n"
    good = ["0,0,0,0,0,0,0", "1,1,0,0,0,0,0"]
    out = []
    for column in range(7):
        for value in (CANARY, "nan", "inf", "9" * 400, str(CANARY_NUMBER * 1e6), str(-CANARY_NUMBER)):
            row = good[1].split(",")
            row[column] = value
            (tmp_path / "t.csv").write_text(head + "\n".join([good[0], ",".join(row)]) + "\n", encoding="utf-8")
            out.append(_refusal(lambda: load_trajectory(tmp_path / "t.csv")))
    (tmp_path / "t.csv").write_text(f"time_s,{CANARY}\n0,1\n", encoding="utf-8")
    out.append(_refusal(lambda: load_trajectory(tmp_path / "t.csv")))
    return out


def _ray_tables(tmp_path: Path, capsys) -> list[str | None]:
    from zbuf_occlude.sensors.patterns.ray_table import load_ray_table

    out = []
    for column in range(3):
        for value in (CANARY, "nan", "-inf", str(CANARY_NUMBER), str(-CANARY_NUMBER)):
            row = ["1", "0", "0"]
            row[column] = value
            (tmp_path / "r.csv").write_text("time_s,azimuth_deg,elevation_deg\n2,0,0\n" + ",".join(row) + "\n", encoding="utf-8")
            out.append(_refusal(lambda: load_ray_table(tmp_path / "r.csv")))
    (tmp_path / "r.csv").write_text(f"time_s,azimuth_deg,{CANARY}\n", encoding="utf-8")
    out.append(_refusal(lambda: load_ray_table(tmp_path / "r.csv")))
    return out


def _las_files(tmp_path: Path, capsys) -> list[str | None]:
    laspy = pytest.importorskip("laspy")
    from zbuf_occlude.io.las import read_las

    header = laspy.LasHeader(point_format=6, version="1.4")
    header.system_identifier = CANARY
    header.generating_software = CANARY
    header.vlrs.append(laspy.VLR(user_id=CANARY, record_id=1, description=CANARY, record_data=SECRET))
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.arange(4.0), np.arange(4.0), np.arange(4.0)
    las.write(tmp_path / "whole.las")
    data = (tmp_path / "whole.las").read_bytes()
    out = []
    for name, cut in (("truncated.las", data[:-10]), ("header.las", data[:300]), ("vlr.las", data[:400])):
        (tmp_path / name).write_bytes(cut)
        out.append(_refusal(lambda n=name: read_las(tmp_path / n)))
    forged = bytearray(data)
    forged[104] = 99  # an unknown point format
    (tmp_path / "format.las").write_bytes(bytes(forged))
    out.append(_refusal(lambda: read_las(tmp_path / "format.las")))
    return out


def _mtl_names(tmp_path: Path, capsys) -> list[str | None]:
    from zbuf_occlude.mesh.load import load_mesh

    folder = tmp_path / "meshes"
    folder.mkdir()
    body = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
    out = []
    for head in (f"mtllib ../{CANARY}.mtl\nusemtl {CANARY}\n", f"mtllib /{CANARY}.mtl\n", f"usemtl {CANARY}\nf 1 2 0\n"):
        (folder / "m.obj").write_text(head + body + "f 1 2 3\n", encoding="utf-8")
        out.append(_refusal(lambda: load_mesh(folder / "m.obj")))
    return out


def _dataset_metadata(tmp_path: Path, capsys) -> list[str | None]:
    from zbuf_occlude.dataset.schema import checked_shards, read_card, read_manifest
    from zbuf_occlude.io.hdf5 import open_hdf5

    fields = ("format_version", "storage", "params", "poses", "splits", "shape_names", "checksums", "joined_files", "point_sets")
    out = [_refusal(lambda d=d: read_card(_json(tmp_path / "card.json", d))) for d in ([{k: v for k in fields} for v in PLANTED])]
    record = {"object_index": 0, "name": "a", "source": "a.off", "class_name": "c", "label": 0, "split": "train", "key": 0,
              "status": "ok", "shards": ["a.h5"], "n_visible": [1]}  # fmt: skip
    for key in ("name", "status", "label", "class_name", "shards", "n_visible", "sha256", "point_columns", "cloud", "visibility_from"):
        for v in PLANTED:
            (tmp_path / "manifest.jsonl").write_text(json.dumps({**record, key: v}) + "\n", encoding="utf-8")
            out.append(_refusal(lambda: read_manifest(tmp_path / "manifest.jsonl")))
    for shard in ("../" + CANARY + ".h5", "/" + CANARY + ".h5"):
        (tmp_path / "manifest.jsonl").write_text(json.dumps({**record, "shards": [shard]}) + "\n", encoding="utf-8")
        ((_, _, rec),) = read_manifest(tmp_path / "manifest.jsonl")
        out.append(_refusal(lambda r=rec: checked_shards(tmp_path, "manifest.jsonl:1", r, None, verify=False)))
    with h5py.File(tmp_path / "s.h5", "w") as f:
        f["data"] = np.zeros((1, 2, 3))
        f.attrs["note"] = CANARY
        f["data"].attrs["note"] = CANARY
        f["link"] = h5py.SoftLink("/data")
    out.append(_refusal(lambda: open_hdf5(tmp_path / "s.h5")))
    return out


#: Each reader of a user's file, and the messages of its refusals of files with the canary in every place.
VALUE_READERS = {
    "class_map": _class_maps, "class_map_cli_link": _class_map_cli, "sensor_json": _sensors, "scene_json_yaml": _scenes,
    "trajectory_csv": _trajectories, "ray_table_csv": _ray_tables, "las_header": _las_files, "obj_mtl": _mtl_names,
    "dataset_metadata": _dataset_metadata,
}  # fmt: skip


@pytest.mark.parametrize("reader", VALUE_READERS)
def test_a_value_read_from_a_file_never_reaches_a_message(tmp_path: Path, capsys, reader: str) -> None:
    """Every reader of a user's file names the key, the row, the type and the size of what it refuses, never its
    value: a secret and a number planted in every place of each kind of file appear in no message."""
    messages = VALUE_READERS[reader](tmp_path, capsys)
    refused = [m for m in messages if m is not None]
    assert len(refused) >= max(1, len(messages) // 2), f"{len(refused)} of {len(messages)} files refused"  # the files are bad
    for message in refused:
        _canary_free(message)


_JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=30),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=8,
)
_PROPERTY_PLACES = (("class map", None), ("lidar", "name"), ("lidar", "rotation_hz"), ("lidar", "elevations_deg"), ("lidar", "source"),
                    ("beam", "dropout"), ("beam", "footprint_rays"), ("beam", "profile"))  # fmt: skip


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(value=_JSON_VALUES, place=st.sampled_from(_PROPERTY_PLACES))
def test_no_json_value_in_a_class_map_or_a_sensor_file_is_quoted(tmp_path: Path, value: object, place: tuple[str, str | None]) -> None:
    from zbuf_occlude.sensors.kinds import sensor_from_spec
    from zbuf_occlude.sensors.scene.las_classes import check_class_map

    kind, key = place
    if kind == "class map":
        message = _refusal(lambda: check_class_map({"car": value}, "classes.json"))
    elif kind == "lidar":
        message = _refusal(lambda: sensor_from_spec({"kind": "lidar", "preset": "vlp16", key: value}))
    else:
        message = _refusal(lambda: sensor_from_spec({"kind": "lidar", "preset": "vlp16", "beam": {key: value}}))
    if message is not None:
        for shown in {repr(value), json.dumps(value), str(value)}:
            assert len(shown) <= 6 or shown not in message, message
