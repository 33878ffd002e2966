"""Procedural families fitted to real crops: which families a class takes, and how wide to draw them.

:func:`fit_families` looks, per class of real crops that a family of
:data:`~zbuf_occlude.mesh.families.FAMILIES` writes to, at what a classifier sees of a crop once it is
normalised: its proportions and how its points spread over its height
(:func:`~zbuf_occlude.experiments.realism_stats.shape_stats`, heading-free).  For each such family it
draws ``objects`` objects, scans ``crops`` crops of each as the ``lidar`` training set does (the
sensor, :data:`~zbuf_occlude.sensors.fit.class_placement.LIDAR_PLACEMENT`, the class's size range),
and fits the family's horizontal stretch (:func:`~zbuf_occlude.mesh.families.fitted.widen`, a factor
drawn in ``[lo, hi]``) to the crops' height / width, in log space: starting from no stretch, each of
``iterations`` updates moves the range's centre by ``log(m_sim / m_real)`` (the medians; height /
width goes as one over the stretch) and its half-width by a quarter of ``log(q90/q10)_real −
log(q90/q10)_sim`` (not below 0), clipped to ``[MIN_WIDTH_SCALE, MAX_WIDTH_SCALE]``.  A family's
distance to the real crops is the mean ``|log(q_sim / q_real)|`` over the 10th, 50th and 90th
percentiles of height / width, plus the same of the footprint's plan elongation (``plan_elongation``:
how much longer than broad the crop is from above, which the stretch does not change), plus the
profile distance (:func:`~zbuf_occlude.experiments.realism_stats.profile_distance`); of the ranges
tried (the first and each update's) the nearest is kept.  A class then takes its nearest family, and
each next family, nearest first, whose crops brought into the chosen ones' bring their union nearer
the real crops (a real class is often a mix: shrubs and hedges, trunks and utility poles), in equal
shares.  Given the user's meshes of the class, scanned the same way, the chosen families must come
nearer the real crops than those meshes (a family that would move the class's crops away from the
real ones adds nothing); a class whose meshes are nearer keeps its meshes alone.  Every family tried
is recorded with what it was fitted to and what it reached, and the meshes' statistics beside them
(:attr:`FamiliesFit.record`).

The objects, crops and their seeds derive from ``seed`` alone, so a fit is the same on every run.  A
class that no family writes to (cars) is left to the user's meshes.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.realism_stats import HEIGHT_BINS, profile_distance, shape_stats
from zbuf_occlude.sensors.fit.class_placement import MIN_RETURNS, CropPlacement
from zbuf_occlude.mesh.families.fitted import (
    FAMILIES_FIT_FORMAT,
    MAX_WIDTH_SCALE,
    MIN_WIDTH_SCALE,
    FamiliesFit,
    draw_object,
    parse_families_fit,
)
from zbuf_occlude.mesh.families.registry import FAMILIES
from zbuf_occlude.mesh.sizes import SizeRange

__all__ = ["FIT_QUANTILES", "MIN_FIT_CROPS", "crop_shapes", "families_of", "family_heights", "family_meshes",
           "fit_families"]  # fmt: skip

log = logging.getLogger(__name__)

#: The percentiles of the crops' height / width that the stretch is fitted to and scored on.
FIT_QUANTILES = (10.0, 50.0, 90.0)
#: Fewest real crops of a class, and fewest simulated crops of a family, a fit is made from.
MIN_FIT_CROPS = 5


def families_of(class_name: str) -> list[str]:
    """The families that write to ``class_name``, in :data:`~zbuf_occlude.mesh.families.FAMILIES` order."""
    return [name for name, f in FAMILIES.items() if f.class_name == class_name]


def family_heights(real: Mapping[str, Sequence[NDArray[np.floating]]]) -> dict[str, SizeRange]:
    """The sizes of the classes a family writes to, from their real crops' object heights.

    The ground is :func:`~zbuf_occlude.sensors.fit.fit_sensor_height` of every crop given; a class's size is
    the :data:`~zbuf_occlude.sensors.fit.scans.DISTANCE_QUANTILES` percentiles of its crops' heights above it
    (:func:`~zbuf_occlude.sensors.fit.fit_crop_heights`: the top return's), as a ``"height"``
    :class:`~zbuf_occlude.mesh.sizes.SizeRange` of at least 5 cm: what ``fit_sensor`` fits for the fitted
    sets, for the classes whose meshes the families join.

    Parameters
    ----------
    real : mapping of str to sequence of (N_i, 3) float
        Per class, segmented real crops: sensor at the origin, z up, metres.

    Returns
    -------
    dict of str to SizeRange
        The classes of ``real`` that a family writes to (:func:`families_of`) and that hold
        :data:`MIN_FIT_CROPS` crops or more.

    Raises
    ------
    InvalidInputError
        What :func:`~zbuf_occlude.sensors.fit.fit_sensor_height` refuses (no crop with a return).
    """
    from zbuf_occlude.sensors.fit.scans import fit_crop_heights, fit_sensor_height

    ground = fit_sensor_height([c for clouds in real.values() for c in clouds])
    out = {}
    for name, clouds in real.items():
        if families_of(name) and sum(len(c) > 0 for c in clouds) >= MIN_FIT_CROPS:
            lo, hi = fit_crop_heights(clouds, ground)
            out[name] = SizeRange("height", max(float(lo), 0.05), max(float(hi), 0.05))
    return out


def crop_shapes(clouds: Sequence[NDArray[np.floating]]) -> dict:
    """The statistics a fit matches, of a class's crops (z up; any frame, any unit).

    Returns
    -------
    dict
        ``crops`` (those with a height and a width), ``height_to_width`` and ``plan_elongation`` (the
        :data:`FIT_QUANTILES` percentiles of :func:`~zbuf_occlude.experiments.realism_stats.shape_stats`'
        height / width and plan elongation, the latter over the crops whose footprint is not a line; NaN
        where every one is) and ``height_shares`` (``(HEIGHT_BINS,)``, their mean share of points per
        tenth of the height).
    """
    return _summary(_crop_stats(clouds))


def _crop_stats(clouds: Sequence[NDArray[np.floating]]) -> list[dict]:
    """:func:`~zbuf_occlude.experiments.realism_stats.shape_stats` of each crop that has a height and a width."""
    stats = [shape_stats(np.asarray(c, np.float64)) for c in clouds if len(c) >= 2]
    return [s for s in stats if math.isfinite(s["height_to_width"]) and s["height_m"] > 0]


def _summary(stats: Sequence[dict]) -> dict:
    """:func:`crop_shapes` of the crops whose :func:`_crop_stats` these are."""
    nan = [math.nan] * len(FIT_QUANTILES)
    if not stats:
        return {"crops": 0, "height_to_width": nan, "plan_elongation": nan, "height_shares": [math.nan] * HEIGHT_BINS}
    ratios = np.array([s["height_to_width"] for s in stats])
    elongation = np.array([s["plan_elongation"] for s in stats])
    return {"crops": len(stats), "height_to_width": [float(v) for v in np.percentile(ratios, FIT_QUANTILES)],
            "plan_elongation": [float(v) for v in np.nanpercentile(elongation, FIT_QUANTILES)] if np.isfinite(elongation).any() else nan,
            "height_shares": [float(v) for v in np.mean([s["height_shares"] for s in stats], axis=0)]}  # fmt: skip


def _distance(sim: dict, real: dict) -> float:
    if sim["crops"] < MIN_FIT_CROPS:
        return math.inf
    q = np.abs(np.log(np.asarray(sim["height_to_width"]) / np.asarray(real["height_to_width"])))
    plan = np.abs(np.log(np.asarray(sim["plan_elongation"]) / np.asarray(real["plan_elongation"])))
    return float(q.mean()) + float(plan.mean()) + profile_distance(sim["height_shares"], real["height_shares"])


def _scanned(entries: Sequence, size: SizeRange, sensor, *, crops: int, seed: int) -> list[NDArray[np.float64]]:
    """``crops`` crops of each of ``entries`` (MeshEntry: normalised, z up), scanned as the ``lidar`` set scans them
    (:data:`~zbuf_occlude.sensors.fit.class_placement.LIDAR_PLACEMENT`, the class's size): those of
    ``MIN_RETURNS`` returns or more, each's distinct points."""
    from zbuf_occlude.sensors.crops import lidar_object_samples

    placement, clouds = CropPlacement(), []
    for entry in entries:
        dist, _ = placement.crop_distributions(entry, size)
        samples = lidar_object_samples(entry.mesh, sensor, name=entry.name, n_samples=crops, n_points=1024, seed=seed,
                                       distributions=dist, class_name=entry.class_name)  # fmt: skip
        clouds += [np.unique(c.points.astype(np.float64), axis=0) for c in samples if c.n_visible >= MIN_RETURNS]
    return clouds


def _json_distance(distance: float) -> float | None:
    """A distance as the record holds it: JSON has no infinity, and too few crops have no distance (None)."""
    return distance if math.isfinite(distance) else None


def _simulated(family: str, size: SizeRange, sensor, width_scale: tuple[float, float], *, objects: int, crops: int,
               seed: int) -> list[NDArray[np.float64]]:  # fmt: skip
    """``crops`` crops each of ``objects`` objects of ``family`` stretched in ``width_scale``, scanned as the ``lidar``
    set scans (:func:`_scanned`; the same objects and placements for every ``width_scale``)."""
    from zbuf_occlude.mesh.inputs.class_folders import MeshEntry
    from zbuf_occlude.mesh.load import normalize_mesh

    fam = FAMILIES[family]
    entries = [MeshEntry(path=None, class_name=fam.class_name, name=f"families/{family}_{k}",
                         mesh=normalize_mesh(draw_object(fam, seed, k, width_scale)[1])) for k in range(objects)]  # fmt: skip
    return _scanned(entries, size, sensor, crops=crops, seed=seed)


def _fit_family(family: str, real: dict, size: SizeRange, sensor, *, objects: int, crops: int, seed: int,
                iterations: int) -> tuple[dict, list[dict]]:  # fmt: skip
    """The stretch of ``family`` fitted to ``real`` (:func:`crop_shapes`): the nearest of ``iterations + 1`` tried (the
    record), and its crops' :func:`_crop_stats`."""
    lo, hi = 1.0, 1.0
    steps, crop_stats = [], []
    for step in range(iterations + 1):
        crop_stats.append(_crop_stats(_simulated(family, size, sensor, (lo, hi), objects=objects, crops=crops, seed=seed)))
        sim = _summary(crop_stats[-1])
        steps.append({"width_scale": [lo, hi], "simulated": sim, "distance": _distance(sim, real)})
        if sim["crops"] < MIN_FIT_CROPS or step == iterations:
            break
        (s10, s50, s90), (r10, r50, r90) = sim["height_to_width"], real["height_to_width"]
        centre, half = 0.5 * math.log(lo * hi), 0.5 * math.log(hi / lo)
        centre += math.log(s50 / r50)  # height / width goes as 1 / stretch: a taller ratio than the real one widens
        half = max(0.0, half + 0.25 * (math.log(r90 / r10) - math.log(s90 / s10)))  # a spread narrower than the real one widens the range
        lo, hi = (float(np.clip(math.exp(v), MIN_WIDTH_SCALE, MAX_WIDTH_SCALE)) for v in (centre - half, centre + half))
    best = min(range(len(steps)), key=lambda k: steps[k]["distance"])
    return {**steps[best], "steps": [{"width_scale": st["width_scale"], "height_to_width": st["simulated"]["height_to_width"],
                                      "crops": st["simulated"]["crops"], "distance": st["distance"]} for st in steps]}, crop_stats[best]  # fmt: skip


def _choose(tried: Mapping[str, dict], crop_stats: Mapping[str, list[dict]], real: dict) -> tuple[list[str], float]:
    """The families a class takes (module docstring): the nearest, then each next, nearest first, whose crops
    (their ``crop_stats``) brought into the chosen ones' bring the union nearer ``real``; and the union's distance."""
    order = sorted((n for n, t in tried.items() if math.isfinite(t["distance"])), key=lambda n: tried[n]["distance"])
    if not order:
        return [], math.inf
    chosen, pool, distance = [order[0]], list(crop_stats[order[0]]), tried[order[0]]["distance"]
    for name in order[1:]:
        candidate = pool + crop_stats[name]
        joined = _distance(_summary(candidate), real)
        if joined < distance:
            chosen, pool, distance = [*chosen, name], candidate, joined
    return chosen, distance


def fit_families(real: Mapping[str, Sequence[NDArray[np.floating]]], sensor, sizes: Mapping[str, SizeRange], *, objects: int = 8,
                 crops: int = 4, iterations: int = 3, seed: int = 0, fitted_on: str = "",
                 meshes: Mapping[str, Sequence] | None = None) -> FamiliesFit:  # fmt: skip
    """Fit the families of each class of ``real`` to its crops (module docstring).

    Parameters
    ----------
    real : mapping of str to sequence of (N_i, 3) float
        Real object crops per class, z up (metres; any frame: the statistics are of proportions).
        Only the crops that may be fitted on: never the scans that score.
    sensor : Lidar
        The scanner of the ``lidar`` set.
    sizes : mapping of str to SizeRange
        The ``lidar`` set's size per class (a class without one is not fitted).
    objects, crops, iterations : int
        Objects drawn per family, crops per object, updates of the stretch (each >= 1).
    seed : int
        Every object's and crop's seed.
    fitted_on : str
        What the crops are, for the record (``"the fit half: 343 scans"``).
    meshes : mapping of str to sequence of MeshEntry, optional
        The user's meshes per class (normalised, z up), scanned as the families are: a class takes its
        chosen families only where their crops together come nearer its real crops than its meshes' do,
        and none otherwise.  A class without meshes here takes its chosen families.

    Returns
    -------
    FamiliesFit
        Its :attr:`~zbuf_occlude.mesh.families.fitted.FamiliesFit.record` is the JSON document
        (``format``, ``fitted_on``, ``statistic``, ``seed``, ``objects``, ``crops``, per class the
        real crops' statistics, every family tried, the meshes' statistics and the chosen families;
        a class that keeps its meshes alone is listed under ``meshes_kept`` instead of ``classes``).

    Raises
    ------
    InvalidInputError
        ``objects``, ``crops`` or ``iterations`` below 1, or no class of ``real`` that a family
        writes to with :data:`MIN_FIT_CROPS` crops.
    """
    for key, value in (("objects", objects), ("crops", crops), ("iterations", iterations)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise InvalidInputError(f"fit_families: {key} must be an integer >= 1, got {value!r}")
    doc: dict = {"format": FAMILIES_FIT_FORMAT, "fitted_on": fitted_on, "sensor": getattr(sensor, "name", ""),
                 "statistic": "crops' height / width and plan elongation (10th, 50th, 90th percentile) and share of points per tenth of the height",
                 "choice": "the nearest family, then each next one that brings the union of the chosen families' crops nearer",
                 "seed": int(seed), "objects": objects, "crops": crops, "iterations": iterations,
                 "classes": {}, "meshes_kept": {}}  # fmt: skip
    for cls in sorted(real):
        names = families_of(cls)
        target = crop_shapes(real[cls])
        if not names or cls not in sizes or target["crops"] < MIN_FIT_CROPS:
            continue
        tried, crop_stats = {}, {}
        for name in names:
            log.info("fitting the %s family to %d %s crops", name, target["crops"], cls)
            tried[name], crop_stats[name] = _fit_family(name, target, sizes[cls], sensor, objects=objects, crops=crops, seed=seed,
                                                        iterations=iterations)  # fmt: skip
        chosen, joined = _choose(tried, crop_stats, target)
        if not chosen:
            continue
        own = crop_shapes(_scanned(meshes[cls], sizes[cls], sensor, crops=crops, seed=seed)) if meshes and meshes.get(cls) else None
        own_distance = _distance(own, target) if own is not None else math.inf
        if joined >= own_distance:
            chosen = []
        for t in tried.values():
            t["distance"] = _json_distance(t["distance"])
        entry = {"real": target, "tried": tried, "chosen_distance": _json_distance(joined)}
        if own is not None:
            entry["meshes"] = {**own, "objects": len(meshes[cls]), "distance": _json_distance(own_distance)}
        if not chosen:
            log.info("the %s meshes come nearer the real crops than every family: the class keeps them alone", cls)
            doc["meshes_kept"][cls] = entry
            continue
        doc["classes"][cls] = {**entry, "chosen": {n: {"width_scale": tried[n]["width_scale"], "share": 1.0 / len(chosen)} for n in chosen}}
    if not doc["classes"] and not doc["meshes_kept"]:
        raise InvalidInputError(
            f"no class of the real crops has a family and {MIN_FIT_CROPS} crops to fit it to; families write to "
            f"{', '.join(sorted({f.class_name for f in FAMILIES.values()}))}"
        )
    return parse_families_fit(doc)


def family_meshes(fit: FamiliesFit, per_class: int, seed: int) -> list:
    """The objects a fit adds: ``per_class`` per fitted class split by the shares (:meth:`FamiliesFit.counts`),
    written as ``zbuf-occlude families FAMILY --fit FILE --count N --seed SEED`` writes them and loaded as
    any mesh file (:func:`zbuf_occlude.load_mesh`).

    Returns
    -------
    list of MeshEntry
        Named ``families/CLASS/FAMILY_K`` (so that no user mesh shares a name, or a seed, with one).
    """
    import tempfile
    from pathlib import Path

    from zbuf_occlude.mesh.inputs.class_folders import MeshEntry
    from zbuf_occlude.mesh.families.write import write_family
    from zbuf_occlude.mesh.load import load_mesh

    out = []
    with tempfile.TemporaryDirectory(prefix="zbuf_occlude_families_") as tmp:
        for family, count in fit.counts(per_class).items():
            run = write_family(family, tmp, count=count, seed=seed, width_scale=fit.width_scale(family))
            for path in run.files:
                rel = path.relative_to(tmp).with_suffix("").as_posix()
                out.append(MeshEntry(Path("families", rel + ".ply"), FAMILIES[family].class_name, f"families/{rel}", load_mesh(path)))
    return out
