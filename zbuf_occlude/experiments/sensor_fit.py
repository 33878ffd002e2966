"""``fit-sensor`` for the experiments: the sensor fitted to real object scans by the one engine,
:mod:`zbuf_occlude.sensors.fit.engine` (:func:`fit_to_scans` for scans already read, :func:`fit_sensor_to_scans` for a folder).

The names are the engine's own functions, imported here so that the experiments and the command line run the same code.
"""

from __future__ import annotations

from zbuf_occlude.sensors.fit.engine import fit_sensor, fit_sensor_to_scans, fit_to_scans

__all__ = ["fit_sensor", "fit_to_scans", "fit_sensor_to_scans"]
