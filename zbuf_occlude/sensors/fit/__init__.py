"""Sensors and their scenes fitted to real object scans: what the simulation can set, estimated from the user's own scans.

``lidar``
    The sensor: azimuth step (firing rate), range noise, range-dependent dropout, with their
    uncertainties (:func:`fit_lidar`).
``airborne``
    An airborne scanner from segmented aerial crops with no sensor position: point density,
    the scan angle at each crop and half the swath, vertical and range noise (:func:`fit_airborne`).
``scans``
    The scenes, per class: where the crops stand, how tall their objects are, how much is hidden
    below, how wide they show across the line of sight and their outline over the height
    (:func:`crop_placement_json`).
``shapes``
    The meshes made to show that, fitted on their own simulated crops (:func:`fit_object_shape`).
``returns``
    The returns of each pulse of a LAS/LAZ scan: returns per pulse, multi-return shares, gaps
    between returns, intensities (:func:`return_statistics`).
``return_model``
    The return model fitted to a LAS/LAZ scan: range resolution, returns per pulse, detection
    threshold and intensity scale (:func:`fit_return_model`).
``divergence``
    The beam divergence fitted by simulation: a simulated multi-return share curve inverted at a
    scan's share (:func:`fit_divergence`, :func:`divergence_from_shares`).
``ray_drop``
    Ray drop on vegetation: the beam's ``foliage_dropout`` from the firings that real scans of
    crowns lose beyond those of solid objects (:func:`fit_foliage_dropout`).
``fitted_beam``
    The return model applied to a scanner: its beam with what was fitted changed, the rest its
    data sheet's, and where each field came from (:func:`~zbuf_occlude.sensors.fit.fitted_beam.fitted_sensor`).
``partial_echoes``, ``partial_echo_meshes``, ``mesh_crops``, ``class_placement``, ``scan_lines``
    The receiver's partial echoes fitted by scanning a folder of meshes (``fit-sensor --meshes``,
    :func:`~zbuf_occlude.sensors.fit.partial_echo_meshes.fit_partial_echoes`): the meshes' crops placed class by
    class, as ``experiment sim2real``'s ``lidar`` set places them, and the outline share of their scan lines against
    the real scans' (imported from their modules).
``engine``
    ``fit-sensor``'s one engine: reads the scans or LAS/LAZ files, fits, writes the sensor file
    and its table (:func:`zbuf_occlude.sensors.fit.engine.fit_sensor`; imported from its module,
    as it reads files).

Every name of the fits is imported from here (``from zbuf_occlude.sensors.fit import fit_lidar``).
"""

from __future__ import annotations

from zbuf_occlude.sensors.fit.airborne import AirborneFit, crop_faces, fit_airborne
from zbuf_occlude.sensors.fit.divergence import (
    divergence_curve,
    divergence_from_shares,
    fit_divergence,
)
from zbuf_occlude.sensors.fit.lidar import (
    BOOTSTRAP,
    MAX_DROPOUT_GAP,
    MIN_RETURNS,
    PLANE_NEIGHBOURS,
    RING_SHARE,
    Estimate,
    LidarFit,
    fit_lidar,
)
from zbuf_occlude.sensors.fit.ray_drop import (
    dropout_by_surface,
    fit_foliage_dropout,
    is_crown_class,
)
from zbuf_occlude.sensors.fit.return_model import (
    ReturnModelFit,
    fit_return_model,
    merge_scans,
)
from zbuf_occlude.sensors.fit.returns import (
    VEGETATION_CLASSES,
    ReturnStatistics,
    return_statistics,
)
from zbuf_occlude.sensors.fit.scans import (
    DISTANCE_QUANTILES,
    MIN_PLACEMENT_SCANS,
    SENSOR_HEIGHT_QUANTILE,
    WIDTH_BAND_M,
    WIDTH_PROFILE_BINS,
    across_sight_width,
    crop_placement_json,
    fit_crop_bottoms,
    fit_crop_distances,
    fit_crop_heights,
    fit_crop_width_profile,
    fit_crop_widths,
    fit_sensor_height,
    median_width_profile,
    sight_coordinates,
    width_profile,
)
from zbuf_occlude.sensors.fit.shapes import (
    WIDTH_SAMPLES,
    fit_object_shape,
    fit_visible_across_sight,
    fit_width_profile,
    fit_width_scale,
)

__all__ = [
    "AirborneFit", "crop_faces", "fit_airborne", "RING_SHARE",
    "across_sight_width", "BOOTSTRAP", "crop_placement_json", "DISTANCE_QUANTILES", "Estimate", "fit_crop_bottoms",
    "fit_crop_distances", "fit_crop_heights", "fit_crop_width_profile", "fit_crop_widths", "fit_lidar", "fit_object_shape",
    "fit_sensor_height", "fit_visible_across_sight", "fit_width_profile", "fit_width_scale", "LidarFit", "median_width_profile",
    "MAX_DROPOUT_GAP", "MIN_PLACEMENT_SCANS", "MIN_RETURNS", "PLANE_NEIGHBOURS", "SENSOR_HEIGHT_QUANTILE", "sight_coordinates", "WIDTH_BAND_M",
    "width_profile", "WIDTH_PROFILE_BINS", "WIDTH_SAMPLES", "return_statistics", "ReturnStatistics", "VEGETATION_CLASSES",
    "divergence_curve", "divergence_from_shares", "fit_divergence", "fit_return_model", "merge_scans", "ReturnModelFit",
    "dropout_by_surface", "fit_foliage_dropout", "is_crown_class",
]  # fmt: skip
