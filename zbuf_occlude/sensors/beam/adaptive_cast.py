"""Adaptive footprints: the multi-return model without casting the sub-rays of a footprint that lies on one plane (the default; approximate).

The multi-return model (:func:`~zbuf_occlude.sensors.beam.echo_energy.echo_returns`) casts K sub-rays per pulse
(:mod:`zbuf_occlude.sensors.beam.footprint`) and resolves their hits into echoes.  On open ground or a wall, every
sub-ray hits the centre ray's face near its hit, and the receiver sees one echo: the K casts
buy nothing that the plane does not already tell.  :func:`adaptive_echo_returns` casts every
pulse's centre ray first and casts the whole footprint only where :func:`uniform_footprints`
cannot rule out a second surface.  A pulse is *uniform* when all of these hold:

* its centre ray hits a face ``f`` that does not transmit;
* every sub-ray meets ``f``'s plane (:func:`~zbuf_occlude.sensors.beam.footprint.plane_subrays`, no cast) inside ``f``,
  with :data:`INSIDE_MARGIN_SHARE` of the scene's size to spare: none leaves ``f`` for a face
  beside or behind it;
* those ranges, sorted, step less than the range resolution (one echo,
  :func:`~zbuf_occlude.sensors.beam.echoes.resolve_echoes`'s merging) and lie within the beam's range limits;
* every neighbour (the pulses fired beside it: :func:`pulse_neighbours`) fires outside the cone
  of the sub-rays (a footprint wider than the pulses' spacing reaches past its neighbours, and is
  cast in full), and hits the same object within :data:`PLANE_SHARE` of the range resolution of
  ``f``'s plane; or, where the centre ray hits nothing, no neighbour hits anything (then no
  sub-ray is taken to hit).

A uniform pulse's echo is the one the K sub-rays would give on ``f``'s plane, computed without
casting them (:func:`plane_echoes`): the energy-weighted mean of their ranges and the sum of
their energies (:func:`~zbuf_occlude.sensors.beam.echoes.hit_energy`), equal to the full model's to rounding, on ``f``.
The one error left: a surface in front of ``f`` inside the cone that neither the centre ray nor
any neighbour meets (a wire, a thin bar between two rings, a corner poking into the footprint):
its echo is lost.  Where the beam draws power noise, the uniform pulses' draws come first, then
the others' (the full model draws them in pulse order).  ``benchmarks/bench_returns.py``
measures its speed and its bias on return shares and points.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.cache import MeshCache
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.beam.echo_energy import Radiometry, Transmission, echo_returns
from zbuf_occlude.sensors.beam.echoes import MIN_RANGE_M, resolve_echoes
from zbuf_occlude.sensors.beam.footprint import footprint_offsets
from zbuf_occlude.sensors.checks import namer
from zbuf_occlude.sensors.pulses import Pulses
from zbuf_occlude.sensors.raycast.embree import BEYOND_HIT_SHARE, cast_embree
from zbuf_occlude.sensors.scene.objects import BuiltScene

__all__ = [
    "FOOTPRINT_MODES",
    "INSIDE_MARGIN_SHARE",
    "LINE_BREAK_STEPS",
    "PLANE_SHARE",
    "adaptive_echo_returns",
    "adaptive_footprint",
    "check_footprint_cast",
    "footprint_mode",
    "grid_neighbours",
    "plane_echoes",
    "pulse_neighbours",
    "uniform_footprints",
]

#: How far inside its face a uniform footprint stays beyond the cone's reach, as a share of the
#: scene's bounding-box diagonal: Embree decides in float32 (~1e-7 of the coordinates), so a sub-ray
#: this far inside (10× :data:`~zbuf_occlude.sensors.raycast.embree.BEYOND_HIT_SHARE`: 2 cm in a 230 m scene) would hit ``f``.
INSIDE_MARGIN_SHARE = 10.0 * BEYOND_HIT_SHARE
#: A neighbour's hit is on the centre face's plane within this share of the range resolution
#: (nearer than that, a second surface would merge into the same echo anyway).
PLANE_SHARE = 0.25
#: A scan line of a pattern without rings ends where its scan angle steps more than this many
#: times the median step, or turns back (:func:`pulse_neighbours`).
LINE_BREAK_STEPS = 4.0


def _face_planes(mesh) -> tuple[NDArray[np.float64], float]:
    """``(planes, diagonal)``: (F, 4, 4) float64 with ``planes[f]`` the rows ``(n, −n · a)`` of
    face ``f``'s plane and ``(m_j, −m_j · p_j)`` of its edges ab, bc, ca (``m_j`` the edge's inward
    unit normal in the plane, ``p_j`` its first vertex), so that ``planes[f] @ (x, 1)`` gives a
    point's distance to the plane and to each edge line (inside: all three ≥ 0; a degenerate face:
    all 0), a face's 16 values together; and the bounding-box diagonal of the mesh, metres."""
    tri = np.asarray(mesh.triangles, dtype=np.float64)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    planes = np.empty((4, 4, len(tri)))
    planes[0, :3] = n.T
    planes[0, 3] = -np.einsum("ij,ij->i", n, tri[:, 0])
    for j in range(3):
        p, q = tri[:, j], tri[:, (j + 1) % 3]
        m = np.cross(n, q - p)
        m /= np.maximum(np.linalg.norm(m, axis=1, keepdims=True), 1e-300)
        planes[j + 1, :3] = m.T
        planes[j + 1, 3] = -np.einsum("ij,ij->i", m, p)
    planes = np.ascontiguousarray(planes.transpose(2, 0, 1))
    planes.flags.writeable = False
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    return planes, float(np.linalg.norm(np.ptp(vertices, axis=0))) if len(vertices) else 1.0


