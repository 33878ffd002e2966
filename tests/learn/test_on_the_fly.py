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
    from zbuf_occlude.mesh.inputs import scan_paths

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
    for x, y in torch.utils.data.DataLoader(ds, batch_size=4, shuffle=True, num_workers=2, drop_last=True,
                                       multiprocessing_context="spawn", timeout=300):
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
        t(Data(pos=torch.zeros(4, 3)))


@pytest.mark.slow
def test_epoch_sampler_carries_the_epoch_to_persistent_workers():
    from zbuf_occlude.learn import EpochSampler

    ds = OnTheFlyOccludedDataset(SAMPLES, n_points=128, dense_points=2048, seed=4)
    sampler = EpochSampler(ds)
    loader = torch.utils.data.DataLoader(ds, batch_size=4, sampler=sampler, num_workers=2, persistent_workers=True,
                                         multiprocessing_context="spawn", timeout=300)
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
    loader = torch.utils.data.DataLoader(ds, batch_size=4, num_workers=2, persistent_workers=True, multiprocessing_context=context,
                                         timeout=300)
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
