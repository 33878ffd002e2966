"""Bad input, library level (issue 9): every malformed file, option or environment gives
one of our errors naming the file, option or value and the cause; nothing is lost silently.

Sections: files (the corpus of broken meshes), options (seed, resolution, memory),
discovery (unreadable folders, non-UTF-8 names).  Every test builds its inputs here or
uses the shipped ``data/samples`` meshes, so it runs in a fresh clone.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import trimesh

from zbuf_occlude.errors import InvalidInputError, MeshLoadError, ZbufOccludeError
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.visibility.registry import resolution_option

REPO_ROOT = Path(__file__).resolve().parents[2]
#: A shipped ModelNet chair: OFF, 2,382 vertices and 2,234 faces (data/samples/SOURCE.md).
CHAIR = REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"

#: A tetrahedron: 4 vertices, 4 faces, as OFF data lines.
TETRA_VERTICES = ["0 0 0", "1 0 0", "0 1 0", "0 0 1"]
TETRA_FACES = ["3 0 2 1", "3 0 1 3", "3 0 3 2", "3 1 2 3"]


def tetra_off(header: str = "OFF\n4 4 0", *, newline: str = "\n", comment: bytes = b"") -> bytes:
    body = newline.join([*TETRA_VERTICES, *TETRA_FACES]) + newline
    return header.replace("\n", newline).encode() + newline.encode() + comment + body.encode()


def assert_names(error: BaseException, *parts: str) -> None:
    """The message names every part (the file, the numbers, the cause)."""
    message = str(error)
    for part in parts:
        assert part in message, f"{part!r} not in {message!r}"


# -- files: the corpus ---------------------------------------------------------------------
#: name -> (content, regex of the cause the message must give).
BAD_FILES = {
    "empty.off": (b"", "empty"),
    "blank_lines.off": (b"\n\n  \n", "empty"),
    "comment_only.off": (b"# nothing here\n", "empty"),
    "no_header.off": (b"4 4 0\n" + "\n".join(TETRA_VERTICES + TETRA_FACES).encode() + b"\n", "no OFF header"),
    "header_only.off": (b"OFF\n", "no vertex and face counts"),
    "counts_not_numbers.off": (b"OFF\nfour four 0\n0 0 0\n", "count line"),
    "counts_missing_faces.off": (b"OFF\n4\n0 0 0\n", "count line"),
    "negative_counts.off": (b"OFF\n-4 4 0\n0 0 0\n", "negative"),
    "truncated_vertices.off": (b"OFF\n4 4 0\n0 0 0\n1 0 0\n", "declares 4 vertices and 4 faces but holds only 2 vertices"),
    "truncated_faces.off": (tetra_off()[: -len("3 1 2 3\n3 0 3 2\n")], "declares 4 faces but holds 2"),
    "cut_mid_face.off": (tetra_off()[: -len(" 3\n")] + b"\n", "face 3 lists 2 of its 3 corners"),
    "cut_mid_vertex.off": (b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1\n3 0 1 2\n", "vertex 2 has 2 coordinates"),
    "short_face_inside.off": (
        b"OFF\n4 4 0\n" + "\n".join(TETRA_VERTICES).encode() + b"\n3 0 2 1\n3 0 1\n3 0 3 2\n3 1 2 3\n",
        "face 1 lists 2 of its 3 corners",
    ),
    "binary_garbage.off": (bytes(range(256)) * 4, "not an OFF file"),
    "binary_garbage.ply": (bytes(range(256)) * 4, "cannot parse as PLY"),
    "binary_garbage.stl": (b"\x00" * 80 + b"\xff\xff\xff\x7f", "cannot parse as STL|empty"),
    "obj_named_off.off": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "not an OFF file"),
    "off_named_ply.ply": (tetra_off(), "cannot parse as PLY"),
    "wrong_extension.txt": (tetra_off(), "unsupported extension '.txt'"),
    "no_extension": (tetra_off(), "unsupported extension ''"),
    "nan_vertex.off": (b"OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n", "1 of 3 vertices are NaN or inf"),
    "inf_vertex.obj": (b"v 0 0 0\nv 1 inf 0\nv 0 1 0\nf 1 2 3\n", "NaN or inf"),
    "zero_extent.off": (b"OFF\n3 1 0\n1 1 1\n1 1 1\n1 1 1\n3 0 1 2\n", "coincide"),
    "all_degenerate.off": (b"OFF\n3 2 0\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n3 0 0 1\n", "all 2 faces are degenerate"),
    "repeated_index.off": (b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 0 1\n", "all 1 faces are degenerate"),
    "no_faces.off": (b"OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "no faces"),
    "index_out_of_range.off": (b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "outside the range"),
    "huge_coordinates.off": (
        b"OFF\n4 4 0\n0 0 0\n1e200 0 0\n0 1e200 0\n0 0 1e200\n" + "\n".join(TETRA_FACES).encode() + b"\n",
        r"1e\+200.*float32",
    ),
    "overflowing_coordinates.obj": (b"v 0 0 0\nv 1e309 0 0\nv 0 1 0\nf 1 2 3\n", "NaN or inf"),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_bad_file_is_a_mesh_load_error_naming_file_and_cause(tmp_path: Path, name: str) -> None:
    content, cause = BAD_FILES[name]
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(MeshLoadError) as info:
        load_mesh(path)
    assert_names(info.value, str(path))
    assert re.search(cause, str(info.value)), f"{cause!r} not in {info.value}"


def test_missing_file_and_folder_name_the_path(tmp_path: Path) -> None:
    with pytest.raises(MeshLoadError, match=re.escape(str(tmp_path / "nope.off")) + ": no such file"):
        load_mesh(tmp_path / "nope.off")
    with pytest.raises(MeshLoadError, match="is a directory"):
        load_mesh(tmp_path)


# -- defect 8: non-UTF-8 comments ------------------------------------------------------------
LATIN1 = "comment by Ren\xe9 M\xfcller, caf\xe9".encode("latin-1")

NON_UTF8_TWINS = {
    # (file with a Latin-1 comment, the same file without it)
    "off": (b"OFF\n# " + LATIN1 + b"\n4 4 0\n", b"OFF\n4 4 0\n"),
    "obj": (b"# " + LATIN1 + b"\n", b""),
    "ply": (
        b"ply\nformat ascii 1.0\ncomment " + LATIN1 + b"\n",
        b"ply\nformat ascii 1.0\n",
    ),
}


def _twin_body(ext: str) -> bytes:
    if ext == "off":
        return ("\n".join(TETRA_VERTICES + TETRA_FACES) + "\n").encode()
    if ext == "obj":
        faces = [" ".join(str(int(i) + 1) for i in f.split()[1:]) for f in TETRA_FACES]
        return ("\n".join([f"v {v}" for v in TETRA_VERTICES] + [f"f {f}" for f in faces]) + "\n").encode()
    header = (
        "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
    )
    return (header + "\n".join(TETRA_VERTICES + TETRA_FACES) + "\n").encode()


@pytest.mark.parametrize("ext", sorted(NON_UTF8_TWINS))
def test_non_utf8_comment_loads_like_its_clean_twin(tmp_path: Path, ext: str) -> None:
    latin, clean = NON_UTF8_TWINS[ext]
    dirty_path, clean_path = tmp_path / f"latin1.{ext}", tmp_path / f"clean.{ext}"
    dirty_path.write_bytes(latin + _twin_body(ext))
    clean_path.write_bytes(clean + _twin_body(ext))
    with pytest.raises(UnicodeDecodeError):
        dirty_path.read_bytes().decode("utf-8")  # the test file really is not UTF-8
    dirty, twin = load_mesh(dirty_path), load_mesh(clean_path)
    assert len(twin.faces) == 4
    np.testing.assert_array_equal(dirty.faces, twin.faces)
    np.testing.assert_array_equal(dirty.vertices, twin.vertices)


def test_binary_ply_with_latin1_comment_keeps_its_body(tmp_path: Path) -> None:
    mesh = trimesh.creation.icosphere(subdivisions=1)
    raw = trimesh.exchange.ply.export_ply(mesh, encoding="binary")
    raw = raw.replace(b"format binary_little_endian 1.0\n", b"format binary_little_endian 1.0\ncomment " + LATIN1 + b"\n", 1)
    path = tmp_path / "binary.ply"
    path.write_bytes(raw)
    loaded = load_mesh(path, normalize=False)
    np.testing.assert_array_equal(loaded.faces, mesh.faces)
    np.testing.assert_allclose(loaded.vertices, mesh.vertices, rtol=1e-6)


# -- defect 10: OFF files cut short ------------------------------------------------------------
def _cut(path: Path, fraction: float, out: Path) -> Path:
    raw = path.read_bytes()
    out.write_bytes(raw[: int(len(raw) * fraction)])
    return out


def test_off_cut_in_its_face_list_names_both_counts(tmp_path: Path) -> None:
    path = _cut(CHAIR, 0.9, tmp_path / "chair_90.off")
    lines = [line for line in path.read_text().splitlines() if line.strip()]
    n_vertices, n_faces = (int(t) for t in lines[1].split()[:2])
    assert (n_vertices, n_faces) == (2382, 2234)
    complete = [line for line in lines[2 + n_vertices :] if len(line.split()) == 4]
    found = len(lines) - 2 - n_vertices  # face lines present, the last one possibly cut
    with pytest.raises(MeshLoadError) as info:
        load_mesh(path)
    assert_names(info.value, str(path), "cut short")
    if found < n_faces:
        assert_names(info.value, f"declares {n_faces:,} faces but holds {found:,}")
    assert len(complete) < n_faces


def test_off_cut_in_half_names_the_vertex_count_not_numpy(tmp_path: Path) -> None:
    path = _cut(CHAIR, 0.5, tmp_path / "chair_50.off")
    with pytest.raises(MeshLoadError) as info:
        load_mesh(path)
    assert_names(info.value, str(path), "declares 2,382 vertices and 2,234 faces but holds only", "cut short")
    assert "inhomogeneous" not in str(info.value)


@pytest.mark.parametrize("fmt", ["ply-ascii", "ply-binary", "stl-binary"])
def test_ply_and_stl_cut_short_are_errors_naming_the_counts(tmp_path: Path, fmt: str) -> None:
    mesh = load_mesh(CHAIR)
    if fmt == "stl-binary":
        raw, suffix = trimesh.exchange.stl.export_stl(mesh), ".stl"
    else:
        raw, suffix = trimesh.exchange.ply.export_ply(mesh, encoding=fmt.split("-")[1]), ".ply"
    whole = tmp_path / f"whole{suffix}"
    whole.write_bytes(raw)
    assert len(load_mesh(whole).faces) == 2234
    for fraction in (0.9, 0.5):
        path = tmp_path / f"cut{suffix}"
        path.write_bytes(raw[: int(len(raw) * fraction)])
        with pytest.raises(MeshLoadError) as info:
            load_mesh(path)
        assert_names(info.value, str(path), "2,234", "cut short")


@pytest.mark.parametrize(
    "header, newline",
    [("OFF\n4 4 0", "\n"), ("OFF4 4 0", "\n"), ("OFF 4 4 0", "\n"), ("OFF\n4 4 0", "\r\n"), ("OFF4 4 0", "\r\n")],
    ids=["plain", "modelnet40-header", "header-with-space", "crlf", "modelnet40-crlf"],
)
def test_modelnet_header_quirks_still_load(tmp_path: Path, header: str, newline: str) -> None:
    path = tmp_path / "quirk.off"
    path.write_bytes(tetra_off(header, newline=newline))
    assert len(load_mesh(path).faces) == 4


def test_polygons_count_as_one_declared_face_each(tmp_path: Path) -> None:
    # A quad and a pentagon are 2 declared faces that become 1 + 2 + 3 triangles.
    path = tmp_path / "polygons.off"
    path.write_bytes(b"OFF\n6 3 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0.5 1.5 0\n0 0 1\n3 0 1 5\n4 0 1 2 3\n5 0 1 2 4 3\n")
    assert len(load_mesh(path).faces) == 1 + 2 + 3


def test_charset_normalizer_is_a_declared_dependency() -> None:
    # trimesh decodes non-UTF-8 OBJ text with it (trimesh.util.decode_text); without it
    # an OBJ with a Latin-1 comment fails with ModuleNotFoundError.
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        text = (REPO_ROOT / "pyproject.toml").read_text()
        assert re.search(r'^\s*"charset-normalizer[<>=!~ ]', text, flags=re.M)
        return
    project = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["project"]
    assert any(re.match(r"charset[-_]normalizer\b", d) for d in project["dependencies"])
    import charset_normalizer  # noqa: F401  (installed, as declared)


# -- options: seeds (defect 6) ------------------------------------------------------------------
@pytest.mark.parametrize("seed", [-1, -(2**70), 1.5, "0", True])
def test_bad_seed_is_our_error_naming_the_seed(seed) -> None:
    import zbuf_occlude as zo

    mesh = trimesh.creation.box()
    with pytest.raises(InvalidInputError, match="seed") as info:
        zo.sample_surface(mesh, 10, seed=seed)
    assert isinstance(info.value, ValueError)  # callers catching ValueError keep working
    assert repr(seed) in str(info.value) or str(seed) in str(info.value)


def test_bad_seed_in_the_seed_derivation_of_generate_and_farm() -> None:
    from zbuf_occlude.geometry.samples import derive_rng
    from zbuf_occlude.pipeline import dense_cloud

    with pytest.raises(InvalidInputError, match="seed must be a non-negative integer, got -1"):
        derive_rng(-1, 7)
    with pytest.raises(InvalidInputError, match="-1"):
        dense_cloud(trimesh.creation.box(), 7, seed=-1, count=10)


def test_check_seed_names_the_option_and_accepts_good_seeds() -> None:
    from zbuf_occlude.geometry.sampling import check_seed

    with pytest.raises(InvalidInputError, match="^--seed must be a non-negative integer, got -3$"):
        check_seed(-3, name="--seed")
    rng = np.random.default_rng(0)
    assert check_seed(rng) is rng
    assert check_seed(None) is None
    assert check_seed(np.int64(5)) == 5 and type(check_seed(np.int64(5))) is int
    assert check_seed(2**63 - 1) == 2**63 - 1  # the largest seed an int64 field can record
    with pytest.raises(InvalidInputError, match=r"^--seed must be at most 2\*\*63 - 1"):
        check_seed(2**64, name="--seed")


# -- options: resolution beyond the GL's limits (defect 6) ----------------------------------------
@pytest.fixture(scope="module")
def gl_context():
    from zbuf_occlude.render.context import shared_context

    return shared_context()


def test_resolution_beyond_the_gl_maximum_names_the_maximum(gl_context) -> None:
    import zbuf_occlude as zo
    from zbuf_occlude.geometry.cameras import camera_on_sphere
    from zbuf_occlude.render.context import max_image_size

    limit = max_image_size(gl_context)
    assert limit == min(gl_context.info["GL_MAX_TEXTURE_SIZE"], gl_context.info["GL_MAX_RENDERBUFFER_SIZE"])
    mesh = load_mesh(CHAIR)
    points, face_index = zo.sample_surface(mesh, 100, seed=0)
    for resolution in (limit + 1, 100_000):
        camera = camera_on_sphere(30, 45, 3.0, resolution=resolution)
        with pytest.raises(InvalidInputError) as info:
            zo.visible_mask(mesh, points, camera, "zbuffer", face_index=face_index, resolution=resolution)
        assert_names(info.value, f"maximum image size of {limit} pixels", str(resolution))
        assert "framebuffer" not in str(info.value)


@pytest.mark.parametrize("resolution", [0, -5, (64, 0), 2.5, True, (1, 2, 3)])
def test_check_image_size_rejects_non_positive_sizes(gl_context, resolution) -> None:
    from zbuf_occlude.render.context import check_image_size

    with pytest.raises(InvalidInputError, match=r"^--resolution must be a positive number of pixels"):
        check_image_size(resolution, ctx=gl_context, name="--resolution")


def test_check_image_size_names_the_option(gl_context) -> None:
    from zbuf_occlude.render.context import check_image_size, max_image_size

    limit = max_image_size(gl_context)
    assert check_image_size(limit, ctx=gl_context) == (limit, limit)
    assert check_image_size((limit, 1), ctx=gl_context) == (limit, 1)
    with pytest.raises(InvalidInputError, match=rf"^--resolution {limit + 1} is larger .* use --resolution <= {limit}$"):
        check_image_size(limit + 1, ctx=gl_context, name="--resolution")


# -- options: memory (defect 7) -----------------------------------------------------------------
def test_a_billion_points_is_refused_naming_option_estimate_and_memory() -> None:
    from zbuf_occlude.errors import InsufficientMemoryError
    from zbuf_occlude.resources import check_memory, estimate_job_memory, format_bytes

    estimate = estimate_job_memory(points=10**9, samples_per_view=10, dense_points=100_000, resolution=1024)
    available = 16 * 2**30
    with pytest.raises(InsufficientMemoryError) as info:
        check_memory(estimate, available=available)
    assert isinstance(info.value, ZbufOccludeError) and isinstance(info.value, ValueError)
    assert_names(info.value, "--points", "1,000,000,000", format_bytes(estimate.total), format_bytes(available))
    assert str(info.value).startswith("--points needs about")
    # Nowhere near 1 TB of memory here, whatever the machine: the real check refuses too.
    with pytest.raises(InsufficientMemoryError, match="--points"):
        check_memory(estimate_job_memory(points=10**12, samples_per_view=10))


def test_memory_estimate_is_linear_in_each_option_and_sums() -> None:
    from zbuf_occlude.resources import (
        BYTES_PER_DENSE_POINT,
        BYTES_PER_FACE,
        BYTES_PER_PIXEL,
        estimate_job_memory,
    )

    one = estimate_job_memory(points=2048, samples_per_view=10, dense_points=100_000, resolution=512, faces=1000)
    two = estimate_job_memory(points=4096, samples_per_view=10, dense_points=200_000, resolution=(1024, 512), faces=2000)
    for part in ("--points", "--dense-points", "--resolution", "mesh faces"):
        assert two.parts[part] == 2 * one.parts[part] > 0
    assert one.total == sum(one.parts.values())
    assert one.parts["--dense-points"] == 100_000 * BYTES_PER_DENSE_POINT
    assert one.parts["--resolution"] == 512 * 512 * BYTES_PER_PIXEL
    assert one.parts["mesh faces"] == 1000 * BYTES_PER_FACE
    held = estimate_job_memory(points=2048, samples_per_view=10, samples_held=250)
    assert held.parts["--points"] > one.parts["--points"]
    workers = estimate_job_memory(points=2048, dense_points=100_000, workers=4)
    assert workers.parts["--dense-points"] == 4 * 100_000 * BYTES_PER_DENSE_POINT and workers.parts["--workers"] > 0
    with pytest.raises(InvalidInputError):
        estimate_job_memory(points=-1)


def test_sampling_refuses_before_allocating(monkeypatch) -> None:
    import tracemalloc

    import zbuf_occlude as zo
    from zbuf_occlude import resources
    from zbuf_occlude.errors import InsufficientMemoryError

    monkeypatch.setattr(resources, "available_memory", lambda: (2**20, "test budget"))
    monkeypatch.setattr(resources, "MIN_CHECKED_BYTES", 0)
    mesh = trimesh.creation.box()
    tracemalloc.start()
    try:
        with pytest.raises(InsufficientMemoryError, match=r"count=1,000,000 needs about 130 MiB.*1 MiB available \(test budget\)"):
            zo.sample_surface(mesh, 10**6, seed=0)
        with pytest.raises(InsufficientMemoryError, match="density"):
            zo.sample_surface(mesh, density=1e6, seed=0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2**20  # refused before the arrays were made
    assert len(zo.sample_surface(mesh, 1000, seed=0)[0]) == 1000  # small jobs are not checked


@pytest.mark.parametrize("version", ["v1", "v2"])
def test_cgroup_limit_is_the_memory_available(tmp_path: Path, version: str) -> None:
    from zbuf_occlude.resources import _cgroup_room

    proc = tmp_path / "cgroup"
    if version == "v2":
        proc.write_text("0::/job\n")
        level = tmp_path / "job"
        level.mkdir()
        (level / "memory.max").write_text(f"{8 * 2**30}\n")
        (level / "memory.current").write_text(f"{3 * 2**30}\n")
        (level / "memory.stat").write_text(f"anon 1\ninactive_file {2**30}\n")
        (tmp_path / "memory.max").write_text("max\n")  # the root has no limit
    else:
        proc.write_text("4:memory:/job\n3:cpuset:/\n")
        level = tmp_path / "memory" / "job"
        level.mkdir(parents=True)
        (level / "memory.limit_in_bytes").write_text(f"{8 * 2**30}\n")
        (level / "memory.usage_in_bytes").write_text(f"{3 * 2**30}\n")
        (level / "memory.stat").write_text(f"total_inactive_file {2**30}\n")
        (tmp_path / "memory" / "memory.limit_in_bytes").write_text("9223372036854771712\n")
    assert _cgroup_room(tmp_path, proc) == 6 * 2**30  # limit - usage + reclaimable cache


def test_available_memory_is_known_here_and_plausible() -> None:
    from zbuf_occlude.resources import available_memory

    found = available_memory()
    assert found is not None
    n_bytes, source = found
    assert 0 < n_bytes < 2**50 and source


# -- discovery: non-UTF-8 names (defect 4), unreadable folders (defect 12) -------------------------
def _tree(root: Path, names: list[str | bytes]) -> None:
    """Copies of the tetrahedron at the given relative paths (bytes for raw file names)."""
    for name in names:
        raw = (name if isinstance(name, bytes) else name.encode()).split(b"/")
        folder = Path(root, *(part.decode("utf-8", "surrogateescape") for part in raw[:-1]))
        folder.mkdir(parents=True, exist_ok=True)
        with open(Path(folder).joinpath(raw[-1].decode("utf-8", "surrogateescape")), "wb") as f:
            f.write(tetra_off())


LATIN1_NAME = b"chair/train/caf\xe9_0002.off"


def test_non_utf8_file_name_is_reported_and_the_others_are_found(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.discovery import find_meshes, scan_meshes

    _tree(tmp_path, ["chair/train/chair_0001.off", LATIN1_NAME, "chair/test/chair_0003.off"])
    scan = scan_meshes([tmp_path])
    assert [name for _, name in scan.meshes] == ["chair/test/chair_0003", "chair/train/chair_0001"]
    assert len(scan.skipped) == 1
    skipped = scan.skipped[0]
    assert skipped.path.endswith("caf\\xe9_0002.off") and "not valid UTF-8" in skipped.reason
    str(skipped).encode("utf-8")  # printable: the report itself cannot fail
    assert find_meshes([tmp_path]) == scan.meshes
    for path, _ in scan.meshes:  # and the rest loads
        assert len(load_mesh(path).faces) == 4


def test_non_utf8_name_given_as_a_file_is_reported(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.discovery import scan_meshes

    _tree(tmp_path, [b"caf\xe9.off", "ok.off"])
    bad = tmp_path / b"caf\xe9.off".decode("utf-8", "surrogateescape")
    scan = scan_meshes([bad, tmp_path / "ok.off"])
    assert [name for _, name in scan.meshes] == ["ok"] and len(scan.skipped) == 1
    with pytest.raises(InvalidInputError, match=r"no mesh files .*skipped 1: .*caf\\xe9.off: file name is not valid UTF-8"):
        scan_meshes([bad])


def test_farm_discovery_reports_non_utf8_names_and_plans_the_rest(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.plan import discover_objects, scan_objects

    _tree(tmp_path, ["chair/train/chair_0001.off", LATIN1_NAME, "table/train/table_0001.off"])
    scan = scan_objects(tmp_path)
    assert [o.name for o in scan.objects] == ["chair/train/chair_0001", "table/train/table_0001"]
    assert [o.key for o in scan.objects]  # object keys encode every planned name
    assert len(scan.skipped) == 1 and "caf\\xe9_0002.off" in str(scan.skipped[0])
    assert discover_objects(tmp_path) == scan.objects


def test_farm_list_file_with_a_non_utf8_line(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    _tree(tmp_path, ["a.off", "b.off"])
    listing = tmp_path / "list.txt"
    listing.write_bytes(b"a.off chair\ncaf\xe9.off chair\nb.off table\n")
    scan = scan_objects(listing)
    assert [o.name for o in scan.objects] == ["a", "b"]
    assert [str(s) for s in scan.skipped] == [f"{listing}:2: line is not valid UTF-8; re-save the list as UTF-8"]


def test_object_key_of_a_non_utf8_name_keys_on_its_bytes() -> None:
    from zbuf_occlude.geometry.samples import object_key

    name = b"caf\xe9_0002".decode("utf-8", "surrogateescape")
    assert object_key(name) != object_key("caf\xe9_0002")  # Latin-1 bytes, not the UTF-8 é
    import hashlib

    for valid in ("chair/train/chair_0001", "caf\xe9_0002", "\u6905\u5b50"):  # keys of valid names are unchanged
        digest = hashlib.blake2b(valid.encode("utf-8"), digest_size=8).digest()
        assert object_key(valid) == int.from_bytes(digest, "little")


@pytest.fixture
def unreadable(monkeypatch):
    """chmod 000 really blocks reading, also as root: os.scandir (which os.walk and
    pathlib use) raises PermissionError on a folder without read permission, as the
    kernel does for other users.  Yields a function that makes a folder unreadable."""
    import os

    real_scandir = os.scandir
    made: list[Path] = []

    def scandir(path="."):
        if made and os.stat(path).st_mode & 0o444 == 0:
            raise PermissionError(13, "Permission denied", os.fspath(path))
        return real_scandir(path)

    monkeypatch.setattr(os, "scandir", scandir)

    def make(folder: Path) -> Path:
        folder.chmod(0)
        made.append(folder)
        return folder

    yield make
    for folder in made:
        folder.chmod(0o755)


def test_unreadable_class_folder_is_reported_not_silently_lost(tmp_path: Path, unreadable) -> None:
    from zbuf_occlude.mesh.inputs.discovery import find_meshes, scan_meshes

    _tree(tmp_path, ["chair/train/chair_0001.off", "table/train/table_0001.off", "table/test/table_0002.off"])
    unreadable(tmp_path / "table")
    scan = scan_meshes([tmp_path])
    assert [name for _, name in scan.meshes] == ["chair/train/chair_0001"]
    assert [str(s) for s in scan.skipped] == [f"{tmp_path / 'table'}: cannot read folder (Permission denied)"]
    assert find_meshes([tmp_path]) == scan.meshes


def test_unreadable_root_folder_says_so(tmp_path: Path, unreadable) -> None:
    from zbuf_occlude.mesh.inputs.discovery import scan_meshes

    _tree(tmp_path, ["data/chair_0001.off"])
    unreadable(tmp_path / "data")
    with pytest.raises(InvalidInputError, match=r"no mesh files .*skipped 1: .*data: cannot read folder \(Permission denied\)"):
        scan_meshes([tmp_path / "data"])


def test_farm_discovery_reports_unreadable_folders_but_not_hidden_ones(tmp_path: Path, unreadable) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    _tree(tmp_path, ["chair/train/chair_0001.off", "table/train/table_0001.off", ".cache/x/chair_0009.off"])
    unreadable(tmp_path / "table" / "train")
    unreadable(tmp_path / ".cache")  # hidden: never searched, so never reported
    scan = scan_objects(tmp_path)
    assert [o.name for o in scan.objects] == ["chair/train/chair_0001"]
    assert [s.path for s in scan.skipped] == [str(tmp_path / "table" / "train")]
    assert "Permission denied" in scan.skipped[0].reason


def test_generate_and_farm_entry_points_survive_a_non_utf8_name(tmp_path: Path) -> None:
    # What `generate DIR` and `farm DIR` do first: find the meshes and key each name.
    from zbuf_occlude.geometry.samples import object_key
    from zbuf_occlude.mesh.inputs.discovery import find_meshes
    from zbuf_occlude.mesh.inputs.plan import discover_objects

    _tree(tmp_path, ["chair/train/chair_0001.off", LATIN1_NAME])
    meshes = find_meshes([tmp_path])
    assert [name for _, name in meshes] == ["chair/train/chair_0001"]
    assert all(object_key(name) >= 0 for _, name in meshes)
    assert [o.name for o in discover_objects(tmp_path) if o.key >= 0] == ["chair/train/chair_0001"]


def test_find_meshes_warns_about_an_unreadable_folder(tmp_path: Path, unreadable, caplog) -> None:
    from zbuf_occlude.mesh.inputs.discovery import find_meshes

    _tree(tmp_path, ["chair/chair_0001.off", "table/table_0001.off"])
    unreadable(tmp_path / "table")
    with caplog.at_level("WARNING"):
        assert [name for _, name in find_meshes([tmp_path])] == ["chair/chair_0001"]
    assert f"{tmp_path / 'table'}: cannot read folder (Permission denied)" in caplog.text


# -- a damaged data set: an error naming the file and the field, never a KeyError or h5py's -------
@pytest.fixture(scope="module")
def tiny_ds(tmp_path_factory) -> Path:
    from conftest import tiny_dataset

    return tiny_dataset(tmp_path_factory.mktemp("tiny") / "ds")


def _edit_json(path: Path, edit) -> None:
    import json

    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc))


def _edit_first_record(ds: Path, edit) -> None:
    import json

    lines = (ds / "manifest.jsonl").read_text().splitlines()
    rec = json.loads(lines[0])
    edit(rec)
    (ds / "manifest.jsonl").write_text("\n".join([json.dumps(rec), *lines[1:]]) + "\n")


def _replace_first_shard(ds: Path, write) -> None:
    """Rewrite the first object's shard with ``write(path, old_arrays)`` and record its new SHA-256 and size."""
    import json

    import h5py

    from zbuf_occlude.io.atomic import file_sha256

    rel = json.loads((ds / "manifest.jsonl").read_text().splitlines()[0])["shards"][0]
    with h5py.File(ds / rel, "r") as f:
        old = {k: f[k][()] for k in f}
    (ds / rel).unlink()
    write(ds / rel, old)
    _edit_first_record(ds, lambda r: r.update(sha256=[file_sha256(ds / rel)], bytes=(ds / rel).stat().st_size))


