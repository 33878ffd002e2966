"""Where a folder of meshes' LiDAR crops are placed, class by class, and the shape each mesh is given: typed, checked
once (``experiment sim2real``'s ``lidar`` sets and ``fit-sensor --meshes``).

A LiDAR training set draws the crops of a mesh from one
:class:`~zbuf_occlude.sensors.placement.CropDistributions` made of three layers, each over the one
before (:meth:`CropPlacement.crop_distributions`):

1. :data:`LIDAR_PLACEMENT`, the published mount and distances that every class starts from;
2. the mesh's class's :class:`ClassPlacement` (:attr:`CropPlacement.per_class`, keyed by class
   name): the crops' distances, the sensor's height and the objects' hidden bottoms (fitted to
   the class's real scans with ``--fit-sensor``), and the targets its meshes' shapes are fitted
   to: the widths across the line of sight, the outline over the height, and how the widths
   are met (:data:`WIDTH_BY`);
3. the mesh's own :class:`MeshShape` (:attr:`CropPlacement.per_mesh`, keyed by
   :attr:`~zbuf_occlude.mesh.inputs.class_folders.MeshEntry.name`): the stretch, visible share
   and warp fitted to those targets once for every set and seed (:func:`fit_mesh_shapes`).  A
   mesh without one, in a class that gives targets, is fitted in each set's draw
   (:meth:`ClassPlacement.fit_mesh`), to the same shape.

Class names and mesh names are kept in two tables, and every value is checked when its layer
is made; :meth:`CropPlacement.from_keywords` builds a placement from plain dicts, naming the
class or mesh and the key of a value it refuses.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.mesh.inputs.class_folders import MeshEntry
from zbuf_occlude.mesh.sizes import SizeRange, size_interval

if TYPE_CHECKING:  # the sensors are imported where they are used
    from zbuf_occlude.sensors.placement import CropDistributions

__all__ = ["LIDAR_PLACEMENT", "MIN_RETURNS", "WIDTH_BY", "crops_to_draw", "ClassPlacement", "MeshShape", "CropPlacement", "fit_mesh_shapes"]

log = logging.getLogger(__name__)

#: Sensor placement of the ``lidar`` set (uniform draws): the distance range where a 32-beam
#: sensor at 1.33° ring spacing puts at least three rings on a 1.5 m object (1.5 m / (3 · tan 1.33°)
#: ≈ 21 m) up to 25 m, from 5 m (closer, the object leaves the vertical field of view); the
#: height of a roof mount on a passenger car or small UGV (1.6–2.0 m; KITTI's HDL-64E: 1.73 m).
LIDAR_PLACEMENT = {"distance_m": (5.0, 25.0), "height_m": (1.6, 2.0)}
#: A crop with fewer returns is redrawn: a segmentation pipeline drops clusters this small, and
#: a handful of points padded to ``n_points`` describes no shape (fixed before any real scan was scored).
MIN_RETURNS = 30
#: How a class's ``across_sight_width_by`` meets its ``across_sight_width_m``: a horizontal
#: stretch of each mesh, the same stretch where it widens the mesh and none where it would
#: narrow it, or a side occluder that leaves part of it in view
#: (:func:`zbuf_occlude.sensors.fit.fit_object_shape`).
WIDTH_BY = ("stretch", "widen", "occluder")
#: The fields of a :class:`ClassPlacement` that are crop keywords (the rest are shape targets).
_CROP_FIELDS = ("distance_m", "height_m", "hidden_below_m")


@dataclass(frozen=True)
class ClassPlacement:
    """One class's crop placement, and the targets its meshes' shapes are fitted to (module docstring).

    A number given for an interval is the interval ``(v, v)`` (no draw).

    Attributes
    ----------
    distance_m : (lo, hi) float, optional
        Horizontal distance from the sensor to the object, metres; None: :data:`LIDAR_PLACEMENT`'s.
    height_m : (lo, hi) float, optional
        The sensor's height above the ground, metres; None: :data:`LIDAR_PLACEMENT`'s.
    hidden_below_m : (lo, hi) float, optional
        Returns lower than this above the ground are hidden, metres; None: nothing hidden.
    across_sight_width_m : (lo, hi) float, optional
        The class's widths across the line of sight, metres, that each mesh is fitted to
        (:func:`zbuf_occlude.sensors.fit.fit_width_scale`); None: the meshes' own widths.
    across_sight_profile : (K,) float, optional
        The class's outline over the height, ``K >= 2`` relative widths > 0, that each mesh is
        warped to (:func:`zbuf_occlude.sensors.fit.fit_width_profile`); None: the meshes' own.
    across_sight_width_by : {"stretch", "widen", "occluder"}
        How the widths are met (:data:`WIDTH_BY`).

    Raises
    ------
    InvalidInputError
        A value of the wrong form or out of its range (distances > 0, heights and hidden
        bottoms >= 0, widths ``0 <= lo <= hi``, ``hi > 0``), or an unknown
        ``across_sight_width_by``, naming the field.
    """

    distance_m: tuple[float, float] | None = None
    height_m: tuple[float, float] | None = None
    hidden_below_m: tuple[float, float] | None = None
    across_sight_width_m: tuple[float, float] | None = None
    across_sight_profile: tuple[float, ...] | None = None
    across_sight_width_by: str = "stretch"

    def __post_init__(self) -> None:
        from zbuf_occlude.sensors.placement import CropDistributions, check_across_sight_width
        from zbuf_occlude.sensors.scene.object_shapes import check_width_profile

        if self.across_sight_width_by not in WIDTH_BY:
            raise InvalidInputError(f"across_sight_width_by must be one of {WIDTH_BY}, got {self.across_sight_width_by!r}")
        checked = CropDistributions(**{**LIDAR_PLACEMENT, **self.crop_keywords})  # the draws' own check, once
        for name in self.crop_keywords:
            object.__setattr__(self, name, getattr(checked, name))
        if self.across_sight_width_m is not None:
            object.__setattr__(self, "across_sight_width_m", check_across_sight_width(self.across_sight_width_m))
        if self.across_sight_profile is not None:
            try:
                profile = check_width_profile(self.across_sight_profile)
            except InvalidInputError as exc:
                raise InvalidInputError(f"across_sight_profile: {exc}") from None
            object.__setattr__(self, "across_sight_profile", profile)

    @property
    def crop_keywords(self) -> dict[str, tuple[float, float]]:
        """The :class:`~zbuf_occlude.sensors.placement.CropDistributions` keywords given (over :data:`LIDAR_PLACEMENT`)."""
        return {name: getattr(self, name) for name in _CROP_FIELDS if getattr(self, name) is not None}

    @property
    def shapes_meshes(self) -> bool:
        """Whether the class gives a target that its meshes' shapes are fitted to (widths or outline)."""
        return self.across_sight_width_m is not None or self.across_sight_profile is not None

    def lacks_shape(self, distributions: CropDistributions) -> bool:
        """Whether ``distributions`` lacks a shape that this class's targets ask for (then :meth:`fit_mesh` fits it)."""
        width_given = distributions.visible_across_sight if self.across_sight_width_by == "occluder" else distributions.width_scale
        return (self.across_sight_width_m is not None and width_given is None) or (
            self.across_sight_profile is not None and distributions.width_profile is None)  # fmt: skip

    def fit_mesh(self, entry: MeshEntry, sensor, distributions: CropDistributions) -> MeshShape:
        """``entry``'s shape fitted to this class's targets, its crops drawn from ``distributions``
        (:func:`~zbuf_occlude.sensors.fit.fit_object_shape`, seed 0; with ``"widen"``, each
        stretch below 1 raised to 1: never narrower than the mesh).

        Raises
        ------
        InvalidInputError
            A mesh whose shape cannot be fitted (no crop shows a width), naming its file.
        """
        from zbuf_occlude.sensors.fit import fit_object_shape

        out = fit_object_shape(entry.mesh, sensor, distributions, self.across_sight_width_m, self.across_sight_profile,
                               occlude=self.across_sight_width_by == "occluder", name=str(entry.path))  # fmt: skip
        if self.across_sight_width_by == "widen" and "width_scale" in out:
            out["width_scale"] = tuple(max(v, 1.0) for v in out["width_scale"])
        return MeshShape(**out)


