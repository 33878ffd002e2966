"""zbuf_occlude.learn.training: the recipe options (balanced sampling, selection, warm-up, clipping)."""

from __future__ import annotations

import json
import os
import stat

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="zbuf_occlude.learn needs PyTorch: pip install -e '.[learn]'")

from zbuf_occlude.errors import (
    CheckpointError,
    InvalidInputError,
    OutputError,
    UnsafePathError,
)
from zbuf_occlude.learn import training as T
from zbuf_occlude.learn.data import CloudSet


def _clouds(labels: list[int], seed: int = 0, n_points: int = 32) -> CloudSet:
    rng = np.random.default_rng(seed)
    y = np.asarray(labels, np.int64)
    pts = (rng.uniform(-0.5, 0.5, (len(y), n_points, 3)) * np.where(y == 0, 1.0, 0.3)[:, None, None]).astype(np.float32)
    return CloudSet(pts, y, np.full(len(y), np.nan), np.arange(len(y)))


def _cfg(**kw) -> T.TrainConfig:
    return T.TrainConfig(**{"model": "pointnet", "epochs": 2, "batch_size": 4, "width": 0.125, "patience": 0,
                            "threads": 1, "seed": 0, **kw})  # fmt: skip


def _labels_seen(monkeypatch: pytest.MonkeyPatch) -> list[np.ndarray]:
    seen: list[np.ndarray] = []
    real = T._loss

    def spy(model, logits, y):
        seen.append(y.numpy().copy())
        return real(model, logits, y)

    monkeypatch.setattr(T, "_loss", spy)
    return seen


@pytest.mark.slow
@pytest.mark.parametrize("balance, expected", [("none", [12, 4]), ("sampler", [8, 8])])
def test_the_sampler_shows_every_class_equally_often(monkeypatch, balance, expected) -> None:
    seen = _labels_seen(monkeypatch)
    T.train(_clouds([0] * 12 + [1] * 4), 2, _cfg(epochs=1, balance=balance), progress=False)
    assert np.bincount(np.concatenate(seen), minlength=2).tolist() == expected


def _scripted_predict(monkeypatch: pytest.MonkeyPatch, probs: list[np.ndarray]) -> None:
    """The validation predictions of successive epochs, whatever the model says."""
    calls = iter(probs)

    def fake(model, points, **kw):
        p = next(calls)
        return p.argmax(axis=1), p

    monkeypatch.setattr(T, "predict", fake)


def _probs(pred: list[int], confidence: float) -> np.ndarray:
    p = np.full((len(pred), 2), 1.0 - confidence)
    p[np.arange(len(pred)), pred] = confidence
    return p


@pytest.mark.parametrize("select, best", [("accuracy", 1), ("mean_class_accuracy", 3)])
def test_the_best_epoch_by_mean_class_accuracy_then_balanced_loss(monkeypatch, select, best) -> None:
    val = _clouds([0] * 9 + [1])
    everything_zero = [0] * 10  # overall 0.9, mean class accuracy 0.5
    both = [0] * 7 + [1, 1, 1]  # overall 0.8, mean class accuracy (7/9 + 1) / 2
    _scripted_predict(monkeypatch, [_probs(everything_zero, 0.9), _probs(both, 0.6), _probs(both, 0.8), _probs(both, 0.7)])
    res = T.train(_clouds([0, 1] * 4), 2, _cfg(epochs=4, select=select), val_set=val, progress=False)
    assert res.best_epoch == best  # epoch 3 ties epoch 2 and 4 on mean class accuracy, with the lowest loss
    if select == "mean_class_accuracy":
        assert res.best_val_mean_class_accuracy == pytest.approx((7 / 9 + 1) / 2)
        assert res.best_val_accuracy == pytest.approx(0.8)
        assert res.history[0]["val_mean_class_accuracy"] == pytest.approx(0.5)


def test_the_best_epoch_by_loss_where_accuracy_ties_at_one(monkeypatch) -> None:
    """Every epoch classifies the validation set without a mistake (accuracy 1.0): by accuracy the
    first one wins the tie; by loss, the epoch most confident in the right classes."""
    val = _clouds([0] * 5 + [1] * 5)
    right = [0] * 5 + [1] * 5
    confidences = [0.6, 0.95, 0.8, 0.7]  # all right; the loss -log(p) is lowest in epoch 2
    for select, best in (("accuracy", 1), ("mean_class_accuracy", 2), ("loss", 2)):
        _scripted_predict(monkeypatch, [_probs(right, c) for c in confidences])
        res = T.train(_clouds([0, 1] * 4), 2, _cfg(epochs=4, select=select), val_set=val, progress=False)
        assert res.best_epoch == best, select
        assert res.best_val_accuracy == res.best_val_mean_class_accuracy == 1.0
    assert res.best_val_loss == pytest.approx(-np.log(0.95))
    assert [r["val_balanced_nll"] for r in res.history] == pytest.approx([-np.log(c) for c in confidences])


