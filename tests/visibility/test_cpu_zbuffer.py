"""The CPU z-buffer pre-pass of embree-fast (zbuf_occlude.visibility.cpu_zbuffer).

Laws tested:
* soundness: every point the pre-pass settles gets the exact oracle's answer (``oracle-numpy``,
  the paper's equations in float64), on random triangle soups from random poses (hypothesis),
  on the shipped meshes, with and without ``face_index``, for points on and off the surface;
* the frustum test is :meth:`Camera.in_frustum`'s, bit for bit;
* the pre-pass settles most points (it is not a stub that leaves everything to the rays);
* embree-fast with the pre-pass equals embree-fast without it up to float32 ray residue, and
  its kept scene (Morton-sorted) equals its one-shot call bit for bit;
* per-mesh state is built once: a second call on the same mesh rebuilds neither the Embree
  scene nor the face data (builds counted), an edited mesh rebuilds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude as zo
from zbuf_occlude.visibility import cpu_zbuffer, embree_fast, visible_mask
from zbuf_occlude.visibility.definition import TOLERANCE
from zbuf_occlude.visibility.embree_fast import FastScene

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"


def _soup(seed: int, n_faces: int) -> trimesh.Trimesh:
    """Random triangles in the unit box: sizes from 0.005 to 0.6, some slivers (one edge 1e-4
    of the others), some seen edge-on from the axes (a zero coordinate spread), and a floor."""
    rng = np.random.default_rng(seed)
    centre = rng.uniform(-0.4, 0.4, (n_faces, 1, 3))
    size = np.exp(rng.uniform(np.log(0.005), np.log(0.6), (n_faces, 1, 1)))
    tri = centre + size * rng.normal(size=(n_faces, 3, 3))
    sliver = rng.random(n_faces) < 0.2
    tri[sliver, 2] = tri[sliver, 1] + 1e-4 * (tri[sliver, 2] - tri[sliver, 1])
    flat = rng.random(n_faces) < 0.1
    tri[flat, :, 1] = tri[flat, :1, 1]  # in a plane y = const: edge-on from azimuth 0, elevation 0
    floor = np.array([[[-0.6, -0.6, -0.5], [0.6, -0.6, -0.5], [0.6, 0.6, -0.5]], [[-0.6, -0.6, -0.5], [0.6, 0.6, -0.5], [-0.6, 0.6, -0.5]]])
    tri = np.concatenate([tri, floor])
    return trimesh.Trimesh(tri.reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3), process=False)


def _check_settled(mesh, points, fi, cam, cells_per_point=cpu_zbuffer.CELLS_PER_POINT) -> float:
    """Assert every settled point equals the exact oracle; return the settled fraction."""
    zb = cpu_zbuffer.build_zbuffer(mesh, cam, len(points), cells_per_point=cells_per_point)
    status = cpu_zbuffer.classify(mesh, points, fi, cam, zb, TOLERANCE)
    truth = visible_mask(mesh, points, cam, "oracle-numpy", face_index=fi)
    visible, hidden = status == cpu_zbuffer.VISIBLE, status == cpu_zbuffer.HIDDEN
    assert not (visible & ~truth).any(), np.flatnonzero(visible & ~truth)
    assert not (hidden & truth).any(), np.flatnonzero(hidden & truth)
    # outside the frustum is HIDDEN, exactly as Camera.in_frustum says
    assert np.array_equal(status[~cam.in_frustum(points)], np.full((~cam.in_frustum(points)).sum(), cpu_zbuffer.HIDDEN))
    return float((status != cpu_zbuffer.UNDECIDED).mean())


@pytest.mark.filterwarnings("ignore::zbuf_occlude.errors.CameraPlacementWarning")  # the drawn camera may stand inside the soup's box
@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n_faces=st.integers(1, 120),
    el=st.floats(-89.0, 89.0),
    az=st.floats(0.0, 360.0),
    radius=st.floats(0.9, 6.0),
    resolution=st.sampled_from([16, 64, 256, 1024]),
    cells_per_point=st.sampled_from([0.05, 0.5, 2.0, 8.0]),
)
def test_settled_points_get_the_oracles_answer_on_random_soups(seed, n_faces, el, az, radius, resolution, cells_per_point):
    mesh = _soup(seed, n_faces)
    cam = zo.camera_on_sphere(el, az, radius, resolution=resolution)
    points, fi = zo.sample_surface(mesh, 1500, seed=seed % 1000)
    _check_settled(mesh, points, fi, cam, cells_per_point)
    _check_settled(mesh, points, None, cam, cells_per_point)
    # points off the surface (no face_index): the proofs do not assume a point is on a face
    rng = np.random.default_rng(seed)
    _check_settled(mesh, rng.uniform(-0.7, 0.7, (500, 3)), None, cam, cells_per_point)


def test_edge_on_faces_and_axis_poses_are_settled_exactly():
    mesh = _soup(7, 80)
    points, fi = zo.sample_surface(mesh, 3000, seed=1)
    for el, az in ((0.0, 0.0), (0.0, 90.0), (90.0, 0.0), (-90.0, 0.0)):
        cam = zo.camera_on_sphere(el, az, resolution=128)
        _check_settled(mesh, points, fi, cam)
        _check_settled(mesh, points, None, cam)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["chair/train/chair_0001.off", "sofa", "bathtub", "table"])
def test_settled_points_get_the_oracles_answer_on_shipped_meshes(name):
    path = SAMPLES / name if name.endswith(".off") else sorted((SAMPLES / name).rglob("*.off"))[0]
    mesh = zo.load_mesh(path)
    points, fi = zo.sample_surface(mesh, 20000, seed=2)
    settled = []
    for el, az in ((30.0, 20.0), (-60.0, 200.0), (0.0, 90.0), (85.0, 300.0)):
        cam = zo.camera_on_sphere(el, az, resolution=512)
        settled.append(_check_settled(mesh, points, fi, cam))
        _check_settled(mesh, points, None, cam)
    assert np.mean(settled) > 0.5, settled  # most points need no ray


def test_a_mesh_behind_the_camera_plane_gets_no_buffer():
    mesh = trimesh.creation.box([1.0, 1.0, 1.0])
    cam = zo.camera_on_sphere(20.0, 30.0, 0.6, resolution=64, bounding_radius=0.5)  # eye inside the box
    points, fi = zo.sample_surface(mesh, 500, seed=0)
    zb = cpu_zbuffer.build_zbuffer(mesh, cam, len(points))
    assert zb.shape == (0, 0)
    status = cpu_zbuffer.classify(mesh, points, fi, cam, zb, 1e-6)
    assert set(np.unique(status)) <= {cpu_zbuffer.HIDDEN, cpu_zbuffer.UNDECIDED}
    assert np.array_equal(status == cpu_zbuffer.UNDECIDED, cam.in_frustum(points))


class _Bands:
    """A ``run`` that rasterises its bands one after the other, recording the cuts."""

    def __init__(self, bands: int):
        self.bands, self.cuts = bands, []

    def __call__(self, fn, args_list) -> None:
        for args in args_list:
            self.cuts.append((args[6], args[7]))  # row_lo, row_hi of _rasterise
            fn(*args)


def test_the_buffer_does_not_depend_on_the_raster_bands():
    # A face within one cell's rows of the grid but reaching across a band's cut went down
    # the one-cell path in each band (a looser bound than the face's own plane gives), so
    # the buffer, and the points it settles, changed with the thread count.
    mesh = trimesh.creation.icosphere(subdivisions=4)
    for el, az in ((10.0, 30.0), (-35.0, 200.0)):
        cam = zo.camera_on_sphere(el, az, resolution=256)
        one = cpu_zbuffer.build_zbuffer(mesh, cam, 20000)
        for bands in (2, 3, 7):
            run = _Bands(bands)
            split = cpu_zbuffer.build_zbuffer(mesh, cam, 20000, run=run)
            assert [lo for lo, _ in run.cuts[1:]] == [hi for _, hi in run.cuts[:-1]]
            assert np.array_equal(one.zbuf.view(np.uint32), split.zbuf.view(np.uint32)), (el, az, bands)


def test_the_grouped_points_do_not_depend_on_the_gather_slices():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(1001, 3))
    face_index = rng.integers(0, 37, 1001)
    perm, grouped, faces = cpu_zbuffer.group_by_face(points, face_index, 37)
    assert np.array_equal(perm, np.argsort(face_index, kind="stable"))
    assert np.array_equal(grouped, points[perm]) and np.array_equal(faces, face_index[perm])
    for bands in (2, 3, 7):
        run = _Slices(bands)
        split = cpu_zbuffer.group_by_face(points, face_index, 37, run=run)
        assert len(run.calls) == bands
        assert all(np.array_equal(a, b) for a, b in zip(split, (perm, grouped, faces)))


class _Slices:
    """A ``run`` that calls each slice in this thread, counting them."""

    def __init__(self, bands: int):
        self.bands, self.calls = bands, []

    def __call__(self, fn, args_list) -> None:
        for args in args_list:
            self.calls.append(args)
            fn(*args)


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 4), st.lists(st.integers(-5, 5), max_size=12))
def test_the_shared_runner_returns_every_result_in_order(threads, values):
    import threading

    seen = set()

    def square(x):
        seen.add(threading.get_ident())
        return x * x

    assert embree_fast._run_shared(threads, square, [(v,) for v in values]) == [v * v for v in values]
    assert len(seen) <= max(threads, 1)


def test_the_shared_runner_raises_what_a_task_raises():
    def fail_on_three(x):
        if x == 3:
            raise ValueError("three")
        return x

    with pytest.raises(ValueError, match="three"):
        embree_fast._run_shared(2, fail_on_three, [(k,) for k in range(6)])


def test_embree_fast_with_and_without_the_pre_pass_and_sorted_or_not():
    mesh = zo.load_mesh(SAMPLES / "chair/train/chair_0001.off")
    points, fi = zo.sample_surface(mesh, 5000, seed=3)
    for el, az in ((10.0, 0.0), (-45.0, 120.0)):
        cam = zo.camera_on_sphere(el, az)
        truth = visible_mask(mesh, points, cam, "oracle", face_index=fi)
        kept = FastScene(mesh, points, fi, sort=True)
        got = kept.visible(cam)
        assert kept.last_ray_fraction < 0.5
        one_shot = visible_mask(mesh, points, cam, "embree-fast", face_index=fi)
        assert np.array_equal(got, one_shot)
        plain = FastScene(mesh, points, fi, prepass=False)
        without = plain.visible(cam)
        assert plain.last_ray_fraction == 1.0
        assert (got == truth).mean() >= 0.9995 and (without == truth).mean() >= 0.9995
        assert (got == without).mean() >= 0.9995


def _count_builds(monkeypatch, cls, cache) -> list:
    """Count constructions of ``cls`` (however they are reached) after emptying ``cache``."""
    built = []
    init = cls.__init__

    def counting(self, mesh, *args, **kwargs):
        built.append(id(mesh))
        init(self, mesh, *args, **kwargs)

    monkeypatch.setattr(cls, "__init__", counting)
    cache.clear()
    return built


def test_a_second_call_on_a_mesh_rebuilds_nothing(monkeypatch):
    mesh = zo.load_mesh(SAMPLES / "chair/train/chair_0001.off")
    points, fi = zo.sample_surface(mesh, 2000, seed=4)
    scenes = _count_builds(monkeypatch, embree_fast._Scene, embree_fast._scenes)
    data = _count_builds(monkeypatch, cpu_zbuffer._MeshData, cpu_zbuffer._mesh_data)
    cams = [zo.camera_on_sphere(el, az) for el, az in ((10.0, 0.0), (40.0, 90.0), (-30.0, 200.0))]
    # embree-fast named: on a GPU machine the default may be zbuffer-exact, which builds neither
    first = [visible_mask(mesh, points, c, "embree-fast", face_index=fi) for c in cams]
    assert len(data) == 1 and len(scenes) == 1
    again = [visible_mask(mesh, points, c, "embree-fast", face_index=fi) for c in cams]
    assert len(data) == 1 and len(scenes) == 1
    assert all(np.array_equal(a, b) for a, b in zip(first, again))
    mesh.vertices = mesh.vertices * 1.01  # an edit: new content hash
    visible_mask(mesh, points, cams[0], "embree-fast", face_index=fi)
    assert len(data) == 2 and len(scenes) == 2


def _visible_in_child(mesh, points, face_index, queue) -> None:
    camera = zo.camera_on_sphere(elevation_deg=20.0, azimuth_deg=30.0, radius=4.0)
    queue.put(zo.visible_mask(mesh, points, camera, face_index=face_index, method="embree-fast").sum())


def test_a_forked_child_gets_its_own_thread_pool():
    """A DataLoader worker is a forked child: it inherits embree-fast's thread pool object but not
    its threads, and a view submitted to that pool waited forever."""
    import multiprocessing as mp

    mesh = zo.load_mesh(SAMPLES / "chair/train/chair_0001.off")
    points, face_index = zo.sample_surface(mesh, count=20_000, seed=0)
    camera = zo.camera_on_sphere(elevation_deg=20.0, azimuth_deg=30.0, radius=4.0)
    expected = zo.visible_mask(mesh, points, camera, face_index=face_index, method="embree-fast").sum()  # pool made here
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_visible_in_child, args=(mesh, points, face_index, queue))
    child.start()
    child.join(timeout=120)
    hung = child.is_alive()
    if hung:
        child.kill()
    assert not hung, "the forked child's view never finished"
    assert child.exitcode == 0 and queue.get(timeout=5) == expected


# -- the one-shot call's steps: raster bands cut by work, the grouping beside them ----------------


def _tower() -> trimesh.Trimesh:
    """A dense sphere (20,480 faces) on top of a 12-face box: seen from the side, nearly all the
    raster's work is in the rows of the sphere."""
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=0.2)
    sphere.apply_translation((0.0, 0.0, 0.3))
    box = trimesh.creation.box(extents=(0.8, 0.8, 0.3))
    box.apply_translation((0.0, 0.0, -0.3))
    return trimesh.util.concatenate([sphere, box])


