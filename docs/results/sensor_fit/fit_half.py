"""What the sensor_fit scripts share: LiDARNet v2's fit half and the sensor, crop placement and heights that
`experiment sim2real --fit-sensor --sensor hdl32e` fits to it, with the street meshes it sees (bush trees glTF, +y up).
Imported by the scripts beside it (run from the repository root, ../shared beside it)."""

import collections
from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from zbuf_occlude.experiments.sim2real import run as S
from zbuf_occlude.experiments.sim2real.data import check_lidar_meshes
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes
from zbuf_occlude.sensors.fit.class_placement import LIDAR_PLACEMENT, CropPlacement
from zbuf_occlude.experiments.sim2real.real import real_clouds, real_scan_rows
from zbuf_occlude.mesh.sizes import size_interval
from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.sensors.crops import object_crop
from zbuf_occlude.sensors.placement import CropDistributions, draw_placement
from zbuf_occlude.sensors.fit import across_sight_width
from zbuf_occlude.sensors.kinds import sensor_from_name


#: The seed of the split these runs were made with.
RECORDED_SPLIT_SEED = 20_231


def recorded_fit_half(labels: np.ndarray) -> np.ndarray:
    """The fit half of the recorded runs (their real_split.csv): per class, in the reader's order (sorted paths), a
    seeded permutation's first half.  Runs made since split the scans by their content instead
    (zbuf_occlude.experiments.sim2real.real.real_halves)."""
    rng = np.random.default_rng(RECORDED_SPLIT_SEED)
    half = []
    for c in np.unique(labels):
        rows = rng.permutation(np.flatnonzero(labels == c))
        half.extend(rows[: len(rows) // 2].tolist())
    return np.sort(np.asarray(half, np.int64))


def load_fit_half(data: str) -> SimpleNamespace:
    """``scans``, ``kept`` (scan row per cloud), ``names``, ``real_y``, ``fit_half`` (cloud rows), ``fitted`` (the sensor),
    ``placement`` (per class, plain dicts: ``CropPlacement.from_keywords`` types them) and ``sizes`` (per class) and ``meshes``
    (those the fitted sensor sees), for the data folder ``data``."""
    scans = load_real_scans(f"{data}/lidarnet_v2_partial")
    meshes = find_class_meshes(f"{data}/street_objects", up_map={"bush/openglforest__*": "+y"})
    names = sorted({m.class_name for m in meshes})
    _, real_y, _ = real_clouds(scans, names, {}, 256, 0)
    half = recorded_fit_half(real_y)
    kept = real_scan_rows(scans, names, {})
    fitted, placement, sizes, _ = S._fit_sensor([scans[kept[i]] for i in half], sensor_from_name("hdl32e"), real_y[half], names)
    meshes, _ = check_lidar_meshes(meshes, fitted, sizes, 256, placement=CropPlacement.from_keywords(placement))
    return SimpleNamespace(scans=scans, kept=kept, names=names, real_y=real_y, fit_half=half, fitted=fitted, placement=placement,
                           sizes=sizes, meshes=meshes)  # fmt: skip


def widths_table(data: str, fit_width, keyword: str, tags: tuple[str, str], last_columns) -> None:
    """Print, per class, the fit half's widths across the line of sight and returns beside those of fitted+placed crops
    made without and with ``keyword`` (``fit_width(mesh, sensor, distributions, width_m)`` per mesh), 12 crops per mesh
    (one seed, at least 30 returns each); ``last_columns(fits, meshes)`` gives the closing columns' names and a
    function of the class that gives their cells."""
    f = load_fit_half(data)
    stats = {tag: collections.defaultdict(list) for tag in ("real", *tags)}
    for i in f.fit_half:
        p = np.asarray(f.scans[f.kept[i]].points_sensor_m, np.float64)
        stats["real"][f.names[f.real_y[i]]].append((across_sight_width(p), len(p)))
    rng = np.random.default_rng(1)
    fits = {}
    for m in f.meshes:
        keywords = dict(f.placement[m.class_name])
        width_m = keywords.pop("across_sight_width_m")
        keywords.pop("across_sight_profile", None)  # the outline: profile_by_class.py
        dist = CropDistributions(size_m=size_interval(m.mesh.extents, f.sizes[m.class_name]), **{**LIDAR_PLACEMENT, **keywords})
        fits[m.name] = fit_width(m.mesh, f.fitted, dist, width_m)
        for tag, d in zip(tags, (dist, replace(dist, **{keyword: fits[m.name]}))):
            for k in range(12):
                c = object_crop(m.mesh, f.fitted, draw_placement(d, rng), seed=k).scan.points
                if len(c) >= 30:  # sim2real's MIN_RETURNS
                    stats[tag][m.class_name].append((across_sight_width(c), len(c)))
    q = lambda v: f"{np.median(v):.2f} ({np.percentile(v, 25):.2f}–{np.percentile(v, 75):.2f})"  # noqa: E731
    names, cells_of = last_columns(fits, f.meshes)
    header = ["class", "fitted width, m"] + [h for tag in stats for h in (f"{tag}: width, m", "returns")] + names
    print("| " + " | ".join(header) + " |\n" + "|---" * len(header) + "|")
    for c in f.names:
        cells = [f"{f.placement[c]['across_sight_width_m'][0]:.2f}–{f.placement[c]['across_sight_width_m'][1]:.2f}"]
        for tag in stats:
            v = np.array(stats[tag][c])
            cells += [q(v[:, 0]), f"{np.median(v[:, 1]):.0f}"]
        print(f"| {c} | " + " | ".join(cells + cells_of(c)) + " |")
