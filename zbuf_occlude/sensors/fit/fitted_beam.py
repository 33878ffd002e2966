"""A scanner given the return model fitted to LAS/LAZ scans: its beam with what was fitted changed, the rest its data sheet's.

A fitted sensor keeps its base's beam (wavelength, profile, power noise, range noise and limits,
...: the data sheet's) and changes only what the fit measured (:mod:`.return_model`):

* ``max_returns`` (at most :data:`~zbuf_occlude.sensors.beam.echoes.MAX_RETURNS`) and, above 1, the
  ``range_resolution_m``; one return per pulse: no range resolution (a footprint's echoes then
  give the strongest, :class:`~zbuf_occlude.sensors.beam.fields.Beam`);
* ``detection_threshold`` (m⁻²) and ``intensity_scale`` (counts·m², with ``max_intensity``
  :data:`~zbuf_occlude.sensors.beam.fields.MAX_INTENSITY_COUNTS`: a LAS file's counts are 16-bit), so
  that a scan of the fitted sensor writes intensities in the scans' counts;
* ``divergence_deg`` where it was fitted by simulation (:mod:`.divergence`).

A beam of several returns needs a footprint to meet several surfaces.  Where the base's beam
has none (one ray per pulse), it is given the data sheet's divergence (the base beam's own, else
that of the preset of its name) and :data:`~zbuf_occlude.sensors.beam.footprint.FOOTPRINT_RAYS`
sub-rays; where no divergence is known it keeps one ray, and the fit says so.  An airborne
scanner flies at the height the scale and threshold were fitted at.  :func:`fitted_sensor`
returns, beside the sensor, where each changed field came from: the sensor file's
``fit.beam`` block.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.geometry.arguments import described
from zbuf_occlude.sensors.beam.fields import MAX_INTENSITY_COUNTS, MODE_RETURNS
from zbuf_occlude.sensors.checks import MAX_RANGE_M
from zbuf_occlude.sensors.beam.echoes import MAX_RETURNS
from zbuf_occlude.sensors.fit.lidar import Estimate
from zbuf_occlude.sensors.beam.footprint import FOOTPRINT_RAYS
from zbuf_occlude.sensors.kinds import capabilities, kind_of

__all__ = ["MIN_DETECTION_THRESHOLD", "SETS_BEAM", "fitted_sensor", "fitted_sets"]

#: Each estimate of the fit that sets the beam, and the beam field it sets.
SETS_BEAM = {"range_resolution_m": "range_resolution_m", "max_returns": "max_returns", "beam_divergence_deg": "divergence_deg",
             "detection_threshold": "detection_threshold", "intensity_scale": "intensity_scale"}  # fmt: skip
#: The least detection threshold a fit may give, m⁻²: the energy a white target returns at
#: normal incidence from :data:`~zbuf_occlude.sensors.checks.MAX_RANGE_M`, the farthest range a
#: sensor has.  A fitted threshold below it rests on a flying height far above the scans' (it
#: scales as 1/altitude²).
MIN_DETECTION_THRESHOLD = 1.0 / MAX_RANGE_M**2


def fitted_sets(estimates: Mapping[str, Estimate], sensor: Any) -> tuple[str, ...]:
    """The estimates that set ``sensor``'s beam (:data:`SETS_BEAM`, in that order): those measured (finite, > 0), for a
    sensor that ``fit-sensor`` fits (:attr:`~zbuf_occlude.sensors.kinds.SensorKind.fits`); none for anything else."""
    if not capabilities(sensor).fits:
        return ()
    return tuple(name for name in SETS_BEAM if math.isfinite(estimates[name].value) and estimates[name].value > 0)


def fitted_sensor(estimates: Mapping[str, Estimate], sensor: Any, *, altitude_m: float, n_pulses: int) -> tuple[Any, dict]:
    """``sensor`` with the fitted return model in its beam (module docstring), and where each beam field came from.

    Parameters
    ----------
    estimates : mapping of str to Estimate
        The return model's (:class:`~zbuf_occlude.sensors.fit.ReturnModelFit` ``estimates``).
    sensor : Lidar or AirborneScanner
    altitude_m : float
        The flying height the fit assumed, metres: an airborne scanner's ``altitude_m``.
    n_pulses : int
        Pulses fitted to, for the sensor's ``source``.

    Returns
    -------
    sensor : Lidar or AirborneScanner
        Named ``<name>-fitted``, its source saying what was fitted.
    origin : dict
        ``{"fitted": {field: value}, "data_sheet": {field: value}, "model": {field: value},
        "source": the data sheet, "kept": sentence}``: the beam fields the fit measured, those taken from the data
        sheet, those the model's rules set (sub-rays, the 16-bit intensity range), and what the rest is.

    Raises
    ------
    ArgumentTypeError
        ``sensor`` is not of a kind ``fit-sensor`` fits.
    InvalidInputError
        A detection threshold below :data:`MIN_DETECTION_THRESHOLD` (naming the altitude it rests on); fitted values
        the beam refuses (naming the field).
    """
    if not capabilities(sensor).fits:
        raise ArgumentTypeError(f"the return model applies to a Lidar or an AirborneScanner, got {described(sensor)}")
    sets = fitted_sets(estimates, sensor)
    e = {SETS_BEAM[name]: estimates[name].value for name in sets}
    beam = sensor.beam
    fitted: dict[str, Any] = {}
    if "max_returns" in e:
        fitted["max_returns"] = min(int(e["max_returns"]), MAX_RETURNS)
    returns = fitted.get("max_returns", beam.max_returns)
    if returns > 1 and "range_resolution_m" in e:
        fitted["range_resolution_m"] = e["range_resolution_m"]
    for name in ("divergence_deg", "intensity_scale"):
        if name in e:
            fitted[name] = e[name]
    if "detection_threshold" in e:
        if e["detection_threshold"] < MIN_DETECTION_THRESHOLD:  # the beam would take it; it cannot be the scans'
            raise InvalidInputError(
                f"the fitted detection threshold {e['detection_threshold']:.3g} m⁻² is below the energy a white target returns "
                f"from {MAX_RANGE_M:g} m, the farthest range a sensor has: the threshold scales as 1/altitude², so "
                f"altitude_m {altitude_m:g} is likely not the scans' flying height"
            )
        fitted["detection_threshold"] = e["detection_threshold"]
    model = _model_changes(beam, returns, "intensity_scale" in fitted)
    data_sheet, source = _footprint(sensor, returns, fitted, model)
    changes = {**fitted, **data_sheet, **model}
    name = sensor.name if sensor.name.endswith("-fitted") else f"{sensor.name}-fitted"
    what = f"returns fitted to {n_pulses:,} pulses ({', '.join(sets) or 'nothing measured'})"
    extra = {"altitude_m": altitude_m} if kind_of(sensor).flies else {}  # the height the scale was fitted at
    out = replace(sensor, beam=beam.with_(**changes), name=name, source=f"{sensor.source}; {what}".lstrip("; "), **extra)
    kept = f"every other beam field is the {beam.name} beam's, as the base sensor {sensor.name} gives it"
    return out, {"fitted": fitted, "data_sheet": data_sheet, "model": model, "source": source, "kept": kept}


def _model_changes(beam: Any, returns: int, scaled: bool) -> dict[str, Any]:
    """The beam fields the model's rules change with ``returns`` per pulse: the return mode and the range resolution or
    echo separation a receiver of that many returns cannot have, and a LAS file's 16-bit intensity range."""
    model: dict[str, Any] = {}
    wanted = MODE_RETURNS.get(beam.return_mode)
    if wanted is not None and wanted != returns:
        model["return_mode"] = "all"  # a single- or dual-return mode records a fixed count: the scans recorded another
    mode = model.get("return_mode", beam.return_mode)
    if returns == 1 and mode == "all" and beam.range_resolution_m > 0:
        model["range_resolution_m"] = 0.0  # one return per pulse resolves no echoes
    if (returns > 1 or mode != "all") and beam.echo_separation_m > 0:
        model["echo_separation_m"] = 0.0  # resolved echoes are kept apart by the range resolution instead
    if scaled:
        model["max_intensity"] = MAX_INTENSITY_COUNTS
    return model


def _footprint(sensor: Any, returns: int, fitted: dict, model: dict) -> tuple[dict[str, Any], str]:
    """The data sheet's divergence (and, in ``model``, :data:`FOOTPRINT_RAYS` sub-rays) for a beam of several returns
    and one ray; and the data sheet's source."""
    beam = sensor.beam
    source = beam.source or sensor.source
    if returns <= 1 or beam.footprint_rays > 1:
        return {}, source
    data_sheet: dict[str, Any] = {}
    divergence = fitted.get("divergence_deg", beam.divergence_deg)
    if divergence > 0 and "divergence_deg" not in fitted:
        data_sheet["divergence_deg"] = divergence
    elif divergence <= 0:
        preset = kind_of(sensor).presets.get(sensor.name.removesuffix("-fitted").lower())
        if preset is not None and preset.beam.divergence_deg > 0:
            data_sheet["divergence_deg"] = divergence = preset.beam.divergence_deg
            source = preset.beam.source or preset.source
    if divergence > 0:
        model["footprint_rays"] = FOOTPRINT_RAYS
    return data_sheet, source
