"""Where a crop's object stands and how it is seen: the distributions (:class:`CropDistributions`),
one draw from them (:class:`Placement`), and how ``scan`` stands one mesh (:class:`ObjectPlacement`).

Pure numpy, so that a farm's parameters can carry crop settings without loading meshes;
:mod:`zbuf_occlude.sensors.crops` scans an object placed so.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import InitVar, dataclass, field, fields
from typing import Any

import numpy as np

from zbuf_occlude.defaults import MAX_POINTS
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.sizes import DIMENSIONS
from zbuf_occlude.sensors.checks import count, namer
from zbuf_occlude.sensors.scene.object_shapes import check_width_profile

__all__ = [
    "check_outside",
    "CropDistributions",
    "ObjectPlacement",
    "Placement",
    "DEFAULT_GROUND_REFLECTIVITY",
    "MAX_REDRAWS",
    "check_across_sight_width",
    "check_ground_margin",
    "draw_placement",
]

#: ρ of the ground plane when a crop models reflectivity: asphalt and concrete in the near infrared, an assumption.
DEFAULT_GROUND_REFLECTIVITY = 0.15
#: Placements drawn again, at most, for a crop holding fewer returns than ``CropDistributions.min_returns``: after
#: them a sample is left out (and named).  A bound on the scans one sample may cost, not a measured figure.
MAX_REDRAWS = 8


def _interval(name: str, value, lowest: float | None = None, *, above: bool = False, unit: str = "") -> tuple[float, float]:
    """``value`` (a number or ``(lo, hi)``) as ``(lo, hi)``, finite, ``lo <= hi`` and ``lo >= lowest`` (``> lowest`` with ``above``).

    Raises
    ------
    InvalidInputError
        Naming ``name`` (a field, or the option that gave it) and the value.
    """
    try:
        lo, hi = (float(value), float(value)) if np.isscalar(value) else (float(value[0]), float(value[1]))
    except (TypeError, ValueError, IndexError):
        lo, hi = math.nan, math.nan
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise InvalidInputError(f"{name} must be a number or an interval lo <= hi, got {value!r}")
    if lowest is not None and (lo <= lowest if above else lo < lowest):
        raise InvalidInputError(f"{name} must be {'>' if above else '>='} {lowest:g}{unit}, got {value!r}")
    return lo, hi


def _draw(interval: tuple[float, float], rng: np.random.Generator) -> float:
    """A uniform draw from ``(lo, hi)``; ``lo`` itself, and no draw, when ``lo == hi``."""
    lo, hi = interval
    return lo if lo == hi else float(rng.uniform(lo, hi))


def check_ground_margin(value, option: str = "ground_margin_m") -> float:
    """``value`` as a ground margin in metres (:class:`CropDistributions`).

    Raises
    ------
    InvalidInputError
        Not a finite number >= 0, naming ``option`` and the value.
    """
    try:
        margin = float(value)
    except (TypeError, ValueError):
        margin = math.nan
    if not (math.isfinite(margin) and margin >= 0):
        raise InvalidInputError(f"{option} must be a number >= 0 metres, got {value!r}")
    return margin


def check_across_sight_width(value, option: str = "across_sight_width_m") -> tuple[float, float]:
    """``value`` (a number or ``(lo, hi)``) as the interval of widths across the line of sight that
    :func:`~zbuf_occlude.sensors.fit.fit_width_scale` fits a mesh to, metres.

    Raises
    ------
    InvalidInputError
        Not ``0 <= lo <= hi`` with ``hi > 0`` (a width of nothing cannot be fitted), naming
        ``option`` and the value.
    """
    lo, hi = _interval(option, value, 0.0, unit=" metres")
    if not hi > 0:
        raise InvalidInputError(f"{option} must have HI > 0 metres (a width of nothing cannot be fitted), got {value!r}")
    return lo, hi


@dataclass(frozen=True)
class Placement:
    """One crop's placement, drawn from :class:`CropDistributions` (:func:`draw_placement`).

    Attributes
    ----------
    distance_m, height_m : float
        Horizontal distance from the sensor to the object's footprint centre, and the sensor's
        height above the ground, metres.
    azimuth_deg, yaw_deg : float
        The object's direction seen from the sensor and its heading about +z, degrees.
    size_m : float
        The object's largest dimension, metres (the largest of ``extents_m`` where given).
    extents_m : (x, y, z) float, optional
        The object stretched to these extents, metres, instead of scaled to ``size_m``.
    reflectivity, ground_reflectivity : float, optional
        Lambertian ρ of the object and of the ground: the scan applies the sensor's radiometric
        threshold (``ground_reflectivity`` None: :data:`DEFAULT_GROUND_REFLECTIVITY`).
    hidden_below_m : float, optional
        The object's returns lower than this above the ground are dropped, metres.
    width_scale : float, optional
        Horizontal stretch of the object (None: 1).
    ground_margin_m : float, optional
        Ground returns under the object's footprint grown by this margin are kept, metres.
    width_profile : tuple of float, optional
        Horizontal stretch per relative-height bin (:class:`~zbuf_occlude.sensors.scene.objects.SceneObject`).
    visible_across_sight : float, optional
        Share of the object's angular width left visible by side occluders, at most 1 (None: 1);
        ``occluder_side`` (+1 or −1) says which side they hide.
    """

    distance_m: float
    height_m: float
    azimuth_deg: float
    yaw_deg: float
    size_m: float
    extents_m: tuple[float, float, float] | None = None
    reflectivity: float | None = None
    ground_reflectivity: float | None = None
    hidden_below_m: float | None = None
    width_scale: float | None = None
    ground_margin_m: float | None = None
    width_profile: tuple[float, ...] | None = None
    visible_across_sight: float | None = None
    occluder_side: float | None = None

    @property
    def stretch(self) -> float:
        """``width_scale``, 1 when not given."""
        return 1.0 if self.width_scale is None else self.width_scale

    @property
    def visible_share(self) -> float:
        """``visible_across_sight``, 1 (nothing hidden) when not given."""
        return 1.0 if self.visible_across_sight is None else self.visible_across_sight

    def to_dict(self) -> dict[str, Any]:
        """The fields given (not None), in field order: what a crop's metadata records."""
        return {f.name: v for f in fields(self) if (v := getattr(self, f.name)) is not None}


