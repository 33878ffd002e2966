"""``farm --sensor``'s parameters: the sensor, its crops' placement and its beam's changes (:class:`SensorCropParams`),
held flat in a farm's plan and card beside :class:`~zbuf_occlude.farm.config.FarmParams`'s (:data:`SENSOR_KEYS`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import InitVar, dataclass
from typing import Any

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.farm.options import OPTION_NAMES
from zbuf_occlude.sensors.beam.footprint import MAX_DIVERGENCE_DEG
from zbuf_occlude.sensors.placement import CropDistributions, check_across_sight_width
from zbuf_occlude.sensors.request import TRAINING_RETURNS

__all__ = ["SensorCropParams", "SENSOR_KEYS", "FARM_CROP_FIELDS", "CROP_OPTION_NAMES", "FARM_REQUEST_NAMES", "FARM_CROP_DISTRIBUTIONS",
           "DEFAULT_SENSOR_DISTANCE_M", "DEFAULT_SENSOR_HEIGHT_M", "DEFAULT_SENSOR_SIZE_M"]  # fmt: skip

#: ``farm --sensor``: per-scan placement drawn uniformly from these intervals (metres).
#: Distance 5–25 m: the range in which an HDL-32E returns more than a few dozen points from a
#: car (LiDARNet v2's cars lie 3–25 m away); height 1.6–2.0 m: a LiDAR on a car roof; size
#: 4.5 m: a car's length (the object's largest dimension).
DEFAULT_SENSOR_DISTANCE_M = (5.0, 25.0)
DEFAULT_SENSOR_HEIGHT_M = (1.6, 2.0)
DEFAULT_SENSOR_SIZE_M = (4.5, 4.5)
#: The plan's and card's key of each :class:`SensorCropParams` setting, in the order they are written:
#: flat ``sensor_*`` keys beside :class:`FarmParams`'s, so a data set's digest is the same however the
#: settings are held.  ``distance_m`` ... ``hidden_below_m`` are :class:`CropDistributions` fields.
SENSOR_KEYS = {
    "distance_m": "sensor_distance_m", "height_m": "sensor_height_m", "size_m": "sensor_size_m",
    "reflectivity": "sensor_reflectivity", "footprint": "sensor_footprint", "ground_margin_m": "sensor_ground_margin_m",
    "hidden_below_m": "sensor_hidden_below_m", "across_sight_width_m": "sensor_across_sight_width_m",
    "divergence_deg": "sensor_divergence_deg", "adaptive_footprint": "sensor_adaptive_footprint", "min_returns": "sensor_min_returns",
    "returns": "sensor_returns",
}  # fmt: skip
#: The :class:`CropDistributions` fields the farm sets (and records); the others keep their defaults.
FARM_CROP_FIELDS = ("distance_m", "height_m", "size_m", "reflectivity", "ground_margin_m", "hidden_below_m", "min_returns")
#: Settings left out of the plan when None: the digest of sensor data sets made before they existed.
_LEFT_OUT_WHEN_NONE = ("ground_margin_m", "hidden_below_m", "across_sight_width_m", "divergence_deg", "adaptive_footprint", "min_returns",
                       "returns")  # fmt: skip
#: The ``farm`` flag of each :class:`CropDistributions` field it sets, for the messages of its checks.
CROP_OPTION_NAMES = {field: OPTION_NAMES[SENSOR_KEYS[field]] for field in FARM_CROP_FIELDS}
#: ``farm``'s option of each field of its :class:`~zbuf_occlude.sensors.request.ScanRequest`, for the request's messages.
FARM_REQUEST_NAMES = {"footprint_cast": OPTION_NAMES["sensor_adaptive_footprint"], "footprint": OPTION_NAMES["sensor_footprint"],
                      "footprint_rays": OPTION_NAMES["sensor_footprint"], "divergence_deg": OPTION_NAMES["sensor_divergence_deg"],
                      "max_returns": "a sensor file's max_returns", "returns": OPTION_NAMES["sensor_returns"]}  # fmt: skip
#: ``farm --sensor``'s placement when no option changes it.
FARM_CROP_DISTRIBUTIONS = CropDistributions(
    distance_m=DEFAULT_SENSOR_DISTANCE_M, height_m=DEFAULT_SENSOR_HEIGHT_M, size_m=DEFAULT_SENSOR_SIZE_M
)


@dataclass(frozen=True)
class SensorCropParams:
    """``farm --sensor``: the sensor that scans each object, and where each scan places it.

    Parameters
    ----------
    name : str
        A sensor preset (``hdl32e``...) or JSON file (:func:`~zbuf_occlude.sensors.kinds.sensor_from_name`).
    distributions : CropDistributions
        Per scan, uniform draws of the horizontal sensor-object distance (``distance_m``), the
        sensor height above the ground (``height_m``) and the object's largest dimension
        (``size_m``), metres (default :data:`FARM_CROP_DISTRIBUTIONS`); the object's
        direction and heading are uniform over 0–360°.  Return physics: ``reflectivity``
        (the sensor's radiometric threshold applies).  ``ground_margin_m``: keep the ground
        returns under each object; ``hidden_below_m``: hide each object's bottom; ``min_returns``: the fewest
        returns of the object a sample holds (a placement giving fewer is drawn again).  The farm
        sets and records these (:data:`FARM_CROP_FIELDS`); the other fields keep their defaults.
    footprint : bool
        Return physics: :data:`~zbuf_occlude.sensors.beam.footprint.FOOTPRINT_RAYS` rays per firing in the
        beam's divergence cone, strongest echo; any pulsed sensor whose beam has a divergence.
    divergence_deg : float or None
        The beam's full-angle divergence, degrees in (0, 90] (for ``footprint`` where the sensor's
        data sheet gives none); None: the sensor's.
    across_sight_width_m : (lo, hi) or None
        Stretch each mesh horizontally so that its crops are, at the median, as wide across the
        line of sight as this interval, metres, drawn per scan
        (:func:`~zbuf_occlude.sensors.fit.fit_width_scale`, a spinning LiDAR only); ``None``: the
        meshes' own proportions.
    footprint_cast : {"auto", "exact", "adaptive"}
        How the crops cast a footprint whose echoes are resolved (``object_crops(..., footprint=...)``):
        "adaptive" casts a pulse's whole footprint only where its centre ray and its neighbours do
        not show one plane filling it (the same crops but for a surface inside the cone that none
        of those rays meets, at a fraction of the cost), and needs a pulsed sensor whose beam fires
        several rays and resolves echoes; "exact" casts every sub-ray; "auto" (default) is
        "adaptive" where it applies, else "exact".  The card records the cast used
        (:attr:`footprint_mode`) as ``sensor_adaptive_footprint: true`` only when adaptive, so the
        digest of data sets made before it is kept; a card without it reads as "exact".  Held as the
        cast it resolves to ("exact" or "adaptive"), so that settings read back from a card compare
        equal and the sensor is not read again to know it.
    returns : int, str or None
        What each crop keeps of a pulse's returns (:func:`~zbuf_occlude.sensors.request.kept_returns`, the rule
        ``experiment sim2real`` follows too): 1 (default, :data:`~zbuf_occlude.sensors.request.TRAINING_RETURNS`) or
        ``"strongest"`` one return per pulse, ``"first"``, ``"last"``, N above 1, or ``"all"`` / None: what the
        sensor's device records.  Held as None where it leaves the sensor as it is (a spinning preset's one return),
        and the card records ``sensor_returns`` only where it changes it (an airborne preset's several returns), so
        the digest of data sets made before it is kept; a card without it reads as None, as they were made.
    option_names : mapping of str to str, optional
        Messages name ``across_sight_width_m`` so (the option as typed; default :data:`OPTION_NAMES`). Not stored.

    Raises
    ------
    InvalidInputError
        An unknown sensor; what :meth:`model` refuses; a bad ``across_sight_width_m``; a
        ``distributions`` field the farm does not record set to other than its default.  Each
        crop setting's value is checked by :class:`CropDistributions`, the one checker of them.
    """

    name: str
    distributions: CropDistributions = FARM_CROP_DISTRIBUTIONS
    footprint: bool = False
    across_sight_width_m: tuple[float, float] | None = None
    divergence_deg: float | None = None
    footprint_cast: str = "auto"
    returns: int | str | None = TRAINING_RETURNS
    option_names: InitVar[Mapping[str, str] | None] = None

    def __post_init__(self, option_names: Mapping[str, str] | None) -> None:
        if not isinstance(self.distributions, CropDistributions):
            raise InvalidInputError(f"--sensor's distributions must be a CropDistributions, got {type(self.distributions).__name__}")
        unset = CropDistributions()
        for f in dataclasses.fields(CropDistributions):
            if f.name not in FARM_CROP_FIELDS and getattr(self.distributions, f.name) != getattr(unset, f.name):
                raise InvalidInputError(
                    f"farm --sensor draws no {f.name} (its card could not say so): leave it at {getattr(unset, f.name)!r}"
                )
        object.__setattr__(self, "footprint", bool(self.footprint))
        from zbuf_occlude.sensors.beam.adaptive_cast import check_footprint_cast, footprint_mode

        check_footprint_cast(self.footprint_cast, None, names=FARM_REQUEST_NAMES)  # the mode alone, before the sensor is read
        if self.divergence_deg is not None:
            from zbuf_occlude.sensors.checks import real

            divergence = real(self.divergence_deg, OPTION_NAMES["sensor_divergence_deg"], low=0.0, low_open=True, high=MAX_DIVERGENCE_DEG)
            object.__setattr__(self, "divergence_deg", divergence)
        if self.across_sight_width_m is not None:
            option = (option_names or {}).get("across_sight_width_m") or OPTION_NAMES["sensor_across_sight_width_m"]
            object.__setattr__(self, "across_sight_width_m", check_across_sight_width(self.across_sight_width_m, option))
        request = self.request()  # raises InvalidInputError naming an unknown sensor, or physics it has not (a depth camera)
        object.__setattr__(self, "returns", request.returns)  # None where it changes nothing: the card records it only where it does
        object.__setattr__(self, "footprint_cast", footprint_mode(self.footprint_cast, request.scanner.beam))  # one value for one cast

    def model(self):
        """The sensor of ``name`` with the beam changes of ``footprint`` and ``divergence_deg``: :meth:`request`'s scanner."""
        return self.request().scanner

    def request(self):
        """The :class:`~zbuf_occlude.sensors.request.ScanRequest` of the farm's crops: the sensor of ``name``, the beam
        changes of ``footprint`` and ``divergence_deg`` (as ``scan``'s beam options) and ``footprint_cast``, refused in
        ``farm``'s options (:data:`FARM_REQUEST_NAMES`).

        Raises
        ------
        InvalidInputError
            Unknown sensor; a sensor without a beam (a depth camera: the farm scans with pulsed
            sensors); ``reflectivity`` for an airborne scanner (its crops fly over every surface
            alike); ``footprint`` for a beam without a divergence (naming ``--sensor-divergence``);
            ``across_sight_width_m`` for a sensor that is not a spinning LiDAR; a divergence the
            beam refuses; ``footprint_cast`` "adaptive" for a beam that fires one ray or resolves no
            echoes.  Each names its ``farm`` option.
        """
        from zbuf_occlude.sensors.kinds import capabilities, sensor_from_name

        sensor = sensor_from_name(self.name)
        kind = capabilities(sensor)  # the kinds table's capabilities, asked once; the request reads the same row
        given = [OPTION_NAMES[f"sensor_{f}"] for f, v in (("footprint", self.footprint), ("divergence_deg", self.divergence_deg),
                                                         ("reflectivity", self.distributions.reflectivity),
                                                         ("adaptive_footprint", self.footprint_cast == "adaptive")) if v not in (None, False)]  # fmt: skip
        if not kind.pulsed:  # its crops would need a camera's placement, which the farm does not draw
            raise InvalidInputError(f"{', '.join([OPTION_NAMES['sensor'], *given])}: {self.name} is a {kind.title}, which has no beam; "
                                    "the farm scans with a pulsed sensor (a LiDAR, a ray table or an airborne scanner), and renders "
                                    "a camera's views without --sensor")  # fmt: skip
        if self.distributions.reflectivity is not None and kind.flies:
            raise InvalidInputError(f"{OPTION_NAMES['sensor_reflectivity']}: {self.name} is an {kind.title}, whose crops fly over "
                                    "every surface alike (no detection threshold per object); leave it out")  # fmt: skip
        if self.across_sight_width_m is not None and not kind.spins:
            raise InvalidInputError(f"--sensor-across-sight-width measures across a spinning LiDAR's line of sight; {self.name} is not one")
        from zbuf_occlude.sensors.request import ScanRequest

        beam = {"footprint": self.footprint, "divergence_deg": self.divergence_deg}
        return ScanRequest(sensor, beam=beam, footprint_cast=self.footprint_cast, returns=self.returns,
                           names={**FARM_REQUEST_NAMES, "sensor": self.name})  # fmt: skip

    @property
    def footprint_mode(self) -> str:
        """``"adaptive"`` or ``"exact"``: how the crops cast a footprint (:func:`~zbuf_occlude.sensors.crops.object_crops`):
        ``footprint_cast``, which construction resolved for the sensor (:func:`~zbuf_occlude.sensors.beam.adaptive_cast.footprint_mode`)."""
        return self.footprint_cast

    def to_dict(self) -> dict[str, Any]:
        """``{"sensor": name, "sensor_distance_m": [lo, hi], ...}``: the flat keys of :data:`SENSOR_KEYS`."""
        values = {**{f: getattr(self.distributions, f) for f in FARM_CROP_FIELDS}, "footprint": self.footprint,
                  "across_sight_width_m": self.across_sight_width_m, "divergence_deg": self.divergence_deg,
                  "adaptive_footprint": True if self.footprint_mode == "adaptive" else None, "returns": self.returns}  # fmt: skip
        d: dict[str, Any] = {"sensor": self.name}
        for field, key in SENSOR_KEYS.items():
            if values[field] is not None or field not in _LEFT_OUT_WHEN_NONE:
                d[key] = list(values[field]) if isinstance(values[field], tuple) else values[field]
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SensorCropParams:
        """The settings of :meth:`to_dict`'s flat keys (``d["sensor"]`` the name; a key left out: its default).

        Raises
        ------
        InvalidInputError
            A bad value, naming its ``farm`` flag.
        """
        values = {field: d[key] for field, key in SENSOR_KEYS.items() if key in d}
        crops = {field: values.pop(field) for field in FARM_CROP_FIELDS if field in values}
        adaptive = values.pop("adaptive_footprint", False)  # the cast used: absent on the cards of exact casts
        if not isinstance(adaptive, bool):  # a card's value: true or false, not "yes"
            raise InvalidInputError(f"{SENSOR_KEYS['adaptive_footprint']} ({OPTION_NAMES['sensor_adaptive_footprint']}) must be true "
                                    f"or false, got {type(adaptive).__name__} {adaptive!r:.40}")  # fmt: skip
        distributions = dataclasses.replace(FARM_CROP_DISTRIBUTIONS, **crops, option_names=CROP_OPTION_NAMES)
        values.setdefault("returns", None)  # absent: the returns as the sensor records them, as the data set was made
        return cls(d["sensor"], distributions, footprint_cast="adaptive" if adaptive else "exact", **values)