def _row_work(mesh: trimesh.Trimesh, cam, zb) -> np.ndarray:
    """(rows,) int: the (face, row) pairs of each row of the grid, plus one (numpy, from scratch)."""
    rt = cam.extrinsics
    v = np.asarray(mesh.vertices) @ rt[:, :3].T + rt[:, 3]
    row = ((v[:, 1] / v[:, 2] - zb.grid[1]) * zb.grid[3])[np.asarray(mesh.faces)]
    lo = np.clip(np.floor(row.min(axis=1) - 1e-3), 0, None).astype(int)
    hi = np.clip(np.floor(row.max(axis=1) + 1e-3), None, zb.shape[1] - 1).astype(int)
    diff = np.zeros(zb.shape[1] + 1, dtype=int)
    np.add.at(diff, lo[lo <= hi], 1)
    np.add.at(diff, hi[lo <= hi] + 1, -1)
    return np.cumsum(diff)[:-1] + 1


def test_the_raster_bands_are_cut_by_work_not_by_rows():
    # Cut in equal numbers of rows, the band with the sphere had all the work and the other
    # thread waited for it.
    mesh = _tower()
    cam = zo.camera_on_sphere(0.0, 30.0, resolution=256)
    for bands in (2, 3, 4):
        run = _Bands(bands)
        zb = cpu_zbuffer.build_zbuffer(mesh, cam, 50_000, run=run)
        work = _row_work(mesh, cam, zb)
        per_band = [work[lo:hi].sum() for lo, hi in run.cuts]
        assert max(per_band) <= 1.1 * work.sum() / bands + work.max(), (bands, per_band)


