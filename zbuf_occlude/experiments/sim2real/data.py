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
``occluded-points`` (:data:`OCCLUDED_POINTS`, made only when asked for)
    The ``occluded`` set's clouds with visibility decided from the dense surface sample alone,
    without the mesh: the same dense sample, poses and draws, each point kept where the z-buffer
    test over point splats keeps it (:func:`zbuf_occlude.visibility.point_splats.point_surfels`
    of the points, normals estimated, then ``.visible(camera)``; the registered method
    ``"point-splat"``).  A pose that sees fewer than ``n_points`` points is not topped up (that
    samples the mesh's faces): its cloud repeats points.

Every cloud ends ``(n_points, 3) float32`` in the pipeline's frame (z up) and is normalised
like the paper's (bounding-box centre 0, max extent 1), or, with ``keep_scale``, centred and
divided by :data:`KEEP_SCALE_UNIT_M` so that size stays a cue.

The meshes are found in :mod:`zbuf_occlude.mesh.inputs.class_folders`, the crops placed and the meshes shaped in
:mod:`zbuf_occlude.sensors.fit.class_placement`, the real scans read in :mod:`.real`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.mesh.inputs.class_folders import MeshEntry, check_classes
from zbuf_occlude.sensors.fit.class_placement import LIDAR_PLACEMENT, MIN_RETURNS, CropPlacement, crops_to_draw
from zbuf_occlude.experiments.sim2real.real import KEEP_SCALE_UNIT_M
from zbuf_occlude.learn.data import CloudSet, normalize_batch
from zbuf_occlude.mesh.sizes import CLASS_SIZES_M, SizeRange, size_interval

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = [
    "TRAINING_SETS", "GROUND_ELEVATION_DEG", "FITTED", "FITTED_PLACED", "POOLED", "FITTED_SETS",
    "OCCLUDED_POINTS", "POINT_VISIBILITY", "SetRecipe", "sensor_elevation_deg", "check_lidar_meshes", "allocate", "build_set", "build_sets", "mix_sets",
]  # fmt: skip

log = logging.getLogger(__name__)

#: The training sets, in report order (``complete`` is the reference of the permutation tests).
TRAINING_SETS = ("complete", "occluded", "lidar", "lidar+complete")
#: The ``occluded`` set with visibility decided from its dense points alone, no mesh (module
#: docstring): made only when asked for (``Sim2RealConfig(occluded_points=True)``, or ``kinds`` of
#: :func:`build_sets`), from the ``occluded`` set's random stream, so the same poses and draws.
OCCLUDED_POINTS = "occluded-points"
#: The visibility method of :data:`OCCLUDED_POINTS`: the points alone, normals estimated.
POINT_VISIBILITY = "point-splat"
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
#: Rounds of crop draws per mesh before the crops found are repeated (logged).
_LIDAR_TRIES = 6


def sensor_elevation_deg(sensor) -> tuple[tuple[float, float], str]:
    """The camera elevations, degrees, from which ``sensor`` sees an object on the ground, and how they were found.

    * A spinning LiDAR (:class:`~zbuf_occlude.sensors.patterns.spinning.Lidar`) on the ``lidar`` set's mount
      (:data:`LIDAR_PLACEMENT`: heights ``h`` of 1.6–2.0 m, objects ``d`` = 5–25 m away) is seen
      from the object's foot at ``atan(h / d)``: from ``atan(h_lo / d_hi)`` (the low mount, the
      far object) to ``atan(h_hi / d_lo)`` (the high mount, the near one), about 3.7° to 21.8°.
    * An airborne scanner (:class:`~zbuf_occlude.sensors.patterns.airborne.AirborneScanner`) sees the
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
    from zbuf_occlude.sensors.kinds import kind_of

    if sensor is None:
        return GROUND_ELEVATION_DEG, "no sensor: a ground sensor's default range"
    kind = kind_of(sensor)
    if kind.flies:
        half = float(sensor.swath_deg) / 2.0
        return (
            90.0 - half,
            90.0,
        ), f"sensor {sensor.name}: 90° minus its incidence angles, 0° to half its {float(sensor.swath_deg):g}° swath"
    if kind.spins:
        (h_lo, h_hi), (d_lo, d_hi) = LIDAR_PLACEMENT["height_m"], LIDAR_PLACEMENT["distance_m"]
        lo, hi = math.degrees(math.atan2(h_lo, d_hi)), math.degrees(math.atan2(h_hi, d_lo))
        return (lo, hi), (f"sensor {sensor.name}: atan(height / distance) over the lidar set's mount, heights {h_lo:g}-{h_hi:g} m, "
                          f"distances {d_lo:g}-{d_hi:g} m")  # fmt: skip
    raise InvalidInputError(f"no elevation range for a {kind.title}: give the occluded set's elevations")


def check_lidar_meshes(meshes: list[MeshEntry], sensor, sizes: Mapping[str, SizeRange], n_points: int, *,
                       min_returns: int = MIN_RETURNS, placement: CropPlacement | None = None,
                       ) -> tuple[list[MeshEntry], list[str]]:  # fmt: skip
    """The meshes that give a LiDAR crop with ``min_returns`` returns, and the paths of those that do not.

    Run before any training set is made, so that a mesh the sensor cannot see (too small for
    its class's size, a sliver) is skipped, with a warning naming its file, instead of aborting
    the run minutes later.  One draw per mesh (:func:`_lidar` with ``k=1``, seed 0), placed by
    ``placement`` where given (as :func:`build_set`).

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
            _lidar(entry, 1, n_points, 0, sensor, sizes[entry.class_name], min_returns, placement)
        except InvalidInputError as exc:
            log.warning("skipping mesh %s: %s", entry.path, exc)
            skipped.append(str(entry.path))
            continue
        kept.append(entry)
    if skipped:
        check_classes(kept, f"after skipping {len(skipped)} meshes without a LiDAR crop ({', '.join(skipped)})")
    return kept, skipped


def allocate(n_meshes: int, n_clouds: int, rng: np.random.Generator) -> NDArray[np.int64]:
    """Clouds per mesh: ``n_clouds`` spread evenly, the remainder to meshes drawn at random."""
    counts = np.full(n_meshes, n_clouds // n_meshes, dtype=np.int64)
    counts[rng.permutation(n_meshes)[: n_clouds % n_meshes]] += 1
    return counts


@dataclass(frozen=True)
class SetRecipe:
    """How the clouds of a training set are made (:func:`build_set`), beyond the meshes, counts and seed.

    Attributes
    ----------
    sensor : Lidar or AirborneScanner, optional
        Scanner of the ``lidar`` set (and of ``lidar+complete``'s half); the other sets need none.
    sizes : mapping of str to SizeRange
        Real size per class (default :data:`zbuf_occlude.mesh.sizes.CLASS_SIZES_M`): the LiDAR
        sets scale each mesh to one drawn in it, and so do the others with ``keep_scale``.
    keep_scale : bool
        Keep metres: clouds centred and divided by :data:`KEEP_SCALE_UNIT_M`, each turned by a
        random yaw, instead of the paper's normalisation (bounding-box centre 0, max extent 1).
    min_returns : int
        A LiDAR crop with fewer returns is redrawn (:data:`MIN_RETURNS`; an airborne scanner at
        a few points per m² needs a much lower value for small objects).
    placement : CropPlacement, optional
        Where the LiDAR crops are placed and the shape each mesh is given, per class and per
        mesh (:mod:`~zbuf_occlude.sensors.fit.class_placement`); None: :data:`LIDAR_PLACEMENT`
        for every class, the meshes' own shapes.
    dense_points, resolution : int
        The ``occluded`` set's dense surface sample per mesh and its z-buffer's resolution, pixels.
    method : str
        HSR method of the ``occluded`` set (:func:`zbuf_occlude.visible_mask`).
    elevation_deg : (lo, hi) float
        The ``occluded`` set's camera elevations, degrees, drawn uniformly (default
        :data:`GROUND_ELEVATION_DEG`; :func:`sensor_elevation_deg` derives them from a sensor).
    footprint : {"exact", "adaptive"}
        How the LiDAR crops cast a pulse's footprint (:func:`~zbuf_occlude.sensors.crops.object_crops`).

    Raises
    ------
    ArgumentTypeError
        A ``placement`` that is no :class:`CropPlacement` (a dict: ``CropPlacement.from_keywords`` takes those).
    """

    sensor: object = None
    sizes: Mapping[str, SizeRange] = field(default_factory=lambda: CLASS_SIZES_M)
    keep_scale: bool = False
    min_returns: int = MIN_RETURNS
    placement: CropPlacement | None = None
    dense_points: int = 8192
    resolution: int = 512
    method: str = "auto"
    elevation_deg: tuple[float, float] = GROUND_ELEVATION_DEG
    footprint: str = "exact"

    def __post_init__(self) -> None:
        if self.placement is not None and not isinstance(self.placement, CropPlacement):
            raise ArgumentTypeError(f"placement must be a CropPlacement (CropPlacement.from_keywords makes one from dicts), "
                                    f"got a {type(self.placement).__name__}")  # fmt: skip


def _draw_sizes(mesh: trimesh.Trimesh, size: SizeRange, k: int, rng: np.random.Generator) -> NDArray[np.float64]:
    lo, hi = size_interval(mesh.extents, size)
    return rng.uniform(lo, hi, k)


def _complete(entry: MeshEntry, k: int, n_points: int, rng: np.random.Generator) -> list[NDArray]:
    from zbuf_occlude.geometry.sampling import sample_surface

    return [sample_surface(entry.mesh, count=n_points, seed=rng)[0] for _ in range(k)]


def _occluded(entry: MeshEntry, k: int, n_points: int, seed: int, rng: np.random.Generator, recipe: SetRecipe, *,
              from_points: bool = False) -> list[NDArray]:  # fmt: skip
    """``k`` occluded clouds of one mesh; ``from_points``: visibility from the dense points alone
    (:data:`POINT_VISIBILITY`, no top-up from the mesh's faces), the same poses and draws otherwise."""
    from zbuf_occlude.geometry.samples import object_key
    from zbuf_occlude.pipeline import CameraSphere, PoseDraws, dense_cloud, occlude_object

    key = object_key(entry.name)
    poses = list(zip(rng.uniform(*recipe.elevation_deg, 2 * k + 2), rng.uniform(0.0, 360.0, 2 * k + 2)))
    dense = dense_cloud(entry.mesh, key, seed=seed, count=recipe.dense_points)
    method, draws = (POINT_VISIBILITY, PoseDraws(n_points, 1, topped_up=False)) if from_points else (recipe.method, PoseDraws(n_points, 1))
    out = []
    for pose_index, _, clouds in occlude_object(entry.mesh, poses, key=key, draws=draws, seed=seed, dense=dense, method=method,
                                                cameras=CameraSphere(resolution=recipe.resolution)):  # fmt: skip
        if clouds:
            out.append(clouds[0].points.astype(np.float64))
            if from_points and clouds[0].n_visible < n_points:
                log.warning("%s: pose %d shows %d of the %d points of a cloud from the points alone; the cloud repeats points",
                            entry.name, pose_index, clouds[0].n_visible, n_points)  # fmt: skip
        if len(out) == k:
            break
    if len(out) < k:
        raise InvalidInputError(f"{entry.path}: only {len(out)} of {k} poses see any point")
    return out


def _lidar(entry: MeshEntry, k: int, n_points: int, seed: int, sensor, size: SizeRange, min_returns: int = MIN_RETURNS,
           placement: CropPlacement | None = None, footprint: str = "exact") -> tuple[list[NDArray], list[float]]:  # fmt: skip
    from zbuf_occlude.sensors.crops import lidar_object_samples

    dist, target = (placement or CropPlacement()).crop_distributions(entry, size)
    if target.lacks_shape(dist):
        dist = replace(dist, **target.fit_mesh(entry, sensor, dist).keywords)  # this mesh's, to the class's scans
    good: list = []
    # Draw about as many crops as needed, then more under another name (new placements) while
    # crops come back with fewer than min_returns returns; at most _LIDAR_TRIES rounds.
    for attempt in range(_LIDAR_TRIES):
        want = k - len(good)
        name = entry.name if attempt == 0 else f"{entry.name}#retry{attempt}"
        drawn = crops_to_draw(want) if attempt == 0 else 2 * want + 2  # later rounds: small objects far away miss more
        clouds = lidar_object_samples(entry.mesh, sensor, name=name, n_samples=drawn, n_points=n_points,
                                      seed=seed, distributions=dist, class_name=entry.class_name, footprint=footprint)  # fmt: skip
        good += [c for c in clouds if c.n_visible >= min_returns][:want]
        if len(good) == k:
            break
    if not good:
        raise InvalidInputError(
            f"{entry.path}: no LiDAR crop with {min_returns} returns in {_LIDAR_TRIES} rounds; "
            "lower --min-returns (a sparse or airborne sensor) or give larger --sizes"
        )
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


def build_set(kind: str, meshes: list[MeshEntry], names: list[str], per_class: int, n_points: int, seed: int,
              recipe: SetRecipe | None = None, *, progress: bool = False) -> CloudSet:  # fmt: skip
    """``per_class`` clouds of every class in ``names`` from ``meshes``, of one training set kind, made as ``recipe`` says.

    Cloud counts are spread over each class's meshes (:func:`allocate`); ``lidar+complete``
    is :func:`mix_sets` of the ``lidar`` and ``complete`` sets of the same seed.  A LiDAR
    set's crops are drawn from ``recipe.placement`` (:class:`CropPlacement`): per class the
    distances, mount heights and hidden bottoms over :data:`LIDAR_PLACEMENT`, and each mesh
    stretched (or partly hidden) to its class's widths and warped to its outline, with the
    mesh's own fitted shape where the placement holds one (:func:`fit_mesh_shapes`) and fitted
    in the draw otherwise.

    Parameters
    ----------
    kind : str
        One of :data:`TRAINING_SETS`, or :data:`OCCLUDED_POINTS` (``occluded``'s random stream:
        the same poses and draws as ``occluded`` of the same seed).
    meshes : list of MeshEntry
    names : list of str
        The classes, in label order (label ``i`` is ``names[i]``).
    per_class, n_points, seed : int
        Clouds per class, points per cloud, and the seed (each kind draws from a stream of its own).
    recipe : SetRecipe, optional
        How the clouds are made (default ``SetRecipe()``: no sensor, the paper's normalisation).
    progress : bool
        Show the meshes done on stderr (:func:`zbuf_occlude.io.progress.progress`).

    Returns
    -------
    CloudSet
        ``points`` ``(len(names) · per_class, n_points, 3) float32``; ``object_index`` is the
        mesh's row in ``meshes``; ``elevation_deg`` is NaN.

    Raises
    ------
    InvalidInputError
        Unknown kind, a class without a size range, or a mesh no pose or crop sees.
    """
    recipe = recipe or SetRecipe()
    if kind not in (*TRAINING_SETS, OCCLUDED_POINTS):
        raise InvalidInputError(f"unknown training set {kind!r}; choose from {(*TRAINING_SETS, OCCLUDED_POINTS)}")
    if kind == "lidar+complete":
        lidar = build_set("lidar", meshes, names, per_class, n_points, seed, recipe, progress=progress)
        return mix_sets(lidar, build_set("complete", meshes, names, per_class, n_points, seed, recipe, progress=progress), seed)
    sizes = recipe.sizes
    missing = sorted({m.class_name for m in meshes} - set(sizes))
    if missing and (kind == "lidar" or recipe.keep_scale):
        raise InvalidInputError(f"no real size for classes {missing}; give them with --sizes CLASS=height:LO-HI")
    from zbuf_occlude.io.progress import progress as progress_bar

    # occluded-points draws from occluded's stream: the same clouds per mesh, poses and samples
    stream = TRAINING_SETS.index("occluded" if kind == OCCLUDED_POINTS else kind)
    rng = np.random.default_rng([seed, stream, 0x52])
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
            elif kind in ("occluded", OCCLUDED_POINTS):
                got = _occluded(entry, int(k), n_points, seed, rng, recipe, from_points=kind == OCCLUDED_POINTS)
            else:
                got, size_k = _lidar(entry, int(k), n_points, seed, recipe.sensor, sizes[cls], recipe.min_returns, recipe.placement,
                                     recipe.footprint)  # fmt: skip
            if kind == "lidar":
                sizes_m.extend(size_k)
            elif recipe.keep_scale:
                sizes_m.extend(_draw_sizes(entry.mesh, sizes[cls], len(got), rng).tolist())
            else:
                sizes_m.extend([1.0] * len(got))
            clouds += got
            labels += [label] * len(got)
            objs += [i] * len(got)
            bar.update(1)
    bar.close()
    points = _finish(clouds, np.asarray(sizes_m), recipe.keep_scale, rng)
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


def build_sets(meshes: list[MeshEntry], names: list[str], per_class: int, n_points: int, seed: int, recipe: SetRecipe | None = None, *,
               fitted_sensor=None, fitted_placement: CropPlacement | None = None, fitted_sizes: Mapping[str, SizeRange] | None = None,
               kinds: Sequence[str] | None = None, progress: bool = False) -> dict[str, CloudSet]:  # fmt: skip
    """The training sets of one seed (as :func:`build_set`): :data:`TRAINING_SETS`
    (``lidar+complete`` mixes the other two); with ``fitted_sensor`` the :data:`FITTED` set, the
    ``lidar`` set's recipe (the same seed, so the same sizes and placements) scanned by
    ``fitted_sensor``; and with ``fitted_placement`` and ``fitted_sizes`` as well, the
    :data:`FITTED_PLACED` set, whose crops are placed and shaped so (per class and per mesh) and
    scaled to those sizes; with both, :data:`POOLED` as well (those three LiDAR sets in one,
    ``3 · per_class`` clouds per class).

    ``kinds`` (default: all of those) names the sets wanted, and only those (and the two that
    ``lidar+complete`` mixes) are made; :data:`OCCLUDED_POINTS` is made only when ``kinds`` names it: each set draws from its own random stream, so a set is
    the same whichever others are made with it (a resumed run makes only what it still needs).

    Raises
    ------
    InvalidInputError
        A kind in ``kinds`` that these arguments cannot make, and :func:`build_set`'s errors.
    """
    recipe = recipe or SetRecipe()
    available = [*TRAINING_SETS, OCCLUDED_POINTS]
    if fitted_sensor is not None:
        available.append(FITTED)
        if fitted_placement is not None and fitted_sizes is not None:
            available += [FITTED_PLACED, POOLED]
    wanted = [k for k in available if k != OCCLUDED_POINTS] if kinds is None else list(kinds)
    unknown = [k for k in wanted if k not in available]
    if unknown:
        raise InvalidInputError(f"cannot make training sets {unknown} with these arguments; these can be made: {available}")
    made = (
        set(wanted)
        | ({"lidar", "complete"} if "lidar+complete" in wanted else set())
        | ({"lidar", FITTED, FITTED_PLACED} if POOLED in wanted else set())
    )
    out = {
        kind: build_set(kind, meshes, names, per_class, n_points, seed, recipe, progress=progress)
        for kind in TRAINING_SETS[:3]
        if kind in made
    }
    if "lidar+complete" in made:
        out["lidar+complete"] = mix_sets(out["lidar"], out["complete"], seed)
    if OCCLUDED_POINTS in made:
        out[OCCLUDED_POINTS] = build_set(OCCLUDED_POINTS, meshes, names, per_class, n_points, seed, recipe, progress=progress)
    if FITTED in made:
        out[FITTED] = build_set("lidar", meshes, names, per_class, n_points, seed, replace(recipe, sensor=fitted_sensor), progress=progress)
    if FITTED_PLACED in made:
        placed = replace(recipe, sensor=fitted_sensor, placement=fitted_placement, sizes=fitted_sizes)
        out[FITTED_PLACED] = build_set("lidar", meshes, names, per_class, n_points, seed, placed, progress=progress)
    if POOLED in made:
        out[POOLED] = CloudSet.concat([out["lidar"], out[FITTED], out[FITTED_PLACED]])
    return {kind: out[kind] for kind in available if kind in wanted}
