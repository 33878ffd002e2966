"""zbuf_occlude.learn: models, the Fisher-vector layer, training loop, metrics, data, the experiments' smoke run."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

torch = pytest.importorskip("torch", reason="zbuf_occlude.learn needs PyTorch: pip install -e '.[learn]'")

from zbuf_occlude.errors import InvalidInputError  # noqa: E402
from zbuf_occlude.farm.config import RunOptions
from zbuf_occlude.learn import data as D  # noqa: E402
from zbuf_occlude.learn.metrics import accuracy_by_elevation, classification_report, confusion_matrix  # noqa: E402
from zbuf_occlude.learn.models import (  # noqa: E402
    FisherVectorLayer,
    PointNet,
    build_model,
    orthogonality_loss,
    voxelize,
)
from zbuf_occlude.learn.training import RECIPES, TrainConfig, predict, train  # noqa: E402
from zbuf_occlude.mesh.inputs.duplicates import dedupe_meshes  # noqa: E402

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"


def test_core_import_does_not_import_torch():
    code = "import sys, zbuf_occlude, zbuf_occlude.cli.main; zbuf_occlude.cli.main.build_parser(); print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("name", ["pointnet", "voxnet", "3dmfv"])
def test_output_shapes_and_finite(name):
    torch.manual_seed(0)
    model = build_model(name, 5, width=0.25)
    model.eval()
    x = torch.rand(3, 100, 3) - 0.5
    y = model(x)
    assert y.shape == (3, 5) and torch.isfinite(y).all()


def test_build_model_rejects_bad_input():
    with pytest.raises(InvalidInputError, match="unknown model"):
        build_model("resnet", 3)
    with pytest.raises(InvalidInputError, match="2 classes"):
        build_model("voxnet", 1)


def test_orthogonality_loss_law():
    q, _ = torch.linalg.qr(torch.randn(4, 3, 3, dtype=torch.float64))
    assert float(orthogonality_loss(q)) < 1e-20
    # A = 2I: I - 4I = -3I, squared Frobenius norm 9k
    assert float(orthogonality_loss(2 * torch.eye(3).expand(2, 3, 3))) == pytest.approx(27.0)
    # scaled regulariser is what PointNet adds; identity T-nets at init make it ~0
    model = PointNet(4, width=0.25)
    model.eval()
    model(torch.rand(2, 50, 3))
    assert float(model.regularizer.detach()) == pytest.approx(0.0, abs=1e-10)
    t_in, t_feat = model.last_transforms
    assert torch.allclose(t_in, torch.eye(3).expand(2, 3, 3))


def test_voxelize_occupancy():
    pts = torch.tensor([[[-0.5, -0.5, -0.5], [0.5, 0.5, 0.5], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]])
    grid = voxelize(pts, 32)
    assert grid.shape == (1, 1, 32, 32, 32) and float(grid.sum()) == 3.0  # the duplicate counts once
    assert grid[0, 0, 4, 4, 4] == 1 and grid[0, 0, 16, 16, 16] == 1 and grid[0, 0, 28, 28, 28] == 1  # 24³ inside 32³


def test_fisher_vector_matches_sklearn_gaussian_mixture():
    mixture = pytest.importorskip("sklearn.mixture", reason="the reference needs scikit-learn")
    m = 3
    layer = FisherVectorLayer(m, normalize=False)
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.9, 0.9, (2, 17, 3))
    k = m**3
    gmm = mixture.GaussianMixture(n_components=k, covariance_type="spherical")
    gmm.weights_ = np.full(k, 1.0 / k)
    gmm.means_ = layer.mu.numpy().astype(np.float64)
    gmm.covariances_ = np.full(k, layer.sigma**2)
    gmm.precisions_cholesky_ = 1.0 / np.sqrt(gmm.covariances_)
    fv = layer(torch.from_numpy(pts), unit_sphere=True).numpy()  # (2, 20, m, m, m)
    assert fv.shape == (2, 20, m, m, m)
    w, s = 1.0 / k, layer.sigma
    for b in range(2):
        x = pts[b]
        gamma = gmm.predict_proba(x)  # (T, K)
        t = len(x)
        diff = (x[:, None, :] - gmm.means_[None]) / s  # (T, K, 3)
        g_pi = (gamma - w) / (np.sqrt(w) * t)
        g_mu = gamma[..., None] * diff / (np.sqrt(w) * t)
        g_sig = gamma[..., None] * (diff**2 - 1) / (np.sqrt(2 * w) * t)
        ref = np.concatenate(
            [
                g_pi.max(0)[:, None],
                g_pi.sum(0)[:, None],
                g_mu.max(0),
                g_mu.min(0),
                g_mu.sum(0),
                g_sig.max(0),
                g_sig.min(0),
                g_sig.sum(0),
            ],
            axis=1,
        )  # fmt: skip  (K, 20)
        np.testing.assert_allclose(fv[b].reshape(20, k).T, ref, rtol=1e-6, atol=1e-9)
    # the normalised layer: each group has unit L2 norm over the Gaussians
    normed = FisherVectorLayer(m)(torch.from_numpy(pts).float(), unit_sphere=True).reshape(2, 20, k)
    assert torch.allclose(normed[:, 0].norm(dim=1), torch.ones(2), atol=1e-5)


def _box_vs_sphere(n_per_class: int, n_points: int, seed: int) -> D.CloudSet:
    rng = np.random.default_rng(seed)
    clouds, labels = [], []
    for _ in range(n_per_class):
        # box surface: a random face, uniform on it; the box's aspect varies a little
        half = rng.uniform(0.35, 0.5, 3)
        p = rng.uniform(-1, 1, (n_points, 3))
        axis = rng.integers(0, 3, n_points)
        p[np.arange(n_points), axis] = np.sign(rng.uniform(-1, 1, n_points))
        clouds.append(p * half)
        s = rng.normal(size=(n_points, 3))
        clouds.append(0.5 * s / np.linalg.norm(s, axis=1, keepdims=True))
        labels += [0, 1]
    pts = D.normalize_batch(np.stack(clouds))
    return D.CloudSet(pts, np.array(labels), np.full(len(labels), np.nan), np.arange(len(labels)))


@pytest.mark.slow
@pytest.mark.parametrize(
    "name,epochs,points,width,optimizer,lr",
    [
        ("pointnet", 6, 64, 0.125, None, None),
        # VoxNet's paper SGD (lr 0.01) needs more steps than 8 epochs of 64 clouds give; the
        # test asks whether the network can learn, so it uses Adam here
        ("voxnet", 10, 256, 0.25, "adam", 1e-3),
        ("3dmfv", 6, 64, 0.125, None, None),
    ],
)
def test_each_model_learns_box_vs_sphere(name, epochs, points, width, optimizer, lr):
    train_set = _box_vs_sphere(32, points, seed=1)
    test_set = _box_vs_sphere(32, points, seed=2)
    cfg = TrainConfig(model=name, epochs=epochs, batch_size=8, width=width, fv_grid=4, seed=0, patience=0,
                      threads=1, optimizer=optimizer, lr=lr)  # fmt: skip
    res = train(train_set, 2, cfg, progress=False)
    pred, prob = predict(res.model, test_set.points)
    assert prob.shape == (len(test_set), 2)
    np.testing.assert_allclose(prob.sum(axis=1), 1.0, rtol=1e-5)
    assert (pred == test_set.labels).mean() > 0.9


def _state(model):
    return {k: v.clone() for k, v in model.state_dict().items()}


def test_training_is_deterministic_and_resume_is_exact(tmp_path):
    data = _box_vs_sphere(12, 64, seed=3)
    val = _box_vs_sphere(4, 64, seed=4)
    cfg = dict(model="voxnet", batch_size=8, width=0.25, seed=5, patience=0, threads=1)
    a = train(data, 2, TrainConfig(epochs=2, **cfg), val_set=val, progress=False)
    b = train(data, 2, TrainConfig(epochs=2, **cfg), val_set=val, progress=False)
    c1 = train(data, 2, TrainConfig(epochs=1, **cfg), val_set=val, checkpoint_dir=tmp_path, progress=False)
    c2 = train(data, 2, TrainConfig(epochs=2, **cfg), val_set=val, checkpoint_dir=tmp_path, progress=False)
    assert len(c1.history) == 1 and len(c2.history) == 2
    sa, sb, sc = _state(a.model), _state(b.model), _state(c2.model)
    for k in sa:
        assert torch.equal(sa[k], sb[k]), k
        assert torch.equal(sa[k], sc[k]), k
    assert a.history == c2.history
    other = train(data, 2, TrainConfig(epochs=1, **{**cfg, "seed": 6}), progress=False)
    assert any(not torch.equal(v, _state(other.model)[k]) for k, v in sa.items())
    # the aspect augmentation reaches the batches: the same seed trains other weights
    aspect = train(data, 2, TrainConfig(epochs=1, aspect=True, **cfg), progress=False)
    assert any(not torch.equal(v, _state(aspect.model)[k]) for k, v in _state(c1.model).items())
    partial = train(data, 2, TrainConfig(epochs=1, partial=True, **cfg), progress=False)  # and the partial one
    assert any(not torch.equal(v, _state(partial.model)[k]) for k, v in _state(c1.model).items())
    with pytest.raises(InvalidInputError, match="another configuration"):
        train(data, 2, TrainConfig(epochs=2, **{**cfg, "seed": 7}), checkpoint_dir=tmp_path, progress=False)
    assert (tmp_path / "best.pt").is_file() and (tmp_path / "history.json").is_file()


def test_metrics_by_hand():
    y = np.array([0, 0, 0, 1, 1, 2])
    p = np.array([0, 1, 0, 1, 1, 0])
    cm = confusion_matrix(y, p, 3)
    np.testing.assert_array_equal(cm, [[2, 1, 0], [0, 2, 0], [1, 0, 0]])
    rep = classification_report(y, p, ["a", "b", "c"])
    assert rep["overall_accuracy"] == pytest.approx(4 / 6)
    assert rep["mean_class_accuracy"] == pytest.approx((2 / 3 + 1 + 0) / 3)
    assert rep["per_class"] == {"a": pytest.approx(2 / 3), "b": 1.0, "c": 0.0}
    rows = accuracy_by_elevation(y, p, np.array([0, 0, 10, 10, 10, np.nan]))
    assert rows == [{"elevation_deg": 0.0, "n": 2, "accuracy": 0.5}, {"elevation_deg": 10.0, "n": 3, "accuracy": 1.0}]
    with pytest.raises(InvalidInputError):
        confusion_matrix(y, p, 2)


def test_augment_rotates_about_z_only():
    rng = np.random.default_rng(0)
    pts = D.normalize_batch(rng.uniform(-1, 1, (4, 50, 3)))
    out = D.augment(pts, np.random.default_rng(1), scale=False, jitter=False)
    # rotation about z keeps each point's z and its distance to the z axis, up to the common re-normalisation
    s = (np.ptp(out[..., 2], axis=1) / np.ptp(pts[..., 2], axis=1))[:, None]
    c_in = (pts[..., 2].max(1) + pts[..., 2].min(1))[:, None] / 2
    c_out = (out[..., 2].max(1) + out[..., 2].min(1))[:, None] / 2
    np.testing.assert_allclose(out[..., 2] - c_out, (pts[..., 2] - c_in) * s, atol=1e-5)
    again = D.augment(pts, np.random.default_rng(1), scale=False, jitter=False)
    np.testing.assert_array_equal(out, again)
    jit = D.augment(pts, np.random.default_rng(1), rotate=False, scale=False)
    assert np.abs(jit - pts).max() <= D.JITTER_CLIP + 1e-7 and np.abs(jit - pts).max() > 0


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(0.05, 1.0), min_size=3, max_size=3), st.integers(0, 2**32 - 1))
def test_aspect_changes_the_proportions_within_its_range_and_keeps_the_size(axes: list[float], seed: int):
    rng = np.random.default_rng(seed)
    pts = D.normalize_batch(rng.uniform(-1, 1, (3, 40, 3)) * np.asarray(axes))
    out = D.augment(pts, np.random.default_rng(seed), rotate=False, scale=False, jitter=False, aspect=True)
    # each axis stretched by a factor in [2/3, 3/2], then re-normalised: max extent 1, and any two axes' ratio
    # changes by at most (3/2) / (2/3)
    ext_in, ext_out = np.ptp(pts, axis=1), np.ptp(out, axis=1)
    np.testing.assert_allclose(ext_out.max(axis=1), 1.0, rtol=1e-5)
    change = (ext_out / ext_in) / (ext_out / ext_in).max(axis=1, keepdims=True)
    assert np.all(change >= (2 / 3) / (3 / 2) - 1e-5) and np.all(change <= 1 + 1e-6)
    # the stretch is an affine map: the points keep their place between the box's faces
    rel_in = (pts - pts.min(axis=1, keepdims=True)) / ext_in[:, None]
    np.testing.assert_allclose((out - out.min(axis=1, keepdims=True)) / ext_out[:, None], rel_in, atol=1e-4)


def test_aspect_is_off_by_default_and_draws_new_proportions_when_on():
    rng = np.random.default_rng(0)
    pts = D.normalize_batch(rng.uniform(-1, 1, (256, 60, 3)))
    plain = D.augment(pts, np.random.default_rng(1))
    np.testing.assert_array_equal(plain, D.augment(pts, np.random.default_rng(1), aspect=False))

    def ratio(p):  # each cloud's height over its width
        return np.ptp(p[..., 2], axis=1) / np.ptp(p[..., :2], axis=1).max(axis=1)

    on = D.augment(pts, np.random.default_rng(1), rotate=False, jitter=False, aspect=True)
    off = D.augment(pts, np.random.default_rng(1), rotate=False, jitter=False)
    # a cube's height over its width stays as it was without it; with it, it spreads towards (2/3)/(3/2) ... (3/2)/(2/3)
    np.testing.assert_allclose(ratio(off), ratio(pts), rtol=1e-5)
    assert ratio(pts).min() > 0.8 and ratio(on).min() < 0.6 and ratio(on).max() > 1.6
    extent = np.ptp(on, axis=1).max(axis=1)
    assert extent.min() >= D.SCALE_RANGE[0] - 1e-5 and extent.max() <= D.SCALE_RANGE[1] + 1e-5
    # a training run's setting: left out of the identity when off (older runs' settings compare equal), refused without augment
    assert "aspect" not in TrainConfig().identity(("seed",)) and TrainConfig(aspect=True).identity(("seed",))["aspect"] is True
    with pytest.raises(InvalidInputError, match="aspect"):
        TrainConfig(aspect=True, augment=False)
    for recipe in RECIPES.values():  # it goes with either recipe
        assert TrainConfig(aspect=True, **recipe).aspect and "aspect" not in TrainConfig(**recipe).identity(("seed",))


def _as_subset(out: np.ndarray, cloud: np.ndarray) -> np.ndarray | None:
    """The rows of ``cloud`` whose normalisation gives ``out``'s points (a positive scale and a shift, no turn), or None."""
    u = np.unique(out, axis=0)
    top, bottom = u[np.argmax(u[:, 2])], u[np.argmin(u[:, 2])]
    if top[2] == bottom[2]:
        return None
    pair = cloud[:, None, :] - cloud[None, :, :]  # (a, b): cloud[a] - cloud[b]
    scale = pair[..., 2] / (top[2] - bottom[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        fits = (scale > 0) & (np.abs(pair / scale[..., None] - (top - bottom)).max(axis=2) < 1e-5)
    for a, b in zip(*np.nonzero(fits)):
        back = u * scale[a, b] + (cloud[a] - top * scale[a, b])
        match = np.abs(back[:, None, :] - cloud[None, :, :]).max(axis=2) < 1e-5
        if match.any(axis=1).all():
            return np.flatnonzero(match.any(axis=0))
    return None


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_partial_keeps_a_normalised_subset_above_a_cut_of_at_most_the_bottom_three_tenths(seed: int):
    rng = np.random.default_rng(seed)
    pts = D.normalize_batch(rng.uniform(-1, 1, (6, 40, 3)))
    out = D.augment(pts, np.random.default_rng(seed), rotate=False, scale=False, jitter=False, partial=True)
    assert out.shape == pts.shape and out.dtype == np.float32
    for cloud, o in zip(pts, out):
        if np.array_equal(cloud, o):  # a cloud left whole
            continue
        np.testing.assert_allclose(np.ptp(o, axis=0).max(), 1.0, rtol=1e-5)  # re-normalised
        kept = _as_subset(o, cloud)
        assert kept is not None, "not a subset of the cloud's own points"
        z = (cloud[:, 2] - cloud[:, 2].min()) / np.ptp(cloud[:, 2])
        # everything above the highest cut could be kept; the dropout keeps at least an eighth of what the cut leaves
        assert len(kept) >= np.ceil((1 - D.PARTIAL_DROPOUT_MAX) * np.count_nonzero(z >= D.PARTIAL_CUT_MAX)) - 1e-9
        assert len(np.unique(o, axis=0)) == len(kept)


def test_partial_is_off_by_default_and_cuts_and_thins_half_the_clouds():
    rng = np.random.default_rng(0)
    pts = D.normalize_batch(rng.uniform(-1, 1, (400, 60, 3)))
    plain = D.augment(pts, np.random.default_rng(1))
    np.testing.assert_array_equal(plain, D.augment(pts, np.random.default_rng(1), partial=False))
    out = D.augment(pts, np.random.default_rng(1), rotate=False, scale=False, jitter=False, partial=True)
    changed = [i for i in range(len(pts)) if not np.array_equal(out[i], pts[i])]
    assert 0.4 < len(changed) / len(pts) < 0.6  # PARTIAL_SHARE
    lowest, share = [], []
    for i in changed[:60]:
        kept = _as_subset(out[i], pts[i])
        z = (pts[i, :, 2] - pts[i, :, 2].min()) / np.ptp(pts[i, :, 2])
        lowest.append(z[kept].min())
        share.append(len(kept) / len(pts[i]))
    # the bottom cut reaches up to three tenths of the height (and not past it but for the dropout); a cloud keeps
    # from an eighth of its points to nearly all of them
    assert 0.2 < np.quantile(lowest, 0.9) and np.median(lowest) < D.PARTIAL_CUT_MAX
    assert min(share) < 0.25 and max(share) > 0.75
    # a training run's setting: left out of the identity when off, refused without augment
    assert "partial" not in TrainConfig().identity(("seed",)) and TrainConfig(partial=True).identity(("seed",))["partial"] is True
    with pytest.raises(InvalidInputError, match="partial"):
        TrainConfig(partial=True, augment=False)


def test_resample_and_split():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(2, 10, 3)).astype(np.float32)
    sub = D.resample(pts, 4, rng)
    assert sub.shape == (2, 4, 3)
    for b in range(2):  # a subset without repeats
        assert len({tuple(r) for r in sub[b]}) == 4 and all(tuple(r) in {tuple(q) for q in pts[b]} for r in sub[b])
    up = D.resample(pts, 13, rng)
    assert {tuple(r) for r in up[0]} == {tuple(r) for r in pts[0]}
    labels = np.array([0] * 10 + [1] * 5 + [2])
    tr, va = D.split_validation(len(labels), 0.2, seed=0, labels=labels)
    assert len(np.intersect1d(tr, va)) == 0 and len(tr) + len(va) == 16
    assert sorted(labels[va].tolist()) == [0, 0, 1]  # a single-sample class stays in training


def test_dedupe_ignores_off_header_layout(tmp_path):
    body = "3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    (tmp_path / "a.off").write_text("OFF\n" + body)
    (tmp_path / "b.off").write_text("OFF" + body.replace("\n", "\r\n"))
    (tmp_path / "c.off").write_text("OFF\n" + body.replace("0 1 0", "0 2 0"))
    kept, dropped = dedupe_meshes(sorted(tmp_path.glob("*.off")))
    assert [p.name for p in kept] == ["a.off", "c.off"] and [(d.name, o.name) for d, o in dropped] == [("b.off", "a.off")]


@pytest.mark.slow
def test_one_epoch_smoke_on_samples(tmp_path):
    """The documented smoke test: `zbuf-occlude experiment elevation data/samples --epochs 1`."""
    from zbuf_occlude.cli.main import main

    out = tmp_path / "el"
    rc = main(["experiment", "elevation", str(SAMPLES), "--model", "voxnet", "--out", str(out), "--epochs", "1",
               "--points", "64", "--no-progress", "--no-profile"])  # fmt: skip
    assert rc == 0
    import csv
    import json

    rows = list(csv.DictReader(open(out / "results.csv")))
    assert [float(r["elevation_deg"]) for r in rows] == sorted({-80, -60, -40, -30, -10, 0, 10, 30, 40, 60, 80})
    run = json.loads((out / "run.json").read_text())
    assert run["meshes"] == 8 and run["epochs_run"] == 1
    assert run["n_train"] + run["n_val"] == 8 * 34 and run["n_test"] == 8 * 66  # one sample per pose at quick scale
    assert "voxnet (paper) | 69.7" in (out / "table.md").read_text()
    assert (out / "accuracy_vs_elevation.png").stat().st_size > 0


@pytest.mark.parametrize("storage", ["dense", "compact"])
def test_from_occluded_reads_both_storage_modes(tmp_path, storage):
    import zbuf_occlude as zo
    from zbuf_occlude.farm import FarmParams

    meshes = sorted(SAMPLES.rglob("*.off"))[:2]
    listing = tmp_path / "list.txt"
    listing.write_text("".join(f"{p} {p.parent.parent.name} train\n" for p in meshes))
    params = FarmParams(views="0:0,60:90", samples_per_view=2, n_points=32, dense_points=2000, resolution=128,
                        storage=storage)  # fmt: skip
    zo.run_farm(listing, tmp_path / "ds", params=params, options=RunOptions(progress=False))
    ds = zo.OccludedDataset(tmp_path / "ds", elevation_deg=[60.0])
    clouds = D.from_occluded(ds, n_points=16, seed=0)
    assert clouds.points.shape == (4, 16, 3)
    np.testing.assert_array_equal(clouds.elevation_deg, 60.0)
    np.testing.assert_array_equal(np.sort(clouds.labels), [0, 0, 1, 1])
    lo, hi = clouds.points.min(axis=1), clouds.points.max(axis=1)
    np.testing.assert_allclose((hi - lo).max(axis=1), 1.0, rtol=1e-5)  # normalised per cloud
    np.testing.assert_allclose((hi + lo) / 2, 0.0, atol=1e-6)
    raw, _ = ds.to_arrays()
    full = D.from_occluded(ds, seed=0)  # all 32 points: exactly the stored samples, normalised
    from zbuf_occlude.real_scans.records import normalize_points

    for b in range(4):
        np.testing.assert_allclose(full.points[b], normalize_points(raw[b]), atol=1e-6)


def test_augmentation_split_rule():
    from zbuf_occlude.experiments.table3.augmentation import _split_3b

    meshes = [
        {"name": "bathtub_1", "class_name": "bathtub", "split": "train"},
        {"name": "bathtub_2", "class_name": "bathtub", "split": "train"},
        {"name": "chair_1", "class_name": "chair", "split": "train"},
        {"name": "chair_9", "class_name": "chair", "split": "test"},
        {"name": "lamp_1", "class_name": "lamp", "split": "train"},
    ]
    out = {m["name"]: m["split"] for m in _split_3b(meshes)}
    # a class without a test mesh gives its last one to test; a single-mesh class is dropped
    assert out == {"bathtub_1": "train", "bathtub_2": "test", "chair_1": "train", "chair_9": "test"}
    assert meshes[1]["split"] == "train"  # the input is not modified


def test_label_map_option():
    from zbuf_occlude.cli.sim2real import parse_pairs

    assert parse_pairs("Car=car, 4wd = car", "--label-map") == {"Car": "car", "4wd": "car"}
    assert parse_pairs(None, "--label-map") == {}
    with pytest.raises(InvalidInputError, match="--label-map expects KEY=VALUE"):
        parse_pairs("car", "--label-map")


@pytest.mark.parametrize(
    ("field", "config", "n_classes"),
    [
        ("width", {"width": 1e9}, 2),
        ("n_classes", {}, 10**9),
        ("fv_grid", {"model": "3dmfv", "fv_grid": 100_000}, 2),
        ("width", {"width": "wide"}, 2),
        ("n_classes", {}, 2.5),
        ("model", {"model": ["pointnet"]}, 2),
    ],
)
def test_load_model_bounds_every_config_field_before_building(tmp_path, field, config, n_classes):
    """A 1 KB checkpoint may not ask for a 768 GB model: the field is named before anything is built."""
    import torch

    from zbuf_occlude.errors import CheckpointError
    from zbuf_occlude.learn.training import load_model

    path = tmp_path / "best.pt"
    torch.save({"config": {"model": "pointnet", "width": 1.0, "fv_grid": 8, **config}, "n_classes": n_classes, "model": {}}, path)
    assert path.stat().st_size < 2048
    with pytest.raises(CheckpointError, match=rf"best\.pt: config field {field}:"):
        load_model(path)


def test_build_model_bounds_match_the_documented_limits():
    from zbuf_occlude.learn.models import MAX_CLASSES, MAX_FV_GRID, MAX_WIDTH, check_model_config

    assert check_model_config("3dmfv", MAX_CLASSES, MAX_WIDTH, MAX_FV_GRID) == ("3dmfv", MAX_CLASSES, MAX_WIDTH, MAX_FV_GRID)
    assert check_model_config("pointnet", 40.0, 1, 8) == ("pointnet", 40, 1.0, 8)
    for bad in ({"n_classes": MAX_CLASSES + 1}, {"width": MAX_WIDTH * 1.01}, {"fv_grid": MAX_FV_GRID + 1}, {"width": 0.0},
                {"n_classes": True}, {"width": float("nan")}):  # fmt: skip
        args = {"name": "pointnet", "n_classes": 4, "width": 1.0, "fv_grid": 8, **bad}
        with pytest.raises(InvalidInputError, match=next(iter(bad))):
            check_model_config(**args)
