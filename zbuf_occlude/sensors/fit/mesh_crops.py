"""The crops a partial-echo fit compares: meshes scanned as ``experiment sim2real``'s ``lidar`` set, and the outline share
of each crop and each real scan whose centroid lies :data:`MATCHED_RANGE_M` away.

The fit itself, the beam it scans with and its result are in :mod:`zbuf_occlude.sensors.fit.partial_echo_meshes`.

How the meshes are scanned is ``experiment sim2real``'s ``lidar`` set (:func:`mesh_crops`): its
mesh folders (:func:`~zbuf_occlude.mesh.inputs.class_folders.find_class_meshes`), its
placements (:class:`~zbuf_occlude.sensors.fit.class_placement.CropPlacement`, sensor 5-25 m
away; each class's real size from :data:`~zbuf_occlude.mesh.sizes.CLASS_SIZES_M`) and its rule
(a crop of fewer than :data:`~zbuf_occlude.sensors.fit.class_placement.MIN_RETURNS` returns is
dropped).  Crop ``k`` of a mesh has the same placement at every threshold, so the thresholds are
compared on the same crops; a crop lost at some threshold (too few returns left) leaves every
threshold's row (:func:`simulated_shares`).  Only scans whose centroid lies :data:`MATCHED_RANGE_M`
away count, real and simulated: the outline share
(:func:`~zbuf_occlude.sensors.fit.scan_lines.outline_share`) changes with range, and most real
scans of every class lie there.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.defaults import MAX_SAMPLES
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.fit.scan_lines import outline_share
from zbuf_occlude.sensors.fit.class_placement import MIN_RETURNS, crops_to_draw
from zbuf_occlude.mesh.inputs.class_folders import MeshEntry
from zbuf_occlude.sensors.fit.class_placement import CropPlacement
from zbuf_occlude.real_scans.records import real_label
from zbuf_occlude.mesh.sizes import CLASS_SIZES_M, SizeRange
from zbuf_occlude.sensors.checks import count
from zbuf_occlude.sensors.kinds import with_beam

if TYPE_CHECKING:
    from zbuf_occlude.real_scans.records import RealScan
    from zbuf_occlude.sensors.patterns.spinning import Lidar

__all__ = [
    "MATCHED_RANGE_M", "MeshCrop", "Say", "centroid_range_m", "mesh_crops", "real_shares", "simulated_shares",
]  # fmt: skip

log = logging.getLogger(__name__)

#: The range bin, metres, [low, high), of the scans' centroids whose outline shares are compared: where most real
#: scans of every class lie (LiDARNet's HDL-32E scans), near the low end of the crops' 5-25 m placements.
MATCHED_RANGE_M = (5.0, 10.0)

Say = Callable[[str], object]


@dataclass(frozen=True)
class MeshCrop:
    """One simulated crop of a mesh: the object's returns of one placement (:func:`mesh_crops`).

    Attributes
    ----------
    mesh : str
        The mesh's name (:attr:`~zbuf_occlude.mesh.inputs.class_folders.MeshEntry.name`, ``car/sedan``).
    class_name : str
    crop : int
        The crop's index ``k`` among the mesh's draws: its placement is the same for every sensor.
    points_m : (N, 3) float64
        The object's returns, sensor frame (sensor at the origin, z up), metres.
    return_number, number_of_returns : (N,) uint8
        Each return's number within its pulse and its pulse's returns (1 where the scan records none).
    distance_m : float
        The placement's horizontal distance from the sensor to the object, metres.
    """

    mesh: str
    class_name: str
    crop: int
    points_m: NDArray[np.float64]
    return_number: NDArray[np.uint8]
    number_of_returns: NDArray[np.uint8]
    distance_m: float

    @property
    def range_m(self) -> float:
        """The range from the sensor to the returns' centroid, metres."""
        return centroid_range_m(self.points_m)