@dataclass(frozen=True)
class CropDistributions:
    """Per-sample sensor placement, every quantity drawn independently and uniformly.

    Parameters
    ----------
    distance_m : (lo, hi)
        Horizontal distance from the sensor to the object's footprint centre, metres.
        Default 5–25 m, the range where an HDL-32E returns more than a few dozen points
        from a car.
    height_m : (lo, hi)
        Sensor height above the ground, metres (car roofs: 1.6–2.0 m).
    azimuth_deg : (lo, hi)
        Direction of the object seen from the sensor, degrees (sensor frame).
    yaw_deg : (lo, hi)
        The object's heading about +z, degrees.
    size_m : (lo, hi) or float
        The object's largest dimension, metres.
    extents_m : (3,) float or 3 × (lo, hi), optional
        Instead of ``size_m``: stretch the mesh to these extents (x, y, z), metres, each a
        value or an interval drawn per sample; with ``round_xy`` the y extent is the drawn x
        (a round cross-section: poles, trunks).
    round_xy : bool
    reflectivity : (lo, hi), optional
        The object's Lambertian reflectivity ρ, drawn per sample; given, the scan applies the
        sensor's radiometric detection threshold (:func:`zbuf_occlude.sensors.scan`).
    ground_reflectivity : float
        ρ of the ground plane when ``reflectivity`` is given (default 0.15: asphalt and
        concrete in the near infrared, an assumption).
    ground_margin_m : float, optional
        Keep the ground returns under the object, the way a box segmentation of a street scan
        leaves them: those inside the object's footprint (its bounding box in the ground plane,
        yawed with it) grown by this margin on every side, metres.  None (default): the crop
        holds the object's returns only.  :func:`~zbuf_occlude.sensors.fit.fit_lidar` reports
        the share of ground returns in real crops (``ground_fraction``) to compare with.
    hidden_below_m : (lo, hi), optional
        Hide the object's returns lower than this height above the ground, metres, drawn per
        sample: the bottom of an object that a real street scan loses to what stands between
        it and the sensor (parked cars, kerbs, low hedges) or to a segmentation's ground
        removal.  A horizontal cut, not a ray-cast occluder.  None (default): nothing hidden.
        :func:`~zbuf_occlude.sensors.fit.fit_crop_bottoms` fits it per class to real scans.
    width_scale : (lo, hi) or float, optional
        Stretch the object's horizontal axes by this factor (> 0), drawn per sample, after the
        scaling to ``size_m`` (which then measures the object before the stretch): posts made as
        thick as the trunks a real scan shows, keeping their height.  None (default): the
        mesh's own proportions.  :func:`~zbuf_occlude.sensors.fit.fit_width_scale` fits it to
        the widths of real scans.
    width_profile : sequence of float, optional
        A fixed horizontal stretch per relative-height bin (:class:`~zbuf_occlude.sensors.scene.objects.SceneObject`
        ``width_profile``), on top of ``width_scale``: the outline over the height that real scans
        show.  None (default): none.  :func:`~zbuf_occlude.sensors.fit.fit_width_profile` fits it.
    visible_across_sight : (lo, hi), optional
        Hide one side of the object behind an occluder that stands between it and the sensor
        (:func:`~zbuf_occlude.sensors.scene.occluders.side_occluders`): the share of the object's angular width, as the sensor sees it,
        left visible, drawn per sample and capped at 1 (1 or more: nothing hidden); the hidden
        side, left or right, is drawn too.  A real street crop often shows part of an object, the
        rest behind a parked car, a wall or a tree, or cut off by the segmentation: a partial
        view, not a thinner object (compare ``width_scale``).  None (default): nothing hidden.
        :func:`~zbuf_occlude.sensors.fit.fit_visible_across_sight` fits it to the widths of real scans.
    min_returns : int, optional
        The fewest returns of the object a crop holds, 1 to :data:`~zbuf_occlude.defaults.MAX_POINTS`: a
        placement whose crop holds fewer is drawn again, up to :data:`MAX_REDRAWS` times
        (:func:`~zbuf_occlude.sensors.crops.object_crops`), so the placements are those drawn here given that the
        sensor sees enough of the object, as a data set of real crops keeps only objects with enough points.
        None (default): every draw, as it comes.
    option_names : mapping of str to str, optional
        What the messages call each field (the command line passes its flags, e.g.
        ``{"hidden_below_m": "--hidden-below"}``); a field not named is called by its name.  Not stored.

    Raises
    ------
    InvalidInputError
        A value that is no number or interval ``lo <= hi``, or out of its range (distances,
        sizes, extents and width scales > 0; heights, hidden bottoms, reflectivities and the
        ground margin >= 0), naming the field or its option.
    """

    distance_m: tuple[float, float] = (5.0, 25.0)
    height_m: tuple[float, float] = (1.6, 2.0)
    azimuth_deg: tuple[float, float] = (0.0, 360.0)
    yaw_deg: tuple[float, float] = (0.0, 360.0)
    size_m: tuple[float, float] | float = 4.5
    extents_m: tuple | None = None
    round_xy: bool = False
    reflectivity: tuple[float, float] | None = None
    ground_reflectivity: float = DEFAULT_GROUND_REFLECTIVITY
    ground_margin_m: float | None = None
    hidden_below_m: tuple[float, float] | None = None
    width_scale: tuple[float, float] | None = None
    width_profile: tuple[float, ...] | None = None
    visible_across_sight: tuple[float, float] | None = None
    min_returns: int | None = None

    option_names: InitVar[Mapping[str, str] | None] = None

    def __post_init__(self, option_names: Mapping[str, str] | None) -> None:
        # the one check of every crop setting; messages name the field, or its option in option_names
        n = namer(option_names)
        for name, lowest, above in (("distance_m", 0.0, True), ("height_m", 0.0, False), ("size_m", 0.0, True),
                                    ("azimuth_deg", None, False), ("yaw_deg", None, False)):  # fmt: skip
            unit = " metres" if name.endswith("_m") else ""
            object.__setattr__(self, name, _interval(n(name), getattr(self, name), lowest, above=above, unit=unit))
        if self.extents_m is not None:
            if np.isscalar(self.extents_m) or len(self.extents_m) != 3:
                raise InvalidInputError(f"{n('extents_m')} must be three values or intervals (x, y, z), got {self.extents_m!r}")
            object.__setattr__(
                self, "extents_m", tuple(_interval(n("extents_m"), v, 0.0, above=True, unit=" metres") for v in self.extents_m)
            )
        for name, unit in (("reflectivity", ""), ("hidden_below_m", " metres above the ground")):  # optional intervals of values >= 0
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _interval(n(name), getattr(self, name), 0.0, unit=unit))
        if self.width_scale is not None:
            object.__setattr__(self, "width_scale", _interval(n("width_scale"), self.width_scale, 0.0, above=True))
        if self.width_profile is not None:
            object.__setattr__(self, "width_profile", check_width_profile(self.width_profile))
        if self.ground_margin_m is not None:
            object.__setattr__(self, "ground_margin_m", check_ground_margin(self.ground_margin_m, n("ground_margin_m")))
        if self.visible_across_sight is not None:
            visible = _interval(n("visible_across_sight"), self.visible_across_sight, lowest=0.0)
            if visible[1] <= 0:
                raise InvalidInputError(f"{n('visible_across_sight')} must leave a share > 0 visible, got {self.visible_across_sight!r}")
            object.__setattr__(self, "visible_across_sight", visible)
        if self.min_returns is not None:
            object.__setattr__(self, "min_returns", count(self.min_returns, n("min_returns"), low=1, high=MAX_POINTS))


