"""LiDAR-like object crops: one object on the ground, scanned from a sensor placed at random.

This is the per-object step a data-set farm calls (``farm --sensor``): for sample ``k`` of an
object, draw the sensor placement from :class:`CropDistributions`, scan the object (plus any
occluders) with :func:`zbuf_occlude.sensors.scan`, keep the object's returns (external
occlusion included, as real data sets were segmented from street scans), and return them
both in metres (sensor frame) and as a fixed-size :class:`zbuf_occlude.io.clouds.OccludedCloud` in the
object's normalised mesh frame, the farm's HDF5 layout.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.samples import OccludedCloud, derive_rng, draw_sample, object_key
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.sensors.patterns.airborne import AirborneScanner
from zbuf_occlude.sensors.patterns.depth_camera import DepthCamera
from zbuf_occlude.sensors.kinds import kind_of
from zbuf_occlude.sensors.patterns.spinning import Lidar
from zbuf_occlude.sensors.placement import DEFAULT_GROUND_REFLECTIVITY, MAX_REDRAWS, CropDistributions, Placement, draw_placement
from zbuf_occlude.sensors.patterns.ray_table import RayTable
from zbuf_occlude.sensors.scan import scan, scanned_by
from zbuf_occlude.sensors.scan_data import Scan
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject, sensor_pose
from zbuf_occlude.sensors.scene.occluders import side_occluders

if TYPE_CHECKING:  # trimesh is imported where it is used
    from collections.abc import Callable, Iterator

    import trimesh

__all__ = [
    "CropSample", "DrawnCrop", "object_crop", "object_crops", "object_returns", "falls_short", "left_out_why",
    "lidar_object_samples", "kept_return_fields",
    "CROP_STREAM", "RETURN_FIELDS",
]  # fmt: skip

log = logging.getLogger(__name__)

#: The seed stream of object crops: keeps their draws apart from the other streams of one seed.
CROP_STREAM = 0x5C4E


@dataclass
class CropSample:
    """One object crop.

    Attributes
    ----------
    scan : Scan
        The object's returns, sensor frame (metres, z up, sensor at the origin), and, with a
        ``ground_margin_m`` in the placement, the ground returns under it (``object_id`` 0).
    placement : Placement
        Where the object stood and how it was seen.
    local_points : (N, 3) float64
        The same returns in the object's mesh frame (as loaded: normalised for mesh files, z up),
        with the object's horizontal stretch (the placement's ``width_scale``) kept: x and y
        times it, and warped by its ``width_profile``, so that the points show the object as it
        was scanned.  ``face_index`` rows are the mesh's.
    sensor_local : (3,) float64
        The sensor centre in that frame.
    full : Scan
        Every return of the sweep (ground included; only the object's sector for a LiDAR
        without occluders), in the frame asked for.
    """

    scan: Scan
    placement: Placement
    local_points: NDArray[np.float64]
    sensor_local: NDArray[np.float64]
    full: Scan


def object_crop(
    mesh,
    sensor: Lidar | RayTable | DepthCamera | AirborneScanner,
    placement: Placement,
    *,
    seed: int = 0,
    occluders: tuple[SceneObject, ...] = (),
    class_name: str = "",
    backend: str = "embree",
    sector_margin_deg: float = 5.0,
    frame: str = "sensor",
    optics: Callable[[ScanScene], dict] | None = None,
    footprint: str = "auto",
) -> CropSample:
    """Scan one object placed per ``placement`` (see :func:`draw_placement`) and crop its returns.

    The sensor stands at the origin, ``height_m`` above the ground; the object's footprint
    centre is ``distance_m`` away in direction ``azimuth_deg``.  With ``ground_margin_m`` in the
    placement (:class:`CropDistributions`), the crop also keeps the ground returns inside the
    object's footprint grown by that margin; with ``hidden_below_m``, it drops the object's
    returns lower than that above the ground (``full`` keeps them).  An
    :class:`~zbuf_occlude.sensors.patterns.airborne.AirborneScanner` flies over the object instead
    (``distance_m · sin(azimuth_deg)`` across track; points in the world frame).  A LiDAR fires only in the
    object's azimuth sector (± ``sector_margin_deg``), which gives the same returns faster.  With
    ``visible_across_sight`` below 1 in the placement, :func:`~zbuf_occlude.sensors.scene.occluders.side_occluders` stand between the
    sensor and the object (after ``occluders``; the object keeps id 1).  ``optics(scene)`` gives the
    scan's ``reflectivity`` and ``transmittance`` keywords for the scene the object stands in
    (:func:`~zbuf_occlude.sensors.scan.scan`'s; e.g. ``"table"``), where the placement draws no
    reflectivity.  ``footprint`` is :func:`~zbuf_occlude.sensors.scan.scan`'s (``"auto"``, ``"exact"`` or ``"adaptive"``).

    Raises
    ------
    InvalidInputError, MeshLoadError
        Bad placement or mesh, ``visible_across_sight`` below 1 or a reflectivity for an airborne
        scanner, or ``optics`` giving a reflectivity where the placement draws one.
    """
    az = math.radians(placement.azimuth_deg)
    d = placement.distance_m
    size = placement.extents_m or placement.size_m
    width_scale, profile = placement.stretch, placement.width_profile
    # the largest side after the stretch, at most
    reach = placement.size_m * max(1.0, width_scale) * (1.0 if profile is None else max(1.0, *profile))
    kind, seed = scanned_by(sensor, seed)
    if kind.flies:
        if placement.visible_share < 1.0:
            raise InvalidInputError(
                "visible_across_sight hides a side of the object from a sensor on the ground; an airborne scanner flies over it"
            )
        if placement.reflectivity is not None:
            raise InvalidInputError(
                f"reflectivity {placement.reflectivity:g}: {sensor.name} is an {kind.title}, whose crops take the materials' "
                "reflectances (reflectivity='auto'); leave the placement's reflectivity out"
            )
        return _airborne_crop(mesh, sensor, placement, seed=seed, occluders=occluders, class_name=class_name, offset_m=d * math.sin(az), size=size,
                              reach=reach, optics=optics, footprint=footprint)  # fmt: skip
    obj = SceneObject(mesh, class_name, (d * math.cos(az), d * math.sin(az)), placement.yaw_deg, size, width_scale=width_scale,
                      width_profile=profile)  # fmt: skip
    pose = sensor_pose([0.0, 0.0, placement.height_m])
    scene = ScanScene(objects=[obj], occluders=list(occluders), ground_half_extent_m=max(2.0 * d, 20.0))
    if placement.visible_share < 1.0:  # after the given occluders; the object is built once
        world = scene.build().world_vertices(1)
        for panel in side_occluders(world, pose[:3, 3], placement.visible_share, placement.occluder_side):
            scene.add_occluder(panel)
    sector = None
    if kind.sweeps_sectors and not occluders:  # the side occluder stands inside the object's sector
        half = math.degrees(math.asin(min(1.0, 0.75 * reach / d))) + sector_margin_deg
        if half < 180.0:
            sector = (placement.azimuth_deg - half, placement.azimuth_deg + half)
    rho = None
    if placement.reflectivity is not None:  # ground, the object, then the occluders (their own ρ: the object's)
        ground = DEFAULT_GROUND_REFLECTIVITY if placement.ground_reflectivity is None else placement.ground_reflectivity
        rho = [ground] + [placement.reflectivity] * (1 + len(occluders))
    surfaces = {"reflectivity": rho} if optics is None else _optics(optics, scene, rho)
    full = scan(scene, sensor, pose, seed=seed, azimuth_range_deg=sector, backend=backend, frame=frame, footprint=footprint, **surfaces)
    offset = pose[:3, 3] if frame == "sensor" else 0.0  # sensor axes = world axes (yaw 0)
    return _crop_object(scene, full, placement, pose[:3, 3], offset)


class DrawnCrop(NamedTuple):
    """One crop of :func:`object_crops`: its number, the crop, and its generator (for the sample's further draws)."""

    index: int
    crop: CropSample
    rng: np.random.Generator


def object_crops(
    mesh,
    sensor: Lidar | RayTable | DepthCamera | AirborneScanner,
    distributions: CropDistributions,
    *,
    name: str,
    n_samples: int,
    seed: int = 0,
    class_name: str = "",
    backend: str = "embree",
    frame: str = "sensor",
    optics: Callable[[ScanScene], dict] | None = None,
    footprint: str = "auto",
) -> Iterator[DrawnCrop]:
    """The crops of one object, each with its own placement: the one loop of ``scan`` and ``farm --sensor``.

    Crop ``k`` draws its placement (:func:`~zbuf_occlude.sensors.placement.draw_placement`) and then its
    scan's seed from ``derive_rng(seed, object_key(name), CROP_STREAM, k)``, so that one seed, one
    name and one mesh give the same crops through either command, and every crop is reproducible alone.
    Where ``distributions.min_returns`` is given and the crop holds fewer returns of the object
    (:func:`object_returns`), crop ``k`` is drawn again from ``derive_rng(..., k, r)``, ``r = 1 ..``
    :data:`~zbuf_occlude.sensors.placement.MAX_REDRAWS`, until one holds enough; the last draw is
    yielded when none does (the caller leaves it out).

    Parameters
    ----------
    mesh : trimesh.Trimesh or dict
        The object (:func:`object_crop`).
    name : str
        The object's stable name, the seed key: the farm's is its path below the input root without
        suffix, ``scan``'s the file's stem.
    n_samples : int
        Crops, ``k = 0 .. n_samples - 1``.
    frame : str
        ``sensor`` or ``world``, as :func:`object_crop`.
    optics : callable, optional
        The scene's surface optics, as :func:`object_crop`.
    footprint : {"auto", "exact", "adaptive"}
        How a footprint is cast, as :func:`object_crop`.

    Yields
    ------
    DrawnCrop
        ``(k, crop, rng)``: ``rng`` has drawn the placement and the scan's seed; a caller draws what
        follows from it (the farm its subsample of the returns).
    """
    key = object_key(name)
    least = distributions.min_returns
    for k in range(int(n_samples)):
        for redraw in range(1 + (0 if least is None else MAX_REDRAWS)):
            rng = derive_rng(seed, key, CROP_STREAM, k, *((redraw,) if redraw else ()))  # the first draw: the stream without the minimum
            placement = draw_placement(distributions, rng)
            crop = object_crop(mesh, sensor, placement, seed=int(rng.integers(2**63)), class_name=class_name, backend=backend, frame=frame,
                               optics=optics, footprint=footprint)  # fmt: skip
            if not falls_short(crop, least):
                break
        yield DrawnCrop(k, crop, rng)


def object_returns(crop: CropSample) -> int:
    """The returns of the object in ``crop`` (ground returns under it not counted)."""
    return int(np.count_nonzero(crop.scan.object_id == 1))


def falls_short(crop: CropSample, min_returns: int | None) -> bool:
    """Whether ``crop`` holds fewer returns of the object than ``min_returns`` (``CropDistributions.min_returns``;
    None: no minimum, never short)."""
    return min_returns is not None and object_returns(crop) < min_returns


def left_out_why(min_returns: int | None) -> str:
    """Why a sample is left out, for the warning that names it: no return of its object, or, with ``min_returns``,
    fewer than that after its redraws (:func:`object_crops`)."""
    if min_returns is None:
        return "no return of the object where it was placed"
    return f"fewer than {min_returns} returns of the object in {1 + MAX_REDRAWS} placements"


def _crop_object(scene: ScanScene, full: Scan, placement: Placement, sensor_world, offset=None) -> CropSample:
    """The crop of object 1 from ``full`` (its points in the world frame, less ``offset`` when
    given): the object's returns (those at least ``hidden_below_m`` above the ground, when the
    placement gives it) and, with a ``ground_margin_m`` in the placement, the ground returns
    under it (:func:`_under_footprint`); ``meta``'s per-point arrays cropped alike
    (:meth:`~zbuf_occlude.sensors.scan_data.Scan.select`).  Local points in the object's mesh frame, and the sensor's (world ``sensor_world``)."""
    built = scene.build()
    to_world = built.local_to_world[1]
    inverse = np.linalg.inv(to_world[:3, :3])

    def world(points):
        p = points.astype(np.float64)
        return p if offset is None else p + offset

    keep = full.object_id == 1
    if placement.hidden_below_m is not None:
        own = np.flatnonzero(keep)
        keep[own] = world(full.points[own])[:, 2] >= scene.ground_z_m + placement.hidden_below_m
    if placement.ground_margin_m is not None:  # only the ground returns are tested
        ground = np.flatnonzero(full.object_id == 0)
        keep[ground] = _under_footprint(built.local_meshes[1], to_world, inverse, world(full.points[ground]), placement.ground_margin_m)
    crop = full.select(keep)
    local = (world(crop.points) - to_world[:3, 3]) @ inverse.T  # the object's local mesh frame: its stretch and warp kept
    return CropSample(crop, placement, local, inverse @ (sensor_world - to_world[:3, 3]), full)


def _under_footprint(mesh, to_world, inverse, world, margin_m: float) -> NDArray[np.bool_]:
    """(N,) bool: the world points ``(N, 3)`` whose ground-plane position lies in the object's
    bounding box (mesh frame) grown by ``margin_m`` metres along each of its horizontal axes."""
    local = (world - to_world[:3, 3]) @ inverse.T
    scale = np.linalg.norm(to_world[:3, :2], axis=0)  # metres per mesh unit along the box's x and y
    lo, hi = np.asarray(mesh.bounds, dtype=np.float64)[:, :2]
    grow = margin_m / scale
    return np.all((local[:, :2] >= lo - grow) & (local[:, :2] <= hi + grow), axis=1)


def _airborne_crop(mesh, sensor: AirborneScanner, placement: Placement, *, seed: int, occluders, class_name: str, offset_m: float, size,
                  reach: float, optics=None, footprint: str = "auto") -> CropSample:  # fmt: skip
    """An airborne crop: the object ``offset_m`` across track from the plan centre (``distance_m ·
    sin(azimuth_deg)`` of the placement; ``height_m`` is unused: the scanner flies at its altitude),
    scanned from every line of the flight plan that sees it.  Points and the full scan are in the
    world frame; the crop's ``meta["line_id"]`` and ``meta["scan_angle_deg"]`` are its returns'.  The crop's
    placement records the object as the aircraft saw it (:func:`_seen_from`)."""
    from zbuf_occlude.sensors.scan import scan_airborne

    obj = SceneObject(mesh, class_name, (0.0, offset_m), placement.yaw_deg, size, width_scale=placement.stretch,
                      width_profile=placement.width_profile)  # fmt: skip
    reach = max(float(np.max(size)), reach) * 0.75 + 1.0
    scene = ScanScene(objects=[obj], occluders=list(occluders), ground_half_extent_m=abs(offset_m) + 2.0 * reach)
    full = scan_airborne(scene, sensor, (0.0, offset_m), reach, seed=seed, footprint=footprint,
                         **({} if optics is None else _optics(optics, scene, None)))  # fmt: skip
    return _crop_object(scene, full, replace(placement, **_seen_from(full.sensor_position, scene.ground_z_m, (0.0, offset_m))),
                        full.sensor_position)  # fmt: skip


def _seen_from(sensor_world, ground_z_m: float, centre_xy: tuple[float, float]) -> dict[str, float]:
    """The placement fields of an airborne crop as its platform saw the object: ``height_m`` the aircraft above the
    ground, ``distance_m`` the horizontal distance from it to the object's footprint centre ``centre_xy`` (world
    frame, metres), ``azimuth_deg`` the object's direction from it in [0, 360), degrees; the aircraft at ``sensor_world``,
    the scan's mean position of its returns.  The ground placement drawn for the crop set only the object's offset
    across track; a crop's record says where the sensor was."""
    x, y, z = (float(v) for v in sensor_world)
    dx, dy = centre_xy[0] - x, centre_xy[1] - y
    return {"height_m": z - float(ground_z_m), "distance_m": math.hypot(dx, dy), "azimuth_deg": math.degrees(math.atan2(dy, dx)) % 360.0}


def _optics(optics: Callable[[ScanScene], dict], scene: ScanScene, rho) -> dict:
    """``optics(scene)``, with the placement's reflectivities ``rho`` where it gives none.

    Raises
    ------
    InvalidInputError
        Both give a reflectivity.
    """
    surfaces = dict(optics(scene))
    if rho is not None:
        if "reflectivity" in surfaces:
            raise InvalidInputError("the placement draws a reflectivity and the optics give one too: give one of them")
        surfaces["reflectivity"] = rho
    return surfaces


#: A LiDAR scan's per-point return fields (:class:`~zbuf_occlude.sensors.scan_data.Scan`'s names, LAS 1.4's
#: Return Number ... Scan Angle), which a crop keeps when its sensor records several returns per pulse.
RETURN_FIELDS = ("return_number", "number_of_returns", "intensity", "pulse_id", "gps_time", "scan_angle_deg")


def kept_return_fields(sensor: Lidar | RayTable | DepthCamera | AirborneScanner) -> tuple[str, ...]:
    """The return fields a crop of ``sensor`` keeps per point: :data:`RETURN_FIELDS` when it records
    several returns per pulse (``max_returns`` above 1), none otherwise (one return per pulse, or a
    depth camera): its crops, and the data sets made of them, are then as they were before these fields."""
    return RETURN_FIELDS if kind_of(sensor).pulsed and sensor.beam.max_returns > 1 else ()


def lidar_object_samples(
    mesh: trimesh.Trimesh | str,
    sensor: Lidar | RayTable | DepthCamera | AirborneScanner,
    *,
    name: str,
    n_samples: int,
    n_points: int = 2048,
    seed: int = 0,
    distributions: CropDistributions = CropDistributions(),
    class_name: str = "",
    label: int = -1,
    backend: str = "embree",
    footprint: str = "auto",
) -> list[OccludedCloud]:
    """The farm's per-object function for ``--sensor``: ``n_samples`` LiDAR crops of one mesh.

    Sample ``k`` is crop ``k`` of :func:`object_crops` (its placement and sensor noise from
    ``derive_rng(seed, object_key(name), CROP_STREAM, k)``), its points drawn from the same generator.

    Parameters
    ----------
    mesh : trimesh.Trimesh or path
        A normalised mesh (:func:`zbuf_occlude.load_mesh`) or its file.
    sensor : Lidar, RayTable, DepthCamera or AirborneScanner
    name : str
        The object's stable name (seeds, ``source``).
    n_samples, n_points : int
        Crops per object and points per crop (fewer returns are padded with repeats, more
        are subsampled, as :func:`zbuf_occlude.geometry.samples.draw_sample`).
    distributions : CropDistributions
    footprint : {"auto", "exact", "adaptive"}
        How a footprint is cast, as :func:`object_crop`.

    Returns
    -------
    list of OccludedCloud
        ``points (n_points, 3) float32`` in the normalised mesh frame (x and y times the
        placement's ``width_scale``, as :attr:`CropSample.local_points`); ``face_index`` into the
        mesh (−1: a ground return, with ``ground_margin_m``); ``elevation_deg, azimuth_deg, radius``: the sensor seen from the object's bounding
        box centre (degrees, degrees, mesh units); ``n_visible``: the returns;
        ``extra``: the placement (metres, degrees), ``n_returns``, ``sensor``, the per-point
        ``ring`` and, for a sensor that records several returns per pulse
        (:func:`kept_return_fields`), the per-point ``returns``: a dict of each return field's
        ``(n_points,)`` values at the sample's points (dtypes as :class:`~zbuf_occlude.sensors.scan_data.Scan`'s).
        Samples with no return, or fewer of the object than ``distributions.min_returns`` after its redraws
        (:func:`object_crops`), are left out (logged).

    Raises
    ------
    InvalidInputError
        ``n_samples`` or ``n_points`` below 1.
    """
    import trimesh

    if int(n_samples) < 1 or int(n_points) < 1:
        raise InvalidInputError(f"n_samples and n_points must be >= 1, got {n_samples}, {n_points}")
    if not isinstance(mesh, trimesh.Trimesh):
        mesh = load_mesh(mesh)
    fields = kept_return_fields(sensor)
    out = []
    for k, crop, rng in object_crops(
        mesh, sensor, distributions, name=name, n_samples=n_samples, seed=seed, class_name=class_name, backend=backend, footprint=footprint
    ):
        placement = crop.placement
        n = len(crop.scan)
        if n == 0 or falls_short(crop, distributions.min_returns):
            log.info("%s sample %d: %d returns of the object at %.1f m", name, k, object_returns(crop), placement.distance_m)
            continue
        chosen, _ = draw_sample(np.arange(n), int(n_points), rng)
        # Sensor seen from the object's bounding-box centre, in the mesh frame.
        sensor_local = crop.sensor_local - np.asarray(mesh.bounds, dtype=np.float64).mean(axis=0)
        # Written out, not np.linalg.norm: on a 1-D vector that is BLAS's dot product, whose rounding
        # depends on the CPU's OpenBLAS kernel (FMA or not), and the radius goes into the records.
        x, y, z = (float(v) for v in sensor_local)
        r = math.sqrt(x * x + y * y + z * z)
        out.append(
            OccludedCloud(
                points=crop.local_points[chosen].astype(np.float32),
                face_index=np.where(crop.scan.object_id[chosen] == 1, crop.scan.face_index[chosen], -1).astype(np.int64),
                elevation_deg=math.degrees(math.asin(sensor_local[2] / r)),
                azimuth_deg=math.degrees(math.atan2(sensor_local[1], sensor_local[0])) % 360.0,
                radius=r,
                label=label,
                class_name=class_name,
                source=name,
                sample_index=k,
                n_visible=n,
                extra={
                    **placement.to_dict(),
                    "n_returns": n,
                    "sensor": sensor.name,
                    "ring": None if crop.scan.ring is None else crop.scan.ring[chosen],
                    **({"returns": {f: getattr(crop.scan, f)[chosen] for f in fields}} if fields else {}),
                },
            )
        )
    return out
