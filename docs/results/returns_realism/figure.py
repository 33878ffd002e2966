"""Real and simulated HDL-32E scans of a pole and a bush, seen from the sensor, coloured by return number.

    .venv/bin/python docs/results/returns_realism/figure.py ../shared/data/street_objects \
        ../shared/data/lidarnet_v2_partial --out docs/results/returns_realism

Writes ``returns_by_class.png`` (rows: :data:`ROWS`; columns: the real scan and the scanner
variants of :data:`VARIANTS`) and its caption ``figure.md`` with the picks into ``--out``.

Each panel holds one object's points only (``object_id != 0`` for the simulated crops; the real
scans hold nothing else), drawn in the sensor frame as azimuth against elevation in degrees (azimuth
to the right of the points' centroid as the sensor sees it: the view from the sensor's side, its
scan lines horizontal), with equal scales and one span per row, so that sizes compare along a row.
Colour is the return number: 1, 2, 3 or later.  The real LiDARNet v2 scans record one return per
pulse, so every real point is return 1; :func:`shared_directions` counts the fit half's pairs of points that
share a direction (as a pulse's two returns would), for the caption.

The picks, by rule (:func:`median_pick`), never by eye:

* **real**: among the **fit half** of the real scans of the class (``experiment sim2real``'s split,
  ``measure.fit_half_scans``), those whose centroid lies
  :data:`RANGE_M` away, the scan whose point count is nearest their median;
* **simulated**: the ``lidar`` set's crops of the class's meshes (``measure.sim_crops``: sim2real's
  placements and rule, ``--crops`` per mesh) kept by every variant, whose centroid lies
  :data:`RANGE_M` away in the first variant, the crop whose first-variant point count is nearest
  their median; every simulated column shows that crop (the same mesh and placement).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
from collections.abc import Callable, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from measure import fit_half_scans, sim_crops  # noqa: E402

from zbuf_occlude.sensors.request import kept_returns  # noqa: E402
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes  # noqa: E402
from zbuf_occlude.io.atomic import write_bytes, write_text  # noqa: E402
from zbuf_occlude.io.encodings import png_bytes  # noqa: E402
from zbuf_occlude.sensors import Lidar  # noqa: E402
from zbuf_occlude.sensors.kinds import sensor_from_name  # noqa: E402

log = logging.getLogger("returns_figure")

#: The rows, one class each.
ROWS = ("pole", "bush")
#: Range to the points' centroid, metres, of the scans and crops a pick is made from: where most real scans of both classes lie.
RANGE_M = (6.0, 10.0)
#: The sensor file of experiment sim2real's "on" runs (fit_threshold.py): the preset's beam with a 7-ray footprint, the strongest
#: return and the fitted min_echo_reflectance.
ON_SENSOR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "fit", "hdl32e_footprint.json")
#: The same with the ray drop on crowns fitted to the fit half (ray_drop.py).
RAY_DROP_SENSOR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "ray_drop", "hdl32e_ray_drop.json")
#: The simulated columns: a title and a function of the HDL-32E preset.
VARIANTS: list[tuple[str, Callable[[Lidar], Lidar]]] = [
    ("simulated, --returns 2", lambda s: kept_returns(s, 2)),
    ("simulated, the on runs' sensor file:\n7 rays, strongest echo, fitted threshold",
     lambda _: sensor_from_name(ON_SENSOR)),
    ("simulated, the same with the fitted\nray drop on crowns (0.073)", lambda _: sensor_from_name(RAY_DROP_SENSOR)),
]  # fmt: skip
#: Colours of return 1, 2 and 3+ (colour-blind-safe: Okabe-Ito blue, orange, vermillion).
RETURN_COLOURS = ("#0072B2", "#E69F00", "#D55E00")
RETURN_LABELS = ("return 1", "return 2", "return 3+")
#: Extra span around a row's widest object, as a share of it, so that no point sits on a panel's edge.
MARGIN = 0.08
DPI = 150
#: Directions within this angle, degrees, count as one pulse's (the HDL-32E fires every 0.16° or so of azimuth: a tenth of a step).
SAME_DIRECTION_DEG = 0.016
#: Two points of one direction further apart in range than this, metres, count as two returns (the 0.75 m echo separation, less margin).
SECOND_RETURN_APART_M = 0.3


def median_pick(ranges_m: Sequence[float], counts: Sequence[int]) -> int:
    """The index of the cloud whose point count is nearest the median count of those :data:`RANGE_M` away.

    Parameters
    ----------
    ranges_m : (C,) float
        Range to each cloud's centroid, metres.
    counts : (C,) int
        Each cloud's points.

    Returns
    -------
    int
        Into ``ranges_m``; ties go to the first.

    Raises
    ------
    SystemExit
        No cloud lies :data:`RANGE_M` away.
    """
    ranges, counts = np.asarray(ranges_m, dtype=np.float64), np.asarray(counts, dtype=np.float64)
    rows = np.flatnonzero((ranges >= RANGE_M[0]) & (ranges < RANGE_M[1]))
    if not len(rows):
        raise SystemExit(f"no cloud {RANGE_M[0]:g}-{RANGE_M[1]:g} m away to pick from")
    median = np.median(counts[rows])
    return int(rows[np.argmin(np.abs(counts[rows] - median))])


def azimuth_elevation(points_m: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Sensor-frame points (N, 3), z up, metres, as the sensor sees them: degrees of azimuth to the right of
    the points' centroid (wrapped to ±180) and of elevation above the horizontal."""
    x, y, z = points_m.T
    cx, cy, _ = points_m.mean(axis=0)
    # clockwise seen from above is rightwards seen from the sensor
    right = -np.degrees(np.arctan2(y, x) - np.arctan2(cy, cx))
    right = (right + 180.0) % 360.0 - 180.0
    return right, np.degrees(np.arctan2(z, np.hypot(x, y)))


