"""Adaptive footprints: the plane's sub-rays without casting them, which pulses need no cast, and the
echoes against the full multi-return model (:mod:`zbuf_occlude.sensors.beam.adaptive_cast`)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors import Lidar, ScanScene, scan, with_beam
from zbuf_occlude.sensors.beam import adaptive_cast as A
from zbuf_occlude.sensors.patterns.airborne_presets import airborne_preset
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.beam.echo_energy import Radiometry, echo_returns
from zbuf_occlude.sensors.beam.echoes import hit_energy, resolve_echoes
from zbuf_occlude.sensors.beam.footprint import footprint_offsets, plane_subrays, subray_directions
from zbuf_occlude.sensors.raycast.embree import cast_embree
from zbuf_occlude.sensors.scan import build_scene

TABLE = Path(__file__).resolve().parents[2] / "data" / "samples" / "table" / "test" / "table_0393.off"
RESOLUTION = 0.75


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 40), st.sampled_from([7, 19, 37]), st.floats(0.01, 5.0))
def test_plane_subrays_are_the_sub_rays_meeting_the_plane(seed, n, k, divergence_deg) -> None:
    rng = np.random.default_rng(seed)
    d = _unit(rng.normal(size=(n, 3)))
    normal = _unit(rng.normal(size=(n, 3)))
    normal[np.abs(np.einsum("ij,ij->i", normal, d)) < 0.2] = d[np.abs(np.einsum("ij,ij->i", normal, d)) < 0.2]  # not grazing
    t = rng.uniform(1.0, 100.0, n)
    offsets = footprint_offsets(k, divergence_deg)[0]
    tk, cos = plane_subrays(t, d, normal, offsets)
    # the same sub-rays cast at the plane through the centre hit: t_k = n · (t d) / (n · d_k)
    rays = subray_directions(d, offsets)
    ndk = np.einsum("nj,nkj->nk", normal, rays)
    expected = np.einsum("nj,nj->n", normal, d * t[:, None])[:, None] / ndk
    assert np.allclose(tk, expected, rtol=1e-12, atol=0) and np.allclose(cos, np.abs(ndk), rtol=1e-12, atol=1e-15)
    assert np.array_equal(tk[:, 0], t)  # the centre ray: its own range, bit for bit


def test_plane_subrays_refuses_rows_of_other_lengths() -> None:
    with pytest.raises(InvalidInputError, match="one row per beam"):
        plane_subrays(np.ones(2), np.eye(3), np.eye(3), footprint_offsets(7, 0.2)[0])


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([7, 19]), st.floats(0.05, 3.0), st.sampled_from(["tophat", "gaussian"]))
def test_a_plane_echo_is_what_the_receiver_makes_of_the_sub_rays_hits(seed, k, divergence_deg, profile) -> None:
    rng = np.random.default_rng(seed)
    n = 20
    d = _unit(rng.normal(size=(n, 3)))
    normal = _unit(d + 0.5 * rng.normal(size=(n, 3)))
    t = rng.uniform(2.0, 60.0, n)
    rho = rng.uniform(0.05, 1.0, n)
    offsets, weights = footprint_offsets(k, divergence_deg, profile=profile)
    tk, cos = plane_subrays(t, d, normal, offsets)
    keep = (tk > 0).all(axis=1)
    tk, cos, rho = tk[keep], cos[keep], rho[keep]
    echo_range, energy = A.plane_echoes(tk, cos, weights, rho)
    # the same hits through hit_energy and resolve_echoes, with a resolution that merges them all
    pulse = np.repeat(np.arange(len(tk)), k)
    e = hit_energy(np.tile(weights, len(tk)), np.repeat(rho, k), cos.reshape(-1), tk.reshape(-1))
    echoes = resolve_echoes(pulse, tk.reshape(-1), e, np.zeros(len(pulse), np.int64), range_resolution_m=1e6, detection_threshold=0.0,
                            max_returns=1)  # fmt: skip
    assert np.array_equal(echoes.pulse, np.arange(len(tk)))
    assert np.allclose(echo_range, echoes.range_m, rtol=1e-12) and np.allclose(energy, echoes.energy, rtol=1e-12)


def test_grid_neighbours_on_a_small_grid() -> None:
    # two lines of three pulses (given out of order); the second a full turn: it wraps around
    position = np.array([0.0, 1.0, 2.0, 0.1, 2.1, 1.1])
    line = np.array([0, 0, 0, 1, 1, 1])
    out = A.grid_neighbours(position, line)
    assert out.tolist() == [[-1, 1, -1, 3], [0, 2, -1, 5], [1, -1, -1, 4], [-1, 5, 0, -1], [5, -1, 2, -1], [3, 4, 1, -1]]
    wrapped = A.grid_neighbours(position, line, period=3.0)
    assert wrapped[0, 0] == 2 and wrapped[2, 1] == 0 and wrapped[3, 0] == 4 and wrapped[4, 1] == 3
    assert A.grid_neighbours(np.zeros(0), np.zeros(0, np.int64)).shape == (0, 4)


def test_a_spinning_scanners_neighbours_are_the_next_firings_and_rings() -> None:
    lidar = Lidar.preset("hdl32e")
    pulses = lidar.pulses(np.eye(4))
    out = A.pulse_neighbours(pulses)
    d = pulses.directions_sensor
    elevation = np.degrees(np.arcsin(d[:, 2]))
    azimuth = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    step = 360.0 / lidar.n_azimuths
    for column in (0, 1):  # along the ring: one azimuth step, around the seam too
        gap = np.abs((azimuth[out[:, column]] - azimuth + 180.0) % 360.0 - 180.0)
        assert np.all(out[:, column] >= 0) and np.allclose(gap, step, atol=1e-6)
    rings = np.sort(np.unique(np.round(elevation, 3)))
    below, above = out[:, 2], out[:, 3]
    assert (below < 0).sum() == lidar.n_azimuths and (above < 0).sum() == lidar.n_azimuths  # the lowest and highest rings
    spacing = np.diff(rings).max() + 1e-3
    for column in (below, above):
        has = column >= 0
        assert np.all(np.abs(elevation[column[has]] - elevation[has]) <= spacing)
        assert np.allclose(azimuth[column[has]], azimuth[has], atol=1e-6)  # the same firing


def test_an_airborne_scanners_neighbours_are_along_and_across_its_scan_lines() -> None:
    scanner = airborne_preset("riegl-q1560")
    pulses = scanner.pulses((0.0, 0.0), 10.0, np.random.default_rng(0))
    out = A.pulse_neighbours(pulses)
    o, d = pulses.origins, pulses.directions
    ground = o + d * (-o[:, 2] / d[:, 2])[:, None]
    for column in range(4):
        has = out[:, column] >= 0
        assert has.mean() > 0.9
        gap = np.linalg.norm(ground[has] - ground[out[has, column]], axis=1)
        assert np.all(gap < 0.5)  # 0.34 m along and across (its pulse and line spacings), never another line's far end


def _plane_scene(n_cells: int = 8) -> trimesh.Trimesh:
    """A flat 40 m square at z = 0 cut into many coplanar triangles (faces whose edges footprints cross)."""
    x = np.linspace(-20.0, 20.0, n_cells + 1)
    gx, gy = np.meshgrid(x, x)
    v = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    i = np.arange(n_cells)
    a = (i[:, None] * (n_cells + 1) + i[None, :]).ravel()
    faces = np.concatenate([np.column_stack([a, a + 1, a + n_cells + 2]), np.column_stack([a, a + n_cells + 2, a + n_cells + 1])])
    return trimesh.Trimesh(v, faces, process=False)


def _uniform(built, pulses, beam, neighbours=None, **kwargs):
    face, t = cast_embree(built.mesh, pulses.origins, pulses.directions)
    nb = A.pulse_neighbours(pulses) if neighbours is None else neighbours
    offsets = footprint_offsets(beam.footprint_rays, beam.divergence_deg)[0]
    rules = {"range_resolution_m": beam.range_resolution_m, "range_limits_m": (beam.min_range_m, beam.max_range_m), **kwargs}
    return face, t, A.uniform_footprints(built, pulses.origins, pulses.directions, face, t, nb, offsets, **rules)


def _lidar(k: int = 7, divergence_deg: float = 0.3):
    return with_beam(Lidar.preset("hdl32e"), footprint_rays=k, max_returns=2, range_resolution_m=RESOLUTION, divergence_deg=divergence_deg)


@pytest.mark.parametrize("k", [7, 19])
def test_a_uniform_footprints_sub_rays_all_hit_its_centre_face(k) -> None:
    # a plane of many coplanar faces: wherever a footprint is taken as uniform, Embree puts every
    # sub-ray on the centre ray's face; footprints across an edge are cast
    built = build_scene(_plane_scene())
    lidar = _lidar(k, divergence_deg=0.3)
    pulses = lidar.pulses(np.array([[1.0, 0, 0, 0.3], [0, 1, 0, 0.2], [0, 0, 1, 1.8], [0, 0, 0, 1]]))
    face, _, uniform = _uniform(built, pulses, lidar.beam)
    rays = lidar.beam.footprint_directions(pulses.directions)
    sub_face, _ = cast_embree(built.mesh, pulses.origins, rays.reshape(-1, 3))
    sub_face = sub_face.reshape(len(pulses), k)
    hit = uniform & (face >= 0)
    assert hit.sum() > 1000 and (~uniform & (face >= 0)).sum() > 50
    assert np.all(sub_face[hit] == face[hit, None])
    assert np.all(sub_face[uniform & (face < 0)] == -1)


def test_what_makes_a_footprint_need_its_sub_rays() -> None:
    built = build_scene(_plane_scene(2))
    lidar = _lidar()
    pulses = lidar.pulses(np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1.8], [0, 0, 0, 1]]))
    face, _, uniform = _uniform(built, pulses, lidar.beam)
    hit = face >= 0
    neighbours = A.pulse_neighbours(pulses)
    all_miss = ((neighbours < 0) | (face[np.maximum(neighbours, 0)] < 0)).all(axis=1)
    assert uniform[hit].mean() > 0.5 and np.array_equal(uniform[~hit], all_miss[~hit])  # the sky: uniform where every neighbour misses
    assert 0 < (~all_miss[~hit]).sum() < 0.2 * (~hit).sum()  # at the plane's far edge
    # no neighbours known: nothing is taken as uniform
    assert not _uniform(built, pulses, lidar.beam, neighbours=np.full((len(pulses), 2), -1))[2].any()
    # a face that transmits: its pulses are cast
    transmits = np.zeros(len(built.mesh.faces), bool)
    transmits[face[hit][0]] = True
    through = _uniform(built, pulses, lidar.beam, transmits=transmits)[2]
    assert not through[face == face[hit][0]].any() and through[hit & (face != face[hit][0])].any()
    # a finer range resolution than the footprint's spread of ranges (grazing rays far away): cast
    fine = _uniform(built, pulses, lidar.beam, range_resolution_m=0.01)[2]
    assert fine[hit].sum() < uniform[hit].sum()
    # the range limits
    near = _uniform(built, pulses, lidar.beam, range_limits_m=(0.0, 5.0))[2]
    _, t, _ = _uniform(built, pulses, lidar.beam)
    assert not near[hit & (t > 5.0)].any()


def test_a_footprint_reaching_past_its_neighbours_is_cast() -> None:
    """The cone's outermost sub-ray against the pulses' spacing (the HDL-32E fires every 0.166° of azimuth)."""
    built = build_scene(_plane_scene(2))
    pose = np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1.8], [0, 0, 0, 1]])
    for divergence_deg, skipped in ((0.3, True), (0.4, True), (0.5, False), (1.0, False)):  # outermost sub-ray 0.11, 0.15, 0.19, 0.38°
        lidar = _lidar(7, divergence_deg=divergence_deg)
        face, _, uniform = _uniform(built, lidar.pulses(pose), lidar.beam)
        assert uniform[face >= 0].any() == skipped, divergence_deg


def test_a_thin_object_across_a_wide_footprint_keeps_its_edge_echoes() -> None:
    """A 0.3 m pole 10 m before a wall, one ring firing every 0.1°, a 1° beam: its footprint spans ten pulses, and the
    wall's pulses beside the pole, whose neighbours hit the wall too, still see the pole in their cones."""
    pole = trimesh.creation.box(extents=(0.05, 0.3, 10.0), transform=trimesh.transformations.translation_matrix((10.0, 0.15, 0.0)))
    wall = trimesh.creation.box(extents=(0.05, 40.0, 10.0), transform=trimesh.transformations.translation_matrix((30.0, 0.0, 0.0)))
    beam = Beam(max_range_m=1000.0, divergence_deg=1.0, footprint_rays=19, max_returns=2, range_resolution_m=0.75)
    lidar = Lidar("row", (0.0,), rotation_hz=10.0, firing_rate_hz=36_000.0, beam=beam)
    mesh = trimesh.util.concatenate([pole, wall])
    on_pole = {cast: np.sum(scan(mesh, lidar, np.eye(4), azimuth_range_deg=(-3.0, 5.0), footprint=cast).points[:, 0] < 20.0)
               for cast in ("exact", "adaptive")}  # fmt: skip
    assert on_pole["exact"] >= 24  # the pole's own 17 pulses and three or four a side of them
    assert on_pole["adaptive"] == on_pole["exact"]


