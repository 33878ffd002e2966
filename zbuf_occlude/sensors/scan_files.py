"""A :class:`~zbuf_occlude.sensors.request.ScanRequest` run into a folder: the scans of a scene file or of one object,
one file per sample and format, written through the owned-folder layer (:class:`~zbuf_occlude.io.owned.OwnedFolder`).

``scan`` builds the request and the object's placement from its options and hands them to :func:`run_scan`; a caller
that holds a folder may run :func:`scan_scene_file` or :func:`scan_object` itself.  File names:
``<stem>_<sensor>_sNNN.<format>`` (:data:`SCAN_FILE_NAMES`).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.spec_files import SCENE_SUFFIXES
from zbuf_occlude.sensors.placement import ObjectPlacement, check_outside
from zbuf_occlude.sensors.request import LAS_FORMATS, ScanRequest
from zbuf_occlude.sensors.scan_data import GPS_START_S, check_gps_start

__all__ = ["FLAT_SHARE", "PRIMITIVES", "SCAN_FILE_NAMES", "TRAJECTORY_SUFFIX", "WrittenScan", "placed_object", "run_scan", "save_scan", "scan_object",
           "scan_scene_file"]  # fmt: skip

log = logging.getLogger(__name__)

#: The files a scan writes in its folder: ``<stem>_<sensor>_sNNN.npz|ply|las|laz``, and ``<stem>_<sensor>_sNNN_trajectory.csv``
#: beside the LAS/LAZ files of a scan whose platform moves along a trajectory it made (an airborne scanner's flight).
SCAN_FILE_NAMES = r"[^/]+_s\d{3,}(\.(npz|ply|las|laz)|_trajectory\.csv)"
#: The end of a scan's trajectory file's name.
TRAJECTORY_SUFFIX = "_trajectory.csv"
#: Unit primitives :func:`run_scan` takes by name instead of a mesh file (stretched by the placement's ``extents_m``).
PRIMITIVES = {
    "cylinder": {"cylinder": {"radius_m": 0.5, "height_m": 1.0, "sections": 48}},
    "box": {"box_m": [1.0, 1.0, 1.0]},
}
#: A mesh whose height is below this share of its largest side is flat in z: stood on the ground it
#: lies in the ground plane, where a scan cannot tell it from the ground (:func:`placed_object` refuses it).
FLAT_SHARE = 1e-6


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
    A scan whose platform moved along a trajectory (``scan.meta["trajectory"]``: an airborne scanner's flight,
    :mod:`~zbuf_occlude.sensors.patterns.flight_times`, or the part of a ``--trajectory`` a ground sensor's sweep
    drove along) written as LAS or LAZ also writes it, ``<stem>_trajectory.csv``
    (:data:`~zbuf_occlude.sensors.platform.EULER_COLUMNS`, read back by :func:`~zbuf_occlude.sensors.platform.load_trajectory`
    where it lies in the scene's frame, without ``origin_m``),
    its times and positions those of the LAS files: the scan's times plus the request's ``gps_start_s``, its positions
    plus the request's ``origin_m`` (:meth:`~zbuf_occlude.sensors.platform.Trajectory.csv_bytes`).

    Raises
    ------
    InvalidInputError
        A GPS start that the scan's own times refuse (:func:`~zbuf_occlude.sensors.scan_data.check_gps_start`,
        naming ``gps_start_s`` as the request's names map it).
    """
    files = []
    start = request.las.get("gps_start_s", GPS_START_S)  # to_las_bytes' default where the request gives none
    if set(request.formats) & set(LAS_FORMATS):
        check_gps_start(start, scan.gps_time, name=request.name_of("gps_start_s"))
    for fmt in request.formats:
        if fmt in LAS_FORMATS:  # encoded in memory
            data = scan.to_las_bytes(compress=fmt == "laz", ground_z_m=ground_z_m, scan_number=number % 65536, **request.las)
            folder.write_bytes(f"{stem}.{fmt}", data)
        else:
            with folder.write(f"{stem}.{fmt}") as tmp:
                getattr(scan, f"to_{fmt}")(tmp)
        files.append(folder.root / f"{stem}.{fmt}")
    trajectory = scan.meta.get("trajectory")
    if trajectory is not None and set(request.formats) & set(LAS_FORMATS):  # a survey's LAS comes with its trajectory
        folder.write_bytes(stem + TRAJECTORY_SUFFIX, trajectory.csv_bytes(start, request.las.get("origin_m") or (0.0, 0.0, 0.0)))
        files.append(folder.root / (stem + TRAJECTORY_SUFFIX))
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

    sensor, trajectory, kind = request.scanner, request.trajectory, request.kind
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
            if trajectory is not None:  # this sweep's part of the path, written beside a LAS as a flight's is
                s.meta["trajectory"] = platform
        yield WrittenScan(save_scan(folder, s, f"{stem}_{sensor.name}_s{k:03d}", request, ground_z_m=scene.ground_z_m, number=k))