def _h5(path: Path, arrays: dict) -> None:
    import h5py

    with h5py.File(path, "w") as f:
        for k, v in arrays.items():
            f[k] = v


DAMAGES = {
    "manifest line without split": (lambda ds: _edit_first_record(ds, lambda r: r.pop("split")), r"manifest\.jsonl:1.*'split'"),
    "manifest line without n_visible": (lambda ds: _edit_first_record(ds, lambda r: r.pop("n_visible")), r"manifest\.jsonl:1.*'n_visible'"),
    "empty shards list": (lambda ds: _edit_first_record(ds, lambda r: r.update(shards=[])), r"manifest\.jsonl:1.*'shards'"),
    "missing shape_names.txt": (lambda ds: (ds / "shape_names.txt").unlink(), r"shape_names\.txt is missing"),
    "card without n_points": (
        lambda ds: _edit_json(ds / "dataset_card.json", lambda c: c["params"].pop("n_points")),
        r"dataset_card\.json.*'params\.n_points'",
    ),
    "non-numeric format version": (
        lambda ds: _edit_json(ds / "dataset_card.json", lambda c: c.update(format_version="one")),
        r"dataset_card\.json.*'format_version'",
    ),
    "malformed poses": (
        lambda ds: _edit_json(ds / "dataset_card.json", lambda c: c.update(poses=[[0.0, "north"], [30.0]])),
        r"dataset_card\.json.*'poses\.0\.1'",
    ),
    "n_visible longer than the poses": (
        lambda ds: _edit_first_record(ds, lambda r: r.update(n_visible=r["n_visible"] * 3)),
        r"manifest\.jsonl:1: field 'n_visible' has 6 entries, the card has 2 poses",
    ),
    "n_visible promising more rows than the shard holds": (
        lambda ds: _replace_first_shard(ds, lambda p, old: _h5(p, {"data": old["data"][:1]})),
        r"shards/train_000000\.h5 holds fewer rows in 'data' than the manifest's field 'n_visible'",
    ),
    "a shard that is not HDF5": (
        # as large as the rows it declares (a smaller file is refused before it is opened, case below)
        lambda ds: _replace_first_shard(ds, lambda p, old: p.write_bytes(b"not hdf5\n".ljust(1 << 16, b"\0"))),
        r"shards/train_000000\.h5 is not a readable HDF5 file",
    ),
    "a shard too small for the rows it declares": (
        lambda ds: _replace_first_shard(ds, lambda p, old: p.write_text("not hdf5\n")),
        r"take 1,536 bytes, more than its shard \S*shards/train_000000\.h5 holds \(9 bytes\)",
    ),
    "a shard without data": (
        lambda ds: _replace_first_shard(ds, lambda p, old: _h5(p, {"label": old["label"]})),
        r"shards/train_000000\.h5 has no dataset 'data'",
    ),
}


