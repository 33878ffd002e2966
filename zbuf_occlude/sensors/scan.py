"""Scans of scenes by LiDARs and depth cameras: :func:`scan` → :class:`Scan`.

A scan casts the sensor's rays from its pose into the scene's triangles (Embree, or the
moderngl z-buffer with exact candidate tests: :mod:`.raycast`), then applies the sensor model:
range or depth limits, grazing-incidence loss (cameras), Gaussian range or axial noise,
depth quantisation (cameras) and independent dropout.  Points are in the sensor frame by
default (LiDAR: x forward, z up; camera: OpenCV), like real scans.
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.sampling import check_seed
from zbuf_occlude.sensors.depth_camera import DepthCamera
from zbuf_occlude.sensors.echo_model import Radiometry, Transmission, echo_returns, strongest_echo, surface_optics
from zbuf_occlude.sensors.echoes import number_returns
from zbuf_occlude.sensors.lidar import Lidar
from zbuf_occlude.sensors.ray_table import RayTable
from zbuf_occlude.sensors.raycast import BACKENDS, cast_embree, cast_zbuffer, face_normals
from zbuf_occlude.sensors.scan_data import FRAMES, Scan
from zbuf_occlude.sensors.scene import BuiltScene, ScanScene, SceneObject

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = ["scan", "look_at_pose", "build_scene", "return_numbers"]


def look_at_pose(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> NDArray[np.float64]:
    """(4, 4) float64 camera → world transform of an OpenCV camera (x right, y down, z forward)
    at ``eye`` looking at ``target`` (world frame, metres).

    Raises
    ------
    InvalidInputError
        ``eye == target`` or ``up`` parallel to the view direction.
    """
    eye, target, up = (np.asarray(v, dtype=np.float64).reshape(3) for v in (eye, target, up))
    z = target - eye
    if np.linalg.norm(z) == 0:
        raise InvalidInputError("look_at_pose: eye and target coincide")
    z /= np.linalg.norm(z)
    x = np.cross(z, up)  # right of the view direction, with up above it: y = z × x points down
    if np.linalg.norm(x) < 1e-9:
        raise InvalidInputError(f"look_at_pose: up {up} is parallel to the view direction")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, :3] = np.column_stack([x, y, z])
    m[:3, 3] = eye
    return m


def _as_pose(pose) -> NDArray[np.float64]:
    m = np.asarray(pose, dtype=np.float64)
    if m.shape == (3,):
        out = np.eye(4)
        out[:3, 3] = m
        m = out
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise InvalidInputError(f"sensor pose must be a (4, 4) sensor → world matrix or a (3,) position, got shape {m.shape}")
    r = m[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
        raise InvalidInputError("sensor pose rotation must be orthonormal and right-handed (no scale)")
    return m


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


def _surface_optics(built: BuiltScene, sensor, backend: str, reflectivity, transmittance):
    """``scan``'s ``reflectivity`` and ``transmittance`` for ``sensor`` (:func:`~.echo_model.surface_optics` at 905 nm)."""
    if reflectivity is None and transmittance is None:
        return None, None
    if not isinstance(sensor, _PULSED):
        what = "reflectivity (radiometric detection)" if reflectivity is not None else "transmittance (hits behind a surface)"
        raise InvalidInputError(f"{what} is modelled for LiDARs only")
    from zbuf_occlude.sensors.reflectance import SPINNING_WAVELENGTH_NM

    return surface_optics(
        built, reflectivity, transmittance, wavelength_nm=SPINNING_WAVELENGTH_NM, multi_return=sensor.multi_return, backend=backend
    )


def _echo_returns(
    built: BuiltScene, sensor: Lidar, rays, face, t, rho, rng, *, origin=None, transmittance=None
) -> tuple[NDArray[np.int64], ...]:
    """The spinning LiDAR's multi-return model: :func:`~.echo_model.echo_returns` with ``sensor``'s footprint,
    range limits (the receiver's blind zone and reach), range resolution, maximum returns, and
    detection threshold and power noise when ``rho`` is given; the hits behind surfaces of
    ``transmittance`` above 0, cast from ``origin``."""
    radiometry = None if rho is None else Radiometry(rho, sensor.detection_threshold, sensor.power_noise, rng)
    return echo_returns(
        built, rays, face, t, sensor.footprint_weights(), range_resolution_m=sensor.range_resolution_m, max_returns=sensor.max_returns,
        radiometry=radiometry, range_limits_m=(sensor.min_range_m, sensor.max_range_m),
        through=None if transmittance is None else Transmission(transmittance, origin),
    )  # fmt: skip


#: Sensors that fire pulses and record returns: a spinning LiDAR, or a table of its rays.
_PULSED = (Lidar, RayTable)


