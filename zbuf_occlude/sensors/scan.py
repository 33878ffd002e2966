"""Scans of scenes by LiDARs and depth cameras: :func:`scan` → :class:`Scan`.

A scan casts the sensor's rays from its pose into the scene's triangles (Embree: :mod:`zbuf_occlude.sensors.raycast.embree`, or the moderngl
z-buffer with exact candidate tests: :mod:`zbuf_occlude.sensors.raycast.zbuffer`), then applies the sensor model: range or depth limits,
grazing-incidence loss (cameras), Gaussian range or axial noise, depth quantisation (cameras) and independent dropout.
Points are in the sensor frame by default (LiDAR: x forward, z up; camera: OpenCV), like real scans.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.sampling import check_seed
from zbuf_occlude.resources import check_memory
from zbuf_occlude.sensors.beam.adaptive_cast import adaptive_echo_returns, adaptive_footprint
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.patterns.depth_camera import DepthCamera
from zbuf_occlude.sensors.beam.echo_energy import Radiometry, Transmission, echo_returns, returns_of_mode, strongest_echo, surface_optics
from zbuf_occlude.sensors.beam.echoes import MAX_RETURNS, number_returns
from zbuf_occlude.sensors.kinds import SensorKind, kind_of
from zbuf_occlude.sensors.platform import Trajectory, as_pose
from zbuf_occlude.sensors.pulses import Pulses
from zbuf_occlude.sensors.raycast.embree import BACKENDS, cast_embree, face_normals
from zbuf_occlude.sensors.raycast.zbuffer import ZBufferView, cast_zbuffer
from zbuf_occlude.sensors.scene.materials import on_crown
from zbuf_occlude.sensors.scan_data import FRAMES, Scan
from zbuf_occlude.sensors.scene.objects import BuiltScene, ScanScene, SceneObject

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = ["scan", "scan_airborne", "scanned_by", "fire_pulses", "build_scene", "return_numbers"]


def _built(scene) -> BuiltScene:
    import trimesh

    if isinstance(scene, ScanScene):
        return scene.build()
    if isinstance(scene, trimesh.Trimesh):
        # A bare mesh: metres, world frame as given, object id 1, no ground.
        f = len(scene.faces)
        return BuiltScene(
            scene, np.ones(f, np.int32), np.arange(f, dtype=np.int64), [SceneObject(scene)], [np.eye(4), np.eye(4)], [None, scene]
        )
    if isinstance(scene, BuiltScene):
        return scene
    raise InvalidInputError(f"scan needs a ScanScene or a trimesh.Trimesh, got {type(scene).__name__}")


def build_scene(scene) -> BuiltScene:
    """The triangles of a :class:`ScanScene` or a bare mesh (object id 1, no ground) for ray casting."""
    return _built(scene)


#: :func:`scan_airborne`'s default surface optics: the material table for a radiometric multi-return beam, else none.
AUTO_OPTICS = "auto"
#: Bytes one sub-ray holds while a scan runs (its direction, origin, hit, range and echo arrays, float64 and int64),
#: what :func:`fire_pulses` checks against the memory available before it casts.
SUBRAY_BYTES = 160
#: Bytes each pair of a pulse's sub-rays holds where one return a pulse is its footprint's strongest echo
#: (:func:`~zbuf_occlude.sensors.beam.echo_energy.strongest_echo`: a same-object matrix, its temporaries and the einsum over it).
SUBRAY_PAIR_BYTES = 24


def _surface_optics(built: BuiltScene, beam: Beam, backend: str, reflectivity, transmittance):
    """A pulsed scan's ``reflectivity`` and ``transmittance`` per face (:func:`~zbuf_occlude.sensors.beam.echo_energy.surface_optics` at the beam's wavelength)."""
    if reflectivity is None and transmittance is None:
        return None, None
    return surface_optics(
        built, reflectivity, transmittance, wavelength_nm=beam.wavelength_nm, multi_return=beam.resolves_echoes, backend=backend
    )


def _cast(built: BuiltScene, origin, rays, backend: str, meta: dict, *, zbuffer: ZBufferView, near_far):
    """First hit ``(face, t)`` of every ray with ``backend``; the z-buffer's fallback count goes into ``meta``."""
    if backend == "embree":
        return cast_embree(built.mesh, origin, rays)
    near, far = near_far
    face, t, n_fallback = cast_zbuffer(built.mesh, origin, rays, resolution=zbuffer.resolution, neighborhood=zbuffer.neighborhood,
                                       znear=max(min(0.05, near * 0.5), 1e-3), zfar=far * 1.5 + 1.0)  # fmt: skip
    meta["n_fallback"] = n_fallback
    return face, t


