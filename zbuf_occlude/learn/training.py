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
import pickle
import time
import zipfile
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from zbuf_occlude.errors import CheckpointError, InvalidInputError, OutputError
from zbuf_occlude.io.atomic import atomic_path
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
_IDENTITY_DEFAULTS = {**PLAIN_RECIPE, "aspect": False}


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
        if self.aspect and not self.augment:
            raise InvalidInputError("aspect is an augmentation: it needs augment=True")
        if self.warmup_epochs < 0 or (self.grad_clip is not None and not self.grad_clip > 0):
            raise InvalidInputError(f"need warmup_epochs >= 0 and grad_clip > 0 or None, got {self.warmup_epochs}, {self.grad_clip}")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def identity(self, exclude: tuple[str, ...]) -> dict:
        """The fields that make results differ, for a checkpoint's or a run's settings: all but
        ``exclude``, with recipe options at their :data:`PLAIN_RECIPE` values and ``aspect`` off
        left out (so a config from before those options existed compares equal)."""
        return {k: v for k, v in self.to_dict().items() if k not in exclude and not (k in _IDENTITY_DEFAULTS and v == _IDENTITY_DEFAULTS[k])}


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
#: How :func:`train` writes a file of :data:`CHECKPOINT_FILES`: called with its name, it returns a
#: context manager that yields the temporary path to write and gives the file its name on exit.
CheckpointWriter = Callable[[str], AbstractContextManager[Path]]


def _save(write: CheckpointWriter, name: str, state: dict) -> None:
    # only tensors, numbers, strings, None, lists and dicts: what load_checkpoint's weights-only load takes
    with write(name) as tmp:
        torch.save(state, tmp)


#: Keys of ``last.pt`` (resume point) and ``best.pt`` (:func:`load_model`).
RESUME_KEYS = ("config_key", "n_train", "epoch", "stale", "model", "optimizer", "scheduler", "history",
               "best_epoch", "best_val_accuracy", "best_model")  # fmt: skip
MODEL_KEYS = ("config", "n_classes", "model")


def load_checkpoint(path: str | os.PathLike, *, keys: tuple[str, ...] = (), device: str | torch.device = "cpu") -> dict:
    """A checkpoint of :func:`train`, loaded as weights only: it never runs code.

    ``torch.load(weights_only=True)`` unpickles tensors, numbers, strings, ``None``, lists
    and dicts only; a checkpoint that needs anything else (pickled objects, which could run
    code) is refused.

    Parameters
    ----------
    path : str or PathLike
    keys : tuple of str
        Keys the checkpoint's dict must hold.
    device : str or torch.device
        Where tensors are loaded (``map_location``).

    Raises
    ------
    CheckpointError
        The file is missing, damaged, truncated, not a PyTorch checkpoint, needs more than
        weights to load, or lacks one of ``keys`` (the message names the file).
    """
    path = Path(path)
    try:
        state = torch.load(path, map_location=device, weights_only=True)
    except pickle.UnpicklingError as exc:
        if "weights only" in str(exc).lower() or "weights_only" in str(exc):
            raise CheckpointError(
                f"{path} needs more than weights to load (pickled objects that could run code); refused: "
                "zbuf_occlude loads only tensors and plain data from checkpoints"
            ) from None
        raise CheckpointError(f"{path} is damaged or not a PyTorch checkpoint ({exc})") from None
    except OSError as exc:
        raise CheckpointError(f"cannot read the checkpoint {path}: {exc.strerror or exc}") from None
    except (RuntimeError, EOFError, ValueError, zipfile.BadZipFile, KeyError, AttributeError, TypeError) as exc:
        # torch reports a truncated or foreign file as a RuntimeError of its zip reader, an empty one as EOFError
        raise CheckpointError(f"{path} is damaged, truncated or not a PyTorch checkpoint ({type(exc).__name__}: {exc})") from None
    if not isinstance(state, dict):
        raise CheckpointError(f"{path} is not a zbuf_occlude checkpoint (a {type(state).__name__}, not a dict)")
    missing = [k for k in keys if k not in state]
    if missing:
        raise CheckpointError(f"{path} is not a zbuf_occlude checkpoint of this kind: it lacks {', '.join(missing)}")
    return state


