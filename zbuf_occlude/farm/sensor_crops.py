"""``farm --sensor``: one object's simulated sensor crops arranged as the datasets of a dense shard.

The sensor package makes the crops (:func:`zbuf_occlude.sensors.crops.lidar_object_samples`);
the farm owns its shard layout (:mod:`zbuf_occlude.dataset.layout`), so the arranging is here.
"""

from __future__ import annotations

import logging
import os
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from zbuf_occlude.dataset.layout import POINT_COLUMNS
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.sensors.crops import kept_return_fields, left_out_why, lidar_object_samples
from zbuf_occlude.sensors.placement import CropDistributions
from zbuf_occlude.sensors.fit import fit_object_shape

if TYPE_CHECKING:
    import trimesh

    from zbuf_occlude.sensors.request import ScanRequest

__all__ = ["farm_datasets"]

log = logging.getLogger(__name__)


def farm_datasets(
    mesh: trimesh.Trimesh | str | os.PathLike,
    request: ScanRequest,
    *,
    name: str,
    label: int,
    object_index: int,
    n_samples: int,
    n_points: int = 2048,
    seed: int = 0,
    distributions: CropDistributions = CropDistributions(),
    across_sight_width_m: tuple[float, float] | None = None,
) -> dict[str, np.ndarray]:
    """What the farm writes for one object with ``--sensor``: the datasets of a dense shard.

    Each LiDAR sample is its own "pose" (its placement is drawn per sample), so
    ``pose_index`` is the sample number and ``sample_index`` is 0; samples without a return
    are left out (their ``n_visible`` would be 0, as for an empty pose), and so are samples with fewer returns of the
    object than ``distributions.min_returns`` after their redraws (:func:`~zbuf_occlude.sensors.crops.object_crops`),
    each named in a warning.  With
    ``across_sight_width_m`` (metres, a LiDAR), the object is stretched horizontally to those
    widths (:func:`~zbuf_occlude.sensors.fit.fit_width_scale`, seeded with ``seed``).  ``request``: the farm's
    :class:`~zbuf_occlude.sensors.request.ScanRequest` (its scanner, backend and footprint cast, as
    :func:`~zbuf_occlude.sensors.crops.object_crops` casts it).

    Returns
    -------
    dict of str → ndarray, B = samples with returns
        The dense layout: ``data (B, n_points, 3) float32`` (normalised mesh frame, x and y times ``width_scale``), ``label``,
        ``object_index``, ``pose_index``, ``sample_index`` (int64), ``elevation_deg``,
        ``azimuth_deg`` (the sensor seen from the object, degrees), ``n_visible`` (returns);
        and the placement: ``radius`` (mesh units), ``distance_m``, ``sensor_height_m``,
        ``object_azimuth_deg``, ``yaw_deg``, ``size_m`` (float64), ``ring (B, n_points) int16``;
        ``hidden_below_m`` (float64, metres) when ``distributions`` hides the objects' bottoms;
        ``width_scale`` (float64) when the object is stretched; and, when the request's scanner records
        several returns per pulse (:func:`~zbuf_occlude.sensors.crops.kept_return_fields`), its
        return fields per point, ``(B, n_points)`` of the dtypes of
        :data:`~zbuf_occlude.dataset.layout.POINT_COLUMNS` (``return_number`` ... ``scan_angle_deg``).

    Raises
    ------
    InvalidInputError
        A mesh the width stretch cannot measure (naming ``name``), or bad distributions.
    """
    sensor, backend, footprint = request.scanner, request.backend, request.cast
    if across_sight_width_m is not None:
        mesh = load_mesh(mesh) if isinstance(mesh, (str, os.PathLike)) else mesh  # once, for the fit and the crops
        distributions = replace(distributions, **fit_object_shape(mesh, sensor, distributions, across_sight_width_m, seed=seed, name=name))
    clouds = lidar_object_samples(mesh, sensor, name=name, n_samples=n_samples, n_points=n_points, seed=seed,
                                  distributions=distributions, label=label, backend=backend, footprint=footprint)  # fmt: skip
    b = len(clouds)
    missing = sorted(set(range(n_samples)) - {c.sample_index for c in clouds})
    if missing:  # each named: the data set holds fewer samples of this object than asked
        log.warning("%s: sample%s %s left out: %s", name, "s" * (len(missing) > 1), ", ".join(map(str, missing)),
                    left_out_why(distributions.min_returns))  # fmt: skip
    f64 = lambda values: np.asarray(values, dtype=np.float64).reshape(b)  # noqa: E731
    optional = {
        key: f64([c.extra[key] for c in clouds]) for key in ("hidden_below_m", "width_scale") if getattr(distributions, key) is not None
    }
    for key in kept_return_fields(sensor):  # per point, as the scans hold them
        dtype = POINT_COLUMNS[key].dtype
        optional[key] = np.stack([c.extra["returns"][key] for c in clouds]).astype(dtype) if b else np.zeros((0, n_points), dtype)
    return {
        "data": np.stack([c.points for c in clouds]) if b else np.zeros((0, n_points, 3), np.float32),
        "label": np.full(b, label, dtype=np.int64),
        "object_index": np.full(b, object_index, dtype=np.int64),
        "pose_index": np.array([c.sample_index for c in clouds], dtype=np.int64),
        "sample_index": np.zeros(b, dtype=np.int64),
        "elevation_deg": f64([c.elevation_deg for c in clouds]),
        "azimuth_deg": f64([c.azimuth_deg for c in clouds]),
        "n_visible": np.array([c.n_visible for c in clouds], dtype=np.int64),
        "radius": f64([c.radius for c in clouds]),
        "distance_m": f64([c.extra["distance_m"] for c in clouds]),
        "sensor_height_m": f64([c.extra["height_m"] for c in clouds]),
        "object_azimuth_deg": f64([c.extra["azimuth_deg"] for c in clouds]),
        "yaw_deg": f64([c.extra["yaw_deg"] for c in clouds]),
        "size_m": f64([c.extra["size_m"] for c in clouds]),
        "ring": (np.stack([c.extra["ring"] for c in clouds]).astype(np.int16) if b and clouds[0].extra["ring"] is not None
                 else np.zeros((b, n_points), np.int16)),
        **optional,
    }  # fmt: skip