def test_the_buffer_does_not_depend_on_the_bands_or_on_a_grouping_beside_them():
    mesh = _tower()
    for el, az in ((0.0, 30.0), (50.0, 200.0)):
        cam = zo.camera_on_sphere(el, az, resolution=256)
        one = cpu_zbuffer.build_zbuffer(mesh, cam, 30_000)
        for bands in (1, 2, 3, 5):
            for grouping in (0, 30_000, 10**7):  # a grouping heavier than a band leaves the last one empty
                zb, tasks = cpu_zbuffer.zbuffer_tasks(mesh, cam, 30_000, bands=bands, grouping=grouping)
                rows = [(args[6], args[7]) for _, args in tasks]
                assert rows[0][0] == 0 and rows[-1][1] == zb.shape[1] and all(a[1] == b[0] for a, b in zip(rows, rows[1:]))
                for fn, args in reversed(tasks):  # any order
                    fn(*args)
                assert np.array_equal(one.zbuf.view(np.uint32), zb.zbuf.view(np.uint32)), (el, az, bands, grouping)


def test_the_view_extent_is_numpys_over_the_vertices_the_faces_use():
    rng = np.random.default_rng(5)
    mesh = _tower()
    # many unused vertices far from the faces (more than three per face): they must not count
    cloud = trimesh.Trimesh(
        np.concatenate([mesh.vertices, rng.normal(size=(3 * len(mesh.faces) + 10, 3)) * 0.3 + 0.1]), mesh.faces, process=False
    )
    for m in (mesh, cloud):
        data = cpu_zbuffer._mesh_data(m)
        rt = np.ascontiguousarray(zo.camera_on_sphere(20.0, 40.0).extrinsics)
        cam, extent = cpu_zbuffer._to_camera(data.vertices, rt, data.used)
        used = cam[np.unique(m.faces)]
        expected = [used[:, 2].min(), np.abs(used[:, 2]).max(), used[:, 3].min(), used[:, 3].max(), used[:, 4].min(), used[:, 4].max()]
        assert extent.tolist() == expected