def _range_m(points_m: NDArray[np.floating]) -> float:
    """Range to the points' centroid, metres (``measure.per_crop``'s ``range_m``)."""
    return float(np.linalg.norm(np.asarray(points_m, dtype=np.float64).mean(axis=0)))


def shared_directions(
    clouds: Sequence[NDArray[np.floating]], *, within_deg: float = SAME_DIRECTION_DEG, apart_m: float = SECOND_RETURN_APART_M
) -> tuple[int, int, int]:
    """Points, pairs of points whose directions from the sensor lie within ``within_deg`` of each other, and those of
    the pairs more than ``apart_m`` apart in range (what a pulse's two returns would be), over sensor-frame clouds (N, 3), m."""
    from scipy.spatial import cKDTree

    points = pairs = apart = 0
    for p in clouds:
        p = np.asarray(p, dtype=np.float64)
        r = np.linalg.norm(p, axis=1)
        # chord between unit vectors for the angle: 2 sin(θ/2)
        found = cKDTree(p / r[:, None]).query_pairs(2 * np.sin(np.radians(within_deg) / 2), output_type="ndarray")
        points, pairs, apart = points + len(p), pairs + len(found), apart + int((np.abs(r[found[:, 0]] - r[found[:, 1]]) > apart_m).sum())
    return points, pairs, apart


def return_counts(return_number: NDArray[np.integer]) -> list[int]:
    """Points that are return 1, 2 and 3 or later."""
    r = np.asarray(return_number)
    return [int((r == 1).sum()), int((r == 2).sum()), int((r >= 3).sum())]


