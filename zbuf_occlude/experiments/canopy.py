"""Canopy height: how tall a tile's trees stand, measured alike on a real LAS tile and on a simulated plot.

How many returns a pulse gives in a crown, and how far apart, depends on how deep the crown is
against the receiver's range resolution: a plot of 10 m trees cannot give a tile of 25 m trees
its third and fourth returns.  :func:`canopy_height` measures a scan's canopy height model (the
highest return of each square cell whose highest return is vegetation, as
:func:`~.tree_cover.tree_cover` counts cells, its height above the ground) and gives a quantile of
it; :func:`plot_canopy_height` measures a plot of meshes the same way with vertical rays, so that
the plot's trees can be scaled to the tile's.

A tile without vegetation classes (Autzen's class 1 holds trees, buildings and open ground the
classifier left) is classed by height first (:func:`classes_by_height`), with the rule the LAS
writer gives simulated vegetation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.returns import GROUND_CLASS
from zbuf_occlude.experiments.tree_cover import TREE_COVER_CELL_M, TREE_COVER_MIN_PULSES, cell_tops, vertical_tops
from zbuf_occlude.io.las import LasPoints
from zbuf_occlude.sensors.checks import count, real
from zbuf_occlude.sensors.fit.returns import VEGETATION_CLASSES
from zbuf_occlude.sensors.scene.las_classes import VEGETATION_HEIGHTS_M
from zbuf_occlude.sensors.scene.objects import ScanScene

__all__ = ["CANOPY_QUANTILE", "GROUND_NEIGHBOURS", "canopy_height", "classes_by_height", "heights_above_ground", "plot_canopy_height"]

#: Ground points (class 2) whose median height is the ground under a point: a few, so that one
#: mislabelled ground point does not lift it, and near, so that a slope does not.
GROUND_NEIGHBOURS = 8
#: The quantile of the canopy height model compared: the 90th percentile of the tops, a usual
#: measure of a stand's height that leaves out the few tallest crowns and the low shrubs.
CANOPY_QUANTILE = 0.9


def heights_above_ground(las: LasPoints, *, neighbours: int = GROUND_NEIGHBOURS) -> NDArray[np.float64]:
    """Each point's height above the ground, metres.

    The ground under a point is the median z of its ``neighbours`` nearest ground points (class 2)
    in x and y (scipy's k-d tree); coordinates in the file's unit times
    :attr:`~zbuf_occlude.io.las.LasPoints.metres_per_unit`.

    Returns
    -------
    (N,) float64
        Metres, negative below the ground.

    Raises
    ------
    InvalidInputError
        ``neighbours`` not a whole number >= 1, or fewer ground points than ``neighbours``.
    """
    from scipy.spatial import cKDTree

    neighbours = count(neighbours, "neighbours", low=1, high=1024)
    points = las.points * las.metres_per_unit
    ground = points[las.classification == GROUND_CLASS]
    if len(ground) < neighbours:
        raise InvalidInputError(f"heights_above_ground: {len(ground):,} ground points (class {GROUND_CLASS}), {neighbours} needed")
    _, nearest = cKDTree(ground[:, :2]).query(points[:, :2], k=neighbours)
    z = ground[nearest.reshape(len(points), neighbours), 2]
    return points[:, 2] - np.median(z, axis=1)


def classes_by_height(las: LasPoints, heights_m: NDArray[np.floating], *, source_class: int = 1) -> LasPoints:
    """``las`` with its ``source_class`` points classed by their height above the ground.

    The rule the LAS writer gives simulated vegetation (:data:`~zbuf_occlude.sensors.scene.las_classes.VEGETATION_HEIGHTS_M`,
    IGN's bounds), except below the lower bound: there a point is at ground level (a field, a road
    or a car park the classifier left unclassified) and becomes ground (2), not low vegetation.
    Between the bounds it becomes medium vegetation (4), above them high vegetation (5).
    Other classes are kept.

    Parameters
    ----------
    las : LasPoints
    heights_m : (N,) float
        Each point's height above the ground, metres (:func:`heights_above_ground`).
    source_class : int
        The class to split (default 1, unclassified).

    Raises
    ------
    InvalidInputError
        ``heights_m`` of another shape, or NaN where a point of ``source_class`` is.
    """
    source_class = count(source_class, "source_class", low=0, high=255)
    heights = np.asarray(heights_m, np.float64)
    if heights.shape != (len(las),):
        raise InvalidInputError(f"classes_by_height: heights_m must have shape ({len(las)},), got {heights.shape}")
    split = las.classification == source_class
    if np.isnan(heights[split]).any():
        raise InvalidInputError("classes_by_height: a NaN height on a point to class")
    low, high = VEGETATION_HEIGHTS_M
    classes = las.classification.copy()
    classes[split] = np.where(heights[split] < low, GROUND_CLASS, np.where(heights[split] < high, 4, 5))
    return replace(las, classification=classes)


def canopy_height(las: LasPoints, *, classes: Sequence[int] = VEGETATION_CLASSES, cell_m: float = TREE_COVER_CELL_M,
                  min_pulses: int = TREE_COVER_MIN_PULSES, quantile: float = CANOPY_QUANTILE,
                  heights_m: NDArray[np.floating] | None = None) -> float:  # fmt: skip
    """The ``quantile`` of a scan's canopy height model, metres.

    The cells are :func:`~.tree_cover.tree_cover`'s (``cell_m`` squares holding ``min_pulses``
    first returns or more, whose highest return is vegetation or the ground); of those whose
    highest return is vegetation (``classes``), that return's height above the ground.

    Parameters
    ----------
    las : LasPoints
        A real tile or a simulated scan read back from LAS, with classes.
    classes, cell_m, min_pulses
        As :func:`~.tree_cover.tree_cover`'s.
    quantile : float
        In [0, 1] (default :data:`CANOPY_QUANTILE`).
    heights_m : (N,) float, optional
        Each point's height above the ground, metres; None: :func:`heights_above_ground`.

    Raises
    ------
    InvalidInputError
        A bad argument (named), no ground to measure from, or no counted cell whose highest return is vegetation.
    """
    quantile = real(quantile, "quantile", low=0.0, high=1.0)
    heights = heights_above_ground(las) if heights_m is None else np.asarray(heights_m, np.float64)
    if heights.shape != (len(las),):
        raise InvalidInputError(f"canopy_height: heights_m must have shape ({len(las)},), got {heights.shape}")
    tops = cell_tops(las, classes=classes, cell_m=cell_m, min_pulses=min_pulses)
    canopy = tops.counted & tops.vegetation
    if not canopy.any():
        raise InvalidInputError(
            f"canopy_height: no cell of {tops.cell_m:g} m holds {tops.min_pulses} pulses and a highest return on vegetation"
        )
    return float(np.quantile(heights[tops.highest[canopy]], quantile))


def plot_canopy_height(scene: ScanScene, center_xy, half_size_m: float, vegetation_ids: Sequence[int], *, cell_m: float = TREE_COVER_CELL_M,
                       rays_per_cell: int, quantile: float = CANOPY_QUANTILE, seed: int = 0) -> float:  # fmt: skip
    """:func:`canopy_height` of a plot of meshes, from vertical rays (:func:`~.tree_cover.vertical_tops`).

    The cells whose highest hit is vegetation (``vegetation_ids``), that hit's height above the
    scene's ground (:attr:`~zbuf_occlude.sensors.scene.objects.ScanScene.ground_z_m`); its ``quantile``.

    Returns
    -------
    float
        Metres.

    Raises
    ------
    InvalidInputError
        As :func:`~.tree_cover.vertical_tops`, a bad quantile, or no cell whose highest hit is vegetation.
    """
    quantile = real(quantile, "quantile", low=0.0, high=1.0)
    first, z = vertical_tops(scene, center_xy, half_size_m, cell_m=cell_m, rays_per_cell=rays_per_cell, seed=seed)
    canopy = np.isin(first, np.asarray(vegetation_ids, np.int64))
    if not canopy.any():
        raise InvalidInputError("plot_canopy_height: no cell's highest hit is vegetation")
    return float(np.quantile(z[canopy] - scene.ground_z_m, quantile))
