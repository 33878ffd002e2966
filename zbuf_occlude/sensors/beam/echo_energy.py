"""The multi-return model on a scene: the sub-ray hits of each pulse weighed and resolved into returns.

One implementation for every scanner (the spinning LiDAR and ray tables of :func:`~zbuf_occlude.sensors.scan.scan`,
the airborne scanner of :func:`~zbuf_occlude.sensors.scan.scan_airborne`): :func:`surface_optics` turns a
scanner's ``reflectivity`` and ``transmittance`` (a number, one per object id, or the cited table
of :mod:`zbuf_occlude.sensors.scene.materials`, whose lookup gives each face its file's material) into values per face of
the scene; :func:`echo_returns` casts each sub-ray on through
the surfaces that transmit (:func:`~zbuf_occlude.sensors.raycast.embree.cast_embree_beyond`), weighs every hit by
:func:`~zbuf_occlude.sensors.beam.echoes.hit_energy` and the transmittance before it (:func:`~zbuf_occlude.sensors.beam.echoes.attenuate_along_subray`)
and resolves a pulse's hits into returns (:func:`~zbuf_occlude.sensors.beam.echoes.resolve_echoes`);
:func:`strongest_echo` is the one-return footprint model (the strongest surface, mixed pixels).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.beam.attenuation import attenuate_along_subray
from zbuf_occlude.sensors.checks import namer, real
from zbuf_occlude.sensors.beam.echoes import MAX_POWER_NOISE, hit_energy, resolve_echoes
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.raycast.embree import MAX_HITS, cast_embree_beyond, face_normals
from zbuf_occlude.sensors.scene.objects import BuiltScene

__all__ = ["Radiometry", "Transmission", "check_transmittance_cast", "echo_returns", "strongest_echo", "surface_optics"]


def surface_optics(built: BuiltScene, reflectivity, transmittance, *, wavelength_nm: float, multi_return: bool, backend: str = "embree"):
    """Reflectivity and transmittance per face of a scanner's scene, checked; one rule for every scanner.

    Parameters
    ----------
    built : BuiltScene
        The scene (its objects give the ids: 0 the ground, then the objects).
    reflectivity, transmittance : None, float, (n_objects + 1,) float, or "table"
        Lambertian ρ ≥ 0 and round-trip transmittance in [0, 1] per object id: one value for
        all, one per id, or ``"table"``: :func:`~zbuf_occlude.sensors.scene.materials.scene_optics` at ``wavelength_nm``
        (the cited table, by each face's material in its file, else its object's material, class
        or file name).
    wavelength_nm : float
        The scanner's wavelength, nm (905 for the spinning presets, 1064 for airborne scanners).
    multi_return : bool
        Whether the scanner resolves several returns per pulse (a transmittance above 0 needs it).
    backend : str
        The ray caster; a transmittance above 0 needs "embree" (every hit along a sub-ray).

    Returns
    -------
    rho : (F,) float64 or None
        Per face of ``built.mesh``.
    tau : (F,) float64 or None
        Per face of ``built.mesh``; None also where every value is 0 (opaque, first hits only).

    Raises
    ------
    InvalidInputError
        A string other than "table", a value out of range or of the wrong length, a
        transmittance above 0 with one return per pulse or another backend than "embree".
    """
    from zbuf_occlude.sensors.scene.materials import scene_optics

    table = None
    for name, value in (("reflectivity", reflectivity), ("transmittance", transmittance)):
        if isinstance(value, str) and value != "table":
            raise InvalidInputError(f"{name} must be a number, one per object id, or 'table', got {value!r}")
        if isinstance(value, str) and table is None:
            table = scene_optics(built, wavelength_nm)
    n_ids = len(built.objects) + 1
    rho = None
    if reflectivity is not None:
        rho = table.face_reflectivity if isinstance(reflectivity, str) else _reflectivity_table(reflectivity, n_ids)[built.face_object]
    tau = None
    if transmittance is not None:
        tau = table.face_transmittance if isinstance(transmittance, str) else _transmittance_table(transmittance, n_ids)[built.face_object]
        if not tau.any():
            tau = None  # opaque everywhere: today's first hits
        else:
            check_transmittance_cast("above 0", resolves_echoes=multi_return, backend=backend)
    return rho, tau


def check_transmittance_cast(shown: str, *, resolves_echoes: bool, backend: str, names: Mapping[str, str | None] | None = None) -> None:
    """The one statement of where a transmittance above 0 applies: to a beam that resolves echoes (the hits behind a
    surface are further echoes of its pulses), cast with Embree (every hit along each sub-ray; the z-buffer keeps the
    nearest face per pixel).  ``shown`` is the transmittance as the caller shows it ("above 0", a user's value);
    ``names`` maps the fields ``transmittance``, ``max_returns``, ``footprint_rays`` and ``backend`` to the caller's
    words, as :func:`~zbuf_occlude.sensors.beam.fields.check_returns`'s do.

    Raises
    ------
    InvalidInputError
        A beam that resolves no echoes, or another backend than "embree".
    """
    n = namer(names)
    if not resolves_echoes:
        raise InvalidInputError(f"{n('transmittance')} {shown} gives hits behind a surface, which only several returns per pulse resolve: "
                                f"give {n('max_returns')} above 1 (and {n('footprint_rays')})")  # fmt: skip
    if backend != "embree":
        raise InvalidInputError(f"{n('transmittance')} {shown} needs every hit along each sub-ray, which {n('backend')} {backend:.40} "
                                f"cannot give (one face per pixel): use {n('backend')} embree")  # fmt: skip


def _reflectivity_table(reflectivity, n_ids: int) -> NDArray[np.float64]:
    """(n_ids,) float64 ρ per object id from a scalar or a per-id sequence."""
    rho = np.asarray(reflectivity, dtype=np.float64).reshape(-1)
    if rho.size == 1:
        rho = np.full(n_ids, float(rho[0]))
    if rho.size != n_ids or not np.all(np.isfinite(rho)) or np.any(rho < 0):
        raise InvalidInputError(f"reflectivity must be one value >= 0 or {n_ids} (ground + objects), got {reflectivity!r}")
    return rho


def _transmittance_table(transmittance, n_ids: int) -> NDArray[np.float64]:
    """(n_ids,) float64 round-trip transmittance per object id from a scalar or a per-id sequence, each in [0, 1]."""
    try:
        tau = np.asarray(transmittance, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        tau = np.full(1, np.nan)
    if tau.size == 1:
        tau = np.full(n_ids, float(tau[0]))
    if tau.size != n_ids or not np.all((tau >= 0) & (tau <= 1)):
        raise InvalidInputError(f"transmittance must be one value in [0, 1] or {n_ids} (ground + objects), got {transmittance!r}")
    return tau


def strongest_echo(
    built: BuiltScene, rays, face, t, k: int, rho, separation: float = 0.0, weights=None
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Resolve each beam's ``k`` footprint rays into one return: the strongest echo.

    Each ray carries ``1/k`` of the beam's energy (``weights`` (k,) instead, when given: a
    Gaussian :attr:`Beam.profile <zbuf_occlude.sensors.beam.fields.Beam.profile>`); a ray hitting a surface of reflectivity ρ at
    incidence θ and range R sends back ``ρ |cos θ| / (k R²)`` (ρ = 1 without ``rho``, else ``rho``
    (F,) per face of ``built.mesh``, :func:`surface_optics`).  The
    echoes of one object id add up; the object with the most energy is the return (ties: the
    lower ray index, the centre first).  Its range is the energy-weighted mean of its rays'
    ranges, its face the nearest of its rays' faces.  With ``separation > 0`` (the sensor's
    ``echo_separation_m``), the rays of any surface within ``separation`` of that range join
    the return, its range becomes the energy-weighted mean over all of them and its energy
    their sum: a mixed pixel where the footprint straddles a shallow depth edge (its face and
    object stay the strongest echo's).

    Returns
    -------
    face : (N,) int64, −1 where no ray hit; t : (N,) float64; energy : (N,) float64
        ``Σ ρ |cos θ| / k`` over the chosen object's rays (the footprint fraction times ρ cos θ).
    """
    n = len(face) // k
    face = face.reshape(n, k)
    t = t.reshape(n, k)
    hit = face >= 0
    obj = np.where(hit, built.face_object[np.maximum(face, 0)], -1)
    normal = face_normals(built.mesh, np.maximum(face, 0))
    cos = np.abs(np.einsum("nkj,nkj->nk", normal, rays.reshape(n, k, 3)))
    reflected = cos * (1.0 if rho is None else rho[np.maximum(face, 0)])
    weight = np.where(hit, reflected / k if weights is None else reflected * weights[None, :], 0.0)
    energy = np.where(hit, hit_energy(weight, 1.0, 1.0, t), 0.0)  # the range equation; ρ cos θ is in weight
    same = (obj[:, :, None] == obj[:, None, :]) & hit[:, :, None] & hit[:, None, :]
    total = np.einsum("nij,nj->ni", same, energy)
    best = np.argmax(total, axis=1)
    rows = np.arange(n)
    mine = same[rows, best]  # (n, k): the rays on the chosen object
    w = np.where(mine, energy, 0.0)
    t_out = np.einsum("nk,nk->n", w, np.where(mine, t, 0.0)) / np.maximum(w.sum(axis=1), 1e-300)
    nearest = np.argmin(np.where(mine, t, np.inf), axis=1)
    face_out = np.where(hit.any(axis=1), face[rows, nearest], -1)
    if separation > 0.0:  # unresolved echoes of other surfaces merge into the return
        mine = mine | (hit & (np.abs(t - t_out[:, None]) <= separation))
        w = np.where(mine, energy, 0.0)
        t_out = np.einsum("nk,nk->n", w, np.where(mine, t, 0.0)) / np.maximum(w.sum(axis=1), 1e-300)
    return face_out, np.where(hit.any(axis=1), t_out, np.inf), np.where(mine, weight, 0.0).sum(axis=1)


@dataclass(frozen=True)
class Radiometry:
    """What weighs and thresholds the echoes of :func:`echo_returns`.

    Attributes
    ----------
    reflectivity : (F,) float
        Lambertian ρ per face of the built scene's mesh (:func:`surface_optics`).
    detection_threshold : float
        Least echo energy kept, m⁻² (:func:`~zbuf_occlude.sensors.beam.echoes.hit_energy`'s units).
    power_noise : float
        σ in [0, :data:`~zbuf_occlude.sensors.beam.echoes.MAX_POWER_NOISE`]: every hit of a pulse is scaled by one
        ``exp(σ z)``, z ~ N(0, 1) per pulse (P draws from ``rng``); 0: nothing is drawn.
    rng : numpy.random.Generator, optional
        Needed when ``power_noise`` is above 0.

    Raises
    ------
    InvalidInputError
        ``detection_threshold`` not a finite number >= 0, ``power_noise`` outside its range,
        naming the field.
    """

    reflectivity: ArrayLike
    detection_threshold: float = 0.0
    power_noise: float = 0.0
    rng: np.random.Generator | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "detection_threshold", real(self.detection_threshold, "detection_threshold", low=0.0))
        object.__setattr__(self, "power_noise", real(self.power_noise, "power_noise", low=0.0, high=MAX_POWER_NOISE))