def draw_panel(ax, cloud: dict, title: str, half_span_deg: tuple[float, float]) -> None:
    """One object's points (``cloud``: ``points_m``, ``return_number``, ``number_of_returns``), azimuth against
    elevation, later returns drawn over earlier ones, points of pulses with two or more returns ringed."""
    right, up = azimuth_elevation(cloud["points_m"])
    r = np.minimum(np.asarray(cloud["return_number"]), 3)
    multi = np.asarray(cloud["number_of_returns"]) >= 2
    for k, colour in enumerate(RETURN_COLOURS, start=1):
        m = r == k
        ax.scatter(right[m], up[m], s=8, c=colour, edgecolors=np.where(multi[m], "black", "none").tolist(), linewidths=0.6, zorder=k)
    mid = (up.max() + up.min()) / 2
    ax.set_xlim(-half_span_deg[0], half_span_deg[0])
    ax.set_ylim(mid - half_span_deg[1], mid + half_span_deg[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_title(title, fontsize=8.5)
    ax.tick_params(labelsize=7)
    ax.grid(True, lw=0.3, alpha=0.5)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("meshes", help="class folders of meshes (street_objects)")
    ap.add_argument("real", help="LiDARNet v2 folder (lidarnet_v2_partial)")
    ap.add_argument("--out", required=True, help="folder for returns_by_class.png and figure.md")
    ap.add_argument("--crops", type=int, default=8, help="crops per mesh (default %(default)s)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--up-map", default="bush/openglforest__*=+y", help="GLOB=AXIS,... as experiment sim2real's (default %(default)s)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    t0 = time.perf_counter()
    up_map = dict(pair.split("=", 1) for pair in args.up_map.split(",") if pair)

    real = fit_half_scans(args.real)
    n_real, n_pairs, n_apart = shared_directions([s.points_sensor_m for s in real])
    meshes = find_class_meshes(args.meshes, up_map=up_map, classes=list(ROWS))
    hdl32e = Lidar.preset("hdl32e")
    sims = []
    for name, make in VARIANTS:
        crops = sim_crops(meshes, make(hdl32e), args.crops, args.seed)
        sims.append({(c["mesh"], c["crop"]): c for c in crops})
        log.info("%s: %d crops", name.replace("\n", " "), len(crops))

    panels, picks, shares = [], [], []  # panels[row] = [(cloud, title), ...]
    for cls in ROWS:
        mine = [s for s in real if s.label == cls]
        ranges = [_range_m(s.points_sensor_m) for s in mine]
        i = median_pick(ranges, [len(s.points_sensor_m) for s in mine])
        scan, n_near = mine[i], sum(RANGE_M[0] <= r < RANGE_M[1] for r in ranges)
        p = np.asarray(scan.points_sensor_m, dtype=np.float64)
        ones = np.ones(len(p), np.uint8)
        row = [({"points_m": p, "return_number": ones, "number_of_returns": ones},
                f"real LiDARNet v2 (fit half), {ranges[i]:.1f} m\n{len(p)} points, all return 1 (one return per pulse recorded)")]  # fmt: skip
        picks.append(f"| {cls} | real | `{os.path.relpath(scan.source, args.real)}` | {ranges[i]:.1f} | {len(p)} | "
                     f"nearest the median of {n_near} fit-half scans |")  # fmt: skip

        keys = sorted(k for k in sims[0] if sims[0][k]["class"] == cls and all(k in s for s in sims[1:]))
        first_ranges = [_range_m(sims[0][k]["points_m"]) for k in keys]
        j = median_pick(first_ranges, [len(sims[0][k]["points_m"]) for k in keys])
        near = [k for k, r in zip(keys, first_ranges) if RANGE_M[0] <= r < RANGE_M[1]]
        for (name, _), sim in zip(VARIANTS, sims):
            c, flat = sim[keys[j]], name.replace("\n", " ")
            rng, n = _range_m(c["points_m"]), len(c["points_m"])
            n1, n2, n3 = return_counts(c["return_number"])
            n_multi = int((c["number_of_returns"] >= 2).sum())
            row.append((c, f"{name}, {rng:.1f} m\n{n} points: {n1} r1, {n2} r2, {n3} r3+; {n_multi} ringed"))
            picks.append(f"| {cls} | {flat} | `{c['mesh']}`, crop {c['crop']} | {rng:.1f} | {n} | "
                         f"nearest the median of {len(near)} crops (by the first simulated column's counts) |")  # fmt: skip
            # what the picked crop stands for: every candidate crop of the class and variant
            total = sum(len(sim[k]["points_m"]) for k in near)
            later = sum(int((sim[k]["return_number"] >= 2).sum()) for k in near)
            multi = sum(int((sim[k]["number_of_returns"] >= 2).sum()) for k in near)
            shares.append(f"| {cls} | {flat} | {len(near)} | {total} | {100 * later / total:.1f} | {100 * multi / total:.1f} |")
        panels.append(row)

    fig, axes = plt.subplots(len(ROWS), 1 + len(VARIANTS), figsize=(14.0, 8.8), squeeze=False)
    for r, (cls, row) in enumerate(zip(ROWS, panels)):
        spans = [azimuth_elevation(c["points_m"]) for c, _ in row]
        half = (max(np.abs(a).max() for a, _ in spans) * (1 + MARGIN), max(np.ptp(e) for _, e in spans) / 2 * (1 + MARGIN))
        for col, (c, title) in enumerate(row):
            draw_panel(axes[r, col], c, title, half)
        axes[r, 0].set_ylabel(f"{cls}\nelevation, deg", fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel("azimuth right of the centroid, deg", fontsize=8)
    handles = [Line2D([], [], ls="", marker="o", ms=5, color=c, label=lab) for c, lab in zip(RETURN_COLOURS, RETURN_LABELS)]
    handles.append(Line2D([], [], ls="", marker="o", ms=5, mfc="white", mec="black", label="ringed: its pulse had 2+ returns"))
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8.5, frameon=False)
    fig.suptitle("HDL-32E scans seen from the sensor, coloured by return number (object points only)", fontsize=10.5)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    os.makedirs(args.out, exist_ok=True)
    png = png_bytes(fig, dpi=DPI)
    write_bytes(os.path.join(args.out, "returns_by_class.png"), png)
    plt.close(fig)

    wall = time.perf_counter() - t0
    caption = (
        "# Real and simulated pole and bush scans by return number\n\n"
        "![returns by class](returns_by_class.png)\n\n"
        "One object's points per panel, seen from the sensor: azimuth to the right of the points' centroid against elevation, "
        "in degrees, on one scale per row, coloured by return number (1, 2, 3+); a ringed point's pulse had two or more returns "
        "(its others fell on the ground or behind the object, or are the object's other coloured points). Rows: pole, bush. "
        "Columns: a real LiDARNet v2 "
        "HDL-32E scan (every point is return 1: the set records one return per pulse; of the fit half's "
        f"{n_real:,} points, {n_pairs} pairs lie within {SAME_DIRECTION_DEG:g}° of one direction, {n_apart} of them more than "
        f"{SECOND_RETURN_APART_M:g} m apart in range as a pulse's two returns would be); "
        'the HDL-32E preset with `--returns 2` (`kept_returns(hdl32e, 2)`); the sensor file of `experiment sim2real`\'s "on" runs '
        "(`fit/hdl32e_footprint.json`: the preset with a 7-ray footprint, the strongest echo and the min_echo_reflectance "
        f"fitted on the fit half, {sensor_from_name(ON_SENSOR).beam.min_echo_reflectance:g}; the runs trained with its strongest "
        "surface instead, which gives the same point counts on these crops). The simulated crops are the `lidar` set's of "
        "`experiment sim2real` (`measure.sim_crops`); both simulated columns show the same mesh and placement.\n\n"
        f"Picks, by rule: among the clouds whose centroid lies {RANGE_M[0]:g}-{RANGE_M[1]:g} m away, the one whose point count "
        "is nearest their median: for the real column among the fit half of the real scans (`experiment sim2real`'s split, as "
        f"`fit_threshold.py` selects it); for the simulated columns among the crops ({args.crops} per mesh, seed {args.seed}) kept "
        "by both variants, by their counts with `--returns 2`.\n\n"
        "| class | column | scan or crop | range to centroid, m | points | picked as |\n|---|---|---|---|---|---|\n"
        + "\n".join(picks)
        + "\n\nWhat a picked crop stands for: over every candidate crop of the class (the crops the pick is made from), the "
        "share of object points that are return 2 or later, and of object points from pulses with two or more returns.\n\n"
        "| class | column | crops | points | % return 2+ | % from 2+-return pulses |\n|---|---|---|---|---|---|\n"
        + "\n".join(shares)
        + "\n\nMade by\n\n"
        "    .venv/bin/python docs/results/returns_realism/figure.py ../shared/data/street_objects \\\n"
        f"        ../shared/data/lidarnet_v2_partial --out docs/results/returns_realism --crops {args.crops} --seed {args.seed}\n\n"
        f"({wall:.0f} s wall on a shared 2-core machine.)\n"
    )
    write_text(os.path.join(args.out, "figure.md"), caption)
    log.info("wrote returns_by_class.png (%d bytes) and figure.md in %.0f s", len(png), wall)
    return 0


if __name__ == "__main__":
    sys.exit(main())
