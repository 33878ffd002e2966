"""The clouds of the sim-to-real experiment: meshes per class, whole-mesh splits, four training sets, real scans.

Everything a training set holds is made from meshes only:

``complete``
    Uniform samples of the whole surface (Algorithms 1–2 of Sryamkin et al. 2023).
``occluded``
    The points of a dense surface sample visible from one camera pose (z-buffer HSR,
    :func:`zbuf_occlude.occlude_object`), elevation drawn uniformly in the range the run's
    sensor sees objects from (:func:`sensor_elevation_deg`: low for a spinning LiDAR, from
    above for an airborne scanner; :data:`GROUND_ELEVATION_DEG` without a sensor), azimuth
    in [0, 360).
``lidar``
    Object crops of a simulated spinning LiDAR (:func:`zbuf_occlude.sensors.crops.lidar_object_samples`):
    the object on a ground plane, scaled to a real size drawn from its class's range
    (:data:`zbuf_occlude.mesh.sizes.CLASS_SIZES_M`), the sensor at a distance and height
    drawn from :data:`LIDAR_PLACEMENT` (published geometry, never the real test scans).
``lidar+complete``
    Half of each (the paper's C3 analogue at the same size).

Every cloud ends ``(n_points, 3) float32`` in the pipeline's frame (z up) and is normalised
like the paper's (bounding-box centre 0, max extent 1), or, with ``keep_scale``, centred and
divided by :data:`KEEP_SCALE_UNIT_M` so that size stays a cue.
"""

from __future__ import annotations

import fnmatch
import hashlib
import logging
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.learn.data import CloudSet, dedupe_meshes, normalize_batch, resample
from zbuf_occlude.mesh.sizes import CLASS_SIZES_M, SizeRange, size_interval

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

    from zbuf_occlude.sensors.placement import CropDistributions

__all__ = [
    "TRAINING_SETS", "GROUND_ELEVATION_DEG", "LIDAR_PLACEMENT", "MIN_RETURNS", "KEEP_SCALE_UNIT_M",
    "MeshEntry", "find_class_meshes", "check_lidar_meshes", "split_whole_meshes", "allocate", "build_set", "build_sets", "mix_sets",
    "real_clouds", "real_scan_rows", "FITTED", "FITTED_PLACED", "POOLED", "FITTED_SETS", "fit_mesh_shapes", "WIDTH_BY",
    "sensor_elevation_deg", "scan_key", "real_halves",
]  # fmt: skip

log = logging.getLogger(__name__)

#: The training sets, in report order (``complete`` is the reference of the permutation tests).
TRAINING_SETS = ("complete", "occluded", "lidar", "lidar+complete")
#: The set made with a sensor fitted to the real scans (``Sim2RealConfig(fit_sensor=True)``): LiDAR
#: crops like ``lidar``'s, from the same placements and sizes, only the sensor differs.
FITTED = "fitted"
#: The fitted sensor, and per class the sensor distances, the objects' heights and their hidden
#: bottoms fitted to the same scans (:func:`zbuf_occlude.sensors.fit.crop_placement_json`); the
#: headings are ``lidar``'s.
FITTED_PLACED = "fitted+placed"
#: The three LiDAR sets of one seed pooled, ``lidar``, ``fitted`` and ``fitted+placed`` (three times
#: their clouds): the sensor and the placements drawn from what the fit pins down and from the
#: wider published ranges alike, so that a classifier meets more of what real scans vary in.
POOLED = "pooled"
#: The sets made with a fitted sensor, in report order.
FITTED_SETS = (FITTED, FITTED_PLACED, POOLED)
#: Camera elevations of the ``occluded`` set without a sensor to derive them from
#: (:func:`sensor_elevation_deg`), degrees: a sensor on the ground or on a vehicle sees objects
#: from slightly below the horizon (kerbs, slopes) to about 30° above (a pedestrian or a bush a
#: few metres from a roof-mounted sensor).
GROUND_ELEVATION_DEG = (-5.0, 30.0)
#: Sensor placement of the ``lidar`` set (uniform draws): the distance range where a 32-beam
#: sensor at 1.33° ring spacing puts at least three rings on a 1.5 m object (1.5 m / (3 · tan 1.33°)
#: ≈ 21 m) up to 25 m, from 5 m (closer, the object leaves the vertical field of view); the
#: height of a roof mount on a passenger car or small UGV (1.6–2.0 m; KITTI's HDL-64E: 1.73 m).
LIDAR_PLACEMENT = {"distance_m": (5.0, 25.0), "height_m": (1.6, 2.0)}
#: A crop with fewer returns is redrawn: a segmentation pipeline drops clusters this small, and
#: a handful of points padded to ``n_points`` describes no shape (fixed before any real scan was scored).
MIN_RETURNS = 30
#: ``keep_scale``: clouds are centred and divided by this many metres (a 10 m object spans ±0.5 ... 1).
KEEP_SCALE_UNIT_M = 10.0
#: How a placement's ``across_sight_width_by`` meets its class's ``across_sight_width_m``: a
#: horizontal stretch of each mesh, the same stretch where it widens the mesh and none where it
#: would narrow it, or a side occluder that leaves part of it in view
#: (:func:`zbuf_occlude.sensors.fit.fit_object_shape`).
WIDTH_BY = ("stretch", "widen", "occluder")
#: Rounds of crop draws per mesh before the crops found are repeated (logged).
_LIDAR_TRIES = 6


