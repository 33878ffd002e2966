"""What an ``experiment sim2real`` run is: its sizes (:class:`Sim2RealScale`) and every setting (:class:`Sim2RealConfig`).

:class:`Sim2RealConfig` checks its settings when it is made, in one place; its messages name the
fields, or the options of the caller's ``option_names`` (the command line passes its flags).
:meth:`Sim2RealConfig.identity` is what of it ``settings.json`` holds, so that a rerun resumes
only a run made with the same settings (:func:`zbuf_occlude.experiments.sim2real.run.run_sim2real`).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping
from dataclasses import InitVar, asdict, dataclass, field, replace
from typing import TYPE_CHECKING, Any

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.sim2real.data import (
    FITTED_SETS,
    OCCLUDED_POINTS,
    POINT_VISIBILITY,
    TRAINING_SETS,
    sensor_elevation_deg,
)
from zbuf_occlude.sensors.fit.class_placement import LIDAR_PLACEMENT, MIN_RETURNS
from zbuf_occlude.experiments.sim2real.real import KEEP_SCALE_UNIT_M
from zbuf_occlude.mesh.sizes import CLASS_SIZES_M, SizeRange
from zbuf_occlude.sensors.beam.adaptive_cast import footprint_mode
from zbuf_occlude.sensors.request import TRAINING_RETURNS, check_kept_returns

if TYPE_CHECKING:  # torch is imported when a run trains
    from zbuf_occlude.learn.training import TrainConfig

__all__ = ["Sim2RealScale", "SIM2REAL_SCALES", "SIM2REAL_RECIPE", "VALIDATION_CHOICES", "FITTED_SHAPES", "WIDTH_SHAPES",
           "FAMILY_COUNT", "FAMILIES_SEED", "Sim2RealConfig"]  # fmt: skip

#: The training recipe of every run (:data:`zbuf_occlude.learn.training.RECIPES`; :mod:`~zbuf_occlude.experiments.sim2real`).
SIM2REAL_RECIPE = "stable"
#: What the mesh-only sets validate on: clouds of held-out whole meshes, or the real scans of the fit half.
VALIDATION_CHOICES = ("meshes", "fit-half")
#: What ``fitted_shape`` may give the fitted+placed set's meshes, and the fitted crop keywords each uses
#: (``widen`` is ``widths`` with every stretch below 1 raised to 1; ``occlude`` meets the widths with a
#: side occluder instead of a stretch).
FITTED_SHAPES = {"widths": "across_sight_width_m", "widen": "across_sight_width_m", "occlude": "across_sight_width_m",
                 "outline": "across_sight_profile"}  # fmt: skip
#: The shapes that meet the widths, of which a run takes one, and how each meets them
#: (:data:`~zbuf_occlude.sensors.fit.class_placement.WIDTH_BY`).
WIDTH_SHAPES = {"widths": "stretch", "widen": "widen", "occlude": "occluder"}
#: Family objects added per class with ``fit_families`` when ``family_count`` is not given.
FAMILY_COUNT = 8
#: The seed of the families' objects and of their fit's crops (:func:`~zbuf_occlude.experiments.sim2real.families.fit_families`): the same every run.
FAMILIES_SEED = 0


@dataclass(frozen=True)
class Sim2RealScale:
    """Sizes of a run: points per cloud, training clouds per class, validation clouds per class
    (from held-out meshes), epochs, early-stopping patience, model width, 3DmFV grid, the
    ``occluded`` set's dense points and z-buffer resolution, and the share of meshes held out."""

    points: int
    per_class: int
    val_per_class: int
    epochs: int
    patience: int
    width: dict
    fv_grid: int
    dense_points: int
    resolution: int
    val_mesh_fraction: float


SIM2REAL_SCALES = {
    "quick": Sim2RealScale(points=256, per_class=100, val_per_class=25, epochs=20, patience=6,
                           width={"pointnet": 0.25, "voxnet": 0.5, "3dmfv": 0.25}, fv_grid=5, dense_points=8192,
                           resolution=512, val_mesh_fraction=0.2),
    "paper": Sim2RealScale(points=1024, per_class=1000, val_per_class=200, epochs=100, patience=20,
                           width={"pointnet": 1.0, "voxnet": 1.0, "3dmfv": 1.0}, fv_grid=8, dense_points=100_000,
                           resolution=1024, val_mesh_fraction=0.2),
}  # fmt: skip