def test_the_loss_comes_first_and_mean_class_accuracy_breaks_its_ties(monkeypatch) -> None:
    val = _clouds([0, 0, 1, 1])
    # p(true class) per scan; -log 0.25 = 2 · -log 0.5 exactly in floating point, so both epochs' class losses are log 2
    one_wrong_each = np.array([[1.0, 0.0], [0.25, 0.75], [0.0, 1.0], [0.75, 0.25]])  # mean class accuracy 0.5
    one_wrong = np.array([[0.5, 0.5], [0.5, 0.5], [0.0, 1.0], [0.75, 0.25]])  # argmax of a tie: class 0; 0.75
    worse = np.array([[0.2, 0.8], [0.2, 0.8], [0.0, 1.0], [0.0, 1.0]])  # a higher loss, whatever its accuracy
    _scripted_predict(monkeypatch, [one_wrong_each, one_wrong, worse])
    res = T.train(_clouds([0, 1] * 4), 2, _cfg(epochs=3, select="loss"), val_set=val, progress=False)
    assert res.history[0]["val_balanced_nll"] == res.history[1]["val_balanced_nll"] < res.history[2]["val_balanced_nll"]
    assert res.best_epoch == 2 and res.best_val_mean_class_accuracy == 0.75


def test_the_stable_recipe_chooses_the_best_epoch_by_loss() -> None:
    assert T.STABLE_RECIPE["select"] == "loss" and T.PLAIN_RECIPE["select"] == "accuracy"
    assert T.TrainConfig(**T.STABLE_RECIPE).identity(())["select"] == "loss"
    assert "select" not in T.TrainConfig(**T.PLAIN_RECIPE).identity(())  # the plain loop's identity as before


def test_early_stopping_counts_epochs_without_a_better_mean_class_accuracy(monkeypatch) -> None:
    val = _clouds([0] * 9 + [1])
    good = _probs([0] * 7 + [1, 1, 1], 0.9)
    worse = _probs([0] * 10, 0.9)  # a better overall accuracy, a worse mean class accuracy
    _scripted_predict(monkeypatch, [good, worse, worse, worse, worse])
    res = T.train(_clouds([0, 1] * 4), 2, _cfg(epochs=5, patience=2, select="mean_class_accuracy"), val_set=val, progress=False)
    assert res.best_epoch == 1 and len(res.history) == 3


def test_warmup_raises_the_rate_linearly_over_the_first_epochs_batches(monkeypatch) -> None:
    rates: list[float] = []
    real_step = torch.optim.Adam.step

    def spy(self, *a, **kw):
        rates.append(self.param_groups[0]["lr"])
        return real_step(self, *a, **kw)

    monkeypatch.setattr(torch.optim.Adam, "step", spy)
    data = _clouds([0, 1] * 8)  # 16 clouds, batch 4: 4 steps per epoch
    # two epochs of warm-up (8 steps) across a halving of the rate after every epoch
    warm = T.train(data, 2, _cfg(epochs=3, warmup_epochs=2, lr=0.01, lr_step=1, lr_gamma=0.5), progress=False)
    np.testing.assert_allclose(rates, [0.01 * k / 8 for k in (1, 2, 3, 4)] + [0.005 * k / 8 for k in (5, 6, 7, 8)] + [0.0025] * 4)
    rates.clear()
    plain = T.train(data, 2, _cfg(epochs=3, lr=0.01, lr_step=1, lr_gamma=0.5), progress=False)
    np.testing.assert_allclose(rates, [0.01] * 4 + [0.005] * 4 + [0.0025] * 4)
    assert [r["lr"] for r in warm.history] == [r["lr"] for r in plain.history]  # the schedule itself is untouched


def test_gradient_clipping_bounds_the_norm_of_every_step(monkeypatch) -> None:
    norms: list[tuple[float, float]] = []
    real_clip = torch.nn.utils.clip_grad_norm_

    def spy(params, max_norm, *a, **kw):
        params = list(params)
        before = float(real_clip(params, max_norm, *a, **kw))
        after = float(torch.norm(torch.stack([p.grad.norm() for p in params if p.grad is not None])))
        norms.append((before, after))
        return before

    monkeypatch.setattr(torch.nn.utils, "clip_grad_norm_", spy)
    T.train(_clouds([0, 1] * 8), 2, _cfg(epochs=1, grad_clip=1e-3), progress=False)
    assert len(norms) == 4 and all(b > 1e-3 and a <= 1e-3 * (1 + 1e-4) for b, a in norms)
    norms.clear()
    T.train(_clouds([0, 1] * 8), 2, _cfg(epochs=1), progress=False)
    assert norms == []  # off by default


def test_the_stable_recipe_is_deterministic_and_resumes_exactly(tmp_path) -> None:
    data, val = _clouds([0] * 10 + [1] * 4, seed=1), _clouds([0] * 3 + [1] * 2, seed=2)
    cfg = {"model": "voxnet", "batch_size": 4, "width": 0.25, "seed": 5, "patience": 0, "threads": 1, **T.STABLE_RECIPE}
    a = T.train(data, 2, T.TrainConfig(epochs=3, **cfg), val_set=val, progress=False)
    c1 = T.train(data, 2, T.TrainConfig(epochs=1, **cfg), val_set=val, checkpoint_dir=tmp_path, progress=False)
    c2 = T.train(data, 2, T.TrainConfig(epochs=3, **cfg), val_set=val, checkpoint_dir=tmp_path, progress=False)
    assert len(c1.history) == 1 and a.history == c2.history and a.best_epoch == c2.best_epoch
    for k, v in a.model.state_dict().items():
        assert torch.equal(v, c2.model.state_dict()[k]), k
    with pytest.raises(InvalidInputError, match="another configuration"):  # the recipe is part of the configuration
        T.train(data, 2, T.TrainConfig(epochs=3, **{**cfg, "balance": "none"}), checkpoint_dir=tmp_path, progress=False)


