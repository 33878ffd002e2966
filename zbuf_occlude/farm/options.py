"""The farm's command-line option of each of its parameters, for the messages of its checks (a leaf: the parameters'
modules import it, it imports nothing of the farm)."""

from __future__ import annotations

__all__ = ["OPTION_NAMES"]

#: Command-line option of each parameter, for messages (``storage`` is ``--format`` in ``generate``).
OPTION_NAMES = {
    "views": "--views", "samples_per_view": "--samples-per-view", "n_points": "--points",
    "dense_points": "--dense-points", "density": "--density", "resolution": "--resolution", "seed": "--seed",
    "radius": "--radius", "storage": "--storage/--format", "method": "--method", "sensor": "--sensor",
    "sensor_distance_m": "--sensor-distance", "sensor_height_m": "--sensor-height", "sensor_size_m": "--sensor-size",
    "sensor_reflectivity": "--sensor-reflectivity", "sensor_footprint": "--sensor-footprint", "sensor_divergence_deg": "--sensor-divergence",
    "sensor_ground_margin_m": "--sensor-ground-margin", "sensor_hidden_below_m": "--sensor-hidden-below",
    "sensor_across_sight_width_m": "--sensor-across-sight-width", "sensor_adaptive_footprint": "--sensor-footprint-cast", "up": "--up",
    "sensor_min_returns": "--sensor-min-returns", "sensor_returns": "--sensor-returns",
}  # fmt: skip