def _sensor_rays(sensor, azimuth_range_deg):
    """``(d_sensor (N, 3) unit, ring or None, pulses or None, pixel or None, (near, far) ranges along the ray)``.

    ``pulses(rows)``: the ``pulse_id``, ``gps_time`` and ``scan_angle_deg`` of the points of ray
    rows ``rows`` (:func:`_return_fields`); None for a depth camera.
    """
    if isinstance(sensor, Lidar):
        d_sensor, ring, azimuth = sensor.rays(azimuth_range_deg)
        return d_sensor, ring, partial(_sweep_pulses, sensor, ring, azimuth), None, (sensor.min_range_m, sensor.max_range_m)
    if isinstance(sensor, RayTable):
        d_sensor, row, _ = sensor.rays(azimuth_range_deg)
        return d_sensor, None, partial(_table_pulses, sensor, row), None, (sensor.min_range_m, sensor.max_range_m)
    if isinstance(sensor, DepthCamera):
        d_cam, pixel = sensor.rays()
        d_sensor = d_cam / np.linalg.norm(d_cam, axis=1, keepdims=True)
        return d_sensor, None, None, pixel, (sensor.min_depth_m, sensor.max_depth_m / float(d_sensor[:, 2].min()))
    raise InvalidInputError(f"sensor must be a Lidar, a RayTable or a DepthCamera, got {type(sensor).__name__}")