#: :func:`_face_planes` of the scenes in use, once per mesh.
_planes = MeshCache(_face_planes, 4)


def uniform_footprints(
    built: BuiltScene,
    origins: NDArray[np.float64],
    directions: NDArray[np.float64],
    face: NDArray[np.int64],
    t: NDArray[np.float64],
    neighbours: NDArray[np.int64],
    offsets: NDArray[np.float64],
    *,
    range_resolution_m: float,
    range_limits_m: tuple[float, float] = (0.0, np.inf),
    transmits: NDArray[np.bool_] | None = None,
) -> NDArray[np.bool_]:
    """(P,) bool: the pulses whose footprint needs no cast of its sub-rays (the rules: module docstring).

    Parameters
    ----------
    built : BuiltScene
        The scene (its mesh, and the object of each face).
    origins : (3,) or (P, 3) float64
        Where the pulses leave, world frame, metres.
    directions : (P, 3) float64
        Unit centre directions, world frame.
    face, t : (P,) int64, (P,) float64
        The centre rays' first hits (:func:`~zbuf_occlude.sensors.raycast.embree.cast_embree`): face, −1 for none, and range, metres.
    neighbours : (P, m) int64
        Rows of each pulse's neighbours, −1 for none (:func:`pulse_neighbours`); a pulse without
        one is never uniform.
    offsets : (K, 2) float64
        The footprint's sub-rays (:func:`~zbuf_occlude.sensors.beam.footprint.footprint_offsets`).
    range_resolution_m : float
        The receiver's range resolution, metres, > 0.
    range_limits_m : (min, max) float
        The beam's range limits, metres: a uniform footprint's ranges lie within them.
    transmits : (F,) bool, optional
        Faces a sub-ray goes on through: a pulse hitting one is never uniform.
    """
    return _uniform(built, origins, directions, face, t, neighbours, offsets, np.ones(len(offsets)), range_resolution_m, range_limits_m,
                    transmits)[0]  # fmt: skip