def scan_object(request: ScanRequest, mesh, distributions, folder, *, name: str, seed: int, crop: bool = False,
                progress: bool = False) -> Iterator[WrittenScan]:  # fmt: skip
    """Stand ``mesh`` on the ground and scan it ``request.samples`` times, each with its own placement drawn from
    ``distributions`` (:func:`~zbuf_occlude.sensors.crops.object_crops`: one seed and one ``name`` give the crops
    ``farm --sensor`` gives), writing each sample (the object's crop with ``crop``, else the object and the ground in
    its azimuth sector; the placement in the scan's ``meta``) as it is made.  With ``distributions.min_returns``, a
    sample whose object returns stay fewer after its redraws is not written, and named in a warning.

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
    kind = request.kind
    if not kind.pulsed:  # refused before any scan: this returns the scans' generator
        raise InvalidInputError(f"scan of a mesh file places a LiDAR; use a scene file for a {kind.title}")
    return _object_scans(request, mesh, distributions, folder, name=name, seed=seed, crop=crop, progress=progress)


def _object_scans(request: ScanRequest, mesh, distributions, folder, *, name: str, seed: int, crop: bool, progress: bool):
    """:func:`scan_object`'s samples, once the request is known to place a LiDAR."""
    from zbuf_occlude.io.progress import progress as progress_bar
    from zbuf_occlude.sensors.crops import falls_short, left_out_why, object_crops
    from zbuf_occlude.sensors.scene.objects import GROUND_ID

    sensor = request.scanner
    crops = object_crops(mesh, sensor, distributions, name=name, n_samples=request.samples, seed=seed, class_name=name,
                         backend=request.backend, frame=request.frame, optics=request.scene_optics(), footprint=request.cast)  # fmt: skip
    for k, drawn, _ in progress_bar(crops, total=request.samples, desc="scan", unit="scan", enabled=progress):
        if falls_short(drawn, distributions.min_returns):  # after its redraws: left out, named
            log.warning("%s: scan %d left out: %s", name, k, left_out_why(distributions.min_returns))
            continue
        s = drawn.scan if crop else drawn.full
        s.meta.update(drawn.placement.to_dict())
        files = save_scan(folder, s, f"{name}_{sensor.name}_s{k:03d}", request, ground_z_m=0.0, number=k)
        yield WrittenScan(files, int(np.count_nonzero(drawn.scan.object_id != GROUND_ID)), drawn.placement.distance_m)


def run_scan(request: ScanRequest, source: str | os.PathLike, out: str | os.PathLike, placement: ObjectPlacement | None = None, *,
             seed: int = 0, crop: bool = False, progress: bool = False) -> Iterator[WrittenScan]:  # fmt: skip
    """Scan ``source`` as ``request`` asks into the folder ``out``, held as its own while the scans are written: a scene
    file's scans (:func:`scan_scene_file`), or a mesh file or a :data:`PRIMITIVES` name stood on the ground as
    ``placement`` says (:func:`placed_object`) and scanned (:func:`scan_object`, its crops only with ``crop``).

    A generator: nothing is read or written before the first scan is asked for; each yields as it is written.
    Messages name the request's fields as ``request.names`` maps them, and the placement's as ``placement.names`` does.

    Raises
    ------
    InvalidInputError
        A trajectory to move the sensor through a mesh file (a trajectory is a scene file's frame); ``crop`` of a
        scene file (scanned whole); what the folder (:class:`~zbuf_occlude.io.owned.OwnedFolder`: another program's
        files), :func:`placed_object`, :func:`scan_scene_file` and :func:`scan_object` refuse.
    """
    from zbuf_occlude.io.owned import OwnedFolder

    src, n = Path(source), request.name_of
    scene_file = src.suffix.lower() in SCENE_SUFFIXES
    if request.trajectory is not None and not scene_file:
        raise InvalidInputError(f"{n('trajectory')} moves the sensor through a scene file's frame; "
                                f"a scan of {src.name} places the sensor per sample (give a scene file)")  # fmt: skip
    if scene_file and crop:
        raise InvalidInputError(f"{n('crop')} keeps one mesh's returns; {src.name} is a scene file, scanned whole")
    with OwnedFolder(out, names=[SCAN_FILE_NAMES], what="the scan") as folder:
        if scene_file:
            from zbuf_occlude.sensors.scene.files import load_scene

            yield from scan_scene_file(request, load_scene(src), folder, stem=src.stem, seed=seed, progress=progress)
        else:
            mesh, dist = placed_object(src, placement or ObjectPlacement(), request, seed=seed)
            yield from scan_object(request, mesh, dist, folder, name=src.stem, seed=seed, crop=crop, progress=progress)