def sensor_elevation_deg(sensor) -> tuple[tuple[float, float], str]:
    """The camera elevations, degrees, from which ``sensor`` sees an object on the ground, and how they were found.

    * A spinning LiDAR (:class:`~zbuf_occlude.sensors.lidar.Lidar`) on the ``lidar`` set's mount
      (:data:`LIDAR_PLACEMENT`: heights ``h`` of 1.6–2.0 m, objects ``d`` = 5–25 m away) is seen
      from the object's foot at ``atan(h / d)``: from ``atan(h_lo / d_hi)`` (the low mount, the
      far object) to ``atan(h_hi / d_lo)`` (the high mount, the near one), about 3.7° to 21.8°.
    * An airborne scanner (:class:`~zbuf_occlude.sensors.airborne.AirborneScanner`) sees the
      ground at incidence angles from 0° (nadir) to half its swath (the strip's edge, where a
      flight plan's neighbouring lines see a point again), so from elevations ``90° − swath/2``
      to 90° (61° to 90° for the RIEGL LMS-Q1560's 58° swath).
    * None: :data:`GROUND_ELEVATION_DEG`.

    Returns
    -------
    (lo_deg, hi_deg) : tuple of float
        ``lo_deg <= hi_deg``, within [-90, 90].
    source : str
        One line saying how (recorded in ``settings.json`` as ``occluded_elevation_from``).

    Raises
    ------
    InvalidInputError
        A sensor of another kind (a depth camera: no mount to derive elevations from).
    """
    from zbuf_occlude.sensors.airborne import AirborneScanner
    from zbuf_occlude.sensors.lidar import Lidar

    if sensor is None:
        return GROUND_ELEVATION_DEG, "no sensor: a ground sensor's default range"
    if isinstance(sensor, AirborneScanner):
        half = float(sensor.swath_deg) / 2.0
        return (90.0 - half, 90.0), f"sensor {sensor.name}: 90° minus its incidence angles, 0° to half its {float(sensor.swath_deg):g}° swath"
    if isinstance(sensor, Lidar):
        (h_lo, h_hi), (d_lo, d_hi) = LIDAR_PLACEMENT["height_m"], LIDAR_PLACEMENT["distance_m"]
        lo, hi = math.degrees(math.atan2(h_lo, d_hi)), math.degrees(math.atan2(h_hi, d_lo))
        return (lo, hi), (f"sensor {sensor.name}: atan(height / distance) over the lidar set's mount, heights {h_lo:g}-{h_hi:g} m, "
                          f"distances {d_lo:g}-{d_hi:g} m")  # fmt: skip
    raise InvalidInputError(f"no elevation range for a {type(sensor).__name__}: give the occluded set's elevations")


@dataclass
class MeshEntry:
    """One mesh of the experiment: file, class, stable name, the loaded (z-up, normalised) mesh."""

    path: Path
    class_name: str
    name: str
    mesh: trimesh.Trimesh


def _up_for(rel: str, up: str, up_map: dict[str, str]) -> str:
    for pattern, axis in up_map.items():
        if fnmatch.fnmatch(rel, pattern):
            return axis
    return up