def centroid_range_m(points_m: NDArray[np.floating]) -> float:
    """The range from the sensor (the origin) to the centroid of ``points_m`` (N, 3), metres."""
    return float(np.linalg.norm(np.asarray(points_m, dtype=np.float64).mean(axis=0)))


def mesh_crops(meshes: Sequence[MeshEntry], sensor: Lidar, crops_per_mesh: int, seed: int, *, placement: CropPlacement | None = None,
               sizes: Mapping[str, SizeRange] = CLASS_SIZES_M, footprint: str = "auto") -> list[MeshCrop]:  # fmt: skip
    """``experiment sim2real``'s ``lidar`` crops of every mesh, scanned by ``sensor``: up to ``crops_per_mesh`` each.

    Per mesh, :func:`~zbuf_occlude.sensors.fit.class_placement.crops_to_draw` placements are drawn
    (:func:`~zbuf_occlude.sensors.crops.object_crops` with the mesh's name and ``seed``, from
    ``placement``'s distributions and the class's size in ``sizes``); crops with fewer than
    :data:`~zbuf_occlude.sensors.fit.class_placement.MIN_RETURNS` returns of the object are dropped and
    the first ``crops_per_mesh`` kept (a mesh with fewer is logged).  Crop ``k`` of a mesh is placed
    by the same draw whatever the sensor, so crops of two sensors with the same ``(mesh, crop)`` are
    paired.  Unlike sim2real, a mesh short of good crops is not drawn again under another name.

    Parameters
    ----------
    meshes : sequence of MeshEntry
        Loaded meshes with their class (:func:`~zbuf_occlude.mesh.inputs.class_folders.find_class_meshes`).
    sensor : Lidar
    crops_per_mesh : int
        1 to :data:`~zbuf_occlude.defaults.MAX_SAMPLES`.
    seed : int
    placement : CropPlacement, optional
        Default ``CropPlacement()``: :data:`~zbuf_occlude.sensors.fit.class_placement.LIDAR_PLACEMENT` for every class.
    sizes : mapping of class name to SizeRange
        The real size of each mesh's class (default :data:`~zbuf_occlude.mesh.sizes.CLASS_SIZES_M`).
    footprint : {"auto", "exact", "adaptive"}
        How a footprint is cast (:func:`~zbuf_occlude.sensors.crops.object_crops`' ``footprint``).

    Returns
    -------
    list of MeshCrop
        Mesh by mesh in ``meshes``' order, each mesh's crops by ``k``.

    Raises
    ------
    InvalidInputError
        ``crops_per_mesh`` out of range, a mesh whose class has no size in ``sizes`` (naming both).
    """
    from zbuf_occlude.sensors.crops import object_crops

    crops_per_mesh = count(crops_per_mesh, "crops_per_mesh", low=1, high=MAX_SAMPLES)
    placement = CropPlacement() if placement is None else placement
    out = []
    for entry in meshes:
        if entry.class_name not in sizes:
            raise InvalidInputError(f"{entry.name}: class {entry.class_name!r} has no real size (sizes: {sorted(sizes)})")
        dist, _ = placement.crop_distributions(entry, sizes[entry.class_name])
        kept = 0
        drawn = crops_to_draw(crops_per_mesh)
        for k, crop, _ in object_crops(
            entry.mesh, sensor, dist, name=entry.name, n_samples=drawn, seed=seed, class_name=entry.class_name, footprint=footprint
        ):
            scan = crop.scan.select(crop.scan.object_id != 0)  # the object's returns (no ground margin: all of them)
            if len(scan) < MIN_RETURNS:
                continue
            ones = np.ones(len(scan), dtype=np.uint8)
            out.append(MeshCrop(
                entry.name, entry.class_name, k, scan.points.astype(np.float64),
                ones if scan.return_number is None else scan.return_number,
                ones if scan.number_of_returns is None else scan.number_of_returns,
                float(crop.placement.distance_m),
            ))  # fmt: skip
            kept += 1
            if kept == crops_per_mesh:
                break
        if kept < crops_per_mesh:
            log.warning("%s: %d of %d crops with >= %d returns", entry.name, kept, crops_per_mesh, MIN_RETURNS)
    return out


