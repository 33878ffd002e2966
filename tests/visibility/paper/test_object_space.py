"""The paper's object-space HSR methods (zbuf_occlude.visibility.paper.object_space) and the peers.

Bounds are measured on real ModelNet meshes (see docs/results for the large runs):

* ``paper-exact``, ``paper-pruned-plane``: equal to ``oracle-numpy`` point for point (same
  definition, same float64 kernel), and to ``oracle`` (Embree) on these inputs.
* ``paper-pruned`` (plane + samples rules): the samples rule is a heuristic; measured
  agreement ≥ 99.47 % per view on the meshes below; bound asserted: ≥ 99 %.
* ``og32`` / ``og64`` ("point" representative): measured mean 0.84 / ≥ 0.88 on the thin
  chair at 1500 points (≥ 0.98 / 0.99 on bathtub and sofa at 10k); asserted ≥ 0.80 / 0.86.
* ``paper-vertex``: deletes whole faces with one occluded corner, so it only ever errs
  towards hidden on closed surfaces; measured 65-99 % per view, asserted ≥ 60 %.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
from conftest import real_mesh

import zbuf_occlude as zo
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.visibility.oracle_numpy import occluded_numpy
from zbuf_occlude.visibility.paper import face_scan, occupancy, pruning, vertex
from zbuf_occlude.visibility.segment_triangle import triangle_planes

#: Small real meshes (faces): quick enough for the O(N·F) methods in CI.  Each is
#: (path in the subset, shipped substitute when the subset is absent); see conftest.
SMALL = (
    ("ModelNet40/bathtub/train/bathtub_0002.off", "ModelNet10/sofa/test/sofa_0681.off"),  # 664 (224)
    ("release_unknown/chair/train/chair_0001.off", None),  # 2234, shipped
    ("ModelNet40/bed/train/bed_0003.off", "release_unknown/bed/train/bed_0001.off"),  # 2440 (1807)
)
POSES = ((30.0, 45.0), (-40.0, 200.0), (85.0, 10.0))
N_POINTS = 1500


def _real(name: tuple[str, str | None]) -> trimesh.Trimesh:
    return zo.load_mesh(real_mesh(*name))


@pytest.fixture(scope="module", params=SMALL, ids=lambda s: Path(s[0]).stem)
def real_case(request: pytest.FixtureRequest):
    mesh = _real(request.param)
    points, face_index = zo.sample_surface(mesh, count=N_POINTS, seed=1)
    return mesh, points, face_index


def _box_behind_plate() -> trimesh.Trimesh:
    """A unit-ish plate at z = 0.3 above a box: from above, the plate hides the box's top."""
    plate = trimesh.creation.box(extents=(0.8, 0.8, 0.02))
    plate.apply_translation((0.0, 0.0, 0.3))
    box = trimesh.creation.box(extents=(0.4, 0.4, 0.4))
    box.apply_translation((0.0, 0.0, -0.2))
    return trimesh.util.concatenate([plate, box])


BACKENDS = ["numpy"] + (["numba"] if face_scan.numba_available() else [])


# -----------------------------------------------------------------------------------------
# The kernel
# -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("backend", BACKENDS)
def test_kernel_equals_oracle_numpy_pair_for_pair(backend: str) -> None:
    mesh = _box_behind_plate()
    points, fi = zo.sample_surface(mesh, count=400, seed=3)
    planes = triangle_planes(mesh.triangles)
    eye = np.array([0.3, -0.2, 4.0])
    ref = occluded_numpy(planes, points, eye, face_index=fi)
    got = face_scan.occluded_by_faces(planes, points, eye, face_index=fi, backend=backend)
    np.testing.assert_array_equal(got, ref)
    assert ref.any() and not ref.all()


@pytest.mark.parametrize("backend", BACKENDS)
def test_kernel_on_real_mesh_matches_oracle_numpy(backend: str) -> None:
    mesh = _real(SMALL[1])
    points, fi = zo.sample_surface(mesh, count=300, seed=5)
    planes = triangle_planes(mesh.triangles)
    for el, az in POSES:
        eye = zo.camera_on_sphere(el, az).eye
        np.testing.assert_array_equal(
            face_scan.occluded_by_faces(planes, points, eye, face_index=fi, backend=backend),
            occluded_numpy(planes, points, eye, face_index=fi),
        )