def test_the_grouping_task_gives_group_by_faces_arrays():
    rng = np.random.default_rng(1)
    points = rng.normal(size=(1001, 3))
    face_index = rng.integers(0, 37, 1001)
    *arrays, (fn, args) = cpu_zbuffer.group_task(points, face_index, 37)
    fn(*args)
    assert all(np.array_equal(a, b) for a, b in zip(arrays, cpu_zbuffer.group_by_face(points, face_index, 37)))


def test_a_one_shot_scene_gives_the_same_masks_whatever_the_threads_and_groups_its_points_when_read():
    mesh = zo.load_mesh(SAMPLES / "chair/train/chair_0001.off")
    points, fi = zo.sample_surface(mesh, 20_000, seed=6)
    cams = [zo.camera_on_sphere(el, az, radius) for el, az, radius in ((15.0, 20.0, 4.0), (-40.0, 250.0, 1.2))]
    for cam in cams:
        masks = [embree_fast.embree_fast_visible(mesh, points, cam, face_index=fi, threads=t) for t in (1, 2, 3)]
        assert all(np.array_equal(masks[0], m) for m in masks[1:])
        scene = FastScene(mesh, points, fi, sort=False, threads=2)
        assert np.array_equal(scene.visible(cam), masks[0])
        assert np.array_equal(scene.visible(cam), masks[0])  # a second view: the points already grouped
    unread = FastScene(mesh, points, fi, sort=False)
    perm, grouped, faces = cpu_zbuffer.group_by_face(points, fi, len(mesh.faces))
    assert np.array_equal(unread.points, grouped) and np.array_equal(unread.face_index, faces)