def _facing_normals(built: BuiltScene, face, d_world):
    """Unit normals of the hit faces turned to face the sensor, ``cos`` of the ray with the face's own
    normal, and the incidence angle in degrees."""
    normal = face_normals(built.mesh, face)
    cos_in = np.einsum("ij,ij->i", normal, d_world)
    normal[cos_in > 0] *= -1.0  # face the sensor
    incidence = np.degrees(np.arccos(np.clip(np.abs(cos_in), 0.0, 1.0)))
    return normal, cos_in, incidence


def scanned_by(sensor, seed) -> tuple[SensorKind, int]:
    """The kind of ``sensor`` (:func:`~zbuf_occlude.sensors.kinds.kind_of`) and ``seed`` checked
    (:func:`~zbuf_occlude.geometry.sampling.check_seed`): what every scan checks before any work
    (:func:`scan`, :func:`scan_airborne`, :func:`~zbuf_occlude.sensors.crops.object_crop`).  numpy's own
    refusals of a seed of -1, 'a' or 1.5 came after the rays were cast, and named no argument.

    Raises
    ------
    InvalidInputError
        Not a sensor of any kind; a seed ``check_seed`` refuses.
    """
    return kind_of(sensor), check_seed(seed)


def _checked_arguments(sensor, seed, backend: str, frame: str) -> tuple[SensorKind, int]:
    """:func:`scan`'s sensor and seed (:func:`scanned_by`), backend and frame, checked before any work."""
    if backend not in BACKENDS:
        raise InvalidInputError(f"unknown scan backend {backend!r}; use one of {BACKENDS}")
    if frame not in FRAMES:
        raise InvalidInputError(f"unknown frame {frame!r}; use one of {FRAMES}")
    return scanned_by(sensor, seed)


def _platform(pose, scene):
    """``scan``'s ``pose``: a (4, 4) sensor → world matrix, or a :class:`~zbuf_occlude.sensors.platform.Trajectory` as given."""
    if isinstance(pose, Trajectory):
        return pose
    if pose is None:
        if not isinstance(scene, ScanScene):
            raise InvalidInputError("scan of a bare mesh needs a sensor pose")
        pose = scene.default_sensor_pose()
    return as_pose(pose)