@dataclass(frozen=True)
class Transmission:
    """Sub-rays that go on through surfaces in :func:`echo_returns`: all hits along each, not only the first.

    Attributes
    ----------
    transmittance : (F,) float
        Round-trip transmittance per face of the built scene's mesh, in [0, 1]
        (:func:`surface_optics`; :func:`~zbuf_occlude.sensors.beam.echoes.attenuate_along_subray`: a gap fraction ``g`` is
        ``g``, a pane of one-way ``T`` is ``T²``); 0 everywhere: opaque.
    origins : (3,) or (P·K, 3) float
        The sub-rays' origin, world frame, metres (one, or one per sub-ray).
    max_hits : int
        Most hits cast along one sub-ray (:func:`~zbuf_occlude.sensors.raycast.embree.cast_embree_beyond`).
    """

    transmittance: ArrayLike
    origins: ArrayLike
    max_hits: int = MAX_HITS


def echo_returns(
    built: BuiltScene, rays, face, t, beam: Beam, *, max_returns: int, radiometry: Radiometry | None = None, through: Transmission | None = None
) -> tuple[NDArray[np.int64], ...]:  # fmt: skip
    """The multi-return model of every scanner: resolve each pulse's sub-ray hits into discrete returns.

    One implementation for the spinning LiDAR (:func:`~zbuf_occlude.sensors.scan.scan`) and the airborne scanner
    (:func:`~zbuf_occlude.sensors.scan.scan_airborne`).  Each sub-ray's first hit is given;
    where ``through`` gives its surface a transmittance above 0, the sub-ray is cast on through it
    (:func:`~zbuf_occlude.sensors.raycast.embree.cast_embree_beyond`, Embree) and each hit behind gets its energy times the
    transmittances of the surfaces before it on the sub-ray (:func:`~zbuf_occlude.sensors.beam.echoes.attenuate_along_subray`).
    Without ``through`` (or with 0 everywhere: opaque) only the first hits count, bit for bit.

    Parameters
    ----------
    built : BuiltScene
        The scene the rays were cast into (object of each face, triangles for the normals).
    rays : (P·K, 3) float64
        Unit sub-ray directions of P pulses, pulse-major (K sub-rays each).
    face : (P·K,) int64
        Face of each sub-ray's first hit in ``built.mesh``, −1 where it hits nothing.
    t : (P·K,) float64
        Range of that hit, metres.
    beam : Beam
        The beam whose rules resolve the echoes: each sub-ray's share of the pulse's energy
        (:meth:`~zbuf_occlude.sensors.beam.fields.Beam.footprint_weights`), ``range_resolution_m`` (echoes of one pulse
        closer than this merge, :func:`~zbuf_occlude.sensors.beam.echoes.resolve_echoes`), the range limits
        (``min_range_m``, ``max_range_m``: hits nearer or farther give no echo, the receiver's blind zone and reach; a hit in
        the blind zone still shades the hits behind it), ``min_echo_reflectance`` (the least apparent reflectance, energy ×
        range², of a detected echo; applied with or without ``radiometry``, ρ 1 without) and ``echo_rule``.
    max_returns : int
        The first this many echoes of a pulse in range order are kept (the beam's, or more for a return mode that picks among them).
    radiometry : Radiometry, optional
        Reflectivity per face, detection threshold and power noise; None: ρ 1 everywhere,
        every echo detected, no noise.
    through : Transmission, optional
        Transmittance per face and the sub-rays' origins; None: opaque, first hits only.

    Returns
    -------
    pulse : (E,) int64, row of the pulse; face : (E,) int64; range : (E,) float64, metres;
    energy : (E,) float64, m⁻² (:func:`~zbuf_occlude.sensors.beam.echoes.hit_energy`: weight · ρ · ``|cos θ|`` / R², times
    the transmittance before the hit): sorted by pulse, then range (:class:`~zbuf_occlude.sensors.beam.echoes.Echoes`).

    Raises
    ------
    InvalidInputError
        A transmittance or reflectivity that is not one value per face of ``built.mesh``.
    """
    weights = beam.footprint_weights()
    k = len(weights)
    n_pulses = len(face) // k
    min_range_m, max_range_m = beam.min_range_m, beam.max_range_m
    n_faces = len(built.face_object)
    tau = None if through is None else np.asarray(through.transmittance, dtype=np.float64)
    rho = None if radiometry is None else np.asarray(radiometry.reflectivity, dtype=np.float64)
    for name, values in (("transmittance", tau), ("reflectivity", rho)):
        if values is not None and values.shape != (n_faces,):
            raise InvalidInputError(
                f"{name} must hold one value per face of the scene ({n_faces:,}; surface_optics), got shape {values.shape}"
            )
    if tau is not None and tau.any():
        sub, f_all, r_all = cast_embree_beyond(built.mesh, through.origins, rays, face, t, tau > 0, max_hits=through.max_hits)
        share = attenuate_along_subray(sub, r_all, f_all.astype(np.int64), tau)
        kept = np.flatnonzero((r_all >= min_range_m) & (r_all <= max_range_m))
        ray, f, r, share = sub[kept], f_all[kept], r_all[kept], share[kept]
    else:
        ray = np.flatnonzero((face >= 0) & (t >= min_range_m) & (t <= max_range_m))
        f, r, share = face[ray], t[ray], None
    obj = built.face_object[f].astype(np.int64)
    normal = face_normals(built.mesh, f)
    cos = np.abs(np.einsum("ij,ij->i", normal, rays[ray]))
    pulse = ray // k
    energy = hit_energy(weights[ray % k], 1.0 if rho is None else rho[f], cos, r)
    if share is not None:
        energy = energy * share
    if radiometry is not None and radiometry.power_noise > 0:
        energy = energy * np.exp(radiometry.power_noise * radiometry.rng.standard_normal(n_pulses))[pulse]
    echoes = resolve_echoes(
        pulse, r, energy, obj, range_resolution_m=beam.range_resolution_m,
        detection_threshold=0.0 if radiometry is None else radiometry.detection_threshold, max_returns=max_returns,
        min_echo_reflectance=beam.min_echo_reflectance, echo_rule=beam.echo_rule,
    )  # fmt: skip
    return echoes.pulse, f[echoes.hit], echoes.range_m, echoes.energy