def draw_placement(dist: CropDistributions, rng: np.random.Generator) -> Placement:
    """One placement ``{distance_m, height_m, azimuth_deg, yaw_deg, size_m}`` (five uniform draws, in that order),
    then ``extents_m``, ``reflectivity``, ``hidden_below_m`` and ``width_scale`` where ``dist`` gives them (drawn only when an interval),
    ``ground_margin_m`` and ``width_profile`` as given (no draw), and ``visible_across_sight`` (capped at 1)
    with ``occluder_side`` (+1: the occluder hides the object's counter-clockwise side, −1 the other; one draw) where given."""
    out: dict = {name: float(rng.uniform(*getattr(dist, name))) for name in ("distance_m", "height_m", "azimuth_deg", "yaw_deg", "size_m")}
    # further draws only where an interval asks for them, so fixed values keep earlier streams
    if dist.extents_m is not None:
        ext = [_draw(interval, rng) for interval in dist.extents_m]
        if dist.round_xy:
            ext[1] = ext[0]
        out["extents_m"] = tuple(ext)
        out["size_m"] = max(out["extents_m"])
    if dist.reflectivity is not None:
        out["reflectivity"] = _draw(dist.reflectivity, rng)
        out["ground_reflectivity"] = float(dist.ground_reflectivity)
    if dist.hidden_below_m is not None:
        out["hidden_below_m"] = _draw(dist.hidden_below_m, rng)
    if dist.width_scale is not None:
        out["width_scale"] = _draw(dist.width_scale, rng)
    if dist.ground_margin_m is not None:  # no draw: a fixed value
        out["ground_margin_m"] = dist.ground_margin_m
    if dist.width_profile is not None:  # no draw
        out["width_profile"] = dist.width_profile
    if dist.visible_across_sight is not None:
        out["visible_across_sight"] = min(1.0, _draw(dist.visible_across_sight, rng))
        out["occluder_side"] = 1.0 if rng.uniform() < 0.5 else -1.0
    return Placement(**out)