def test_a_view_computes_the_cameras_extrinsics_once():
    import dataclasses

    mesh = zo.load_mesh(SAMPLES / "chair/train/chair_0001.off")
    points, fi = zo.sample_surface(mesh, 5000, seed=7)
    cam = zo.camera_on_sphere(25.0, 60.0)
    calls = []

    class Counting(type(cam)):
        @property
        def extrinsics(self):
            calls.append(1)
            return super().extrinsics

    counting = Counting(**{f.name: getattr(cam, f.name) for f in dataclasses.fields(cam) if f.init})
    expected = FastScene(mesh, points, fi, sort=False, threads=1).visible(cam)
    got = FastScene(mesh, points, fi, sort=False, threads=1).visible(counting)
    assert np.array_equal(got, expected) and len(calls) == 1


def test_embree_fast_casts_its_rays_in_the_oracles_bvh_and_groups_the_faces_once(monkeypatch):
    """One Embree BVH and one grouping of identical faces per mesh, shared by the rays, the
    pre-pass's raster and the oracle's re-checks; the masks are those of a fresh grouping."""
    from zbuf_occlude.geometry.grouping import exact_face_groups
    from zbuf_occlude.visibility import oracle_embree

    base = zo.load_mesh(SAMPLES / "chair/train/chair_0001.off")
    faces = np.concatenate([base.faces, base.faces[:50]])  # 50 stacked copies
    mesh = trimesh.Trimesh(base.vertices, faces, process=False)
    points, fi = zo.sample_surface(mesh, 3000, seed=8)
    groupings = []
    monkeypatch.setattr(cpu_zbuffer, "exact_face_groups", lambda t: groupings.append(1) or exact_face_groups(t))
    oracles = _count_builds(monkeypatch, oracle_embree._EmbreeScene, oracle_embree._scenes)
    embree_fast._scenes.clear()
    cpu_zbuffer._mesh_data.clear()
    cam = zo.camera_on_sphere(20.0, 30.0)
    got = FastScene(mesh, points, fi, threads=1).visible(cam)
    assert len(oracles) == 1 and not groupings
    assert embree_fast._scenes(mesh).scene is oracle_embree.scene_for(mesh).scene
    listed = np.flatnonzero(exact_face_groups(mesh.triangles) == np.arange(len(mesh.faces)))
    assert embree_fast._scenes(mesh).n_faces_in_bvh == len(listed) == len(base.faces)
    assert np.array_equal(cpu_zbuffer._mesh_data(mesh).raster_ids, listed)
    assert (got == visible_mask(mesh, points, cam, "oracle", face_index=fi)).mean() >= 0.9995


def test_the_default_threads_change_the_threads_not_the_masks():
    mesh = zo.load_mesh(SAMPLES / "chair/train/chair_0001.off")
    points, fi = zo.sample_surface(mesh, 5000, seed=9)
    cam = zo.camera_on_sphere(-20.0, 140.0)
    before = embree_fast.DEFAULT_THREADS
    try:
        masks = []
        for threads in (1, 3):
            embree_fast.set_default_threads(threads)
            scene = FastScene(mesh, points, fi)
            assert scene.threads == threads
            masks.append(scene.visible(cam))
        assert np.array_equal(masks[0], masks[1])
        assert FastScene(mesh, points, fi, threads=2).threads == 2  # an explicit count wins
        with pytest.raises(zo.InvalidInputError):
            embree_fast.set_default_threads(0)
    finally:
        embree_fast.set_default_threads(before)