def returns_of_mode(pulse: ArrayLike, energy: ArrayLike, mode: str) -> NDArray[np.int64]:
    """Rows of resolved echoes that a receiver in return mode ``mode`` records (:data:`~zbuf_occlude.sensors.beam.fields.RETURN_MODES`).

    Parameters
    ----------
    pulse : (E,) int
        Each echo's pulse, sorted; the echoes of a pulse in range order (:func:`echo_returns`).
    energy : (E,) float
        Each echo's received energy.
    mode : {"first", "strongest", "last", "dual"}
        ``"first"``: the pulse's first (nearest) echo; ``"strongest"``: its strongest echo (the nearest of equals); ``"last"``: its last
        echo; ``"dual"``: the last and the strongest, or the last and the second strongest
        where they are one (Velodyne's dual-return mode: VLP-16 user manual 63-9243 Rev. D,
        "Dual Return Mode").

    Returns
    -------
    (R,) int64
        Rows into the echoes, ascending (still sorted by pulse, then range).
    """
    pulse = np.asarray(pulse, dtype=np.int64)
    energy = np.asarray(energy, dtype=np.float64)
    n = len(pulse)
    if n == 0:
        return np.zeros(0, np.int64)
    start = np.flatnonzero(np.r_[True, pulse[1:] != pulse[:-1]])
    last = np.r_[start[1:], n] - 1
    # strongest per pulse: order by (pulse, −energy, row) and take each pulse's first
    order = np.lexsort((np.arange(n), -energy, pulse))
    strongest = order[start]
    if mode == "strongest":
        return np.sort(strongest)
    if mode == "last":
        return last
    if mode == "first":
        return start
    if mode != "dual":
        raise InvalidInputError(f"unknown return mode {mode!r}")
    second = np.where(last - start >= 1, order[np.minimum(start + 1, n - 1)], -1)
    other = np.where(strongest == last, second, strongest)
    return np.unique(np.concatenate([last, other[other >= 0]]))