def placed_object(source: str | os.PathLike, placement: ObjectPlacement, request: ScanRequest, *, seed: int = 0):
    """The mesh that :func:`run_scan` stands on the ground and its crops' distributions.

    ``source`` is a mesh file, read once and turned to ``placement.up``, or a :data:`PRIMITIVES` name (where no such
    file exists).  The distributions are ``placement``'s, with ``size_m`` the interval of the object's largest side where
    it measures another (:func:`~zbuf_occlude.mesh.sizes.size_interval`), and the width or outline fitted
    (:func:`~zbuf_occlude.sensors.fit.fit_object_shape`, with ``seed``).

    Returns
    -------
    mesh : trimesh.Trimesh or dict
        Z-up, metres (a dict: a unit primitive).
    distributions : CropDistributions

    Raises
    ------
    InvalidInputError
        Naming the fields as ``placement.names`` maps them: a mesh :func:`~zbuf_occlude.mesh.load.load_mesh` refuses, one
        flat in z (:data:`FLAT_SHARE`), a size of a primitive's length or height, what the fit refuses, a distance that
        may put a sensor that does not fly inside the object (:func:`~zbuf_occlude.sensors.placement.check_outside`).
    """
    n, src = placement.name_of, Path(source)
    mesh = PRIMITIVES.get(str(src)) if not src.exists() else None
    if mesh is None:
        from zbuf_occlude.mesh.load import load_mesh

        mesh = load_mesh(src, up=placement.up)
        if not mesh.extents[2] > FLAT_SHARE * mesh.extents.max():
            raise InvalidInputError(
                f"{src}: flat in z (no height once its up axis is turned to +z, {n('up')} {placement.up}): stood on the ground it lies "
                f"in the ground plane, where no scan can tell it from the ground; give {n('up')} the axis it should stand along "
                f"(e.g. {n('up')} +y), or give it a thickness"
            )
    dist = placement.distributions
    if placement.size_of != "max":
        from zbuf_occlude.mesh.sizes import SizeRange, size_interval

        if isinstance(mesh, dict):
            raise InvalidInputError(f"{n('size_of')} {placement.size_of} measures a mesh file; a primitive takes {n('size_m')} "
                                    f"(its largest dimension) or {n('extents_m')}")  # fmt: skip
        size = size_interval(mesh.extents, SizeRange(placement.size_of, *dist.size_m))
        dist = replace(dist, size_m=size, option_names=placement.names)
    if placement.across_sight_width_m is not None or placement.width_profile is not None:
        from zbuf_occlude.sensors.fit import fit_object_shape

        dist = replace(dist, **fit_object_shape(mesh, request.scanner, dist, placement.across_sight_width_m, placement.width_profile,
                                                occlude=placement.occlude, seed=seed, name=str(src)))  # fmt: skip
        log.info("%s: width_scale %s, visible_across_sight %s, width_profile %s", src.name, dist.width_scale, dist.visible_across_sight,
                 dist.width_profile)  # fmt: skip
    if not request.kind.flies:  # an aircraft flies its altitude above the object
        check_outside(dist, None if isinstance(mesh, dict) else mesh.extents, name=n("distance_m"))
    return mesh, dist