def _uniform(built, origins, directions, face, t, neighbours, offsets, weights, range_resolution_m, range_limits_m, transmits):
    """:func:`uniform_footprints`, and the uniform hits' rows, ascending, and their plane echo's range and
    energy for ρ = 1 (:func:`plane_echoes`), by :func:`~zbuf_occlude.sensors.beam.adaptive_kernel.uniform_plane_echoes`."""
    from zbuf_occlude.sensors.beam.adaptive_kernel import UniformRules, uniform_plane_echoes  # numba: imported when used

    planes, diagonal = _planes(built.mesh)
    transmits = np.zeros(len(planes), bool) if transmits is None else np.asarray(transmits, dtype=bool)
    rules = UniformRules(range_resolution_m, range_limits_m, INSIDE_MARGIN_SHARE * diagonal, PLANE_SHARE * range_resolution_m, MIN_RANGE_M)
    return uniform_plane_echoes(
        origins, directions, face, t, neighbours, planes, np.asarray(built.face_object), transmits, offsets, weights, rules
    )


def plane_echoes(
    range_m: NDArray[np.float64],
    cos_incidence: NDArray[np.float64],
    weights: NDArray[np.float64],
    reflectivity: NDArray[np.float64] | float = 1.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(range, energy)`` (P,) float64: the one echo of each pulse's K sub-ray hits on one surface.

    Sub-ray ``k`` hits at range ``t_k`` and incidence ``cos_incidence`` (``|n · d_k|``,
    :func:`~zbuf_occlude.sensors.beam.footprint.plane_subrays`) and sends back ``E_k = w_k ρ |n · d_k| / t_k²``
    (:func:`~zbuf_occlude.sensors.beam.echoes.hit_energy`).  The echo: ``Σ E_k t_k / Σ E_k`` (the energy-weighted mean
    range, :func:`~zbuf_occlude.sensors.beam.echoes.resolve_echoes`) and ``Σ E_k``: :func:`~zbuf_occlude.sensors.beam.adaptive_kernel.plane_echo` of each row, the
    adaptive scan's own.

    Parameters
    ----------
    range_m, cos_incidence : (P, K) float64
        Each sub-ray's range, metres, and ``|cos θ|``.
    weights : (K,) float64
        Each sub-ray's share of the pulse's energy.
    reflectivity : float or (P,) float64
        ρ of each pulse's surface.
    """
    from zbuf_occlude.sensors.beam.adaptive_kernel import plane_echo_rows  # numba: imported when used

    tk, cos = (np.ascontiguousarray(np.atleast_2d(a), dtype=np.float64) for a in (range_m, cos_incidence))
    echo_range, energy = plane_echo_rows(tk, cos, np.ascontiguousarray(weights, dtype=np.float64), MIN_RANGE_M)
    return echo_range, energy * np.asarray(reflectivity, dtype=np.float64)


def grid_neighbours(position: NDArray[np.float64], line: NDArray[np.int64], *, period: float | None = None) -> NDArray[np.int64]:
    """(P, 4) int64: each pulse's neighbours on a grid of scan lines, −1 for none.

    Columns: the previous and next pulse of its line by ``position``, then the pulses of the
    lines ranked just below and just above its own nearest to it by ``position``.  With
    ``period`` (a spinning scanner's azimuth: 2π), a line that spans a full turn (the gap across
    the seam less than twice its mean step) wraps around.

    Parameters
    ----------
    position : (P,) float
        Each pulse's place along its line (an azimuth, a scan angle).
    line : (P,) int
        Each pulse's line, ranked: lines ``r`` and ``r + 1`` lie side by side.
    period : float, optional
        The period of ``position``.
    """
    position = np.asarray(position, dtype=np.float64)
    line = np.asarray(line, dtype=np.int64)
    n = len(position)
    out = np.full((n, 4), -1, np.int64)
    if n == 0:
        return out
    # one key (line, position), sorted: a stable sort of it is nearly free on a pattern's firing order
    low = float(position.min())
    width = float(position.max()) - low + 1.0
    key = line * width + (position - low)
    order = np.argsort(key, kind="stable")
    key, p, r = key[order], position[order], line[order]
    same = r[1:] == r[:-1]
    out[order[1:][same], 0] = order[:-1][same]
    out[order[:-1][same], 1] = order[1:][same]
    first = np.flatnonzero(np.concatenate([[True], ~same]))
    last = np.concatenate([first[1:], [n]]) - 1
    if period is not None:
        span = p[last] - p[first]
        wraps = (last - first >= 2) & (period - span < 2.0 * span / np.maximum(last - first, 1))
        out[order[first[wraps]], 0] = order[last[wraps]]
        out[order[last[wraps]], 1] = order[first[wraps]]
    # the pulses of line r ± 1 nearest to each pulse by position (ties: the lower position), a compiled loop
    from zbuf_occlude.sensors.beam.adaptive_kernel import nearest_in_line  # numba: imported when used

    for column, step in ((2, -1), (3, 1)):
        nearest_in_line(key, p, r, order, width, low, step, column, out)
    return out


def pulse_neighbours(pulses: Pulses) -> NDArray[np.int64]:
    """(P, 4) int64: each pulse's neighbours (:func:`grid_neighbours`), −1 for none.

    A pattern with rings (a spinning scanner): its rings ranked by elevation, azimuth along each
    (a full turn wraps around).  Otherwise (an airborne scanner, a ray table): its scan lines in
    firing order, each ending where the scan angle turns back or steps more than
    :data:`LINE_BREAK_STEPS` times its median step, the scan angle along each.  A table whose rows
    interleave elevations (a real HDL-32E's firing order) breaks a line at nearly every row: its
    footprints are then nearly all cast, as the exact model casts them, and nothing is saved.
    """
    d = pulses.directions_sensor
    if pulses.ring is not None:
        ring = np.asarray(pulses.ring, dtype=np.int64)
        count = np.bincount(ring)
        elevation = np.bincount(ring, weights=d[:, 2])[count > 0] / count[count > 0]  # the rings fired, by mean sine
        rank = np.zeros(len(count), np.int64)
        rank[np.flatnonzero(count)[np.argsort(elevation, kind="stable")]] = np.arange(len(elevation))
        return grid_neighbours(np.arctan2(d[:, 1], d[:, 0]), rank[ring], period=2.0 * np.pi)
    angle = np.asarray(pulses.scan_angle_deg, dtype=np.float64)
    step = np.diff(angle)
    typical = float(np.median(np.abs(step))) if len(step) else 0.0
    breaks = np.abs(step) > LINE_BREAK_STEPS * typical  # a sawtooth's flyback
    breaks[1:] |= (np.sign(step[1:]) * np.sign(step[:-1]) < 0) & ~breaks[1:] & ~breaks[:-1]  # an oscillating mirror's turn
    return grid_neighbours(angle, np.concatenate([[0], np.cumsum(breaks)]))


#: How a beam that resolves echoes casts its footprint (``scan(footprint=...)``): "auto" (the default) the
#: adaptive cast where it applies, else every sub-ray; "exact" every sub-ray; "adaptive" only where needed.
FOOTPRINT_MODES = ("auto", "exact", "adaptive")


def check_footprint_cast(
    footprint: object,
    beam: Beam | None,
    backend: str = "embree",
    *,
    sensor: str | None = None,
    names: Mapping[str, str | None] | None = None,
) -> str:
    """``footprint`` (one of :data:`FOOTPRINT_MODES`) where it applies to ``beam`` and ``backend``: the one statement of the rule.

    "adaptive" skips the sub-rays of footprints whose echoes are resolved, so it needs a beam that
    resolves the echoes of several sub-rays (``Beam.resolves_footprint``), and it casts with Embree.
    Messages name each field as ``names`` maps it (``footprint_cast``, ``backend``, and in the remedy
    ``footprint_rays`` and ``max_returns``; a field mapped to None is left out of the remedy: the
    caller sets it itself), as :func:`~zbuf_occlude.sensors.beam.fields.check_returns` does; ``sensor`` is the
    sensor's name (default: the beam's).  ``beam`` None checks the mode alone (before a sensor is read).

    Raises
    ------
    InvalidInputError
        An unknown mode (naming its type and value), or "adaptive" for a beam that resolves no echoes
        or fires one ray, or with another backend than "embree".
    """
    n = namer(names)
    if not isinstance(footprint, str) or footprint not in FOOTPRINT_MODES:
        shown = f"{footprint!r:.40}" if isinstance(footprint, str) else f"{type(footprint).__name__} {footprint!r:.40}"
        raise InvalidInputError(f"{n('footprint_cast')} must be one of {', '.join(FOOTPRINT_MODES)}, got {shown}")
    if footprint != "adaptive" or beam is None:
        return footprint
    if not beam.resolves_footprint:
        needed = {"footprint_rays": beam.footprint_rays == 1, "max_returns": not beam.resolves_echoes}
        remedy = [f"{n(f)} 2 or more" if f == "max_returns" else n(f, "footprint_rays above 1")
                  for f, lacking in needed.items() if lacking and (names or {}).get(f, f) is not None]  # fmt: skip
        raise InvalidInputError(
            f"{n('footprint_cast')} adaptive skips the sub-rays of a footprint whose echoes are resolved; {sensor or beam.name} "
            f"fires one ray a pulse or resolves none of its echoes (footprint_rays {beam.footprint_rays}, max_returns "
            f"{beam.max_returns}, return_mode {beam.return_mode})" + (f": give it {' and '.join(remedy)}" if remedy else "")
        )
    if backend != "embree":
        raise InvalidInputError(f"{n('footprint_cast')} adaptive casts rays with Embree; {n('backend')} {backend:.40} renders a z-buffer")
    return footprint


def adaptive_footprint(footprint: str, beam: Beam, backend: str) -> bool:
    """Whether ``footprint`` (:data:`FOOTPRINT_MODES`) casts the adaptive footprint with ``beam`` and ``backend``.

    "auto" casts it wherever it applies: a beam that resolves the echoes of several sub-rays
    (``Beam.resolves_footprint``) and the "embree" backend; elsewhere every sub-ray is cast, as
    "exact" casts them everywhere.  "adaptive" asks for it and is refused where it does not apply
    (:func:`check_footprint_cast`, in the words of :func:`~zbuf_occlude.sensors.scan.scan`'s parameters).

    Raises
    ------
    InvalidInputError
        As :func:`check_footprint_cast`.
    """
    mode = check_footprint_cast(footprint, beam, backend, names={"footprint_cast": "footprint"})
    if mode == "auto":
        return beam.resolves_footprint and backend == "embree"
    return mode == "adaptive"


def footprint_mode(footprint: str, beam: Beam, backend: str = "embree") -> str:
    """``"adaptive"`` or ``"exact"``: the cast ``footprint`` (:data:`FOOTPRINT_MODES`) makes with ``beam`` and ``backend``
    (:func:`adaptive_footprint`, which raises what it raises)."""
    return "adaptive" if adaptive_footprint(footprint, beam, backend) else "exact"


def adaptive_echo_returns(
    built: BuiltScene,
    beam: Beam,
    pulses: Pulses,
    *,
    max_returns: int,
    radiometry: Radiometry | None = None,
    transmittance: NDArray[np.float64] | None = None,
    neighbours: NDArray[np.int64] | None = None,
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray[np.bool_]]:
    """:func:`~zbuf_occlude.sensors.beam.echo_energy.echo_returns` of ``pulses`` fired with ``beam``, the uniform footprints' echoes from their plane.

    The centre rays are cast (Embree, :func:`~zbuf_occlude.sensors.raycast.embree.cast_embree`); the uniform pulses
    (:func:`uniform_footprints`) get the one echo their sub-rays would give on the centre face's
    plane (:func:`plane_echoes`), the others' ``beam.footprint_rays`` sub-rays are cast and
    resolved by :func:`~zbuf_occlude.sensors.beam.echo_energy.echo_returns`, through the faces that transmit.  The beam's
    range resolution, range limits, ``min_echo_reflectance`` and ``echo_rule`` apply to both.

    Parameters
    ----------
    built : BuiltScene
    beam : Beam
        A beam that resolves echoes (``Beam.resolves_echoes``) with ``footprint_rays`` > 1.
    pulses : Pulses
    max_returns : int
        As :func:`~zbuf_occlude.sensors.beam.echo_energy.echo_returns`.
    radiometry : Radiometry, optional
        As :func:`~zbuf_occlude.sensors.beam.echo_energy.echo_returns`: ρ per face, threshold, power noise (one draw per pulse).
    transmittance : (F,) float64, optional
        Round-trip transmittance per face (:func:`~zbuf_occlude.sensors.beam.echo_energy.surface_optics`); None: opaque.
    neighbours : (P, m) int64, optional
        Default :func:`pulse_neighbours`.

    Returns
    -------
    pulse, face, range, energy
        As :func:`~zbuf_occlude.sensors.beam.echo_energy.echo_returns`: (E,) each, sorted by pulse, then range.
    uniform : (P,) bool
        The pulses whose sub-rays were not cast.
    """
    mesh = built.mesh
    d = pulses.directions
    k = beam.footprint_rays
    face, t = cast_embree(mesh, pulses.origins, d)
    tau = None if transmittance is None else np.asarray(transmittance, dtype=np.float64)
    limits = (beam.min_range_m, beam.max_range_m)
    offsets = footprint_offsets(k, beam.divergence_deg)[0]
    uniform, one, echo_range, energy = _uniform(
        built, pulses.origins, d, face, t, pulse_neighbours(pulses) if neighbours is None else neighbours, offsets,
        beam.footprint_weights(), beam.range_resolution_m, limits, None if tau is None else tau > 0,
    )  # fmt: skip
    # the uniform pulses that hit: their plane's echo, then the receiver's rules (resolve_echoes)
    f = face[one]
    if radiometry is not None:
        energy = energy * np.asarray(radiometry.reflectivity, dtype=np.float64)[f]
    if radiometry is not None and radiometry.power_noise > 0:
        energy = energy * np.exp(radiometry.power_noise * radiometry.rng.standard_normal(len(one)))
    plane = resolve_echoes(
        one, echo_range, energy, np.asarray(built.face_object)[f].astype(np.int64), range_resolution_m=beam.range_resolution_m,
        detection_threshold=0.0 if radiometry is None else radiometry.detection_threshold, max_returns=max_returns,
        min_echo_reflectance=beam.min_echo_reflectance, echo_rule=beam.echo_rule,
    )  # fmt: skip
    # the others: every sub-ray cast (the centre ray again: its bits as the full model's)
    full = np.flatnonzero(~uniform)
    rays = beam.footprint_directions(d[full]).reshape(-1, 3)
    origins = pulses.origins if pulses.static else np.repeat(pulses.origins[full], k, axis=0)
    sub_face, sub_t = cast_embree(mesh, origins, rays)
    cast = echo_returns(
        built, rays, sub_face, sub_t, beam, max_returns=max_returns, radiometry=radiometry,
        through=None if tau is None else Transmission(tau, origins),
    )  # fmt: skip
    pulse = np.concatenate([plane.pulse, full[cast[0]]])
    order = np.argsort(pulse, kind="stable")  # a pulse's echoes all come from one part, in range order
    face_out = np.concatenate([face[plane.pulse], cast[1]])[order]
    return pulse[order], face_out, np.concatenate([plane.range_m, cast[2]])[order], np.concatenate([plane.energy, cast[3]])[order], uniform
