"""A :class:`~zbuf_occlude.sensors.request.ScanRequest` run into a folder: the scans of a scene file or of one object,
one file per sample and format, written through the owned-folder layer (:class:`~zbuf_occlude.io.owned.OwnedFolder`).

``scan`` builds the request and the object's placement from its options and runs one of these; so may any caller
that holds a folder.  File names: ``<stem>_<sensor>_sNNN.<format>`` (:data:`SCAN_FILE_NAMES`).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.kinds import capabilities
from zbuf_occlude.sensors.request import LAS_FORMATS, ScanRequest
from zbuf_occlude.sensors.scan_data import check_gps_start

__all__ = ["SCAN_FILE_NAMES", "WrittenScan", "save_scan", "scan_object", "scan_scene_file"]

#: The files a scan writes in its folder: ``<stem>_<sensor>_sNNN.npz|ply|las|laz``.
SCAN_FILE_NAMES = r"[^/]+_s\d{3,}\.(npz|ply|las|laz)"


@dataclass(frozen=True)
class WrittenScan:
    """One sample's files: ``files`` (one a format), and for a scan of an object its returns (``object_returns``) and distance, metres."""

    files: tuple[Path, ...]
    object_returns: int | None = None
    distance_m: float | None = None


def save_scan(folder, scan, stem: str, request: ScanRequest, *, ground_z_m: float, number: int) -> tuple[Path, ...]:
    """Write ``scan`` as ``<stem>.<format>`` for each of the request's formats through ``folder`` (an
    :class:`~zbuf_occlude.io.owned.OwnedFolder`): a LAS/LAZ file (1.4, point format 6) with the request's ``las``
    keywords, ``ground_z_m`` and ``number`` modulo 65,536 as its point source id where it has no flight lines.

    Raises
    ------
    InvalidInputError
        A GPS start that the scan's own times refuse (:func:`~zbuf_occlude.sensors.scan_data.check_gps_start`,
        naming ``gps_start_s`` as the request's names map it).
    """
    files = []
    if set(request.formats) & set(LAS_FORMATS):
        check_gps_start(request.las.get("gps_start_s"), scan.gps_time, name=request.names.get("gps_start_s") or "gps_start_s")
    for fmt in request.formats:
        if fmt in LAS_FORMATS:  # encoded in memory
            data = scan.to_las_bytes(compress=fmt == "laz", ground_z_m=ground_z_m, scan_number=number % 65536, **request.las)
            folder.write_bytes(f"{stem}.{fmt}", data)
        else:
            with folder.write(f"{stem}.{fmt}") as tmp:
                getattr(scan, f"to_{fmt}")(tmp)
        files.append(folder.root / f"{stem}.{fmt}")
    return tuple(files)


