"""A user's path on a real airborne tile: fit a sensor to it, scan a plot of vegetation meshes with that sensor, compare.

    python docs/results/scanners/user_path.py ../shared/data/als_returns/ign_lidarhd_sample.laz ../shared/data/street_objects/bush SEEDS \
        [--preset NAME] [SCAN OPTIONS]

1. ``zbuf-occlude fit-sensor TILE --sensor riegl-q1560 --altitude 1500 --out OUT/fitted.json`` (the command a user runs;
   with ``--preset NAME`` no fit: the preset as it comes, out of the box);
2. a plot of the vegetation meshes at their real sizes (``experiments.returns.PLOT_TREES``) on flat ground, 14 m apart;
3. ``zbuf-occlude scan plot.json --sensor OUT/fitted.json --format laz --seed S`` over the plot (a scene file of the meshes),
   one seed at a time, the LAZ read back with laspy;
4. on the points classified high vegetation (ASPRS 5) in the LAZ: the share from pulses of several returns, the
   intensities (counts) and the median intensity of first-of-several returns over that of single returns, beside
   the tile's own figures (laspy on the tile); and of the pulses that return from high vegetation: the share that
   end there with one return, the share that reach the ground, and how bright the ground returns behind them are
   (their median intensity over that of the single ground returns).

Prints one row per seed and the mean ± std over seeds (research data: never copied into the repository).
"""

from __future__ import annotations

import io
import json
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import laspy
import numpy as np

from zbuf_occlude.experiments.returns import PLOT_TREES
from zbuf_occlude.sensors.kinds import sensor_from_name


def _crown_pulses(t, cls, n, i) -> dict[str, float]:
    """Of the complete pulses that return from high vegetation (a pulse: the returns sharing a GPS time): the share with
    one return, the share that also return from the ground (class 2), and the median intensity of those ground returns
    over that of the single ground returns."""
    _, inverse, count = np.unique(t, return_inverse=True, return_counts=True)
    returns = np.zeros(len(count), np.int64)
    np.maximum.at(returns, inverse, n)
    crown, ground = np.zeros(len(count), bool), np.zeros(len(count), bool)
    np.logical_or.at(crown, inverse, cls == 5)
    np.logical_or.at(ground, inverse, cls == 2)
    crown &= count == returns
    behind = i[(cls == 2) & crown[inverse]]
    return {"crown_single": float((returns[crown] == 1).mean()), "crown_ground": float(ground[crown].mean()),
            "ground_behind": float(np.median(behind) / np.median(i[(cls == 2) & (n == 1)])) if len(behind) else float("nan")}  # fmt: skip


def tile_figures(path: Path) -> dict[str, float]:
    """The tile's high-vegetation (class 5) multi-return share and intensity ratio, with laspy (complete pulses not required)."""
    las = laspy.read(path)
    cls, n, r = np.asarray(las.classification), np.asarray(las.number_of_returns), np.asarray(las.return_number)
    i = np.asarray(las.intensity, np.float64)
    high = cls == 5
    return {"multi_share": float((n[high] > 1).mean()), "ratio": float(np.median(i[high & (n > 1) & (r == 1)]) / np.median(i[high & (n == 1)])),
            "intensity_median": float(np.median(i[high])), **_ground_spread(cls, n, i), **_crown_pulses(np.asarray(las.gps_time), cls, n, i)}  # fmt: skip


def _ground_spread(cls, n, i) -> dict[str, float]:
    """The intensities of single returns of the ground (class 2): p5, p50, p95 and p95 / p5."""
    p5, p50, p95 = np.percentile(i[(cls == 2) & (n == 1)], [5, 50, 95])
    return {"ground_p5": float(p5), "ground_p50": float(p50), "ground_p95": float(p95), "ground_spread": float(p95 / max(p5, 1.0))}


def plot_figures(laz: bytes) -> dict[str, float]:
    """The same figures on a simulated LAZ's high vegetation."""
    las = laspy.read(io.BytesIO(laz))
    cls, n, r = np.asarray(las.classification), np.asarray(las.number_of_returns), np.asarray(las.return_number)
    i = np.asarray(las.intensity, np.float64)
    high = cls == 5
    several, single = i[high & (n > 1) & (r == 1)], i[high & (n == 1)]
    return {"points": int(high.sum()), "multi_share": float((n[high] > 1).mean()),
            "ratio": float(np.median(several) / np.median(single)) if len(several) and len(single) else float("nan"),
            "intensity_median": float(np.median(i[high])), "zero": float((i == 0).mean()), "saturated": float((i[high] == 65535).mean()),
            **_ground_spread(cls, n, i), **_crown_pulses(np.asarray(las.gps_time), cls, n, i)}  # fmt: skip


