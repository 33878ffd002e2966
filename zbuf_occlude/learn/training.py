"""Training and inference: one loop for the three models, deterministic, resumable, early stopping.

Optimiser defaults (Sryamkin et al. 2023 give none; these are the models' own papers):

* PointNet (Qi et al. 2017, Appendix C): Adam, lr 0.001, batch 32, lr × 0.7 every 20
  epochs, feature-transform regulariser weight 0.001, dropout keep 0.7.
* VoxNet (Maturana & Scherer 2015, §4.1): SGD, lr 0.01, momentum 0.9, batch 32,
  lr ÷ 10 every 40 000 batches (kept as a step every 20 epochs here), weight decay 0.001.
* 3DmFV-Net (Ben-Shabat et al. 2018, §IV-A): Adam, lr 0.001, batch 64, lr × 0.7 every 20
  epochs, weight decay 0 (its code), dropout keep 0.7.

Recipe options for small, imbalanced sets (all off by default, so that the paper's Table 3
runs are unchanged; ``experiment sim2real`` turns them on, :data:`STABLE_RECIPE`):

* ``balance="sampler"``: class-balanced sampling (:func:`~zbuf_occlude.learn.data.balanced_epoch_rows`,
  Shen et al., ECCV 2016), every class equally often in every epoch;
* ``select="mean_class_accuracy"``: early stopping and the best epoch on the validation set's
  mean class accuracy (ties: the lower class-balanced validation cross-entropy,
  :func:`~zbuf_occlude.learn.metrics.balanced_nll`) instead of its overall accuracy, which a
  model that drops a small class barely loses;
* ``select="loss"``: early stopping and the best epoch on the validation set's class-balanced
  mean cross-entropy (:func:`~zbuf_occlude.learn.metrics.balanced_nll`, the plain mean
  cross-entropy on a class-balanced validation set; ties: the higher mean class accuracy),
  a signal that does not saturate: once a small validation set is classified without a
  mistake (accuracy 1.0, as held-out meshes often are after a few epochs), every later epoch
  ties on accuracy and the "best" epoch is only the tie-break, while the loss still tells
  the epoch whose predictions are most confident where they are right;
* ``warmup_epochs``: the learning rate rises linearly from ``lr / steps`` to ``lr`` over the
  first epochs' batches (Goyal et al. 2017, "Accurate, large minibatch SGD", §2.2);
* ``grad_clip``: the gradient's global L2 norm is clipped (Pascanu et al., ICML 2013).

Determinism: given a seed, model initialisation, the epoch's shuffle and augmentation all
come from that seed (and the epoch number), and torch runs with deterministic algorithms
on CPU; a resumed run continues from the last finished epoch's checkpoint (model,
optimiser, scheduler, best-so-far) and gives the same result as one that never stopped.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from zbuf_occlude.errors import CheckpointError, InvalidInputError
from zbuf_occlude.io import atomic
from zbuf_occlude.io.checkpoints import checkpoint_bytes, load_checkpoint
from zbuf_occlude.learn.data import CloudSet, augment, balanced_epoch_rows
from zbuf_occlude.learn.metrics import balanced_nll, mean_class_accuracy
from zbuf_occlude.learn.models import build_model, check_model_config

__all__ = [
    "TrainConfig", "OPTIMISER_DEFAULTS", "train", "predict", "TrainResult", "resolve_device", "seed_everything",
    "load_checkpoint", "load_model", "PLAIN_RECIPE", "STABLE_RECIPE", "RECIPES", "SELECT_CHOICES", "CHECKPOINT_FILES",
    "CheckpointWriter",
]  # fmt: skip

log = logging.getLogger(__name__)

#: Per-model optimiser defaults from the models' papers (module docstring).
OPTIMISER_DEFAULTS = {
    "pointnet": {"optimizer": "adam", "lr": 1e-3, "batch_size": 32, "lr_step": 20, "lr_gamma": 0.7, "weight_decay": 0.0},
    "voxnet": {"optimizer": "sgd", "lr": 1e-2, "batch_size": 32, "lr_step": 20, "lr_gamma": 0.1, "weight_decay": 1e-3},
    "3dmfv": {"optimizer": "adam", "lr": 1e-3, "batch_size": 64, "lr_step": 20, "lr_gamma": 0.7, "weight_decay": 0.0},
}

#: The recipe options' values that reproduce the plain loop (TrainConfig's defaults): a checkpoint
#: made before the options existed resumes with them.
PLAIN_RECIPE = {"balance": "none", "select": "accuracy", "warmup_epochs": 0, "grad_clip": None}
#: The recipe for small, imbalanced sets (module docstring): class-balanced sampling, selection
#: on the class-balanced validation loss, two epochs of warm-up, gradient norm clipped at 5 (a
#: bound that normal steps of these models stay under and a diverging step does not).
STABLE_RECIPE = {"balance": "sampler", "select": "loss", "warmup_epochs": 2, "grad_clip": 5.0}
#: What ``TrainConfig.select`` may choose the best epoch by (module docstring).
SELECT_CHOICES = ("accuracy", "mean_class_accuracy", "loss")
#: The recipes by name (``experiment sim2real --recipe``).
RECIPES = {"plain": PLAIN_RECIPE, "stable": STABLE_RECIPE}
#: Fields a run's identity leaves out at these values (:meth:`TrainConfig.identity`): options newer than some runs.
_IDENTITY_DEFAULTS = {**PLAIN_RECIPE, "aspect": False, "partial": False}


@dataclass
class TrainConfig:
    """What a training run does; ``None`` fields take :data:`OPTIMISER_DEFAULTS` of the model.

    Attributes
    ----------
    model : {"pointnet", "voxnet", "3dmfv"}
    epochs : int
    batch_size, lr, optimizer, lr_step, lr_gamma, weight_decay
        Optimiser settings (``optimizer``: ``adam`` or ``sgd``; the lr is multiplied by
        ``lr_gamma`` every ``lr_step`` epochs).
    patience : int
        Early stopping: stop after this many epochs without a better validation accuracy
        (0 disables); the best epoch's weights are kept.
    width : float
        Channel multiplier of the model (1.0 = its paper).
    fv_grid : int
        3DmFV Gaussians per side.
    augment : bool
        Rotation about z, scaling and jitter on every training batch.
    aspect : bool
        With ``augment``, random proportions too (:func:`~zbuf_occlude.learn.data.augment`'s
        ``aspect``: x, y and z stretched by independent factors in [2/3, 3/2]).
    partial : bool
        With ``augment``, partial objects too (:func:`~zbuf_occlude.learn.data.augment`'s ``partial``: half the
        clouds lose up to 0.3 of their height from the bottom and up to 0.875 of their points).
    balance : {"none", "sampler"}
        ``sampler``: class-balanced epochs (module docstring).
    select : {"accuracy", "mean_class_accuracy", "loss"}
        What early stopping and the best epoch go by on the validation set: its overall
        accuracy, its mean class accuracy (ties: the lower class-balanced loss) or its
        class-balanced mean cross-entropy (lower is better; ties: the higher mean class
        accuracy), the one that does not saturate at accuracy 1.0 (module docstring).
    warmup_epochs : int
        Epochs of linear learning-rate warm-up, per batch (0: none).
    grad_clip : float or None
        Maximum global L2 norm of the gradient (None: not clipped).
    seed : int
    device : {"cpu", "cuda"}
    threads : int or None
        ``torch.set_num_threads`` on CPU (None leaves torch's default).
    """

    model: str = "pointnet"
    epochs: int = 20
    batch_size: int | None = None
    lr: float | None = None
    optimizer: str | None = None
    lr_step: int | None = None
    lr_gamma: float | None = None
    weight_decay: float | None = None
    patience: int = 10
    width: float = 1.0
    fv_grid: int = 8
    augment: bool = True
    aspect: bool = False
    partial: bool = False
    balance: str = "none"
    select: str = "accuracy"
    warmup_epochs: int = 0
    grad_clip: float | None = None
    seed: int = 0
    device: str = "cpu"
    threads: int | None = None

    def __post_init__(self) -> None:
        if self.model not in OPTIMISER_DEFAULTS:
            raise InvalidInputError(f"unknown model {self.model!r}; choose from {', '.join(OPTIMISER_DEFAULTS)}")
        for key, value in OPTIMISER_DEFAULTS[self.model].items():
            if getattr(self, key) is None:
                setattr(self, key, value)
        if self.epochs < 1 or self.batch_size < 1:
            raise InvalidInputError(f"need epochs >= 1 and batch size >= 1, got {self.epochs}, {self.batch_size}")
        if self.optimizer not in ("adam", "sgd"):
            raise InvalidInputError(f"optimizer must be adam or sgd, got {self.optimizer!r}")
        if self.balance not in ("none", "sampler"):
            raise InvalidInputError(f"balance must be none or sampler, got {self.balance!r}")
        if self.select not in SELECT_CHOICES:
            raise InvalidInputError(f"select must be one of {', '.join(SELECT_CHOICES)}, got {self.select!r}")
        for name in ("aspect", "partial"):
            if getattr(self, name) and not self.augment:
                raise InvalidInputError(f"{name} is an augmentation: it needs augment=True")
        if self.warmup_epochs < 0 or (self.grad_clip is not None and not self.grad_clip > 0):
            raise InvalidInputError(f"need warmup_epochs >= 0 and grad_clip > 0 or None, got {self.warmup_epochs}, {self.grad_clip}")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def identity(self, exclude: tuple[str, ...]) -> dict:
        """The fields that make results differ, for a checkpoint's or a run's settings: all but
        ``exclude``, with recipe options at their :data:`PLAIN_RECIPE` values and ``aspect`` and ``partial``
        off left out (so a config from before those options existed compares equal)."""
        return {
            k: v for k, v in self.to_dict().items() if k not in exclude and not (k in _IDENTITY_DEFAULTS and v == _IDENTITY_DEFAULTS[k])
        }


@dataclass
class TrainResult:
    """What :func:`train` returns: the model (best or last weights), one history row per epoch,
    the best epoch (1-based) and its validation overall accuracy, mean class accuracy and
    class-balanced cross-entropy (``best_val_loss``; NaN without a validation set), whichever
    of them ``TrainConfig.select`` chose it by."""

    model: nn.Module
    history: list[dict] = field(default_factory=list)
    best_epoch: int = 0
    best_val_accuracy: float = float("nan")
    best_val_mean_class_accuracy: float = float("nan")
    best_val_loss: float = float("nan")
    seconds: float = 0.0
    samples_per_second: float = float("nan")


#: Where CUDA builds of torch are installed from (pip's index of the PyTorch project, CUDA 12.6).
CUDA_WHEEL_INDEX = "https://download.pytorch.org/whl/cu126"


def _torch_release() -> str:
    """This torch's version without its local build tag (``2.13.0+cpu`` → ``2.13.0``)."""
    return torch.__version__.split("+", 1)[0]


def _cuda_device(option: str, index: int | None) -> torch.device:
    from zbuf_occlude.errors import BackendUnavailable

    if torch.version.cuda is None and getattr(torch.version, "hip", None) is None:
        raise BackendUnavailable(
            f"{option}: this torch ({torch.__version__}) is a CPU-only build, without CUDA: install a CUDA build of the "
            f"same version (pip install torch=={_torch_release()} --index-url {CUDA_WHEEL_INDEX}), or use --device cpu"
        )
    count = torch.cuda.device_count()
    if not torch.cuda.is_available() or count == 0:
        built = f"CUDA {torch.version.cuda}" if torch.version.cuda else f"ROCm (HIP {torch.version.hip})"
        hidden = os.environ.get("CUDA_VISIBLE_DEVICES")
        where = f"; CUDA_VISIBLE_DEVICES={hidden!r} may hide it" if hidden is not None else ""
        raise BackendUnavailable(
            f"{option}: torch {torch.__version__} is built with {built} but sees no GPU (torch.cuda.is_available() is False, "
            f"torch.cuda.device_count() = {count}): no GPU or no working driver is visible here (check nvidia-smi{where}), "
            "or use --device cpu"
        )
    if index is not None and index >= count:
        raise BackendUnavailable(f"{option}: there is no GPU {index} here; torch sees {count} (cuda:0 to cuda:{count - 1})")
    return torch.device("cuda" if index is None else f"cuda:{index}")


def _mps_device(option: str) -> torch.device:
    from zbuf_occlude.errors import BackendUnavailable

    mps = getattr(torch.backends, "mps", None)
    if mps is None or not mps.is_built():
        raise BackendUnavailable(f"{option}: this torch ({torch.__version__}) is built without MPS (Apple's GPUs: the macOS builds have it), "
                                 "or use --device cpu")  # fmt: skip
    if not mps.is_available():
        raise BackendUnavailable(f"{option}: torch is built with MPS but cannot use it here: it needs macOS 12.3 or later on a Mac "
                                 "with an Apple-silicon or AMD GPU; or use --device cpu")  # fmt: skip
    return torch.device("mps")


def resolve_device(name: str) -> torch.device:
    """The torch device ``name`` (``cpu``, ``cuda``, ``cuda:N`` or ``mps``), checked to be usable here.

    Call it before any work: the message names the device and says what is really missing.

    Raises
    ------
    BackendUnavailable
        ``cuda``: torch is a CPU-only build (how to install a CUDA build of the same version),
        or it is built with CUDA but sees no GPU (``torch.cuda.device_count()``, the driver,
        ``CUDA_VISIBLE_DEVICES``), or GPU ``N`` does not exist; ``mps``: torch is built
        without MPS, or MPS is not available on this machine.
    InvalidInputError
        Not one of the names above.
    """
    option = f"--device {name}"
    kind, colon, index = str(name).strip().partition(":")
    if kind == "cpu" and not colon:
        return torch.device("cpu")
    if kind == "cuda" and (not colon or index.isdecimal()):
        return _cuda_device(option, int(index) if colon else None)
    if kind == "mps" and not colon:
        return _mps_device(option)
    raise InvalidInputError(f"--device must be cpu, cuda, cuda:N or mps, got {name!r}")


def seed_everything(seed: int) -> None:
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True, warn_only=True)


