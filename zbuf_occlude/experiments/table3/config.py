"""What an ``experiment elevation|augmentation`` run is: its sizes (:class:`Scale`) and its settings (:class:`Table3Config`).

:class:`Table3Config` checks its settings when it is made, in one place, before any mesh is read
or any folder held; its messages name the fields, or the options of the caller's ``option_names``
(the command line passes its flags).  Both experiments of :mod:`zbuf_occlude.experiments.table3`
take one.  Importing this module imports neither torch nor the visibility methods.
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping, Sequence
from dataclasses import InitVar, dataclass
from typing import TYPE_CHECKING

from zbuf_occlude.defaults import DEFAULT_METHOD
from zbuf_occlude.errors import InvalidInputError

if TYPE_CHECKING:  # torch is imported when a run trains
    from zbuf_occlude.learn.training import TrainConfig

__all__ = ["Scale", "SCALES", "Table3Config", "ELEVATION_MODEL", "AUGMENTATION_MODEL"]

#: The model Table 3A trains when none is named (the first of the paper's three).
ELEVATION_MODEL = "pointnet"
#: The model Table 3B trains when none is named (the paper's model of that table).
AUGMENTATION_MODEL = "3dmfv"


@dataclass(frozen=True)
class Scale:
    """Sizes of a run (``quick`` fits a 2-core CPU; ``paper`` is the paper's data and our full-size models)."""

    points: int
    samples_per_view: int
    dense_points: int
    resolution: int
    epochs: int
    patience: int
    width: dict
    fv_grid: int
    complete_per_mesh: int  # uniform clouds per mesh for C2 / Test 1
    val_fraction: float
    profile_points: int
    profile_azimuths: int


SCALES = {
    "quick": Scale(points=256, samples_per_view=1, dense_points=8192, resolution=512, epochs=30, patience=10,
                   width={"pointnet": 0.25, "voxnet": 0.5, "3dmfv": 0.25}, fv_grid=5, complete_per_mesh=25,
                   val_fraction=0.1, profile_points=4000, profile_azimuths=4),
    "paper": Scale(points=1024, samples_per_view=10, dense_points=100_000, resolution=1024, epochs=100, patience=20,
                   width={"pointnet": 1.0, "voxnet": 1.0, "3dmfv": 1.0}, fv_grid=8, complete_per_mesh=1,
                   val_fraction=0.1, profile_points=20_000, profile_azimuths=8),
}  # fmt: skip


@dataclass(frozen=True)
class Table3Config:
    """Every setting of a Table 3 run (:func:`~zbuf_occlude.experiments.table3.elevation.run_elevation`,
    :func:`~zbuf_occlude.experiments.table3.augmentation.run_augmentation`), checked when made.

    Parameters
    ----------
    model : {"pointnet", "voxnet", "3dmfv"}
        The classifier (the scale gives each its width).
    scale : {"quick", "paper"}
        Sizes of the run (:data:`SCALES`).
    epochs, points : int, optional
        Override the scale's epochs and points per cloud.
    method : str
        HSR method of the farm (a registered name, :func:`zbuf_occlude.available_methods`;
        ``og32`` is the paper's).
    classes : sequence of str, optional
        Class folders to keep (stored as a tuple); None: every class.
    seed : int
        Seed of the data set, the splits and the training (an int from 0 to
        :data:`~zbuf_occlude.defaults.MAX_SEED`).
    device : str
        torch device of the training (``cpu``, ``cuda``, ``cuda:N``, ``mps``); checked by
        :func:`~zbuf_occlude.learn.training.resolve_device` when the run trains (the command
        line checks it before any work).
    threads : int, optional
        torch CPU threads (None: torch's default).
    option_names : mapping of str to str, optional
        What the messages call each field (``{"points": "--points", ...}``: the command line's
        flags); a field not named here is called by its name.  Not stored.

    Raises
    ------
    InvalidInputError
        An unknown scale, model or HSR method, a seed that is not an int in [0, MAX_SEED], or
        epochs, points or threads below 1 or not whole numbers, naming the field or its option.
    """

    model: str
    scale: str = "quick"
    epochs: int | None = None
    points: int | None = None
    method: str = DEFAULT_METHOD
    classes: Sequence[str] | None = None
    seed: int = 0
    device: str = "cpu"
    threads: int | None = None
    option_names: InitVar[Mapping[str, str] | None] = None

    def __post_init__(self, option_names: Mapping[str, str] | None) -> None:
        from zbuf_occlude.geometry.sampling import check_seed
        from zbuf_occlude.visibility.registry import method_info

        def n(name: str) -> str:
            return (option_names or {}).get(name, name)

        if self.scale not in SCALES:
            raise InvalidInputError(f"{n('scale')} must be one of {', '.join(SCALES)}, got {self.scale!r}")
        if self.model not in SCALES[self.scale].width:
            raise InvalidInputError(f"{n('model')} must be one of {', '.join(SCALES[self.scale].width)}, got {self.model!r}")
        for name in ("epochs", "points", "threads"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1):
                raise InvalidInputError(f"{n(name)} must be a whole number >= 1, got {value!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, numbers.Integral):
            raise InvalidInputError(f"{n('seed')} must be a non-negative integer, got {self.seed!r}")
        object.__setattr__(self, "seed", check_seed(self.seed, name=n("seed")))
        try:
            method_info(self.method)
        except InvalidInputError as exc:
            raise InvalidInputError(f"{n('method')}: {exc}") from None
        if self.classes is not None:
            object.__setattr__(self, "classes", tuple(self.classes))

    @property
    def scale_values(self) -> Scale:
        """The scale's sizes (:data:`SCALES`)."""
        return SCALES[self.scale]

    @property
    def n_points(self) -> int:
        """Points per cloud: ``points``, or the scale's."""
        return self.points or self.scale_values.points

    def train_config(self) -> TrainConfig:
        """The :class:`~zbuf_occlude.learn.training.TrainConfig` of every training of the run (imports torch)."""
        from zbuf_occlude.learn.training import TrainConfig

        sc = self.scale_values
        return TrainConfig(model=self.model, epochs=self.epochs or sc.epochs, patience=sc.patience, width=sc.width[self.model],
                           fv_grid=sc.fv_grid, seed=self.seed, device=self.device, threads=self.threads)  # fmt: skip