def find_class_meshes(root: str | os.PathLike, *, up: str = "auto", up_map: dict[str, str] | None = None,
                      classes: list[str] | None = None) -> list[MeshEntry]:  # fmt: skip
    """Meshes under ``root/CLASS/...`` (the class is the first folder), loaded, duplicates dropped.

    Parameters
    ----------
    up : str
        Up axis of every file (:func:`zbuf_occlude.load_mesh`; ``auto``: each format's convention).
    up_map : dict, optional
        ``{glob of the path relative to root: axis}``, first match wins, for files that break
        their format's convention.

    Raises
    ------
    InvalidInputError
        No mesh, fewer than two classes, or a class with a single mesh (nothing to validate on).
    MeshLoadError
        A mesh that cannot be loaded (named).
    """
    from zbuf_occlude.mesh.discovery import walk_mesh_files
    from zbuf_occlude.mesh.load import load_mesh

    root = Path(root)
    if not root.is_dir():
        raise InvalidInputError(f"mesh root {root} is not a folder")
    files, _ = walk_mesh_files(root, skip_hidden=True)
    files = [f for f in files if len(f.relative_to(root).parts) >= 2]
    kept, dropped = dedupe_meshes(files)
    for dup, orig in dropped:
        log.warning("dropping %s: same bytes as %s", dup, orig)
    out = []
    for f in kept:
        rel = f.relative_to(root).as_posix()
        cls = rel.split("/", 1)[0]
        if classes and cls not in classes:
            continue
        mesh = load_mesh(f, up=_up_for(rel, up, up_map or {}))
        out.append(MeshEntry(f, cls, rel.rsplit(".", 1)[0], mesh))
    _check_classes(out, str(root))
    return out


def _check_classes(meshes: list[MeshEntry], where: str) -> None:
    by_class: dict[str, list[MeshEntry]] = {}
    for m in meshes:
        by_class.setdefault(m.class_name, []).append(m)
    if len(by_class) < 2:
        raise InvalidInputError(f"{where}: need meshes of two or more classes in CLASS/ folders, found {sorted(by_class)}")
    single = [c for c, ms in by_class.items() if len(ms) < 2]
    if single:
        raise InvalidInputError(f"{where}: classes {single} have one mesh; a held-out mesh is needed for validation")


def check_lidar_meshes(meshes: list[MeshEntry], sensor, sizes: dict[str, SizeRange], n_points: int, *,
                       min_returns: int = MIN_RETURNS, placement: dict[str, dict] | None = None,
                       ) -> tuple[list[MeshEntry], list[str]]:  # fmt: skip
    """The meshes that give a LiDAR crop with ``min_returns`` returns, and the paths of those that do not.

    Run before any training set is made, so that a mesh the sensor cannot see (too small for
    its class's size, a sliver) is skipped, with a warning naming its file, instead of aborting
    the run minutes later.  One draw per mesh (:func:`_lidar` with ``k=1``, seed 0), with the
    class's ``placement`` where given (as :func:`build_set`).

    Raises
    ------
    InvalidInputError
        A class without a size range, or fewer than two classes of two meshes left.
    """
    missing = sorted({m.class_name for m in meshes} - set(sizes))
    if missing:
        raise InvalidInputError(f"no real size for classes {missing}; give them with --sizes CLASS=height:LO-HI")
    kept, skipped = [], []
    for entry in meshes:
        try:
            _lidar(entry, 1, n_points, 0, sensor, sizes[entry.class_name], min_returns, _placement_of(placement, entry))
        except InvalidInputError as exc:
            log.warning("skipping mesh %s: %s", entry.path, exc)
            skipped.append(str(entry.path))
            continue
        kept.append(entry)
    if skipped:
        _check_classes(kept, f"after skipping {len(skipped)} meshes without a LiDAR crop ({', '.join(skipped)})")
    return kept, skipped


def split_whole_meshes(meshes: list[MeshEntry], fraction: float, seed: int) -> tuple[list[MeshEntry], list[MeshEntry]]:
    """Training and validation meshes: per class ``round(fraction · n)`` whole meshes (at least
    one, at most ``n − 1``) drawn with ``seed`` go to validation; no mesh is on both sides."""
    rng = np.random.default_rng([seed, 0x5E2])
    train, val = [], []
    for cls in sorted({m.class_name for m in meshes}):
        ms = [m for m in meshes if m.class_name == cls]
        k = min(max(int(round(fraction * len(ms))), 1), len(ms) - 1)
        held = set(rng.permutation(len(ms))[:k].tolist())
        for i, m in enumerate(ms):
            (val if i in held else train).append(m)
    return train, val