def test_a_neighbour_on_another_surface_makes_a_pulse_cast() -> None:
    scene = ScanScene().add(str(TABLE), class_name="table", position_m=(6.0, 0.0), size_m=1.5)
    built = scene.build()
    lidar = _lidar(7, divergence_deg=0.16)
    pulses = lidar.pulses(scene.default_sensor_pose(), (-30.0, 30.0))
    face, _, uniform = _uniform(built, pulses, lidar.beam)
    neighbours = A.pulse_neighbours(pulses)
    obj = np.where(face >= 0, built.face_object[np.maximum(face, 0)], -1)
    other = ((neighbours >= 0) & (obj[np.maximum(neighbours, 0)] != obj[:, None])).any(axis=1)
    assert other.sum() > 100 and not uniform[other].any()


def _scene_and_pulses(sector=(-40.0, 40.0)):
    scene = ScanScene().add(str(TABLE), class_name="table", position_m=(6.0, 0.0), size_m=1.5)
    return scene.build(), scene.default_sensor_pose(), sector


@pytest.mark.parametrize(
    ("k", "power_noise", "echo_rule"), [(7, 0.0, "chain"), (19, 0.0, "chain"), (7, 0.3, "chain"), (19, 0.0, "waveform")]
)
def test_adaptive_echoes_against_the_full_model(k, power_noise, echo_rule) -> None:
    built, pose, sector = _scene_and_pulses()
    lidar = with_beam(_lidar(k, divergence_deg=0.16), power_noise=power_noise, detection_threshold=1e-5, echo_rule=echo_rule)
    beam, pulses = lidar.beam, lidar.pulses(pose, sector)
    rho = np.full(len(built.mesh.faces), 0.5)
    rays = beam.footprint_directions(pulses.directions).reshape(-1, 3)
    face, t = cast_embree(built.mesh, pulses.origins, rays)
    assert (beam.range_resolution_m, beam.echo_rule) == (RESOLUTION, echo_rule)  # the rules both casts resolve echoes by

    def radiometry() -> Radiometry:
        return Radiometry(rho, 1e-5, power_noise, np.random.default_rng(1))

    full = echo_returns(built, rays, face, t, beam, max_returns=2, radiometry=radiometry())
    pulse, f, r, e, uniform = A.adaptive_echo_returns(built, beam, pulses, max_returns=2, radiometry=radiometry())
    assert uniform.mean() > 0.5 and np.all(np.diff(pulse) >= 0)
    # the pulses cast: the full model's echoes bit for bit (without power noise, whose draws fall elsewhere)
    cast_full, cast_ours = ~uniform[full[0]], ~uniform[pulse]
    assert np.array_equal(full[0][cast_full], pulse[cast_ours]) and np.array_equal(full[1][cast_full], f[cast_ours])
    if power_noise == 0:
        for a, b in zip(full[2:], (r, e)):
            assert a[cast_full].tobytes() == b[cast_ours].tobytes()
        # the uniform pulses: one echo each, the full model's to rounding, on the same face
        mine_full, mine = uniform[full[0]], uniform[pulse]
        assert np.array_equal(full[0][mine_full], pulse[mine]) and np.array_equal(full[1][mine_full], f[mine])
        assert np.allclose(full[2][mine_full], r[mine], rtol=1e-12) and np.allclose(full[3][mine_full], e[mine], rtol=1e-10)
    else:  # the same echoes, their energies drawn anew: those kept differ only near the threshold
        assert abs(len(pulse) - len(full[0])) < 0.02 * len(pulse)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 30), st.sampled_from([7, 19, 37]), st.floats(0.01, 5.0), st.booleans())