def test_kernel_backends_agree_with_exclusion_keys() -> None:
    if not face_scan.numba_available():
        pytest.skip("numba not installed (a core dependency: pip install -e .)")
    mesh = _real(SMALL[2])
    points, fi = zo.sample_surface(mesh, count=500, seed=2)
    planes = triangle_planes(mesh.triangles)
    eye = zo.camera_on_sphere(20.0, 130.0).eye
    key = pruning.face_keys(mesh, planes, eye, ("plane", "samples"), points, fi)
    limit = np.linalg.norm(points - eye, axis=1)
    a = face_scan.occluded_by_faces(planes, points, eye, face_index=fi, face_key=key, limit=limit, backend="numpy")
    b = face_scan.occluded_by_faces(planes, points, eye, face_index=fi, face_key=key, limit=limit, backend="numba")
    np.testing.assert_array_equal(a, b)


def test_face_order_never_changes_the_answer() -> None:
    mesh = _box_behind_plate()
    points, fi = zo.sample_surface(mesh, count=300, seed=4)
    planes = triangle_planes(mesh.triangles)
    eye = np.array([0.1, 0.2, 3.5])
    base = face_scan.occluded_by_faces(planes, points, eye, face_index=fi)
    order = np.random.default_rng(0).permutation(len(mesh.faces))
    np.testing.assert_array_equal(face_scan.occluded_by_faces(planes, points, eye, face_index=fi, order=order), base)


def test_kernel_rejects_bad_arguments() -> None:
    planes = triangle_planes(_box_behind_plate().triangles)
    pts = np.zeros((2, 3))
    with pytest.raises(InvalidInputError):
        face_scan.occluded_by_faces(planes, pts, [0, 0, 4], backend="cuda")
    with pytest.raises(InvalidInputError):
        face_scan.occluded_by_faces(planes, pts, [0, 0, 4], face_key=np.zeros(len(planes.offset)))
    with pytest.raises(InvalidInputError):
        face_scan.occluded_by_faces(planes, pts, [0, 0, 4], tolerance=-1.0)
    with pytest.raises(InvalidInputError):
        face_scan.occluded_by_faces(planes, pts, [0, 0, np.nan])


def test_plane_distance_is_a_lower_bound_of_every_corner() -> None:
    mesh = _box_behind_plate()
    planes = triangle_planes(mesh.triangles)
    eye = np.array([1.0, 2.0, 3.0])
    d = pruning.plane_distance(planes, eye)
    corners = np.linalg.norm(mesh.triangles - eye, axis=2).min(axis=1)
    assert np.all(d <= corners + 1e-12)
    assert np.allclose(pruning.min_sample_distance(np.asarray(mesh.triangles), eye), corners)


# -----------------------------------------------------------------------------------------
# The registered methods on a scene with a known answer
# -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["paper-exact", "paper-pruned", "paper-pruned-plane", "og64", "paper-vertex"])
def test_plate_hides_box_top_from_above(method: str) -> None:
    mesh = _box_behind_plate()
    camera = zo.camera_on_sphere(90.0, 0.0)
    top = np.array([[0.05, -0.05, 0.0], [-0.1, 0.1, 0.0]])  # box top, under the plate
    plate = np.array([[0.3, 0.35, 0.31], [-0.35, 0.2, 0.31]])  # plate top, in the open
    points = np.vstack([top, plate])
    fi = mesh.nearest.on_surface(points)[2]
    visible = zo.visible_mask(mesh, points, camera, method, face_index=fi)
    np.testing.assert_array_equal(visible, [False, False, True, True])


# -----------------------------------------------------------------------------------------
# Agreement with the oracle on real meshes
# -----------------------------------------------------------------------------------------
def _agreement(mesh, points, fi, method, **options) -> list[float]:
    acc = []
    for el, az in POSES:
        camera = zo.camera_on_sphere(el, az)
        ref = zo.visible_mask(mesh, points, camera, "oracle", face_index=fi)
        got = zo.visible_mask(mesh, points, camera, method, face_index=fi, **options)
        acc.append(float(np.mean(got == ref)))
    return acc


def test_paper_exact_equals_oracle_point_for_point(real_case) -> None:
    mesh, points, fi = real_case
    for el, az in POSES:
        camera = zo.camera_on_sphere(el, az)
        exact = zo.visible_mask(mesh, points, camera, "paper-exact", face_index=fi)
        np.testing.assert_array_equal(exact, zo.visible_mask(mesh, points, camera, "oracle", face_index=fi))
        np.testing.assert_array_equal(exact, zo.visible_mask(mesh, points, camera, "oracle-numpy", face_index=fi))