def _in_window(range_m: float) -> bool:
    lo, hi = MATCHED_RANGE_M
    return lo <= range_m < hi


def real_shares(scans: Sequence[RealScan], classes: Sequence[str]) -> dict[str, list[float]]:
    """Per class of ``classes``, the outline shares of its real scans at :data:`MATCHED_RANGE_M`.

    Parameters
    ----------
    scans : sequence of RealScan
        Real object scans with ``label`` and ``points_sensor_m`` ((N, 3) float64, sensor at the origin, z up, metres);
        a scan whose label is no class of ``classes`` (:func:`~zbuf_occlude.real_scans.records.real_label`) is
        passed over.
    classes : sequence of str

    Returns
    -------
    dict of str to list of float
        Every class of ``classes``, with the outline share of each of its scans whose centroid lies
        :data:`MATCHED_RANGE_M` away, in ``scans``' order (empty where none).

    Raises
    ------
    InvalidInputError
        A scan of one of ``classes`` without sensor-frame points, naming its source.
    """
    out: dict[str, list[float]] = {c: [] for c in classes}
    for s in scans:
        label = real_label(s.label, classes)
        if label not in out:
            continue
        if s.points_sensor_m is None or len(s.points_sensor_m) == 0:
            raise InvalidInputError(f"{s.source}: no sensor-frame points (the outline share needs the sensor at the origin)")
        points = np.asarray(s.points_sensor_m, dtype=np.float64)
        if _in_window(centroid_range_m(points)):
            out[label].append(outline_share(points))
    return out


def simulated_shares(meshes: Sequence[MeshEntry], base: Lidar, grid: Sequence[float], classes: Sequence[str], *, crops_per_mesh: int,
                     seed: int, placement: CropPlacement | None, sizes: Mapping[str, SizeRange],
                     say: Say) -> dict[float, dict[str, list[float]]]:  # fmt: skip
    """Per threshold of ``grid``, per class, the outline shares of the same crops: those at :data:`MATCHED_RANGE_M` at the
    first threshold, less any lost (too few returns) at another.

    ``meshes`` are scanned by ``base`` with each threshold of ``grid`` as its ``min_echo_reflectance``
    (:func:`mesh_crops` with ``crops_per_mesh``, ``seed``, ``placement`` and ``sizes``); ``say`` is told each
    threshold's crops and time.

    Returns
    -------
    dict of float to dict of str to list of float
        Per threshold of ``grid``, every class of ``classes`` with its crops' outline shares, the same crops in the
        same order at every threshold.

    Raises
    ------
    InvalidInputError
        What :func:`mesh_crops` or :func:`~zbuf_occlude.sensors.kinds.with_beam` refuse.
    """
    import time

    shares: dict[float, dict[tuple[str, int], float]] = {}
    keys: list[tuple[str, int, str]] | None = None
    for tau in grid:
        t = time.perf_counter()
        crops = mesh_crops(meshes, with_beam(base, min_echo_reflectance=tau), crops_per_mesh, seed, placement=placement, sizes=sizes)
        if keys is None:  # the crops compared: those in range at the first threshold, looked up by (mesh, crop) at the others
            keys = [(c.mesh, c.crop, c.class_name) for c in crops if _in_window(c.range_m)]
        wanted = {(m, k) for m, k, _ in keys}
        shares[tau] = {(c.mesh, c.crop): outline_share(c.points_m) for c in crops if (c.mesh, c.crop) in wanted}
        say(f"threshold {tau:g}: {len(crops)} crops in {time.perf_counter() - t:.0f} s")
    keys = [key for key in keys or [] if all((key[0], key[1]) in shares[tau] for tau in grid)]  # a lost crop leaves every row
    return {tau: {c: [shares[tau][(m, k)] for m, k, cls in keys if cls == c] for c in classes} for tau in grid}