def test_the_kernels_sub_rays_are_plane_subrays_bit_for_bit(seed, n, k, divergence_deg, near_pole) -> None:
    import math

    from zbuf_occlude.sensors.beam.adaptive_kernel import plane_subray, subray_axes

    rng = np.random.default_rng(seed)
    d = _unit(rng.normal(size=(n, 3)) + ([0.0, 0.0, 3.0] if near_pole else 0.0))  # |d_z| ≥ 0.9 turns about x
    normal = _unit(rng.normal(size=(n, 3)))
    t = rng.uniform(0.5, 2000.0, n)
    offsets = footprint_offsets(k, divergence_deg)[0]
    tk, cos = plane_subrays(t, d, normal, offsets)
    tan = np.array([math.tan(theta) for theta in offsets[:, 0]])
    cos_phi, sin_phi, root = np.cos(offsets[:, 1]), np.sin(offsets[:, 1]), np.sqrt(1.0 + tan * tan)
    for i in range(n):
        ux, uy, uz, vx, vy, vz = subray_axes(*d[i])
        (nx, ny, nz), (dx, dy, dz) = normal[i], d[i]
        nd, nu, nv = nx * dx + ny * dy + nz * dz, nx * ux + ny * uy + nz * uz, nx * vx + ny * vy + nz * vz
        got = np.array([plane_subray(t[i], nd, nu, nv, tan[j], cos_phi[j], sin_phi[j], root[j]) for j in range(k)])
        assert got[:, 0].tobytes() == tk[i].tobytes() and got[:, 1].tobytes() == cos[i].tobytes()


