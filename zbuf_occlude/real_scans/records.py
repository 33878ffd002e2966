"""One real object scan, normalised like the paper's meshes (Sryamkin et al. 2023, §4.1)."""

from __future__ import annotations

from collections.abc import Container, Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError

__all__ = ["RealScan", "normalize_points", "real_label"]


@dataclass
class RealScan:
    """One real object scan, normalised.

    Attributes
    ----------
    points : (n, 3) float32
        Bounding-box centre at 0, max extent 1, z up (object units, like a normalised mesh).
    label : str
        The data set's class name (``object`` column, or SUO file-name prefix).
    source : str
        The file it came from.
    dataset : {"suo", "lidarnet"}
    extent_m : (3,) float64
        Bounding-box size before normalisation, metres (x, y, z with z up).
    points_sensor_m : (n, 3) float64 or None
        The same returns before normalisation, z up, metres, in ``points``' order: the sensor
        frame (sensor at the origin) for SUO and LiDARNet; for class folders of point files, the
        file's own coordinates (a sensor frame when the data set keeps one; a fit refuses
        clouds centred on the object, :func:`zbuf_occlude.sensors.fit.fit_lidar`).
    """

    points: NDArray[np.float32]
    label: str
    source: str
    dataset: str
    extent_m: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    points_sensor_m: NDArray[np.float64] | None = None


def normalize_points(points: NDArray[np.floating], *, what: str = "") -> NDArray[np.float32]:
    """Centre the bounding box on the origin and scale the largest extent to 1.

    Parameters
    ----------
    points : (n, 3) float
        Any unit.
    what : str
        The scan (its file), first words of a message.

    Returns
    -------
    (n, 3) float32

    Raises
    ------
    InvalidInputError
        Empty, not (n, 3), non-finite values, or zero extent (naming ``what``).
    """
    said = f"{what}: " if what else ""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise InvalidInputError(f"{said}need (n >= 1, 3) points, got shape {p.shape}")
    if not np.isfinite(p).all():
        raise InvalidInputError(f"{said}points contain NaN or inf")
    lo, hi = p.min(axis=0), p.max(axis=0)
    extent = float((hi - lo).max())
    if extent == 0.0:
        raise InvalidInputError(f"{said}all {len(p):,} points coincide (zero extent); a scan needs an extent to be normalised")
    return ((p - (lo + hi) / 2.0) / extent).astype(np.float32)


def real_label(label: str, names: Container[str], label_map: Mapping[str, str] | None = None) -> str:
    """A real scan's class among ``names``: its label (renamed by ``label_map``), or that in lower case where the label
    itself is none of them (LiDARNet's ``Car`` folders hold ``car``).  A label that is no class either way comes back in
    lower case."""
    label = (label_map or {}).get(label, label)
    return label if label in names else label.lower()