def plot_file(seed: int, spacing_m: float = 14.0) -> dict:
    """A scene file of the plot: the meshes of :data:`PLOT_TREES` (copied to ``meshes/`` beside it: a scene's meshes lie in its
    folder) at their sizes on a square grid, each turned by a drawn yaw, classed vegetation, on a ground reaching past the
    grid (what ``experiments.returns.plot_scene`` builds)."""
    rng = np.random.default_rng(seed)
    side = math.ceil(math.sqrt(len(PLOT_TREES)))
    objects = []
    for i, tree in enumerate(PLOT_TREES):
        row, col = divmod(i, side)
        up = {} if tree.up == "auto" else {"up": tree.up.lstrip("+")}  # a scene file's meshes stand by their file's own up axis
        objects.append({"mesh": f"meshes/{tree.file}", "class": "vegetation", **up, "size_m": tree.size_m,
                        "position_m": [(col - (side - 1) / 2) * spacing_m, (row - (side - 1) / 2) * spacing_m],
                        "yaw_deg": float(rng.uniform(0.0, 360.0))})  # fmt: skip
    return {"ground": {"half_extent_m": side * spacing_m}, "objects": objects}


def main(tile: str, bush_folder: str, seeds: int, extra: list[str]) -> None:
    out = Path(tempfile.mkdtemp(prefix="user_path_"))
    if extra[:1] == ["--preset"]:  # the preset out of the box, no fit
        fitted, extra = extra[1], extra[2:]
    else:
        fitted = out / "fitted.json"
        subprocess.run([sys.executable, "-m", "zbuf_occlude", "fit-sensor", tile, "--sensor", "riegl-q1560", "--altitude", "1500",
                        "--out", str(fitted)], check=True)  # fmt: skip
    sensor = sensor_from_name(fitted)
    b = sensor.beam
    print(
        f"{sensor.name} beam: divergence {b.divergence_deg * np.pi / 180 * 1e3:.3f} mrad, {b.footprint_rays} sub-rays, max returns {b.max_returns}, "
        f"range resolution {b.range_resolution_m:.3f} m, threshold {b.detection_threshold:.3g} m^-2, intensity scale {b.intensity_scale:.3g}"
    )
    real = tile_figures(Path(tile))
    print(
        f"tile, high vegetation: multi-return share {real['multi_share']:.3f}, intensity ratio {real['ratio']:.3f}, median {real['intensity_median']:.0f}; "
        f"ground single returns p5/p50/p95 {real['ground_p5']:.0f}/{real['ground_p50']:.0f}/{real['ground_p95']:.0f}"
    )
    shutil.copytree(bush_folder, out / "meshes")
    rows = []
    for seed in range(seeds):
        scene = out / f"plot_{seed}.json"
        scene.write_text(json.dumps(plot_file(seed)))
        subprocess.run([sys.executable, "-m", "zbuf_occlude", "scan", str(scene), "--sensor", str(fitted), "--format", "laz",
                        "--seed", str(seed), "--no-progress", "--out", str(out / f"scan_{seed}"), *extra], check=True)  # fmt: skip
        row = plot_figures(next((out / f"scan_{seed}").glob("*.laz")).read_bytes())
        rows.append(row)
        print(
            f"seed {seed}: {row['points']} high-vegetation points, multi-return share {row['multi_share']:.3f}, ratio {row['ratio']:.3f}, "
            f"median {row['intensity_median']:.0f}, zero {row['zero']:.3f}, saturated {row['saturated']:.3f}, ground single returns "
            f"p5/p50/p95 {row['ground_p5']:.0f}/{row['ground_p50']:.0f}/{row['ground_p95']:.0f}"
        )
    for key in ("multi_share", "ratio", "intensity_median", "ground_spread", "crown_single", "crown_ground", "ground_behind"):
        v = np.array([r[key] for r in rows])
        print(
            f"{key}: {v.mean():.3f} ± {v.std(ddof=1) if len(v) > 1 else 0:.3f} (tile {real[key]:.3f}; simulated / tile {v.mean() / real[key]:.3f})"
        )


if __name__ == "__main__":
    # any further arguments go to scan (e.g. --transmittance 0: opaque foliage)
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 3, sys.argv[4:])