def scan(
    scene: ScanScene | trimesh.Trimesh,
    sensor,
    pose: ArrayLike | Trajectory | None = None,
    *,
    seed: int = 0,
    backend: str = "embree",
    frame: str = "sensor",
    azimuth_range_deg: tuple[float, float] | None = None,
    zbuffer: ZBufferView = ZBufferView(),
    reflectivity: float | ArrayLike | str | None = None,
    transmittance: float | ArrayLike | str | None = None,
    footprint: str = "auto",
) -> Scan:
    """Scan ``scene`` with ``sensor`` at ``pose`` (or along a trajectory).

    Parameters
    ----------
    scene : ScanScene or trimesh.Trimesh
        A mesh is taken as one object (id 1) in metres, world frame, with no ground.
    sensor : Lidar, RayTable or DepthCamera
        An airborne scanner flies its own plan: :func:`scan_airborne`.
    pose : (4, 4) or (3,) float, or Trajectory, optional
        Sensor → world transform (LiDAR frame: x forward, z up; camera frame: OpenCV, see
        :func:`look_at_pose`), or just the position; default ``scene.default_sensor_pose()``.
        A :class:`~zbuf_occlude.sensors.platform.Trajectory` moves a LiDAR or ray table during
        its sweep: each pulse leaves from the pose at its own time (the sweep starts at the
        trajectory's start), so a moving scanner's sweep has the motion distortion of a real one.
    seed : int, numpy.random.Generator or None
        Seeds noise and dropout (``numpy.random.default_rng(seed)``); same seed, same bytes.
    backend : {"embree", "zbuffer"}
        Ray casting (:mod:`zbuf_occlude.sensors.raycast.embree`); "embree" is the reference.  "zbuffer" renders from one
        point: a scanner standing still.
    frame : {"sensor", "world"}
        Frame of ``points``, ``normal`` and ``sensor_position``.  On a trajectory, "sensor" is each
        pulse's own sensor frame at its time: the raw, motion-distorted sweep a driver reports.
    azimuth_range_deg : (lo, hi), optional
        LiDAR and ray table only: fire only in this azimuth sector (degrees, sensor frame), to save time.
    zbuffer : ZBufferView
        "zbuffer" backend: view size in pixels and candidate window radius.
    reflectivity : float or (n_objects + 1,) float, optional
        Any pulsed sensor (a LiDAR or a ray table; a depth camera refuses it): Lambertian
        reflectivity ρ of every surface, or per object id (index 0: the ground).  Given, a
        return is kept only when its received power clears the beam's threshold,
        ``ρ · cos θ · f / R² · exp(σ z) ≥ τ`` (:class:`~zbuf_occlude.sensors.beam.fields.Beam` ``detection_threshold``,
        ``power_noise`` σ, z ~ N(0, 1) per firing, ``f`` the footprint fraction).  None: every
        hit returns (no radiometric detection).  With the multi-return model (the beam resolves
        echoes), ρ weighs each sub-ray's echo and the threshold applies per echo.  ``"table"``:
        each object's ρ from its material at the beam's wavelength
        (:func:`~zbuf_occlude.sensors.scene.materials.scene_optics`; the ground: asphalt).
    transmittance : float or (n_objects + 1,) float, optional
        A pulsed sensor whose beam resolves echoes (``Beam.resolves_echoes``: ``max_returns``
        above 1 or a Velodyne return mode) only: round-trip transmittance per object id, in
        [0, 1] (a gap fraction for foliage, ``T²`` for a pane); sub-rays go on through such
        surfaces (Embree: all hits along each sub-ray, :func:`~zbuf_occlude.sensors.raycast.embree.cast_embree_beyond`) and
        the hits behind return their energy times the transmittances before them.
        ``"table"``: from each object's material (:func:`~zbuf_occlude.sensors.scene.materials.scene_optics`: foliage
        :data:`~zbuf_occlude.sensors.scene.materials.FOLIAGE_GAP_FRACTION`).  None or 0 everywhere: opaque, first hits
        only, bit for bit as without it.  The "zbuffer" backend keeps the nearest face per
        pixel only and refuses a transmittance above 0.
    footprint : {"auto", "exact", "adaptive"}
        How a beam that resolves echoes casts its footprint.  "adaptive": only where the centre
        ray and its neighbouring pulses do not show one plane filling the footprint
        (:mod:`zbuf_occlude.sensors.beam.adaptive_cast`: approximate, the echo of a surface inside the cone that
        neither the centre ray nor a neighbour meets is lost; ``benchmarks/bench_returns.py``
        measures its speed and bias); it needs a beam that resolves echoes with
        ``footprint_rays`` above 1 (``Beam.resolves_footprint``) and the "embree" backend.
        "exact": every sub-ray of every pulse.  "auto" (default): "adaptive" where it applies,
        else "exact".

    Returns
    -------
    Scan
        One point per return (:func:`fire_pulses`).  A depth camera's scan has no return fields.

    Raises
    ------
    InvalidInputError
        A negative, too large or non-integer ``seed``; bad pose, frame, backend or scene; a
        bad ``reflectivity`` or ``transmittance``, or a transmittance above 0 with the
        "zbuffer" backend or with a beam that does not resolve echoes, or either for a depth
        camera; an airborne scanner (use :func:`scan_airborne`); a trajectory with the
        "zbuffer" backend or a depth camera, or shorter than the sweep; an unknown
        ``footprint``, or "adaptive" where it does not apply (above).
    BackendUnavailable
        Embree or OpenGL missing for the chosen backend.
    """
    kind, seed = _checked_arguments(sensor, seed, backend, frame)
    built = _built(scene)
    platform = _platform(pose, scene)
    if not kind.pulsed:
        if footprint not in ("auto", "exact"):
            raise InvalidInputError(
                f"footprint {footprint!r:.40}: a {kind.title} has no beam ('auto' or 'exact'; 'adaptive' is for a LiDAR)"
            )
        if isinstance(platform, Trajectory):
            raise InvalidInputError(f"a {kind.title} takes one pose, not a trajectory")
        return _scan_camera(built, sensor, platform, seed, backend=backend, frame=frame, zbuffer=zbuffer, reflectivity=reflectivity,
                            transmittance=transmittance)  # fmt: skip
    if kind.flies:
        raise InvalidInputError(f"{sensor.name!r} is an airborne scanner: it flies its own plan (scan_airborne)")
    pulses = sensor.pulses(platform, azimuth_range_deg)
    pose_matrix = platform if isinstance(platform, np.ndarray) else platform.pose_at(platform.start_s)
    return fire_pulses(
        built, sensor.beam, pulses, np.random.default_rng(seed), sensor_name=sensor.name, sensor_to_world=pose_matrix,
        backend=backend, frame=frame, zbuffer=zbuffer, optics=(reflectivity, transmittance),
        footprint=footprint,
    )  # fmt: skip