@pytest.mark.parametrize("damage", sorted(DAMAGES))
def test_a_damaged_data_set_is_an_error_naming_the_file_and_field(tiny_ds: Path, tmp_path: Path, damage: str) -> None:
    import shutil

    from zbuf_occlude import OccludedDataset

    ds = Path(shutil.copytree(tiny_ds, tmp_path / "ds", symlinks=True))
    apply, message = DAMAGES[damage]
    apply(ds)
    with pytest.raises(ZbufOccludeError, match=message):
        OccludedDataset(ds).to_arrays()


# -- meshes and cameras given through the API ----------------------------------------------------
GPU_AND_EXACT = ["zbuffer", "zbuffer-tolerance", "naive-zbuffer", "oracle"]


@pytest.fixture(scope="module")
def chair_and_points():
    import zbuf_occlude as zo

    mesh = load_mesh(CHAIR)
    points, face_index = zo.sample_surface(mesh, 300, seed=0)
    return mesh, points, face_index


# The oracle's own check (visibility/oracle.py, another branch's) covers NaN/inf, not
# coordinates beyond float32; meshes from load_mesh never have them (MAX_ABS_COORDINATE).
@pytest.mark.parametrize("method, bad", [(m, b) for m in GPU_AND_EXACT for b in ("nan", "inf", "huge") if (m, b) != ("oracle", "huge")])
@pytest.mark.filterwarnings("ignore::zbuf_occlude.errors.CameraPlacementWarning")  # a vertex at 1e200 puts any camera inside the box
def test_visibility_of_a_non_finite_mesh_is_an_error_not_an_answer(chair_and_points, method: str, bad: str) -> None:
    import zbuf_occlude as zo
    from zbuf_occlude.geometry.cameras import camera_on_sphere

    mesh, points, face_index = chair_and_points
    vertices = mesh.vertices.copy()
    vertices[5] = {"nan": np.nan, "inf": np.inf, "huge": 1e200}[bad]
    broken = trimesh.Trimesh(vertices=vertices, faces=mesh.faces, process=False)
    with pytest.raises(InvalidInputError, match="NaN|inf"):
        zo.visible_mask(broken, points, camera_on_sphere(30, 45, 3.0), method, face_index=face_index, **resolution_option(method, 64))