@pytest.mark.parametrize("k", [7, 19])
def test_the_kernels_plane_echo_is_plane_echoes(k) -> None:
    # the uniform pulses' echoes from the kernel against plane_echoes of plane_subrays, on a plane of many faces
    built = build_scene(_plane_scene())
    lidar = _lidar(k, divergence_deg=0.3)
    beam = lidar.beam
    pulses = lidar.pulses(np.array([[1.0, 0, 0, 0.3], [0, 1, 0, 0.2], [0, 0, 1, 1.8], [0, 0, 0, 1]]))
    face, t = cast_embree(built.mesh, pulses.origins, pulses.directions)
    offsets, weights = footprint_offsets(k, beam.divergence_deg)
    uniform, rows, echo_range, energy = A._uniform(built, pulses.origins, pulses.directions, face, t, A.pulse_neighbours(pulses), offsets,
                                                   weights, RESOLUTION, (0.0, np.inf), None)  # fmt: skip
    assert len(rows) > 1000 and np.array_equal(rows, np.flatnonzero(uniform & (face >= 0)))
    planes = A._planes(built.mesh)[0]
    tk, cos = plane_subrays(t[rows], pulses.directions[rows], planes[face[rows], 0, :3], offsets)
    expected_range, expected_energy = A.plane_echoes(tk, cos, weights)
    assert np.allclose(echo_range, expected_range, rtol=1e-14, atol=0) and np.allclose(energy, expected_energy, rtol=1e-14, atol=0)