def check_outside(dist: CropDistributions, extents=None, *, name: str = "distance_m") -> None:
    """Refuse a distance (``dist.distance_m``'s low end) that may put the sensor inside the object.

    The object's footprint centre lies ``distance_m`` from the sensor and its largest
    horizontal dimension is up to ``size_m`` (or the X/Y ``extents_m``) high end, or, given the
    mesh's ``extents (3,)``, its larger horizontal side scaled so, times the ``width_scale``
    high end where it stretches the object and the largest ``width_profile`` factor above 1
    where it warps it; a distance below half of that may stand the sensor
    inside it (every ray starts inside).

    Raises
    ------
    InvalidInputError
        Naming the distance as ``name`` (a command's option for it) and the smallest distance allowed.
    """
    if dist.extents_m is not None:
        sizes = [dist.extents_m[0][1], dist.extents_m[1][1]]
    else:
        e = None if extents is None else np.asarray(extents, dtype=np.float64)
        sizes = [dist.size_m[1] * (1.0 if e is None or not e.max() > 0 else float(e[:2].max() / e.max()))]
    if dist.width_scale is not None:
        sizes = [v * dist.width_scale[1] for v in sizes]
    if dist.width_profile is not None:
        sizes = [v * max(1.0, *dist.width_profile) for v in sizes]
    half = max(sizes) / 2
    if dist.distance_m[0] < half:
        raise InvalidInputError(
            f"{name} {dist.distance_m[0]:g} m may put the sensor inside the object (up to {max(sizes):g} m across): "
            f"use a distance of at least {half:g} m"
        )