@dataclass(frozen=True)
class MeshShape:
    """One mesh's shape, fitted to its class's targets (:func:`fit_mesh_shapes`): crop keywords over its class's placement.

    Attributes
    ----------
    width_scale : (lo, hi) float, optional
        Horizontal stretch (:class:`~zbuf_occlude.sensors.placement.CropDistributions`
        ``width_scale``) to the class's ``across_sight_width_m``.
    visible_across_sight : (lo, hi) float, optional
        Instead of a stretch (``across_sight_width_by="occluder"``): the share of the mesh's
        width a side occluder leaves in view.
    width_profile : (K,) float, optional
        Stretch per relative-height bin, to the class's ``across_sight_profile``.

    Raises
    ------
    InvalidInputError
        A value of the wrong form or out of its range, naming the field.
    """

    width_scale: tuple[float, float] | None = None
    visible_across_sight: tuple[float, float] | None = None
    width_profile: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        from zbuf_occlude.sensors.placement import CropDistributions

        checked = CropDistributions(**self.keywords)  # the draws' own check, once
        for name in self.keywords:
            object.__setattr__(self, name, getattr(checked, name))

    @property
    def keywords(self) -> dict[str, tuple[float, ...]]:
        """The :class:`~zbuf_occlude.sensors.placement.CropDistributions` keywords given."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}


@dataclass(frozen=True)
class CropPlacement:
    """The placement of a LiDAR set's crops: per class, and per mesh over its class (module docstring).

    Attributes
    ----------
    per_class : mapping of str to ClassPlacement
        Keyed by class name; a class not in it gets ``ClassPlacement()`` (:data:`LIDAR_PLACEMENT`, the meshes' own shapes).
    per_mesh : mapping of str to MeshShape
        Keyed by mesh name (:attr:`~zbuf_occlude.mesh.inputs.class_folders.MeshEntry.name`): the shapes
        fitted once (:func:`fit_mesh_shapes`, :meth:`with_mesh_shapes`).

    Raises
    ------
    ArgumentTypeError
        A value of ``per_class`` that is no :class:`ClassPlacement`, or of ``per_mesh`` no
        :class:`MeshShape` (a dict: :meth:`from_keywords` takes those), naming its key.
    """

    per_class: Mapping[str, ClassPlacement] = field(default_factory=dict)
    per_mesh: Mapping[str, MeshShape] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for table, kind in (("per_class", ClassPlacement), ("per_mesh", MeshShape)):
            own = dict(getattr(self, table))  # a copy of its own: the caller's dict may change
            bad = sorted(str(k) for k, v in own.items() if not isinstance(v, kind))
            if bad:
                raise ArgumentTypeError(f"{table} {bad}: each must be a {kind.__name__}; CropPlacement.from_keywords takes dicts")
            object.__setattr__(self, table, own)

    @classmethod
    def from_keywords(cls, per_class: Mapping[str, Mapping[str, Any]],
                      per_mesh: Mapping[str, Mapping[str, Any]] | None = None) -> CropPlacement:  # fmt: skip
        """A placement from plain dicts: ``{class: {ClassPlacement field: value}}`` and ``{mesh name: {MeshShape field: value}}``.

        For example ``{"car": {"distance_m": (6.0, 8.0), "across_sight_width_m": (1.6, 2.0)}}``.

        Raises
        ------
        InvalidInputError
            An unknown key or a bad value, naming the class or mesh and the key.
        """
        classes = {name: _made(ClassPlacement, keywords, f"class {name!r}") for name, keywords in per_class.items()}
        meshes = {name: _made(MeshShape, keywords, f"mesh {name!r}") for name, keywords in (per_mesh or {}).items()}
        return cls(classes, meshes)

    def with_mesh_shapes(self, shapes: Mapping[str, MeshShape]) -> CropPlacement:
        """This placement with ``shapes`` (mesh name → shape) over the mesh shapes it has."""
        return replace(self, per_mesh={**self.per_mesh, **shapes})

    def of_class(self, class_name: str) -> ClassPlacement:
        """The class's placement (``ClassPlacement()`` for a class not given)."""
        return self.per_class.get(class_name) or ClassPlacement()

    def crop_distributions(self, entry: MeshEntry, size: SizeRange) -> tuple[CropDistributions, ClassPlacement]:
        """The distributions ``entry``'s crops are drawn from, and its class's placement (whose targets
        :meth:`ClassPlacement.fit_mesh` fits where the mesh has no shape of its own).

        :data:`LIDAR_PLACEMENT`, its class's crop keywords over it, its own :class:`MeshShape`
        over those, and a size drawn in ``size`` (:func:`zbuf_occlude.mesh.sizes.size_interval`).
        """
        from zbuf_occlude.sensors.placement import CropDistributions

        target = self.of_class(entry.class_name)
        own = self.per_mesh.get(entry.name) or MeshShape()
        keywords = {**LIDAR_PLACEMENT, **target.crop_keywords, **own.keywords}
        return CropDistributions(size_m=size_interval(entry.mesh.extents, size), **keywords), target


def crops_to_draw(want: int) -> int:
    """Crops drawn in a first round to keep ``want`` with enough returns: a fifth more, at least one (some miss the object)."""
    return want + max(1, want // 5)


def _made(kind: type, keywords: Mapping[str, Any], what: str):
    """``kind(**keywords)``, its errors naming ``what`` (a class or a mesh)."""
    known = [f.name for f in fields(kind)]
    unknown = sorted(set(keywords) - set(known))
    if unknown:
        raise InvalidInputError(f"placement of {what}: unknown keys {unknown}; a {kind.__name__} takes {known}")
    try:
        return kind(**keywords)
    except InvalidInputError as exc:
        raise InvalidInputError(f"placement of {what}: {exc}") from None


def fit_mesh_shapes(meshes: list[MeshEntry], sensor, sizes: Mapping[str, SizeRange], placement: CropPlacement) -> dict[str, MeshShape]:
    """Each mesh's shape fitted to its class's targets in ``placement``, once for every training set and seed.

    For the meshes of classes that give ``across_sight_width_m`` or ``across_sight_profile``:
    ``{mesh name: MeshShape}`` (:meth:`ClassPlacement.fit_mesh`, seed 0), to put into the
    placement (:meth:`CropPlacement.with_mesh_shapes`): a mesh's own shape is taken over its
    class's targets, so the crops are what fitting the shape in every draw would give, without
    fitting it again.  A mesh whose shape cannot be fitted is left out (logged; its crops then
    raise, naming it, and :func:`~zbuf_occlude.experiments.sim2real.data.check_lidar_meshes` skips it).

    Raises
    ------
    KeyError
        A mesh's class missing from ``sizes``.
    """
    out = {}
    for entry in meshes:
        dist, target = placement.crop_distributions(entry, sizes[entry.class_name])
        if target.shapes_meshes:
            try:
                out[entry.name] = target.fit_mesh(entry, sensor, dist)
            except InvalidInputError as exc:
                log.warning("%s", exc)
    return out