@dataclass(frozen=True)
class Sim2RealConfig:
    """Every setting of a sim-to-real run (:mod:`zbuf_occlude.experiments.sim2real`), checked when made.

    Parameters
    ----------
    mesh_root : path
        ``CLASS/.../mesh`` files (any format :func:`zbuf_occlude.load_mesh` reads).
    real : path
        Real scans (:func:`zbuf_occlude.real_scans.datasets.load_real_scans`; ``real_options`` are
        passed to it).
    model : {"pointnet", "voxnet", "3dmfv"}
    sensor : str, Lidar or AirborneScanner
        Scanner of the ``lidar`` set: a preset name (:data:`zbuf_occlude.sensors.LIDAR_PRESETS`,
        :data:`zbuf_occlude.sensors.patterns.airborne.AIRBORNE_PRESETS`) or a sensor ``.json`` file.
    scale : {"quick", "paper"}; points, epochs, per_class : int, optional
        Override the scale's points per cloud, epochs and training clouds per class (the
        validation clouds per class follow in the scale's proportion).
    seeds : int
        Repetitions (≥ 2 for a standard deviation; 5 or more for a permutation test able to
        reach p < 0.05).
    keep_scale : bool
        Keep metres (centred, divided by :data:`~zbuf_occlude.experiments.sim2real.real.KEEP_SCALE_UNIT_M`;
        augmentation off, random yaw drawn once per cloud) instead of the paper's normalisation.
    label_map : mapping, optional
        Real label → class folder name (labels equal to a class up to case need none).
    up, up_map : mesh up axis and per-file overrides (:func:`~zbuf_occlude.mesh.inputs.class_folders.find_class_meshes`).
    sizes : mapping of str to SizeRange, optional
        Real sizes per class (default :data:`zbuf_occlude.mesh.sizes.CLASS_SIZES_M`).
    real_options : mapping, optional
        Keywords of :func:`~zbuf_occlude.real_scans.datasets.load_real_scans`.
    min_returns : int
        LiDAR crops with fewer returns are redrawn (:data:`~zbuf_occlude.sensors.fit.class_placement.MIN_RETURNS`).
        Before any set is made, every mesh is tried once with the sensor; one that gives no
        such crop is skipped with a warning naming it (``settings.json``: ``meshes_skipped``).
    method : str
        HSR method of the ``occluded`` set.
    classes : "real", sequence of str, or None
        Class folders to train on: ``"real"``, those the real scans have (after
        ``label_map``; a real scan can then only be called a class it can be); a list, those;
        None, every class folder of ``mesh_root``.
    occluded_elevation_deg : (lo, hi), optional
        Camera elevations of the ``occluded`` set, degrees in [-90, 90], drawn uniformly.
        Default: the range ``sensor`` sees objects from
        (:func:`~zbuf_occlude.experiments.sim2real.data.sensor_elevation_deg`: about 3.7° to
        21.8° for a spinning LiDAR on the ``lidar`` set's mount, ``90° − swath/2`` to 90° for an
        airborne scanner, e.g. 61° to 90°); :attr:`occluded_elevation_from` says which.
    fit_sensor : bool
        Fit ``sensor`` (a spinning LiDAR) to the sensor-frame points of the fixed first half of
        the real scans (the half real→real trains on), and each class's crop distances and
        heights to the same scans, and add the
        :data:`~zbuf_occlude.experiments.sim2real.data.FITTED_SETS` (every row is scored on the
        other half with or without it; :mod:`~zbuf_occlude.experiments.sim2real`).
    recipe : {"stable", "plain"}
        Training recipe (:data:`zbuf_occlude.learn.training.RECIPES`).
    best_epoch_by : {"loss", "mean_class_accuracy", "accuracy"}, optional
        What every run's best epoch (and early stopping) goes by on its validation set
        (:class:`~zbuf_occlude.learn.training.TrainConfig`'s ``select``); default: the
        recipe's (``stable``: the class-balanced validation loss, which does not saturate at
        accuracy 1.0 as held-out meshes' accuracy often does; ``plain``: overall accuracy).
    validate_on : {"meshes", "fit-half"}
        What the mesh-only sets validate on (best epoch, early stopping): clouds of the same kind
        from held-out whole meshes, or, with ``fit_sensor``, the real scans of the fit half (the
        sets then train on every mesh). real→real is the same either way.
    fitted_shape : tuple of str
        What the fitted+placed set changes in each mesh's shape (needs ``fit_sensor``; keys of
        :data:`FITTED_SHAPES`): ``"widths"``, a horizontal stretch to the class's widths across
        the line of sight, or ``"widen"``, the same stretch where it widens the mesh and none
        where it would narrow it (a narrow real width is often a partial view, not a thinner
        object), or ``"occlude"``, a side occluder that leaves in view as much of the mesh as
        the widths show where its crops are wider (a partial view; nothing hidden where they are
        narrower); ``"outline"``, a warp to its outline over the height, alone or with one of
        the three.  Empty (default): the meshes' own shapes.  Each is fitted per mesh once
        (:func:`~zbuf_occlude.sensors.fit.class_placement.fit_mesh_shapes`).
    returns : int or str
        What the ``lidar`` set's scanner keeps of each pulse's returns
        (:func:`~zbuf_occlude.sensors.request.kept_returns`, the rule ``farm --sensor`` follows too):
        1 (default, :data:`~zbuf_occlude.sensors.request.TRAINING_RETURNS`) or ``"strongest"``: one return per
        pulse (a spinning preset as given; a beam that resolves echoes, an airborne preset's, records its
        footprint's strongest echo); ``"first"`` or ``"last"``: the receiver's first or last echo; ``"all"``:
        what the device records; N above 1: the multi-return model (each pulse's footprint cast as
        sub-rays, its hits resolved into up to N echoes).  ``settings.json``: ``lidar_returns`` where it
        is not 1.  The fits (``fit_sensor``, ``fit_families``) and the fitted sets keep one return per pulse, as the
        real scans they are fitted to record.
    footprint_cast : {"auto", "exact", "adaptive"}
        How the ``lidar`` set's crops cast a footprint whose echoes are resolved
        (:func:`~zbuf_occlude.sensors.crops.object_crops`' ``footprint``): "adaptive" casts a
        pulse's whole footprint only where its centre ray and its neighbours do not show one plane
        filling it, at a fraction of the cost, and needs a beam that resolves a footprint's echoes
        (``returns`` above 1, or a sensor whose beam has a return mode); "exact" every sub-ray;
        "auto" (default) "adaptive" where it applies, else "exact".  ``settings.json``:
        ``lidar_footprint`` "adaptive" where the crops cast it (:attr:`footprint_mode`).  The
        meshes are still screened with the whole footprint.
    occluded_points : bool
        Also train on the :data:`~zbuf_occlude.experiments.sim2real.data.OCCLUDED_POINTS` set:
        the ``occluded`` set's clouds (the same dense samples, poses and draws) with visibility
        decided from the points alone (:data:`~zbuf_occlude.experiments.sim2real.data.POINT_VISIBILITY`),
        tested against ``occluded``.  Not with a ``method`` that already decides from the points
        alone (nothing to compare).
    aspect : bool
        Every run's augmentation also draws random proportions (x, y and z stretched by
        independent factors in [2/3, 3/2], DGCNN's range; :func:`zbuf_occlude.learn.data.augment`),
        real→real's too.  Not with ``keep_scale``, which turns augmentation off.
    partial : bool
        Every run's augmentation also makes half the clouds partial (up to 0.3 of the height cut from the bottom, up
        to 0.875 of the points dropped; :func:`zbuf_occlude.learn.data.augment`), real→real's too.  Not with
        ``keep_scale`` nor with ``aspect``.
    fit_families : bool
        Fit the procedural families (:data:`~zbuf_occlude.mesh.families.FAMILIES`) of each class to
        the fixed first half of the real scans (the half real→real trains on, the fit half with
        ``fit_sensor``; :func:`~zbuf_occlude.experiments.sim2real.families.fit_families`) and add
        ``family_count`` objects of the chosen families per class to the meshes of every mesh-only
        set (``fitted_families.json``; ``settings.json``: ``fit_families``).  A class no family
        writes to, or whose meshes' crops come nearer the real ones than every family's, keeps the
        user's meshes alone.
    family_count : int
        Family objects added per fitted class (:data:`FAMILY_COUNT`), 1 to
        :data:`~zbuf_occlude.defaults.MAX_FAMILY_MESHES`.
    family_heights : bool
        With ``fit_families``: each class a family writes to takes the first half's object heights as its
        size, for its meshes, its families and every mesh-only set alike
        (:func:`~zbuf_occlude.experiments.sim2real.families.family_heights`; ``settings.json``: ``fit_families``).
    sets : sequence of str
        Train only these mesh-only sets (of :attr:`available_sets`; real→real always trains);
        empty (default): every one.  ``settings.json`` records them when given.
    option_names : mapping of str to str, optional
        What the messages call each field (``{"validate_on": "--validate-on", ...}``: the
        command line's flags); a field not named here is called by its name.  Not stored.

    Attributes
    ----------
    occluded_elevation_from : str
        ``"option"`` when ``occluded_elevation_deg`` was given, else how it was derived from the
        sensor (one line; ``settings.json`` records it).

    Raises
    ------
    InvalidInputError
        A bad setting (an unknown scale, recipe, model or validation choice, seeds below 1,
        ``aspect`` or ``partial`` with ``keep_scale``, both together, ``occluded_points`` with ``method`` point-splat,
        ``validate_on="fit-half"`` or ``fitted_shape`` without
        ``fit_sensor``, an unknown shape or two that meet the widths, elevations outside
        [-90, 90] degrees, a sensor that is no LiDAR, ``fit_sensor`` with an airborne
        ``sensor``, ``returns`` not one of :func:`~zbuf_occlude.sensors.request.kept_returns`' choices, or
        above 1 with a sensor without a beam divergence, a ``family_count`` out of range, a set in ``sets`` these settings
        do not make), naming the field or its option.
    """

    mesh_root: str | os.PathLike
    real: str | os.PathLike
    model: str = "pointnet"
    sensor: Any = "hdl32e"
    scale: str = "quick"
    points: int | None = None
    epochs: int | None = None
    per_class: int | None = None
    seeds: int = 5
    keep_scale: bool = False
    label_map: Mapping[str, str] | None = None
    up: str = "auto"
    up_map: Mapping[str, str] | None = None
    sizes: Mapping[str, SizeRange] | None = None
    real_options: Mapping[str, Any] | None = None
    min_returns: int = MIN_RETURNS
    method: str = "auto"
    classes: str | tuple[str, ...] | None = None
    occluded_elevation_deg: tuple[float, float] | None = None
    fit_sensor: bool = False
    recipe: str = SIM2REAL_RECIPE
    best_epoch_by: str | None = None
    validate_on: str = "meshes"
    fitted_shape: tuple[str, ...] = ()
    aspect: bool = False
    partial: bool = False
    occluded_points: bool = False
    returns: int | str = TRAINING_RETURNS
    footprint_cast: str = "auto"
    fit_families: bool = False
    family_count: int = FAMILY_COUNT
    family_heights: bool = False
    sets: tuple[str, ...] = ()
    option_names: InitVar[Mapping[str, str] | None] = None
    occluded_elevation_from: str = field(init=False, default="option")
    #: The sensor as given (``sensor`` is it with ``returns`` kept): the fits take it with one return a pulse.
    given_sensor: Any = field(init=False, default=None, repr=False, compare=False)

    def __post_init__(self, option_names: Mapping[str, str] | None) -> None:
        from zbuf_occlude.learn.training import OPTIMISER_DEFAULTS, RECIPES, SELECT_CHOICES

        def n(name: str) -> str:
            return (option_names or {}).get(name, name)

        for name, value in (("label_map", self.label_map), ("up_map", self.up_map), ("real_options", self.real_options)):
            object.__setattr__(self, name, dict(value or {}))
        object.__setattr__(self, "sizes", dict(self.sizes or CLASS_SIZES_M))
        object.__setattr__(self, "fitted_shape", tuple(self.fitted_shape))
        if self.classes is not None and self.classes != "real":
            object.__setattr__(self, "classes", tuple(self.classes))
        if self.model not in OPTIMISER_DEFAULTS:
            raise InvalidInputError(f"{n('model')} must be one of {', '.join(OPTIMISER_DEFAULTS)}, got {self.model!r}")
        if self.scale not in SIM2REAL_SCALES:
            raise InvalidInputError(f"{n('scale')} must be one of {sorted(SIM2REAL_SCALES)}, got {self.scale!r}")
        if self.recipe not in RECIPES:
            raise InvalidInputError(f"{n('recipe')} must be one of {sorted(RECIPES)}, got {self.recipe!r}")
        if self.best_epoch_by is not None and self.best_epoch_by not in SELECT_CHOICES:
            raise InvalidInputError(f"{n('best_epoch_by')} must be one of {', '.join(SELECT_CHOICES)}, got {self.best_epoch_by!r}")
        for name in ("aspect", "partial"):
            if getattr(self, name) and self.keep_scale:
                raise InvalidInputError(f"{n(name)} needs augmentation, which {n('keep_scale')} turns off")
        if self.aspect and self.partial:
            raise InvalidInputError(f"{n('aspect')} and {n('partial')} are two augmentations: choose one")
        if int(self.seeds) < 1:
            raise InvalidInputError(f"{n('seeds')} must be >= 1, got {self.seeds}")
        self._check_validation(n)
        self._check_occluded_points(n)
        self._check_fitted_shape(n)
        self._check_families(n)
        self._check_sets(n)
        self._check_sensor(n)
        if self.occluded_elevation_deg is None:  # derived from the sensor, which is checked by now
            elevation, source = sensor_elevation_deg(self.sensor)
            object.__setattr__(self, "occluded_elevation_deg", elevation)
            object.__setattr__(self, "occluded_elevation_from", source)
        object.__setattr__(self, "occluded_elevation_deg", _elevation_range(self.occluded_elevation_deg, n("occluded_elevation_deg")))

    def _check_validation(self, n) -> None:
        if self.validate_on not in VALIDATION_CHOICES:
            raise InvalidInputError(f"{n('validate_on')} must be one of {', '.join(VALIDATION_CHOICES)}, got {self.validate_on!r}")
        if self.validate_on == "fit-half" and not self.fit_sensor:
            raise InvalidInputError(f"{n('validate_on')} fit-half needs {n('fit_sensor')} (which splits the real scans into the fit half "
                                    "and the scored half)")  # fmt: skip

    def _check_occluded_points(self, n) -> None:
        if not self.occluded_points:
            return
        from zbuf_occlude.visibility.registry import method_info

        try:
            method = method_info(self.method).name  # the canonical name of an alias
        except InvalidInputError as exc:  # an unknown method: refused here too, before any work
            raise InvalidInputError(f"{n('method')}: {exc}") from None
        if method == POINT_VISIBILITY:
            raise InvalidInputError(f"{n('occluded_points')} compares {POINT_VISIBILITY} visibility with the occluded set's method, "
                                    f"but {n('method')} {self.method} is {POINT_VISIBILITY} already: give a mesh method or drop "
                                    f"{n('occluded_points')}")  # fmt: skip

    def _check_fitted_shape(self, n) -> None:
        shapes = self.fitted_shape
        if unknown := [v for v in shapes if v not in FITTED_SHAPES]:
            raise InvalidInputError(f"{n('fitted_shape')} must name {' and/or '.join(FITTED_SHAPES)}, got {', '.join(map(repr, unknown))}")
        if len(set(shapes) & set(WIDTH_SHAPES)) > 1:
            raise InvalidInputError(f"{n('fitted_shape')} takes one of {', '.join(WIDTH_SHAPES)}, not both, got {','.join(shapes)!r}")
        if shapes and not self.fit_sensor:
            raise InvalidInputError(f"{n('fitted_shape')} needs {n('fit_sensor')} (it shapes the fitted+placed set's meshes)")

    def _check_families(self, n) -> None:
        from zbuf_occlude.defaults import MAX_FAMILY_MESHES

        count = self.family_count
        if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_FAMILY_MESHES:
            raise InvalidInputError(f"{n('family_count')} must be an integer from 1 to {MAX_FAMILY_MESHES:,}, got {count!r}")
        if self.family_heights and not self.fit_families:
            raise InvalidInputError(
                f"{n('family_heights')} fits the heights of the classes the families write to: it needs {n('fit_families')}"
            )

    @property
    def available_sets(self) -> tuple[str, ...]:
        """The mesh-only sets this run can train, in report order (``sets`` picks among them)."""
        return (*TRAINING_SETS, *((OCCLUDED_POINTS,) if self.occluded_points else ()), *(FITTED_SETS if self.fit_sensor else ()))

    def _check_sets(self, n) -> None:
        sets = (self.sets,) if isinstance(self.sets, str) else tuple(self.sets)
        available = self.available_sets
        if unknown := [s for s in sets if s not in available]:
            raise InvalidInputError(f"{n('sets')} must name sets of {', '.join(available)} (these settings' sets), "
                                    f"got {', '.join(map(repr, unknown))}")  # fmt: skip
        object.__setattr__(self, "sets", tuple(k for k in available if k in sets))

    @property
    def training_sets(self) -> tuple[str, ...]:
        """The mesh-only sets the run trains, in report order: ``sets``, or every available one."""
        return self.sets or self.available_sets

    def _check_sensor(self, n) -> None:
        from zbuf_occlude.sensors.kinds import kind_of, sensor_from_name

        sensor = sensor_from_name(os.fspath(self.sensor)) if isinstance(self.sensor, (str, os.PathLike)) else self.sensor
        kind = kind_of(sensor)
        if not kind.trains:  # a spinning LiDAR on a car's mount, or an airborne scanner flying over (data.sensor_elevation_deg)
            raise InvalidInputError(f"{n('sensor')} {sensor.name}: the lidar training set needs a LiDAR or an airborne scanner, "
                                    f"not a {kind.title}")  # fmt: skip
        if self.fit_sensor and kind.flies:
            # refused here, before any scan or mesh is read: the fit (sensors.fit.fit_lidar) fits a spinning LiDAR only
            raise InvalidInputError(f"{n('fit_sensor')} fits a spinning LiDAR, but {n('sensor')} {sensor.name} is an airborne scanner: "
                                    f"drop {n('fit_sensor')} or give {n('sensor')} a spinning LiDAR")  # fmt: skip
        from zbuf_occlude.sensors.request import ScanRequest

        object.__setattr__(self, "returns", check_kept_returns(self.returns, n("returns")))  # as asked: settings.json says it
        # the lidar set's request: its sensor with the returns kept, and the cast checked against them
        request = ScanRequest(sensor, footprint_cast=self.footprint_cast, returns=self.returns,
                              names={"footprint_cast": n("footprint_cast"), "returns": n("returns"), "max_returns": n("returns"),
                                     "footprint_rays": None})  # fmt: skip
        object.__setattr__(self, "given_sensor", sensor)
        object.__setattr__(self, "sensor", request.scanner)

    @property
    def footprint_mode(self) -> str:
        """``"adaptive"`` or ``"exact"``: how the ``lidar`` set's crops cast a footprint, ``footprint_cast`` resolved for the sensor."""
        return footprint_mode(self.footprint_cast, self.sensor.beam)

    @functools.cached_property
    def scale_values(self) -> Sim2RealScale:
        """The scale's sizes, with ``per_class`` (and the validation clouds in proportion) where given."""
        sc = SIM2REAL_SCALES[self.scale]
        if self.per_class:
            per_class = int(self.per_class)
            sc = replace(sc, per_class=per_class, val_per_class=max(1, round(per_class * sc.val_per_class / sc.per_class)))
        return sc

    @property
    def n_points(self) -> int:
        """Points per cloud: ``points``, or the scale's."""
        return int(self.points or self.scale_values.points)

    @property
    def validates_on_fit_half(self) -> bool:
        return self.validate_on == "fit-half"

    def train_config(self, seed: int, *, device: str = "cpu", threads: int | None = None) -> TrainConfig:
        """The :class:`~zbuf_occlude.learn.training.TrainConfig` of every run of ``seed`` (``device``, ``threads``: how it runs)."""
        from zbuf_occlude.learn.training import RECIPES, TrainConfig

        sc = self.scale_values
        return TrainConfig(model=self.model, epochs=int(self.epochs or sc.epochs), patience=sc.patience, width=sc.width[self.model],
                           fv_grid=sc.fv_grid, seed=seed, device=device, threads=threads, augment=not self.keep_scale,
                           aspect=bool(self.aspect), partial=bool(self.partial), **{**RECIPES[self.recipe], **({"select": self.best_epoch_by} if self.best_epoch_by else {})})  # fmt: skip

    def identity(self) -> dict[str, Any]:
        """The settings that make results differ, as ``settings.json`` holds them (JSON types).

        ``validate_on`` only when it is ``"fit-half"``, so that runs which validate on meshes
        keep the settings they were written with, and likewise ``occluded_points`` only when it is
        set (the visibility of the :data:`~zbuf_occlude.experiments.sim2real.data.OCCLUDED_POINTS`
        set); ``lidar_placement`` as far as it applies to
        the sensor's kind (an airborne scanner flies at its own altitude: no mount height; the
        distance sets the object's offset across track); what the run finds in its inputs
        (classes, meshes, scans, the fitted sensor) and the sensor's every field are added by
        the run (``sensor_spec``)."""
        from zbuf_occlude.sensors.kinds import kind_of

        placement = {"distance_m": LIDAR_PLACEMENT["distance_m"]} if kind_of(self.sensor).flies else LIDAR_PLACEMENT
        return {
            "mesh_root": str(self.mesh_root), "real": str(self.real), "model": self.model, "sensor": self.sensor.name,
            "scale": self.scale, "scale_values": asdict(self.scale_values), "points": self.n_points, "seeds": int(self.seeds),
            "keep_scale": bool(self.keep_scale), "label_map": dict(self.label_map), "up": self.up, "up_map": dict(self.up_map),
            "sizes_m": {k: asdict(v) for k, v in self.sizes.items()}, "occluded_elevation_deg": list(self.occluded_elevation_deg),
            "lidar_placement": placement, "lidar_min_returns": int(self.min_returns), "keep_scale_unit_m": KEEP_SCALE_UNIT_M,
            "method": self.method, "train_config": self.train_config(0).identity(("seed", "device", "threads")),
            **({"validate_on": self.validate_on} if self.validates_on_fit_half else {}),
            **({"lidar_returns": _returns_spec(self.sensor, self.returns)} if self.returns != 1 else {}),
            **({"lidar_footprint": "adaptive"} if self.footprint_mode == "adaptive" else {}),
            **({"occluded_points": {"set": OCCLUDED_POINTS, "method": POINT_VISIBILITY, "normals": "estimated", "topped_up": False}}
               if self.occluded_points else {}),
            **({"sets": list(self.sets)} if self.sets else {}),
            **({"fit_families": {"objects_per_class": int(self.family_count), "seed": FAMILIES_SEED,
                                 **({"heights": "the first half's object heights"} if self.family_heights else {})}}
               if self.fit_families else {}),
        }  # fmt: skip


def _returns_spec(sensor, returns: int | str) -> dict[str, Any]:
    """What ``settings.json`` records of the returns the lidar set keeps (the sensor's every field is there too,
    ``sensor_spec``): the beam's returns, and ``kept`` where ``returns`` is a name (first, last, all)."""
    beam = sensor.beam
    return {"max_returns": int(beam.max_returns), "footprint_rays": int(beam.footprint_rays), "divergence_deg": float(beam.divergence_deg),
            "range_resolution_m": float(beam.range_resolution_m), "profile": beam.profile,
            **({"kept": returns, "return_mode": beam.return_mode} if isinstance(returns, str) else {})}  # fmt: skip


def _elevation_range(value, name: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name} must be LO:HI degrees, got {value!r}") from None
    if not (-90.0 <= lo <= hi <= 90.0):
        raise InvalidInputError(f"{name} must be LO:HI with -90 <= LO <= HI <= 90 degrees, got {lo:g}:{hi:g}")
    return lo, hi