@dataclass(frozen=True)
class ObjectPlacement:
    """How a scan of one mesh stands it on the ground before the sensor
    (:func:`~zbuf_occlude.sensors.scan_files.run_scan`): the crops' distributions, the mesh's up axis, what its
    size measures, and the width and outline its crops are fitted to.

    Parameters
    ----------
    distributions : CropDistributions
        Checked already; ``size_m`` measures the side ``size_of`` names.
    up : str
        The mesh's up axis, turned to +z as it is read (:func:`~zbuf_occlude.mesh.load.load_mesh`'s ``up``; "auto": by
        its path and format).
    size_of : {"max", "length", "height"}
        What ``size_m`` measures: the largest side, or the mesh's length or height
        (:func:`~zbuf_occlude.mesh.sizes.size_interval` converts it to the largest side).
    across_sight_width_m : (lo, hi) or None
        Fit the mesh's crops to this width across the line of sight, metres
        (:func:`~zbuf_occlude.sensors.fit.fit_object_shape`, checked by :func:`check_across_sight_width`).
    width_profile : sequence of float or None
        Fit the crops' outline to these widths over the height, bottom to top (2 or more > 0).
    occlude : bool
        Meet the width with a side occluder instead of a thinner object (needs ``across_sight_width_m``).
    names : mapping of str to str
        A caller's name of each field, and of ``distributions``' fields, for messages
        (:func:`~zbuf_occlude.sensors.checks.namer`).

    Raises
    ------
    InvalidInputError
        Naming the fields as ``names`` maps them: a ``size_of`` that is none of those, or other than "max"
        with ``extents_m`` (which gives every side); a bad width or outline; ``occlude`` without a width.
    """

    distributions: CropDistributions = CropDistributions()
    up: str = "auto"
    size_of: str = "max"
    across_sight_width_m: tuple[float, float] | None = None
    width_profile: tuple[float, ...] | None = None
    occlude: bool = False
    names: Mapping[str, str] = field(default_factory=dict)

    def name_of(self, name: str) -> str:
        """How the caller calls the field ``name`` in a message: its option in :attr:`names` (``--max-returns``), else
        ``name`` (:func:`~zbuf_occlude.sensors.checks.namer`)."""
        return namer(self.names)(name)

    def __post_init__(self) -> None:
        n = self.name_of
        if self.size_of not in DIMENSIONS:
            raise InvalidInputError(f"{n('size_of')} must be one of {', '.join(DIMENSIONS)}, got {self.size_of!r:.40}")
        if self.size_of != "max" and self.distributions.extents_m is not None:
            raise InvalidInputError(
                f"{n('size_of')} {self.size_of} says what {n('size_m')} measures; {n('extents_m')} gives every side instead"
            )
        if self.across_sight_width_m is not None:
            object.__setattr__(self, "across_sight_width_m", check_across_sight_width(self.across_sight_width_m, n("across_sight_width_m")))
        if self.width_profile is not None:
            try:
                object.__setattr__(self, "width_profile", check_width_profile(self.width_profile))
            except InvalidInputError:
                shown = ",".join(str(v) for v in self.width_profile) if isinstance(self.width_profile, (tuple, list)) else "another value"
                raise InvalidInputError(
                    f"{n('width_profile')} must be 2 or more numbers > 0, V,V,..., bottom to top, got {shown!r:.80}"
                ) from None
        if self.occlude and self.across_sight_width_m is None:
            width = n("across_sight_width_m")
            raise InvalidInputError(f"{n('occlude')} meets {width} with a side occluder: it needs {width}")
