"""Canopy height and classes by height (experiments/canopy.py), and tree cover in a file's own unit: tiny synthetic scans, no ../shared data."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.canopy import canopy_height, classes_by_height, heights_above_ground, plot_canopy_height
from zbuf_occlude.experiments.returns import plot_scene
from zbuf_occlude.experiments.tree_cover import cell_tops, tree_cover, vertical_tops
from zbuf_occlude.io.las import LasPoints

FOOT_M = 0.3048


def _las(points, classes, *, returns=None, unit_m: float = float("nan")) -> LasPoints:
    points = np.asarray(points, np.float64)
    n = len(points)
    numbers = np.ones(n) if returns is None else np.asarray(returns)
    return LasPoints(points=points, intensity=np.ones(n), return_number=numbers, number_of_returns=np.maximum(numbers, 1),
                     gps_time=np.arange(n, dtype=np.float64), scan_angle_deg=np.zeros(n), classification=classes,
                     point_source_id=np.zeros(n), scanner_channel=np.zeros(n), linear_unit_m=unit_m)  # fmt: skip


def _cells(tops_m, *, cell_m: float = 2.0, pulses: int = 6, top_class: int = 5, ground_z: float = 10.0, unit_m: float = 1.0) -> LasPoints:
    """One row of ``cell_m`` cells: per cell ``pulses`` ground first returns at ``ground_z`` and, where
    ``tops_m[i]`` is not None, a second return of ``top_class`` that high above it (coordinates in units of ``unit_m``)."""
    points, classes, numbers = [], [], []
    for i, top in enumerate(tops_m):
        x = (i + 0.5) * cell_m
        for j in range(pulses):
            points.append((x + 0.05 * j - 0.15, cell_m / 2 + 0.05 * (j % 3), ground_z))
            classes.append(2)
            numbers.append(1)
        if top is not None:
            points.append((x, cell_m / 2, ground_z + top))
            classes.append(top_class)
            numbers.append(2)
    return _las(np.array(points) / unit_m, classes, returns=numbers, unit_m=unit_m)


def test_heights_are_above_the_nearest_ground_in_metres_whatever_the_files_unit() -> None:
    gx, gy = np.meshgrid(np.arange(10.0), np.arange(10.0))
    ground = np.column_stack([gx.ravel(), gy.ravel(), np.full(100, 50.0)])
    above = np.array([[4.5, 4.5, 53.0], [2.2, 7.1, 50.5], [8.0, 1.0, 49.0]])
    points = np.vstack([ground, above])
    classes = [2] * 100 + [1, 5, 1]
    expected = np.r_[np.zeros(100), 3.0, 0.5, -1.0]
    assert heights_above_ground(_las(points, classes)) == pytest.approx(expected, abs=1e-12)
    # the same ground and points stored in international feet: heights in metres
    assert heights_above_ground(_las(points / FOOT_M, classes, unit_m=FOOT_M)) == pytest.approx(expected, abs=1e-9)


def test_heights_follow_a_sloping_ground() -> None:
    gx, gy = np.meshgrid(np.arange(0.0, 20.0, 0.5), np.arange(0.0, 20.0, 0.5))
    ground = np.column_stack([gx.ravel(), gy.ravel(), 0.2 * gx.ravel()])
    tree = np.array([[10.1, 10.1, 0.2 * 10.1 + 12.0]])
    h = heights_above_ground(_las(np.vstack([ground, tree]), [2] * len(ground) + [5]))
    assert h[-1] == pytest.approx(12.0, abs=0.05)  # the 8 nearest ground points' median, 0.2 m/m of slope over their spread


def test_heights_need_enough_ground() -> None:
    with pytest.raises(InvalidInputError, match="3 ground points .* 8 needed"):
        heights_above_ground(_las([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]], [2, 2, 2, 1]))
    with pytest.raises(InvalidInputError, match="neighbours"):
        heights_above_ground(_las([[0, 0, 0]], [2]), neighbours=0)


def test_class_one_is_classed_by_the_vegetation_bounds_and_ground_level_is_ground() -> None:
    heights = np.array([-0.3, 0.1, 0.49, 0.5, 1.49, 1.5, 20.0, 20.0, 0.2])
    las = _las(np.zeros((9, 3)), [1, 1, 1, 1, 1, 1, 1, 6, 2])
    classed = classes_by_height(las, heights)
    assert classed.classification.tolist() == [2, 2, 2, 4, 4, 5, 5, 6, 2]  # a building (6) and the ground kept
    assert las.classification.tolist() == [1, 1, 1, 1, 1, 1, 1, 6, 2]  # the input is not changed
    assert classes_by_height(las, heights, source_class=6).classification.tolist() == [1, 1, 1, 1, 1, 1, 1, 5, 2]


def test_classes_by_height_refuses_bad_heights() -> None:
    las = _las(np.zeros((3, 3)), [1, 2, 1])
    with pytest.raises(InvalidInputError, match=r"shape \(3,\)"):
        classes_by_height(las, np.zeros(2))
    with pytest.raises(InvalidInputError, match="NaN"):
        classes_by_height(las, [0.0, 1.0, np.nan])
    assert classes_by_height(las, [0.0, np.nan, 2.0]).classification.tolist() == [2, 2, 5]  # NaN where nothing is classed


def test_canopy_height_is_a_quantile_of_the_vegetation_cells_tops() -> None:
    las = _cells([2.0, 4.0, 6.0, 8.0, None])
    assert canopy_height(las, cell_m=2.0, quantile=0.5) == pytest.approx(5.0)
    assert canopy_height(las, cell_m=2.0, quantile=1.0) == pytest.approx(8.0)
    assert canopy_height(las, cell_m=2.0, quantile=0.0) == pytest.approx(2.0)
    # cells too sparse are left out, as tree_cover leaves them
    assert canopy_height(_cells([2.0, 9.0], pulses=4), cell_m=2.0, min_pulses=4, quantile=1.0) == pytest.approx(9.0)
    with pytest.raises(InvalidInputError, match="no cell of 2 m holds 5 pulses"):
        canopy_height(_cells([2.0, 9.0], pulses=4), cell_m=2.0)
    # a cell topped by a building is not canopy
    with pytest.raises(InvalidInputError, match="highest return on vegetation"):
        canopy_height(_cells([7.0, None], top_class=6), cell_m=2.0)
    with pytest.raises(InvalidInputError, match="quantile"):
        canopy_height(las, quantile=1.5)


def test_canopy_height_and_cover_cut_cells_in_metres_in_a_file_in_feet() -> None:
    tops = [3.0, None, 7.0, None, 11.0]
    metres, feet = _cells(tops), _cells(tops, unit_m=FOOT_M)
    assert canopy_height(feet, cell_m=2.0, quantile=0.5) == pytest.approx(canopy_height(metres, cell_m=2.0, quantile=0.5)) == 7.0
    assert tree_cover(feet, cell_m=2.0, bootstrap=10).value == tree_cover(metres, cell_m=2.0, bootstrap=10).value == 3 / 5
    # five cells 2 m wide, not 2 feet wide (which would split each cell in three)
    assert len(cell_tops(feet, cell_m=2.0).highest) == 5


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(0.5, 40.0), min_size=1, max_size=8), st.floats(0.0, 1.0), st.floats(0.2, 5.0))
def test_canopy_height_scales_with_the_stand(tops, quantile, factor) -> None:
    """Law: a stand scaled in height by ``factor`` has its canopy height scaled by ``factor``."""
    las = _cells([*tops, None])  # an open cell: ground enough for the ground model
    assert canopy_height(_cells([*(t * factor for t in tops), None]), cell_m=2.0, quantile=quantile) == pytest.approx(
        factor * canopy_height(las, cell_m=2.0, quantile=quantile), rel=1e-9, abs=1e-9
    )


def test_the_plots_canopy_height_is_its_meshes_tops() -> None:
    low, tall = trimesh.creation.box(extents=(2.0, 2.0, 3.0)), trimesh.creation.box(extents=(3.0, 3.0, 6.0))
    scene, vegetation = plot_scene([low, tall], [3.0, 6.0], spacing_m=8.0, seed=0)
    half = 8.0
    assert plot_canopy_height(scene, (0.0, 0.0), half, vegetation, cell_m=1.0, rays_per_cell=4, quantile=1.0) == pytest.approx(6.0)
    assert plot_canopy_height(scene, (0.0, 0.0), half, vegetation, cell_m=1.0, rays_per_cell=4, quantile=0.0) == pytest.approx(3.0)
    first, z = vertical_tops(scene, (0.0, 0.0), half, cell_m=1.0, rays_per_cell=4)
    assert set(np.unique(first).tolist()) <= {0, 1, 2} and np.all(z[first == 0] == pytest.approx(0.0))
    with pytest.raises(InvalidInputError, match="no cell's highest hit is vegetation"):
        plot_canopy_height(scene, (500.0, 500.0), 2.0, vegetation, cell_m=1.0, rays_per_cell=1)
