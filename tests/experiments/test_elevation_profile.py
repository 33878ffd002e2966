"""Values of the Fig. 12 elevation profile (zbuf_occlude.experiments.elevation_profile) against analytic areas.

An axis-aligned box of sides (1, 0.6, 0.3) has faces of three different areas, one per
projection plane, so a swapped plane or an ignored elevation changes the numbers.  A
convex box seen from outside shows exactly its front-facing faces, and a face of normal
``±e_k`` projects onto the plane perpendicular to ``e_k`` with its full area and onto the
other two with none, so the projected visible areas are sums of front-facing face areas.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from zbuf_occlude.experiments import elevation_profile as prof
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS

SIDES = np.array([1.0, 0.6, 0.3])  # x, y, z extents: the maximum extent is 1 (normalised)
#: plane name -> axis of its normal (x-y plane ⟂ z, y-z plane ⟂ x, x-z plane ⟂ y)
NORMAL_AXIS = {"xy": 2, "yz": 0, "xz": 1}


@pytest.fixture(scope="module")
def box():
    return trimesh.creation.box(extents=SIDES)


def eye_at(el_deg: float, az_deg: float, radius: float = DEFAULT_RADIUS) -> np.ndarray:
    """The camera centre of the documented pose convention (z up, az from +x towards +y)."""
    el, az = math.radians(el_deg), math.radians(az_deg)
    return radius * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


def analytic_areas(eye: np.ndarray) -> dict[str, float]:
    """Projected visible areas of the box: its faces of normal ±e_k facing ``eye``."""
    out = dict.fromkeys([*NORMAL_AXIS, "visible"], 0.0)
    for plane, k in NORMAL_AXIS.items():
        others = [i for i in range(3) if i != k]
        face_area = float(SIDES[others[0]] * SIDES[others[1]])
        # the faces x_k = ±SIDES[k]/2 face the eye iff the eye lies beyond their plane
        facing = int(eye[k] > SIDES[k] / 2) + int(eye[k] < -SIDES[k] / 2)
        out[plane] += facing * face_area
        out["visible"] += facing * face_area
    return out


def test_projected_areas_per_plane_with_stratified_samples(box):
    """Samples in exact proportion to face area make the estimate exact: each face of normal
    ±e_k projects its whole area onto one plane (xy for ±z, yz for ±x, xz for ±y)."""
    areas = box.area_faces
    counts = np.rint(areas / 0.03).astype(int)  # triangle areas 0.09, 0.15, 0.3: 3, 5, 10 samples
    assert np.allclose(counts / counts.sum(), areas / areas.sum())
    face_index = np.repeat(np.arange(len(areas)), counts)
    normals = box.face_normals
    for k, plane in ((0, "yz"), (1, "xz"), (2, "xy")):
        for sign in (1.0, -1.0):
            visible = np.isclose(normals[face_index, k], sign)  # one face of the box
            got = prof.projected_areas(box, face_index, visible)
            side = float(np.prod(np.delete(SIDES, k)))
            assert got[plane] == pytest.approx(side, rel=1e-12)
            assert got["visible"] == pytest.approx(side, rel=1e-12)
            for other in set(NORMAL_AXIS) - {plane}:
                assert got[other] == pytest.approx(0.0, abs=1e-12)
    everything = prof.projected_areas(box, face_index, np.ones(len(face_index), dtype=bool))
    assert everything["xy"] == pytest.approx(2 * 1.0 * 0.6)
    assert everything["yz"] == pytest.approx(2 * 0.6 * 0.3)
    assert everything["xz"] == pytest.approx(2 * 1.0 * 0.3)
    assert everything["visible"] == pytest.approx(box.area)


def test_the_profile_follows_the_analytic_curves(box):
    """profile_table (exact oracle) vs the analytic front-facing areas, per elevation
    averaged over azimuths, within 4 binomial standard deviations of the Monte Carlo."""
    elevations = (-60.0, -20.0, 0.0, 30.0, 75.0)
    n_az, n = 8, 20_000
    rows = prof.profile_table(box, method="oracle", points=n, elevations=elevations, azimuths=n_az, progress=False)
    assert [r["elevation_deg"] for r in rows] == list(elevations)
    total = float(box.area)
    for row in rows:
        el = row["elevation_deg"]
        per_az = [analytic_areas(eye_at(el, k * 360.0 / n_az)) for k in range(n_az)]
        for key in (*NORMAL_AXIS, "visible"):
            expected = float(np.mean([a[key] for a in per_az]))
            p = min(max(expected / total, 1e-3), 1 - 1e-3)
            sigma = total * math.sqrt(p * (1 - p) / n)
            assert row[f"area_{key}"] == pytest.approx(expected, abs=4 * sigma + 1e-9), (el, key)
            spread = float(np.std([a[key] for a in per_az]))
            assert row[f"area_{key}_std"] == pytest.approx(spread, abs=4 * sigma + 1e-9), (el, key)
        assert row["surface_area"] == pytest.approx(total)
    # The curves' shape: the top (x-y) area is zero at the horizon and 1 x 0.6 above and below.
    by_el = {r["elevation_deg"]: r for r in rows}
    assert by_el[0.0]["area_xy"] == 0.0
    assert by_el[75.0]["area_xy"] == pytest.approx(0.6, rel=0.03)
    assert by_el[-60.0]["area_xy"] == pytest.approx(0.6, rel=0.03)


def test_the_analytic_reference_itself():
    """From +x at the horizon only the +x face (0.6 x 0.3) shows, on the y-z plane."""
    assert analytic_areas(eye_at(0.0, 0.0)) == {"xy": 0.0, "yz": pytest.approx(0.18), "xz": 0.0, "visible": pytest.approx(0.18)}
    top = analytic_areas(eye_at(90.0, 0.0))
    assert top["xy"] == pytest.approx(0.6) and top["yz"] == 0.0 and top["xz"] == 0.0
