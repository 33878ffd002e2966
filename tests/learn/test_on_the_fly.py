"""Occlusion on the fly (zbuf_occlude.learn.on_the_fly, learn.pyg): determinism, visibility, workers, training."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from zbuf_occlude.errors import InvalidInputError  # noqa: E402
from zbuf_occlude.geometry.cameras import camera_on_sphere  # noqa: E402
from zbuf_occlude.geometry.samples import object_key
from zbuf_occlude.learn import OnTheFlyOccludedDataset, PoseDistribution, RandomOcclusion  # noqa: E402
from zbuf_occlude.learn.models import PointNet  # noqa: E402
from zbuf_occlude.mesh.inputs.kinds import MESH, POINT_SET  # noqa: E402
from zbuf_occlude.mesh.load import load_mesh  # noqa: E402
from zbuf_occlude.pipeline import dense_cloud  # noqa: E402
from zbuf_occlude.protocols import modelnet40c  # noqa: E402
from zbuf_occlude.visibility.registry import visible_mask  # noqa: E402

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
CHAIR = SAMPLES / "chair" / "train" / "chair_0001.off"


@pytest.fixture(scope="module")
def chair():
    mesh = load_mesh(CHAIR)
    return mesh, dense_cloud(mesh, object_key("chair"), count=4096)


def test_same_seed_epoch_index_same_sample(chair):
    mesh, dense = chair
    a, b = RandomOcclusion(512, seed=3), RandomOcclusion(512, seed=3)
    s1, s2 = a(mesh, dense, 5), b(mesh, dense, 5)
    assert np.array_equal(s1["points"], s2["points"]) and s1["elevation_deg"] == s2["elevation_deg"]
    a.set_epoch(1)
    s3 = a(mesh, dense, 5)
    assert s3["elevation_deg"] != s1["elevation_deg"] and not np.array_equal(s3["points"], s1["points"])
    assert a(mesh, dense, 6)["azimuth_deg"] != s3["azimuth_deg"]


def test_sample_holds_only_visible_points(chair):
    mesh, dense = chair
    t = RandomOcclusion(256, seed=1, normalize=False)
    for index in range(4):
        s = t(mesh, dense, index)
        camera = camera_on_sphere(s["elevation_deg"], s["azimuth_deg"], t.poses.radius, resolution=64)
        oracle = visible_mask(mesh, dense.points, camera, "oracle", face_index=dense.face_index)
        assert s["n_visible"] == oracle.sum()
        seen = {tuple(p) for p in dense.points[oracle].astype(np.float32)}
        assert all(tuple(p) in seen for p in s["points"])
        # every visible point is taken once before any repeat
        assert len(np.unique(s["points"], axis=0)) == min(256, s["n_visible"])


def test_pose_distributions_are_stated():
    rng = np.random.default_rng(0)
    band = PoseDistribution((10.0, 20.0), (30.0, 40.0), 3.0)
    draws = np.array([band.draw(rng) for _ in range(2000)])
    assert draws[:, 0].min() >= 10 and draws[:, 0].max() <= 20 and draws[:, 1].min() >= 30 and draws[:, 1].max() <= 40
    # uniform in area: sin(el) uniform, so the median elevation is asin of the mean of the sines
    mid = np.degrees(np.arcsin((np.sin(np.radians(10)) + np.sin(np.radians(20))) / 2))
    assert abs(np.median(draws[:, 0]) - mid) < 0.3
    with pytest.raises(InvalidInputError):
        PoseDistribution((20.0, 10.0))


@pytest.mark.parametrize("severity", [1, 3, 5])
def test_modelnet40c_distribution_covers_their_cameras(severity):
    dist = PoseDistribution.modelnet40c(severity)
    rs = np.random.RandomState(severity)
    for _ in range(50):
        centre = np.linalg.inv(modelnet40c.occlusion_pose(severity, rs))[:3, 3]  # camera centre, their units
        el = np.degrees(np.arcsin(centre[2] / np.linalg.norm(centre)))
        az = np.degrees(np.arctan2(centre[1], centre[0]))
        assert dist.elevation_deg[0] - 1e-9 <= el <= dist.elevation_deg[1] + 1e-9
        assert abs((az - dist.azimuth_deg[0]) % 360.0) <= dist.azimuth_deg[1] - dist.azimuth_deg[0] + 1e-9
        assert np.isclose(np.linalg.norm(centre) / 2.0, dist.radius)  # their max extent is 2, ours 1


def test_dataset_labels_and_splits_match_the_farm():
    from zbuf_occlude.mesh.inputs.plan import scan_paths

    ds = OnTheFlyOccludedDataset(SAMPLES, split="test", n_points=128, dense_points=2048)
    objects, _ = scan_paths([SAMPLES])
    expected = {o.name: o.label for o in objects if o.split == "test"}
    assert {o.name: o.label for o in ds.objects} == expected and len(ds) == len(expected)
    with pytest.raises(InvalidInputError, match="'nope'"):
        OnTheFlyOccludedDataset(SAMPLES, split="nope")


def _epoch(ds, workers):
    # spawn: the parent has rendered (threads of the renderer and Embree); a fork then can deadlock a worker
    extra = {"multiprocessing_context": "spawn", "timeout": 300} if workers else {}
    loader = torch.utils.data.DataLoader(ds, batch_size=4, num_workers=workers, shuffle=False, **extra)
    return torch.cat([x for x, _ in loader]).numpy()


@pytest.mark.slow
def test_dataloader_workers_give_the_single_process_samples():
    ds = OnTheFlyOccludedDataset(SAMPLES, n_points=256, dense_points=4096, seed=2)
    ds.set_epoch(4)
    single = _epoch(ds, 0)
    assert np.array_equal(_epoch(ds, 2), single)
    ds.set_epoch(5)
    assert not np.array_equal(_epoch(ds, 2), single)


@pytest.mark.slow
def test_random_occlusion_trains_pointnet_for_one_epoch():
    torch.manual_seed(0)
    ds = OnTheFlyOccludedDataset(SAMPLES, n_points=512, dense_points=8192, views_per_object=2)
    model = PointNet(n_classes=len(ds.shape_names), width=0.25)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    before = [p.detach().clone() for p in model.parameters()]
    losses = []
    ds.set_epoch(0)
    for x, y in torch.utils.data.DataLoader(
        ds, batch_size=4, shuffle=True, num_workers=2, drop_last=True, multiprocessing_context="spawn", timeout=300
    ):
        loss = torch.nn.functional.cross_entropy(model(x), y) + model.regularizer
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert len(losses) == len(ds) // 4 and all(np.isfinite(losses))
    assert any(not torch.equal(a, b) for a, b in zip(before, model.parameters()))


def test_pyg_transform():
    pytest.importorskip("torch_geometric")
    from torch_geometric.data import Data

    from zbuf_occlude.learn.pyg import OccludeMesh

    mesh = load_mesh(CHAIR)
    data = Data(pos=torch.tensor(mesh.vertices * 7.0 + 3.0, dtype=torch.float32), face=torch.tensor(mesh.faces.T), y=torch.tensor([8]))
    t = OccludeMesh(300, dense_points=4096, seed=1)
    out = t(data)
    assert out.pos.shape == (300, 3) and out.y.tolist() == [8] and getattr(out, "face", None) is None
    assert torch.equal(t(data).pos, out.pos)  # (seed, epoch, mesh content) decide the view
    t.set_epoch(1)
    assert not torch.equal(t(data).pos, out.pos)
    with pytest.raises(InvalidInputError, match="mesh Data"):
        t(Data(pos=torch.zeros(4, 2)))


@pytest.mark.slow
def test_epoch_sampler_carries_the_epoch_to_persistent_workers():
    from zbuf_occlude.learn import EpochSampler

    ds = OnTheFlyOccludedDataset(SAMPLES, n_points=128, dense_points=2048, seed=4)
    sampler = EpochSampler(ds)
    loader = torch.utils.data.DataLoader(
        ds, batch_size=4, sampler=sampler, num_workers=2, persistent_workers=True, multiprocessing_context="spawn", timeout=300
    )
    epochs = []
    for epoch in (0, 1):
        sampler.set_epoch(epoch)
        epochs.append(torch.cat([x for x, _ in loader]).numpy())
        ds.set_epoch(epoch)
        assert np.array_equal(epochs[-1], np.stack([ds.sample(i)["points"] for i in range(len(ds))]))
    assert not np.array_equal(epochs[0], epochs[1])
    shuffled = EpochSampler(ds, shuffle=True, seed=1)
    assert sorted(i for _, i in shuffled) == list(range(len(ds))) and list(shuffled) == list(EpochSampler(ds, shuffle=True, seed=1))


@pytest.mark.slow
@pytest.mark.parametrize("context", ["fork", "spawn"])
def test_set_epoch_reaches_persistent_workers(context):
    """The usual pattern: ds.set_epoch(e) before each epoch, persistent workers, no special sampler."""
    ds = OnTheFlyOccludedDataset(SAMPLES, n_points=64, dense_points=1024, seed=2)
    loader = torch.utils.data.DataLoader(
        ds, batch_size=4, num_workers=2, persistent_workers=True, multiprocessing_context=context, timeout=300
    )
    epochs = []
    for epoch in (0, 1):
        ds.set_epoch(epoch)
        epochs.append(torch.cat([x for x, _ in loader]).numpy())
        assert np.array_equal(epochs[-1], np.stack([ds.sample(i)["points"] for i in range(len(ds))]))
    assert not np.array_equal(epochs[0], epochs[1])


def test_a_copied_data_set_keeps_its_epoch_but_not_the_link():
    import copy

    ds = OnTheFlyOccludedDataset(SAMPLES, n_points=64, dense_points=1024)
    ds.set_epoch(3)
    twin = copy.deepcopy(ds)
    assert twin.occlusion.epoch == 3
    ds.set_epoch(4)
    assert (ds.occlusion.epoch, twin.occlusion.epoch) == (4, 3)


# -- point sets: clouds without a mesh -------------------------------------------------------------
from zbuf_occlude.io.point_sets import PointSet, read_point_sets  # noqa: E402

SPHERE_CENTRE, SPHERE_RADIUS = np.array([2.0, -1.0, 5.0]), 3.0


def _sphere_points(n: int = 4000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Points uniform on a sphere of radius 3 around (2, -1, 5) (any frame and units), and their normals."""
    normals = np.random.default_rng(seed).normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return SPHERE_CENTRE + SPHERE_RADIUS * normals, normals


