"""Per class: the outline over the height (width_profile) of the fitted+placed crops as `--fitted-shape none`, `widths` and
`outline` make them, against the fit half's real scans (the sensor fitted as `--fit-sensor` does).

    python docs/results/sensor_fit/profile_by_class.py ../shared/data   (from the repository root)

12 crops per mesh, one seed, at least 30 returns each; medians over the class's crops and scans. Also the median width across
the line of sight and the returns per crop, and each mesh's distance from its class's real outline (the mean absolute
difference over the 8 bins) without → with the warp, and the warp.
"""

import collections
import sys

import numpy as np

from fit_half import load_fit_half
from zbuf_occlude.sensors.fit.class_placement import CropPlacement, fit_mesh_shapes
from zbuf_occlude.sensors.crops import object_crop
from zbuf_occlude.sensors.placement import draw_placement
from zbuf_occlude.sensors.fit import across_sight_width, width_profile

f = load_fit_half(sys.argv[1])
scans, kept, names, real_y, fit_half, fitted, placement, sizes, meshes = (f.scans, f.kept, f.names, f.real_y, f.fit_half, f.fitted,
                                                                           f.placement, f.sizes, f.meshes)  # fmt: skip


def without(*keys: str) -> CropPlacement:
    shaped = CropPlacement.from_keywords({c: {k: v for k, v in kw.items() if k not in keys} for c, kw in placement.items()})
    return shaped.with_mesh_shapes(fit_mesh_shapes(meshes, fitted, sizes, shaped))


# --fitted-shape none, widths and outline
variants = {
    "placed": without("across_sight_width_m", "across_sight_profile"),
    "widths": without("across_sight_profile"),
    "outline": without("across_sight_width_m"),
}
stats = collections.defaultdict(list)  # (tag, class) -> [(profile, width, returns)]
per_mesh = collections.defaultdict(list)  # (tag, mesh) -> [profile]
for i in fit_half:
    p = np.asarray(scans[kept[i]].points_sensor_m, np.float64)
    stats["real", names[real_y[i]]].append((width_profile(p), across_sight_width(p), len(p)))
for tag, place in variants.items():
    rng = np.random.default_rng(1)
    for m in meshes:
        dist, _ = place.crop_distributions(m, sizes[m.class_name])
        for k in range(12):
            c = object_crop(m.mesh, fitted, draw_placement(dist, rng), seed=k).scan.points.astype(np.float64)
            if len(c) >= 30:  # sim2real's MIN_RETURNS
                stats[tag, m.class_name].append((width_profile(c), across_sight_width(c), len(c)))
                per_mesh[tag, m.name].append(width_profile(c))
real_profile = {c: np.asarray(placement[c]["across_sight_profile"]) for c in names}
print("| class | crops | " + " | ".join(f"{b / 8:.3g}–{(b + 1) / 8:.3g}" for b in range(8)) + " | width, m | returns |")
print("|---|---|" + "---|" * 10)
for c in names:
    for tag in ("real", *variants):
        rows = stats[tag, c]
        prof = np.nanmedian(np.array([r[0] for r in rows]), axis=0)
        print(
            f"| {c} | {tag} | "
            + " | ".join(f"{v:.2f}" for v in prof)
            + f" | {np.median([r[1] for r in rows]):.2f} | {np.median([r[2] for r in rows]):.0f} |"
        )
print()
print("| class | mesh | outline distance, placed → outline | warp per bin (mesh height, bottom → top) |")
print("|---|---|---|---|")
for m in meshes:
    d = [np.nanmean(np.abs(np.nanmedian(np.array(per_mesh[t, m.name]), axis=0) - real_profile[m.class_name])) if per_mesh[t, m.name] else np.nan
         for t in ("placed", "outline")]  # fmt: skip
    shape = variants["outline"].per_mesh.get(m.name)
    warp = shape.width_profile if shape else None
    print(f"| {m.class_name} | {m.name} | {d[0]:.2f} → {d[1]:.2f} | " + (" ".join(f"{v:.2f}" for v in warp) if warp else "") + " |")
