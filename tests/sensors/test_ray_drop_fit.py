"""Ray drop on crowns fitted from scans: ``fit_foliage_dropout`` inverts what ``Beam.foliage_dropout`` does.

The algebra is checked exactly (a hypothesis law), and end to end: boxes of class "bush" and "car" scanned by an
HDL-32E with a known ray drop on crowns stand for the real scans, the same boxes scanned without it for the meshes."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors import Lidar, scan, with_beam
from zbuf_occlude.sensors.fit import Estimate, dropout_by_surface, fit_foliage_dropout, is_crown_class
from zbuf_occlude.sensors.fit.ray_drop import CROWN, SOLID
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject

PLACES = [(6.0, 0.0), (8.0, 20.0), (10.0, -15.0), (12.0, 5.0), (9.0, -30.0)]


def _rates(crown: float, solid: float, sd: float = 0.01) -> dict[str, Estimate]:
    return {CROWN: Estimate(crown, sd, 1000, "dropout"), SOLID: Estimate(solid, sd, 1000, "dropout")}


def test_crown_classes_are_those_of_a_crown_material() -> None:
    assert all(is_crown_class(c) for c in ("bush", "Bush", "tree", "Tree_1", "hedge", "shrub", "pine_tree"))
    assert not any(is_crown_class(c) for c in ("car", "pedestrian", "pole", "building", "", "grown_leaf"))


@settings(max_examples=50, deadline=None)
@given(f=st.floats(0.0, 0.9), shared=st.floats(0.0, 0.3), solid_sim=st.floats(0.0, 0.3), crown_sim=st.floats(0.0, 0.3))
def test_the_fit_gives_back_the_ray_drop_that_made_the_contrast(f: float, shared: float, solid_sim: float, crown_sim: float) -> None:
    # the real scans lose what the meshes lose and a share more that both classes lose (the sensor's dropout); crowns 1 - f more
    solid_real = 1.0 - (1.0 - solid_sim) * (1.0 - shared)
    crown_real = 1.0 - (1.0 - crown_sim) * (1.0 - shared) * (1.0 - f)
    got = fit_foliage_dropout(_rates(crown_real, solid_real), _rates(crown_sim, solid_sim))
    assert got.value == pytest.approx(f, abs=1e-9) and got.set_in_sensor and got.std > 0


def test_crowns_that_lose_no_more_than_the_meshes_give_none_and_bad_rates_are_refused() -> None:
    assert fit_foliage_dropout(_rates(0.05, 0.05), _rates(0.10, 0.0)).value == 0.0
    # the deviation: relative errors in quadrature, here four equal ones of 0.01 / 0.9 on a ratio of 1
    e = fit_foliage_dropout(_rates(0.1, 0.1), _rates(0.1, 0.1))
    assert e.value == pytest.approx(0.0, abs=1e-12) and e.std == pytest.approx(2 * 0.01 / 0.9)
    for real in ({CROWN: Estimate(0.1, 0.01, 9, "")}, _rates(1.0, 0.1), _rates(math.nan, 0.1)):
        with pytest.raises(InvalidInputError, match="ray drop"):
            fit_foliage_dropout(real, _rates(0.0, 0.0))


def _clouds(sensor: Lidar, seed: int) -> tuple[list[np.ndarray], list[str]]:
    """A bush-sized box and a car-sized box at each place, scanned one at a time in the sensor frame."""
    clouds, labels = [], []
    for i, (distance, yaw) in enumerate(PLACES):
        for label, extents in (("bush", (1.5, 1.5, 1.5)), ("car", (4.0, 1.8, 1.5))):
            box = trimesh.creation.box(extents=extents)
            box.apply_transform(trimesh.transformations.rotation_matrix(np.radians(yaw), (0, 0, 1)))
            obj = SceneObject(box, class_name=label, position_m=(distance, 0.0), size_m=max(extents))
            s = scan(ScanScene(objects=[obj], ground=False), sensor, seed=seed + i, azimuth_range_deg=(-40.0, 40.0))
            clouds.append(np.asarray(s.points, dtype=np.float64))
            labels.append(label)
    return clouds, labels


def test_scans_with_a_known_ray_drop_give_it_back() -> None:
    hdl32e = Lidar.preset("hdl32e")
    truth = 0.2
    real = dropout_by_surface(*_clouds(with_beam(hdl32e, dropout=0.03, foliage_dropout=truth), 0), hdl32e, bootstrap=20)
    sim = dropout_by_surface(*_clouds(hdl32e, 1000), hdl32e, bootstrap=20)
    assert real[CROWN].value > real[SOLID].value + 0.1  # the crowns lose more
    fit = fit_foliage_dropout(real, sim)
    assert fit.value == pytest.approx(truth, abs=max(0.03, 4 * fit.std))
    with pytest.raises(InvalidInputError, match="no scan of a crown class"):
        dropout_by_surface(*_clouds(hdl32e, 0)[:1], ["car"] * 10, hdl32e)
    with pytest.raises(InvalidInputError, match="10 scans but 3 labels"):
        dropout_by_surface(_clouds(hdl32e, 0)[0], ["car"] * 3, hdl32e)