def scan_airborne(scene, scanner, center_xy=(0.0, 0.0), half_size_m: float = 10.0, *, seed: int = 0,
                  phase_s: float | None = None, lateral_shift_m=None, reflectivity="auto", transmittance="auto",
                  footprint: str = "auto") -> Scan:  # fmt: skip
    """Scan the part of ``scene`` around ``center_xy`` from every line of an airborne scanner's flight plan; world frame.

    The pulses are :meth:`AirborneScanner.pulses <zbuf_occlude.sensors.patterns.airborne.AirborneScanner.pulses>`
    (every line's pulses whose flat-ground footprint falls in the square ``center_xy ±
    half_size_m`` of its own frame, merged, each keeping its line id), fired by the one
    pipeline (:func:`fire_pulses`) with the scanner's beam.

    Parameters
    ----------
    scene : ScanScene or trimesh.Trimesh
        World frame, metres, ground at z = 0 (a bare mesh: as given).
    scanner : AirborneScanner
    center_xy, half_size_m
        The square of flat ground whose pulses are cast, metres.
    seed : int
        Noise, dropout and what is drawn (the lines' phases and shifts first).
    phase_s, lateral_shift_m : optional
        As :meth:`AirborneScanner.pulses <zbuf_occlude.sensors.patterns.airborne.AirborneScanner.pulses>`.
    reflectivity, transmittance : optional
        As :func:`scan`'s, at the beam's wavelength (1064 nm for the airborne presets).  ``"auto"``
        (default) for both: a beam that resolves echoes and scales intensities (every airborne
        preset's, and a sensor fitted to a LAS file) takes ``"table"`` for both, the materials'
        reflectances and foliage's gap fraction (:func:`~zbuf_occlude.sensors.scene.materials.scene_optics`),
        which its intensities and its returns through a canopy rest on; any other beam none.  Each
        ``"auto"`` is decided on its own: giving one of them leaves the other as ``"auto"`` makes it.
        None: none (opaque surfaces; a detection threshold applies with ρ = 1).
    footprint : {"auto", "exact", "adaptive"}
        As :func:`scan`'s.

    Returns
    -------
    Scan
        ``frame="world"`` (the aircraft moves: no one sensor frame), ``ring`` and ``pixel`` None,
        ``sensor_position`` the mean aircraft position of the returns.  ``meta``:
        ``scan_angle_deg`` (N,) float64 and ``line_id`` (N,) int32 per return; ``phase_s`` (the
        first line's), ``line_phase_s`` (per line, by id), ``lateral_shift_m`` (per heading),
        ``line_length_m``, ``line_start_s`` (per line, by id), ``trajectory`` (the aircraft's flight,
        :mod:`~zbuf_occlude.sensors.patterns.flight_times`; none for a block whose lines reach beyond
        :data:`~zbuf_occlude.sensors.checks.MAX_COORDINATE_M`), ``n_rays``.  The return fields: ``pulse_id`` the
        pulse's row among all the plan's pulses, ``gps_time`` its firing time on the plan's clock (the lines
        flown one after another from 0 on), ``scan_angle_deg`` the across-track angle signed as ASPRS LAS 1.4
        defines it (``−meta["scan_angle_deg"]``).  The same seed gives the same bytes.

    Raises
    ------
    InvalidInputError
        A seed :func:`~zbuf_occlude.geometry.sampling.check_seed` refuses; what
        :meth:`~zbuf_occlude.sensors.patterns.airborne.AirborneScanner.pulses` refuses; a reflectivity or
        transmittance out of range, or a transmittance above 0 without the multi-return model.
    """
    kind, seed = scanned_by(scanner, seed)  # before the scene is built: numpy would refuse -1 or 'a' only when drawing
    if not kind.flies:
        raise InvalidInputError(f"scan_airborne flies an airborne scanner, got {type(scanner).__name__}")
    built = _built(scene)
    auto = [isinstance(v, str) and v == AUTO_OPTICS for v in (reflectivity, transmittance)]
    radiometric = scanner.beam.resolves_echoes and scanner.beam.intensity_scale is not None
    fill = "table" if radiometric else None  # each "auto" on its own: a transmittance given keeps the table's reflectances
    reflectivity, transmittance = (fill if a else v for a, v in zip(auto, (reflectivity, transmittance)))
    rng = np.random.default_rng(seed)
    pulses = scanner.pulses(center_xy, half_size_m, rng, phase_s=phase_s, lateral_shift_m=lateral_shift_m)
    s = fire_pulses(built, scanner.beam, pulses, rng, sensor_name=scanner.name, sensor_to_world=None, frame="world",
                    optics=(reflectivity, transmittance), footprint=footprint)  # fmt: skip
    time_s, position_m, rotation = s.meta.pop("flight")
    if Trajectory.holds(position_m):  # a block reaching beyond a trajectory's bound writes none
        s.meta["trajectory"] = Trajectory(time_s, position_m, rotation, name=scanner.name)
    return s


