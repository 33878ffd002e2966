"""All hits along each sub-ray: :func:`~zbuf_occlude.sensors.raycast.embree.cast_embree_beyond` and
``scan(transmittance=...)``, the multi-return model through surfaces that let part of a pulse on.

Analytic scenes: parallel plates facing the sensor along +x, so every hit's range and energy is
known in closed form.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

import zbuf_occlude.sensors as S
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.beam.footprint import footprint_offsets, subray_directions
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.raycast.embree import cast_embree, cast_embree_beyond
from zbuf_occlude.sensors.scene.objects import BuiltScene, SceneObject

R = 10.0  # near plate, metres
DIVERGENCE = 2.0  # degrees: a 0.35 m footprint at 10 m


def _plate(x: float, y_max: float = 5.0) -> trimesh.Trimesh:
    """The rectangle x = ``x``, -5 <= y <= ``y_max``, |z| <= 5 (two triangles, normal along x)."""
    v = np.array([[x, -5.0, -5.0], [x, y_max, -5.0], [x, y_max, 5.0], [x, -5.0, 5.0]], dtype=np.float64)
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


def _stack(xs, y_max=None) -> BuiltScene:
    """Plates at x = ``xs`` (object ids 1, 2, ...), each over y <= ``y_max[i]`` (default: everywhere)."""
    plates = [_plate(x, 5.0 if y_max is None else y_max[i]) for i, x in enumerate(xs)]
    n = len(plates)
    return BuiltScene(trimesh.util.concatenate(plates), np.repeat(np.arange(1, n + 1), 2).astype(np.int32), np.tile([0, 1], n),
                      [SceneObject(p) for p in plates], [np.eye(4)] * (n + 1), [None, *plates])  # fmt: skip


def _lidar(elevations_deg=(0.0,), **beam_changes) -> S.Lidar:
    beam = {"min_range_m": 0.1, "max_range_m": 1000.0, "divergence_deg": DIVERGENCE, "footprint_rays": 7, "max_returns": 3,
            "range_resolution_m": 0.5}  # fmt: skip
    return S.Lidar("plates", elevations_deg, rotation_hz=10.0, firing_rate_hz=3600.0, beam=Beam(**(beam | beam_changes)))


def _one_pulse(built, lidar, **kw) -> S.Scan:
    return S.scan(built, lidar, np.zeros(3), azimuth_range_deg=(-0.5, 0.5), **kw)  # the firing at azimuth 0 only


def _cast_all(built, directions, transmits, **kw):
    face, t = cast_embree(built.mesh, np.zeros(3), directions)
    return face, t, cast_embree_beyond(built.mesh, np.zeros(3), directions, face, t, transmits, **kw)


# -- cast_embree_beyond ------------------------------------------------------------------------


def test_rays_go_on_through_transmitting_faces_and_stop_at_the_first_opaque_one():
    built = _stack([R, R + 1.0, R + 2.5])
    d = subray_directions([[1.0, 0.0, 0.0]], footprint_offsets(7, DIVERGENCE)[0])[0]
    through_two = np.isin(built.face_object, [1, 2])  # plates 1 and 2 transmit, 3 does not
    face, t, (ray, f, r) = _cast_all(built, d, through_two)
    assert ray.tolist() == np.repeat(np.arange(7), 3).tolist()
    np.testing.assert_array_equal(built.face_object[f], np.tile([1, 2, 3], 7))
    want = np.array([R, R + 1.0, R + 2.5])[None, :] / d[:, :1]  # the plane x = const along each ray
    np.testing.assert_allclose(r.reshape(7, 3), want, rtol=1e-12)
    # the first hits are the given ones, bit for bit
    np.testing.assert_array_equal(f[::3], face)
    np.testing.assert_array_equal(r[::3], t)
    # plate 2 opaque: two hits per ray; max_hits 2: two hits too; plate 1 opaque: the first hits only
    assert len(_cast_all(built, d, built.face_object == 1)[2][0]) == 14
    assert len(_cast_all(built, d, through_two, max_hits=2)[2][0]) == 14
    ray, f, r = _cast_all(built, d, np.zeros(len(built.face_object), bool))[2]
    np.testing.assert_array_equal(ray, np.arange(7))
    np.testing.assert_array_equal(r, t)


def test_a_ray_through_a_shared_edge_or_a_closed_box_meets_each_surface_once():
    # the diagonal of each plate is the edge its two triangles share: one hit per plate, not two
    built = _stack([R, R + 1.0])
    d = np.array([[1.0, 0.0, 0.0], [R, 3.0, 3.0]])  # (R, 3, 3) lies on the diagonal y = z of the near plate
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ray, f, r = _cast_all(built, d, np.ones(4, bool))[2]
    assert ray.tolist() == [0, 0, 1, 1]
    np.testing.assert_array_equal(built.face_object[f], [1, 2, 1, 2])
    # a closed box: in at its front face, out at its back face
    box = trimesh.creation.box(extents=[2.0, 2.0, 2.0])
    box.apply_translation([R + 1.0, 0.0, 0.0])
    one = BuiltScene(box, np.ones(len(box.faces), np.int32), np.arange(len(box.faces)), [SceneObject(box)], [np.eye(4)] * 2, [None, box])
    ray, f, r = _cast_all(one, np.array([[1.0, 0.0, 0.0]]), np.ones(len(box.faces), bool))[2]
    np.testing.assert_allclose(r, [R, R + 2.0], rtol=1e-12)


def test_cast_embree_beyond_checks_its_arguments():
    built = _stack([R])
    d = np.array([[1.0, 0.0, 0.0]])
    face, t = cast_embree(built.mesh, np.zeros(3), d)
    with pytest.raises(InvalidInputError, match="face_transmits"):
        cast_embree_beyond(built.mesh, np.zeros(3), d, face, t, np.ones(3, bool))
    with pytest.raises(InvalidInputError, match="max_hits"):
        cast_embree_beyond(built.mesh, np.zeros(3), d, face, t, np.ones(2, bool), max_hits=0)
    with pytest.raises(InvalidInputError, match="step_m"):
        cast_embree_beyond(built.mesh, np.zeros(3), d, face, t, np.ones(2, bool), step_m=-1.0)


def test_the_memory_for_the_hits_is_checked_before_the_rounds():
    from zbuf_occlude.errors import InsufficientMemoryError

    built = _stack([R, R + 1.0])
    d = np.array([[1.0, 0.0, 0.0]] * 4)
    face, t = cast_embree(built.mesh, np.zeros(3), d)
    with pytest.raises(InsufficientMemoryError, match="4 transmitting rays x max_hits"):
        cast_embree_beyond(built.mesh, np.zeros(3), d, face, t, np.ones(4, bool), max_hits=10**15)


def test_echo_returns_casts_on_from_each_rays_own_origin():
    # an airborne-like pulse: one origin per sub-ray (the aircraft moves), plates below along -z
    from zbuf_occlude.sensors.beam.echo_energy import Transmission, echo_returns

    built = _stack([R, R + 2.0])
    origins = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.5]])
    d = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    face = np.empty(2, np.int64)
    t = np.empty(2)
    for i in range(2):
        face[i : i + 1], t[i : i + 1] = cast_embree(built.mesh, origins[i], d[i : i + 1])
    through = Transmission(np.array([0.0, 0.5, 0.0])[built.face_object], origins)  # per face: object 1 transmits half
    beam = Beam(max_returns=3, range_resolution_m=0.5)  # one ray a pulse, no range limits
    pulse, f, r, e = echo_returns(built, d, face, t, beam, max_returns=3, through=through)
    assert pulse.tolist() == [0, 0, 1, 1] and built.face_object[f].tolist() == [1, 2, 1, 2]
    np.testing.assert_allclose(r, [R, R + 2.0, R, R + 2.0], rtol=1e-12)
    np.testing.assert_allclose(e, [1 / R**2, 0.5 / (R + 2.0) ** 2] * 2, rtol=1e-12)
    with pytest.raises(InvalidInputError, match="transmittance must hold one value per face of the scene"):
        echo_returns(built, d, face, t, beam, max_returns=3, through=Transmission([0.5, 0.5], origins))


# -- scan(transmittance=...) ------------------------------------------------------------------


def _subray_energy(x_m: float, k: int = 7):
    """Per sub-ray of the pulse along +x: range to the plane x = ``x_m`` and energy (ρ = 1, top hat)."""
    d = subray_directions([[1.0, 0.0, 0.0]], footprint_offsets(k, DIVERGENCE)[0])[0]
    r = x_m / d[:, 0]
    return r, d[:, 0] / k / r**2


def test_a_half_transmitting_plate_gives_a_second_return_from_the_plate_behind_it():
    built = _stack([R, R + 2.0])  # both plates cover the whole footprint
    lidar = _lidar()
    assert len(_one_pulse(built, lidar)) == 1  # opaque: the near plate only
    s = _one_pulse(built, lidar, transmittance=[0.0, 0.5, 0.0])
    assert s.object_id.tolist() == [1, 2]
    assert s.return_number.tolist() == [1, 2] and s.number_of_returns.tolist() == [2, 2]
    (r1, e1), (r2, e2) = _subray_energy(R), _subray_energy(R + 2.0)
    np.testing.assert_allclose(s.range_m, [np.average(r1, weights=e1), np.average(r2, weights=e2)], rtol=1e-6)
    # the far plate's echo: its energy times the near plate's transmittance
    np.testing.assert_allclose(s.intensity, [e1.sum(), 0.5 * e2.sum()], rtol=1e-6)
    # a third plate behind an opaque second one gives nothing; behind a transmitting one, a third return
    three = _stack([R, R + 2.0, R + 4.0])
    assert len(_one_pulse(three, lidar, transmittance=[0.0, 0.5, 0.0, 0.0])) == 2
    s3 = _one_pulse(three, lidar, transmittance=[0.0, 0.5, 0.5, 0.0])
    _, e3 = _subray_energy(R + 4.0)
    np.testing.assert_allclose(s3.intensity, [e1.sum(), 0.5 * e2.sum(), 0.25 * e3.sum()], rtol=1e-6)


def test_the_threshold_drops_a_hit_dimmed_by_the_surface_before_it():
    built = _stack([R, R + 2.0])
    _, e2 = _subray_energy(R + 2.0)
    tau = np.sqrt(0.5 * e2.sum() * 0.1 * e2.sum())  # between the far echo through 0.5 and through 0.1
    lidar = _lidar(detection_threshold=float(tau))
    assert len(_one_pulse(built, lidar, reflectivity=1.0, transmittance=[0.0, 0.5, 0.0])) == 2
    assert len(_one_pulse(built, lidar, reflectivity=1.0, transmittance=[0.0, 0.1, 0.0])) == 1


def test_opaque_transmittance_gives_the_first_hits_bit_for_bit():
    scene = S.ScanScene()
    scene.add({"box_m": [1.0, 2.0, 1.5]}, class_name="car", position_m=(8.0, 0.5), yaw_deg=20.0)
    scene.add({"cylinder": {"radius_m": 0.1, "height_m": 3.0}}, class_name="pole", position_m=(6.0, -0.3))
    lidar = with_beam(S.Lidar.preset("vlp16"), footprint_rays=7, divergence_deg=0.3, max_returns=3, range_resolution_m=0.5)
    base = S.scan(scene, lidar, seed=3, azimuth_range_deg=(-30, 30))
    for tau in (0.0, [0.0, 0.0, 0.0]):
        other = S.scan(scene, lidar, seed=3, azimuth_range_deg=(-30, 30), transmittance=tau)
        for key, value in base.arrays().items():
            np.testing.assert_array_equal(other.arrays()[key], value, err_msg=key)
    # and the pole let through: more returns, the first ones unchanged where nothing transmits
    through = S.scan(scene, lidar, seed=3, azimuth_range_deg=(-30, 30), transmittance=[0.0, 0.0, 0.5])
    assert len(through) > len(base)


def test_transmittance_is_refused_where_it_cannot_apply():
    built = _stack([R, R + 2.0])
    with pytest.raises(InvalidInputError, match="zbuffer"):
        _one_pulse(built, _lidar(), transmittance=0.5, backend="zbuffer")
    with pytest.raises(InvalidInputError, match="max_returns above 1"):
        _one_pulse(built, _lidar(max_returns=1, footprint_rays=1), transmittance=0.5)
    for bad in (1.5, -0.1, float("nan"), [0.5, 0.5], "opaque"):
        with pytest.raises(InvalidInputError, match="transmittance"):
            _one_pulse(built, _lidar(), transmittance=bad)


@settings(max_examples=25, deadline=None)
@given(
    gaps=st.lists(st.floats(0.1, 3.0), min_size=1, max_size=4),
    tau=st.lists(st.sampled_from([0.0, 0.2, 0.5, 0.9]), min_size=4, max_size=4),
    k=st.sampled_from([1, 7, 19]),
    max_returns=st.integers(2, 5),
    resolution=st.sampled_from([0.05, 0.5, 1.5]),
)
def test_returns_are_numbered_one_to_n_within_each_pulse_through_transmitting_plates(gaps, tau, k, max_returns, resolution):
    xs = R + np.concatenate([[0.0], np.cumsum(gaps)])[: len(gaps)]
    # half-covering plates, alternating sides, so pulses see different stacks
    built = _stack(list(xs), y_max=[(-0.5 if i % 2 else 0.5) for i in range(len(xs))])
    lidar = _lidar(footprint_rays=k, max_returns=max_returns, range_resolution_m=resolution, divergence_deg=0.0 if k == 1 else DIVERGENCE,
                   elevations_deg=(-3.0, 0.0, 2.0))  # fmt: skip
    s = S.scan(built, lidar, np.zeros(3), azimuth_range_deg=(-8, 8), transmittance=[0.0, *tau[: len(xs)]])
    for pid in np.unique(s.pulse_id):
        mine = s.pulse_id == pid
        n = s.number_of_returns[mine]
        assert np.all(n == n[0]) and n[0] <= max_returns
        assert s.return_number[mine].tolist() == list(range(1, int(mine.sum()) + 1))
        assert np.all(np.diff(s.range_m[mine]) > 0)