def _cast(built: BuiltScene, origin, rays, backend: str, meta: dict, *, resolution: int, neighborhood: int, near_far):
    """First hit ``(face, t)`` of every ray with ``backend``; the z-buffer's fallback count goes into ``meta``."""
    if backend == "embree":
        return cast_embree(built.mesh, origin, rays)
    near, far = near_far
    face, t, n_fallback = cast_zbuffer(built.mesh, origin, rays, resolution=resolution, neighborhood=neighborhood,
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


def _checked_arguments(seed, backend: str, frame: str):
    """:func:`scan`'s seed (:func:`~zbuf_occlude.geometry.sampling.check_seed`), backend and frame, checked before any
    work: numpy's own refusals of a seed of -1, 'a' or 1.5 came after the rays were cast, and named no argument."""
    if backend not in BACKENDS:
        raise InvalidInputError(f"unknown scan backend {backend!r}; use one of {BACKENDS}")
    if frame not in FRAMES:
        raise InvalidInputError(f"unknown frame {frame!r}; use one of {FRAMES}")
    return check_seed(seed)


def scan(
    scene: ScanScene | trimesh.Trimesh,
    sensor: Lidar | RayTable | DepthCamera,
    pose: ArrayLike | None = None,
    *,
    seed: int = 0,
    backend: str = "embree",
    frame: str = "sensor",
    azimuth_range_deg: tuple[float, float] | None = None,
    resolution: int = 2048,
    neighborhood: int = 1,
    reflectivity: float | ArrayLike | str | None = None,
    transmittance: float | ArrayLike | str | None = None,
) -> Scan:
    """Scan ``scene`` with ``sensor`` at ``pose``.

    Parameters
    ----------
    scene : ScanScene or trimesh.Trimesh
        A mesh is taken as one object (id 1) in metres, world frame, with no ground.
    sensor : Lidar, RayTable or DepthCamera
    pose : (4, 4) or (3,) float, optional
        Sensor → world transform (LiDAR frame: x forward, z up; camera frame: OpenCV, see
        :func:`look_at_pose`), or just the position; default ``scene.default_sensor_pose()``.
    seed : int, numpy.random.Generator or None
        Seeds noise and dropout (``numpy.random.default_rng(seed)``); same seed, same bytes.
    backend : {"embree", "zbuffer"}
        Ray casting (:mod:`.raycast`); "embree" is the reference.
    frame : {"sensor", "world"}
        Frame of ``points``, ``normal`` and ``sensor_position``.
    azimuth_range_deg : (lo, hi), optional
        LiDAR only: fire only in this azimuth sector (degrees, sensor frame), to save time.
    resolution, neighborhood : int
        "zbuffer" backend: view size in pixels and candidate window radius.
    reflectivity : float or (n_objects + 1,) float, optional
        LiDAR only: Lambertian reflectivity ρ of every surface, or per object id (index 0:
        the ground).  Given, a return is kept only when its received power clears the
        sensor's threshold, ``ρ · cos θ · f / R² · exp(σ z) ≥ τ`` (:class:`Lidar`
        ``detection_threshold``, ``power_noise`` σ, z ~ N(0, 1) per firing, ``f`` the
        footprint fraction).  None: every hit returns (no radiometry).  With the multi-return
        model (``Lidar.max_returns`` above 1), ρ weighs each sub-ray's echo and the threshold
        applies per echo (:class:`Lidar` ``max_returns``).  ``"table"``: each object's ρ from
        its material at 905 nm (:func:`~.reflectance.scene_optics`; the ground: asphalt).
    transmittance : float or (n_objects + 1,) float, optional
        LiDAR with the multi-return model only: round-trip transmittance per object id, in
        [0, 1] (a gap fraction for foliage, ``T²`` for a pane); sub-rays go on through such
        surfaces (Embree: all hits along each sub-ray, :func:`~.raycast.cast_embree_beyond`) and
        the hits behind return their energy times the transmittances before them.
        ``"table"``: from each object's material (:func:`~.reflectance.scene_optics`: foliage
        :data:`~.reflectance.FOLIAGE_GAP_FRACTION`).  None or 0 everywhere: opaque, first hits
        only, bit for bit as without it.  The "zbuffer" backend keeps the nearest face per
        pixel only and refuses a transmittance above 0.

    Returns
    -------
    Scan
        One point per return.  LiDAR scans carry the return fields (``return_number`` ...
        ``scan_angle_deg``).  With the multi-return model, each echo of a pulse is one point on
        the pulse's centre direction at the echo's range (then range noise and dropout per
        echo, as for single returns); its object, face and normal are those of the echo's
        strongest surface's strongest hit.  Echoes lost to the range limits or dropout leave
        the pulse's other returns renumbered 1..n.  With ``max_returns`` 1 every array is
        what it was before the return fields existed, bit for bit.

    Raises
    ------
    InvalidInputError
        A negative, too large or non-integer ``seed``; bad pose, frame, backend or scene; a bad ``reflectivity`` or ``transmittance``, or a
        transmittance above 0 with the "zbuffer" backend or without the multi-return model.
    BackendUnavailable
        Embree or OpenGL missing for the chosen backend.
    """
    seed = _checked_arguments(seed, backend, frame)
    built = _built(scene)
    if pose is None:
        if not isinstance(scene, ScanScene):
            raise InvalidInputError("scan of a bare mesh needs a sensor pose")
        pose = scene.default_sensor_pose()
    m = _as_pose(pose)
    rot, origin = m[:3, :3], m[:3, 3]
    d_sensor, ring, pulses, pixel, (near, far) = _sensor_rays(sensor, azimuth_range_deg)
    d_world = d_sensor @ rot.T
    meta: dict = {"backend": backend, "n_rays": len(d_world)}
    k = sensor.footprint_rays if isinstance(sensor, _PULSED) else 1
    rays = d_world if k == 1 else sensor.footprint_directions(d_world).reshape(-1, 3)
    face, t = _cast(built, origin, rays, backend, meta, resolution=resolution, neighborhood=neighborhood, near_far=(near, far))
    rho, tau = _surface_optics(built, sensor, backend, reflectivity, transmittance)
    multi = isinstance(sensor, _PULSED) and sensor.multi_return
    rng = np.random.default_rng(seed)
    if multi:
        hit, face, t, echo_energy = _echo_returns(built, sensor, rays, face, t, rho, rng, origin=origin, transmittance=tau)
    else:
        if k > 1:
            weights = sensor.footprint_weights() if sensor.beam_profile != "tophat" else None
            face, t, fraction = strongest_echo(built, rays, face, t, k, rho, sensor.echo_separation_m, weights)
        hit = np.flatnonzero(face >= 0)
        face, t = face[hit], t[hit]
    d_s = d_sensor[hit]
    normal, cos_in, incidence = _facing_normals(built, face, d_world[hit])
    gauss = rng.standard_normal(len(hit))  # drawn for every hit, so filters do not shift streams
    lost = rng.random(len(hit)) < (sensor.dropout_probability(t) if isinstance(sensor, _PULSED) else sensor.dropout)
    # Limits apply to what the sensor measures (noise and quantisation included).
    if isinstance(sensor, _PULSED):
        measured = t + sensor.range_noise_m * gauss
        keep = (measured >= sensor.min_range_m) & (measured <= sensor.max_range_m) & ~lost
        power = echo_energy if multi else np.ones(len(hit))
        if not multi and rho is not None:
            # received power of an extended Lambertian target (Kashani et al. 2015, Eq. 4), up to a constant
            power = (fraction[hit] if k > 1 else rho[face] * np.abs(cos_in)) / np.maximum(t, 1e-9) ** 2
            if sensor.power_noise > 0:
                power = power * np.exp(sensor.power_noise * rng.standard_normal(len(hit)))
            keep &= power >= sensor.detection_threshold
    else:
        cos_axis = d_s[:, 2]  # depth = t · cos(angle to the optical axis)
        depth = t * cos_axis
        depth_measured = sensor.quantize(depth + sensor.sigma_m(depth, incidence) * gauss)
        measured = depth_measured / cos_axis
        in_range = (depth_measured >= sensor.min_depth_m) & (depth_measured <= sensor.max_depth_m)
        keep = in_range & (incidence <= sensor.max_incidence_deg) & ~lost
    keep &= measured > 0
    sel = np.flatnonzero(keep)
    returns = {}
    if pulses is not None:
        returns = _return_fields(pulses, hit[sel], power[sel], renumber=multi)
    points = d_s[sel] * measured[sel, None]
    normal_out = normal[sel] @ rot  # world → sensor
    sensor_position = np.zeros(3)
    if frame == "world":
        points = points @ rot.T + origin
        normal_out = normal[sel]
        sensor_position = origin.copy()
    return Scan(
        points=points.astype(np.float32),
        ring=None if ring is None else ring[hit][sel].astype(np.int32),
        pixel=None if pixel is None else pixel[hit][sel].astype(np.int32),
        range_m=measured[sel].astype(np.float32),
        face_index=built.face_local[face[sel]],
        object_id=built.face_object[face[sel]],
        normal=normal_out.astype(np.float32),
        incidence_deg=incidence[sel].astype(np.float32),
        frame=frame,
        sensor_position=sensor_position,
        sensor_to_world=m,
        sensor=getattr(sensor, "name", ""),
        meta=meta,
        **returns,
    )


def return_numbers(pulse, *, renumber: bool) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """``return_number`` and ``number_of_returns`` (N,) uint8 of points of pulse rows ``pulse`` (N,), sorted.

    With ``renumber``, the points of one pulse (in range order) are numbered 1..n and each carries
    n (:func:`~.echoes.number_returns`); otherwise every point is its pulse's only return (1 of 1).  Shared by the spinning and the
    airborne scanners.
    """
    if renumber:
        return number_returns(pulse)
    ones = np.ones(len(pulse), np.uint8)
    return ones, ones.copy()


def _return_fields(pulses, pulse, power, *, renumber: bool) -> dict[str, np.ndarray]:
    """The :class:`Scan` return fields of the points of pulse rows ``pulse`` (sorted) of a LiDAR sweep or a ray table.

    ``pulses(pulse)`` gives the pulses' ids, times and scan angles (:func:`_sweep_pulses`,
    :func:`_table_pulses`), ``power`` (N,) the points' received energies.  With ``renumber``,
    the points of a pulse (sorted by range) are numbered 1..n; otherwise each is its pulse's
    only return.
    """
    return_number, number_of_returns = return_numbers(pulse, renumber=renumber)
    return {
        "return_number": return_number,
        "number_of_returns": number_of_returns,
        "intensity": np.asarray(power, dtype=np.float32),
        **pulses(pulse),
    }


def _sweep_pulses(sensor: Lidar, ring, azimuth, pulse) -> dict[str, np.ndarray]:
    """``pulse_id``, ``gps_time``, ``scan_angle_deg`` of pulse rows ``pulse`` of a spinning LiDAR's sweep.

    ``ring`` (P,) int64 and ``azimuth`` (P,) float64 degrees are the pulses' beams and firing
    azimuths (:meth:`Lidar.rays`).  The beams of one firing cycle fire one after another, beam
    ``b`` (its index in ``elevations_deg``) ``b / B`` of a cycle (``1 / (n_azimuths · rotation_hz)``
    seconds) after the cycle starts, so every pulse has a time of its own, as LAS readers that group returns into pulses
    by time expect (Velodyne HDL-32E user manual: its 32 lasers fire 1.152 µs apart in a 46.08 µs
    cycle; the model spreads the B beams evenly over the cycle).
    """
    n_az = sensor.n_azimuths
    index = np.rint((azimuth[pulse] - sensor.azimuth_offset_deg) / (360.0 / n_az)).astype(np.int64) % n_az
    return {
        "pulse_id": ring[pulse] * n_az + index,
        "gps_time": (index + ring[pulse] / sensor.n_beams) / (n_az * sensor.rotation_hz),
        "scan_angle_deg": sensor._elev[ring[pulse]].astype(np.float32),
    }


def _table_pulses(sensor: RayTable, row, pulse) -> dict[str, np.ndarray]:
    """``pulse_id``, ``gps_time``, ``scan_angle_deg`` of pulse rows ``pulse`` of a ray table's scan: the table's
    row, its time (exactly) and its elevation; ``row`` (P,) int64 is each ray's table row (:meth:`RayTable.rays`)."""
    r = row[pulse]
    return {"pulse_id": r, "gps_time": sensor.time_s[r], "scan_angle_deg": sensor.elevation_deg[r].astype(np.float32)}