def test_paper_pruned_plane_is_exact(real_case) -> None:
    mesh, points, fi = real_case
    assert min(_agreement(mesh, points, fi, "paper-pruned-plane")) == 1.0


def test_paper_pruned_within_measured_bound(real_case) -> None:
    mesh, points, fi = real_case
    assert min(_agreement(mesh, points, fi, "paper-pruned")) >= 0.99


def test_og_within_measured_bound_and_improves_with_grid(real_case) -> None:
    mesh, points, fi = real_case
    og32 = np.mean(_agreement(mesh, points, fi, "og32"))
    og64 = np.mean(_agreement(mesh, points, fi, "og64"))
    assert og32 >= 0.80
    assert og64 >= 0.86
    assert og64 >= og32 - 0.005


def test_og_centre_representative_runs_and_is_worse_than_point() -> None:
    mesh = _real(SMALL[0])
    points, fi = zo.sample_surface(mesh, count=N_POINTS, seed=1)
    point = np.mean(_agreement(mesh, points, fi, "og", grid=64, representative="point"))
    centre = np.mean(_agreement(mesh, points, fi, "og", grid=64, representative="centre"))
    assert 0.8 <= centre <= point


def test_paper_vertex_within_measured_bound(real_case) -> None:
    mesh, points, fi = real_case
    assert min(_agreement(mesh, points, fi, "paper-vertex")) >= 0.60


def test_paper_vertex_subdivision_keeps_more_faces() -> None:
    # A 1 x 1 ground of two triangles whose shared corner (0.5, 0.5, 0) is hidden, seen from
    # above, by a small plate: without subdivision one occluded corner deletes both faces,
    # the whole ground; split to 0.05 only the sub-faces around the shadow go.
    ground = trimesh.Trimesh([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], [[0, 1, 2], [0, 2, 3]], process=False)
    plate = trimesh.creation.box(extents=(0.2, 0.2, 0.02))
    plate.apply_translation((0.4, 0.4, 0.2))
    mesh = trimesh.util.concatenate([ground, plate])
    camera = zo.camera_on_sphere(90.0, 0.0)
    tested, survived, parent = vertex.surviving_faces(mesh, camera)
    assert tested is mesh and np.array_equal(parent, np.arange(len(mesh.faces)))
    assert not survived[:2].any()  # the ground is gone
    tested, survived, parent = vertex.surviving_faces(mesh, camera, max_edge=0.05)
    assert len(tested.faces) > len(mesh.faces) and parent.max() == len(mesh.faces) - 1
    assert np.sqrt(tested.area_faces.max() * 2) <= 0.05 + 1e-12  # right triangles, legs <= max_edge
    kept = tested.area_faces[survived & (parent < 2)].sum()
    # measured: 0.965 of the ground kept; the exact visible fraction is 0.969, and the kept
    # sub-faces are all truly visible (the method errs only towards hidden here)
    assert 0.93 < kept <= 0.975
    centroids = tested.triangles_center[survived & (parent < 2)]
    assert not occluded_numpy(tested.triangles[parent >= 2], centroids, camera.eye).any()


def test_paper_vertex_subdivision_is_closer_to_the_oracle_on_a_real_mesh() -> None:
    # measured (800 points, POSES): agreement gains +0.05 .. +0.16 per pose with
    # max_edge=0.25 (bathtub_0002: 0.749/0.812/0.880 -> 0.879/0.953/0.931; sofa_0681:
    # 0.907/0.904/0.795 -> 0.979/0.974/0.951)
    mesh = _real(SMALL[0])
    points, fi = zo.sample_surface(mesh, count=800, seed=1)
    for el, az in POSES:
        camera = zo.camera_on_sphere(el, az)
        ref = zo.visible_mask(mesh, points, camera, "oracle", face_index=fi)
        plain = zo.visible_mask(mesh, points, camera, "paper-vertex", face_index=fi)
        split = zo.visible_mask(mesh, points, camera, "paper-vertex", face_index=fi, max_edge=0.25)
        assert np.mean(split == ref) >= np.mean(plain == ref) + 0.03, (el, az)