def fire_pulses(
    built: BuiltScene, beam: Beam, pulses: Pulses, rng: np.random.Generator, *, sensor_name: str, sensor_to_world,
    backend: str = "embree", frame: str = "sensor", zbuffer: ZBufferView = ZBufferView(), optics=(None, None),
    footprint: str = "auto",
) -> Scan:  # fmt: skip
    """The one pipeline: cast ``pulses`` with ``beam``, resolve their echoes, add noise and loss, and make the :class:`Scan`.

    Whatever the pattern and the platform: each pulse's ``beam.footprint_rays`` sub-rays are cast
    from its origin; one return per pulse is the centre ray's first hit or the footprint's
    strongest echo (:func:`~zbuf_occlude.sensors.beam.echo_energy.strongest_echo`), several are the resolved echoes
    (:func:`~zbuf_occlude.sensors.beam.echo_energy.echo_returns`, then the beam's ``return_mode``); then range noise,
    dropout and the beam's ray drop on crowns (each drawn for every hit, so filters do not shift
    the streams), the range limits on the measured range and, where reflectivities are given
    (or the pattern detects with a default ρ), the detection threshold.  Points lie on each pulse's centre direction at the measured
    range.  With the beam's ``intensity_scale`` set, every return's intensity is its received
    energy (ρ = 1 where no reflectivity is given); without, a single return without
    reflectivities has intensity 1.0.

    Parameters
    ----------
    built : BuiltScene
    beam : Beam
    pulses : Pulses
    rng : numpy.random.Generator
        Drawn from in a fixed order: power noise of the echoes, range noise, dropout, ray drop on
        crowns (only where ``beam.foliage_dropout`` is above 0), then the single return's power noise.
    sensor_name : str
    sensor_to_world : (4, 4) float64 or None
        The scan's ``sensor_to_world``; None: a translation to the mean origin of the returns.
    backend, frame, zbuffer, footprint, optics
        As :func:`scan`'s; ``optics`` is its ``(reflectivity, transmittance)``.

    Raises
    ------
    InvalidInputError
        As :func:`scan`: "zbuffer" or a sensor frame where the pulses leave from more than one
        point and the pattern has no sensor frame.
    """
    if not pulses.static and backend != "embree":
        raise InvalidInputError(f"backend {backend!r:.40} renders from one point: a moving scanner needs the embree backend")
    if frame == "sensor" and not pulses.has_sensor_frame:
        raise InvalidInputError(f"{sensor_name!r} moves along its flight lines: its points have no one sensor frame; use the world frame")
    meta: dict = {"backend": backend, "n_rays": len(pulses), **pulses.meta}
    if not pulses.static and pulses.has_sensor_frame:
        meta["moving"] = True  # each point in its own pulse's frame when frame="sensor" (Scan.to_las_bytes refuses to classify it)
    k = beam.footprint_rays
    # one return a pulse from a footprint compares every sub-ray with every other (strongest_echo: pulses × K × K booleans and floats)
    pair_bytes = 0 if k == 1 or beam.resolves_echoes else k * SUBRAY_PAIR_BYTES
    check_memory(len(pulses) * k * (SUBRAY_BYTES + pair_bytes), f"{len(pulses):,} pulses × footprint_rays {k} of {sensor_name}",
                 hint="take fewer footprint_rays, or scan fewer pulses (a sector, a smaller square)")  # fmt: skip
    multi, adaptive = beam.resolves_echoes, adaptive_footprint(footprint, beam, backend)
    d_world = pulses.directions
    rho, tau = _surface_optics(built, beam, backend, *optics)
    if rho is None and pulses.default_reflectivity is not None and beam.detection_threshold > 0:
        rho = np.full(len(built.face_object), float(pulses.default_reflectivity))
    radiometry = None if rho is None else Radiometry(rho, beam.detection_threshold, beam.power_noise, rng)
    most = beam.max_returns if beam.return_mode == "all" else MAX_RETURNS
    if adaptive:  # the centre rays first; the footprints that are not one plane cast in full
        hit, face, t, power, uniform = adaptive_echo_returns(
            built, beam, pulses, max_returns=most, radiometry=radiometry, transmittance=tau
        )
        meta["footprint_uniform_share"] = float(uniform.mean()) if len(uniform) else 0.0
    else:
        rays = d_world if k == 1 else beam.footprint_directions(d_world).reshape(-1, 3)
        origin = pulses.origins if pulses.static or k == 1 else np.repeat(pulses.origins, k, axis=0)
        face, t = _cast(built, origin, rays, backend, meta, zbuffer=zbuffer,
                        near_far=(beam.min_range_m, beam.max_range_m))  # fmt: skip
    if multi:
        if not adaptive:
            hit, face, t, power = echo_returns(
                built, rays, face, t, beam, max_returns=most, radiometry=radiometry,
                through=None if tau is None else Transmission(tau, origin),
            )  # fmt: skip
        if beam.return_mode != "all":
            chosen = returns_of_mode(hit, power, beam.return_mode)
            hit, face, t, power = hit[chosen], face[chosen], t[chosen], power[chosen]
    else:
        if k > 1:
            weights = beam.footprint_weights() if beam.profile != "tophat" else None
            face, t, fraction = strongest_echo(built, rays, face, t, k, rho, beam.echo_separation_m, weights)
        hit = np.flatnonzero(face >= 0)
        face, t = face[hit], t[hit]
    normal, cos_in, incidence = _facing_normals(built, face, d_world[hit])
    gauss = rng.standard_normal(len(hit))  # drawn for every hit, so filters do not shift streams
    lost = rng.random(len(hit)) < beam.dropout_probability(t)
    if beam.foliage_dropout > 0:  # drawn for every hit after dropout's, so a beam without it keeps its streams
        lost |= (rng.random(len(hit)) < beam.foliage_dropout) & on_crown(built, face)
    measured = t + beam.range_noise_m * gauss  # limits apply to what the sensor measures
    keep = (measured >= beam.min_range_m) & (measured <= beam.max_range_m) & ~lost
    if not multi:
        radiometric, relative = rho is not None or beam.intensity_scale is not None, beam.min_echo_reflectance > 0
        if radiometric or relative:
            # received power of an extended Lambertian target (Kashani et al. 2015, Eq. 4), ρ = 1 without reflectivities
            reflected = fraction[hit] if k > 1 else (np.abs(cos_in) if rho is None else rho[face] * np.abs(cos_in))
        power = reflected / np.maximum(t, 1e-9) ** 2 if radiometric else np.ones(len(hit))
        if rho is not None:
            if beam.power_noise > 0:
                power = power * np.exp(beam.power_noise * rng.standard_normal(len(hit)))
            keep &= power >= beam.detection_threshold
        if relative:  # the apparent reflectance E · R²: ρ |cos θ| times the footprint's share (Beam.min_echo_reflectance)
            keep &= (power * np.maximum(t, 1e-9) ** 2 if radiometric else reflected) >= beam.min_echo_reflectance
    keep &= measured > 0
    sel = np.flatnonzero(keep)
    rows = hit[sel]
    return_number, number_of_returns = return_numbers(rows, renumber=multi)
    points, normal_out, position, pose = _placed_points(pulses, rows, measured[sel], normal[sel], frame, sensor_to_world)
    meta.update({key: values[rows] for key, values in pulses.per_pulse_meta.items()})
    return Scan(
        points=points.astype(np.float32),
        ring=None if pulses.ring is None else pulses.ring[rows].astype(np.int32),
        pixel=None,
        range_m=measured[sel].astype(np.float32),
        face_index=built.face_local[face[sel]],
        object_id=built.face_object[face[sel]],
        normal=normal_out.astype(np.float32),
        incidence_deg=incidence[sel].astype(np.float32),
        frame=frame,
        sensor_position=position,
        sensor_to_world=pose,
        sensor=sensor_name,
        meta=meta,
        return_number=return_number,
        number_of_returns=number_of_returns,
        intensity=np.asarray(power[sel], dtype=np.float32),
        pulse_id=pulses.pulse_id[rows],
        gps_time=pulses.time_s[rows],
        scan_angle_deg=pulses.scan_angle_deg[rows],
        intensity_scale=beam.intensity_scale,
        max_intensity=beam.max_intensity,
        intensity_unit=beam.intensity_unit,
        object_classes=object_classes(built),
    )