@pytest.mark.parametrize("radius", [0.0, 0.1, 0.6])
@pytest.mark.parametrize("method", GPU_AND_EXACT)
def test_camera_inside_the_object_is_a_camera_error_naming_the_radius(chair_and_points, method: str, radius: float) -> None:
    import zbuf_occlude as zo
    from zbuf_occlude.errors import CameraError
    from zbuf_occlude.geometry.cameras import camera_on_sphere

    mesh, points, face_index = chair_and_points
    with pytest.raises(CameraError, match=rf"radius {radius} is inside the object's bounding sphere"):
        zo.visible_mask(mesh, points, camera_on_sphere(30, 45, radius), method, face_index=face_index, **resolution_option(method, 64))


@pytest.mark.parametrize("method", GPU_AND_EXACT)
def test_nan_points_are_an_error(chair_and_points, method: str) -> None:
    import zbuf_occlude as zo
    from zbuf_occlude.geometry.cameras import camera_on_sphere

    mesh, points, face_index = chair_and_points
    points = points.copy()
    points[7, 1] = np.nan
    with pytest.raises(InvalidInputError, match="NaN"):
        zo.visible_mask(mesh, points, camera_on_sphere(30, 45, 3.0), method, face_index=face_index, **resolution_option(method, 64))


EMPTY_AND_DEGENERATE = {
    "empty": trimesh.Trimesh(),
    "one_degenerate_face": trimesh.Trimesh(vertices=[[0, 0, 0], [1, 0, 0], [2, 0, 0]], faces=[[0, 1, 2]], process=False),
    "nan_vertex": trimesh.Trimesh(vertices=[[0, 0, 0], [1, np.nan, 0], [0, 1, 0]], faces=[[0, 1, 2]], process=False),
}