def _truly_visible(points: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """The visible cap of the sphere, in the poses' frame (bounding box centred, maximum extent 1: radius 0.5)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    q = (points - (lo + hi) / 2) / (hi - lo).max()
    return q @ eye > 0.25  # p · eye > r²: the tangent cone from the eye


@pytest.mark.parametrize("with_normals", [True, False])
def test_a_sphere_point_set_keeps_the_visible_cap(with_normals):
    points, normals = _sphere_points()
    cloud = PointSet(points, normals if with_normals else None, None, "sphere")
    t = RandomOcclusion(len(points), seed=5, normalize=False)
    for index in range(4):
        s = t(cloud, index=index)
        eye = camera_on_sphere(s["elevation_deg"], s["azimuth_deg"], t.poses.radius, resolution=64).eye
        truth = _truly_visible(points, eye)
        assert abs(s["n_visible"] - truth.sum()) <= 0.05 * len(points), (s["n_visible"], truth.sum())
        kept = np.unique(s["point_index"])  # n_points = N: every visible point is drawn
        seen = np.isin(np.arange(len(points)), kept)
        assert len(kept) == s["n_visible"] and (seen == truth).mean() >= 0.95  # the splats' reach at the silhouette
        back = (points - SPHERE_CENTRE) @ eye / np.linalg.norm(eye) < -0.5 * SPHERE_RADIUS  # far behind the horizon
        assert seen[back].mean() < 0.01
        # the sample is rows of the cloud, in its own frame, with their normals
        assert np.array_equal(s["points"], points[s["point_index"]].astype(np.float32))
        if with_normals:
            assert np.array_equal(s["normals"], normals[s["point_index"]].astype(np.float32))
        else:
            assert "normals" not in s and "face_index" not in s


def test_a_point_set_sample_is_determined_by_seed_epoch_and_index():
    points, normals = _sphere_points(2000, seed=1)
    cloud = PointSet(points, normals, None, "sphere")
    a, b = RandomOcclusion(256, seed=3), RandomOcclusion(256, seed=3)
    s1, s2 = a(cloud, index=5), b(PointSet(points.copy(), normals.copy(), None, "copy"), index=5)
    assert np.array_equal(s1["points"], s2["points"]) and np.array_equal(s1["point_index"], s2["point_index"])
    assert s1["points"].shape == (256, 3) and s1["points"].dtype == np.float32
    # normalised as the mesh samples are: bounding box centred on 0, maximum extent 1
    assert np.isclose(np.ptp(s1["points"], axis=0).max(), 1.0) and np.allclose(s1["points"].min(0) + s1["points"].max(0), 0, atol=1e-6)
    assert not np.array_equal(a(cloud, index=6)["point_index"], s1["point_index"])
    a.set_epoch(1)
    assert not np.array_equal(a(cloud, index=5)["point_index"], s1["point_index"])
    assert np.array_equal(a(cloud, index=5, epoch=0)["point_index"], s1["point_index"])
    # an array is a point set without normals
    assert a(points, index=0)["points"].shape == (256, 3)


def test_the_up_axis_of_a_point_set_sets_where_elevation_is_measured():
    points, normals = _sphere_points(3000, seed=2)
    top = PoseDistribution((89.0, 90.0), (0.0, 360.0))
    t = RandomOcclusion(500, poses=top, seed=0, normalize=False)
    for up, axis in (("+z", 2), ("+y", 1)):
        s = t(PointSet(points, normals, None, "sphere"), index=0, up=up)
        assert (s["points"][:, axis] > SPHERE_CENTRE[axis]).mean() > 0.99, up  # seen from the top: the upper cap
    with pytest.raises(InvalidInputError, match="up must be one of"):
        t(points, index=0, up="sideways")


def test_random_occlusion_refuses_mixed_up_calls(chair):
    mesh, dense = chair
    t = RandomOcclusion(64)
    with pytest.raises(InvalidInputError, match="a mesh with its dense cloud, or a point set alone"):
        t(mesh, index=0)
    with pytest.raises(InvalidInputError, match="a mesh with its dense cloud, or a point set alone"):
        t(PointSet(dense.points, None, None, "x"), dense, 0)
    with pytest.raises(InvalidInputError, match="needs the sample's index"):
        t(dense.points)
    with pytest.raises(InvalidInputError, match=r"\(N, 3\)"):
        t(np.zeros((10, 2)), index=0)
    with pytest.raises(InvalidInputError, match="normals must have the shape of the points"):
        t(PointSet(dense.points, dense.points[:, :2], None, "x"), index=0)


def _npy_class_folders(root: Path) -> dict[str, np.ndarray]:
    """Two classes of .npy clouds (xyz + normals) sampled from the shipped meshes: CLASS/NAME.npy."""
    import zbuf_occlude as zo

    clouds = {}
    for mesh_file in [CHAIR, SAMPLES / "stool" / "train" / "stool_0002.off", SAMPLES / "table" / "test" / "table_0393.off"]:
        mesh = load_mesh(mesh_file)
        points, face_index = zo.sample_surface(mesh, count=3000, seed=0)
        cloud = np.hstack([points * 10.0, mesh.face_normals[face_index]])  # any units
        name = f"{mesh_file.parents[1].name}/{mesh_file.parent.name}/{mesh_file.stem}"
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        np.save(root / f"{name}.npy", cloud)
        clouds[name] = cloud
    return clouds


def test_a_data_set_of_point_sets_gives_subsets_of_each_cloud(tmp_path):
    from zbuf_occlude.mesh.inputs.point_sets import load_cloud

    clouds = _npy_class_folders(tmp_path)
    ds = OnTheFlyOccludedDataset(tmp_path, n_points=200, seed=7, views_per_object=2, normalize=False)
    assert [o.name for o in ds.objects] == sorted(clouds) and ds.shape_names == sorted({n.split("/")[0] for n in clouds})
    assert [o.label for o in ds.objects] == [ds.shape_names.index(n.split("/")[0]) for n in sorted(clouds)]
    assert "point-splat" in repr(ds) and len(ds) == 2 * len(clouds)
    for i in range(len(ds)):
        s = ds.sample(i)
        cloud = load_cloud(tmp_path / f"{s['name']}.npy", 0)  # the farm's frame: largest side 1
        assert s["points"].shape == (200, 3) and s["n_visible"] > 200 and len(np.unique(s["point_index"])) == 200
        assert np.array_equal(s["points"], cloud.points[s["point_index"]].astype(np.float32))
        assert np.array_equal(s["normals"], cloud.normals[s["point_index"]].astype(np.float32))
        assert np.array_equal(ds.sample(i)["points"], s["points"])  # same (seed, epoch, index), same sample
    x, y = ds[0]
    assert tuple(x.shape) == (200, 3) and x.dtype == torch.float32 and y == ds.objects[0].label
    first = ds.sample(0)["point_index"]
    ds.set_epoch(1)
    assert not np.array_equal(ds.sample(0)["point_index"], first)
    twin = OnTheFlyOccludedDataset(tmp_path, n_points=200, seed=7, views_per_object=2, normalize=False)
    assert np.array_equal(twin.sample(0, epoch=0)["point_index"], first)  # a new data set, a new process: the same
    test_only = OnTheFlyOccludedDataset(tmp_path, split="test", n_points=32)
    assert [o.name for o in test_only.objects] == ["table/test/table_0393"]


def _pointnet_folder(root: Path) -> list:
    """``modelnet40_ply_hdf5_2048``'s layout in small: two files, labels, shape_names.txt, the file lists."""
    import h5py

    root.mkdir()
    points, _ = _sphere_points(512, seed=3)
    y_up = points[:, [0, 2, 1]] * [1.0, 0.5, 1.0]  # an ellipsoid, flat along y (its up axis)
    for split, labels in (("train", [1, 0, 1]), ("test", [0, 1])):
        with h5py.File(root / f"ply_data_{split}0.h5", "w") as f:
            f["data"] = np.stack([y_up * (1 + 0.1 * i) for i in range(len(labels))]).astype(np.float32)
            f["label"] = np.array(labels, np.uint8)[:, None]
        (root / f"{split}_files.txt").write_text(f"data/{root.name}/ply_data_{split}0.h5\n")
    (root / "shape_names.txt").write_text("bowl\ncup\n")
    return read_point_sets(root / "ply_data_train0.h5")


def test_a_data_set_of_pointnet_hdf5_takes_the_files_labels_and_splits(tmp_path):
    rows = _pointnet_folder(tmp_path / "modelnet40_ply_hdf5_2048")
    top = PoseDistribution((80.0, 90.0))
    ds = OnTheFlyOccludedDataset(tmp_path / "modelnet40_ply_hdf5_2048", split="train", n_points=128, normalize=False,
                                 poses=top, up="+y")  # fmt: skip
    assert ds.shape_names == ["bowl", "cup"]
    assert [(o.name, o.label, o.class_name, o.cloud) for o in ds.objects] == [
        ("ply_data_train0_0000", 1, "cup", 0),
        ("ply_data_train0_0001", 0, "bowl", 1),
        ("ply_data_train0_0002", 1, "cup", 2),
    ]
    assert ds.labels.tolist() == [1, 0, 1]
    s = ds.sample(1)
    assert len(np.unique(s["point_index"])) == 128
    # +y turned to +z: seen from the top, the sample is the cloud's upper (+y) half, now its +z half
    height = rows[1].points[:, 1] - (rows[1].points[:, 1].min() + rows[1].points[:, 1].max()) / 2
    assert (height[s["point_index"]] > 0).mean() > 0.9 and s["points"][:, 2].min() > -0.05
    test = OnTheFlyOccludedDataset(tmp_path / "modelnet40_ply_hdf5_2048", split="test", n_points=128)
    assert [o.label for o in test.objects] == [0, 1] and len(test) == 2


def test_point_set_inputs_that_are_refused_name_the_file(tmp_path):
    bad = tmp_path / "bad"
    (bad / "chair").mkdir(parents=True)
    (bad / "stool").mkdir()
    np.save(bad / "chair" / "a.npy", np.zeros((10, 4)))  # neither (N, 3) nor (N, 6)
    np.save(bad / "stool" / "b.npy", np.ones((10, 3)))
    with pytest.raises(InvalidInputError, match=r"a\.npy: holds float64 values of shape .10, 4.") as exc:
        OnTheFlyOccludedDataset(bad)
    assert "\n" not in str(exc.value)
    nan = tmp_path / "nan"
    (nan / "chair").mkdir(parents=True)
    (nan / "stool").mkdir()
    np.save(nan / "chair" / "a.npy", np.full((10, 3), np.nan))  # found by its header; refused when read
    np.save(nan / "stool" / "b.npy", np.random.default_rng(0).random((10, 3)))
    ds = OnTheFlyOccludedDataset(nan, n_points=4)
    with pytest.raises(InvalidInputError, match=r"a\.npy: cloud 'a': 10 points have NaN or inf") as exc:
        ds.sample(0)
    assert str(nan / "chair" / "a.npy") in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(InvalidInputError, match="up must be one of"):
        OnTheFlyOccludedDataset(nan, up="+w")


def test_meshes_and_point_sets_together(tmp_path):
    import shutil

    import zbuf_occlude as zo

    shutil.copytree(SAMPLES, tmp_path / "samples")
    mesh = load_mesh(SAMPLES / "sofa" / "test" / "sofa_0681.off")
    points, face_index = zo.sample_surface(mesh, count=2000, seed=0)
    np.save(tmp_path / "samples" / "sofa" / "test" / "sofa_9999.npy", points)
    mixed = OnTheFlyOccludedDataset(tmp_path / "samples", n_points=64, dense_points=1024)
    meshes = OnTheFlyOccludedDataset(SAMPLES, n_points=64, dense_points=1024)
    assert [o.name for o in mixed.objects if o.kind is MESH] == [o.name for o in meshes.objects]
    assert mixed.shape_names == meshes.shape_names and "embree-fast and point-splat" in repr(mixed)
    (cloud,) = [i for i, o in enumerate(mixed.objects) if o.kind is POINT_SET]
    assert mixed.sample(cloud)["points"].shape == (64, 3) and mixed.objects[cloud].label == mixed.shape_names.index("sofa")
    for i in range(cloud):  # the meshes before it keep their index: the same samples as without it
        assert np.array_equal(mixed.sample(i)["points"], meshes.sample(i)["points"])


def test_pyg_transform_of_a_point_cloud():
    pytest.importorskip("torch_geometric")
    from torch_geometric.data import Data

    from zbuf_occlude.learn.pyg import OccludeMesh

    points, normals = _sphere_points(3000, seed=4)
    data = Data(pos=torch.tensor(points, dtype=torch.float32), normal=torch.tensor(normals, dtype=torch.float32), y=torch.tensor([2]))
    t = OccludeMesh(300, seed=1, normalize=False)
    out = t(data)
    assert out.pos.shape == (300, 3) and out.normal.shape == (300, 3) and out.y.tolist() == [2]
    rows = {tuple(p) for p in np.hstack([data.pos.numpy(), data.normal.numpy()])}
    assert all(tuple(p) in rows for p in np.hstack([out.pos.numpy(), out.normal.numpy()]))  # rows of the input
    assert torch.equal(t(data).pos, out.pos)  # (seed, epoch, content) decide the view
    bare = t(Data(pos=data.pos))
    assert bare.pos.shape == (300, 3) and getattr(bare, "normal", None) is None
    t.set_epoch(1)
    assert not torch.equal(t(data).pos, out.pos)
    with pytest.raises(InvalidInputError, match="normal must be"):
        t(Data(pos=data.pos, normal=data.normal[:10]))
    with pytest.raises(InvalidInputError, match="up must be one of"):
        OccludeMesh(up="auto")