def _load_state(path: Path, target, state_dict, what: str) -> None:
    """``target.load_state_dict(state_dict)``; a mismatch names the checkpoint."""
    try:
        target.load_state_dict(state_dict)
    except (RuntimeError, KeyError, ValueError, TypeError, AttributeError, IndexError) as exc:
        raise CheckpointError(f"{path}: its {what} does not fit this model ({type(exc).__name__}: {exc})") from None


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
        an output folder a command holds (``lambda name: folder.write(f"checkpoints/{name}")``,
        :meth:`zbuf_occlude.io.owned.OwnedFolder.write`); default: atomically in
        ``checkpoint_dir`` (:func:`~zbuf_occlude.io.atomic.atomic_path`).
    progress : bool
        Progress on stderr per epoch (:func:`zbuf_occlude.io.progress.progress`; in a log, a line
        every few seconds).

    Returns
    -------
    TrainResult
        ``model`` holds the best (or last) weights, in eval mode.

    Raises
    ------
    InvalidInputError
        Empty training set, or a checkpoint from a different configuration.
    """
    from zbuf_occlude.io.progress import progress as progress_bar

    if len(train_set) == 0:
        raise InvalidInputError("empty training set")
    device = resolve_device(config.device)
    if config.threads and device.type == "cpu":
        torch.set_num_threads(config.threads)
    seed_everything(config.seed)
    model = build_model(config.model, n_classes, width=config.width, fv_grid=config.fv_grid).to(device)
    if config.optimizer == "adam":
        opt = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    else:
        opt = torch.optim.SGD(model.parameters(), lr=config.lr, momentum=0.9, weight_decay=config.weight_decay)
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=config.lr_step, gamma=config.lr_gamma)
    result = TrainResult(model)
    start_epoch, best_state, stale, best_score = 0, None, 0, None
    cfg = config.to_dict()
    cfg_key = config.identity(("device", "threads", "epochs", "patience"))  # older checkpoints resume
    ckpt_dir = Path(checkpoint_dir) if checkpoint_dir is not None else None
    write = checkpoint_writer or (lambda name: atomic_path(ckpt_dir / name))
    if ckpt_dir is not None and (ckpt_dir / "last.pt").is_file():
        last = ckpt_dir / "last.pt"
        state = load_checkpoint(last, keys=RESUME_KEYS, device=device)
        if state["config_key"] != cfg_key or state["n_train"] != len(train_set):
            raise InvalidInputError(
                f"{last} was made with another configuration or data "
                f"({state['config_key']}, {state['n_train']} samples); remove it or choose another --out"
            )
        for target, key in ((model, "model"), (opt, "optimizer"), (sched, "scheduler")):
            _load_state(last, target, state[key], key)
        start_epoch, stale = state["epoch"] + 1, state["stale"]
        result.history, result.best_epoch = state["history"], state["best_epoch"]
        result.best_val_accuracy = state["best_val_accuracy"]
        result.best_val_mean_class_accuracy = state.get("best_val_mean_class_accuracy", float("nan"))
        result.best_val_loss = state.get("best_val_loss", float("nan"))
        best_score = state.get("best_score", None if state["best_epoch"] == 0 else [result.best_val_accuracy])
        best_state = state["best_model"]
        shapes = {k: tuple(v.shape) for k, v in model.state_dict().items()}
        if best_state is not None and (
            not isinstance(best_state, dict)
            or {k: tuple(getattr(v, "shape", ())) for k, v in best_state.items()} != shapes
        ):
            raise CheckpointError(f"{last}: its best_model does not fit this model")
        log.info("resuming %s from epoch %d", config.model, start_epoch)
    t0, seen = time.perf_counter(), 0
    n = len(train_set)
    for epoch in range(start_epoch, config.epochs):
        if config.patience and stale >= config.patience:
            break
        rng = np.random.default_rng([config.seed, epoch])
        torch.manual_seed(config.seed * 100_003 + epoch)
        order = balanced_epoch_rows(train_set.labels, rng) if config.balance == "sampler" else rng.permutation(n)
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
                pts = augment(pts, rng, aspect=config.aspect)
            x = torch.from_numpy(np.ascontiguousarray(pts)).to(device)
            y = torch.from_numpy(train_set.labels[rows]).to(device)
            step = epoch * n_batches + i // config.batch_size
            if step < warmup_steps:
                for g, lr in zip(opt.param_groups, epoch_lr):
                    g["lr"] = lr * (step + 1) / warmup_steps
            opt.zero_grad()
            logits = model(x)
            loss = _loss(model, logits, y)
            loss.backward()
            if config.grad_clip is not None:
                torch.nn.utils.clip_grad_norm_(model.parameters(), config.grad_clip)
            opt.step()
            total_loss += loss.item() * len(rows)
            correct += int((logits.argmax(1) == y).sum())
            seen += len(rows)
            bar.set_postfix(loss=f"{loss.item():.3f}")
        for g, lr in zip(opt.param_groups, epoch_lr):  # the scheduler steps from the epoch's own rate
            g["lr"] = lr
        sched.step()
        row = {"epoch": epoch + 1, "train_loss": total_loss / len(order), "train_accuracy": correct / len(order),
               "lr": opt.param_groups[0]["lr"]}  # fmt: skip
        if val_set is not None and len(val_set):
            pred, prob = predict(model, val_set.points, batch_size=config.batch_size, device=device)
            acc = float((pred == val_set.labels).mean())
            row["val_accuracy"] = acc
            score = _val_score(config.select, prob, val_set.labels, n_classes)
            mca, loss = mean_class_accuracy(val_set.labels, pred, n_classes), balanced_nll(prob, val_set.labels)
            if config.select != "accuracy":  # the plain loop's history keeps the rows it always had
                row["val_mean_class_accuracy"], row["val_balanced_nll"] = mca, loss
            if _better(score, best_score):
                result.best_val_accuracy, result.best_epoch, stale, best_score = acc, epoch + 1, 0, list(score)
                result.best_val_mean_class_accuracy, result.best_val_loss = mca, loss
                best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
            else:
                stale += 1
        else:
            result.best_epoch = epoch + 1
            best_state = None
        result.history.append(row)
        log.info("%s epoch %d: %s", config.model, epoch + 1, row)
        if on_epoch is not None:
            on_epoch(row)
        if ckpt_dir is not None:
            if checkpoint_writer is None:
                try:
                    ckpt_dir.mkdir(parents=True, exist_ok=True)
                except OSError as exc:
                    raise OutputError(f"cannot create {ckpt_dir}: {exc}") from None
            _save(write, "last.pt", {
                "config": cfg, "config_key": cfg_key, "n_train": n, "epoch": epoch, "stale": stale,
                "model": model.state_dict(), "optimizer": opt.state_dict(), "scheduler": sched.state_dict(),
                "history": result.history, "best_epoch": result.best_epoch,
                "best_val_accuracy": result.best_val_accuracy, "best_model": best_state, "best_score": best_score,
                "best_val_mean_class_accuracy": result.best_val_mean_class_accuracy, "best_val_loss": result.best_val_loss,
            })  # fmt: skip
    if best_state is not None:
        model.load_state_dict(best_state)
    if ckpt_dir is not None:
        _save(write, "best.pt", {"config": cfg, "n_classes": n_classes, "model": model.state_dict(),
                                 "best_epoch": result.best_epoch})  # fmt: skip
        with write("history.json") as tmp:
            tmp.write_text(json.dumps(result.history, indent=1))
    result.seconds = time.perf_counter() - t0
    result.samples_per_second = seen / result.seconds if result.seconds > 0 and seen else float("nan")
    model.eval()
    return result


def load_model(path: str | os.PathLike, device: str = "cpu") -> tuple[nn.Module, dict]:
    """A model saved as ``best.pt`` by :func:`train`, in eval mode, and its config dict.

    Loaded as weights only (:func:`load_checkpoint`): a checkpoint never runs code.

    Raises
    ------
    CheckpointError
        Damaged, not a ``best.pt`` of :func:`train`, it needs more than weights to load, or a
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