@pytest.mark.parametrize("name", sorted(EMPTY_AND_DEGENERATE))
def test_empty_degenerate_and_nan_meshes_cannot_be_sampled_or_normalised(name: str) -> None:
    import zbuf_occlude as zo
    from zbuf_occlude.mesh.load import clean_mesh, normalize_mesh

    mesh = EMPTY_AND_DEGENERATE[name]
    cause = {"empty": "zero total area|empty", "one_degenerate_face": "zero total area|degenerate", "nan_vertex": "NaN"}[name]
    for fn in (lambda: zo.sample_surface(mesh, 10), lambda: normalize_mesh(mesh), lambda: clean_mesh(mesh)):
        with pytest.raises(InvalidInputError, match=cause):
            fn()


def test_farm_list_file_in_a_non_utf8_folder_is_reported(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.plan import scan_objects

    folder = tmp_path / b"caf\xe9".decode("utf-8", "surrogateescape")
    _tree(folder, ["a.off"])
    listing = folder / "list.txt"
    listing.write_text("a.off chair\n")
    with pytest.raises(InvalidInputError, match=r"no mesh files .*skipped 1: .*caf\\xe9/a.off: file name is not valid UTF-8"):
        scan_objects(listing)


@pytest.mark.parametrize("ext", ["off", "ply", "obj"])
def test_unreadable_mesh_file_names_file_and_cause(tmp_path: Path, monkeypatch, ext: str) -> None:
    import builtins

    path = tmp_path / f"locked.{ext}"
    path.write_bytes(NON_UTF8_TWINS[ext][1] + _twin_body(ext))
    assert len(load_mesh(path).faces) == 4
    # chmod 000 does not stop root: make every way of opening this file fail as it would.
    real_open, real_read_bytes = builtins.open, Path.read_bytes

    def denied(*_args, **_kwargs):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(builtins, "open", lambda f, *a, **k: denied() if str(f) == str(path) else real_open(f, *a, **k))
    monkeypatch.setattr(Path, "read_bytes", lambda self: denied() if self == path else real_read_bytes(self))
    with pytest.raises(MeshLoadError, match=re.escape(str(path)) + r": cannot read file \(Permission denied\)"):
        load_mesh(path)


def test_occlude_object_refuses_a_job_that_cannot_fit_before_allocating(monkeypatch) -> None:
    import tracemalloc

    from zbuf_occlude import resources
    from zbuf_occlude.errors import InsufficientMemoryError
    from zbuf_occlude.pipeline import CameraSphere, PoseDraws, occlude_object

    monkeypatch.setattr(resources, "available_memory", lambda: (8 * 2**30, "test budget"))
    mesh = load_mesh(CHAIR)
    tracemalloc.start()
    try:
        with pytest.raises(InsufficientMemoryError, match=r"^--points needs about .*--points 1,000,000,000.*8 GiB available"):
            next(occlude_object(mesh, [(30.0, 45.0)], key=1, draws=PoseDraws(n_points=10**9, samples_per_view=10)))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2**20
    with pytest.raises(InsufficientMemoryError, match=r"--resolution"):
        big = CameraSphere(resolution=(40_000, 40_000))
        next(occlude_object(mesh, [(30.0, 45.0)], key=1, draws=PoseDraws(n_points=16, samples_per_view=1), cameras=big))


# -- the command line, end to end: checks before any mesh, skipped inputs (defects 4, 6, 7, 11, 12) --
#: One pose, one small sample: a run over the test trees takes seconds.
CLI_ARGS = ["--views", "0:0", "--resolution", "64"]
#: The subcommands, each with what it needs besides PATH and the options above.
_RUN = ["--out", "{out}", "--samples-per-view", "1", "--points", "32", "--dense-points", "500"]
CLI_COMMANDS = {"generate": _RUN, "farm": [*_RUN, "--no-progress"], "validate": ["--dense-points", "32"]}
#: The option that sizes the command's largest point array (validate holds only the dense cloud).
POINTS_OPTION = {"generate": "--points", "farm": "--points", "validate": "--dense-points"}


def _cli(command: str, path: Path, out: Path, *extra: str) -> int:
    from zbuf_occlude.cli.main import main

    tail = [a.replace("{out}", str(out)) for a in CLI_COMMANDS[command]]
    return main([command, str(path), *tail, *CLI_ARGS, *extra])


def _cli_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error:") and "\n" not in err and "Traceback" not in err, err
    return err


@pytest.fixture
def cli_tree(tmp_path: Path) -> Path:
    """Two shipped chairs (real meshes) in a ModelNet tree."""
    import shutil

    root = tmp_path / "in"
    for rel in ("chair/train/chair_0001.off", "chair/test/chair_0002.off"):
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(CHAIR, root / rel)
    return root


@pytest.mark.parametrize("command", sorted(CLI_COMMANDS))
def test_cli_a_billion_points_exits_2_naming_points_before_any_mesh(
    cli_tree: Path, tmp_path: Path, capsys, monkeypatch, no_mesh_loaded, command: str
) -> None:
    from zbuf_occlude import resources

    monkeypatch.setattr(resources, "available_memory", lambda: (2**30, "test budget"))
    option = POINTS_OPTION[command]
    # 10**8, the cap MAX_POINTS: a larger count is refused by the cap, before the memory is estimated
    assert _cli(command, cli_tree, tmp_path / "out", option, "100000000") == 2
    err = _cli_error(capsys)
    assert re.search(rf"error: {option} needs about [\d.]+ GiB of memory \({option} 100,000,000", err), err
    assert_names(err, "1 GiB available (test budget)", f"lower {option}")
    assert not (tmp_path / "out" / "records").exists()


@pytest.mark.parametrize("command", sorted(CLI_COMMANDS))
def test_cli_resolution_beyond_the_gl_maximum_exits_2_naming_the_maximum(
    cli_tree: Path, tmp_path: Path, capsys, no_mesh_loaded, gl_context, command: str
) -> None:
    from zbuf_occlude.render.context import max_image_size

    beyond = max_image_size(gl_context) + 1  # below the cap MAX_RESOLUTION, which refuses larger sizes first
    assert _cli(command, cli_tree, tmp_path / "out", "--resolution", str(beyond)) == 2
    err = _cli_error(capsys)
    assert_names(err, f"--resolution {beyond}", f"maximum image size of {max_image_size(gl_context)} pixels")


@pytest.mark.parametrize("command", sorted(CLI_COMMANDS))
def test_cli_negative_seed_exits_2_naming_the_option(cli_tree: Path, tmp_path: Path, capsys, no_mesh_loaded, command: str) -> None:
    assert _cli(command, cli_tree, tmp_path / "out", "--seed", "-1") == 2
    assert "--seed must be a non-negative integer, got -1" in _cli_error(capsys)


@pytest.mark.slow
@pytest.mark.parametrize("command", ["generate", "farm"])
def test_cli_skipped_inputs_exit_1_are_recorded_and_the_rest_is_done(
    cli_tree: Path, tmp_path: Path, capsys, unreadable, command: str
) -> None:
    import json
    import os
    import shutil

    from zbuf_occlude.dataset.layout import CARD_FILE

    latin1 = os.fsdecode(str(cli_tree).encode() + b"/chair/train/caf\xe9_0003.off")
    shutil.copy(CHAIR, latin1)
    (cli_tree / "table" / "train").mkdir(parents=True)
    shutil.copy(CHAIR, cli_tree / "table" / "train" / "table_0001.off")
    unreadable(cli_tree / "table")
    out = tmp_path / "out"
    assert _cli(command, cli_tree, out) == 1
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    card = json.loads((out / CARD_FILE).read_text())
    skipped = {s["path"]: s["reason"] for s in card["skipped_inputs"]}  # relative to the input root
    assert sorted(skipped) == ["chair/train/caf\\xe9_0003.off", "table"]
    assert "Permission denied" in skipped["table"] and "not valid UTF-8" in skipped["chair/train/caf\\xe9_0003.off"]
    assert str(cli_tree) not in (out / CARD_FILE).read_text()
    records = [json.loads(p.read_text()) for p in sorted((out / "records").glob("*.json"))]
    assert [r["status"] for r in records] == ["ok", "ok"]  # both chairs done
    report = captured.out + captured.err
    assert f"SKIPPED {cli_tree / 'table'}" in report or f"SKIPPED   {cli_tree / 'table'}" in report


def printable(path: str) -> str:
    from zbuf_occlude.mesh.paths import printable_path

    return printable_path(path)


@pytest.mark.parametrize("entry", ["generate", "farm"])
def test_two_files_with_one_name_are_refused_naming_both(tmp_path: Path, entry: str) -> None:
    # generate and the farm plan with one function (farm.inputs.number_objects)
    from zbuf_occlude.mesh.inputs.plan import scan_objects, scan_paths

    _tree(tmp_path, ["chair/train/chair_0001.off", "chair/train/chair_0002.off"])
    (tmp_path / "chair/train/chair_0001.off").rename(tmp_path / "chair/train/chair_0001.obj")
    _tree(tmp_path, ["chair/train/chair_0001.off"])
    with pytest.raises(InvalidInputError) as info:
        scan_paths([tmp_path]) if entry == "generate" else scan_objects(tmp_path)
    assert_names(info.value, "chair_0001.obj and ", "chair_0001.off are both 'chair/train/chair_0001'", "unique")


# -- issue 15: far cameras, experiment options, hostile scene files, non-UTF-8 CSVs -------------------
def _main_exit(argv: list[str], capsys) -> tuple[int, str]:
    from zbuf_occlude.cli.main import main

    code = main(argv)
    return code, capsys.readouterr().err.strip()


def test_a_camera_beyond_float64s_reach_is_refused_naming_the_limit() -> None:
    import zbuf_occlude as zo
    from zbuf_occlude.defaults import MAX_CAMERA_RADIUS
    from zbuf_occlude.errors import CameraError
    from zbuf_occlude.geometry.cameras import camera_on_sphere

    assert 1e6 <= MAX_CAMERA_RADIUS < 1e7  # derived from float64's eps and the 1e-6 tolerance
    with pytest.raises(CameraError, match=r"camera radius 1e\+08 is beyond 1\.1e\+06 object units"):
        camera_on_sphere(20, 30, 1e8)
    # within the limit the exact oracle is right: a sphere seen from afar shows about half its surface
    sphere = trimesh.creation.icosphere(subdivisions=3)
    sphere.apply_scale(0.5)
    points, face_index = zo.sample_surface(sphere, count=3000, seed=0)
    for radius in (4.0, 1e6):  # a sphere of radius r seen from distance R shows (1 - r/R) / 2 of its area
        visible = zo.visible_mask(sphere, points, camera_on_sphere(20, 30, radius), "oracle", face_index=face_index)
        assert visible.mean() == pytest.approx((1 - 0.5 / radius) / 2, abs=0.03)


def test_the_embree_oracle_stays_exact_for_a_far_eye() -> None:
    """Its ray-sphere clip lost the sphere for far eyes (90 % of a sphere called visible at 1e8)."""
    import zbuf_occlude as zo
    from zbuf_occlude.visibility.oracle_embree import occluded_embree
    from zbuf_occlude.visibility.oracle_numpy import occluded_numpy

    sphere = trimesh.creation.icosphere(subdivisions=3)
    sphere.apply_scale(0.5)
    points, face_index = zo.sample_surface(sphere, count=3000, seed=0)
    direction = np.array([np.cos(0.3) * np.cos(0.5), np.cos(0.3) * np.sin(0.5), np.sin(0.3)])
    for distance in (1e7, 1e8, 1e9):
        exact = occluded_numpy(sphere.triangles, points, distance * direction, face_index=face_index)
        assert exact.mean() == pytest.approx(0.5, abs=0.03)
        assert np.array_equal(occluded_embree(sphere, points, distance * direction, face_index=face_index), exact)


@pytest.mark.parametrize("command", ["generate", "validate", "farm"])
def test_radius_1e8_is_a_usage_error_before_any_mesh_is_loaded(tmp_path: Path, capsys, no_mesh_loaded, command) -> None:
    argv = [command, "data/samples/sofa/test/sofa_0681.off", "--radius", "1e8"]
    if command == "farm":
        argv = [command, "data/samples", "--radius", "1e8", "--no-progress"]
    if command != "validate":
        argv += ["--out", str(tmp_path / "o")]
    code, err = _main_exit(argv, capsys)
    assert code == 2 and "\n" not in err, err
    assert "--radius 1e+08" in err or "--radius 100000000.0" in err
    assert "beyond 1.1e+06 object units" in err


@pytest.mark.parametrize(
    ("option", "value"), [("--epochs", "0"), ("--points", "0"), ("--threads", "-1"), ("--threads", "0"), ("--seed", "-2")]
)
def test_experiment_options_out_of_range_are_usage_errors(tmp_path: Path, capsys, option: str, value: str) -> None:
    code, err = _main_exit(["experiment", "elevation", str(tmp_path), "--out", str(tmp_path / "o"), option, value], capsys)
    assert code == 2, err
    assert option in err and value in err and "\n" not in err
    assert not (tmp_path / "o").exists()  # refused before any work


def _nested(depth: int, suffix: str) -> str:
    if suffix == ".json":
        return '{"objects": ' + "[" * depth + "]" * depth + "}"
    return "objects: " + "[" * depth + "]" * depth + "\n"  # YAML flow sequences


@pytest.mark.parametrize("suffix", [".json", ".yaml"])
def test_a_scene_nested_10000_deep_is_an_error_naming_the_file(tmp_path: Path, suffix: str) -> None:
    if suffix == ".yaml":
        pytest.importorskip("yaml", reason="YAML scenes need the [yaml] extra (PyYAML)")
    from zbuf_occlude.sensors.scene.files import load_scene

    path = tmp_path / f"deep{suffix}"
    path.write_text(_nested(10_000, suffix))
    with pytest.raises(InvalidInputError, match=rf"deep\{suffix}.*deeper than 64 levels"):
        load_scene(path)


def _scene(tmp_path: Path, spec: dict) -> Path:
    import json

    path = tmp_path / "scene.json"
    path.write_text(json.dumps(spec))
    return path


@pytest.mark.parametrize(
    ("sections", "found"),
    [(-4, "a whole number outside that range"), (0, "a whole number outside that range"), (2, "a whole number outside that range"),
     (10**8, "a whole number outside that range"), (2.5, "a number that is not whole"), ("48", "a string of 2 characters")],
)  # fmt: skip
def test_cylinder_sections_are_checked_before_allocating(tmp_path: Path, sections, found: str) -> None:
    from zbuf_occlude.sensors.scene.object_shapes import MAX_CYLINDER_SECTIONS
    from zbuf_occlude.sensors.scene.files import load_scene

    spec = {"objects": [{"mesh": {"cylinder": {"radius_m": 0.5, "height_m": 1.0, "sections": sections}}, "position_m": [5, 0]}]}
    with pytest.raises(
        InvalidInputError,
        match=rf"scene\.json: .*sections must be an integer from 3 to {MAX_CYLINDER_SECTIONS}, got {found}$",
    ):
        load_scene(_scene(tmp_path, spec)).build()


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ({"ground": {"half_extent_m": 1e300}}, r"ground half_extent_m must be > 0 and <= 16777 metres .*got a number outside that range"),
        ({"ground": {"half_extent_m": -3}}, r"ground half_extent_m must be > 0 .*got a number outside that range"),
        ({"sensor": {"height_m": -5}}, r"sensor height_m must be >= 0 metres \(above the ground\), got a number outside that range"),
    ],
    ids=["huge-ground", "negative-ground", "sensor-below-ground"],
)
def test_scene_numbers_out_of_range_are_usage_errors_of_scan(tmp_path: Path, capsys, spec: dict, message: str) -> None:
    spec = {**spec, "objects": [{"mesh": {"box_m": [1, 1, 1]}, "position_m": [5, 0]}]}
    path = _scene(tmp_path, spec)
    code, err = _main_exit(["scan", str(path), "--sensor", "vlp16", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "\n" not in err, err
    assert re.search(message, err) and "scene.json" in err, err


def test_realism_on_a_non_utf8_csv_names_the_file(tmp_path: Path, capsys) -> None:
    real = tmp_path / "real" / "Car"
    real.mkdir(parents=True)
    header = b"origin_x,origin_y,origin_z,relative_x,relative_y,relative_z,object,complexity\n"
    (real / "car0.csv").write_bytes(header + b"100,50,200,1,1,1,Car\xe9\xff,1\n")
    code, err = _main_exit(["realism", str(real.parent), str(real.parent), "--out", str(tmp_path / "o"), "--no-figure"], capsys)
    assert code == 2 and "\n" not in err, err
    assert "car0.csv is not UTF-8" in err and "Traceback" not in err


def test_first_day_mistakes_get_messages_that_say_what_to_do(tmp_path, capsys):
    import zbuf_occlude as zo
    from zbuf_occlude.cli.main import main

    with pytest.raises(InvalidInputError, match="got PointCloud.*point cloud has no faces"):
        zo.occlude(trimesh.PointCloud(np.random.default_rng(0).random((10, 3))))
    with pytest.raises(InvalidInputError, match="no such data set folder"):
        zo.OccludedDataset(tmp_path / "missing")
    chair = Path(__file__).resolve().parents[2] / "data" / "samples" / "chair"
    assert main(["generate", str(chair), "--protocol", "modelnet40-c-occlusion", "--out", str(tmp_path / "o")]) == 2
    assert "needs a severity: --severity 1..5" in capsys.readouterr().err and not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "options, message",
    [
        (["--echo-separation", "0.75"], r"--echo-separation 0\.75 needs --footprint"),
        (["--footprint", "--echo-separation", "-1"], r"--echo-separation must be a number >= 0 metres, got -1"),
        (["--ground-margin", "0.5"], r"--ground-margin .* needs --crop"),
        (["--crop", "--ground-margin", "nan"], r"--ground-margin must be a finite number of metres, got nan"),
        (["--sensor", "hdl64e", "--footprint"], r"hdl64e's beam \(hdl64e\) has no divergence .*: give --divergence DEG"),
        (["--hidden-below", "0.5"], r"--hidden-below .* needs --crop"),
        (["--crop", "--hidden-below=-0.2:0.5"], r"--hidden-below must be >= 0 metres above the ground, got \(-0\.2, 0\.5\)"),
        (["--crop", "--hidden-below", "low"], r"--hidden-below must be a number or LO:HI, got 'low'"),
    ],
)
def test_return_physics_options_of_scan_are_usage_errors(tmp_path: Path, capsys, options: list, message: str) -> None:
    code, err = _main_exit(["scan", "box", "--out", str(tmp_path / "o"), *options], capsys)
    assert code == 2 and "\n" not in err, err
    assert re.search(message, err), err
    assert not (tmp_path / "o").exists()


def test_return_physics_options_apply_to_a_scene_file_too(tmp_path: Path, capsys) -> None:
    path = _scene(tmp_path, {"objects": [{"mesh": {"box_m": [1, 1, 1]}, "position_m": [5, 0]}]})
    code, err = _main_exit(["scan", str(path), "--sensor", "kinect-v1", "--footprint", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and re.search(r"--footprint: kinect-v1 is a depth camera, which has no beam to change", err), err
    assert not (tmp_path / "o").exists()

    def returns(name: str, *options: str) -> int:
        assert (
            _main_exit(["scan", str(path), "--sensor", "vlp16", "--format", "npz", "--out", str(tmp_path / name), *options], capsys)[0] == 0
        )
        (npz,) = (tmp_path / name).glob("*.npz")
        with np.load(npz) as data:
            return len(data["points"])

    code, err = _main_exit(["scan", str(path), "--crop", "--out", str(tmp_path / "c")], capsys)
    assert code == 2 and re.search(r"--crop keeps one mesh's returns; .* is a scene file", err), err
    # a 7-ray footprint widens the box by the divergence cone: more returns than the centre ray alone
    assert returns("wide", "--footprint") > returns("plain")
