"""Returns per pulse, simulated and real: an airborne scan of trees measured as a real LAS file is.

The experiment behind ``zbuf-occlude experiment returns`` and docs/results/returns.md:

1. **A plot**: a flat ground and tree and bush meshes at their real sizes (:func:`plot_scene`),
   scanned by an airborne scanner at a national survey's settings (:func:`ign_scanner`) with the
   multi-return model (:func:`~zbuf_occlude.sensors.scan.scan_airborne`).
2. **The same measure on both sides**: the simulated scan is written as LAS
   (:meth:`~zbuf_occlude.sensors.scan_data.Scan.to_las_bytes`), read back by
   :func:`~zbuf_occlude.io.las.read_las`, given ASPRS classes (:func:`simulated_classes`) and
   measured by :func:`~zbuf_occlude.sensors.fit.returns.return_statistics`, the function that
   measures the real file.  Per side, the figures are taken on the **vegetation pulses** (a
   return on classes 3–5) and on the **ground pulses** (every return on class 2), selected by
   :func:`pulse_subset` the same way in both files.
3. **The divergence by simulation**: the multi-return share on vegetation rises with the beam's
   divergence; the fitted divergence is where the simulated curve meets the real share
   (:func:`~zbuf_occlude.sensors.fit.divergence.divergence_from_shares`).
4. **The ground under trees**: how many ground returns come from pulses that passed through a
   crown first depends on how much of the ground the crowns cover; :mod:`.tree_cover` measures it
   on a LAS file and spaces the plot's trees so that the plot's cover equals the real tile's.

The classes the LAS file stores (by the objects' class names) are replaced after reading, point
for point (LAS keeps the scan's order), by classes from the scan's object ids:
the ground is 2, vegetation 3, 4 or 5 by its height above the ground (:data:`VEGETATION_HEIGHTS_M`),
any other object 1.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.atomic import write_bytes
from zbuf_occlude.io.las import LasPoints, read_las
from zbuf_occlude.sensors.patterns.airborne import AIRBORNE_IDEAL_BEAM, AirborneScanner
from zbuf_occlude.sensors.scan import scan_airborne
from zbuf_occlude.sensors.fit.returns import (
    VEGETATION_CLASSES,
    ReturnStatistics,
    return_statistics,
)
from zbuf_occlude.sensors.scene.las_classes import GROUND_CODE, VEGETATION_HEIGHTS_M, asprs_classification
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject

if TYPE_CHECKING:
    from zbuf_occlude.sensors.scan_data import Scan

__all__ = [
    "AUTZEN_CELL_M", "GROUND_CLASS", "IGN_ALTITUDE_M", "IGN_DIVERGENCE_DEG", "IGN_PULSES_PER_M2", "PLOT_CROWN_SHELL_M", "PLOT_LEAF_SIDE_M", "PLOT_TREES",
    "VEGETATION_HEIGHTS_M", "PlotTree",
    "SimulatedScan", "ign_scanner", "object_pulse_shares", "plot_scene", "pulse_subset", "simulate", "simulated_classes",
]  # fmt: skip

#: ASPRS class of the ground (LAS 1.4 R15, Table 17); the class rule is the LAS writer's (:mod:`zbuf_occlude.sensors.scene.las_classes`).
GROUND_CLASS = GROUND_CODE
#: Flying height of IGN LiDAR HD, metres: "about 1,500 m" (IGN's programme as described by
#: d-booker.fr, "Exemple d'utilisation de données géographiques 3D"; 10 points/m² on average, ign.fr).
IGN_ALTITUDE_M = 1500.0
#: Full-angle beam divergence, degrees: 0.25 mrad, the RIEGL LMS-Q1560 data sheet's (2015) bound
#: (the sample names no scanner model; its SOURCE.md says RIEGL).
IGN_DIVERGENCE_DEG = math.degrees(0.25e-3)
#: Full scan angle, degrees: the IGN sample's scan angles run from −13° to +15°.
IGN_SWATH_DEG = 30.0
#: Ground speed, metres per second: an ASSUMPTION (a usual survey speed; no source gives IGN's).
IGN_SPEED_MPS = 60.0
#: Pulses per square metre of flat ground of one flight line: IGN's target density, 10 points/m² on average (ign.fr).
IGN_PULSES_PER_M2 = 10.0
#: Pulses per second and lines per second: :data:`IGN_PULSES_PER_M2` on flat ground with
#: equal along- and across-track spacings (0.32 m) at 60 m/s and a 30° swath from 1,500 m.
IGN_PULSE_RATE_HZ, IGN_LINE_RATE_HZ = 483_000.0, 190.0
#: Most returns a pulse keeps: the IGN sample's largest ``number_of_returns`` is 5.
IGN_MAX_RETURNS = 5
#: The plot's leaves (:func:`~zbuf_occlude.sensors.scene.foliage.add_foliage`): side of a square leaf, metres (a
#: broadleaf's), and the depth of the crown they fill under the mesh's surface, metres.  ASSUMPTIONS.
PLOT_LEAF_SIDE_M, PLOT_CROWN_SHELL_M = 0.1, 1.0
#: Side of the cells on which the Autzen tile's tree cover and canopy height are measured, metres:
#: its pulses, thinned to about 2.5 first returns per m² (the median over its occupied 10 m
#: squares), put about 10 in a 2 m cell, as the IGN sample's whole strips (about 20 per m²) put
#: 20 in a 1 m cell (:data:`~.tree_cover.TREE_COVER_CELL_M`).
AUTZEN_CELL_M = 2.0


@dataclass(frozen=True)
class PlotTree:
    """One tree or bush mesh of the plot: file (under the mesh folder), up axis, largest dimension in metres,
    and whether its crown is a hull or leaf cards to fill with leaves.

    ``size_m`` is the file's own size where it declares metres or inches (COLLADA), else an
    ASSUMPTION of a real tree's size (the docs' results page lists which).  ``foliage``: the plot
    fills the crown with leaves (:func:`~zbuf_occlude.sensors.scene.foliage.add_foliage`); False for a
    plant whose mesh models its leaves one by one.
    """

    file: str
    up: str
    size_m: float
    foliage: bool = True


#: The eight meshes of ``street_objects/bush`` (its SOURCE.md), at real sizes: COLLADA files in
#: their declared units; the OBJ files, which state none, at sizes assumed for their kind of tree.
PLOT_TREES = (
    PlotTree("gazebo__oak_tree.dae", "auto", 10.61),  # declared metres
    PlotTree("gazebo__pine_tree.dae", "auto", 5.08),  # declared metres
    PlotTree("gzcollection__Tree_1.dae", "auto", 4.97),  # declared inches (195.5 in)
    PlotTree("gzcollection__leaf.dae", "auto", 0.80, foliage=False),  # declared metres: a leafy plant, leaf by leaf
    PlotTree("gzcollection__plant.dae", "auto", 0.55, foliage=False),  # declared metres: a low plant, leaf by leaf
    PlotTree("duckietown__tree.obj", "auto", 8.0),  # assumed: a deciduous tree 8 m across
    PlotTree("duckietown__tree_pine_lowpoly.obj", "auto", 10.0),  # assumed: a pine 10 m tall
    PlotTree("openglforest__tree.obj", "+y", 12.0),  # assumed: a conifer 12 m tall; +y up (taller along y)
)


def ign_scanner(divergence_deg: float = IGN_DIVERGENCE_DEG, footprint_rays: int = 19, *, range_resolution_m: float = 0.82,
                profile: str = "gaussian", max_returns: int = IGN_MAX_RETURNS, range_noise_m: float = 0.02) -> AirborneScanner:  # fmt: skip
    """The IGN LiDAR HD survey's scanner as this experiment models it (module constants give each source).

    Parameters
    ----------
    divergence_deg : float
        The beam's full angle, degrees (default: 0.25 mrad).
    footprint_rays : int
        Sub-rays per pulse, 1..:data:`~zbuf_occlude.sensors.beam.footprint.MAX_SUBRAYS`.
    range_resolution_m : float
        Least range between two returns of one pulse, metres (default: the IGN sample's smallest
        gap between returns, 0.82 m).
    profile, max_returns, range_noise_m
        As :class:`~zbuf_occlude.sensors.beam.fields.Beam`'s (at 1064 nm, no detection threshold: the
        fitted return model sets it, :meth:`~zbuf_occlude.sensors.fit.return_model.ReturnModelFit.apply`).

    Raises
    ------
    InvalidInputError
        A field the scanner refuses (named).
    """
    source = "IGN LiDAR HD as modelled in zbuf_occlude.experiments.returns (altitude, density: IGN; divergence: RIEGL LMS-Q1560)"
    beam = AIRBORNE_IDEAL_BEAM.with_(name="ign-lidarhd", source=source, divergence_deg=divergence_deg, footprint_rays=footprint_rays,
                                     profile=profile, max_returns=max_returns, range_resolution_m=range_resolution_m,
                                     range_noise_m=range_noise_m)  # fmt: skip
    return AirborneScanner(
        "ign-lidarhd", swath_deg=IGN_SWATH_DEG, pulse_rate_hz=IGN_PULSE_RATE_HZ, line_rate_hz=IGN_LINE_RATE_HZ,
        altitude_m=IGN_ALTITUDE_M, speed_mps=IGN_SPEED_MPS, pattern="linear", beam=beam, source=source,
    )  # fmt: skip


def plot_scene(meshes: Sequence, sizes_m: Sequence[float], *, spacing_m: float, center_xy=(0.0, 0.0),
               seed: int = 0) -> tuple[ScanScene, tuple[int, ...]]:  # fmt: skip
    """A flat ground with the meshes standing on a square grid, each turned by a random yaw.

    Parameters
    ----------
    meshes : sequence of trimesh.Trimesh
        Z-up meshes (any scale: each is scaled to its size).
    sizes_m : sequence of float
        Largest dimension of each, metres.
    spacing_m : float
        Distance between grid cells' centres, metres; the grid is ``ceil(sqrt(n))`` cells wide,
        centred on ``center_xy`` (metres; the ground square, centred on the origin, reaches past it).
    seed : int
        Draws the yaws.

    Returns
    -------
    scene : ScanScene
        Ground at z = 0; object ids 1..n in the order given.
    vegetation_ids : tuple of int
        The meshes' object ids.

    Raises
    ------
    InvalidInputError
        No mesh, sizes of another length, a spacing not > 0, or a field the scene refuses.
    """
    if len(meshes) == 0 or len(meshes) != len(sizes_m):
        raise InvalidInputError(f"plot_scene needs one size per mesh, got {len(meshes)} meshes and {len(sizes_m)} sizes")
    if not (math.isfinite(spacing_m) and spacing_m > 0):
        raise InvalidInputError(f"spacing_m must be a finite number > 0, got {spacing_m!r}")
    rng = np.random.default_rng(seed)
    side = math.ceil(math.sqrt(len(meshes)))
    centre = (side - 1) / 2.0
    cx, cy = (float(v) for v in center_xy)
    objects = []
    for i, (mesh, size) in enumerate(zip(meshes, sizes_m)):
        row, col = divmod(i, side)
        objects.append(SceneObject(mesh, class_name="vegetation", position_m=(cx + (col - centre) * spacing_m, cy + (row - centre) * spacing_m),
                                   yaw_deg=float(rng.uniform(0.0, 360.0)), size_m=float(size)))  # fmt: skip
    reach = max(abs(cx), abs(cy)) + side * spacing_m
    scene = ScanScene(objects=objects, ground=True, ground_half_extent_m=reach)
    return scene, tuple(range(1, len(meshes) + 1))


def simulated_classes(scan: Scan, vegetation_ids: Sequence[int], ground_z_m: float = 0.0) -> NDArray[np.uint8]:
    """ASPRS classes of a simulated scan's points (module docstring).

    Returns
    -------
    (N,) uint8
        2 on the ground (object 0), 3/4/5 on ``vegetation_ids`` by height above ``ground_z_m``
        (:data:`VEGETATION_HEIGHTS_M`), 1 on anything else.
    """
    ids = np.asarray(scan.object_id, np.int64)
    vegetation = {int(i) for i in vegetation_ids}
    classes = ["ground"] + ["vegetation" if i in vegetation else "" for i in range(1, int(ids.max(initial=0)) + 1)]
    return asprs_classification(ids, classes, scan.points[:, 2].astype(np.float64) - ground_z_m)  # the LAS writer's rule


def _select(las: LasPoints, mask: NDArray[np.bool_]) -> LasPoints:
    arrays = {f.name: getattr(las, f.name)[mask] for f in fields(las) if isinstance(getattr(las, f.name), np.ndarray)}
    return replace(las, **arrays)


def pulse_subset(las: LasPoints, side: str, *, classes: Sequence[int] = VEGETATION_CLASSES) -> LasPoints:
    """The points of the pulses of one side: ``"vegetation"`` (a return on ``classes``) or ``"ground"``
    (every return on class 2); a pulse is a GPS time within one point source and scanner channel,
    as :func:`~zbuf_occlude.sensors.fit.returns.return_statistics` counts them.

    Raises
    ------
    InvalidInputError
        An unknown side, or no pulse on it.
    """
    keys = np.column_stack(
        [
            las.point_source_id.astype(np.float64),
            las.scanner_channel.astype(np.float64),
            las.gps_time,
        ]
    )
    _, pulse = np.unique(keys, axis=0, return_inverse=True)
    pulse = pulse.reshape(-1)
    n = int(pulse.max()) + 1 if len(pulse) else 0
    if side == "vegetation":
        chosen = np.bincount(pulse, weights=np.isin(las.classification, classes), minlength=n) > 0
    elif side == "ground":
        chosen = np.bincount(pulse, weights=las.classification != GROUND_CLASS, minlength=n) == 0
    else:
        raise InvalidInputError(f"side must be 'vegetation' or 'ground', got {side!r}")
    mask = chosen[pulse]
    if not mask.any():
        raise InvalidInputError(f"no {side} pulse in the scan")
    return _select(las, mask)


@dataclass(frozen=True)
class SimulatedScan:
    """Simulated scans, as measured: the LAS points read back (classes given; one point source per
    seed), the figures per side, the first seed's scan, pulses cast and the scans' wall time in seconds."""

    scan: Scan
    las: LasPoints
    statistics: dict[str, ReturnStatistics]
    pulses: int
    seconds: float


def _concatenate(parts: Sequence[LasPoints]) -> LasPoints:
    names = [f.name for f in fields(parts[0]) if isinstance(getattr(parts[0], f.name), np.ndarray)]
    return replace(
        parts[0],
        **{name: np.concatenate([getattr(p, name) for p in parts]) for name in names},
    )


def simulate(scene: ScanScene, scanner: AirborneScanner, vegetation_ids: Sequence[int], *, center_xy=(0.0, 0.0), half_size_m: float,
             seeds: Sequence[int] = (0,), bootstrap: int = 200, reflectivity=None, transmittance=None,
             on_scan: Callable[[], object] | None = None) -> SimulatedScan:  # fmt: skip
    """Scan the plot, write each scan as LAS, read it back and measure them together (module docstring, steps 1–2).

    Parameters
    ----------
    scene : ScanScene
    scanner : AirborneScanner
        Its beam with ``max_returns`` above 1.
    vegetation_ids : sequence of int
        Object ids classed as vegetation.
    center_xy, half_size_m
        The square of ground whose pulses are cast (:func:`~zbuf_occlude.sensors.scan.scan_airborne`), metres.
    seeds : sequence of int
        One scan per seed (noise and the line's phase: the pulses fall elsewhere), each its own
        point source (flight line) in the pooled points; the first also seeds the bootstrap.
    bootstrap : int
        Resamples of :func:`~zbuf_occlude.sensors.fit.returns.return_statistics`.
    reflectivity, transmittance : optional
        Per object id (ground first) or ``"table"``, as
        :func:`~zbuf_occlude.sensors.scan.scan_airborne` takes them; None (default): every
        surface reflects alike and stops the sub-ray.
    on_scan : callable, optional
        Called with no argument after each seed's scan (a progress bar's ``update``).

    Returns
    -------
    SimulatedScan
        ``statistics``: ``"all"`` (class set 3–5), ``"vegetation"`` and ``"ground"``
        (:func:`pulse_subset`); ``seconds``: the scans' wall time (rays and echoes, not the
        file round trip or the measuring).

    Raises
    ------
    InvalidInputError
        No seed, a scan refused (too many rays) or a side without pulses.
    """
    import time

    if len(seeds) == 0:
        raise InvalidInputError("simulate needs one seed or more")
    full_scale = 2.0 / scanner.altitude_m**2  # a white target at nadir filling the beam stores about 32,767
    parts, seconds, pulses, first = [], 0.0, 0, None
    with tempfile.TemporaryDirectory(prefix="zbuf-returns-") as folder:
        for source, seed in enumerate(seeds):
            start = time.perf_counter()
            # every sub-ray cast: the comparison measures the exact model, whose shares converge with the sub-ray count
            optics = {"reflectivity": reflectivity, "transmittance": transmittance}
            scan = scan_airborne(scene, scanner, center_xy, half_size_m, seed=int(seed), footprint="exact", **optics)
            seconds += time.perf_counter() - start
            if on_scan is not None:
                on_scan()
            pulses += int(scan.meta["n_rays"])
            first = scan if first is None else first
            path = write_bytes(
                Path(folder) / f"simulated_{source}.las",
                scan.to_las_bytes(intensity_scale=65535.0 / full_scale),
            )
            las = read_las(path)
            parts.append(replace(las, classification=simulated_classes(scan, vegetation_ids, scene.ground_z_m),
                                 point_source_id=np.full(len(las), source, np.uint16)))  # fmt: skip
    las = _concatenate(parts)
    seed = int(seeds[0])
    statistics = {"all": return_statistics(las, seed=seed, bootstrap=bootstrap)}
    for side in ("vegetation", "ground"):
        statistics[side] = return_statistics(pulse_subset(las, side), seed=seed, bootstrap=bootstrap)
    return SimulatedScan(first, las, statistics, pulses, seconds)


def object_pulse_shares(scan: Scan, object_ids: Sequence[int], *, counts: Sequence[int] = (1, 2, 3, 4), seed: int = 0,
                        bootstrap: int = 200) -> tuple[dict[str, tuple[float, float]], int]:  # fmt: skip
    """The shares of a scan's pulses on some objects with 1, 2, ... returns, each with its bootstrap standard deviation.

    For scans whose LAS file cannot tell their pulses apart (a spinning LiDAR's rings fire in one
    column at one GPS time, on one scanner channel), read from the scan itself: a pulse is a
    ``pulse_id``; it is on the objects when one of its returns is (``object_id``); its count is
    its ``number_of_returns``.

    Parameters
    ----------
    scan : Scan
        With the return fields (a multi-return scan).
    object_ids : sequence of int
        The objects' ids (:class:`~zbuf_occlude.sensors.scene.objects.ScanScene`: 1..n; the ground is 0).
    counts : sequence of int
        The return counts whose shares are given.
    seed, bootstrap : int
        Of the bootstrap over the objects' pulses
        (:func:`~zbuf_occlude.sensors.fit.returns.pulse_bootstrap`).

    Returns
    -------
    shares : dict of str to (float, float)
        ``returns_<k>``: the share of the objects' pulses with k returns and its standard deviation.
    n_pulses : int
        The objects' pulses.

    Raises
    ------
    InvalidInputError
        A scan without return fields, or no pulse on the objects.
    """
    from zbuf_occlude.sensors.fit.returns import pulse_bootstrap

    if scan.pulse_id is None or scan.number_of_returns is None:
        raise InvalidInputError("object_pulse_shares needs a scan with the return fields (pulse_id, number_of_returns)")
    on = np.isin(scan.object_id, np.asarray(object_ids, np.int64))
    pulses, first = np.unique(scan.pulse_id[on], return_index=True)
    if len(pulses) == 0:
        raise InvalidInputError(f"no pulse of the scan meets the objects {list(object_ids)}")
    n = scan.number_of_returns[on][first].astype(np.int64)

    def share(k: int):
        hit = (n == k).astype(np.float64)
        return lambda w: float(hit.mean()) if w is None else float(np.dot(w, hit) / w.sum())

    out = pulse_bootstrap(len(n), {f"returns_{k}": share(int(k)) for k in counts}, seed=seed, bootstrap=bootstrap)
    return out, len(n)