def object_classes(built: BuiltScene) -> tuple[str, ...]:
    """The class name of each object id of ``built`` (index 0: ``"ground"``), what a scan's LAS file classifies by."""
    return ("ground", *(obj.class_name for obj in built.objects))


def _placed_points(pulses: Pulses, rows, measured, normal, frame: str, sensor_to_world):
    """``(points, normals, sensor_position, sensor_to_world)`` of returns of pulse rows ``rows`` at ranges ``measured`` in ``frame``."""
    if pulses.static:
        rot, origin = pulses.rotation, pulses.origins
        points = pulses.directions_sensor[rows] * measured[:, None]
        if frame == "world":
            return points @ rot.T + origin, normal, origin.copy(), sensor_to_world
        return points, normal @ rot, np.zeros(3), sensor_to_world
    if frame == "sensor":  # each pulse's own frame at its time: the raw sweep
        sensor_normal = np.einsum("pj,pjk->pk", normal, pulses.rotations[rows])  # Rᵀ n, world → each pulse's sensor frame
        return pulses.directions_sensor[rows] * measured[:, None], sensor_normal, np.zeros(3), sensor_to_world
    o, d = pulses.origins[rows], pulses.directions[rows]
    position = o.mean(axis=0) if len(o) else pulses.home()
    if sensor_to_world is None:
        sensor_to_world = np.eye(4)
        sensor_to_world[:3, 3] = position
    return o + d * measured[:, None], normal, position, sensor_to_world