@pytest.mark.parametrize(("share", "stays"), [(0.2, True), (0.3, False)])
def test_a_neighbour_off_the_centre_faces_plane_makes_a_pulse_cast(share, stays) -> None:
    # one neighbour's hit moved along its ray so that it lies share × the range resolution off the plane (PLANE_SHARE: 0.25)
    built = build_scene(_plane_scene())
    lidar = _lidar(7, divergence_deg=0.3)
    pulses = lidar.pulses(np.array([[1.0, 0, 0, 0.3], [0, 1, 0, 0.2], [0, 0, 1, 1.8], [0, 0, 0, 1]]))
    face, t, uniform = _uniform(built, pulses, lidar.beam)
    neighbours = A.pulse_neighbours(pulses)
    hit = face >= 0
    good = np.flatnonzero(uniform & hit & (neighbours >= 0).all(axis=1) & hit[np.maximum(neighbours, 0)].all(axis=1))
    i = good[len(good) // 2]
    j = neighbours[i, 0]
    moved = t.copy()
    moved[j] += share * RESOLUTION / abs(pulses.directions[j, 2])  # the plane is z = 0: off it by share × resolution
    offsets = footprint_offsets(7, lidar.beam.divergence_deg)[0]
    again = A.uniform_footprints(built, pulses.origins, pulses.directions, face, moved, neighbours, offsets, range_resolution_m=RESOLUTION)
    assert again[i] == stays
    others = np.ones(len(pulses), bool)  # the pulses that do not see the moved hit: unchanged
    others[(neighbours == j).any(axis=1)] = others[j] = False
    assert np.array_equal(again[others], uniform[others])


def test_the_kernel_refuses_indices_outside_its_arrays() -> None:
    from zbuf_occlude.sensors.beam.adaptive_kernel import UniformRules, uniform_plane_echoes

    built = build_scene(_plane_scene(2))
    planes = A._planes(built.mesh)[0]
    n_faces = len(planes)
    offsets, weights = footprint_offsets(7, 0.5)
    d = np.tile([0.0, 0.0, -1.0], (3, 1))
    args = {"origins": np.array([[0.0, 0.0, 10.0]]), "directions": d, "face": np.array([0, 1, -1]), "t": np.full(3, 10.0),
            "neighbours": np.array([[1, -1], [0, 2], [1, -1]]), "planes": planes, "face_object": np.zeros(n_faces, np.int64),
            "transmits": np.zeros(n_faces, bool), "offsets": offsets, "weights": weights}  # fmt: skip
    rules = UniformRules(range_resolution_m=0.75, range_limits_m=(0.0, np.inf), margin_m=0.0, tolerance_m=0.2, min_range_m=1e-9)
    uniform_plane_echoes(**args, rules=rules)  # these are fine
    for change, words in [
        ({"neighbours": np.array([[1, -1], [0, 3], [1, -1]])}, "neighbour indices outside -1..2"),
        ({"neighbours": np.array([[1, -2], [0, 2], [1, -1]])}, "neighbour indices outside -1..2"),
        ({"face": np.array([0, n_faces, -1])}, f"face indices outside -1..{n_faces - 1}"),
        ({"t": np.full(2, 10.0)}, "t (2,) (P,)"),
        ({"origins": np.zeros((2, 3))}, "origins (2, 3)"),
        ({"planes": planes[:, :3]}, "planes"),
        ({"weights": weights[:3]}, "weights (3,) (K,)"),
    ]:
        with pytest.raises(InvalidInputError, match=re.escape(words)):
            uniform_plane_echoes(**(args | change), rules=rules)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 6), st.integers(1, 40))
def test_a_pulses_neighbour_across_lines_is_the_nearest_by_position(seed, n_lines, per_line) -> None:
    rng = np.random.default_rng(seed)
    line = rng.permutation(np.repeat(np.arange(n_lines), rng.integers(1, per_line + 1, n_lines)))
    position = rng.uniform(-3.0, 3.0, len(line)).round(2)  # rounded: ties of distance, and of position, happen
    out = A.grid_neighbours(position, line)
    for i in range(len(line)):
        for column, step in ((2, -1), (3, 1)):
            others = np.flatnonzero(line == line[i] + step)
            if len(others) == 0:
                assert out[i, column] == -1
                continue
            j = out[i, column]
            assert line[j] == line[i] + step
            gap = np.abs(position[others] - position[i])
            assert abs(position[j] - position[i]) == gap.min()
            nearest = others[gap == gap.min()]
            assert position[j] == position[nearest].min()  # a tie of distance: the lower position