def scan_scene_file(request: ScanRequest, scene, folder, *, stem: str, seed: int, progress: bool = False) -> Iterator[WrittenScan]:
    """Scan ``scene`` (a :class:`~zbuf_occlude.sensors.scene.objects.ScanScene`, a scene file's) ``request.samples`` times, sample ``k``
    with seed ``seed + k``, writing each (:func:`save_scan`, stem ``<stem>_<sensor>_sNNN``) as it is made.

    A LiDAR stands at the scene's sensor pose (or moves along the request's trajectory, sample ``k`` sweeping from its
    start plus ``k`` sweeps); a depth camera there looks at the first object; an airborne scanner flies its plan over
    the scene's ground, in the world frame.

    Raises
    ------
    InvalidInputError
        What :func:`~zbuf_occlude.sensors.scan.scan`, :func:`~zbuf_occlude.sensors.scan.scan_airborne` and
        :func:`save_scan` refuse.
    """
    from zbuf_occlude.io.progress import progress as progress_bar
    from zbuf_occlude.sensors.platform import look_at_pose
    from zbuf_occlude.sensors.scan import scan, scan_airborne

    sensor, trajectory, kind = request.scanner, request.trajectory, capabilities(request.scanner)
    if kind.pulsed:
        pose = scene.default_sensor_pose()
    else:  # a camera looks at the first object from the sensor position
        target = scene.build().local_to_world[1][:3, 3] if scene.objects else np.array([1.0, 0.0, scene.ground_z_m])
        pose = look_at_pose(scene.default_sensor_pose()[:3, 3], target + [0, 0, 0.5])
    optics = request.surface_optics(scene)  # the scene's, once: every sample scans the same scene
    for k in progress_bar(range(request.samples), desc="scan", unit="scan", enabled=progress):
        if kind.flies:  # a flight over the scene's ground (world frame)
            s = scan_airborne(scene, sensor, (0.0, 0.0), scene.ground_half_extent_m, seed=seed + k, footprint=request.cast, **optics)
        else:
            start_s = None if trajectory is None else trajectory.start_s + k * sensor.sweep_s  # this sweep's samples only
            platform = pose if trajectory is None else trajectory.since(start_s, until_s=start_s + sensor.sweep_s)
            s = scan(scene, sensor, platform, seed=seed + k, backend=request.backend, frame=request.frame, footprint=request.cast, **optics)
        yield WrittenScan(save_scan(folder, s, f"{stem}_{sensor.name}_s{k:03d}", request, ground_z_m=scene.ground_z_m, number=k))


def scan_object(request: ScanRequest, mesh, distributions, folder, *, name: str, seed: int, crop: bool = False,
                progress: bool = False) -> Iterator[WrittenScan]:  # fmt: skip
    """Stand ``mesh`` on the ground and scan it ``request.samples`` times, each with its own placement drawn from
    ``distributions`` (:func:`~zbuf_occlude.sensors.crops.object_crops`: one seed and one ``name`` give the crops
    ``farm --sensor`` gives), writing each sample (the object's crop with ``crop``, else the object and the ground in
    its azimuth sector; the placement in the scan's ``meta``) as it is made.

    Parameters
    ----------
    mesh : trimesh.Trimesh or dict
        The object, z-up, metres (a dict: a unit primitive, :func:`~zbuf_occlude.sensors.crops.object_crop`).
    distributions : CropDistributions
    name : str
        The object's name: the seed key, its class and the files' stem.

    Raises
    ------
    InvalidInputError
        A sensor that is not pulsed (a depth camera scans a scene file), or what the crops and :func:`save_scan` refuse.
    """
    kind = capabilities(request.scanner)
    if not kind.pulsed:  # refused before any scan: this returns the scans' generator
        raise InvalidInputError(f"scan of a mesh file places a LiDAR; use a scene file for a {kind.title}")
    return _object_scans(request, mesh, distributions, folder, name=name, seed=seed, crop=crop, progress=progress)


def _object_scans(request: ScanRequest, mesh, distributions, folder, *, name: str, seed: int, crop: bool, progress: bool):
    """:func:`scan_object`'s samples, once the request is known to place a LiDAR."""
    from zbuf_occlude.io.progress import progress as progress_bar
    from zbuf_occlude.sensors.crops import object_crops
    from zbuf_occlude.sensors.scene.objects import GROUND_ID

    sensor = request.scanner
    crops = object_crops(mesh, sensor, distributions, name=name, n_samples=request.samples, seed=seed, class_name=name,
                         backend=request.backend, frame=request.frame, optics=request.scene_optics(), footprint=request.cast)  # fmt: skip
    for k, drawn, _ in progress_bar(crops, total=request.samples, desc="scan", unit="scan", enabled=progress):
        s = drawn.scan if crop else drawn.full
        s.meta.update(drawn.placement.to_dict())
        files = save_scan(folder, s, f"{name}_{sensor.name}_s{k:03d}", request, ground_z_m=0.0, number=k)
        yield WrittenScan(files, int(np.count_nonzero(drawn.scan.object_id != GROUND_ID)), drawn.placement.distance_m)