def _scan_camera(built: BuiltScene, camera: DepthCamera, m, seed: int, *, backend: str, frame: str, zbuffer: ZBufferView,
                 reflectivity, transmittance) -> Scan:  # fmt: skip
    """A depth camera's frame: its pixels' rays cast from pose ``m``, then depth limits, grazing-incidence loss, axial
    noise, quantisation and dropout (:class:`~zbuf_occlude.sensors.patterns.depth_camera.DepthCamera`)."""
    if reflectivity is not None or transmittance is not None:
        what = "reflectivity (radiometric detection)" if reflectivity is not None else "transmittance (hits behind a surface)"
        raise InvalidInputError(f"{what} is modelled for LiDARs only")
    rot, origin = m[:3, :3], m[:3, 3]
    d_cam, pixel = camera.rays()
    d_sensor = d_cam / np.linalg.norm(d_cam, axis=1, keepdims=True)
    d_world = d_sensor @ rot.T
    meta: dict = {"backend": backend, "n_rays": len(d_world)}
    near_far = (camera.min_depth_m, camera.max_depth_m / float(d_sensor[:, 2].min()))
    face, t = _cast(built, origin, d_world, backend, meta, zbuffer=zbuffer, near_far=near_far)
    rng = np.random.default_rng(seed)
    hit = np.flatnonzero(face >= 0)
    face, t = face[hit], t[hit]
    d_s = d_sensor[hit]
    normal, _, incidence = _facing_normals(built, face, d_world[hit])
    gauss = rng.standard_normal(len(hit))
    lost = rng.random(len(hit)) < camera.dropout
    cos_axis = d_s[:, 2]  # depth = t · cos(angle to the optical axis)
    depth_measured = camera.quantize(t * cos_axis + camera.sigma_m(t * cos_axis, incidence) * gauss)
    measured = depth_measured / cos_axis
    in_range = (depth_measured >= camera.min_depth_m) & (depth_measured <= camera.max_depth_m)
    keep = in_range & (incidence <= camera.max_incidence_deg) & ~lost & (measured > 0)
    sel = np.flatnonzero(keep)
    points = d_s[sel] * measured[sel, None]
    normal_out = normal[sel] @ rot  # world → sensor
    sensor_position = np.zeros(3)
    if frame == "world":
        points = points @ rot.T + origin
        normal_out = normal[sel]
        sensor_position = origin.copy()
    return Scan(
        points=points.astype(np.float32), ring=None, pixel=pixel[hit][sel].astype(np.int32), range_m=measured[sel].astype(np.float32),
        face_index=built.face_local[face[sel]], object_id=built.face_object[face[sel]], normal=normal_out.astype(np.float32),
        incidence_deg=incidence[sel].astype(np.float32), frame=frame, sensor_position=sensor_position, sensor_to_world=m,
        sensor=camera.name, meta=meta, object_classes=object_classes(built),
    )  # fmt: skip


def return_numbers(pulse, *, renumber: bool) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """``return_number`` and ``number_of_returns`` (N,) uint8 of points of pulse rows ``pulse`` (N,), sorted.

    With ``renumber``, the points of one pulse (in range order) are numbered 1..n and each carries
    n (:func:`~zbuf_occlude.sensors.beam.echoes.number_returns`); otherwise every point is its pulse's only return (1 of 1).
    """
    if renumber:
        return number_returns(pulse)
    ones = np.ones(len(pulse), np.uint8)
    return ones, ones.copy()