def allocate(n_meshes: int, n_clouds: int, rng: np.random.Generator) -> NDArray[np.int64]:
    """Clouds per mesh: ``n_clouds`` spread evenly, the remainder to meshes drawn at random."""
    counts = np.full(n_meshes, n_clouds // n_meshes, dtype=np.int64)
    counts[rng.permutation(n_meshes)[: n_clouds % n_meshes]] += 1
    return counts


def _draw_sizes(mesh: trimesh.Trimesh, size: SizeRange, k: int, rng: np.random.Generator) -> NDArray[np.float64]:
    lo, hi = size_interval(mesh.extents, size)
    return rng.uniform(lo, hi, k)


def _complete(entry: MeshEntry, k: int, n_points: int, rng: np.random.Generator) -> list[NDArray]:
    from zbuf_occlude.geometry.sampling import sample_surface

    return [sample_surface(entry.mesh, count=n_points, seed=rng)[0] for _ in range(k)]


def _occluded(entry: MeshEntry, k: int, n_points: int, seed: int, rng: np.random.Generator, *, dense_points: int,
              resolution: int, method: str, elevation_deg: tuple[float, float] = GROUND_ELEVATION_DEG) -> list[NDArray]:  # fmt: skip
    from zbuf_occlude.geometry.samples import object_key
    from zbuf_occlude.pipeline import dense_cloud, occlude_object

    key = object_key(entry.name)
    poses = list(zip(rng.uniform(*elevation_deg, 2 * k + 2), rng.uniform(0.0, 360.0, 2 * k + 2)))
    dense = dense_cloud(entry.mesh, key, seed=seed, count=dense_points)
    out = []
    for _, _, clouds in occlude_object(entry.mesh, poses, key=key, n_points=n_points, samples_per_view=1, seed=seed,
                                       dense=dense, method=method, resolution=resolution):  # fmt: skip
        if clouds:
            out.append(clouds[0].points.astype(np.float64))
        if len(out) == k:
            break
    if len(out) < k:
        raise InvalidInputError(f"{entry.path}: only {len(out)} of {k} poses see any point")
    return out


def _placement_of(placement: dict[str, dict] | None, entry: MeshEntry) -> dict:
    """``placement``'s keywords for ``entry``: its class's, and over them its own (keyed by its name)."""
    return {**(placement or {}).get(entry.class_name, {}), **(placement or {}).get(entry.name, {})}


def _distributions(entry: MeshEntry, size: SizeRange, placement: dict) -> tuple[CropDistributions, dict]:
    """The mesh's crop distributions (its stretch left out unless given) and what its class's
    ``across_sight_width_m``, ``across_sight_profile`` and ``across_sight_width_by`` ask
    :func:`_fit_shape` to fit (``width_m``, ``profile``, ``by``)."""
    from zbuf_occlude.sensors.placement import CropDistributions

    keywords = {**LIDAR_PLACEMENT, **placement}
    by = keywords.pop("across_sight_width_by", "stretch")
    if by not in WIDTH_BY:
        raise InvalidInputError(f"across_sight_width_by must be one of {WIDTH_BY}, got {by!r}")
    shape = {"width_m": keywords.pop("across_sight_width_m", None), "profile": keywords.pop("across_sight_profile", None), "by": by}
    return CropDistributions(size_m=size_interval(entry.mesh.extents, size), **keywords), shape


def _fit_shape(entry: MeshEntry, sensor, dist: CropDistributions, shape: dict) -> dict:
    """The mesh's :func:`~zbuf_occlude.sensors.fit.fit_object_shape` for a ``shape`` of :func:`_distributions`
    (with ``by="widen"``, each stretch below 1 raised to 1: never narrower than the mesh)."""
    from zbuf_occlude.sensors.fit import fit_object_shape

    out = fit_object_shape(entry.mesh, sensor, dist, shape["width_m"], shape["profile"], occlude=shape["by"] == "occluder",
                           name=str(entry.path))  # fmt: skip
    if shape["by"] == "widen" and "width_scale" in out:
        out["width_scale"] = tuple(max(v, 1.0) for v in out["width_scale"])
    return out


def fit_mesh_shapes(meshes: list[MeshEntry], sensor, sizes: dict[str, SizeRange], placement: dict[str, dict]) -> dict[str, dict]:
    """Each mesh's stretch to its class's ``across_sight_width_m`` and warp to its ``across_sight_profile`` in ``placement``, once for every training set and seed.

    Returns ``{mesh name: {"width_scale": (lo, hi), "width_profile": (K factors)}}`` (``"visible_across_sight"``
    instead of ``"width_scale"`` where the class's ``across_sight_width_by`` is ``"occluder"``)
    (:func:`_fit_shape`, seed 0; each key where the class gives what it fits) for the meshes of classes that give either, to merge into ``placement``: a mesh's
    own keywords override its class's (:func:`build_set`), so the crops are what fitting the
    stretch in every draw would give, without fitting it again.  A mesh whose stretch cannot be
    fitted is left out (its crops then raise, naming it; :func:`check_lidar_meshes` skips it).
    """
    out = {}
    for entry in meshes:
        dist, shape = _distributions(entry, sizes[entry.class_name], _placement_of(placement, entry))
        if shape["width_m"] is not None or shape["profile"] is not None:
            try:
                out[entry.name] = _fit_shape(entry, sensor, dist, shape)
            except InvalidInputError as exc:
                log.warning("%s", exc)
    return out


def _lidar(entry: MeshEntry, k: int, n_points: int, seed: int, sensor, size: SizeRange, min_returns: int = MIN_RETURNS,
           placement: dict | None = None) -> tuple[list[NDArray], list[float]]:  # fmt: skip
    from zbuf_occlude.sensors.crops import lidar_object_samples
    dist, shape = _distributions(entry, size, placement or {})
    width_given = dist.visible_across_sight if shape["by"] == "occluder" else dist.width_scale
    if (shape["width_m"] is not None and width_given is None) or (shape["profile"] is not None and dist.width_profile is None):
        dist = replace(dist, **_fit_shape(entry, sensor, dist, shape))  # this mesh's, to the class's scans
    good: list = []
    # Draw about as many crops as needed, then more under another name (new placements) while
    # crops come back with fewer than min_returns returns; at most _LIDAR_TRIES rounds.
    for attempt in range(_LIDAR_TRIES):
        want = k - len(good)
        name = entry.name if attempt == 0 else f"{entry.name}#retry{attempt}"
        extra = max(1, want // 5) if attempt == 0 else want + 2  # later rounds: small objects far away miss more
        clouds = lidar_object_samples(entry.mesh, sensor, name=name, n_samples=want + extra, n_points=n_points,
                                      seed=seed, distributions=dist, class_name=entry.class_name)  # fmt: skip
        good += [c for c in clouds if c.n_visible >= min_returns][:want]
        if len(good) == k:
            break
    if not good:
        raise InvalidInputError(f"{entry.path}: no LiDAR crop with {min_returns} returns in {_LIDAR_TRIES} rounds; "
                                "lower --min-returns (a sparse or airborne sensor) or give larger --sizes")
    if len(good) < k:
        log.warning("%s: %d of %d LiDAR crops have >= %d returns; repeating them", entry.name, len(good), k, min_returns)
        good = [good[i % len(good)] for i in range(k)]
    return [c.points.astype(np.float64) for c in good], [float(c.extra["size_m"]) for c in good]


def _finish(clouds: list[NDArray], sizes_m: NDArray[np.float64], keep_scale: bool, rng: np.random.Generator) -> NDArray[np.float32]:
    """Normalise (paper) or scale to metres and centre (``keep_scale``, with a random yaw)."""
    pts = np.stack(clouds)
    if not keep_scale:
        return normalize_batch(pts)
    pts = pts * np.asarray(sizes_m, dtype=np.float64)[:, None, None]
    theta = rng.uniform(0.0, 2 * np.pi, len(pts))
    c, s = np.cos(theta), np.sin(theta)
    x, y = pts[..., 0].copy(), pts[..., 1].copy()
    pts[..., 0], pts[..., 1] = c[:, None] * x - s[:, None] * y, s[:, None] * x + c[:, None] * y
    lo, hi = pts.min(axis=1, keepdims=True), pts.max(axis=1, keepdims=True)
    return ((pts - (lo + hi) / 2) / KEEP_SCALE_UNIT_M).astype(np.float32)


def build_set(kind: str, meshes: list[MeshEntry], names: list[str], per_class: int, n_points: int, seed: int, *,
              sensor=None, sizes: dict[str, SizeRange] = CLASS_SIZES_M, keep_scale: bool = False,
              dense_points: int = 8192, resolution: int = 512, method: str = "auto",
              min_returns: int = MIN_RETURNS, elevation_deg: tuple[float, float] = GROUND_ELEVATION_DEG,
              placement: dict[str, dict] | None = None, progress: bool = False) -> CloudSet:  # fmt: skip
    """``per_class`` clouds of every class in ``names`` from ``meshes``, of one training set kind.

    Cloud counts are spread over each class's meshes (:func:`allocate`); ``lidar+complete``
    is :func:`mix_sets` of the ``lidar`` and ``complete`` sets of the same seed.
    ``object_index`` is the mesh's row in ``meshes``; ``elevation_deg`` is NaN.  A LiDAR crop
    with fewer than ``min_returns`` returns is redrawn (:data:`MIN_RETURNS`; an airborne
    scanner at a few points per m² needs a much lower value for small objects).  The
    ``occluded`` set's camera elevations are drawn uniformly in ``elevation_deg`` (degrees).
    ``placement`` gives a LiDAR set's :class:`~zbuf_occlude.sensors.placement.CropDistributions`
    keywords per class (``{class: {"distance_m": (lo, hi), "hidden_below_m": (lo, hi)}}``,
    metres), over :data:`LIDAR_PLACEMENT`'s, and per mesh (keyed by its name, over its class's);
    a class's ``"across_sight_width_m": (lo, hi)`` stretches each of its meshes to those widths
    (:func:`zbuf_occlude.sensors.fit.fit_width_scale`; with ``"across_sight_width_by": "widen"``
    never narrower), or with ``"occluder"`` hides a side of each where its crops are wider
    (:func:`zbuf_occlude.sensors.fit.fit_visible_across_sight`; :data:`WIDTH_BY`), and its ``"across_sight_profile"`` warps
    them to that outline (:func:`zbuf_occlude.sensors.fit.fit_width_profile`), unless the
    mesh gives its ``width_scale`` (or ``visible_across_sight``) and ``width_profile`` (:func:`fit_mesh_shapes`).
    ``progress`` shows the meshes done on stderr (:func:`zbuf_occlude.io.progress.progress`).

    Raises
    ------
    InvalidInputError
        Unknown kind, a class without a size range, or a mesh no pose or crop sees.
    """
    if kind not in TRAINING_SETS:
        raise InvalidInputError(f"unknown training set {kind!r}; choose from {TRAINING_SETS}")
    if kind == "lidar+complete":
        common = dict(sizes=sizes, keep_scale=keep_scale, progress=progress)
        lidar = build_set("lidar", meshes, names, per_class, n_points, seed, sensor=sensor, min_returns=min_returns,
                          placement=placement, **common)  # fmt: skip
        return mix_sets(lidar, build_set("complete", meshes, names, per_class, n_points, seed, **common), seed)
    missing = sorted({m.class_name for m in meshes} - set(sizes))
    if missing and (kind == "lidar" or keep_scale):
        raise InvalidInputError(f"no real size for classes {missing}; give them with --sizes CLASS=height:LO-HI")
    from zbuf_occlude.io.progress import progress as progress_bar

    rng = np.random.default_rng([seed, TRAINING_SETS.index(kind), 0x52])
    clouds, sizes_m, labels, objs = [], [], [], []
    bar = progress_bar(total=sum(m.class_name in names for m in meshes), desc=f"sim2real {kind} set", unit="mesh", enabled=progress)
    for label, cls in enumerate(names):
        rows = [i for i, m in enumerate(meshes) if m.class_name == cls]
        for i, k in zip(rows, allocate(len(rows), per_class, rng)):
            if k == 0:
                bar.update(1)
                continue
            entry = meshes[i]
            if kind == "complete":
                got = _complete(entry, int(k), n_points, rng)
            elif kind == "occluded":
                got = _occluded(entry, int(k), n_points, seed, rng, dense_points=dense_points, resolution=resolution, method=method,
                                elevation_deg=elevation_deg)  # fmt: skip
            else:
                got, size_k = _lidar(entry, int(k), n_points, seed, sensor, sizes[cls], min_returns, _placement_of(placement, entry))
            if kind == "lidar":
                sizes_m.extend(size_k)
            elif keep_scale:
                sizes_m.extend(_draw_sizes(entry.mesh, sizes[cls], len(got), rng).tolist())
            else:
                sizes_m.extend([1.0] * len(got))
            clouds += got
            labels += [label] * len(got)
            objs += [i] * len(got)
            bar.update(1)
    bar.close()
    points = _finish(clouds, np.asarray(sizes_m), keep_scale, rng)
    n = len(labels)
    return CloudSet(points, np.asarray(labels, np.int64), np.full(n, np.nan), np.asarray(objs, np.int64))


def mix_sets(a: CloudSet, b: CloudSet, seed: int) -> CloudSet:
    """Per class, half of the clouds (rounded up) drawn from ``a`` and the rest from ``b``, as
    many per class as ``a`` has: the ``lidar+complete`` set from the ``lidar`` and ``complete`` sets."""
    rng = np.random.default_rng([seed, 0x313])
    rows_a, rows_b = [], []
    for c in np.unique(a.labels):
        n = int((a.labels == c).sum())
        rows_a += rng.permutation(np.flatnonzero(a.labels == c))[: (n + 1) // 2].tolist()
        rows_b += rng.permutation(np.flatnonzero(b.labels == c))[: n // 2].tolist()
    return CloudSet.concat([a.subset(np.sort(np.asarray(rows_a, np.int64))), b.subset(np.sort(np.asarray(rows_b, np.int64)))])


def build_sets(meshes: list[MeshEntry], names: list[str], per_class: int, n_points: int, seed: int, *,
               fitted_sensor=None, fitted_placement: dict[str, dict] | None = None,
               fitted_sizes: dict[str, SizeRange] | None = None, kinds: Sequence[str] | None = None,
               **options) -> dict[str, CloudSet]:  # fmt: skip
    """The training sets of one seed (options as :func:`build_set`): :data:`TRAINING_SETS`
    (``lidar+complete`` mixes the other two); with ``fitted_sensor`` the :data:`FITTED` set, the
    ``lidar`` set's recipe (the same seed, so the same sizes and placements) scanned by
    ``fitted_sensor``; and with ``fitted_placement`` (per class, as :func:`build_set`'s
    ``placement``) and ``fitted_sizes`` as well, the :data:`FITTED_PLACED` set, whose crops are
    placed so per class and scaled to those sizes; with both, :data:`POOLED` as well (those
    three LiDAR sets in one, ``3 · per_class`` clouds per class).

    ``kinds`` (default: all of those) names the sets wanted, and only those (and the two that
    ``lidar+complete`` mixes) are made: each set draws from its own random stream, so a set is
    the same whichever others are made with it (a resumed run makes only what it still needs).

    Raises
    ------
    InvalidInputError
        A kind in ``kinds`` that these arguments cannot make, and :func:`build_set`'s errors.
    """
    available = [*TRAINING_SETS]
    if fitted_sensor is not None:
        available.append(FITTED)
        if fitted_placement is not None and fitted_sizes is not None:
            available += [FITTED_PLACED, POOLED]
    wanted = list(available if kinds is None else kinds)
    unknown = [k for k in wanted if k not in available]
    if unknown:
        raise InvalidInputError(f"cannot make training sets {unknown} with these arguments; these can be made: {available}")
    made = set(wanted) | ({"lidar", "complete"} if "lidar+complete" in wanted else set()) | ({"lidar", FITTED, FITTED_PLACED} if POOLED in wanted else set())
    out = {kind: build_set(kind, meshes, names, per_class, n_points, seed, **options) for kind in TRAINING_SETS[:3] if kind in made}
    if "lidar+complete" in made:
        out["lidar+complete"] = mix_sets(out["lidar"], out["complete"], seed)
    if FITTED in made:
        out[FITTED] = build_set("lidar", meshes, names, per_class, n_points, seed, **{**options, "sensor": fitted_sensor})
    if FITTED_PLACED in made:
        out[FITTED_PLACED] = build_set("lidar", meshes, names, per_class, n_points, seed,
                                       **{**options, "sensor": fitted_sensor, "placement": fitted_placement, "sizes": fitted_sizes})  # fmt: skip
    if POOLED in made:
        out[POOLED] = CloudSet.concat([out["lidar"], out[FITTED], out[FITTED_PLACED]])
    return {kind: out[kind] for kind in available if kind in wanted}


def _real_label(scan, index: dict[str, int], label_map: dict[str, str]) -> str:
    label = label_map.get(scan.label, scan.label)
    return label if label in index else label.lower()


def real_scan_rows(scans, names: list[str], label_map: dict[str, str]) -> list[int]:
    """Indices into ``scans`` of the scans :func:`real_clouds` keeps (a label among ``names``), in its order."""
    index = {n: i for i, n in enumerate(names)}
    return [i for i, s in enumerate(scans) if _real_label(s, index, label_map) in index]


def scan_key(points: NDArray, seed: int = 0) -> int:
    """A 64-bit key of a scan's content: the first 8 bytes of the SHA-256 of ``seed`` and the
    scan's ``(n, 3)`` points as float32, as an unsigned integer.

    The same points give the same key whatever file they came from, its name or its place in
    the data set; another ``seed`` gives an unrelated key (a seeded draw per scan).
    """
    pts = np.ascontiguousarray(points, dtype=np.float32)
    digest = hashlib.sha256(int(seed).to_bytes(8, "little", signed=True) + np.asarray(pts.shape, np.int64).tobytes() + pts.tobytes())
    return int.from_bytes(digest.digest()[:8], "little")


def real_halves(points: Sequence[NDArray], labels: NDArray[np.integer], seed: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """A fixed stratified split of the real scans into two halves, from their content alone.

    Each class's scans are ordered by :func:`scan_key` of their points with ``seed`` (a seeded
    draw per scan: a random order that no file name, no position in the data set and no other
    class changes); the first ``n // 2`` are half A, the rest half B.  Scans with the same
    points, whose keys tie, keep their order in ``points`` (the reader's, sorted by path).

    Parameters
    ----------
    points : sequence of (n_i, 3) arrays
        The scans' points (``RealScan.points``), one per row of ``labels``.
    labels : (S,) int
    seed : int

    Returns
    -------
    half_a, half_b : int64 arrays
        Rows of ``labels``, class by class (in ``np.unique`` order), each class's rows in key order.
    """
    labels = np.asarray(labels)
    keys = np.asarray([scan_key(p, seed) for p in points], dtype=np.uint64)
    a, b = [], []
    for c in np.unique(labels):
        rows = np.flatnonzero(labels == c)
        rows = rows[np.argsort(keys[rows], kind="stable")]
        a += rows[: len(rows) // 2].tolist()
        b += rows[len(rows) // 2 :].tolist()
    return np.asarray(a, np.int64), np.asarray(b, np.int64)


def real_clouds(scans, names: list[str], label_map: dict[str, str], n_points: int, seed: int, *,
                keep_scale: bool = False) -> tuple[NDArray[np.float32], NDArray[np.int64], list[str]]:  # fmt: skip
    """Real scans as clouds of ``n_points`` (random subset, or all plus repeats) and label indices.

    Labels are renamed with ``label_map`` (then lower-cased when that matches a class); scans
    of labels outside ``names`` are left out (logged).  Each scan's subset is drawn with
    ``seed`` and its own :func:`scan_key`, so that it depends on its points only, not on where
    the reader found it.

    Returns
    -------
    points : (S, n_points, 3) float32; labels : (S,) int64; sources : list of str
    """
    index = {n: i for i, n in enumerate(names)}
    pts, labels, sources, dropped = [], [], [], {}
    for s in scans:
        label = _real_label(s, index, label_map)
        if label not in index:
            dropped[s.label] = dropped.get(s.label, 0) + 1
            continue
        rng = np.random.default_rng([seed, 0x2EA1, scan_key(s.points)])
        p = resample(np.asarray(s.points, np.float32)[None], n_points, rng)[0].astype(np.float64)
        if keep_scale:
            p = p * float(np.max(s.extent_m))
        pts.append(p)
        labels.append(index[label])
        sources.append(s.source)
    if dropped:
        log.warning("real scans left out (label not a training class %s): %s", names, dropped)
    if not pts:
        raise InvalidInputError(f"no real scan has a label among the training classes {names}; use --label-map")
    arr = np.stack(pts)
    if keep_scale:
        lo, hi = arr.min(axis=1, keepdims=True), arr.max(axis=1, keepdims=True)
        out = ((arr - (lo + hi) / 2) / KEEP_SCALE_UNIT_M).astype(np.float32)
    else:
        out = normalize_batch(arr)
    return out, np.asarray(labels, np.int64), sources