def _val_score(select: str, prob: np.ndarray, labels: np.ndarray, n_classes: int) -> tuple[float, ...]:
    """The validation score an epoch is ranked by (higher is better, compared as a tuple)."""
    pred = prob.argmax(axis=1)
    if select == "accuracy":
        return (float((pred == labels).mean()),)
    if select == "loss":
        return (-balanced_nll(prob, labels), mean_class_accuracy(labels, pred, n_classes))
    return (mean_class_accuracy(labels, pred, n_classes), -balanced_nll(prob, labels))


def _better(score: tuple[float, ...], best: tuple[float, ...] | None) -> bool:
    # NaN-safe: the first epoch always counts
    return best is None or not (score <= tuple(best))


def _loss(model: nn.Module, logits: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    loss = F.cross_entropy(logits, y)
    reg = getattr(model, "regularizer", None)
    return loss + reg if isinstance(reg, torch.Tensor) and reg.requires_grad else loss


@torch.no_grad()
def predict(model: nn.Module, points: np.ndarray, *, batch_size: int = 64, device: str | torch.device = "cpu"
            ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Class predictions and softmax probabilities.

    Parameters
    ----------
    points : (B, N, 3) float32
        Normalised clouds.

    Returns
    -------
    pred : (B,) int64
    prob : (B, K) float32
    """
    model.eval()
    device = torch.device(device)
    probs = []
    for i in range(0, len(points), batch_size):
        x = torch.from_numpy(np.ascontiguousarray(points[i : i + batch_size])).to(device)
        probs.append(torch.softmax(model(x), dim=1).cpu().numpy())
    prob = np.concatenate(probs) if probs else np.zeros((0, 0), dtype=np.float32)
    return prob.argmax(axis=1).astype(np.int64), prob


#: The files :func:`train` writes in its ``checkpoint_dir``: the resume point, the best weights, the history.
CHECKPOINT_FILES = ("last.pt", "best.pt", "history.json")
#: How :func:`train` writes a file of :data:`CHECKPOINT_FILES`: called with its name and its bytes,
#: it writes them atomically under that name (:meth:`zbuf_occlude.io.owned.OwnedFolder.write_bytes`,
#: :func:`zbuf_occlude.io.atomic.write_bytes`).
CheckpointWriter = Callable[[str, bytes], object]


def _save(write: CheckpointWriter, name: str, state: dict) -> None:
    # only tensors, numbers, strings, None, lists and dicts: what load_checkpoint's weights-only load takes
    write(name, checkpoint_bytes(state))


#: Keys of ``last.pt`` (resume point) and ``best.pt`` (:func:`load_model`).
RESUME_KEYS = ("config_key", "n_train", "epoch", "stale", "model", "optimizer", "scheduler", "history",
               "best_epoch", "best_val_accuracy", "best_model")  # fmt: skip
MODEL_KEYS = ("config", "n_classes", "model")


def _load_state(path: Path, target, state_dict, what: str) -> None:
    """``target.load_state_dict(state_dict)``; a mismatch names the checkpoint."""
    try:
        target.load_state_dict(state_dict)
    except (RuntimeError, KeyError, ValueError, TypeError, AttributeError, IndexError) as exc:
        raise CheckpointError(f"{path}: its {what} does not fit this model ({type(exc).__name__}: {exc})") from None


#: TrainConfig fields a run may change and still resume from its ``last.pt``: where and how fast it
#: runs, and how long (more epochs, another patience).
_MAY_CHANGE_ON_RESUME = ("device", "threads", "epochs", "patience")


def _from_older_checkpoint(state: dict) -> dict:
    """A ``last.pt`` an earlier version wrote, with the keys this version adds, as that version meant them.

    The one place that knows older checkpoints: before the recipe options (:data:`PLAIN_RECIPE`),
    ``last.pt`` held no ``best_val_mean_class_accuracy``, ``best_val_loss`` (unknown: NaN) or
    ``best_score`` (the best epoch went by overall accuracy: the best one's, none before a best
    epoch).  Its ``config_key`` compares equal to this version's, which leaves the recipe options out
    at their plain values (:meth:`TrainConfig.identity`).
    """
    state = dict(state)
    state.setdefault("best_val_mean_class_accuracy", float("nan"))
    state.setdefault("best_val_loss", float("nan"))
    state.setdefault("best_score", None if state["best_epoch"] == 0 else [state["best_val_accuracy"]])
    return state


@dataclass
class _Run:
    """One training run's moving parts, carried from epoch to epoch: what ``last.pt`` holds."""

    model: nn.Module
    opt: torch.optim.Optimizer
    sched: torch.optim.lr_scheduler.LRScheduler
    result: TrainResult
    config_key: dict
    n_train: int
    start_epoch: int = 0
    stale: int = 0
    best_score: list[float] | None = None
    best_state: dict | None = None
    seen: int = 0


def _start(config: TrainConfig, n_classes: int, n_train: int, device: torch.device) -> _Run:
    """The model, optimiser and scheduler of a new run, seeded (:func:`seed_everything`) before the model is built."""
    seed_everything(config.seed)
    model = build_model(config.model, n_classes, width=config.width, fv_grid=config.fv_grid).to(device)
    if config.optimizer == "adam":
        opt = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    else:
        opt = torch.optim.SGD(model.parameters(), lr=config.lr, momentum=0.9, weight_decay=config.weight_decay)
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=config.lr_step, gamma=config.lr_gamma)
    return _Run(model, opt, sched, TrainResult(model), config.identity(_MAY_CHANGE_ON_RESUME), n_train)


def _resume(run: _Run, last: Path, device: torch.device) -> None:
    """Continue ``run`` from ``last`` (a ``last.pt``): the epoch after its last, its weights, optimiser,
    scheduler, history and best so far; refused when it was made with another configuration or data,
    or when it leads out of its checkpoint folder."""
    state = _from_older_checkpoint(load_checkpoint(last, keys=RESUME_KEYS, device=device, within=last.parent))
    if state["config_key"] != run.config_key or state["n_train"] != run.n_train:
        raise InvalidInputError(
            f"{last} was made with another configuration or data "
            f"({state['config_key']}, {state['n_train']} samples); remove it or choose another --out"
        )
    for target, key in ((run.model, "model"), (run.opt, "optimizer"), (run.sched, "scheduler")):
        _load_state(last, target, state[key], key)
    run.start_epoch, run.stale, run.best_score, run.best_state = (
        state["epoch"] + 1,
        state["stale"],
        state["best_score"],
        state["best_model"],
    )
    result = run.result
    result.history, result.best_epoch, result.best_val_accuracy = state["history"], state["best_epoch"], state["best_val_accuracy"]
    result.best_val_mean_class_accuracy, result.best_val_loss = state["best_val_mean_class_accuracy"], state["best_val_loss"]
    shapes = {k: tuple(v.shape) for k, v in run.model.state_dict().items()}
    best = run.best_state
    if best is not None and (not isinstance(best, dict) or {k: tuple(getattr(v, "shape", ())) for k, v in best.items()} != shapes):
        raise CheckpointError(f"{last}: its best_model does not fit this model")


def _train_epoch(run: _Run, train_set: CloudSet, config: TrainConfig, epoch: int, device: torch.device, progress: bool) -> dict:
    """One epoch over ``train_set``; its shuffle and augmentation come from ``(seed, epoch)``.

    The learning rate warms up per batch over the first ``warmup_epochs`` (module docstring); the
    scheduler then steps from the epoch's own rate.  Returns the epoch's row of history (its
    training loss, accuracy and the rate after the step).
    """
    from zbuf_occlude.io.progress import progress as progress_bar

    model, opt = run.model, run.opt
    rng = np.random.default_rng([config.seed, epoch])
    torch.manual_seed(config.seed * 100_003 + epoch)
    order = balanced_epoch_rows(train_set.labels, rng) if config.balance == "sampler" else rng.permutation(len(train_set))
    model.train()
    epoch_lr = [g["lr"] for g in opt.param_groups]
    n_batches = -(-len(order) // config.batch_size)  # ceil
    warmup_steps = config.warmup_epochs * n_batches
    total_loss, correct = 0.0, 0
    batches = range(0, len(order), config.batch_size)
    bar = progress_bar(batches, desc=f"{config.model} epoch {epoch + 1}/{config.epochs}", unit="batch", enabled=progress, leave=False)
    for i in bar:
        rows = order[i : i + config.batch_size]
        if len(rows) < 2:  # batch norm needs two samples
            continue
        pts = train_set.points[rows]
        if config.augment:
            pts = augment(pts, rng, aspect=config.aspect, partial=config.partial)
        x = torch.from_numpy(np.ascontiguousarray(pts)).to(device)
        y = torch.from_numpy(train_set.labels[rows]).to(device)
        step = epoch * n_batches + i // config.batch_size
        if step < warmup_steps:
            for g, lr in zip(opt.param_groups, epoch_lr):
                g["lr"] = lr * (step + 1) / warmup_steps
        logits, loss = _step(model, opt, x, y, config.grad_clip)
        total_loss += loss.item() * len(rows)
        correct += int((logits.argmax(1) == y).sum())
        run.seen += len(rows)
        bar.set_postfix(loss=f"{loss.item():.3f}")
    for g, lr in zip(opt.param_groups, epoch_lr):  # the scheduler steps from the epoch's own rate
        g["lr"] = lr
    run.sched.step()
    return {"epoch": epoch + 1, "train_loss": total_loss / len(order), "train_accuracy": correct / len(order),
            "lr": opt.param_groups[0]["lr"]}  # fmt: skip


def _step(model: nn.Module, opt: torch.optim.Optimizer, x: torch.Tensor, y: torch.Tensor, grad_clip: float | None
          ) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """One optimiser step on the batch ``(x, y)``, the gradient's norm clipped at ``grad_clip``; its logits and loss."""
    opt.zero_grad()
    logits = model(x)
    loss = _loss(model, logits, y)
    loss.backward()
    if grad_clip is not None:
        torch.nn.utils.clip_grad_norm_(model.parameters(), grad_clip)
    opt.step()
    return logits, loss


def _validate(run: _Run, row: dict, val_set: CloudSet | None, config: TrainConfig, n_classes: int, epoch: int,
              device: torch.device) -> None:  # fmt: skip
    """Score the epoch on ``val_set`` into ``row`` and keep it as the best (or count it stale), by
    ``config.select``; without a validation set every epoch is the best so far."""
    result = run.result
    if val_set is None or not len(val_set):
        result.best_epoch, run.best_state = epoch + 1, None
        return
    pred, prob = predict(run.model, val_set.points, batch_size=config.batch_size, device=device)
    acc = float((pred == val_set.labels).mean())
    row["val_accuracy"] = acc
    score = _val_score(config.select, prob, val_set.labels, n_classes)
    mca, loss = mean_class_accuracy(val_set.labels, pred, n_classes), balanced_nll(prob, val_set.labels)
    if config.select != "accuracy":  # the plain loop's history keeps the rows it always had
        row["val_mean_class_accuracy"], row["val_balanced_nll"] = mca, loss
    if _better(score, run.best_score):
        result.best_val_accuracy, result.best_epoch, run.stale, run.best_score = acc, epoch + 1, 0, list(score)
        result.best_val_mean_class_accuracy, result.best_val_loss = mca, loss
        run.best_state = {k: v.detach().clone() for k, v in run.model.state_dict().items()}
    else:
        run.stale += 1


def _save_resume_point(write: CheckpointWriter, run: _Run, config: TrainConfig, epoch: int) -> None:
    """``last.pt`` after ``epoch``: everything :func:`_resume` needs to continue as if the run never stopped."""
    result = run.result
    _save(write, "last.pt", {
        "config": config.to_dict(), "config_key": run.config_key, "n_train": run.n_train, "epoch": epoch, "stale": run.stale,
        "model": run.model.state_dict(), "optimizer": run.opt.state_dict(), "scheduler": run.sched.state_dict(),
        "history": result.history, "best_epoch": result.best_epoch,
        "best_val_accuracy": result.best_val_accuracy, "best_model": run.best_state, "best_score": run.best_score,
        "best_val_mean_class_accuracy": result.best_val_mean_class_accuracy, "best_val_loss": result.best_val_loss,
    })  # fmt: skip


def _save_final(write: CheckpointWriter, run: _Run, config: TrainConfig, n_classes: int) -> None:
    """``best.pt`` (the weights :func:`train` returns, :func:`load_model`) and ``history.json``."""
    _save(write, "best.pt", {"config": config.to_dict(), "n_classes": n_classes, "model": run.model.state_dict(),
                             "best_epoch": run.result.best_epoch})  # fmt: skip
    write("history.json", json.dumps(run.result.history, indent=1).encode("utf-8"))


def _checkpoint_writer(checkpoint_dir: Path, writer: CheckpointWriter | None) -> CheckpointWriter:
    """``writer``, or atomic writes into ``checkpoint_dir`` (:func:`~zbuf_occlude.io.atomic.write_bytes`,
    which makes the folder when the first file is written)."""
    if writer is not None:
        return writer

    def write(name: str, data: bytes) -> None:
        atomic.write_bytes(checkpoint_dir / name, data)

    return write


def train(
    train_set: CloudSet,
    n_classes: int,
    config: TrainConfig,
    *,
    val_set: CloudSet | None = None,
    checkpoint_dir: str | os.PathLike | None = None,
    progress: bool = True,
    on_epoch: Callable[[dict], None] | None = None,
    checkpoint_writer: CheckpointWriter | None = None,
) -> TrainResult:
    """Train one model; with ``checkpoint_dir`` save after every epoch and resume from there.

    Parameters
    ----------
    train_set : CloudSet
        Normalised clouds ``(B, N, 3)``.
    n_classes : int
    config : TrainConfig
    val_set : CloudSet, optional
        Early stopping and best-epoch selection on its overall accuracy, mean class accuracy
        or class-balanced loss, as ``config.select`` says; without it the last epoch is kept.
    checkpoint_dir : path, optional
        ``last.pt`` (resume point), ``best.pt`` (best validation weights) and ``history.json``
        (:data:`CHECKPOINT_FILES`) go here; a ``last.pt`` made with another config is refused.
    checkpoint_writer : callable, optional
        How those files are written (:data:`CheckpointWriter`), for a ``checkpoint_dir`` inside
        an output folder a command holds
        (``lambda name, data: folder.write_bytes(f"checkpoints/{name}", data)``,
        :meth:`zbuf_occlude.io.owned.OwnedFolder.write_bytes`); default: atomically in
        ``checkpoint_dir`` (:func:`~zbuf_occlude.io.atomic.write_bytes`).
    progress : bool
        Progress on stderr per epoch (:func:`zbuf_occlude.io.progress.progress`; in a log, a line
        every few seconds).
    on_epoch : callable, optional
        Called with each epoch's row of history once the epoch is scored, before it is saved.

    Returns
    -------
    TrainResult
        ``model`` holds the best (or last) weights, in eval mode.

    Raises
    ------
    InvalidInputError
        Empty training set, or a checkpoint from a different configuration.
    CheckpointError
        A ``last.pt`` that is damaged, not a regular file (a FIFO), or does not fit the model
        (:func:`~zbuf_occlude.io.checkpoints.load_checkpoint`).
    UnsafePathError
        A ``last.pt`` that is a link leading out of ``checkpoint_dir``.
    OutputError
        ``checkpoint_dir`` cannot be made or written.
    """
    if len(train_set) == 0:
        raise InvalidInputError("empty training set")
    device = resolve_device(config.device)
    if config.threads and device.type == "cpu":
        torch.set_num_threads(config.threads)
    run = _start(config, n_classes, len(train_set), device)
    ckpt_dir = Path(checkpoint_dir) if checkpoint_dir is not None else None
    if ckpt_dir is not None and os.path.lexists(ckpt_dir / "last.pt"):  # a FIFO or a link is refused, not skipped
        _resume(run, ckpt_dir / "last.pt", device)
        log.info("resuming %s from epoch %d", config.model, run.start_epoch)
    write = _checkpoint_writer(ckpt_dir, checkpoint_writer) if ckpt_dir is not None else None
    t0 = time.perf_counter()
    for epoch in range(run.start_epoch, config.epochs):
        if config.patience and run.stale >= config.patience:
            break
        row = _train_epoch(run, train_set, config, epoch, device, progress)
        _validate(run, row, val_set, config, n_classes, epoch, device)
        run.result.history.append(row)
        log.info("%s epoch %d: %s", config.model, epoch + 1, row)
        if on_epoch is not None:
            on_epoch(row)
        if write is not None:
            _save_resume_point(write, run, config, epoch)
    if run.best_state is not None:
        run.model.load_state_dict(run.best_state)
    if write is not None:
        _save_final(write, run, config, n_classes)
    result = run.result
    result.seconds = time.perf_counter() - t0
    result.samples_per_second = run.seen / result.seconds if result.seconds > 0 and run.seen else float("nan")
    run.model.eval()
    return result


def load_model(path: str | os.PathLike, device: str = "cpu") -> tuple[nn.Module, dict]:
    """A model saved as ``best.pt`` by :func:`train`, in eval mode, and its config dict.

    Loaded as weights only (:func:`load_checkpoint`): a checkpoint never runs code.

    Raises
    ------
    CheckpointError
        Damaged, not a regular file (a FIFO), larger than
        :data:`~zbuf_occlude.io.caps.MAX_CHECKPOINT_BYTES`, not a ``best.pt`` of :func:`train`,
        it needs more than weights to load, or a
        config field out of the bounds of :func:`zbuf_occlude.learn.models.check_model_config`
        (``width`` <= 8, ``n_classes`` <= 1,000, ``fv_grid`` <= 16; the message names the field),
        checked before the model is built.
    """
    path = Path(path)
    state = load_checkpoint(path, keys=MODEL_KEYS, device=device)
    cfg = state["config"]
    if not isinstance(cfg, dict):
        raise CheckpointError(f"{path}: its config is a {type(cfg).__name__}, not a dict")
    missing = [k for k in ("model", "width", "fv_grid") if k not in cfg]
    if missing:
        raise CheckpointError(f"{path}: its config lacks {', '.join(missing)}")
    try:
        # bounded before anything is built: a 1 KB checkpoint may say width 1e9 (768 GB)
        name, n_classes, width, fv_grid = check_model_config(cfg["model"], state["n_classes"], cfg["width"], cfg["fv_grid"])
    except InvalidInputError as exc:
        raise CheckpointError(f"{path}: config field {exc}") from None
    model = build_model(name, n_classes, width=width, fv_grid=fv_grid)
    _load_state(path, model, state["model"], "model")
    return model.to(device).eval(), cfg