def test_paper_vertex_without_face_index_locates_points() -> None:
    mesh = _box_behind_plate()
    points, fi = zo.sample_surface(mesh, count=200, seed=0)
    camera = zo.camera_on_sphere(60.0, 30.0)
    np.testing.assert_array_equal(
        zo.visible_mask(mesh, points, camera, "paper-vertex"),
        zo.visible_mask(mesh, points, camera, "paper-vertex", face_index=fi),
    )


# -----------------------------------------------------------------------------------------
# Occupancy grid
# -----------------------------------------------------------------------------------------
def test_occupancy_grid_cells_contain_their_points() -> None:
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.5, 0.5, size=(2000, 3)) * [1.0, 0.5, 0.25]
    centres, cell_of, size = occupancy.occupancy_grid(points, 16)
    assert math.isclose(size, float((points.max(0) - points.min(0)).max()) / 16)
    assert np.all(np.abs(points - centres[cell_of]) <= size / 2 + 1e-12)
    assert len(np.unique(cell_of)) == len(centres)
    with pytest.raises(InvalidInputError):
        occupancy.occupancy_grid(points, 0)


def test_og_names_fix_the_grid() -> None:
    mesh = _box_behind_plate()
    points, fi = zo.sample_surface(mesh, count=500, seed=0)
    camera = zo.camera_on_sphere(30.0, 60.0)
    np.testing.assert_array_equal(
        zo.visible_mask(mesh, points, camera, "og32", face_index=fi),
        zo.visible_mask(mesh, points, camera, "og", face_index=fi, grid=32),
    )
    with pytest.raises(TypeError, match="'grid'"):  # the name fixes it: another grid is an error, not ignored
        zo.visible_mask(mesh, points, camera, "og32", face_index=fi, grid=8)


def test_options_of_other_methods_and_bad_values_raise() -> None:
    mesh = _box_behind_plate()
    points, fi = zo.sample_surface(mesh, count=50, seed=0)
    camera = zo.camera_on_sphere(30.0, 60.0)
    with pytest.raises(TypeError, match="'grid', 'resolution'"):
        zo.visible_mask(mesh, points, camera, "paper-exact", face_index=fi, resolution=512, grid=8)
    with pytest.raises(TypeError, match="'prune'"):  # paper-pruned-plane fixes it
        zo.visible_mask(mesh, points, camera, "paper-pruned-plane", face_index=fi, prune=("plane",))
    with pytest.raises(InvalidInputError):
        zo.visible_mask(mesh, points, camera, "paper-pruned", face_index=fi, prune="nearest")
    with pytest.raises(InvalidInputError):
        zo.visible_mask(mesh, points, camera, "og", face_index=fi, representative="corner")
    with pytest.raises(InvalidInputError):
        zo.visible_mask(mesh, points, camera, "paper-exact", face_index=fi, face_order="random")


# -----------------------------------------------------------------------------------------
# Peers
# -----------------------------------------------------------------------------------------
def _open3d_or_skip() -> None:
    from zbuf_occlude.visibility.peers import import_open3d

    try:
        import_open3d()
    except BackendUnavailable as exc:
        pytest.skip(str(exc))


def test_open3d_raycast_agrees_with_oracle() -> None:
    _open3d_or_skip()  # one skip for the missing extra, not one per mesh
    for name in SMALL:
        mesh = _real(name)
        points, fi = zo.sample_surface(mesh, count=N_POINTS, seed=1)
        assert min(_agreement(mesh, points, fi, "open3d-raycast")) >= 0.99, name


def test_open3d_hpr_runs() -> None:
    _open3d_or_skip()
    mesh = _real(SMALL[0])
    points, fi = zo.sample_surface(mesh, count=N_POINTS, seed=1)
    assert np.mean(_agreement(mesh, points, fi, "open3d-hpr")) >= 0.7


def test_naive_zbuffer_errs_towards_hidden() -> None:
    mesh = _real(SMALL[0])
    points, fi = zo.sample_surface(mesh, count=N_POINTS, seed=1)
    camera = zo.camera_on_sphere(30.0, 45.0)
    try:
        naive = zo.visible_mask(mesh, points, camera, "naive-zbuffer", face_index=fi, resolution=512)
    except BackendUnavailable as exc:
        pytest.skip(str(exc))
    ref = zo.visible_mask(mesh, points, camera, "oracle", face_index=fi)
    false_hidden = np.mean(~naive & ref)
    false_visible = np.mean(naive & ~ref)
    assert false_hidden > false_visible  # shadow acne: a zero tolerance loses own-surface points