def test_a_resumed_run_keeps_the_best_score_so_far(monkeypatch, tmp_path) -> None:
    val = _clouds([0] * 9 + [1])
    good, worse = _probs([0] * 7 + [1, 1, 1], 0.9), _probs([0] * 10, 0.9)
    _scripted_predict(monkeypatch, [good, worse, worse])
    cfg = {"select": "mean_class_accuracy", "balance": "sampler"}
    T.train(_clouds([0, 1] * 4), 2, _cfg(epochs=1, **cfg), val_set=val, checkpoint_dir=tmp_path, progress=False)
    res = T.train(_clouds([0, 1] * 4), 2, _cfg(epochs=3, **cfg), val_set=val, checkpoint_dir=tmp_path, progress=False)
    assert res.best_epoch == 1 and len(res.history) == 3


@pytest.mark.parametrize("field, value", [("balance", "oversample"), ("select", "f1"), ("warmup_epochs", -1), ("grad_clip", 0.0)])
def test_bad_recipe_options_are_refused_naming_them(field, value) -> None:
    with pytest.raises(InvalidInputError, match=field):
        T.TrainConfig(**{field: value})


def test_a_checkpoint_from_before_the_recipe_options_resumes_as_if_the_run_never_stopped(tmp_path) -> None:
    data, val = _clouds([0] * 6 + [1] * 6, seed=1), _clouds([0, 1] * 3, seed=2)
    whole = T.train(data, 2, _cfg(epochs=3), val_set=val, progress=False)
    T.train(data, 2, _cfg(epochs=1), val_set=val, checkpoint_dir=tmp_path, progress=False)
    state = torch.load(tmp_path / "last.pt", weights_only=True)
    for key in ("best_score", "best_val_mean_class_accuracy", "best_val_loss"):  # what last.pt held before the options
        del state[key]
    torch.save(state, tmp_path / "last.pt")
    resumed = T.train(data, 2, _cfg(epochs=3), val_set=val, checkpoint_dir=tmp_path, progress=False)
    assert resumed.history == whole.history and resumed.best_epoch == whole.best_epoch
    for k, v in whole.model.state_dict().items():
        assert torch.equal(v, resumed.model.state_dict()[k]), k


def test_train_is_short_enough_to_read() -> None:
    import inspect

    assert len(inspect.getsource(T.train).splitlines()) < 150


# -- the checkpoint folder, read and written through zbuf_occlude.io ---------------------------------
@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
def test_a_last_pt_that_is_a_fifo_is_refused_not_skipped_and_left_as_it_is(tmp_path) -> None:
    os.mkfifo(tmp_path / "last.pt")
    with pytest.raises(CheckpointError, match=r"last\.pt: is a FIFO"):
        T.train(_clouds([0, 1] * 4), 2, _cfg(epochs=1), checkpoint_dir=tmp_path, progress=False)
    assert stat.S_ISFIFO(os.lstat(tmp_path / "last.pt").st_mode) and not (tmp_path / "best.pt").exists()


def test_a_last_pt_linked_out_of_the_checkpoint_folder_is_refused(tmp_path) -> None:
    data = _clouds([0, 1] * 4)
    T.train(data, 2, _cfg(epochs=1), checkpoint_dir=tmp_path / "other", progress=False)
    run = tmp_path / "run"
    run.mkdir()
    (run / "last.pt").symlink_to(tmp_path / "other" / "last.pt")
    with pytest.raises(UnsafePathError, match=r"last\.pt leads outside .*run"):
        T.train(data, 2, _cfg(epochs=2), checkpoint_dir=run, progress=False)


def test_the_checkpoint_folder_is_made_and_written_atomically_with_the_same_files(tmp_path) -> None:
    ckpt = tmp_path / "a" / "b"
    res = T.train(_clouds([0, 1] * 4), 2, _cfg(epochs=1), checkpoint_dir=ckpt, progress=False)
    assert sorted(p.name for p in ckpt.iterdir()) == sorted(T.CHECKPOINT_FILES)  # no temporary left
    assert json.loads((ckpt / "history.json").read_text()) == res.history
    assert T.load_checkpoint(ckpt / "best.pt", keys=T.MODEL_KEYS)["n_classes"] == 2


def test_a_checkpoint_folder_that_cannot_be_made_is_one_output_error(tmp_path) -> None:
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match=r"cannot write .*file"):
        T.train(_clouds([0, 1] * 4), 2, _cfg(epochs=1), checkpoint_dir=tmp_path / "file" / "ckpt", progress=False)
